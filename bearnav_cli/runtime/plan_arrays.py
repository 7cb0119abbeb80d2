"""The arrays of a ``plan.npz`` that a robot needs, loaded with numpy only (DESIGN §3.2, §6).

:class:`PlanArrays` is the run-time view of a plan: the contract keys of DESIGN §3.2 that
a controller uses, plus arrays derived once on loading (each cell's affine field, padded
cell and barrier rows for vectorised tests, the route length from each exit point, the
obstacle edges of the embedded map). :mod:`bearnav_cli.runtime` builds on it.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bearnav_cli.errors import ArtifactError
from bearnav_cli.runtime import plan_file, schema

__all__ = [
    "CHUNK",
    "INDEX_BINS",
    "PlanArrays",
    "ring_edges",
    "RUNTIME_KEYS",
    "tree_costs",
]

log = logging.getLogger(__name__)

#: Largest number of robot × node distances computed at once by :func:`voronoi_owner`.
CHUNK = 1 << 20

#: ``plan.npz`` entries a robot needs (DESIGN §3.2), as :mod:`bearnav_cli.runtime.schema` declares them.
RUNTIME_KEYS = schema.RUNTIME_KEYS
#: The declaration of ``plan.npz``: dtypes and symbolic shapes.
_PLAN = schema.ENTRIES["plan"]
#: Arrays of the view that ``plan.npz`` does not hold: derived from the embedded map on loading.
_MAP_ARRAYS = {
    "bounds": (np.dtype(float), (4,)),
    "obstacle_edges": (np.dtype(float), None),
    "sight_edges": (np.dtype(float), None),
}
#: Entries whose shape :meth:`PlanArrays._check_shapes` checks (the rest are checked where they are used).
_CHECKED_SHAPES = (
    "landmarks",
    "nodes",
    "parent",
    "cell_node",
    "cell_A",
    "cell_b",
    "cell_row_offsets",
    "exit_point",
    "exit_dir",
    "gain",
    "u_max",
    "bounds",
    "cell_landmarks",
    "fixed_landmark",
    "status",
    "c_h",
    "c_v",
    "exit_inset",
    "usable_tolerance",
)

#: The cell index of :class:`PlanArrays`: at most this many bins along each side of the bounds.
INDEX_BINS = 32


def _readonly(value: Any, dtype: Any) -> np.ndarray:
    array = np.array(value, dtype=dtype, copy=True)
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class PlanArrays:
    """The arrays of a plan that a controller needs at run time.

    N tree nodes, C cells, L landmarks, R half-plane rows, H barrier rows, V cell vertices,
    E (E') inflated (raw) obstacle edges. Build it with :meth:`from_npz` (a ``plan.npz`` file)
    or :meth:`from_plan` (a :class:`~bearnav_cli.datatypes.Plan` in memory). Lengths are in
    map units; every array is read-only.

    Attributes
    ----------
    landmarks : ndarray of float64, shape (L, 2)
        Landmark positions (map units), the embedded map's.
    nodes : ndarray of float64, shape (N, 2)
        Tree node positions (map units); the root (``parent == -1``) is the goal.
    parent : ndarray of int64, shape (N,)
        Parent index of each node, ``-1`` exactly at the root.
    cell_node : ndarray of int64, shape (C,)
        Node owning each cell; every node owns exactly one cell (so C == N).
    cell_A : ndarray of float64, shape (R, 2)
        Outward unit normals of the cells' half-planes (dimensionless): cell ``c`` is
        ``{x : A x <= b}`` over its rows ``cell_row_offsets[c]:cell_row_offsets[c + 1]``.
    cell_b : ndarray of float64, shape (R,)
        Offsets of those half-planes (map units).
    cell_row_offsets : ndarray of int64, shape (C + 1,)
        Where each cell's rows of ``cell_A``/``cell_b`` begin (row indices, unitless); starts
        at 0, every cell has at least one row.
    exit_point : ndarray of float64, shape (C, 2)
        ``x_j``, the parent node each cell drives to (map units); zeros for the goal cell.
    exit_dir : ndarray of float64, shape (C, 2)
        Unit ``z`` from the exit face into the cell (dimensionless): ``V(x) = z·(x − x_j)``;
        zeros for the goal cell.
    gain : ndarray of float64, shape (C, 2, 2L)
        Affine gains (1/s): ``u = gain[c] @ y`` with ``y = (landmarks − x).ravel()`` (or its
        bearing reconstruction), ``u`` in map units / s; unused landmarks' columns are zero.
    u_max : ndarray of float64, shape (C,)
        Input bound ``|u_k| <= u_max`` of each cell's certificate (map units / s).
    goal_tolerance : float
        Success radius around the goal (map units).
    bounds : ndarray of float64, shape (4,)
        ``[xmin, ymin, xmax, ymax]`` of the embedded map (map units).
    cell_landmarks : ndarray of bool, shape (C, L)
        Landmarks each cell's controller uses.
    fixed_landmark : ndarray of int64, shape (C,)
        Index of the landmark ``l_f`` that rescales bearings in each cell (ALGORITHMS §5.5).
    status : ndarray of int8, shape (C,)
        Synthesis status of each cell (``CellStatus`` values: 0 certified, 1 certified after
        relaxing constants, 2 not certified, 3 solver failure, 4 goal cell).
    cbf_A : ndarray of float64, shape (H, 2)
        Barrier normals (dimensionless): ``h(x) = A x + b``, safe where every ``h >= 0``.
    cbf_b : ndarray of float64, shape (H,)
        Barrier offsets (map units).
    cbf_offsets : ndarray of int64, shape (C + 1,)
        Where each cell's barrier rows of ``cbf_A``/``cbf_b`` begin (row indices, unitless).
    obstacle_edges : ndarray of float64, shape (E, 2, 2)
        Every ring edge ``(start, end)`` of the inflated obstacles (map units, from the embedded
        map), for the exact straight-line checks of :func:`approach_target`.
    sight_edges : ndarray of float64, shape (E', 2, 2)
        Every ring edge of the raw obstacles (map units): what hides a landmark
        (``sight.in_sight``).
    certificate : {"funnel", "paper"}
        ``funnel``: the cells compose and the policy is ALGORITHMS §11.3's (least rank);
        ``paper``: per-cell certificates only.
    cell_rank : ndarray of float64, shape (C,)
        Rank of each cell for the switching policy: the cost-to-go of its node (map units,
        0 for the goal cell).
    tolerance : ndarray of float64, shape (C,)
        ``δ_c``, the position error each cell's certificate tolerates (map units; NaN for
        ``paper``).
    plan_tolerance : float
        ``min_c τ_c`` (map units): a step whose position error bound is at most this is
        certified in every cell (NaN for ``paper``).
    exit_inset : ndarray of float64, shape (C,)
        ``δ_e,c`` (map units): cell c's exit face lies in its parent cell eroded by ``δ_e,c``
        (0 for ``paper``, NaN for the goal cell).
    usable_tolerance : ndarray of float64, shape (C,)
        ``τ_c = min(δ_c, δ_e,c/2)`` (map units, ALGORITHMS §12.3): a step in cell c whose
        position error bound is at most this is certified (NaN for ``paper``).
    lookahead : float
        ``λ`` (map units, ALGORITHMS §12.6): the cells were built for the point ``λ`` ahead of
        a unicycle's axle, with the obstacles inflated by ``ρ + λ``; 0 for a robot that is its
        own reference point.
    robot_radius : float
        ρ (map units): the walls of the straight-line checks are ``B_r``, the bounds less ρ.
    cell_vertices : ndarray of float64, shape (V, 2)
        The cells as CCW polygons (map units); their bounding boxes build the cell index
        (``bin_cells``).
    cell_vertex_offsets : ndarray of int64, shape (C + 1,)
        Where each cell's vertices in ``cell_vertices`` begin (vertex indices, unitless).
    c_h : ndarray of float64, shape (C,)
        Barrier constant of each cell's certificate (1/s; NaN without barrier rows).
    c_v : ndarray of float64, shape (C,)
        Lyapunov constant of each cell's certificate (1/s); with ``c_h``, what the unicycle's
        heading allowance (:func:`bearnav_cli.runtime.unicycle.heading_allowance`) needs.
    goal : ndarray of float64, shape (2,)
        Derived: the root node's position (map units).
    bin_cells : ndarray of int64, shape (B, K)
        Derived cell index, ``B = INDEX_BINS ** 2`` bins (row-major over ``bin_shape``): each
        bin's candidate cells (those whose bounding box meets it) in (rank, index) order,
        padded with ``-1``; K is the most cells of a bin (at least 1).
    bin_origin : ndarray of float64, shape (2,)
        Derived: lower-left corner ``(xmin, ymin)`` of the index grid (map units).
    bin_size : ndarray of float64, shape (2,)
        Derived: width and height of one index bin (map units).
    bin_shape : tuple of int
        Derived: ``(INDEX_BINS, INDEX_BINS)``, the bins along x and y (unitless).
    cell_order : ndarray of int64, shape (C,)
        Derived: each cell's place in (rank, index) order (the order of a bin's cells).
    free_bounds : ndarray of float64, shape (4,)
        Derived: ``B_r``, ``bounds`` shrunk by ``robot_radius + lookahead`` on every side (map units).
    tol : float
        Derived: ``1e-9·D``, D the diagonal of ``bounds`` (map units), the geometric
        tolerance of the run-time tests.
    node_cell : ndarray of int64, shape (N,)
        Derived: the cell of each node (inverse of ``cell_node``).
    parent_cell : ndarray of int64, shape (C,)
        Derived: the cell a cell switches to, its parent node's cell (``-1`` for the goal cell).
    field_a : ndarray of float64, shape (C, 2)
        Derived constant term of each cell's affine field (map units / s):
        ``gain[c] @ (landmarks − x).ravel() = field_a[c] − field_M[c] @ x``.
    field_M : ndarray of float64, shape (C, 2, 2)
        Derived linear term of that field (1/s), the sum of the 2×2 gain blocks.
    row_A : ndarray of float64, shape (C, P, 2)
        Derived: ``cell_A`` padded per cell to P, the most rows of a cell, for vectorised
        membership tests (dimensionless; padding rows are ``0·x <= 0``).
    row_b : ndarray of float64, shape (C, P)
        Derived: ``cell_b`` padded the same way (map units; padding 0).
    bar_A : ndarray of float64, shape (C, Q, 2)
        Derived: ``cbf_A`` padded per cell to Q, the most barrier rows of a cell
        (dimensionless; padding rows ``0·x + inf >= 0``).
    bar_b : ndarray of float64, shape (C, Q)
        Derived: ``cbf_b`` padded the same way (map units; padding ``inf``).
    node_cost : ndarray of float64, shape (N,)
        Derived: the tree route length from each node to the goal (map units,
        :func:`tree_costs`).
    cost_to_go : ndarray of float64, shape (C,)
        Derived: the tree route length from each cell's exit point to the goal (map units;
        0 for the goal cell).
    """

    landmarks: np.ndarray
    nodes: np.ndarray
    parent: np.ndarray
    cell_node: np.ndarray
    cell_A: np.ndarray
    cell_b: np.ndarray
    cell_row_offsets: np.ndarray
    exit_point: np.ndarray
    exit_dir: np.ndarray
    gain: np.ndarray
    u_max: np.ndarray
    goal_tolerance: float
    bounds: np.ndarray
    cell_landmarks: np.ndarray
    fixed_landmark: np.ndarray
    status: np.ndarray
    cbf_A: np.ndarray
    cbf_b: np.ndarray
    cbf_offsets: np.ndarray
    obstacle_edges: np.ndarray
    sight_edges: np.ndarray
    certificate: str
    cell_rank: np.ndarray
    tolerance: np.ndarray
    plan_tolerance: float
    exit_inset: np.ndarray
    usable_tolerance: np.ndarray
    lookahead: float
    robot_radius: float
    cell_vertices: np.ndarray
    cell_vertex_offsets: np.ndarray
    c_h: np.ndarray
    c_v: np.ndarray
    goal: np.ndarray = dataclasses.field(init=False, repr=False)
    bin_cells: np.ndarray = dataclasses.field(init=False, repr=False)
    bin_origin: np.ndarray = dataclasses.field(init=False, repr=False)
    bin_size: np.ndarray = dataclasses.field(init=False, repr=False)
    bin_shape: tuple = dataclasses.field(init=False, repr=False)
    cell_order: np.ndarray = dataclasses.field(init=False, repr=False)
    free_bounds: np.ndarray = dataclasses.field(init=False, repr=False)
    tol: float = dataclasses.field(init=False, repr=False)
    node_cell: np.ndarray = dataclasses.field(init=False, repr=False)
    parent_cell: np.ndarray = dataclasses.field(init=False, repr=False)
    field_a: np.ndarray = dataclasses.field(init=False, repr=False)
    field_M: np.ndarray = dataclasses.field(init=False, repr=False)
    row_A: np.ndarray = dataclasses.field(init=False, repr=False)
    row_b: np.ndarray = dataclasses.field(init=False, repr=False)
    bar_A: np.ndarray = dataclasses.field(init=False, repr=False)
    bar_b: np.ndarray = dataclasses.field(init=False, repr=False)
    node_cost: np.ndarray = dataclasses.field(init=False, repr=False)
    cost_to_go: np.ndarray = dataclasses.field(init=False, repr=False)

    def __post_init__(self) -> None:
        put = object.__setattr__
        for name in RUNTIME_KEYS:
            entry = _PLAN[name]
            if entry.dtype == "str":
                put(self, name, str(getattr(self, name)))
            elif entry.ndim == 0:
                put(self, name, float(getattr(self, name)))
            else:
                put(self, name, _readonly(getattr(self, name), entry.numpy_dtype))
        for name, (dtype, _) in _MAP_ARRAYS.items():
            put(self, name, _readonly(getattr(self, name), dtype))
        put(self, "robot_radius", float(self.robot_radius))
        r = max(0.0, self.robot_radius + self.lookahead)  # the cells' reference point keeps ρ + λ (§12.6)
        put(self, "free_bounds", _readonly(self.bounds + np.array([r, r, -r, -r]), float))  # B_r (Map.free_bounds)
        n, c, n_lm = len(self.nodes), len(self.cell_node), len(self.landmarks)
        self._check_shapes(n, c, n_lm)
        roots = np.flatnonzero(self.parent == -1)
        if len(roots) != 1 or np.any((self.parent < -1) | (self.parent >= n)):
            raise ArtifactError("parent must be -1 at exactly one node and index nodes elsewhere", field="parent")
        if np.any((self.cell_node < 0) | (self.cell_node >= n)):
            raise ArtifactError("cell_node index out of range", field="cell_node")
        node_cell = np.full(n, -1, np.int64)
        node_cell[self.cell_node] = np.arange(c)
        if c != n or np.any(node_cell < 0):
            raise ArtifactError("every tree node must own exactly one cell", field="cell_node")
        xmin, ymin, xmax, ymax = self.bounds
        put(self, "goal", _readonly(self.nodes[roots[0]], float))
        put(self, "tol", 1e-9 * math.hypot(xmax - xmin, ymax - ymin))
        put(self, "node_cell", _readonly(node_cell, np.int64))
        up = self.parent[self.cell_node]
        put(self, "parent_cell", _readonly(np.where(up >= 0, node_cell[np.maximum(up, 0)], -1), np.int64))
        blocks = self.gain.reshape(c, 2, n_lm, 2)  # K_k = gain[c][:, 2k:2k+2]
        put(self, "field_M", _readonly(blocks.sum(axis=2), float))
        put(self, "field_a", _readonly(self.gain @ self.landmarks.ravel(), float))
        row_A, row_b = _padded(self.cell_A, self.cell_b, self.cell_row_offsets, 0.0)  # 0·x <= 0 always holds
        put(self, "row_A", _readonly(row_A, float))
        put(self, "row_b", _readonly(row_b, float))
        bar_A, bar_b = _padded(self.cbf_A, self.cbf_b, self.cbf_offsets, math.inf)  # 0·x + inf >= 0 always holds
        put(self, "bar_A", _readonly(bar_A, float))
        put(self, "bar_b", _readonly(bar_b, float))
        node_cost = tree_costs(self.nodes, self.parent)
        put(self, "node_cost", _readonly(node_cost, float))
        put(self, "cost_to_go", _readonly(np.where(up >= 0, node_cost[np.maximum(up, 0)], 0.0), float))
        self._index_cells()

    def _index_cells(self) -> None:
        """A uniform grid over the bounds listing, per bin, the cells whose bounding box meets it, in
        (rank, index) order: the first of a bin's cells that holds a point is its least-rank cell."""
        put = object.__setattr__
        c = self.n_cells
        shape = (INDEX_BINS, INDEX_BINS)
        origin = self.bounds[:2]
        size = np.maximum((self.bounds[2:] - origin) / np.array(shape), 1e-300)
        members = np.zeros((shape[0], shape[1], c), bool)
        if c and len(self.cell_vertices):
            vo = self.cell_vertex_offsets
            lo = np.minimum.reduceat(self.cell_vertices, vo[:-1], axis=0)
            hi = np.maximum.reduceat(self.cell_vertices, vo[:-1], axis=0)
            first = np.clip(np.floor((lo - origin) / size).astype(np.int64), 0, np.array(shape) - 1)
            last = np.clip(np.floor((hi - origin) / size).astype(np.int64), 0, np.array(shape) - 1)
            for k in range(c):
                members[first[k, 0] : last[k, 0] + 1, first[k, 1] : last[k, 1] + 1, k] = True
        order = np.lexsort((np.arange(c), self.cell_rank))  # by rank, then index
        members = members.reshape(-1, c)[:, order]
        width = max(1, int(members.sum(axis=1).max(initial=0)))
        # each bin's cells in (rank, index) order, padded with -1
        slot = np.cumsum(members, axis=1) - 1
        bins = np.full((members.shape[0], width), -1, np.int64)
        b_idx, m_idx = np.nonzero(members)
        bins[b_idx, slot[b_idx, m_idx]] = order[m_idx]
        put(self, "bin_cells", _readonly(bins, np.int64))
        put(self, "bin_origin", _readonly(origin, float))
        put(self, "bin_size", _readonly(size, float))
        put(self, "bin_shape", shape)
        place = np.empty(c, np.int64)
        place[order] = np.arange(c)
        put(self, "cell_order", _readonly(place, np.int64))

    def cells_near(self, x: np.ndarray, reach: np.ndarray | float = 0.0) -> np.ndarray:
        """Candidate cells of each point (those whose bounding box meets its bin), shape (R, K), padded with ``-1``,
        in (rank, index) order.

        With ``reach`` (R,) or one (map units): the candidates of every bin the square of half-side ``reach``
        around the point meets, so that a cell within ``reach`` of the point is among them (a cell grown by ``e``
        may hold a point outside its bounding box's bins); a cell may then appear twice. A square over more than
        2 × 2 bins takes every cell.
        """
        p = np.asarray(x, float).reshape(-1, 2)
        top = np.array(self.bin_shape) - 1
        ij = np.clip(np.floor((p - self.bin_origin) / self.bin_size).astype(np.int64), 0, top)
        own = self.bin_cells[ij[:, 0] * self.bin_shape[1] + ij[:, 1]]
        r = np.broadcast_to(np.maximum(np.asarray(reach, float), 0.0), (len(p),))[:, None]
        if not np.any(r > 0.0):
            return own
        lo = np.clip(np.floor((p - r - self.bin_origin) / self.bin_size).astype(np.int64), 0, top)
        hi = np.clip(np.floor((p + r - self.bin_origin) / self.bin_size).astype(np.int64), 0, top)
        wide = np.flatnonzero(np.any(lo != hi, axis=1))  # a square inside its own bin has that bin's cells
        if not len(wide):
            return own
        lo, hi = lo[wide], hi[wide]
        far = np.any(hi - lo > 1, axis=1)
        parts = []
        for di in range(2):
            for dj in range(2):
                i, j = np.minimum(lo[:, 0] + di, hi[:, 0]), np.minimum(lo[:, 1] + dj, hi[:, 1])
                # a bin past the square repeats its last row or column: not a candidate twice
                past = (lo[:, 0] + di > hi[:, 0]) | (lo[:, 1] + dj > hi[:, 1]) | far
                parts.append(np.where(past[:, None], -1, self.bin_cells[i * self.bin_shape[1] + j]))
        cand = np.concatenate(parts, axis=1)
        key = np.where(cand >= 0, self.cell_order[np.maximum(cand, 0)], self.n_cells)
        cand = np.take_along_axis(cand, np.argsort(key, axis=1), axis=1)
        # a square over more than 2 × 2 bins (a large e: a robot's first sets span the map) takes every cell, in
        # (rank, index) order; the cell rows decide which hold the point
        width = max(own.shape[1], int(np.count_nonzero(cand >= 0, axis=1).max(initial=0)), self.n_cells * far.any())
        out = np.full((len(p), width), -1, np.int64)
        out[:, : own.shape[1]] = own
        out[wide] = -1
        out[wide, : min(width, cand.shape[1])] = cand[:, :width]
        if far.any():
            out[wide[far], : self.n_cells] = np.argsort(self.cell_order)
        return out

    def _check_shapes(self, n: int, c: int, n_lm: int) -> None:
        rows = int(self.cell_row_offsets[-1]) if len(self.cell_row_offsets) else -1
        dims = {"N": n, "C": c, "L": n_lm, "R": rows}
        for name in _CHECKED_SHAPES:
            shape = _MAP_ARRAYS[name][1] if name in _MAP_ARRAYS else _PLAN[name].resolve(dims)
            if getattr(self, name).shape != shape:
                raise ArtifactError(f"expected shape {shape}, got {getattr(self, name).shape}", field=name)
        if self.cell_row_offsets[0] != 0 or np.any(np.diff(self.cell_row_offsets) < 1):
            raise ArtifactError("offsets must start at 0 and give every cell a row", field="cell_row_offsets")
        for name in ("landmarks", "nodes", "cell_A", "cell_b", "exit_point", "exit_dir", "gain", "u_max", "bounds"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ArtifactError("contains NaN or infinity", field=name)

    @property
    def n_cells(self) -> int:
        return len(self.cell_node)

    @property
    def funnel(self) -> bool:
        """Whether the plan's cells compose (ALGORITHMS §11): the least-rank policy applies."""
        return self.certificate == "funnel"

    def tolerance_in(self, cell: np.ndarray) -> np.ndarray:
        """``τ_c`` of each robot's active cell (ALGORITHMS §12.3), shape (R,), map units.

        Parameters
        ----------
        cell : ndarray of int, shape (R,)
            Active cells; ``-1`` (no cell) gets the plan's ``min_c τ_c``.

        Returns
        -------
        ndarray, shape (R,)
            NaN for ``paper`` plans.
        """
        cell = np.asarray(cell, np.int64).reshape(-1)
        return np.where(cell >= 0, self.usable_tolerance[np.maximum(cell, 0)], self.plan_tolerance)

    @property
    def goal_cell(self) -> int:
        """The root's cell (no exit; the run ends on success there)."""
        return int(self.node_cell[np.flatnonzero(self.parent == -1)[0]])

    @classmethod
    def from_plan(cls, plan: Any) -> PlanArrays:
        """Take the run-time arrays from a :class:`~bearnav_cli.datatypes.Plan` (duck-typed): the same
        entries ``plan.npz`` stores, read as :meth:`from_npz` reads them."""
        data = plan.arrays()
        return cls._from_entries({key: data[key] for key in RUNTIME_KEYS}, plan.map.to_json())

    @classmethod
    def from_npz(cls, path: str | Path) -> PlanArrays:
        """Load the run-time arrays from a ``plan.npz`` file, after every check of
        :func:`~bearnav_cli.runtime.plan_file.load_plan` (manifest, entries, content hash, the
        plan's invariants: the ones ``bearnav inspect`` makes, but for the map's shapely checks).

        Raises
        ------
        ArtifactError
            Naming the file (and the field): a damaged or edited file, or a plan that makes no sense.
        """
        return cls.from_loaded(plan_file.load_plan(path))

    @classmethod
    def from_loaded(cls, loaded: plan_file.LoadedPlan) -> PlanArrays:
        """The run-time arrays of a plan :func:`~bearnav_cli.runtime.plan_file.load_plan` has read."""
        entries = {key: loaded.entries[key] for key in RUNTIME_KEYS}
        return cls._from_entries(entries, loaded.map, str(loaded.path))

    @classmethod
    def _from_entries(cls, entries: dict[str, Any], map_json: Any, file: str | None = None) -> PlanArrays:
        """Build from the ``RUNTIME_KEYS`` entries and the embedded map (bounds, radius, obstacle rings):
        its JSON document or :class:`~bearnav_cli.runtime.plan_file.EmbeddedMap`."""
        entries = dict(entries)
        map_ = map_json if isinstance(map_json, plan_file.EmbeddedMap) else plan_file.embedded_map(map_json, file)
        for key in RUNTIME_KEYS:
            if _PLAN[key].ndim == 0:  # 0-d arrays in the file: a number, or the certificate's text
                entries[key] = str(entries[key]) if _PLAN[key].dtype == "str" else float(entries[key])
        try:
            return cls(
                bounds=map_.bounds,
                obstacle_edges=ring_edges(map_.obstacles),
                sight_edges=ring_edges(map_.raw_obstacles),
                robot_radius=map_.robot_radius,
                **entries,
            )
        except ArtifactError as exc:
            raise exc.located(file) if file else exc from None


def ring_edges(polygons: list[tuple[np.ndarray, ...]]) -> np.ndarray:
    """Every edge of every ring (exterior and holes, each without the closing repeat), shape (E, 2, 2)."""
    edges = [np.zeros((0, 2, 2))]
    for rings in polygons:
        for ring in rings:
            ring = np.asarray(ring, float).reshape(-1, 2)
            if len(ring) >= 2:
                edges.append(np.stack([ring, np.roll(ring, -1, axis=0)], axis=1))
    return np.concatenate(edges)


def _padded(A: np.ndarray, b: np.ndarray, offsets: np.ndarray, fill: float) -> tuple[np.ndarray, np.ndarray]:
    """Ragged rows (coords + offsets) as arrays (C, P, 2) and (C, P), padded with ``0·x`` and ``fill``."""
    c = len(offsets) - 1
    counts = np.diff(offsets)
    width = int(counts.max()) if c > 0 and len(counts) else 0
    out_A = np.zeros((c, width, 2))
    out_b = np.full((c, width), fill)
    cell_of_row = np.repeat(np.arange(c), counts)
    slot = np.arange(len(b)) - offsets[cell_of_row]
    out_A[cell_of_row, slot] = A
    out_b[cell_of_row, slot] = b
    return out_A, out_b


def tree_costs(nodes: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """Length of the tree path from every node to the root, shape (N,), by pointer doubling.

    Invariant: ``cost[i]`` is the tree distance from ``i`` to ``up[i]``; each round doubles
    the jump, so ``O(log depth)`` rounds reach the root (whose ``up`` is itself).

    Raises
    ------
    ArtifactError
        ``parent`` has a cycle.
    """
    n = len(nodes)
    up = np.where(parent >= 0, parent, np.arange(n))
    cost = np.hypot(*(nodes - nodes[up]).T)
    for _ in range(n.bit_length() + 1):
        # a fixed point is the end only if every jump lands on a root: on a cycle of length 2^k,
        # k doublings make every node its own ancestor, a fixed point too
        if np.array_equal(up, up[up]):
            if np.all(parent[up] == -1):
                return cost
            break
        cost = cost + cost[up]
        up = up[up]
    raise ArtifactError("parent does not describe a tree", field="parent")
