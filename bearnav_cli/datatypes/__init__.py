"""Typed, immutable containers for every artifact (DESIGN §3).

Each artifact is a frozen dataclass of numpy arrays plus a few scalars. The constructors check
shapes and dtypes and make the arrays read-only, so an artifact cannot be changed after it is
built. The keys, dtypes and shapes come from the one schema declaration,
:data:`bearnav_cli.runtime.schema.ENTRIES` (shared with the loader, the robot's run-time view and
the docs test). Serialisation lives in ``artifacts/``; this package knows nothing about files.
Every name is re-exported here, its module imported when the name is first used; its modules, each
with one job:

- :mod:`~bearnav_cli.datatypes.frozen` — read-only dicts, arrays of their declared dtypes and shapes, and
  :class:`ArraysOnMap`, what every artifact but the map is;
- :mod:`~bearnav_cli.datatypes.words` — counts, shares and cell lists as messages word them;
- :mod:`~bearnav_cli.datatypes.map_` — :class:`Polygon`, :class:`Map` and the map's invariants;
- :mod:`~bearnav_cli.datatypes.tree` — :class:`Tree` (``tree.npz``, ``simplified.npz``);
- :mod:`~bearnav_cli.datatypes.cells` — :class:`Cells`, :class:`Plan`, the cell statuses and flags;
- :mod:`~bearnav_cli.datatypes.simulation` — :class:`Simulation` and the run :class:`Outcome`;
- :mod:`~bearnav_cli.datatypes.kinds` — every kind's invariants, :func:`validate_artifact`, :func:`replace`.
"""

from bearnav_cli.runtime.lazy import lazy_names

#: Where each name of ``__all__`` is defined: a module is imported when one of its names is first used
#: (PEP 562), so that ``bearnav rrtstar`` (a map in, a tree out) imports neither the cells' nor the
#: simulation's module.
_ORIGIN = {
    **dict.fromkeys(("AREA_QUANTILES", "CELL_KEYS", "CLAIMS_CERTIFICATE", "PLAN_KEYS", "CellFlag", "Cells",
                     "CellStatus", "Plan", "active_regions", "cell_polygons", "tolerance_by_area"), "cells"),
    **dict.fromkeys(("ArraysOnMap", "FrozenDict", "freeze", "frozen_array", "ragged", "thaw"), "frozen"),
    **dict.fromkeys(("INVARIANTS", "replace", "validate_artifact"), "kinds"),
    **dict.fromkeys(("MAP_INVARIANTS", "Map", "Polygon"), "map_"),
    **dict.fromkeys(("SIMULATION_INVARIANTS", "SIMULATION_KEYS", "Outcome", "Simulation"), "simulation"),
    **dict.fromkeys(("TREE_INVARIANTS", "TREE_KEYS", "Tree"), "tree"),
    **dict.fromkeys(("NEGLIGIBLE_SHARE", "cell_list", "percent", "plural"), "words"),
}  # fmt: skip
#: The submodules, also attributes of the package once imported.
_SUBMODULES = ("cells", "frozen", "kinds", "map_", "simulation", "tree", "words")


__getattr__, __dir__ = lazy_names(__name__, globals(), _ORIGIN, _SUBMODULES)


__all__ = [
    "AREA_QUANTILES",
    "ArraysOnMap",
    "CELL_KEYS",
    "CLAIMS_CERTIFICATE",
    "active_regions",
    "cell_polygons",
    "cell_list",
    "CellFlag",
    "Cells",
    "CellStatus",
    "freeze",
    "frozen_array",
    "FrozenDict",
    "INVARIANTS",
    "Map",
    "MAP_INVARIANTS",
    "NEGLIGIBLE_SHARE",
    "Outcome",
    "percent",
    "Plan",
    "PLAN_KEYS",
    "plural",
    "Polygon",
    "ragged",
    "replace",
    "Simulation",
    "SIMULATION_INVARIANTS",
    "SIMULATION_KEYS",
    "thaw",
    "tolerance_by_area",
    "Tree",
    "TREE_INVARIANTS",
    "TREE_KEYS",
    "validate_artifact",
]
