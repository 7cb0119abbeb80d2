"""The cells of ``cells.npz`` and the plan of ``plan.npz`` (cells with a certified gain each), statuses and flags.

Their invariants are the robot's loader's too (:mod:`bearnav_cli.runtime.invariants`), and are checked
in the constructors.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely

from bearnav_cli.datatypes.frozen import ArraysOnMap, data_keys, freeze, freeze_fields, ragged
from bearnav_cli.datatypes.map_ import Map
from bearnav_cli.runtime.invariants import cell_areas, check_cells_form, check_plan_form
from bearnav_cli.runtime.schema import ENTRIES

__all__ = [
    "CLAIMS_CERTIFICATE",
    "AREA_QUANTILES",
    "CELL_KEYS",
    "CellFlag",
    "Cells",
    "CellStatus",
    "Plan",
    "PLAN_KEYS",
    "active_regions",
    "cell_polygons",
    "tolerance_by_area",
]


class CellStatus(enum.IntEnum):
    """Outcome of a cell's synthesis (``plan.npz`` ``status``, ALGORITHMS §5.3)."""

    CERTIFIED = 0
    RELAXED = 1  # certified after halving the constants
    NOT_CERTIFIED = 2  # least-violation solution stored
    SOLVER_FAILURE = 3
    GOAL = 4


#: The statuses that claim a certificate: the ones ``verify`` re-checks and ``synthesize`` judges the barrier rows of.
CLAIMS_CERTIFICATE = (CellStatus.CERTIFIED, CellStatus.RELAXED, CellStatus.GOAL)


class CellFlag(enum.IntFlag):
    """Warnings attached to a cell by decomposition (ALGORITHMS §4.5, §5.4, §5.5)."""

    NONE = 0
    FEW_LANDMARKS = 1  # fewer than 2 landmarks visible from the whole cell (topped up)
    DEGENERATE_RISK = 2  # every landmark line through the fixed landmark crosses the cell
    LANDMARK_INSIDE = 4  # every candidate fixed landmark lies in the cell (s_min = 0)
    SAMPLE_ON_EDGE = 8  # a collision sample on the edge line was skipped
    BLIND_SPOT = 16  # a free point of the coverage grid (spacing D/100) in the cell sees < 2 landmarks


