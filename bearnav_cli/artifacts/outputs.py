"""Output paths: refused before any work when they cannot be written, and one run per output folder (a lock).

:func:`check_output_file` and :func:`check_output_folder` refuse bad paths, :func:`check_distinct`
two outputs of one run at the same path or one inside the other, and :func:`output_folder`
creates a folder and holds an exclusive ``fcntl.flock`` on it while a run writes there.
"""

from __future__ import annotations

import contextlib
import errno
import os
from collections.abc import Iterator
from pathlib import Path

from bearnav_cli.artifacts.atomic import make_parents, remove_stale_temp_files
from bearnav_cli.errors import FolderBusyError, OutputPathError

__all__ = ["check_distinct", "check_output_file", "check_output_folder", "output_folder"]

try:  # POSIX; elsewhere output folders are not locked
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]


def _check_writable_folder(folder: Path, option: str | None) -> None:
    """``folder`` is a folder we may write in, or can be created under one."""
    probe = folder
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise OutputPathError("is a file, not a folder", file=str(probe), option=option)
    if not os.access(probe, os.W_OK | os.X_OK):
        raise OutputPathError("folder is not writable", file=str(probe), option=option)


def check_output_file(
    path: str | os.PathLike,
    suffixes: tuple[str, ...],
    option: str | None = "-o/--out",
    inputs: tuple[str | os.PathLike, ...] = (),
) -> Path:
    """Refuse an output path before any work: wrong extension, a folder, the input itself, an unwritable folder.

    Missing parent folders are fine (they are created when the file is written).

    Parameters
    ----------
    path : str or os.PathLike
        The output file the user asked for.
    suffixes : tuple of str
        Accepted extensions, lowercase with the dot (``(".npz",)``); the first is suggested
        when ``path`` is a folder.
    option : str or None, default "-o/--out"
        The CLI option that gave ``path``, named in the error (None: none).
    inputs : tuple of str or os.PathLike, default ()
        Input files ``path`` must not be (compared with :func:`os.path.samefile`).

    Returns
    -------
    Path
        ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    OutputPathError
        What is wrong with ``path``, naming it and ``option``.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputPathError(f"is a folder; give a file name ending in {suffixes[0]}", file=str(path), option=option)
    if path.suffix.lower() not in suffixes:
        shown = f"extension {path.suffix!r}" if path.suffix else "no extension"
        raise OutputPathError(f"{shown}: expected {', '.join(suffixes)}", file=str(path), option=option)
    if path.exists() and not path.is_file():
        raise OutputPathError("exists and is not a regular file", file=str(path), option=option)
    for source in inputs:
        source = Path(source)
        if source.exists() and path.exists() and os.path.samefile(source, path):
            raise OutputPathError("is the input file; write the output elsewhere", file=str(path), option=option)
    _check_writable_folder(path.parent, option)
    return path


def check_output_folder(
    folder: str | os.PathLike, names: tuple[str, ...] = (), option: str | None = "-o/--out"
) -> Path:
    """Refuse an output folder before any work: a file there, a folder where one of ``names`` goes, unwritable.

    Parameters
    ----------
    folder : str or os.PathLike
        The output folder the user asked for; it need not exist yet.
    names : tuple of str, default ()
        File names the run will write in it (``"plan.npz"``); none of them may be a folder.
    option : str or None, default "-o/--out"
        The CLI option that gave ``folder``, named in the error (None: none).

    Returns
    -------
    Path
        ``folder`` as a :class:`~pathlib.Path`.

    Raises
    ------
    OutputPathError
        What is wrong with ``folder``, naming it and ``option``.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputPathError("is a file, expected a folder", file=str(folder), option=option)
    for name in names:
        if (folder / name).is_dir():
            raise OutputPathError(f"is a folder where the file {name} belongs", file=str(folder / name), option=option)
    _check_writable_folder(folder, option)
    return folder


def check_distinct(outputs: dict[str, str | os.PathLike | None]) -> None:
    """Refuse two outputs of one run at the same path, or one inside the other (a bag folder around sim.npz).

    Parameters
    ----------
    outputs : dict of str to path-like or None
        Option (``"-o/--out"``, ``"--bag"``) to the output path it gives; None entries are skipped.

    Raises
    ------
    OutputPathError
        Naming the later option's path and the option it collides with.
    """
    seen: list[tuple[str, Path, str]] = []
    for option, given in outputs.items():
        if given is None:
            continue
        real = Path(os.path.realpath(given))
        for other, other_real, other_given in seen:
            if real == other_real:
                raise OutputPathError(
                    f"is also the output of {other}; give each output its own path", file=str(given), option=option
                )
            if other_real in real.parents or real in other_real.parents:
                outer, inner = (other_given, str(given)) if other_real in real.parents else (str(given), other_given)
                raise OutputPathError(
                    f"{inner} would lie inside {outer}; give each output its own path", file=str(given), option=option
                )
        seen.append((option, real, str(given)))


#: Folders this process holds the lock of: real path -> [fd, depth] (the lock is re-entrant per process).
_HELD: dict[str, list[int]] = {}


def _remove_empty(folders: list[Path]) -> None:
    for path in reversed(folders):
        try:
            path.rmdir()
        except OSError:
            return


@contextlib.contextmanager
def output_folder(folder: str | os.PathLike) -> Iterator[Path]:
    """Create ``folder`` if needed and hold its lock while the block runs (one bearnav run per folder).

    The lock is ``fcntl.flock`` on the folder itself (no lock file is left behind; the kernel drops
    it when the process dies, even by SIGKILL). A second run finds it taken and raises
    :class:`FolderBusyError` at once. Stale temp files of dead runs are removed on entry. If the
    block fails, folders this call created are removed again when they are still empty.
    """
    folder = Path(folder)
    created = make_parents(folder)
    key = os.path.realpath(folder)
    held = _HELD.get(key)
    if held is not None:
        held[1] += 1
        try:
            yield folder
        finally:
            held[1] -= 1
        return
    if fcntl is None:  # pragma: no cover - not POSIX: no lock
        remove_stale_temp_files(folder)
        yield folder
        return
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError as exc:
        _remove_empty(created)
        raise OutputPathError(f"cannot open the folder to lock it ({exc.strerror or exc})", file=str(folder)) from exc
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        os.close(fd)
        _remove_empty(created)
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            raise FolderBusyError(str(folder)) from None
        raise OutputPathError(f"cannot lock the folder ({exc.strerror or exc})", file=str(folder)) from exc
    _HELD[key] = [fd, 1]
    ok = False
    try:
        remove_stale_temp_files(folder)
        yield folder
        ok = True
    finally:
        del _HELD[key]
        try:
            fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            os.close(fd)
        if not ok:
            _remove_empty(created)
