"""Exception hierarchy of bearnav.

Every error the library raises on purpose derives from :class:`BearnavError`, so a
caller (the CLI) can turn it into a one-line message and an exit code. Errors
about input data also derive from :class:`ValueError`; :class:`InternalError`, a bug of
bearnav's own, does not.
"""

from __future__ import annotations

__all__ = [
    "ArtifactError",
    "BearnavError",
    "FolderBusyError",
    "InternalError",
    "InvalidMapError",
    "InvalidParamsError",
    "InvalidSweepError",
    "OutputPathError",
    "ResourceLimitError",
]


class BearnavError(Exception):
    """Base class of every error raised on purpose by bearnav."""


def _locate(message: str, file: str | None, field: str | None) -> str:
    where = ": ".join(part for part in (file, field) if part)
    return f"{where}: {message}" if where else message


class InvalidMapError(BearnavError, ValueError):
    """A map (YAML, occupancy grid or ``map.json``) is malformed or inconsistent.

    Parameters
    ----------
    message : str
        What is wrong, in a few words.
    file : str, optional
        The file the problem is in.
    field : str, optional
        The field path inside that file, e.g. ``obstacles[2].circle.radius``.
    """

    def __init__(self, message: str, *, file: str | None = None, field: str | None = None):
        self.file = file
        self.field = field
        self.reason = message
        super().__init__(_locate(message, file, field))


class InvalidParamsError(BearnavError, ValueError):
    """A stage parameter is out of range (``iterations < 1``, ``step <= 0`` ...)."""

    def __init__(self, message: str, *, field: str | None = None):
        self.field = field
        self.reason = message
        super().__init__(_locate(message, None, field))


class InvalidSweepError(BearnavError, ValueError):
    """A sweep file (``bearnav sweep``, docs/sweeps.md) is malformed: an unknown key, an empty list, a bad value.

    Parameters
    ----------
    message : str
        What is wrong, in a few words.
    file : str, optional
        The sweep file.
    field : str, optional
        Its key (``noise_deg``).
    """

    def __init__(self, message: str, *, file: str | None = None, field: str | None = None):
        self.file = file
        self.field = field
        self.reason = message
        super().__init__(_locate(message, file, field))


class ArtifactError(BearnavError, ValueError):
    """An artifact file is missing, unreadable, of the wrong type, corrupted, tampered with or meaningless.

    Parameters
    ----------
    message : str
        What is wrong, in a few words.
    file : str, optional
        The artifact file; :meth:`located` adds it when the raiser did not know it.
    field : str, optional
        The entry or key inside the artifact, e.g. ``cell_offsets`` or ``manifest.kind``.
    """

    def __init__(self, message: str, *, file: str | None = None, field: str | None = None):
        self.file = file
        self.field = field
        self.reason = message
        super().__init__(_locate(message, file, field))

    def located(self, file: str) -> ArtifactError:
        """The same error naming ``file`` (when it names none yet)."""
        return ArtifactError(self.reason, file=self.file or file, field=self.field)


class OutputPathError(BearnavError, ValueError):
    """An output path cannot be written: a folder where a file belongs, a file where a folder
    belongs, an unwritable folder, an unknown extension, the input itself.

    Parameters
    ----------
    message : str
        What is wrong.
    file : str
        The path.
    option : str, optional
        The option that gave it (``-o/--out``, ``--gif``).
    """

    def __init__(self, message: str, *, file: str, option: str | None = None):
        self.file = file
        self.option = option
        super().__init__(_locate(message, option, file))


class FolderBusyError(BearnavError):
    """Another bearnav run holds the lock of an output folder (one run per folder)."""

    def __init__(self, folder: str):
        self.file = folder
        super().__init__(_locate("another bearnav run is writing to this folder; wait until it ends", folder, None))


class ResourceLimitError(InvalidParamsError):
    """A request would need more memory (or steps) than the limits allow; the message says what fits."""


class InternalError(BearnavError):
    """A broken internal invariant: a bug in bearnav, not bad input.

    A stage made an artifact that fails its own type's checks, say. The CLI reports it apart from
    invalid input (exit 70, EX_SOFTWARE of sysexits.h, instead of 3), so that a bug never reads as
    the user's mistake.

    Parameters
    ----------
    message : str
        What broke.
    file : str, optional
        The file it concerns (an output that was not written, say).
    """

    def __init__(self, message: str, *, file: str | None = None):
        self.file = file
        self.reason = message
        super().__init__(_locate(message, file, None))
