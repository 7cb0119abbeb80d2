"""The robot-side part of a plan: cell location, switching and the field (DESIGN §6, ALGORITHMS §7.3).

This module needs numpy only (and :mod:`bearnav_cli.errors`, which needs nothing), so it
can be copied onto a robot next to ``plan.npz``. ``bearnav simulate`` and ``bearnav
verify`` call exactly these functions, so what is simulated is what runs on the robot.

Everything is vectorised over ``R`` robots: positions are arrays of shape ``(R, 2)``,
cells are ``int64`` arrays of shape ``(R,)``. A single robot is ``R = 1``.

:class:`PlanArrays` holds the arrays a controller needs at run time. On top of it:

- :func:`contains` — is ``x`` in cell ``c`` (within a tolerance);
- :func:`voronoi_owner` — the cell of the nearest tree node, which always contains
  the point (ALGORITHMS §4.1, Lemma 2);
- :func:`locate` — the cell to use at a point: one whose safe set holds it, on the
  shortest route (docs/algorithms.md);
- :func:`switch` — the switching and relocation rule of ALGORITHMS §7.3, relocating by
  :func:`locate`;
- :func:`apply_gain` / :func:`field` — ``u = gain[c] @ y`` for an output ``y``; with the
  displacement output ``y = (landmarks − x).ravel()`` this is the certified affine field.

The bearing reconstruction (``bearing`` module) produces the scaled output ``ỹ`` and an
estimate ``x̂``; a controller then calls ``switch(arrays, cell, x̂, ...)`` and
``apply_gain(arrays, cell, ỹ)``.
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

log = logging.getLogger(__name__)

#: Largest number of robot × node distances computed at once by :func:`voronoi_owner`.
_CHUNK = 1 << 20

#: ``plan.npz`` entries a robot needs (DESIGN §3.2).
RUNTIME_KEYS = (
    "landmarks", "nodes", "parent", "cell_node", "cell_A", "cell_b", "cell_row_offsets", "exit_point",
    "exit_dir", "gain", "u_max", "goal_tolerance", "cell_landmarks", "fixed_landmark", "status",
    "cbf_A", "cbf_b", "cbf_offsets",
)  # fmt: skip


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

    Derived attributes (computed on construction): ``goal`` (2,), ``tol`` (``1e-9·D``),
    ``node_cell`` (N,) the cell of each node, ``parent_cell`` (C,) the cell a cell switches
    to (``-1`` for the goal cell), ``field_a`` (C, 2) and ``field_M`` (C, 2, 2) with
    ``gain[c] @ (landmarks − x).ravel() = field_a[c] − field_M[c] @ x``, and the rows padded
    to ``row_A`` (C, P, 2), ``row_b`` (C, P) for vectorised membership tests, the barrier rows
    padded the same way to ``bar_A`` (C, Q, 2), ``bar_b`` (C, Q) (padding rows ``0·x + inf``),
    and ``cost_to_go`` (C,): the tree route length from each cell's exit point to the goal.
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
    goal: np.ndarray = dataclasses.field(init=False, repr=False)
    tol: float = dataclasses.field(init=False, repr=False)
    node_cell: np.ndarray = dataclasses.field(init=False, repr=False)
    parent_cell: np.ndarray = dataclasses.field(init=False, repr=False)
    field_a: np.ndarray = dataclasses.field(init=False, repr=False)
    field_M: np.ndarray = dataclasses.field(init=False, repr=False)
    row_A: np.ndarray = dataclasses.field(init=False, repr=False)
    row_b: np.ndarray = dataclasses.field(init=False, repr=False)
    bar_A: np.ndarray = dataclasses.field(init=False, repr=False)
    bar_b: np.ndarray = dataclasses.field(init=False, repr=False)
    cost_to_go: np.ndarray = dataclasses.field(init=False, repr=False)

    def __post_init__(self) -> None:
        put = object.__setattr__
        for name, dtype in (
            ("landmarks", float), ("nodes", float), ("parent", np.int64), ("cell_node", np.int64),
            ("cell_A", float), ("cell_b", float), ("cell_row_offsets", np.int64), ("exit_point", float),
            ("exit_dir", float), ("gain", float), ("u_max", float), ("bounds", float), ("cell_landmarks", bool),
            ("fixed_landmark", np.int64), ("status", np.int8), ("cbf_A", float), ("cbf_b", float),
            ("cbf_offsets", np.int64),
        ):  # fmt: skip
            put(self, name, _readonly(getattr(self, name), dtype))
        put(self, "goal_tolerance", float(self.goal_tolerance))
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
        put(self, "cost_to_go", _readonly(np.where(up >= 0, node_cost[np.maximum(up, 0)], 0.0), float))

    def _check_shapes(self, n: int, c: int, n_lm: int) -> None:
        rows = int(self.cell_row_offsets[-1]) if len(self.cell_row_offsets) else -1
        expected = {
            "landmarks": (n_lm, 2), "nodes": (n, 2), "parent": (n,), "cell_node": (c,), "cell_A": (rows, 2),
            "cell_b": (rows,), "cell_row_offsets": (c + 1,), "exit_point": (c, 2), "exit_dir": (c, 2),
            "gain": (c, 2, 2 * n_lm), "u_max": (c,), "bounds": (4,), "cell_landmarks": (c, n_lm),
            "fixed_landmark": (c,), "status": (c,),
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
    def goal_cell(self) -> int:
        """The root's cell (no exit; the run ends on success there)."""
        return int(self.node_cell[np.flatnonzero(self.parent == -1)[0]])

    @classmethod
    def from_plan(cls, plan: Any) -> PlanArrays:
        """Take the run-time arrays from a :class:`~bearnav_cli.datatypes.Plan` (duck-typed)."""
        cells = plan.cells
        return cls(
            landmarks=plan.cells.map.landmarks,
            nodes=cells.nodes,
            parent=cells.parent,
            cell_node=cells.cell_node,
            cell_A=cells.cell_A,
            cell_b=cells.cell_b,
            cell_row_offsets=cells.cell_row_offsets,
            exit_point=cells.exit_point,
            exit_dir=cells.exit_dir,
            gain=plan.gain,
            u_max=plan.u_max,
            goal_tolerance=plan.goal_tolerance,
            bounds=cells.map.bounds,
            cell_landmarks=cells.cell_landmarks,
            fixed_landmark=cells.fixed_landmark,
            status=plan.status,
            cbf_A=cells.cbf_A,
            cbf_b=cells.cbf_b,
            cbf_offsets=cells.cbf_offsets,
        )

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
                missing = [key for key in (*RUNTIME_KEYS, "map") if key not in data.files]
                if missing:
                    raise ArtifactError(f"missing entries {', '.join(missing)}", file=str(path))
                entries = {key: np.array(data[key]) for key in RUNTIME_KEYS}
                map_json = json.loads(str(data["map"][()]))
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
            if isinstance(exc, ArtifactError):
                raise
            raise ArtifactError(f"cannot read plan ({type(exc).__name__}: {exc})", file=str(path)) from exc
        try:
            bounds = np.asarray(map_json["bounds"], float)
        except (KeyError, TypeError, ValueError) as exc:
            raise ArtifactError("embedded map has no bounds", file=str(path), field="map") from exc
        entries["goal_tolerance"] = float(entries["goal_tolerance"])
        return cls(bounds=bounds, **entries)


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


