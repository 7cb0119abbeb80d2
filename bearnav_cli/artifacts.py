"""Reading and writing every artifact, with manifests and content hashes (DESIGN §3).

This is the only module that touches artifact files. Each file is self-describing:
npz files hold a ``manifest`` entry (0-d JSON string), ``map.json`` a top-level
``"manifest"`` object. Writes are atomic (temp file + ``os.replace``); loads check
the schema, the keys, shapes and dtypes and the content hash.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import platform
import tempfile
import zipfile
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path
from typing import Any, Callable

import numpy as np

from bearnav_cli import __version__
from bearnav_cli.datatypes import CELL_KEYS, PLAN_KEYS, SIMULATION_KEYS, Cells, Map, Plan, Simulation, Tree
from bearnav_cli.errors import ArtifactError, BearnavError


@dataclass(frozen=True)
class Kind:
    """One artifact type: its schema name, conventional file name and required entries.

    ``entries`` maps each data key to ``(dtype kind, ndim)``; ``"U"`` is a 0-d JSON text.
    """

    name: str
    schema: str
    filename: str
    entries: dict[str, tuple[str, int]]


_TREE_ENTRIES = {
    "map": ("U", 0),
    "nodes": ("f", 2),
    "parent": ("i", 1),
    "cost": ("f", 1),
    "collision_samples": ("f", 2),
}

_CELL_ENTRIES = {
    "map": ("U", 0),
    "nodes": ("f", 2),
    "parent": ("i", 1),
    "collision_samples": ("f", 2),
    "cell_node": ("i", 1),
    "cell_A": ("f", 2),
    "cell_b": ("f", 1),
    "cell_row_offsets": ("i", 1),
    "cell_vertices": ("f", 2),
    "cell_vertex_offsets": ("i", 1),
    "exit_point": ("f", 2),
    "exit_dir": ("f", 2),
    "cbf_A": ("f", 2),
    "cbf_b": ("f", 1),
    "cbf_offsets": ("i", 1),
    "cell_landmarks": ("b", 2),
    "fixed_landmark": ("i", 1),
    "s_min": ("f", 1),
    "s_max": ("f", 1),
    "cell_flags": ("i", 1),
    "certificate": ("U", 0),
    "cell_exit_row": ("i", 1),
    "cell_rank": ("f", 1),
    "exit_inset": ("f", 0),
    "node_added": ("b", 1),
    "free_coverage": ("f", 0),
}

_PLAN_ENTRIES = {
    **_CELL_ENTRIES,
    "landmarks": ("f", 2),
    "gain": ("f", 3),
    "c_h": ("f", 1),
    "c_v": ("f", 1),
    "u_max": ("f", 1),
    "margin_h": ("f", 1),
    "margin_v": ("f", 1),
    "status": ("i", 1),
    "goal_tolerance": ("f", 0),
    "tolerance": ("f", 1),
    "plan_tolerance": ("f", 0),
}

KINDS: dict[str, Kind] = {
    "map": Kind("map", "bearnav.map/1", "map.json", {}),
    "tree": Kind("tree", "bearnav.tree/1", "tree.npz", _TREE_ENTRIES),
    "simplified": Kind("simplified", "bearnav.simplified/1", "simplified.npz", _TREE_ENTRIES),
    "cells": Kind("cells", "bearnav.cells/2", "cells.npz", _CELL_ENTRIES),
    "plan": Kind("plan", "bearnav.plan/2", "plan.npz", _PLAN_ENTRIES),
    "simulation": Kind("simulation", "bearnav.sim/1", "sim.npz", {"map": ("U", 0), **SIMULATION_KEYS}),
}


#: Schemas of earlier versions, with what to do about a file that has one.
RETIRED_SCHEMAS = {
    "bearnav.cells/1": "cells without composable certificates; re-run `bearnav plan MAP.yaml --force`",
    "bearnav.plan/1": "per-cell certificates only; re-run `bearnav plan MAP.yaml --force` to get bearnav.plan/2",
}


@dataclass(frozen=True)
class Loaded:
    """An artifact read from disk: the typed object, its manifest and where it came from."""

    artifact: Any
    manifest: dict
    path: Path


# --------------------------------------------------------------------------- hashing


def canonical_json(value: Any) -> str:
    """Deterministic JSON text: sorted keys, no spaces, plain floats."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=True)