@dataclass(frozen=True, eq=False)  # arrays inside: identity equality, a hash that works
class Cells(ArraysOnMap):
    """Convex cells with their CLF and CBF rows, one per tree node (``cells.npz``, ALGORITHMS §4).

    C cells, R half-plane rows, V vertices, H barrier rows, L landmarks. Cell ``c``
    is ``{x : cell_A[r] @ x <= cell_b[r]}`` for ``r`` in its row range; rows are the
    outward unit normals of the CCW polygon edges, row ``q`` for edge ``v_q → v_{q+1}``.

    Attributes
    ----------
    map : Map
        The map.
    nodes, parent, collision_samples : ndarray, shapes (N, 2), (N,), (S, 2)
        The simplified tree the cells were cut along.
    cell_node : ndarray of int64, shape (C,)
        Node owning each cell (``cell_node[c] == c``; node 0's cell is the goal cell).
    cell_A, cell_b, cell_row_offsets : ndarray, shapes (R, 2), (R,), (C + 1,)
        Half-planes of each cell.
    cell_vertices, cell_vertex_offsets : ndarray, shapes (V, 2), (C + 1,)
        The same cells as CCW polygons (aligned with the rows).
    exit_point, exit_dir : ndarray, shape (C, 2)
        ``x_j`` and unit ``z`` into the cell: ``V(x) = z·(x − x_j)``; zeros for the goal cell.
    cbf_A, cbf_b, cbf_offsets : ndarray, shapes (H, 2), (H,), (C + 1,)
        Barrier rows ``h(x) = cbf_A @ x + cbf_b``, safe where ``h >= 0``.
    cell_landmarks : ndarray of bool, shape (C, L)
        Landmarks each cell's controller uses.
    fixed_landmark : ndarray of int64, shape (C,)
        Landmark ``f`` that rescales bearings in each cell (ALGORITHMS §5.5).
    s_min, s_max : ndarray, shape (C,)
        Exact smallest and largest distance from ``l_f`` to the cell (map units).
    cell_flags : ndarray of int64, shape (C,)
        :class:`CellFlag` bits.
    certificate : {"funnel", "paper"}
        ``funnel``: every cell is obstacle-free and its exit face lies in its parent cell, so the
        certificates compose (ALGORITHMS §11); ``paper``: the §4 cells, per-cell certificates only.
    cell_exit_row : ndarray of int64, shape (C,)
        Index of the exit row among each cell's own rows (local, 0-based); ``-1`` for the goal cell.
    cell_rank : ndarray, shape (C,)
        Rank of the switching policy: the cost-to-go of the cell's node (0 for the goal cell).
    exit_inset : ndarray, shape (C,)
        ``δ_e,c``: cell c's exit face lies in its parent cell eroded by this (map units,
        ALGORITHMS §12.3; 0 for ``paper``); NaN for the goal cell.
    node_added : ndarray of bool, shape (N,)
        Nodes added by densification (ALGORITHMS §11.5), not by the tree stages.
    free_coverage : float
        ``area(D) / area(F)`` of the reached part of ``F`` as built (ALGORITHMS §12.7; NaN for
        ``paper``: its cells are not a certified domain).
    lookahead : float
        ``λ`` the cells were built for (map units, ALGORITHMS §12.6): the map's obstacles and
        walls are inflated by ``ρ + λ``; 0 for a robot that is its own reference point.
    stats : dict
        Statistics for the manifest.
    """

    map: Map
    nodes: np.ndarray
    parent: np.ndarray
    collision_samples: np.ndarray
    cell_node: np.ndarray
    cell_A: np.ndarray
    cell_b: np.ndarray
    cell_row_offsets: np.ndarray
    cell_vertices: np.ndarray
    cell_vertex_offsets: np.ndarray
    exit_point: np.ndarray
    exit_dir: np.ndarray
    cbf_A: np.ndarray
    cbf_b: np.ndarray
    cbf_offsets: np.ndarray
    cell_landmarks: np.ndarray
    fixed_landmark: np.ndarray
    s_min: np.ndarray
    s_max: np.ndarray
    cell_flags: np.ndarray
    certificate: str
    cell_exit_row: np.ndarray
    cell_rank: np.ndarray
    exit_inset: np.ndarray
    node_added: np.ndarray
    free_coverage: float
    lookahead: float = 0.0
    stats: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stats", freeze(dict(self.stats)))
        _check_cell_arrays(self)
        dims = {"C": len(self.cell_node), "N": len(self.nodes)}
        put = object.__setattr__
        freeze_fields(self, "cells", ("cell_flags",), dims)
        put(self, "certificate", str(self.certificate))
        freeze_fields(self, "cells", ("cell_exit_row", "cell_rank", "node_added", "exit_inset"), dims)
        put(self, "free_coverage", float(self.free_coverage))
        put(self, "lookahead", float(self.lookahead))
        check_cells_form(self)  # the robot's loader runs the same checks (runtime.invariants)

    @property
    def is_funnel(self) -> bool:
        """Whether the cells compose (ALGORITHMS §11)."""
        return self.certificate == "funnel"

    @property
    def n_cells(self) -> int:
        return len(self.cell_node)

    def flagged(self, flag: CellFlag) -> list[int]:
        """Indices of the cells carrying ``flag``."""
        return np.flatnonzero(self.cell_flags & flag).tolist()

    def vertices(self, c: int) -> np.ndarray:
        """CCW vertices of cell ``c``, shape (p, 2)."""
        return self.cell_vertices[self.cell_vertex_offsets[c] : self.cell_vertex_offsets[c + 1]]

    def rows(self, c: int) -> tuple[np.ndarray, np.ndarray]:
        """``(A, b)`` of cell ``c``, shapes (p, 2) and (p,)."""
        r0, r1 = self.cell_row_offsets[c], self.cell_row_offsets[c + 1]
        return self.cell_A[r0:r1], self.cell_b[r0:r1]

    def barrier(self, c: int) -> tuple[np.ndarray, np.ndarray]:
        """Barrier rows ``(n, q)`` of cell ``c`` (``h = n @ x + q``), shapes (h, 2) and (h,)."""
        r0, r1 = self.cbf_offsets[c], self.cbf_offsets[c + 1]
        return self.cbf_A[r0:r1], self.cbf_b[r0:r1]

    def arrays(self) -> dict[str, np.ndarray]:
        """The data entries of ``cells.npz`` (without ``manifest`` and ``map``)."""
        return {name: _entry(getattr(self, name)) for name in CELL_KEYS}


