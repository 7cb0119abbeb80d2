"""What an artifact is: its kind and schema, its data entries, their content hash, the cache key and the manifest.

Every file is self-describing (DESIGN §3.1): its manifest names the schema, the stage, the
parameters, the input's content hash and its own, and the key that decides freshness.
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from bearnav_cli import __version__
from bearnav_cli.datatypes import ArraysOnMap, Map
from bearnav_cli.runtime import plan_file
from bearnav_cli.runtime.plan_file import canonical_json
from bearnav_cli.runtime.schema import ENTRIES, SCHEMAS, STAGES, Entry

__all__ = [
    "ARTIFACT_FORMAT",
    "cache_key",
    "content_hash",
    "embedded_map_text",
    "entries_of",
    "Kind",
    "kind_of_schema",
    "KINDS",
    "make_manifest",
    "params_dict",
    "RETIRED_SCHEMAS",
    "sha256_text",
    "software_versions",
]


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


#: Schemas of earlier versions, with what a file that has one lacks (``reading._rerun_hint`` adds the command
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


def kind_of_schema(schema: Any) -> str | None:
    """The kind (``"plan"``) whose current schema name is ``schema`` (``"bearnav.plan/2"``), or None.

    A retired schema (:data:`RETIRED_SCHEMAS`) or any other value gives None.
    """
    for kind in KINDS.values():
        if kind.schema == schema:
            return kind.name
    return None


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
            {
                "stage": stage,
                "stage_version": stage_version,
                "params": params,
                "input": input_hash,
                "format": ARTIFACT_FORMAT,
            }
        )
    )


def software_versions() -> dict[str, str]:
    """Versions of the packages that shape results (provenance, not part of the key)."""
    return dict(_installed_versions())


@functools.cache
def _installed_versions() -> tuple[tuple[str, str], ...]:
    # the versions cannot change within one process, and a plan makes five manifests
    versions = {"bearnav": __version__, "python": platform.python_version()}
    for package in ("numpy", "shapely", "scipy", "highspy"):
        # a loaded module's own version is its distribution's (numpy, shapely, scipy say it)
        loaded = getattr(sys.modules.get(package), "__version__", None)
        found = loaded if isinstance(loaded, str) else _distribution_version(package)
        if found is not None:
            versions[package] = found
    return tuple(versions.items())


def _distribution_version(package: str) -> str | None:
    """The installed version of ``package``, or None if it is not installed.

    Read from the name of its ``NAME-VERSION.dist-info`` folder, the first on ``sys.path`` (where
    :func:`importlib.metadata.version` looks too); only where there is none (an egg, a zip), from
    :mod:`importlib.metadata`, whose import (email, csv, zipfile ...) and parsing of the metadata
    file take 20 ms: a fifth of a whole ``bearnav rrtstar`` process beside the planner.
    """
    prefix, suffix = package.lower().replace("-", "_") + "-", ".dist-info"
    for entry in sys.path:
        for name in _dist_infos(entry):
            if name.lower().startswith(prefix):
                return name[len(prefix) : -len(suffix)]
    from importlib import metadata

    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


@functools.cache
def _dist_infos(entry: str) -> tuple[str, ...]:
    """The ``.dist-info`` folders in one ``sys.path`` entry (none in a zip or a missing folder), listed once
    per process for every package looked up (site-packages holds a few hundred names)."""
    try:
        return tuple(name for name in os.listdir(entry or ".") if name.endswith(".dist-info"))
    except OSError:
        return ()


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


@functools.lru_cache(maxsize=4)
def embedded_map_text(map_: Map) -> str:
    """The map as later artifacts embed it: ``map.json``'s JSON without its provenance ``source``.

    Leaving the YAML's name and hash out makes every later artifact depend on the map alone, so
    the same map gives the same content hashes whatever file (or cached run) it came from. A map
    cannot change: the text is made once per map (a stage's manifest hashes it, then its file holds it).
    """
    document = map_.to_json()
    document.pop("source", None)
    return plan_file.map_text(document)


def entries_of(artifact: Any) -> dict[str, Any]:
    """The data entries of an artifact (what is hashed and stored besides the manifest)."""
    if isinstance(artifact, Map):
        return {"map": artifact.to_json_text()}
    if isinstance(artifact, ArraysOnMap):  # a Tree, Cells, Plan or Simulation
        return {"map": embedded_map_text(artifact.map), **artifact.arrays()}
    raise TypeError(f"not an artifact: {type(artifact).__name__}")
