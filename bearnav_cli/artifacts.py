"""Reading and writing every artifact, with manifests and content hashes (DESIGN §3).

This is the only module that touches artifact files. Each file is self-describing:
npz files hold a ``manifest`` entry (0-d JSON string), ``map.json`` a top-level
``"manifest"`` object.

- **One loader**, :func:`load`: every way a read can fail (a missing or unreadable file, a
  folder, a damaged zip or deflate stream, a ``.npy`` where an ``.npz`` belongs, JSON that is
  not an object, a manifest without its fields, missing or extra entries, dtypes, shapes, the
  content hash) raises :class:`ArtifactError` naming the file and the problem; then the
  artifact's meaning is checked (``datatypes.INVARIANTS``), whatever its hash says.
- **Writes** are atomic (temp files in the same folder, then ``os.replace``, with SIGINT and
  SIGTERM held back while the files are renamed), checked against the same invariants first,
  and ``sim.npz`` + ``sim.json`` are committed together. Temp files are named
  ``.NAME.bearnav-PID-MARK-XXXX.tmp``: those of a run that died are removed by the next one.
- **Output folders**: :func:`check_output_file` and :func:`check_output_folder` refuse bad
  output paths before any work; :func:`output_folder` creates the folder and holds an
  exclusive ``fcntl.flock`` on it (one run per folder).
- **Never replace what bearnav did not write**: :func:`written_by` tells which command wrote a
  file or a bag (its manifest, the marker line of a ``tags`` map, the custom data of a bag);
  :func:`check_overwrite` refuses to replace anything else without ``--force``,
  :func:`check_plan_folder` a plan folder of another map, and :func:`check_distinct` two outputs
  of one run at the same path or one inside the other.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import hashlib
import io
import json
import os
import platform
import re
import signal
import sys
import threading
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

__all__ = [
    "ARTIFACT_FORMAT",
    "atomic_output",
    "atomic_write",
    "cache_key",
    "check_distinct",
    "check_output_file",
    "check_output_folder",
    "check_overwrite",
    "check_plan_folder",
    "content_hash",
    "copy_file",
    "embedded_map_text",
    "entries_of",
    "fresh",
    "Kind",
    "kind_of_schema",
    "KINDS",
    "load",
    "Loaded",
    "map_source_of",
    "make_manifest",
    "metrics_path",
    "output_files",
    "Origin",
    "output_folder",
    "params_dict",
    "read_manifest",
    "read_record",
    "remove_stale_temp_files",
    "RETIRED_SCHEMAS",
    "save",
    "sha256_text",
    "software_versions",
    "staging_folder",
    "TAGS_MARKER",
    "write_parquet",
    "write_record",
    "write_table",
    "written_by",
]

try:  # POSIX; elsewhere output folders are not locked
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

from bearnav_cli import __version__
from bearnav_cli.datatypes import (
    CELL_KEYS,
    PLAN_KEYS,
    SIMULATION_KEYS,
    TREE_KEYS,
    Cells,
    Map,
    Plan,
    Simulation,
    Tree,
    validate_artifact,
)
from bearnav_cli.errors import ArtifactError, FolderBusyError, OutputPathError
from bearnav_cli.runtime import invariants, plan_file
from bearnav_cli.runtime.plan_file import canonical_json, memory_budget
from bearnav_cli.runtime.schema import ENTRIES, SCHEMAS, STAGES, Entry


@dataclass(frozen=True)
class Kind:
    """One artifact type: its schema name, conventional file name, the stage that writes it and its entries.

    Attributes
    ----------
    name : str
        The kind (``"plan"``), as :data:`KINDS` and ``datatypes.INVARIANTS`` name it.
    schema : str
        The manifest's ``schema`` (``"bearnav.plan/2"``), from ``runtime.schema.SCHEMAS``.
    filename : str
        The conventional file name (``"plan.npz"``).
    entries : dict of str to Entry
        ``runtime.schema.ENTRIES[name]``: each data key's dtype, symbolic shape and meaning. The loader
        requires each key with its dtype kind (``"U"``: a 0-d JSON text) and number of dimensions;
        ``map.json``'s one entry is its document.
    stage : str
        The stage that writes it.
    """

    name: str
    schema: str
    filename: str
    entries: dict[str, Entry]
    stage: str = ""

    @property
    def suffix(self) -> str:
        return Path(self.filename).suffix


#: Every artifact kind: its file here; its schema name, entries and the stage that writes it come from
#: the one declaration, :mod:`bearnav_cli.runtime.schema`.
KINDS: dict[str, Kind] = {
    name: Kind(name, SCHEMAS[name], filename, ENTRIES[name], STAGES[name])
    for name, filename in (
        ("map", "map.json"),
        ("tree", "tree.npz"),
        ("simplified", "simplified.npz"),
        ("cells", "cells.npz"),
        ("plan", "plan.npz"),
        ("simulation", "sim.npz"),
    )
}


#: Schemas of earlier versions, with what a file that has one lacks (:func:`_rerun_hint` adds the command
#: that makes it again, with the file's own map or plan).
RETIRED_SCHEMAS = {
    "bearnav.cells/1": "cells without composable certificates",
    "bearnav.plan/1": "per-cell certificates only",
    "bearnav.cells/2": "one plan-wide exit inset",
    "bearnav.plan/2": "one plan-wide exit inset and δ* of millimetres",
    "bearnav.sim/1": "runs without their loop constants",
}

#: Part of every cache key: bumped when what an artifact holds changes for the same inputs (2: the
#: embedded map no longer carries the YAML's ``source``; 3: content hashes leave out the map's
#: ``params``), so older outputs rerun once.
ARTIFACT_FORMAT = 3


@dataclass(frozen=True)
class Loaded:
    """An artifact read from disk: the typed object, its manifest and where it came from.

    Attributes
    ----------
    artifact : Map, Tree, Cells, Plan or Simulation
        The typed, checked artifact (every check of :func:`load` passed).
    manifest : dict
        Its manifest (DESIGN §3.1), as stored: ``schema``, ``stage``, ``params``, ``input``,
        ``content_sha256``, ``key``, ...
    path : Path
        The file it was read from.
    """

    artifact: Any
    manifest: dict
    path: Path


# --------------------------------------------------------------------------- hashing


def sha256_text(text: str) -> str:
    """SHA-256 of ``text`` encoded as UTF-8, as 64 lowercase hex digits."""
    return hashlib.sha256(text.encode()).hexdigest()


def content_hash(entries: dict[str, Any], kind: str | None = None) -> str:
    """SHA-256 over data entries in sorted key order (name, dtype, shape and bytes of each).

    The one implementation is :func:`bearnav_cli.runtime.plan_file.content_hash`, which the robot's
    loader recomputes too. The map (``map.json``'s document, or the ``map`` entry every later
    artifact embeds) is hashed without ``source`` (the YAML's name and hash) and ``params`` (the
    map's per-stage parameters): editing a comment or ``params: simulate:`` in the YAML reruns the
    map stage, but an identical map does not invalidate the stages after it, and each stage's own
    parameters are part of its cache key (:func:`cache_key`). ``kind`` is not used: every kind
    hashes the same way.
    """
    return plan_file.content_hash(entries)


def cache_key(stage: str, stage_version: int, params: dict, input_hash: str) -> str:
    """The freshness key: SHA-256 of the canonical JSON of what determines the output.

    The key also covers :data:`ARTIFACT_FORMAT`, so a format change reruns every stage once.

    Parameters
    ----------
    stage : str
        The stage's name (``"rrtstar"``).
    stage_version : int
        The stage module's ``VERSION``, bumped when its algorithm changes.
    params : dict
        The stage's resolved parameters as plain JSON (:func:`params_dict`).
    input_hash : str
        The input artifact's content hash (its manifest's ``content_sha256``; for the map
        stage, ``MapSource.sha256``, the hash of every byte it read).

    Returns
    -------
    str
        64 lowercase hex digits, stored as the manifest's ``key``.
    """
    return sha256_text(
        canonical_json(
            {"stage": stage, "stage_version": stage_version, "params": params, "input": input_hash,
             "format": ARTIFACT_FORMAT}
        )
    )  # fmt: skip


def software_versions() -> dict[str, str]:
    """Versions of the packages that shape results (provenance, not part of the key)."""
    return dict(_installed_versions())


@functools.cache
def _installed_versions() -> tuple[tuple[str, str], ...]:
    # each metadata lookup scans site-packages (about 4 ms): a plan makes five manifests, and the
    # versions cannot change within one process
    from importlib import metadata  # 10 ms (email, csv ...): only when a manifest is made, never to load

    versions = {"bearnav": __version__, "python": platform.python_version()}
    for package in ("numpy", "shapely", "scipy", "highspy"):
        # a loaded module's own version is its distribution's (numpy, shapely, scipy say it)
        loaded = getattr(sys.modules.get(package), "__version__", None)
        try:
            versions[package] = loaded if isinstance(loaded, str) else metadata.version(package)
        except metadata.PackageNotFoundError:
            pass
    return tuple(versions.items())


def params_dict(params: Any) -> dict:
    """A frozen ``Params`` dataclass as a plain dict (all defaults filled)."""
    return asdict(params)


def make_manifest(
    kind: str,
    artifact: Any,
    *,
    stage: str,
    stage_version: int,
    params: dict,
    input_path: str | None,
    input_hash: str,
    summary: str,
    elapsed_s: float,
    stats: dict | None = None,
) -> dict:
    """Build the manifest of DESIGN §3.1 for ``artifact``, to be saved as ``kind``.

    Parameters
    ----------
    kind : str
        A key of :data:`KINDS` (``"plan"``): gives the manifest's ``schema``.
    artifact : Map, Tree, Cells, Plan or Simulation
        The output, whose entries give ``content_sha256`` (:func:`content_hash`).
    stage : str
        The stage that made it (``"synthesize"``).
    stage_version : int
        That stage's ``VERSION`` (part of the cache key).
    params : dict
        The stage's resolved parameters as plain JSON (:func:`params_dict`).
    input_path : str or None
        The input file as given (provenance only; None for an input not read from a file).
    input_hash : str
        The input's content hash, stored as ``input.content_sha256`` and part of the key.
    summary : str
        The one-line summary the CLI prints for the stage.
    elapsed_s : float
        Wall-clock time of the stage (s), rounded to µs.
    stats : dict, optional
        The stage's statistics (``manifest.stats``; a simulation's metrics); empty by default.

    Returns
    -------
    dict
        Every field of :data:`MANIFEST_FIELDS`, with ``software`` from :func:`software_versions`.
    """
    return {
        "schema": KINDS[kind].schema,
        "stage": stage,
        "stage_version": stage_version,
        "params": params,
        "input": {"path": input_path, "content_sha256": input_hash},
        "content_sha256": content_hash(entries_of(artifact), kind),
        "key": cache_key(stage, stage_version, params, input_hash),
        "software": software_versions(),
        "summary": summary,
        "elapsed_s": round(float(elapsed_s), 6),
        "stats": dict(stats or {}),
    }


# --------------------------------------------------------------------------- entries


#: Which Python type each artifact kind holds.
_TYPES: dict[str, type] = {
    "map": Map, "tree": Tree, "simplified": Tree, "cells": Cells, "plan": Plan, "simulation": Simulation,
}  # fmt: skip


def embedded_map_text(map_: Map) -> str:
    """The map as later artifacts embed it: ``map.json``'s JSON without its provenance ``source``.

    Leaving the YAML's name and hash out makes every later artifact depend on the map alone, so
    the same map gives the same content hashes whatever file (or cached run) it came from.
    """
    document = map_.to_json()
    document.pop("source", None)
    return canonical_json(document)


def entries_of(artifact: Any) -> dict[str, Any]:
    """The data entries of an artifact (what is hashed and stored besides the manifest)."""
    if isinstance(artifact, Map):
        return {"map": artifact.to_json_text()}
    if isinstance(artifact, (Tree, Cells, Plan, Simulation)):
        return {"map": embedded_map_text(artifact.map), **artifact.arrays()}
    raise TypeError(f"not an artifact: {type(artifact).__name__}")


def _parse_map(text: str) -> Map:
    try:
        document = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ArtifactError(f"not valid JSON ({exc})", field="map") from exc
    if not isinstance(document, dict):
        raise ArtifactError(f"expected a JSON object, got {type(document).__name__}", field="map")
    return Map.from_json(document)


def _from_entries(kind: str, entries: dict[str, Any], manifest: dict, check_map: bool = True) -> Any:
    """The typed artifact; the map is parsed and (when ``check_map``) checked first, so that an error
    about it names ``map.FIELD`` rather than an array built on it."""
    prefix = "" if kind == "map" else "map."
    try:
        map_ = _parse_map(entries["map"])
        if check_map:
            validate_artifact("map", map_)
    except ArtifactError as exc:
        field = exc.field if not prefix or exc.field in (None, "map") else prefix + exc.field
        raise ArtifactError(exc.reason, field=field or "map") from None
    if kind == "map":
        return map_
    stats = dict(manifest.get("stats", {}))
    if kind in ("tree", "simplified"):
        return Tree(map=map_, stats=stats, **{key: entries[key] for key in TREE_KEYS})
    if kind == "simulation":
        return Simulation(map=map_, stats=stats, **{key: entries[key] for key in SIMULATION_KEYS})
    cell_arrays = {key: entries[key] for key in CELL_KEYS}
    if kind == "cells":
        return Cells(map=map_, stats=stats, **cell_arrays)
    cells = Cells(map=map_, **cell_arrays)
    problem = invariants.landmarks_problem(entries["landmarks"], map_.landmarks)
    if problem is not None:
        raise ArtifactError(problem, field="landmarks")
    return Plan(cells=cells, stats=stats, **{key: entries[key] for key in PLAN_KEYS if key != "landmarks"})


# --------------------------------------------------------------------------- memory


# --------------------------------------------------------------------------- writing

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


def _make_parents(folder: Path) -> list[Path]:
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


def _remove_empty(folders: list[Path]) -> None:
    for path in reversed(folders):
        try:
            path.rmdir()
        except OSError:
            return


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


def _write_all(files: list[tuple[Path, Callable[[io.BufferedWriter], None]]],
               on_commit: Callable[[], None] | None = None) -> None:  # fmt: skip
    """Write several files atomically and together: every temp file first, then one commit."""
    written: list[tuple[Path, Path]] = []
    try:
        for path, write in files:
            _make_parents(path.parent)
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
    _write_all([(Path(path), write)])


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """A temp path (same folder, same suffix) for a writer that wants a file name (figures, GIFs).

    The file is renamed to ``path`` when the block ends normally and removed otherwise.
    """
    path = Path(path)
    _make_parents(path.parent)
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


def save(path: str | os.PathLike, artifact: Any, manifest: dict, on_commit: Callable[[], None] | None = None) -> Path:
    """Check ``artifact`` (its invariants) and write it with its ``manifest`` to ``path`` atomically.

    A simulation also writes ``sim.json`` (the metrics) next to ``sim.npz``; both are committed
    together. ``on_commit`` is called once every file is in place, before a held-back interrupt
    is delivered.

    Parameters
    ----------
    path : str or os.PathLike
        Where to write (``plan.npz``, ``map.json`` ...); its folder must exist.
    artifact : Map, Tree, Cells, Plan or Simulation
        What to write; it must fit the manifest's schema and pass :func:`validate_artifact`.
    manifest : dict
        Its manifest (:func:`make_manifest`), stored as the npz's ``manifest`` entry or the
        ``"manifest"`` object of ``map.json``.
    on_commit : callable, optional
        Called with no argument once every file is in place (``pipeline`` records that the
        output is written).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ArtifactError
        The manifest's schema does not fit the artifact, or the artifact breaks an invariant.
    """
    kind = kind_of_schema(manifest.get("schema", ""))
    if kind is None or not isinstance(artifact, _TYPES[kind]):
        raise ArtifactError(f"manifest schema {manifest.get('schema')!r} does not fit a {type(artifact).__name__}")
    path = Path(path)
    validate_artifact(kind, artifact)
    entries = entries_of(artifact)
    files: list[tuple[Path, Callable[[io.BufferedWriter], None]]] = []
    if kind == "map":
        document = dict(json.loads(entries["map"]), manifest=manifest)
        text = json.dumps(document, indent=1, sort_keys=True) + "\n"
        files.append((path, lambda handle: handle.write(text.encode())))
    else:
        arrays = {key: (np.array(value) if isinstance(value, str) else value) for key, value in entries.items()}
        arrays["manifest"] = np.array(canonical_json(manifest))
        files.append((path, lambda handle: np.savez_compressed(handle, **arrays)))
    if kind == "simulation":
        # sim.json next to sim.npz: the metrics, for people and scripts that do not read npz
        metrics = json.dumps({"manifest": manifest, "metrics": manifest.get("stats", {})}, indent=1, sort_keys=True)
        files.append((metrics_path(path), lambda handle: handle.write((metrics + "\n").encode())))
    _write_all(files, on_commit)
    return path


def metrics_path(path: str | os.PathLike) -> Path:
    """``sim.json`` for ``sim.npz``: the same name with ``.json``."""
    return Path(path).with_suffix(".json")


def output_files(kind: str, path: str | os.PathLike) -> list[Path]:
    """Every file an artifact of ``kind`` saved at ``path`` consists of (``sim.npz`` also has ``sim.json``)."""
    path = Path(path)
    return [path, metrics_path(path)] if kind == "simulation" else [path]


# --------------------------------------------------------------------------- output paths and locks


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


def check_output_file(path: str | os.PathLike, suffixes: tuple[str, ...], option: str | None = "-o/--out",
                      inputs: tuple[str | os.PathLike, ...] = ()) -> Path:  # fmt: skip
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


def check_output_folder(folder: str | os.PathLike, names: tuple[str, ...] = (),
                        option: str | None = "-o/--out") -> Path:  # fmt: skip
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


#: The first line of every map YAML ``bearnav tags`` writes (a YAML comment): how a later run tells
#: its own output from a map someone wrote by hand.
TAGS_MARKER = "# bearnav tags:"
#: The custom-data key every bag ``simulate --bag`` writes carries (``metadata.yaml``, or inside the MCAP file).
BAG_MARKER = "bearnav.map"
#: How much of the end of an MCAP file is searched for :data:`BAG_MARKER`: rosbags writes the
#: metadata record (uncompressed) after the data, at close.
_MCAP_TAIL = 1 << 20


@dataclass(frozen=True)
class Origin:
    """Which bearnav command wrote an output (:func:`written_by`).

    Attributes
    ----------
    command : str
        A stage (``"map"`` ... ``"synthesize"``, ``"simulate"``, also for ``sim.json``), ``"tags"``
        (a map YAML) or ``"bag"`` (a ROS 2 bag, file or folder).
    map_name : str or None
        The name of the map it was made from, where the file records it (map.json and the npz artifacts).
    """

    command: str
    map_name: str | None = None


def _npz_origin(path: Path) -> Origin | None:
    # only the manifest and map members are read: a plan's arrays stay on disk
    with np.load(path, allow_pickle=False) as npz:
        if "manifest" not in npz.files:
            return None
        manifest = json.loads(str(npz["manifest"]))
        document = json.loads(str(npz["map"])) if "map" in npz.files else {}
    if not isinstance(manifest, dict) or not isinstance(manifest.get("stage"), str):
        return None
    name = document.get("name") if isinstance(document, dict) else None
    return Origin(manifest["stage"], name if isinstance(name, str) else None)


def _json_origin(path: Path) -> Origin | None:
    document = json.loads(path.read_bytes().decode("utf-8"))
    manifest = document.get("manifest") if isinstance(document, dict) else None
    if not isinstance(manifest, dict) or not isinstance(manifest.get("stage"), str):
        return None
    name = document.get("name")  # map.json's; sim.json does not name its map
    return Origin(manifest["stage"], name if isinstance(name, str) and manifest["stage"] == "map" else None)


def _bag_folder_origin(path: Path) -> Origin | None:
    metadata = path / "metadata.yaml"
    if not metadata.is_file() or BAG_MARKER not in metadata.read_text(errors="replace"):
        return None
    # what bearnav writes there: metadata.yaml and the MCAP file; anything else is someone's
    if any(child.name != "metadata.yaml" and (child.suffix != ".mcap" or not child.is_file())
           for child in path.iterdir()):  # fmt: skip
        return None
    return Origin("bag")


def _mcap_origin(path: Path) -> Origin | None:
    with open(path, "rb") as handle:
        handle.seek(max(0, path.stat().st_size - _MCAP_TAIL))
        return Origin("bag") if BAG_MARKER.encode() in handle.read() else None


def written_by(path: str | os.PathLike) -> Origin | None:
    """Which bearnav command wrote ``path``, or None if bearnav did not (or it cannot tell).

    Told by content, never by name alone: an npz or JSON artifact by its manifest's ``stage``
    (``sim.json`` too), a map YAML by :data:`TAGS_MARKER` on its first line, a ROS 2 bag by
    :data:`BAG_MARKER` in its metadata (a bag folder must hold nothing else than ``metadata.yaml``
    and MCAP files). A file too damaged to show its manifest gives None.

    Parameters
    ----------
    path : str or os.PathLike
        An existing file or folder.

    Returns
    -------
    Origin or None
        The command (and the map's name where the file records it).
    """
    path = Path(path)
    try:
        if path.is_symlink():  # replacing a link replaces the link, not what it points to: never bearnav's
            return None
        if path.is_dir():
            return _bag_folder_origin(path)
        if not path.is_file():
            return None
        suffix = path.suffix.lower()
        if suffix in (".yaml", ".yml"):
            with open(path, "rb") as handle:
                first = handle.readline(4096).decode("utf-8", errors="replace")
            return Origin("tags") if first.startswith(TAGS_MARKER) else None
        if suffix == ".mcap":
            return _mcap_origin(path)
        with open(path, "rb") as handle:
            head = handle.read(4)
        if head in _ZIP_MAGIC:
            return _npz_origin(path)
        if suffix == ".json":
            return _json_origin(path)
    except Exception:  # noqa: BLE001 - a damaged or unreadable file is not known to be bearnav's
        return None
    return None


def check_overwrite(path: str | os.PathLike, command: str, *, force: bool = False,
                    option: str | None = "-o/--out") -> None:  # fmt: skip
    """Refuse to replace ``path`` unless it is missing, an output of ``command`` (:func:`written_by`), or ``force``.

    Parameters
    ----------
    path : str or os.PathLike
        An output the run will write (or replace).
    command : str
        The command about to write it, as :class:`Origin` names it (``"simulate"``, ``"tags"``).
    force : bool, default False
        Replace it whoever wrote it (the user's ``--force``).
    option : str or None, default "-o/--out"
        The option that gave ``path``, named in the error.

    Raises
    ------
    OutputPathError
        ``path`` exists and bearnav's ``command`` did not write it.
    """
    path = Path(path)
    if force or not os.path.lexists(path):
        return
    origin = written_by(path)
    if origin is None:
        raise OutputPathError("exists and was not written by bearnav; give another name, or --force to replace it",
                              file=str(path), option=option)  # fmt: skip
    if origin.command != command:
        raise OutputPathError(f"is an output of bearnav {origin.command}, not {command}; give another name, or "
                              "--force to replace it", file=str(path), option=option)  # fmt: skip


def check_plan_folder(folder: str | os.PathLike, names: tuple[str, ...], map_name: str, *, force: bool = False,
                      option: str | None = "-o/--out") -> None:  # fmt: skip
    """Refuse a plan folder that holds the artifacts of another map (a plan folder belongs to one map).

    The same map planned again (other parameters, an edited YAML, another file with the same
    ``name:``) is the normal case and passes; so does a folder without artifacts.

    Parameters
    ----------
    folder : str or os.PathLike
        The plan folder.
    names : tuple of str
        The artifact files of a plan (``map.json``, ``tree.npz`` ...), which record their map's name.
    map_name : str
        The name of the map about to be planned there.
    force : bool, default False
        Plan there anyway (its artifacts are replaced).
    option : str or None, default "-o/--out"
        The option that gave ``folder``, named in the error.

    Raises
    ------
    OutputPathError
        The folder holds another map's artifacts, naming the folder and that map.
    """
    if force:
        return
    for name in names:
        origin = written_by(Path(folder) / name) if os.path.lexists(Path(folder) / name) else None
        if origin is not None and origin.map_name is not None and origin.map_name != map_name:
            raise OutputPathError(f"holds the plan of the map {origin.map_name!r} ({name}), not of {map_name!r}; "
                                  "give another folder, or --force to replace it", file=str(folder),
                                  option=option)  # fmt: skip


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
                raise OutputPathError(f"is also the output of {other}; give each output its own path",
                                      file=str(given), option=option)  # fmt: skip
            if other_real in real.parents or real in other_real.parents:
                outer, inner = (other_given, str(given)) if other_real in real.parents else (str(given), other_given)
                raise OutputPathError(f"{inner} would lie inside {outer}; give each output its own path",
                                      file=str(given), option=option)  # fmt: skip
        seen.append((option, real, str(given)))


#: Folders this process holds the lock of: real path -> [fd, depth] (the lock is re-entrant per process).
_HELD: dict[str, list[int]] = {}


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


@contextlib.contextmanager
def output_folder(folder: str | os.PathLike) -> Iterator[Path]:
    """Create ``folder`` if needed and hold its lock while the block runs (one bearnav run per folder).

    The lock is ``fcntl.flock`` on the folder itself (no lock file is left behind; the kernel drops
    it when the process dies, even by SIGKILL). A second run finds it taken and raises
    :class:`FolderBusyError` at once. Stale temp files of dead runs are removed on entry. If the
    block fails, folders this call created are removed again when they are still empty.
    """
    folder = Path(folder)
    created = _make_parents(folder)
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


# --------------------------------------------------------------------------- reading

_NPY_MAGIC = b"\x93NUMPY"
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")

#: Every byte of an input file, or one clear error naming it (one reader for the robot and the CLI).
read_input = plan_file.read_input


def _read_file(path: Path) -> bytes:
    return read_input(path, ArtifactError)


def _parse_json(path: Path, data: bytes) -> tuple[dict, dict[str, Any]]:
    try:
        document = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ArtifactError(f"not valid JSON ({exc})", file=str(path)) from None
    if not isinstance(document, dict):
        raise ArtifactError(f"expected a JSON object at the top level, got {type(document).__name__}", file=str(path))
    manifest = document.pop("manifest", None)
    if not isinstance(manifest, dict):
        raise ArtifactError("no manifest object (not a bearnav artifact)", file=str(path), field="manifest")
    if manifest.get("schema") == KINDS["simulation"].schema:
        raise ArtifactError("holds a simulation's metrics; give its sim.npz", file=str(path))
    return manifest, {"map": canonical_json(document)}


def _parse_npz(path: Path, data: bytes) -> tuple[dict, dict[str, Any]]:
    # the robot's reader (runtime.plan_file), within this process's budget (a test lowers it)
    return plan_file.parse_npz(data, str(path), memory_budget())


def _read_raw(path: Path) -> tuple[dict, dict[str, Any]]:
    """Manifest and data entries of any artifact file (npz or JSON, told apart by content)."""
    data = _read_file(path)
    if data.startswith(_NPY_MAGIC) or data.startswith(_ZIP_MAGIC) or path.suffix.lower() == ".npz":
        return _parse_npz(path, data)
    return _parse_json(path, data)


def kind_of_schema(schema: Any) -> str | None:
    """The kind (``"plan"``) whose current schema name is ``schema`` (``"bearnav.plan/2"``), or None.

    A retired schema (:data:`RETIRED_SCHEMAS`) or any other value gives None.
    """
    for kind in KINDS.values():
        if kind.schema == schema:
            return kind.name
    return None


def _rerun_hint(schema: str, path: Path, manifest: dict) -> str:
    """The command that writes a retired artifact again in the current schema, naming its real input.

    A simulation is re-run from the plan its manifest records; cells and plans are re-planned
    from the map YAML they came from (:func:`map_source_of`), else from the ``map.json`` beside them.
    """
    import shlex

    kind = next((k for k in KINDS.values() if schema.startswith(k.schema.rpartition("/")[0] + "/")), None)
    current = f" to get {kind.schema}" if kind is not None else ""
    if kind is not None and kind.name == "simulation":
        source = (manifest.get("input") or {}).get("path") if isinstance(manifest.get("input"), dict) else None
        if isinstance(source, str):
            plan = os.path.normpath(path.parent / source)
            return f"re-run `bearnav simulate {shlex.quote(plan)} --force`{current}"
        return f"re-run `bearnav simulate` on the plan it was made from, with --force{current}"
    origin = map_source_of(path) or (path.parent / "map.json" if (path.parent / "map.json").is_file() else None)
    if origin is not None:
        return f"re-run `bearnav plan {shlex.quote(str(origin))} --force`{current}"
    return f"re-run `bearnav plan` on the map it was made from, with --force{current}"


def _check_manifest(manifest: dict, path: Path, expect: tuple[str, ...] | None) -> str:
    """The kind of the artifact, after checking the manifest's fields; raises ArtifactError."""
    schema = manifest.get("schema")
    kind = kind_of_schema(schema)
    if kind is None:
        if schema in RETIRED_SCHEMAS:
            raise ArtifactError(f"is a {schema} artifact, which this version no longer reads "
                                f"({RETIRED_SCHEMAS[schema]}; {_rerun_hint(schema, path, manifest)})", file=str(path),
                                field="manifest.schema")  # fmt: skip
        raise ArtifactError(f"unknown schema {schema!r}", file=str(path), field="manifest.schema")
    if expect and kind not in expect:
        names = " or ".join(KINDS[w].schema for w in expect)
        raise ArtifactError(f"is a {schema} artifact, expected {names}", file=str(path))
    plan_file.check_manifest_fields(manifest, str(path), KINDS[kind].stage)
    return kind


def read_manifest(path: str | os.PathLike) -> dict:
    """The checked manifest of any artifact file (for freshness checks and tests)."""
    path = Path(path)
    manifest, _ = _read_raw(path)
    _check_manifest(manifest, path, None)
    return manifest


def _manifest_of(path: Path) -> dict | None:
    """The manifest of an artifact file, unchecked, reading no other member of an npz; None if it has none."""
    try:
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as npz:
                manifest = json.loads(str(npz["manifest"])) if "manifest" in npz.files else None
        else:
            manifest = json.loads(path.read_bytes().decode("utf-8")).get("manifest")
    except Exception:  # noqa: BLE001 - a file that does not show its manifest names no source
        return None
    return manifest if isinstance(manifest, dict) else None


def map_source_of(path: str | os.PathLike) -> Path | None:
    """The map YAML an artifact was planned from, following the manifests' inputs; None if there is none.

    Each manifest records its input relative to its own folder (plan.npz ← cells.npz ← ... ←
    map.json ← the YAML); the chain ends at the map stage's input. The answer is a path as the
    caller can use it (relative when the artifact's path is), and only a YAML file that exists:
    a plan made from a map.json whose YAML moved, or from options, names none.

    Parameters
    ----------
    path : str or os.PathLike
        Any artifact of a plan (``plan.npz``, ``cells.npz``, ``map.json``, ...).

    Returns
    -------
    Path or None
    """
    path = Path(path)
    for _ in range(len(KINDS) + 1):  # one step per stage: a chain that loops ends here
        manifest = _manifest_of(path)
        source = (manifest or {}).get("input") or {}
        if not isinstance(source, dict) or not isinstance(source.get("path"), str):
            return None
        path = Path(os.path.normpath(path.parent / source["path"]))
        if manifest.get("stage") == "map":
            return path if path.suffix.lower() in (".yaml", ".yml") and path.is_file() else None
    return None


#: SHA-256 of the map texts whose invariants this process has checked (a plan reads one map five times).
_CHECKED_MAPS: set[str] = set()


def load(path: str | os.PathLike, expect: str | tuple[str, ...] | None = None) -> Loaded:
    """Load an artifact and check its form and its meaning.

    Parameters
    ----------
    path : path-like
        The artifact file.
    expect : str or tuple of str, optional
        Acceptable kinds (``"map"``, ``"tree"``, ``"simplified"`` ...).

    Raises
    ------
    ArtifactError
        Naming the file (and the field) and the problem: unreadable, damaged, wrong type,
        manifest fields, missing or unexpected entry, shape or dtype, content hash mismatch
        (corruption or tampering), or an invariant of ``datatypes.INVARIANTS`` that does not hold.
    """
    path = Path(path)
    manifest, entries = _read_raw(path)
    wanted = (expect,) if isinstance(expect, str) else expect
    kind = _check_manifest(manifest, path, wanted)
    plan_file.check_entries(kind, entries, str(path))
    if kind == "plan":  # the robot's loader checks these shapes before its hash: so does this one
        problem = plan_file.shape_problem(kind, entries)
        if problem is not None:
            raise ArtifactError(problem[1], file=str(path), field=problem[0])
    if content_hash(entries, kind) != manifest["content_sha256"]:
        raise ArtifactError("content hash mismatch (file corrupted or edited)", file=str(path))
    if kind == "simulation":
        _check_companion(path, manifest)
    map_digest = sha256_text(entries["map"])
    try:
        artifact = _from_entries(kind, entries, manifest, check_map=map_digest not in _CHECKED_MAPS)
        _CHECKED_MAPS.add(map_digest)
        validate_artifact(kind, artifact, check_map=False)
    except ArtifactError as exc:
        raise exc.located(str(path)) from None
    except (ValueError, TypeError, KeyError, IndexError, AttributeError, OverflowError) as exc:
        raise ArtifactError(f"malformed ({type(exc).__name__}: {exc})", file=str(path)) from None
    return Loaded(artifact, manifest, path)


def _check_companion(path: Path, manifest: dict) -> None:
    """Refuse a ``sim.npz`` whose ``sim.json`` is another run's (a mixed pair).

    The two are renamed into place one after the other (:func:`_commit`), so a SIGKILL between the
    renames leaves the new ``sim.npz`` beside the old ``sim.json``; every reader refuses that pair
    (``fresh`` too, so the next ``simulate`` rewrites both). A missing ``sim.json``, or a JSON file
    that is not a bearnav simulation's metrics, is no pair and passes.
    """
    metrics = metrics_path(path)
    if not metrics.is_file():
        return
    try:
        companion = json.loads(_read_file(metrics).decode("utf-8"))
    except (ArtifactError, UnicodeDecodeError, json.JSONDecodeError, OSError, ValueError):
        return  # not a readable JSON file: not bearnav's metrics
    other = companion.get("manifest") if isinstance(companion, dict) else None
    if not isinstance(other, dict) or other.get("schema") != manifest["schema"]:
        return
    if other != json.loads(canonical_json(manifest)):
        raise ArtifactError(f"{metrics.name} beside it holds another run's metrics (a write was cut between the "
                            "two files): re-run the simulation with --force", file=str(path))  # fmt: skip


def fresh(path: str | os.PathLike, kind: str, key: str, input_hash: str) -> Loaded | None:
    """The artifact at ``path`` if it is fresh, else None.

    Fresh means: it loads (every check of :func:`load`), its manifest has ``key`` and names
    ``input_hash`` as its input's content hash, and, for a simulation, ``sim.json`` is there with
    the same manifest (the two are written, checked and called fresh together).

    Parameters
    ----------
    path : str or os.PathLike
        The existing output of the stage, if any.
    kind : str
        The kind it must be (``"plan"``), a key of :data:`KINDS`.
    key : str
        The cache key of the run about to happen (:func:`cache_key`).
    input_hash : str
        The current input's content hash.

    Returns
    -------
    Loaded or None
        The loaded artifact when it is fresh; None when it is missing, does not load, or was
        made with another key or input.
    """
    path = Path(path)
    if not path.is_file():
        return None
    try:
        loaded = load(path, kind)
    except ArtifactError:
        return None
    manifest = loaded.manifest
    if manifest["key"] != key or manifest["input"].get("content_sha256") != input_hash:
        return None
    if kind == "simulation":
        try:
            companion = json.loads(_read_file(metrics_path(path)).decode("utf-8"))
        except (ArtifactError, UnicodeDecodeError, json.JSONDecodeError):
            return None
        if not isinstance(companion, dict) or companion.get("manifest") != json.loads(canonical_json(manifest)):
            return None
    return loaded


# --------------------------------------------------------------------------- the sweep store (bearnav sweep)


def write_record(path: str | os.PathLike, document: dict) -> None:
    """Write one small JSON record of the sweep store (a job, a plan's provenance) atomically.

    NaN and infinities are written as ``null`` (JSON has neither); the folder is created.
    """

    def clean(value: Any) -> Any:
        if isinstance(value, float) and not np.isfinite(value):
            return None
        if isinstance(value, dict):
            return {str(k): clean(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [clean(v) for v in value]
        return value

    text = json.dumps(clean(document), indent=1, sort_keys=True, allow_nan=False) + "\n"
    atomic_write(path, lambda handle: handle.write(text.encode()))


def read_record(path: str | os.PathLike, schema: str) -> dict | None:
    """A record :func:`write_record` wrote with this ``schema``, or None (missing, unreadable, another schema)."""
    try:  # through the one reader of input files: a FIFO or a huge file in the store is refused, not read
        document = json.loads(_read_file(Path(path)).decode("utf-8"))
    except (ArtifactError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not isinstance(document, dict) or document.get("schema") != schema:
        return None
    return document


def write_table(path: str | os.PathLike, columns: tuple[str, ...], rows: list[dict]) -> Path:
    """Write ``rows`` as CSV (a header of ``columns``, None as an empty cell) atomically; returns ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write (replaced atomically).
    columns : tuple of str
        The column names, in order.
    rows : list of dict
        One dict per row, column name → value (a missing or None value is an empty cell).
    """
    import csv

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(columns), lineterminator="\n")
    writer.writeheader()
    writer.writerows([{c: ("" if row.get(c) is None else row.get(c)) for c in columns} for row in rows])
    data = buffer.getvalue().encode()
    atomic_write(path, lambda handle: handle.write(data))
    return Path(path)


def write_parquet(path: str | os.PathLike, columns: tuple[str, ...], rows: list[dict]) -> Path | None:
    """Write ``rows`` as Parquet atomically when pyarrow is installed (else nothing, None).

    Parameters
    ----------
    path : str or os.PathLike
        The file to write (replaced atomically).
    columns : tuple of str
        The column names, in order.
    rows : list of dict
        One dict per row, column name → value (a missing value is null).
    """
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return None
    table = pa.table({c: [row.get(c) for row in rows] for c in columns})
    with atomic_output(path) as tmp:
        pq.write_table(table, str(tmp))
    return Path(path)
