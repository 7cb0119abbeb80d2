"""The arrays of a ``plan.npz`` that a robot needs, loaded with numpy only (DESIGN §3.2, §6).

:class:`PlanArrays` is the run-time view of a plan: the contract keys of DESIGN §3.2 that
a controller uses, plus arrays derived once on loading (each cell's affine field, padded
cell and barrier rows for vectorised tests, the route length from each exit point, the
obstacle edges of the embedded map). :mod:`bearnav_cli.runtime` builds on it.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bearnav_cli.errors import ArtifactError

__all__ = [
    "CHUNK", "INDEX_BINS", "PlanArrays", "ring_edges", "RUNTIME_KEYS", "tree_costs",
]

log = logging.getLogger(__name__)

#: Largest number of robot × node distances computed at once by :func:`voronoi_owner`.
CHUNK = 1 << 20

#: ``plan.npz`` entries a robot needs (DESIGN §3.2).
RUNTIME_KEYS = (
    "landmarks", "nodes", "parent", "cell_node", "cell_A", "cell_b", "cell_row_offsets", "exit_point",
    "exit_dir", "gain", "u_max", "goal_tolerance", "cell_landmarks", "fixed_landmark", "status",
    "cbf_A", "cbf_b", "cbf_offsets", "certificate", "cell_rank", "tolerance", "plan_tolerance", "exit_inset",
    "cell_vertices", "cell_vertex_offsets", "c_h", "c_v",
)  # fmt: skip

#: The cell index of :class:`PlanArrays`: at most this many bins along each side of the bounds.
INDEX_BINS = 32


def _readonly(value: Any, dtype: Any) -> np.ndarray:
    array = np.array(value, dtype=dtype, copy=True)
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class PlanArrays:
    """The arrays of a plan that a controller needs at run time.

    N tree nodes, C cells, L landmarks, R half-plane rows. Build it with
    :meth:`from_npz` (a ``plan.npz`` file) or :meth:`from_plan` (a
    :class:`~bearnav_cli.datatypes.Plan` in memory).

    Attributes
    ----------
    landmarks : ndarray, shape (L, 2)
        Landmark positions (map units).
    nodes : ndarray, shape (N, 2)
        Tree nodes; the root (``parent == -1``) is the goal.
    parent : ndarray of int64, shape (N,)
        Parent of each node, ``-1`` at the root.
    cell_node : ndarray of int64, shape (C,)
        Node owning each cell; every node owns exactly one cell.
    cell_A, cell_b : ndarray, shapes (R, 2), (R,)
        Cell ``c`` is ``{x : A x <= b}`` over its rows ``cell_row_offsets[c]:cell_row_offsets[c + 1]``.
    cell_row_offsets : ndarray of int64, shape (C + 1,)
    exit_point, exit_dir : ndarray, shape (C, 2)
        ``x_j`` and the unit ``z`` into the cell: ``V(x) = z·(x − x_j)``; zeros for the goal cell.
    gain : ndarray, shape (C, 2, 2L)
        ``u = gain[c] @ y`` with ``y = (landmarks − x).ravel()`` (or its bearing reconstruction).
    u_max : ndarray, shape (C,)
        Input bound of each cell's certificate (map units / s).
    goal_tolerance : float
        Success radius around the goal (map units).
    bounds : ndarray, shape (4,)
        ``[xmin, ymin, xmax, ymax]``.
    cell_landmarks : ndarray of bool, shape (C, L)
        Landmarks each cell's controller uses.
    fixed_landmark : ndarray of int64, shape (C,)
        Landmark that rescales bearings in each cell.
    status : ndarray of int8, shape (C,)
        Synthesis status of each cell (``CellStatus`` values).
    cbf_A, cbf_b, cbf_offsets : ndarray, shapes (H, 2), (H,), (C + 1,)
        Barrier rows ``h(x) = A x + b`` of each cell, safe where every ``h >= 0``.
    obstacle_edges : ndarray, shape (E, 2, 2)
        Every ring edge of the inflated obstacles (from the embedded map), for the exact
        straight-line checks of :func:`approach_target`.
    sight_edges : ndarray, shape (E', 2, 2)
        Every ring edge of the raw obstacles: what hides a landmark (``cell_policy.in_sight``).
    certificate : {"funnel", "paper"}
        ``funnel``: the cells compose and the policy is ALGORITHMS §11.3's (least rank).
    cell_rank : ndarray, shape (C,)
        Rank of each cell (cost-to-go of its node).
    tolerance : ndarray, shape (C,)
        ``δ_c`` of each cell (NaN for ``paper``).
    plan_tolerance : float
        ``δ*``: a step whose position error bound is at most this is certified (NaN for ``paper``).
    exit_inset : float
        ``δ_e`` (map units).
    robot_radius : float
        ρ (map units): the walls of the straight-line checks are ``B_r``, the bounds less ρ.
    cell_vertices, cell_vertex_offsets : ndarray, shapes (V, 2), (C + 1,)
        The cells as polygons (their bounding boxes index them, see ``bin_cells``).
    c_h, c_v : ndarray, shape (C,)
        The certificate's constants (1/s; ``c_h`` NaN without barrier rows): the unicycle's
        heading allowance (:func:`bearnav_cli.runtime.step.heading_allowance`) needs the margins.

    Derived attributes (computed on construction): ``goal`` (2,), ``free_bounds`` (4,) ``B_r``,
    ``tol`` (``1e-9·D``),
    ``node_cell`` (N,) the cell of each node, ``parent_cell`` (C,) the cell a cell switches
    to (``-1`` for the goal cell), ``field_a`` (C, 2) and ``field_M`` (C, 2, 2) with
    ``gain[c] @ (landmarks − x).ravel() = field_a[c] − field_M[c] @ x``, and the rows padded
    to ``row_A`` (C, P, 2), ``row_b`` (C, P) for vectorised membership tests, the barrier rows
    padded the same way to ``bar_A`` (C, Q, 2), ``bar_b`` (C, Q) (padding rows ``0·x + inf``),
    ``node_cost`` (N,): the tree route length from each node to the goal, and ``cost_to_go``
    (C,): the same from each cell's exit point.
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
    exit_inset: float
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
        for name, dtype in (
            ("landmarks", float), ("nodes", float), ("parent", np.int64), ("cell_node", np.int64),
            ("cell_A", float), ("cell_b", float), ("cell_row_offsets", np.int64), ("exit_point", float),
            ("exit_dir", float), ("gain", float), ("u_max", float), ("bounds", float), ("cell_landmarks", bool),
            ("fixed_landmark", np.int64), ("status", np.int8), ("cbf_A", float), ("cbf_b", float),
            ("cbf_offsets", np.int64), ("obstacle_edges", float), ("sight_edges", float), ("cell_rank", float),
            ("tolerance", float),
            ("cell_vertices", float), ("cell_vertex_offsets", np.int64), ("c_h", float), ("c_v", float),
        ):  # fmt: skip
            put(self, name, _readonly(getattr(self, name), dtype))
        for name in ("goal_tolerance", "plan_tolerance", "exit_inset", "robot_radius"):
            put(self, name, float(getattr(self, name)))
        put(self, "certificate", str(self.certificate))
        r = max(0.0, self.robot_radius)
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

    def cells_near(self, x: np.ndarray) -> np.ndarray:
        """Candidate cells of each point (those whose bounding box meets its bin), shape (R, K), padded with ``-1``,
        in (rank, index) order."""
        p = np.asarray(x, float).reshape(-1, 2)
        ij = np.clip(np.floor((p - self.bin_origin) / self.bin_size).astype(np.int64), 0, np.array(self.bin_shape) - 1)
        return self.bin_cells[ij[:, 0] * self.bin_shape[1] + ij[:, 1]]

    def _check_shapes(self, n: int, c: int, n_lm: int) -> None:
        rows = int(self.cell_row_offsets[-1]) if len(self.cell_row_offsets) else -1
        expected = {
            "landmarks": (n_lm, 2), "nodes": (n, 2), "parent": (n,), "cell_node": (c,), "cell_A": (rows, 2),
            "cell_b": (rows,), "cell_row_offsets": (c + 1,), "exit_point": (c, 2), "exit_dir": (c, 2),
            "gain": (c, 2, 2 * n_lm), "u_max": (c,), "bounds": (4,), "cell_landmarks": (c, n_lm),
            "fixed_landmark": (c,), "status": (c,), "c_h": (c,), "c_v": (c,),
        }  # fmt: skip
        for name, shape in expected.items():
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
        """Load the run-time arrays from a ``plan.npz`` file (``allow_pickle=False``).

        The bounds come from the embedded ``map`` JSON. This loader does not check the
        manifest or the content hash (``bearnav inspect`` does).

        Raises
        ------
        ArtifactError
            A missing entry, a wrong shape, or a file numpy cannot read.
        """
        try:
            with np.load(path, allow_pickle=False) as data:
                manifest = json.loads(str(data["manifest"][()])) if "manifest" in data.files else {}
                if isinstance(manifest, dict) and manifest.get("schema") == "bearnav.plan/1":
                    raise ArtifactError("is a bearnav.plan/1 plan, which this version no longer reads; re-run "
                                        "`bearnav plan MAP.yaml --force`", file=str(path))  # fmt: skip
                missing = [key for key in (*RUNTIME_KEYS, "map") if key not in data.files]
                if missing:
                    raise ArtifactError(f"missing entries {', '.join(missing)}", file=str(path))
                entries = {key: np.array(data[key]) for key in RUNTIME_KEYS}
                map_json = json.loads(str(data["map"][()]))
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
            if isinstance(exc, ArtifactError):
                raise
            raise ArtifactError(f"cannot read plan ({type(exc).__name__}: {exc})", file=str(path)) from exc
        return cls._from_entries(entries, map_json, str(path))

    @classmethod
    def _from_entries(cls, entries: dict[str, Any], map_json: dict, file: str | None = None) -> PlanArrays:
        """Build from the ``RUNTIME_KEYS`` entries and the embedded map (bounds, radius, obstacle rings)."""
        entries = dict(entries)
        try:
            bounds = np.asarray(map_json["bounds"], float)
            radius = float(map_json.get("robot_radius", 0.0))
            rings, sight = (
                [(np.asarray(o["exterior"], float), *(np.asarray(h, float) for h in o.get("holes", ())))
                 for o in map_json[key]]
                for key in ("obstacles", "raw_obstacles")
            )  # fmt: skip
        except (KeyError, TypeError, ValueError) as exc:
            raise ArtifactError("embedded map has no bounds or obstacles", file=file, field="map") from exc
        for key in ("goal_tolerance", "plan_tolerance", "exit_inset"):
            entries[key] = float(entries[key])
        entries["certificate"] = str(entries["certificate"])
        return cls(bounds=bounds, obstacle_edges=ring_edges(rings), sight_edges=ring_edges(sight), robot_radius=radius,
                   **entries)  # fmt: skip


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
        if np.array_equal(up, up[up]):
            return cost
        cost = cost + cost[up]
        up = up[up]
    raise ArtifactError("parent does not describe a tree", field="parent")