# --------------------------------------------------------------------------- vectorised queries


def _cells(arrays: PlanArrays, cell: Any) -> np.ndarray:
    return np.asarray(cell, np.int64).reshape(-1)


def _points(x: Any) -> np.ndarray:
    return np.asarray(x, float).reshape(-1, 2)


def contains(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray, tol: float | None = None) -> np.ndarray:
    """Whether each robot lies in its cell: ``A_c x <= b_c + tol`` for every row.

    Parameters
    ----------
    arrays : PlanArrays
    cell : ndarray of int, shape (R,)
    x : ndarray, shape (R, 2)
        Positions (map units).
    tol : float, optional
        Slack on every row (map units); default ``arrays.tol`` (``1e-9·D``).

    Returns
    -------
    ndarray of bool, shape (R,)
    """
    c, p = _cells(arrays, cell), _points(x)
    tol = arrays.tol if tol is None else tol
    lhs = np.einsum("rpk,rk->rp", arrays.row_A[c], p)
    return np.all(lhs <= arrays.row_b[c] + tol, axis=1)


def nearest_node(arrays: PlanArrays, x: np.ndarray) -> np.ndarray:
    """Index of the tree node nearest to each point (ties: lowest index), shape (R,).

    Distances are computed in chunks of robots × nodes, as differences (not through
    ``‖p‖² − 2p·x + ‖x‖²``, which loses the ties on Voronoi boundaries).
    """
    p = _points(x)
    nodes = arrays.nodes
    out = np.empty(len(p), np.int64)
    step = max(1, _CHUNK // max(1, len(nodes)))
    for s in range(0, len(p), step):
        d = p[s : s + step, None, :] - nodes[None, :, :]
        out[s : s + step] = np.argmin(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1], axis=1)
    return out


