"""Exception hierarchy of bearnav.

Every error the library raises on purpose derives from :class:`BearnavError`, so a
caller (the CLI) can turn it into a one-line message and an exit code. Errors
about input data also derive from :class:`ValueError`.
"""

from __future__ import annotations


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
        super().__init__(_locate(message, None, field))


class ArtifactError(BearnavError, ValueError):
    """An artifact file is missing, of the wrong type, corrupted or tampered with."""

    def __init__(self, message: str, *, file: str | None = None, field: str | None = None):
        self.file = file
        self.field = field
        super().__init__(_locate(message, file, field))


class StaleInputError(BearnavError):
    """An artifact was built from an input whose content has changed since."""
