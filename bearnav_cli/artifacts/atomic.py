"""Files that appear whole or not at all: temp files in the same folder renamed into place, and their cleanup.

Temp files are named ``.NAME.bearnav-PID-MARK-XXXX.tmp``; SIGINT and SIGTERM are held back while
files that belong together are renamed, and the temp files of a run that died are removed by the
next one (:func:`remove_stale_temp_files`).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import os
import re
import signal
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Callable

from bearnav_cli.errors import ArtifactError, OutputPathError

__all__ = [
    "atomic_output",
    "atomic_write",
    "copy_file",
    "make_parents",
    "remove_stale_temp_files",
    "staging_folder",
    "write_all",
]


_TEMP = re.compile(r"^\.(?P<name>.+)\.bearnav-(?P<pid>\d+)-(?P<mark>[0-9a-f]{8})-[A-Za-z0-9_]+\.tmp(\.[A-Za-z0-9]+)?$")


def _temp_mark(pid: int) -> str:
    """Eight hex digits only bearnav puts after the PID in its temp names: a user's file that merely
    looks like one (``.notes.bearnav-4194303-x.tmp``) lacks them and is never cleaned up."""
    return hashlib.sha256(f"bearnav temp file of process {pid}".encode()).hexdigest()[:8]


def _temp_prefix(path: Path, pid: int | None = None) -> str:
    """The start of the name of a temp file or staging folder for ``path``, made by process ``pid``."""
    pid = os.getpid() if pid is None else pid
    return f".{path.name}.bearnav-{pid}-{_temp_mark(pid)}-"


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back (main thread only): they are delivered when the block ends."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    try:
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and its missing parents; return those created, outermost first."""
    missing = []
    probe = folder
    while not probe.exists():
        missing.append(probe)
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise OutputPathError("is a file, not a folder", file=str(probe))
    created = []
    for path in reversed(missing):
        try:
            path.mkdir()
        except FileExistsError:
            continue
        except OSError as exc:
            raise OutputPathError(f"cannot create folder ({exc.strerror or exc})", file=str(path)) from exc
        created.append(path)
    return created


def _temp_file(path: Path) -> tuple[int, Path]:
    """A new temp file next to ``path`` (same suffix at the end, so formats that go by it work)."""
    import tempfile  # writing only: loading an artifact does not need it (nor random, shutil ...)

    fd, tmp = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=f".tmp{path.suffix}", dir=path.parent)
    # mkstemp makes 0600; an artifact is as readable as any other file. fchmod on the descriptor:
    # a chmod by path could reach another file swapped in under that name in a shared folder
    os.fchmod(fd, 0o666 & ~_umask())
    return fd, Path(tmp)


