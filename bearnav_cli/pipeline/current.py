"""What this process is working on (:data:`ACTIVITY`), for the message of an interrupt and of a warning.

The runners of :mod:`bearnav_cli.pipeline.files` name the stage they start and record when its output is
committed; the commands name what else they make (:func:`activity`); the command line's error handler
says from it what an interrupt or a failure left unwritten.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from dataclasses import dataclass
from typing import Iterator

__all__ = ["Activity", "ACTIVITY", "activity", "begin", "committed", "reset_activity"]


@dataclass
class Activity:
    """The stage this process is working on, for the message of an interrupt and of a warning.

    Attributes
    ----------
    stage : str or None
        Set when a stage starts, before its input is read.
    written : bool
        Set once its output is committed (artifacts.save's ``on_commit``, run with SIGINT held back).
    file : str or None
        What the stage reads: the map, or the artifact before it (warnings name it).
    """

    stage: str | None = None
    written: bool = False
    file: str | None = None


ACTIVITY = Activity()


def reset_activity() -> None:
    """Forget the current stage (:data:`ACTIVITY`): nothing is running, nothing written."""
    ACTIVITY.stage, ACTIVITY.written, ACTIVITY.file = None, False, None


def begin(stage: str, file: str | os.PathLike | None = None) -> None:
    """Name the stage starting (nothing written yet) and what it reads."""
    ACTIVITY.stage, ACTIVITY.written, ACTIVITY.file = stage, False, None if file is None else str(file)


@contextlib.contextmanager
def activity(stage: str, file: str | os.PathLike | None = None) -> Iterator[Activity]:
    """Name what the block works on in :data:`ACTIVITY` (nothing written yet), and restore what it named
    before when the block ends.

    An exception leaves it named: the command's error handler, outside the block, says from it what an
    interrupt or a failure left unwritten (and it resets :data:`ACTIVITY` before the next command).

    Parameters
    ----------
    stage : str
        What is being made: a command (``"verify"``) or a file (``"fig.png"``); interrupts and warnings say it.
    file : str or path, optional
        What it reads (warnings say ``STAGE of FILE``).
    """
    before = dataclasses.replace(ACTIVITY)
    begin(stage, file)
    yield ACTIVITY
    ACTIVITY.stage, ACTIVITY.written, ACTIVITY.file = before.stage, before.written, before.file


def committed() -> None:
    """Record that the current stage's output is in place."""
    ACTIVITY.written = True
