"""Typed, immutable containers for every artifact (DESIGN §3).

Each artifact is a frozen dataclass of numpy arrays plus a few scalars. The constructors check
shapes and dtypes and make the arrays read-only, so an artifact cannot be changed after it is
built. The keys, dtypes and shapes come from the one schema declaration,
:data:`bearnav_cli.runtime.schema.ENTRIES` (shared with the loader, the robot's run-time view and
the docs test). Serialisation lives in ``artifacts/``; this package knows nothing about files.
Every name is re-exported here; its modules, each with one job:

- :mod:`~bearnav_cli.datatypes.frozen` — read-only dicts, and arrays of their declared dtypes and shapes;
- :mod:`~bearnav_cli.datatypes.words` — counts, shares and cell lists as messages word them;
- :mod:`~bearnav_cli.datatypes.map_` — :class:`Polygon`, :class:`Map` and the map's invariants;
- :mod:`~bearnav_cli.datatypes.tree` — :class:`Tree` (``tree.npz``, ``simplified.npz``);
- :mod:`~bearnav_cli.datatypes.cells` — :class:`Cells`, :class:`Plan`, the cell statuses and flags;
- :mod:`~bearnav_cli.datatypes.simulation` — :class:`Simulation` and the run :class:`Outcome`;
- :mod:`~bearnav_cli.datatypes.kinds` — every kind's invariants, :func:`validate_artifact`, :func:`replace`.
"""

from bearnav_cli.datatypes.cells import (
    AREA_QUANTILES,
    CELL_KEYS,
    CLAIMS_CERTIFICATE,
    PLAN_KEYS,
    CellFlag,
    Cells,
    CellStatus,
    Plan,
    active_regions,
    cell_polygons,
    tolerance_by_area,
)
from bearnav_cli.datatypes.frozen import FrozenDict, freeze, frozen_array, ragged, thaw
from bearnav_cli.datatypes.kinds import INVARIANTS, replace, validate_artifact
from bearnav_cli.datatypes.map_ import MAP_INVARIANTS, Map, Polygon
from bearnav_cli.datatypes.simulation import SIMULATION_INVARIANTS, SIMULATION_KEYS, Outcome, Simulation
from bearnav_cli.datatypes.tree import TREE_INVARIANTS, TREE_KEYS, Tree
from bearnav_cli.datatypes.words import NEGLIGIBLE_SHARE, cell_list, percent, plural

__all__ = [
    "AREA_QUANTILES",
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