@functools.cache
def _umask() -> int:
    """The process's umask, read without changing it where Linux shows it (``/proc/self/status``).

    Elsewhere it is read the only portable way, by setting and restoring it, once per process.
    """
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _write_temp(path: Path, write: Callable[[io.BufferedWriter], None]) -> Path:
    """Write ``path``'s content into a temp file next to it; the temp file is removed if ``write`` fails."""
    fd, tmp = _temp_file(path)
    try:
        with os.fdopen(fd, "wb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def _commit(pairs: list[tuple[Path, Path]], on_commit: Callable[[], None] | None = None) -> None:
    """Rename every temp file into place with SIGINT/SIGTERM held back, then call ``on_commit``.

    An interrupt that was already pending when the block began is re-raised after every file
    is in place (so files that belong together land together).
    """
    interrupted: BaseException | None = None
    with _signals_held():
        for tmp, final in pairs:
            done = False
            while not done:
                try:
                    if os.path.lexists(tmp):
                        os.replace(tmp, final)
                    done = True
                except KeyboardInterrupt as exc:
                    interrupted = exc
        if on_commit is not None:
            on_commit()
    if interrupted is not None:
        raise interrupted


def write_all(
    files: list[tuple[Path, Callable[[io.BufferedWriter], None]]], on_commit: Callable[[], None] | None = None
) -> None:
    """Write several files atomically and together: every temp file first, then one commit."""
    written: list[tuple[Path, Path]] = []
    try:
        for path, write in files:
            make_parents(path.parent)
            remove_stale_temp_files(path.parent)  # a killed run's (tags, plot): no lock's entry removed them
            written.append((_write_temp(path, write), path))
        _commit(written, on_commit)
    except BaseException:
        for tmp, _ in written:
            tmp.unlink(missing_ok=True)
        raise


def copy_file(source: str | os.PathLike, target: str | os.PathLike) -> bool:
    """Copy ``source`` to ``target`` atomically, unless they are the same file.

    Parameters
    ----------
    source, target : path-like
        The file to copy and where it goes (replaced if it exists).

    Returns
    -------
    bool
        Whether a copy was written (False: ``target`` is ``source``).
    """
    source, target = Path(source), Path(target)
    if target.exists() and os.path.samefile(source, target):
        return False
    data = source.read_bytes()
    atomic_write(target, lambda f: f.write(data))
    return True


def atomic_write(path: str | os.PathLike, write: Callable[[io.BufferedWriter], None]) -> None:
    """Write a file through ``write(fileobj)`` into a temp file, then rename it into place.

    An exception inside ``write`` removes the temp file and leaves any existing file untouched.
    """
    write_all([(Path(path), write)])


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """A temp path (same folder, same suffix) for a writer that wants a file name (figures, GIFs).

    The file is renamed to ``path`` when the block ends normally and removed otherwise.
    """
    path = Path(path)
    make_parents(path.parent)
    remove_stale_temp_files(path.parent)
    fd, tmp = _temp_file(path)
    os.close(fd)
    try:
        yield tmp
        if not tmp.exists() or tmp.stat().st_size == 0:
            raise ArtifactError("the writer produced no file", file=str(path))
        _commit([(tmp, path)])
    finally:
        tmp.unlink(missing_ok=True)


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temp_files(folder: str | os.PathLike) -> list[Path]:
    """Remove the temp files and staging folders a killed bearnav run left in ``folder``.

    Only names bearnav gives them (``.NAME.bearnav-PID-MARK-XXXX.tmp``, :func:`staging_folder`'s too,
    with ``MARK`` the PID's :func:`_temp_mark`), owned by this user, whose writer's PID is gone are
    removed: a live run's, another user's and a lookalike without the mark are left alone.

    Parameters
    ----------
    folder : str or os.PathLike
        The folder to clean; a missing or unreadable one is left as it is.

    Returns
    -------
    list of Path
        What was removed.
    """
    import shutil  # writing only, like tempfile

    removed = []
    try:
        names = os.listdir(folder)
    except OSError:
        return removed
    for name in names:
        match = _TEMP.match(name)
        if not match or match.group("mark") != _temp_mark(int(match.group("pid"))):
            continue
        path = Path(folder) / name
        try:  # only this user's: never another's file in a shared folder
            owner = path.lstat().st_uid
        except OSError:
            continue
        mine = not hasattr(os, "getuid") or owner == os.getuid()
        if mine and not _pid_alive(int(match.group("pid"))):
            try:
                if path.is_dir() and not path.is_symlink():
                    shutil.rmtree(path)
                else:
                    path.unlink()
                removed.append(path)
            except OSError:
                pass
    return removed


@contextlib.contextmanager
def staging_folder(path: str | os.PathLike) -> Iterator[Path]:
    """A temp folder next to ``path``, named like bearnav's temp files, removed when the block ends.

    For writers that build a folder (a ROS 2 bag) and rename the result into place. Stale temp
    files and staging folders of killed runs next to ``path`` are removed first
    (:func:`remove_stale_temp_files`): a SIGKILL skips the removal at the end of the block.
    """
    import shutil
    import tempfile

    path = Path(path)
    remove_stale_temp_files(path.parent)
    staging = Path(tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=".tmp", dir=path.parent))
    try:
        yield staging
    finally:
        shutil.rmtree(staging, ignore_errors=True)
