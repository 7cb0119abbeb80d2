"""What the command line writes: the consoles, -q, library warnings, JSON, progress bars, stage lines, figures.

rich, logging and matplotlib are imported on first use, not with the app, so that ``bearnav --help``
starts at once (bench/README.md "Start-up"; tests/test_cli_startup.py).
"""

import functools
import json
import os
import re
import sys
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from rich.console import Console
    from rich.progress import Progress

    from bearnav_cli import pipeline

__all__ = [
    "FIGURE_SUFFIXES",
    "QUIET_HELP",
    "Quiet",
    "count_column",
    "err",
    "out",
    "plotting",
    "print_json",
    "progress_bar",
    "progress_factory",
    "report_line",
    "setup_logging",
]


#: Where rich would print what it prints plainly anywhere else: styles and escapes may appear (a forced
#: terminal), emoji codes become emoji, ``[tags]`` are markup, tabs and control characters are rewritten.
_RICH_ENVIRONMENT = ("FORCE_COLOR", "TTY_COMPATIBLE", "TTY_INTERACTIVE", "JUPYTER_COLUMNS", "JUPYTER_LINES")
_EMOJI_CODE = re.compile(r":\S*:")
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


class _Console:
    """A rich Console made on first use: importing rich.console takes 20 ms that ``--help`` does not need.

    Everything but :attr:`console` (the Console itself, for rich's own classes) is the Console's. A line
    that rich would write unchanged (:meth:`print`) is written without it: a command whose output goes to
    a file or a pipe then never imports rich (a fifth of a ``bearnav rrtstar`` process beside the planner).
    """

    def __init__(self, stderr: bool = False) -> None:
        self._stderr = stderr

    @functools.cached_property
    def console(self) -> "Console":
        from rich.console import Console

        return Console(stderr=self._stderr)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.console, name)

    def print(self, *objects: Any, **options: Any) -> None:
        """``Console.print``; a plain line without rich when rich would print exactly the text and a newline.

        That is one string, unhighlighted and soft-wrapped (never cut to a width), going to a stream that
        is not a terminal while nothing in the environment makes rich style it, holding no control
        character, no ``[`` (markup) and no ``:…:`` (emoji codes).
        """
        text = objects[0] if len(objects) == 1 else None
        stream = (
            self._plain_stream()
            if type(text) is str
            and options.get("highlight", True) is False
            and options.get("soft_wrap") is True
            and set(options) <= {"highlight", "soft_wrap", "markup"}
            and "[" not in text
            and _EMOJI_CODE.search(text) is None
            and _CONTROL.search(text) is None
            else None
        )
        if stream is None:
            self.console.print(*objects, **options)
            return
        try:
            stream.write(text + "\n")
            stream.flush()
        except BrokenPipeError:  # the reader left (``| head``): as rich's Console.on_broken_pipe does
            os.dup2(os.open(os.devnull, os.O_WRONLY), stream.fileno())
            raise SystemExit(1) from None

    def _plain_stream(self) -> Any:
        """The stream rich would write to, if it is not a terminal and nothing forces one; else None."""
        if any(name in os.environ for name in _RICH_ENVIRONMENT) or "IPython" in sys.modules:
            return None
        stream = sys.stderr if self._stderr else sys.stdout
        try:
            return None if stream is None or stream.isatty() else stream
        except (AttributeError, ValueError):  # no isatty, or a closed stream: rich's own rules apply
            return None


out = _Console()
err = _Console(stderr=True)


#: Suffixes ``bearnav plot -o`` writes (matplotlib's formats that need nothing more than pillow).
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".svgz", ".eps", ".ps", ".jpg", ".jpeg", ".tif", ".tiff", ".webp")


#: What -q does, for ``bearnav -q`` and every command's own ``-q``.
QUIET_HELP = "Quiet: errors and the final result only (no stage lines, progress bars or warnings)."


class Quiet:
    """Whether -q is on (``bearnav -q`` or the command's own): one flag for the whole process."""

    enabled = False


