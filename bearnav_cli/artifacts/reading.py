"""The one loader: every way a read can fail is an :class:`ArtifactError` naming the file and the problem.

:func:`load` reads a file (npz or JSON, told apart by content), checks its manifest, entries,
dtypes, shapes and content hash, then the artifact's meaning (``datatypes.INVARIANTS``), whatever
its hash says; :func:`fresh` tells whether an existing output may be kept.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bearnav_cli.artifacts.manifest import KINDS, RETIRED_SCHEMAS, content_hash, kind_of_schema, sha256_text
from bearnav_cli.artifacts.writing import metrics_path
from bearnav_cli.datatypes import Map, validate_artifact
from bearnav_cli.errors import ArtifactError
from bearnav_cli.runtime import invariants, plan_file
from bearnav_cli.runtime.plan_file import canonical_json, memory_budget

__all__ = [
    "fresh",
    "load",
    "Loaded",
    "map_source_of",
    "read_file",
    "read_input",
    "read_manifest",
    "ZIP_MAGIC",
]


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


_NPY_MAGIC = b"\x93NUMPY"
ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")

#: Every byte of an input file, or one clear error naming it (one reader for the robot and the CLI).
read_input = plan_file.read_input


def read_file(path: Path) -> bytes:
    """Every byte of an artifact or record file (:data:`read_input`), or an :class:`ArtifactError` naming it."""
    return read_input(path, ArtifactError)


def _parse_json(path: Path, data: bytes) -> tuple[dict, dict[str, Any], dict]:
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
    # the text and what its content hash hashes, both made from the document parsed here (plan_file.map_text)
    return manifest, {"map": plan_file.map_text(document)}, document


def _parse_npz(path: Path, data: bytes) -> tuple[dict, dict[str, Any], None]:
    # the robot's reader (runtime.plan_file), within this process's budget (a test lowers it)
    return (*plan_file.parse_npz(data, str(path), memory_budget()), None)


def _read_raw(path: Path) -> tuple[dict, dict[str, Any], dict | None]:
    """Manifest and data entries of any artifact file (npz or JSON, told apart by content), and the map
    document of a JSON file (its ``map`` entry parsed, less the manifest) or None."""
    data = read_file(path)
    if data.startswith(_NPY_MAGIC) or data.startswith(ZIP_MAGIC) or path.suffix.lower() == ".npz":
        return _parse_npz(path, data)
    return _parse_json(path, data)


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
            raise ArtifactError(
                f"is a {schema} artifact, which this version no longer reads "
                f"({RETIRED_SCHEMAS[schema]}; {_rerun_hint(schema, path, manifest)})",
                file=str(path),
                field="manifest.schema",
            )
        raise ArtifactError(f"unknown schema {schema!r}", file=str(path), field="manifest.schema")
    if expect and kind not in expect:
        names = " or ".join(KINDS[w].schema for w in expect)
        raise ArtifactError(f"is a {schema} artifact, expected {names}", file=str(path))
    plan_file.check_manifest_fields(manifest, str(path), KINDS[kind].stage)
    return kind


def read_manifest(path: str | os.PathLike) -> dict:
    """The checked manifest of any artifact file (for freshness checks and tests)."""
    path = Path(path)
    manifest, _, _ = _read_raw(path)
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
    manifest, entries, document = _read_raw(path)
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
        artifact = _from_entries(kind, entries, manifest, map_digest not in _CHECKED_MAPS, document)
        _CHECKED_MAPS.add(map_digest)
        validate_artifact(kind, artifact, check_map=False)
    except ArtifactError as exc:
        raise exc.located(str(path)) from None
    except (ValueError, TypeError, KeyError, IndexError, AttributeError, OverflowError) as exc:
        raise ArtifactError(f"malformed ({type(exc).__name__}: {exc})", file=str(path)) from None
    return Loaded(artifact, manifest, path)


def _check_companion(path: Path, manifest: dict) -> None:
    """Refuse a ``sim.npz`` whose ``sim.json`` is another run's (a mixed pair).

    The two are renamed into place one after the other (``atomic._commit``), so a SIGKILL between the
    renames leaves the new ``sim.npz`` beside the old ``sim.json``; every reader refuses that pair
    (``fresh`` too, so the next ``simulate`` rewrites both). A missing ``sim.json``, or a JSON file
    that is not a bearnav simulation's metrics, is no pair and passes.
    """
    metrics = metrics_path(path)
    if not metrics.is_file():
        return
    try:
        companion = json.loads(read_file(metrics).decode("utf-8"))
    except (ArtifactError, UnicodeDecodeError, json.JSONDecodeError, OSError, ValueError):
        return  # not a readable JSON file: not bearnav's metrics
    other = companion.get("manifest") if isinstance(companion, dict) else None
    if not isinstance(other, dict) or other.get("schema") != manifest["schema"]:
        return
    if other != json.loads(canonical_json(manifest)):
        raise ArtifactError(
            f"{metrics.name} beside it holds another run's metrics (a write was cut between the "
            "two files): re-run the simulation with --force",
            file=str(path),
        )


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
            companion = json.loads(read_file(metrics_path(path)).decode("utf-8"))
        except (ArtifactError, UnicodeDecodeError, json.JSONDecodeError):
            return None
        if not isinstance(companion, dict) or companion.get("manifest") != json.loads(canonical_json(manifest)):
            return None
    return loaded


def _parse_map(text: str, document: dict | None = None) -> Map:
    """The map of a ``map`` entry; ``document`` is that text parsed already (``map.json``'s), when it was."""
    try:
        document = json.loads(text) if document is None else document
    except json.JSONDecodeError as exc:
        raise ArtifactError(f"not valid JSON ({exc})", field="map") from exc
    if not isinstance(document, dict):
        raise ArtifactError(f"expected a JSON object, got {type(document).__name__}", field="map")
    return Map.from_json(document)


def _from_entries(
    kind: str, entries: dict[str, Any], manifest: dict, check_map: bool = True, document: dict | None = None
) -> Any:
    """The typed artifact; the map is parsed (unless ``document`` is its ``map`` entry parsed) and (when
    ``check_map``) checked first, so that an error about it names ``map.FIELD`` rather than an array built on it."""
    prefix = "" if kind == "map" else "map."
    try:
        map_ = _parse_map(entries["map"], document)
        if check_map:
            validate_artifact("map", map_)
    except ArtifactError as exc:
        field = exc.field if not prefix or exc.field in (None, "map") else prefix + exc.field
        raise ArtifactError(exc.reason, field=field or "map") from None
    if kind == "map":
        return map_
    stats = dict(manifest.get("stats", {}))
    # each kind's type imported here, for its kind only (loading a tree imports neither cells nor simulation)
    if kind in ("tree", "simplified"):
        from bearnav_cli.datatypes.tree import TREE_KEYS, Tree

        return Tree(map=map_, stats=stats, **{key: entries[key] for key in TREE_KEYS})
    if kind == "simulation":
        from bearnav_cli.datatypes.simulation import SIMULATION_KEYS, Simulation

        return Simulation(map=map_, stats=stats, **{key: entries[key] for key in SIMULATION_KEYS})
    from bearnav_cli.datatypes.cells import CELL_KEYS, PLAN_KEYS, Cells, Plan

    cell_arrays = {key: entries[key] for key in CELL_KEYS}
    if kind == "cells":
        return Cells(map=map_, stats=stats, **cell_arrays)
    cells = Cells(map=map_, **cell_arrays)
    problem = invariants.landmarks_problem(entries["landmarks"], map_.landmarks)
    if problem is not None:
        raise ArtifactError(problem, field="landmarks")
    return Plan(cells=cells, stats=stats, **{key: entries[key] for key in PLAN_KEYS if key != "landmarks"})
