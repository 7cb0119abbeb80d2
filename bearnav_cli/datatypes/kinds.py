"""Every artifact kind at once: the invariants of each (:data:`INVARIANTS`), the one check of an artifact's
meaning (:func:`validate_artifact`) and :func:`replace`."""

from __future__ import annotations

import dataclasses
import weakref
from typing import Any

from bearnav_cli.datatypes.map_ import MAP_INVARIANTS
from bearnav_cli.datatypes.tree import TREE_INVARIANTS
from bearnav_cli.runtime.invariants import CELLS_INVARIANTS, PLAN_INVARIANTS, Invariant, validate

__all__ = ["INVARIANTS", "replace", "validate_artifact"]


def _invariants(kind: str) -> tuple[Invariant, ...]:
    """The invariants of one artifact kind (``artifacts.KINDS`` names them): a simulation's from its module,
    imported here, so that checking a map or a tree does not import it."""
    if kind == "simulation":
        from bearnav_cli.datatypes.simulation import SIMULATION_INVARIANTS

        return SIMULATION_INVARIANTS
    return {
        "map": MAP_INVARIANTS,
        "tree": TREE_INVARIANTS,
        "simplified": TREE_INVARIANTS,
        "cells": CELLS_INVARIANTS,
        "plan": CELLS_INVARIANTS + PLAN_INVARIANTS,
    }[kind]


def __getattr__(name: str) -> Any:
    # INVARIANTS, made on first use (PEP 562): it holds the simulation's
    if name == "INVARIANTS":
        found = {kind: _invariants(kind) for kind in ("map", "tree", "simplified", "cells", "plan", "simulation")}
        globals()[name] = found
        return found
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: The invariants of each artifact kind (``artifacts.KINDS`` names); every kind but ``map`` also checks
#: its embedded map against :data:`MAP_INVARIANTS` (fields ``map.NAME``). Made on first use.
INVARIANTS: dict[str, tuple[Invariant, ...]]


#: The maps that passed :data:`MAP_INVARIANTS` in this process: a map cannot change (a frozen dataclass of
#: read-only arrays), so a stage's output is not checked again for the map its input was checked for.
_VALID_MAPS: weakref.WeakSet[Any] = weakref.WeakSet()


def _check_map(map_: Any, prefix: str = "") -> None:
    if map_ not in _VALID_MAPS:
        validate(MAP_INVARIANTS, map_, prefix=prefix)
        _VALID_MAPS.add(map_)


def validate_artifact(kind: str, artifact: Any, check_map: bool = True) -> None:
    """Check what ``artifact`` (of ``kind``) means: its map's invariants, then its own.

    Parameters
    ----------
    kind : {"map", "tree", "simplified", "cells", "plan", "simulation"}
        The artifact's kind, a key of :data:`INVARIANTS`.
    artifact : Map, Tree, Cells, Plan or Simulation
        The artifact to check; a plan is checked as its ``cells``, then as a plan.
    check_map : bool, default True
        Also run :data:`MAP_INVARIANTS` on the map (its fields named ``map.…``); False when
        the map was checked already (a loader that read it once). A map object that passed once in
        this process is not checked again.

    Raises
    ------
    ArtifactError
        Naming the field (``map.goal``, ``parent`` ...) and what is wrong.
    """
    if kind == "map":
        if check_map:
            _check_map(artifact)
        return
    if check_map:
        _check_map(artifact.map, prefix="map.")
    if kind == "plan":
        validate(CELLS_INVARIANTS, artifact.cells)
        validate(PLAN_INVARIANTS, artifact)
        return
    validate(_invariants(kind), artifact)


def replace(artifact: Any, **changes: Any) -> Any:
    """:func:`dataclasses.replace` for artifacts (they are immutable); ``map=`` works on every one.

    Parameters
    ----------
    artifact : Map, Tree, Cells, Plan or Simulation
        The artifact to copy.
    **changes
        Fields to change; a :class:`Plan`'s ``map`` is its cells' (``map=`` replaces that).

    Returns
    -------
    Any
        The new artifact, checked by its type.
    """
    from bearnav_cli.datatypes.cells import Plan  # here: a tree or a map is replaced without the cells' module

    if isinstance(artifact, Plan) and "map" in changes:
        changes["cells"] = dataclasses.replace(changes.get("cells", artifact.cells), map=changes.pop("map"))
    return dataclasses.replace(artifact, **changes)
