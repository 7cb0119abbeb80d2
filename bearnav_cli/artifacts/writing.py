"""Saving an artifact: checked against its invariants, written with its manifest, ``sim.json`` beside ``sim.npz``."""

from __future__ import annotations

import io
import json
import os
import zipfile
from pathlib import Path
from typing import Any, Callable

import numpy as np

from bearnav_cli import datatypes
from bearnav_cli.artifacts.atomic import write_all
from bearnav_cli.artifacts.manifest import entries_of, kind_of_schema
from bearnav_cli.datatypes import validate_artifact
from bearnav_cli.errors import ArtifactError
from bearnav_cli.runtime.plan_file import canonical_json

__all__ = ["metrics_path", "output_files", "save"]


#: The deflate level of an npz's members. numpy's ``savez_compressed`` takes zlib's default (6); level 3 writes a
#: tree or a plan in about two thirds of the time for files 4-13% larger (the kitchen's: 1.7 ms instead of 2.7 for
#: ``tree.npz``, 4.7 instead of 7.3 for ``plan.npz``), most of it the embedded map's text (UTF-32 in an npz).
#: Any level reads the same.
NPZ_DEFLATE_LEVEL = 3

#: Which Python type each artifact kind holds, by its name in :mod:`bearnav_cli.datatypes` (whose modules are
#: imported on first use: saving a tree does not import the cells' module).
_TYPES: dict[str, str] = {
    "map": "Map", "tree": "Tree", "simplified": "Tree", "cells": "Cells", "plan": "Plan", "simulation": "Simulation",
}  # fmt: skip


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
    if kind is None or not isinstance(artifact, getattr(datatypes, _TYPES[kind])):
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
        files.append((path, lambda handle: _write_npz(handle, arrays)))
    if kind == "simulation":
        # sim.json next to sim.npz: the metrics, for people and scripts that do not read npz
        metrics = json.dumps({"manifest": manifest, "metrics": manifest.get("stats", {})}, indent=1, sort_keys=True)
        files.append((metrics_path(path), lambda handle: handle.write((metrics + "\n").encode())))
    write_all(files, on_commit)
    return path


def _write_npz(handle: io.BufferedWriter, arrays: dict[str, np.ndarray]) -> None:
    """``np.savez_compressed(handle, **arrays)`` at :data:`NPZ_DEFLATE_LEVEL`: the same members (``NAME.npy``,
    numpy's format, zip64 as numpy forces it), deflated at that level."""
    deflated = zipfile.ZIP_DEFLATED
    with zipfile.ZipFile(handle, "w", deflated, allowZip64=True, compresslevel=NPZ_DEFLATE_LEVEL) as archive:
        for key, value in arrays.items():
            with archive.open(key + ".npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)


def metrics_path(path: str | os.PathLike) -> Path:
    """``sim.json`` for ``sim.npz``: the same name with ``.json``."""
    return Path(path).with_suffix(".json")


def output_files(kind: str, path: str | os.PathLike) -> list[Path]:
    """Every file an artifact of ``kind`` saved at ``path`` consists of (``sim.npz`` also has ``sim.json``)."""
    path = Path(path)
    return [path, metrics_path(path)] if kind == "simulation" else [path]