@functools.cache
def _warning_handler() -> type:
    """:class:`_WarningHandler`, defined on first use: logging is imported by the commands, not by ``--help``."""
    import logging

    class _WarningHandler(logging.Handler):
        """Print library warnings as one line each on stderr."""

        def emit(self, record: logging.LogRecord) -> None:
            if not Quiet.enabled or record.levelno >= logging.ERROR:
                from rich.markup import escape

                from bearnav_cli import pipeline

                # which stage said it, of which file: a plan's five stages warn about one map
                where = pipeline.ACTIVITY.stage or ""
                if pipeline.ACTIVITY.file and where:
                    where += f" of {pipeline.ACTIVITY.file}"
                where = f"{escape(where)}: " if where else ""
                err.print(
                    f"[yellow]warning:[/yellow] {where}{escape(record.getMessage())}", highlight=False, soft_wrap=True
                )

    return _WarningHandler


def setup_logging() -> None:
    """Send the ``bearnav_cli`` loggers' warnings to stderr, one line each (once per process)."""
    import logging

    handler = _warning_handler()
    logger = logging.getLogger("bearnav_cli")
    if not any(isinstance(h, handler) for h in logger.handlers):
        logger.addHandler(handler(level=logging.WARNING))
    logger.setLevel(logging.WARNING)
    logger.propagate = False


def plotting():
    """:mod:`bearnav_cli.plot` on matplotlib's file backend: the command line only writes files.

    The backend is chosen here, not in ``plot`` itself, so that importing ``plot`` from a notebook
    keeps the notebook's backend.
    """
    from bearnav_cli import plot

    plot.use_file_backend()
    return plot


def print_json(data: Any) -> None:
    """Print ``data`` as indented JSON on stdout, never wrapped: rich's print_json breaks long strings at the
    terminal's width, mid-token, and what a machine reads must parse whatever the terminal."""
    out.print(json.dumps(data, indent=2, ensure_ascii=False), markup=False, highlight=False, soft_wrap=True)


def report_line(report: "pipeline.StageReport") -> str:
    """A stage's one line: name, ran or fresh, seconds, the file and its summary."""
    state = "ran  " if report.ran else "fresh"
    timing = f"{report.elapsed_s:6.2f} s" if report.ran else "       -"
    return f"{report.stage:<10} {state} {timing}  {report.path}  {report.summary}"


def progress_factory(progress: "Progress") -> "Callable[[str], pipeline.Progress]":
    """``make(stage)``: a new task of ``progress`` and the ``progress(done, total)`` callback a stage takes."""

    def make(stage: str) -> "pipeline.Progress":
        task = progress.add_task(stage, total=None)

        def update(done: int, total: int) -> None:
            progress.update(task, completed=done, total=total)

        return update

    return make


@functools.cache
def count_column() -> type:
    """:class:`_CountColumn`, defined on first use: rich.progress is imported only by commands that show progress."""
    from rich.progress import ProgressColumn
    from rich.text import Text

    class _CountColumn(ProgressColumn):
        """``done/total``, or nothing while the stage has not said how much there is (never ``0/None``)."""

        def render(self, task: Any) -> Text:
            if task.total is None:
                return Text("")
            return Text(f"{int(task.completed)}/{int(task.total)}")

    return _CountColumn


class _NoProgress:
    """What :func:`progress_bar` gives when no bar is shown (quiet, or not a terminal): it takes the
    same calls and does nothing, without importing rich.progress (about 35 ms of a plan's start)."""

    def __enter__(self) -> "_NoProgress":
        return self

    def __exit__(self, *exc: Any) -> None:
        return None

    def add_task(self, *args: Any, **kwargs: Any) -> int:
        return 0

    def update(self, *args: Any, **kwargs: Any) -> None:
        return None


def progress_bar() -> "Progress | _NoProgress":
    """The stages' progress bars on stderr, transient; none when quiet or not on a terminal."""
    # a stream that is plainly not a terminal (:meth:`_Console.print`) needs no rich to say so
    if Quiet.enabled or err._plain_stream() is not None or not err.is_terminal:
        return _NoProgress()
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn("{task.description:<10}"),
        BarColumn(),
        count_column()(),
        TimeElapsedColumn(),
        console=err.console,
        transient=True,
    )