#: The quantiles of :func:`tolerance_by_area`, by name.
AREA_QUANTILES = {"p10": 0.1, "median": 0.5, "p90": 0.9}


def cell_polygons(cells: Cells) -> np.ndarray:
    """Every cell as a shapely polygon, object array of shape (C,)."""
    out = np.empty(cells.n_cells, dtype=object)
    out[:] = [shapely.Polygon(cells.vertices(c)) for c in range(cells.n_cells)]
    return out


def active_regions(polygons: Any, rank: np.ndarray) -> list:
    """Where each cell drives the robot under the funnel policy (ALGORITHMS §11.3).

    Cell ``c``'s region is ``P_c`` less every cell of smaller rank (ties: lower index), i.e. the
    points where :func:`bearnav_cli.runtime.least_rank_cell` returns ``c``. The regions do not
    overlap and their union is ``D``; a cell whose region is empty is never used.

    Parameters
    ----------
    polygons : sequence of shapely.Polygon, length C
        The cells (:func:`cell_polygons`).
    rank : ndarray, shape (C,)
        Each cell's rank (``cell_rank``).

    Returns
    -------
    list of shapely geometries, length C
    """
    regions: list = [shapely.Polygon()] * len(polygons)
    taken = shapely.Polygon()
    for c in np.lexsort((np.arange(len(polygons)), np.asarray(rank, float))):
        regions[c] = shapely.difference(polygons[c], taken)
        taken = shapely.union(taken, polygons[c])
    return regions


def tolerance_by_area(cells: Cells, usable: np.ndarray) -> dict[str, float]:
    """The distribution of ``τ_c`` over ``D`` by area (ALGORITHMS §12.4): its minimum and quantiles, map units.

    Each cell weighs by its own area (a point of several cells counts in each: the policy may
    use any of them once the robot is in it). Cells without a finite ``τ_c`` are left out.

    Parameters
    ----------
    cells : Cells
        The cells (their polygons give the areas).
    usable : ndarray, shape (C,)
        ``τ_c`` of each cell (map units).

    Returns
    -------
    dict
        ``{"min", "p10", "median", "p90"}``; NaN values when no cell has a finite ``τ_c``.
    """
    tau = np.asarray(usable, float)
    keep = np.isfinite(tau)
    if not keep.any():
        return {"min": math.nan, **{k: math.nan for k in AREA_QUANTILES}}
    order = np.argsort(tau[keep], kind="stable")
    values, weight = tau[keep][order], np.cumsum(np.abs(cell_areas(cells))[keep][order])
    out = {"min": float(values[0])}
    for name, q in AREA_QUANTILES.items():
        out[name] = float(values[min(int(np.searchsorted(weight, q * weight[-1])), len(values) - 1)])
    return out


def _entry(value: Any) -> Any:
    """A data entry as artifacts store it: texts stay ``str`` (a 0-d text entry), the rest arrays."""
    return value if isinstance(value, str) else np.asarray(value)


#: Data keys common to ``cells.npz`` and ``plan.npz`` besides ``map`` (DESIGN §3.2–3.3).
CELL_KEYS = data_keys("cells")