def voronoi_owner(arrays: PlanArrays, x: np.ndarray) -> np.ndarray:
    """The cell of the nearest tree node, which contains the point (Lemma 2), shape (R,)."""
    return arrays.node_cell[nearest_node(arrays, x)]


def lyapunov(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``V_c(x) = z_c·(x − x_j)``, shape (R,); identically 0 in the goal cell."""
    c, p = _cells(arrays, cell), _points(x)
    return np.einsum("rk,rk->r", arrays.exit_dir[c], p - arrays.exit_point[c])


def barrier_values(arrays: PlanArrays, x: np.ndarray) -> np.ndarray:
    """``min_k h_k(x)`` over every cell's barrier rows, shape (R, C); ``inf`` for a cell without rows.

    ``>= 0`` exactly when ``x`` lies in the cell's safe set.
    """
    p = _points(x)
    return np.min(np.einsum("cqk,rk->rcq", arrays.bar_A, p) + arrays.bar_b[None], axis=2, initial=math.inf)


def locate(arrays: PlanArrays, x: np.ndarray, tol: float | None = None) -> np.ndarray:
    """The cell a robot at ``x`` should use, shape (R,): safety first, then the shortest route.

    Cells overlap, so a point lies in several. Candidates are the cells that contain
    ``x`` and, for edge cells, have ``V(x) > tol`` (a robot on an exit face would leave at
    once). Among the candidates whose safe set contains ``x`` (every barrier row
    ``h(x) >= 0``), take the one with the shortest remaining tree route
    ``‖x − x_j‖ + cost(x_j)`` (``‖x − g‖`` for the goal cell); if there is none, the one
    whose barrier rows are least violated (largest ``min_k h_k(x)``): the rows never
    decrease while negative, so that cell keeps the robot farthest behind its obstacle
    lines. Without any candidate, the Voronoi owner (which contains ``x``, Lemma 2).

    Parameters
    ----------
    arrays : PlanArrays
    x : ndarray, shape (R, 2)
        Positions or their estimates (map units).
    tol : float, optional
        Membership slack (map units); default ``arrays.tol``.
    """
    p = _points(x)
    tol = arrays.tol if tol is None else tol
    inside = np.all(np.einsum("cpk,rk->rcp", arrays.row_A, p) <= arrays.row_b[None] + tol, axis=2)
    gap = p[:, None, :] - arrays.exit_point[None]
    edge = arrays.parent_cell >= 0
    leaving = edge[None] & (np.einsum("ck,rck->rc", arrays.exit_dir, gap) <= tol)
    candidate = inside & ~leaving
    h = np.where(candidate, barrier_values(arrays, p), -math.inf)
    route = np.where(edge[None], np.hypot(gap[..., 0], gap[..., 1]) + arrays.cost_to_go[None], 0.0)
    route = np.where(edge[None], route, np.hypot(*(p - arrays.goal).T)[:, None])
    safe = candidate & (h >= 0)
    best_safe = np.argmin(np.where(safe, route, math.inf), axis=1)
    least_violated = np.argmax(h, axis=1)
    rows = np.arange(len(p))
    chosen = np.where(safe.any(axis=1), best_safe, least_violated)
    if not candidate[rows, chosen].all():
        lost = ~candidate[rows, chosen]
        chosen[lost] = voronoi_owner(arrays, p[lost])
    return chosen


def switch(
    arrays: PlanArrays, cell: np.ndarray, x: np.ndarray, eps_sw: float, tol: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Switching and relocation (ALGORITHMS §7.3 with the safety rule of docs/algorithms.md), for every robot.

    An edge cell ``i → j`` hands over to the cell of ``j`` when ``V(x) <= 0`` or
    ``‖x − x_j‖ <= eps_sw``. If ``x`` then lies outside the (new) cell by more than
    ``tol``, or the hand-over lands outside the parent cell's safe set, the robot is
    relocated by :func:`locate`. One switch per call: a robot that is also at the next
    exit switches again on the next call.

    Parameters
    ----------
    arrays : PlanArrays
    cell : ndarray of int, shape (R,)
        Active cell of each robot.
    x : ndarray, shape (R, 2)
        Position, or its estimate ``x̂`` (map units).
    eps_sw : float
        Switching radius around ``x_j`` (map units; ``2·v·dt`` in ``simulate``).
    tol : float, optional
        Membership slack (map units); default ``arrays.tol``.

    Returns
    -------
    new_cell : ndarray of int64, shape (R,)
    relocated : ndarray of bool, shape (R,)
        Robots found outside their (new) cell and relocated (each one is a ``left_cell``
        event; a hand-over moved on to a safer cell is not).
    """
    c, p = _cells(arrays, cell).copy(), _points(x)
    up = arrays.parent_cell[c]
    edge = up >= 0
    handed = np.zeros(len(c), bool)
    if edge.any():
        ce, pe = c[edge], p[edge]
        gap = pe - arrays.exit_point[ce]
        value = np.einsum("rk,rk->r", arrays.exit_dir[ce], gap)
        hand_over = (value <= 0.0) | (gap[:, 0] * gap[:, 0] + gap[:, 1] * gap[:, 1] <= eps_sw * eps_sw)
        handed[np.flatnonzero(edge)[hand_over]] = True
        c[handed] = up[edge][hand_over]
    outside = ~contains(arrays, c, p, tol)
    unsafe = handed & ~outside
    if unsafe.any():
        idx = np.flatnonzero(unsafe)
        rows = np.einsum("rqk,rk->rq", arrays.bar_A[c[idx]], p[idx]) + arrays.bar_b[c[idx]]
        unsafe[idx] = np.min(rows, axis=1, initial=math.inf) < 0
    move = outside | unsafe
    if move.any():
        c[move] = locate(arrays, p[move], tol)
    return c, outside


def displacement(arrays: PlanArrays, x: np.ndarray) -> np.ndarray:
    """The displacement output ``y = (landmarks − x).ravel()`` of each robot, shape (R, 2L)."""
    p = _points(x)
    return (arrays.landmarks[None, :, :] - p[:, None, :]).reshape(len(p), 2 * len(arrays.landmarks))


def apply_gain(arrays: PlanArrays, cell: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``u = gain[c] @ y`` for each robot, shape (R, 2).

    Parameters
    ----------
    cell : ndarray of int, shape (R,)
    y : ndarray, shape (R, 2L)
        The output: displacements to every landmark, or their bearing reconstruction
        scaled by the fixed landmark's distance (columns of unused landmarks are ignored,
        their gain is zero).
    """
    c = _cells(arrays, cell)
    return np.einsum("rij,rj->ri", arrays.gain[c], np.asarray(y, float).reshape(len(c), arrays.gain.shape[2]))


def field(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The certified field ``u = gain[c] @ (landmarks − x).ravel()``, shape (R, 2), map units / s."""
    return apply_gain(arrays, cell, displacement(arrays, x))


def affine_field(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The same field through its affine form ``a_c − M_c x``, shape (R, 2).

    Equal to :func:`field` up to rounding; the stall test (ALGORITHMS §7.2) uses it
    with the position estimate ``x̂`` whatever the output mode.
    """
    c, p = _cells(arrays, cell), _points(x)
    return arrays.field_a[c] - np.einsum("rij,rj->ri", arrays.field_M[c], p)