def sha256_text(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def content_hash(entries: dict[str, Any], kind: str | None = None) -> str:
    """SHA-256 over data entries in sorted key order (name, dtype, shape and bytes of each).

    For ``map.json`` the ``source`` field (file name and hash of the YAML) is provenance and
    stays out of the hash: editing a comment in the YAML reruns the map stage, but an
    identical map does not invalidate the stages after it.
    """
    if kind == "map":
        document = json.loads(entries["map"])
        document.pop("source", None)
        entries = {"map": canonical_json(document)}
    digest = hashlib.sha256()
    for key in sorted(entries):
        value = entries[key]
        if isinstance(value, str):
            digest.update(f"{key}|str|".encode())
            digest.update(value.encode())
        else:
            array = np.ascontiguousarray(value)
            digest.update(f"{key}|{array.dtype.str}|{array.shape}|".encode())
            digest.update(array.tobytes())
    return digest.hexdigest()


def cache_key(stage: str, stage_version: int, params: dict, input_hash: str) -> str:
    """The freshness key: SHA-256 of the canonical JSON of what determines the output."""
    return sha256_text(
        canonical_json({"stage": stage, "stage_version": stage_version, "params": params, "input": input_hash})
    )


def software_versions() -> dict[str, str]:
    """Versions of the packages that shape results (provenance, not part of the key)."""
    versions = {"bearnav": __version__, "python": platform.python_version()}
    for package in ("numpy", "shapely", "scipy", "highspy"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            pass
    return versions


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
    """Build the manifest of DESIGN §3.1 for ``artifact``, to be saved as ``kind``."""
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
}


def entries_of(artifact: Any) -> dict[str, Any]:
    """The data entries of an artifact (what is hashed and stored besides the manifest)."""
    if isinstance(artifact, Map):
        return {"map": artifact.to_json_text()}
    if isinstance(artifact, (Tree, Cells, Plan, Simulation)):
        return {"map": artifact.map.to_json_text(), **artifact.arrays()}
    raise TypeError(f"not an artifact: {type(artifact).__name__}")


def _from_entries(kind: str, entries: dict[str, Any], manifest: dict) -> Any:
    map_ = Map.from_json(json.loads(entries["map"]))
    if kind == "map":
        return map_
    stats = dict(manifest.get("stats", {}))
    if kind in ("tree", "simplified"):
        return Tree(map=map_, stats=stats, **{key: entries[key] for key in ("nodes", "parent", "cost",
                                                                           "collision_samples")})
    if kind == "simulation":
        values = {key: entries[key] for key in SIMULATION_KEYS}
        values["dt"] = float(values["dt"])
        return Simulation(map=map_, stats=stats, **values)
    cell_arrays = {key: entries[key] for key in CELL_KEYS}
    if kind == "cells":
        return Cells(map=map_, stats=stats, **cell_arrays)
    cells = Cells(map=map_, **cell_arrays)
    if not np.array_equal(entries["landmarks"], map_.landmarks):
        raise ArtifactError("landmarks differ from the embedded map's", field="landmarks")
    return Plan(cells=cells, stats=stats, **{key: entries[key] for key in PLAN_KEYS if key != "landmarks"})


# --------------------------------------------------------------------------- writing


def atomic_write(path: str | os.PathLike, write: Callable[[io.BufferedWriter], None]) -> None:
    """Write a file through ``write(fileobj)`` into a temp file, then rename it into place.

    An exception inside ``write`` removes the temp file and leaves any existing file untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; an artifact is as readable as any other file
    try:
        with os.fdopen(fd, "wb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save(path: str | os.PathLike, artifact: Any, manifest: dict) -> Path:
    """Write ``artifact`` with its ``manifest`` to ``path`` atomically."""
    kind = kind_of_schema(manifest.get("schema", ""))
    if kind is None or not isinstance(artifact, _TYPES[kind]):
        raise ArtifactError(f"manifest schema {manifest.get('schema')!r} does not fit a {type(artifact).__name__}")
    entries = entries_of(artifact)
    path = Path(path)
    if kind == "map":
        document = dict(json.loads(entries["map"]), manifest=manifest)
        text = json.dumps(document, indent=1, sort_keys=True) + "\n"
        atomic_write(path, lambda handle: handle.write(text.encode()))
    else:
        arrays = {key: (np.array(value) if isinstance(value, str) else value) for key, value in entries.items()}
        arrays["manifest"] = np.array(canonical_json(manifest))
        atomic_write(path, lambda handle: np.savez_compressed(handle, **arrays))
    if kind == "simulation":
        # sim.json next to sim.npz: the metrics, for people and scripts that do not read npz
        text = json.dumps({"manifest": manifest, "metrics": manifest.get("stats", {})}, indent=1, sort_keys=True)
        atomic_write(metrics_path(path), lambda handle: handle.write((text + "\n").encode()))
    return path


def metrics_path(path: str | os.PathLike) -> Path:
    """``sim.json`` for ``sim.npz``: the same name with ``.json``."""
    return Path(path).with_suffix(".json")


# --------------------------------------------------------------------------- reading


def _read_raw(path: Path) -> tuple[dict, dict[str, Any]]:
    """Manifest and data entries of any artifact file, without checks beyond parsing."""
    if not path.is_file():
        raise ArtifactError("no such file", file=str(path))
    if path.suffix == ".json":
        try:
            document = json.loads(path.read_text())
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ArtifactError(f"not valid JSON ({exc})", file=str(path)) from exc
        if not isinstance(document, dict) or not isinstance(document.get("manifest"), dict):
            raise ArtifactError("no manifest (not a bearnav artifact)", file=str(path))
        manifest = document.pop("manifest")
        return manifest, {"map": canonical_json(document)}
    try:
        with np.load(path, allow_pickle=False) as npz:
            data = {key: npz[key] for key in npz.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ArtifactError(f"unreadable or corrupted npz ({exc})", file=str(path)) from exc
    if "manifest" not in data or data["manifest"].dtype.kind != "U" or data["manifest"].ndim != 0:
        raise ArtifactError("no manifest (not a bearnav artifact)", file=str(path))
    try:
        manifest = json.loads(str(data.pop("manifest")))
    except json.JSONDecodeError as exc:
        raise ArtifactError(f"manifest is not valid JSON ({exc})", file=str(path)) from exc
    entries = {
        key: (str(value) if value.dtype.kind == "U" and value.ndim == 0 else value) for key, value in data.items()
    }
    return manifest, entries


def read_manifest(path: str | os.PathLike) -> dict:
    """The manifest of any artifact file (for ``inspect`` and freshness checks)."""
    return _read_raw(Path(path))[0]


def kind_of_schema(schema: str) -> str | None:
    for kind in KINDS.values():
        if kind.schema == schema:
            return kind.name
    return None


def load(path: str | os.PathLike, expect: str | tuple[str, ...] | None = None) -> Loaded:
    """Load and check an artifact.

    Parameters
    ----------
    path : path-like
        The artifact file.
    expect : str or tuple of str, optional
        Acceptable kinds (``"map"``, ``"tree"``, ``"simplified"`` ...).

    Raises
    ------
    ArtifactError
        Naming the file and the problem: wrong type, missing entry, wrong shape or
        dtype, content hash mismatch (corruption or tampering).
    """
    path = Path(path)
    manifest, entries = _read_raw(path)
    schema = manifest.get("schema")
    kind = kind_of_schema(schema) if isinstance(schema, str) else None
    if kind is None:
        if schema in RETIRED_SCHEMAS:
            raise ArtifactError(f"is a {schema} artifact, which this version no longer reads "
                                f"({RETIRED_SCHEMAS[schema]})", file=str(path), field="manifest.schema")  # fmt: skip
        raise ArtifactError(f"unknown schema {schema!r}", file=str(path), field="manifest.schema")
    wanted = (expect,) if isinstance(expect, str) else expect
    if wanted and kind not in wanted:
        names = " or ".join(KINDS[w].schema for w in wanted)
        raise ArtifactError(f"is a {schema} artifact, expected {names}", file=str(path))
    for key, (dtype_kind, ndim) in KINDS[kind].entries.items():
        if key not in entries:
            raise ArtifactError("missing entry", file=str(path), field=key)
        value = entries[key]
        if dtype_kind == "U":
            if not isinstance(value, str):
                raise ArtifactError("expected a JSON text", file=str(path), field=key)
        elif value.dtype.kind != dtype_kind or value.ndim != ndim:
            raise ArtifactError(
                f"expected {ndim}-d {dtype_kind} array, got {value.ndim}-d {value.dtype}", file=str(path), field=key
            )
    if content_hash(entries, kind) != manifest.get("content_sha256"):
        raise ArtifactError("content hash mismatch (file corrupted or edited)", file=str(path))
    try:
        artifact = _from_entries(kind, entries, manifest)
    except BearnavError as exc:
        raise ArtifactError(str(exc), file=str(path)) from exc
    return Loaded(artifact, manifest, path)


def is_fresh(path: str | os.PathLike, key: str) -> bool:
    """Whether the artifact at ``path`` was made with ``key`` and its content is intact."""
    path = Path(path)
    if not path.is_file():
        return False
    try:
        manifest, entries = _read_raw(path)
    except ArtifactError:
        return False
    kind = kind_of_schema(str(manifest.get("schema")))
    return manifest.get("key") == key and content_hash(entries, kind) == manifest.get("content_sha256")