def _check_cell_arrays(obj: Any) -> None:
    """The cell arrays of ``obj`` (a :class:`Cells`) as read-only arrays of their declared dtypes and shapes;
    what they must then satisfy is :func:`~bearnav_cli.runtime.invariants.check_cells_form`'s."""
    freeze_fields(obj, "cells", ("nodes",), {})
    n = len(obj.nodes)
    c = len(np.asarray(obj.cell_node))
    dims = {"N": n, "C": c, "L": len(obj.map.landmarks)}
    freeze_fields(
        obj,
        "cells",
        ("parent", "collision_samples", "cell_node", "exit_point", "exit_dir", "fixed_landmark", "s_min", "s_max"),
        dims,
    )
    for coords, values, offsets in (
        ("cell_A", "cell_b", "cell_row_offsets"),
        ("cbf_A", "cbf_b", "cbf_offsets"),
        ("cell_vertices", None, "cell_vertex_offsets"),
    ):
        entry = ENTRIES["cells"][coords]
        a, off = ragged(getattr(obj, coords), getattr(obj, offsets), entry.shape[1], coords, c, entry.numpy_dtype)
        object.__setattr__(obj, coords, a)
        object.__setattr__(obj, offsets, off)
        if values is not None:
            freeze_fields(obj, "cells", (values,), {entry.shape[0]: len(a)})
    freeze_fields(obj, "cells", ("cell_landmarks",), dims)


#: Data keys that ``plan.npz`` adds to the cell keys (DESIGN §3.2–3.3).
PLAN_KEYS = tuple(name for name in ENTRIES["plan"] if name not in ENTRIES["cells"])


@dataclass(frozen=True, eq=False)  # arrays inside: identity equality, a hash that works
class Plan(ArraysOnMap):
    """Cells with a synthesised, certified controller each (``plan.npz``, DESIGN §3.2, ALGORITHMS §5).

    Attributes
    ----------
    cells : Cells
        The decomposition the controllers were synthesised for.
    gain : ndarray, shape (C, 2, 2L)
        ``u(x) = gain[c] @ (landmarks − x).ravel()``; unused landmarks' columns are zero.
    c_h, c_v, u_max : ndarray, shape (C,)
        Constants the certificate is stated with; ``c_h`` is NaN in a cell without barrier rows.
    margin_h, margin_v : ndarray, shape (C,)
        Worst-case CBF and CLF slack over the cell (≤ 0 holds; NaN where no row).
    status : ndarray of int8, shape (C,)
        :class:`CellStatus` of each cell.
    goal_tolerance : float
        Success radius around the goal (map units).
    tolerance : ndarray, shape (C,)
        ``δ_c``, the position error each cell's certificate tolerates (ALGORITHMS §11.4, map
        units); ``+inf`` where the field is constant (``M = 0``: its margins do not depend on
        the position); NaN where none (``paper`` cells).
    usable_tolerance : ndarray, shape (C,)
        ``τ_c = min(δ_c, δ_e,c / 2)`` (``δ_c`` in the goal cell), finite in every funnel cell:
        the error radius under which the runtime may move in cell c (ALGORITHMS §12.3, map
        units); NaN for ``paper``.
    plan_tolerance : float
        ``min_c τ_c`` (NaN for ``paper``).
    stats : dict
        Statistics for the manifest.
    """

    cells: Cells
    gain: np.ndarray
    c_h: np.ndarray
    c_v: np.ndarray
    u_max: np.ndarray
    margin_h: np.ndarray
    margin_v: np.ndarray
    status: np.ndarray
    goal_tolerance: float
    tolerance: np.ndarray
    usable_tolerance: np.ndarray
    plan_tolerance: float
    stats: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stats", freeze(dict(self.stats)))
        dims = {"C": self.cells.n_cells, "L": len(self.cells.map.landmarks)}
        freeze_fields(self, "plan", ("gain", "c_h", "c_v", "u_max", "margin_h", "margin_v", "status"), dims)
        object.__setattr__(self, "goal_tolerance", float(self.goal_tolerance))
        freeze_fields(self, "plan", ("tolerance", "usable_tolerance"), dims)
        object.__setattr__(self, "plan_tolerance", float(self.plan_tolerance))
        check_plan_form(self)  # the robot's loader runs the same checks (runtime.invariants)

    @property
    def map(self) -> Map:
        return self.cells.map

    @property
    def landmarks(self) -> np.ndarray:
        return self.cells.map.landmarks

    def arrays(self) -> dict[str, np.ndarray]:
        """The data entries of ``plan.npz`` (without ``manifest`` and ``map``): exactly DESIGN §3.2."""
        out = self.cells.arrays()
        out.update({name: np.asarray(getattr(self, name)) for name in PLAN_KEYS})  # landmarks: the map's
        return out
