"""Where a robot is and which cell's controller it uses (ALGORITHMS §7.3 with docs/choices.md).

Numpy only. Everything is vectorised over ``R`` robots: positions are arrays of shape
``(R, 2)``, cells ``int64`` arrays of shape ``(R,)``. On top of :class:`PlanArrays`:

- :func:`contains` — is ``x`` in cell ``c`` (within a tolerance);
- :func:`voronoi_owner` — the cell of the nearest tree node, which always contains the
  point (ALGORITHMS §4.1, Lemma 2);
- :func:`locate` — the cell to use at a point: one whose safe set holds it, on the
  shortest route;
- :func:`switch` — hand-over at the exit face and relocation (ALGORITHMS §7.3);
- :func:`approach_target` — the straight approach to a tree node from outside every safe set
  (its exact segment test is :func:`~bearnav_cli.runtime.sight.segments_clear`);
- :func:`update` — the whole cell policy of one step;
- :func:`apply_gain` / :func:`field` — ``u = gain[c] @ y``; with the displacement output
  ``y = (landmarks − x).ravel()`` this is the certified affine field.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bearnav_cli.runtime import bounded, sight
from bearnav_cli.runtime.plan_arrays import CHUNK, PlanArrays
from bearnav_cli.runtime.planar import points
from bearnav_cli.runtime.sight import segments_clear

__all__ = [
    "affine_field",
    "apply_gain",
    "approach_target",
    "barrier_values",
    "cell_slack",
    "contains",
    "displacement",
    "field",
    "funnel_update",
    "in_safe_set",
    "least_rank_cell",
    "least_rank_cell_holding",
    "locate",
    "nearest_node",
    "switch",
    "update",
    "voronoi_owner",
]


# --------------------------------------------------------------------------- vectorised queries


def _cells(arrays: PlanArrays, cell: Any) -> np.ndarray:
    return np.asarray(cell, np.int64).reshape(-1)


def contains(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray, tol: float | None = None) -> np.ndarray:
    """Whether each robot lies in its cell: ``A_c x <= b_c + tol`` for every row.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: each cell's half-plane rows ``A_c``, ``b_c`` (padded).
    cell : ndarray of int, shape (R,)
        The cell each robot is tested against.
    x : ndarray, shape (R, 2)
        Positions (map units).
    tol : float, optional
        Slack on every row (map units); default ``arrays.tol`` (``1e-9·D``).

    Returns
    -------
    ndarray of bool, shape (R,)
    """
    c, p = _cells(arrays, cell), points(x)
    tol = arrays.tol if tol is None else tol
    lhs = np.einsum("rpk,rk->rp", arrays.row_A[c], p)
    return np.all(lhs <= arrays.row_b[c] + tol, axis=1)


def cell_slack(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray) -> np.ndarray:
    """How deep each point lies in its cell: ``min_k (b_k − A_kᵀx)`` over the cell's real rows, shape (R,).

    Map units (rows are unit); negative outside the cell. ``x`` is in ``P_c ⊖ δ`` exactly where
    this is at least ``δ``.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: each cell's half-plane rows (padded; the padding rows do not count).
    cell : ndarray of int, shape (R,)
        The cell each point is measured in.
    x : ndarray, shape (R, 2)
        Points (map units).
    """
    c, p = _cells(arrays, cell), points(x)
    slack = arrays.row_b[c] - np.einsum("rpk,rk->rp", arrays.row_A[c], p)
    real = np.arange(arrays.row_A.shape[1]) < np.diff(arrays.cell_row_offsets)[c][:, None]
    return np.min(np.where(real, slack, math.inf), axis=1, initial=math.inf)


def nearest_node(arrays: PlanArrays, x: np.ndarray) -> np.ndarray:
    """Index of the tree node nearest to each point (ties: lowest index), shape (R,).

    Distances are computed in chunks of robots × nodes, as differences (not through
    ``‖p‖² − 2p·x + ‖x‖²``, which loses the ties on Voronoi boundaries).
    """
    p = points(x)
    nodes = arrays.nodes
    out = np.empty(len(p), np.int64)
    step = max(1, CHUNK // max(1, len(nodes)))
    for s in range(0, len(p), step):
        d = p[s : s + step, None, :] - nodes[None, :, :]
        out[s : s + step] = np.argmin(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1], axis=1)
    return out


def voronoi_owner(arrays: PlanArrays, x: np.ndarray) -> np.ndarray:
    """The cell of the nearest tree node, which contains the point (Lemma 2), shape (R,)."""
    return arrays.node_cell[nearest_node(arrays, x)]


def barrier_values(arrays: PlanArrays, x: np.ndarray, where: np.ndarray | None = None) -> np.ndarray:
    """``min_k h_k(x)`` over every cell's barrier rows, shape (R, C); ``inf`` for a cell without rows.

    ``>= 0`` exactly when ``x`` lies in the cell's safe set. With ``where`` (bool, (R, C)) only
    those pairs are evaluated (a point lies in a handful of the C cells) and the rest are ``-inf``.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: every cell's barrier rows ``h(x) = A x + b`` (padded).
    x : ndarray, shape (R, 2)
        Positions or their estimates (map units); ``h`` is in map units.
    where : ndarray of bool, shape (R, C), optional
        The (robot, cell) pairs to evaluate; default all.
    """
    p = points(x)
    if where is None:
        return np.min(np.einsum("cqk,rk->rcq", arrays.bar_A, p) + arrays.bar_b[None], axis=2, initial=math.inf)
    h = np.full(where.shape, -math.inf)
    r_idx, c_idx = np.nonzero(where)
    if len(r_idx):
        rows = np.einsum("nqk,nk->nq", arrays.bar_A[c_idx], p[r_idx]) + arrays.bar_b[c_idx]
        h[r_idx, c_idx] = np.min(rows, axis=1, initial=math.inf)
    return h


def locate(arrays: PlanArrays, x: np.ndarray, tol: float | None = None, eps_sw: float = 0.0) -> np.ndarray:
    """The cell a robot at ``x`` should use, shape (R,).

    Funnel plans: the containing cell of least rank (ALGORITHMS §11.3), the Voronoi owner
    outside every cell. Paper plans: safety first, then the shortest route, as follows.

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
        The plan: cells, barrier rows, exit points and route costs (funnel plans: cell ranks).
    x : ndarray, shape (R, 2)
        Positions or their estimates (map units).
    tol : float, optional
        Membership slack (map units); default ``arrays.tol``.
    eps_sw : float
        Switching radius (map units), paper plans: an edge cell whose exit point is within it is
        no candidate either (the robot would switch at once); ignored for funnel plans.
    """
    p = points(x)
    if arrays.funnel:  # ALGORITHMS §11.3: the containing cell of least rank (the Voronoi owner outside D)
        best = least_rank_cell(arrays, p)
        outside = best < 0
        if outside.any():
            best[outside] = voronoi_owner(arrays, p[outside])
        return best
    tol = arrays.tol if tol is None else tol
    inside = np.all(np.einsum("cpk,rk->rcp", arrays.row_A, p) <= arrays.row_b[None] + tol, axis=2)
    gap = p[:, None, :] - arrays.exit_point[None]
    edge = arrays.parent_cell >= 0
    near_exit = np.einsum("rck,rck->rc", gap, gap) <= eps_sw * eps_sw
    leaving = edge[None] & ((np.einsum("ck,rck->rc", arrays.exit_dir, gap) <= tol) | near_exit)
    candidate = inside & ~leaving
    h = barrier_values(arrays, p, candidate)
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


def least_rank_cell(
    arrays: PlanArrays, x: np.ndarray, erosion: np.ndarray | float = 0.0, below: np.ndarray | None = None
) -> np.ndarray:
    """The containing cell of least rank (ties: lower index), ALGORITHMS §11.3, shape (R,); ``-1`` outside ``D``.

    Membership is tested on the cells eroded by ``erosion`` (``x ∈ P_c ⊖ δ``: every row with
    slack ``δ``), so a robot that acts on an estimate within ``δ`` of its position switches only
    where the certificate of §11.4 holds.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: cell rows, ranks and the spatial index of the cells (``cells_near``).
    x : ndarray, shape (R, 2)
        Positions or their estimates (map units).
    erosion : float or ndarray, shape (R,)
        ``δ`` of each robot (map units).
    below : ndarray, shape (R,), optional
        Only cells of rank strictly below this count (the active cell's rank: is there a cell to
        switch to?); default all.
    """
    p = points(x)
    delta = np.broadcast_to(np.asarray(erosion, float), (len(p),))
    # (R, K) in (rank, index) order, -1 padding; a cell grown by e may hold p from a bin its box does not meet
    cand = arrays.cells_near(p, np.maximum(-delta, 0.0))
    wanted = cand >= 0
    if below is not None:
        wanted &= arrays.cell_rank[np.maximum(cand, 0)] < np.asarray(below, float)[:, None]
    # only the real (robot, candidate) pairs: bins hold 16 cells on average but up to 75 (kitchen)
    r_idx, k_idx = np.nonzero(wanted)
    inside = cell_slack(arrays, cand[r_idx, k_idx], p[r_idx]) >= delta[r_idx] - arrays.tol
    return _first_candidate(cand, r_idx[inside], k_idx[inside])


def least_rank_cell_holding(
    arrays: PlanArrays, x: np.ndarray, vertices: np.ndarray, count: np.ndarray, margin: np.ndarray | float = 0.0
) -> np.ndarray:
    """The cell of least rank that holds the whole of each set, shape (R,); ``-1`` where none does.

    The truth lies in its estimate set (Lemma 5, ALGORITHMS §12.2), so a cell that holds the set
    holds the truth, and its certificate applies wherever the estimate ``x`` lies in that set. The
    test is exact (:func:`~bearnav_cli.runtime.bounded.inside_rows`: a convex set lies in a convex
    cell when its vertices do). Near a boundary between two cells no cell eroded by ``e`` may hold
    ``x`` while a third, of higher rank, holds all of the set.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: cell rows, ranks and the spatial index of the cells.
    x : ndarray, shape (R, 2)
        A point of each set (its estimate, map units): a cell that holds the set holds it, so the
        candidates are its cells.
    vertices, count : ndarray, shapes (R, W, 2), (R,)
        The padded sets (map units).
    margin : float or ndarray, shape (R,)
        Room every vertex must keep inside each row (map units): the set is grown by it.
    """
    p = points(x)
    grow = np.broadcast_to(np.asarray(margin, float), (len(p),))
    cand = arrays.cells_near(p)
    r_idx, k_idx = np.nonzero(cand >= 0)
    # a cell that does not hold x does not hold the set: the cheap test first
    near = cell_slack(arrays, cand[r_idx, k_idx], p[r_idx]) >= grow[r_idx] - arrays.tol
    r_idx, k_idx = r_idx[near], k_idx[near]
    c = cand[r_idx, k_idx]
    inside = bounded.inside_rows(vertices[r_idx], count[r_idx], arrays.row_A[c], arrays.row_b[c], grow[r_idx])
    return _first_candidate(cand, r_idx[inside], k_idx[inside])


def _first_candidate(cand: np.ndarray, r_idx: np.ndarray, k_idx: np.ndarray) -> np.ndarray:
    """The first of each row's candidates ``cand`` (R, K) among the pairs ``(r_idx, k_idx)`` that pass, shape (R,);
    candidates are in (rank, index) order, so the least rank, then the lower index; ``-1`` where none passes."""
    first = np.full(len(cand), cand.shape[1], np.int64)
    np.minimum.at(first, r_idx, k_idx)
    found = first < cand.shape[1]
    out = np.full(len(cand), -1, np.int64)
    out[found] = cand[np.flatnonzero(found), first[found]]
    return out


def funnel_update(
    arrays: PlanArrays,
    cell: np.ndarray,
    target: np.ndarray,
    x: np.ndarray,
    eps_sw: float,
    erosion: np.ndarray | float = 0.0,
    keep: np.ndarray | float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The composition policy of ALGORITHMS §11.3 for every robot (funnel plans).

    The active cell is kept while the robot is in it; whenever it lies in a cell of smaller rank
    it switches to the containing cell of least rank (at the start, the containing cell of least
    rank). A robot outside every cell (a start outside the certified domain ``D``, §11.5 step 4)
    approaches a tree node in a straight line until some cell holds it; a robot found outside its
    cell with no cell of smaller rank holding it (which the theorem rules out in continuous time)
    is relocated to the least-rank cell that holds it, or approaches a node.

    Parameters
    ----------
    arrays : PlanArrays
        A funnel plan: its cells, their ranks, tree nodes and obstacle edges (for approaches).
    cell, target : ndarray of int, shape (R,)
        Current cell (``-1`` before the first update) and approach node (``-1`` for none).
    x : ndarray, shape (R, 2)
        Positions or their estimates (map units).
    eps_sw : float
        Arrival radius of a straight approach (map units).
    erosion : float or ndarray, shape (R,)
        ``δ`` of each robot's estimate (map units): membership is tested on ``P ⊖ δ``.
    keep : float or ndarray, shape (R,), optional
        The robot stays in its cell while ``x`` lies in it grown by this (map units); default the
        membership slack ``arrays.tol``.

    Returns
    -------
    cell, target : ndarray of int64, shape (R,)
    relocated : ndarray of bool, shape (R,)
        Robots found outside their cell with no cell of smaller rank holding them.
    """
    c, t, p = _cells(arrays, cell).copy(), _cells(arrays, target).copy(), points(x)
    delta = np.broadcast_to(np.asarray(erosion, float), (len(p),)).copy()
    # for a robot in a cell only the cells of smaller rank matter (is there one to switch to?)
    following = (c >= 0) & (t < 0)
    below = np.where(following, arrays.cell_rank[np.maximum(c, 0)], np.inf)
    best = least_rank_cell(arrays, p, delta, below)
    relocated = np.zeros(len(c), bool)
    if following.any():
        idx = np.flatnonzero(following)
        grown = np.broadcast_to(np.asarray(0.0 if keep is None else keep, float), (len(p),))[idx]
        here = cell_slack(arrays, c[idx], p[idx]) >= -grown - arrays.tol
        lower = best[idx] >= 0
        out = idx[~here & ~lower]  # left its cell with no smaller rank holding it: any cell that does
        if len(out):
            best[out] = least_rank_cell(arrays, p[out], delta[out])
        relocated[idx] = ~here & ~lower
        move = lower | ~here
        c[idx[move]] = best[idx[move]]
    fresh = (c < 0) | ((t >= 0) & (best >= 0))
    c[fresh] = best[fresh]
    t[fresh & (best >= 0)] = -1
    lost = (c < 0) & (t < 0)
    if lost.any():  # outside D: a straight approach to a node (uncertified)
        t[lost] = approach_target(arrays, p[lost])
    going = t >= 0
    if going.any():
        gap = p[going] - arrays.nodes[t[going]]
        near = np.einsum("rk,rk->r", gap, gap) <= eps_sw * eps_sw
        idx = np.flatnonzero(going)[near]
        c[idx] = arrays.node_cell[t[idx]]  # the node lies strictly inside its own cell
        t[idx] = -1
    driving = (c < 0) & (t >= 0)
    c[driving] = arrays.node_cell[t[driving]]  # the cell it drives to, for the record
    return c, t, relocated


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
        The plan: cells, their parents, exit points and directions, barrier rows.
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
    c, p = _cells(arrays, cell).copy(), points(x)
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
        unsafe[idx] = ~in_safe_set(arrays, c[idx], p[idx])
    move = outside | unsafe
    if move.any():
        c[move] = locate(arrays, p[move], tol, eps_sw)
    return c, outside


def in_safe_set(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Whether each robot lies in its cell's safe set (every barrier row ``h(x) >= 0``), shape (R,).

    Parameters
    ----------
    arrays : PlanArrays
        The plan: every cell's barrier rows ``h(x) = A x + b`` (padded).
    cell : ndarray of int, shape (R,)
        The cell of each robot.
    x : ndarray, shape (R, 2)
        Positions or their estimates (map units).
    """
    c, p = _cells(arrays, cell), points(x)
    rows = np.einsum("rqk,rk->rq", arrays.bar_A[c], p) + arrays.bar_b[c]
    return np.min(rows, axis=1, initial=math.inf) >= 0


#: Nodes :func:`approach_target` tests at a time, in route order, for a robot that sees none of its nearest.
APPROACH_BATCH = 16


def approach_target(arrays: PlanArrays, x: np.ndarray, nearest: int = 8) -> np.ndarray:
    """The tree node a robot outside every safe set drives to in a straight line, shape (R,); ``-1`` if none.

    Among the ``nearest`` closest nodes (all nodes if none of those qualifies), the one with a
    clear straight segment from ``x`` and the shortest route ``‖x − x_n‖ + cost(n)``. The node
    lies strictly inside its own cell's safe set, so the robot is certified once it arrives. A
    look-ahead point (``λ > 0``) up to ``2λ`` inside an inflated obstacle gets the node of the point
    just outside its nearest edge; any other point inside one gets ``-1``.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: tree nodes, their route costs to the goal and the inflated obstacle edges.
    x : ndarray, shape (R, 2)
        Positions or their estimates (map units).
    nearest : int
        How many of the closest nodes are tried first.
    """
    p = points(x)
    out = np.full(len(p), -1, np.int64)
    if not len(p):
        return out
    nodes = arrays.nodes
    cost = arrays.node_cost
    dist = np.hypot(*(p[:, None, :] - nodes[None]).transpose(2, 0, 1))
    order = np.argsort(dist, axis=1, kind="stable")
    width = min(nearest, len(nodes))
    cand = order[:, :width]
    clear = segments_clear(arrays, np.repeat(p, width, axis=0), nodes[cand.ravel()]).reshape(-1, width)
    route = np.where(clear, dist[np.arange(len(p))[:, None], cand] + cost[cand], math.inf)
    best = np.argmin(route, axis=1)
    found = np.isfinite(route[np.arange(len(p)), best])
    out[found] = cand[found, best[found]]
    todo = np.flatnonzero(~found)
    # a point inside an obstacle has no clear segment to any node: no scan of every node from it
    # (an estimate swung into an obstacle, as a look-ahead point does while its robot turns to look,
    # or one wheel slip carried a hair past a cell that keeps only d/20 from the inflated obstacle).
    # A look-ahead point lies up to 2λ inside the obstacles inflated by ρ + λ while its body is free
    # (its axle, λ behind, keeps ρ): its way out is the shortest one, to the point just outside the
    # nearest edge, and its node the one that point would approach; without one it stood there, a
    # stall (a point deeper in, or any for λ = 0, is a body in an obstacle: no node)
    inside = sight.inside_obstacles(arrays, p[todo])  # even where obstacles overlap: only a True is sure
    stuck, todo = todo[inside], todo[~inside]
    if len(stuck) and arrays.lookahead > 0.0:
        depth, away = sight.obstacle_clearance(arrays, p[stuck])
        exits = p[stuck] - away * (depth + 1e3 * arrays.tol)[:, None]
        lo, hi = arrays.free_bounds[:2], arrays.free_bounds[2:]
        ok = (depth <= 2.0 * arrays.lookahead) & np.any(away != 0.0, axis=1)
        ok &= np.all((exits >= lo) & (exits <= hi), axis=1)
        ok[ok] = ~sight.inside_obstacles(arrays, exits[ok])
        out[stuck[ok]] = approach_target(arrays, exits[ok], nearest)  # outside: no deeper call
    if not len(todo):
        return out
    # the others: every node, in route order (ties in distance order, as argmin over the distance
    # order picks them), a few at a time; the first clear one is the one of shortest route, and
    # most robots find it among the first few instead of testing every node against every edge
    route = np.take_along_axis(dist[todo], order[todo], axis=1) + cost[order[todo]]
    by_route = np.take_along_axis(order[todo], np.argsort(route, axis=1, kind="stable"), axis=1)
    for start in range(0, len(nodes), APPROACH_BATCH):
        if not len(todo):
            break
        cand = by_route[:, start : start + APPROACH_BATCH]
        k = cand.shape[1]
        clear = segments_clear(arrays, np.repeat(p[todo], k, axis=0), nodes[cand.ravel()]).reshape(-1, k)
        hit = clear.any(axis=1)
        out[todo[hit]] = cand[hit, np.argmax(clear[hit], axis=1)]
        todo, by_route = todo[~hit], by_route[~hit]
    return out


def update(
    arrays: PlanArrays,
    cell: np.ndarray,
    target: np.ndarray,
    x: np.ndarray,
    eps_sw: float,
    tol: float | None = None,
    erosion: np.ndarray | float | None = None,
    keep: np.ndarray | float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One control update of the cell policy for every robot.

    Funnel plans: :func:`funnel_update` (ALGORITHMS §11.3; ``erosion`` is the estimate's error
    bound). Paper plans: ALGORITHMS §7.3 with docs/choices.md, as follows.

    A robot is either in a cell (``target == -1``), following its certified field, or
    approaching a tree node in a straight line (``target >= 0``). In a cell it switches and
    relocates by :func:`switch`; whenever its cell changes (or at the start, ``cell == -1``)
    and it is not inside the new cell's safe set, it approaches the node of
    :func:`approach_target` instead, if one exists. An approach ends within ``eps_sw`` of the
    node or as soon as some cell's safe set holds the robot; the robot is then located again.

    Parameters
    ----------
    arrays : PlanArrays
        The plan; ``arrays.funnel`` picks the policy.
    cell, target : ndarray of int, shape (R,)
        Current cell (``-1`` before the first update) and approach node (``-1`` for none).
    x : ndarray, shape (R, 2)
        Positions or their estimates (map units).
    eps_sw : float
        Switching and arrival radius (map units).
    tol : float, optional
        Membership slack (map units); default ``arrays.tol``. Paper plans only.
    erosion : float or ndarray, shape (R,), optional
        Funnel plans: ``δ`` of each robot's estimate (map units), its error bound: membership is
        tested on ``P ⊖ δ``; ``None``: 0. Ignored for paper plans.
    keep : float or ndarray, shape (R,), optional
        Funnel plans: a robot keeps its cell while ``x`` lies in it grown by this (map units): a
        bounded estimate within ``e`` of a robot that the certificate keeps in its cell may lie up to
        ``e`` outside it (ALGORITHMS §12.3); ``None``: the membership slack ``tol``.

    Returns
    -------
    cell, target : ndarray of int64, shape (R,)
    relocated : ndarray of bool, shape (R,)
        Robots found outside their cell and relocated (``left_cell`` events).
    """
    if arrays.funnel:
        return funnel_update(arrays, cell, target, x, eps_sw, 0.0 if erosion is None else erosion, keep)
    c, t, p = _cells(arrays, cell).copy(), _cells(arrays, target).copy(), points(x)
    relocated = np.zeros(len(c), bool)
    fresh = c < 0
    if fresh.any():
        c[fresh] = locate(arrays, p[fresh], tol, eps_sw)
    going = t >= 0
    if going.any():
        idx = np.flatnonzero(going)
        here = locate(arrays, p[idx], tol, eps_sw)
        gap = p[idx] - arrays.nodes[t[idx]]
        done = (np.einsum("rk,rk->r", gap, gap) <= eps_sw * eps_sw) | in_safe_set(arrays, here, p[idx])
        c[idx[done]] = here[done]
        t[idx[done]] = -1
    steady = (t < 0) & ~fresh & ~going
    if steady.any():
        idx = np.flatnonzero(steady)
        new, moved = switch(arrays, c[idx], p[idx], eps_sw, tol)
        fresh[idx] = new != c[idx]
        c[idx], relocated[idx] = new, moved
    check = fresh & (t < 0)
    if check.any():
        idx = np.flatnonzero(check)
        unsafe = idx[~in_safe_set(arrays, c[idx], p[idx])]
        if len(unsafe):
            t[unsafe] = approach_target(arrays, p[unsafe])
    return c, t, relocated


def displacement(arrays: PlanArrays, x: np.ndarray) -> np.ndarray:
    """The displacement output ``y = (landmarks − x).ravel()`` of each robot, shape (R, 2L)."""
    p = points(x)
    return (arrays.landmarks[None, :, :] - p[:, None, :]).reshape(len(p), 2 * len(arrays.landmarks))


def apply_gain(arrays: PlanArrays, cell: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``u = gain[c] @ y`` for each robot, shape (R, 2).

    Parameters
    ----------
    arrays : PlanArrays
        The plan: every cell's gain (C, 2, 2L), 1/s.
    cell : ndarray of int, shape (R,)
        The cell whose gain each robot applies.
    y : ndarray, shape (R, 2L)
        The output: displacements to every landmark, or their bearing reconstruction
        scaled by the fixed landmark's distance (columns of unused landmarks are ignored,
        their gain is zero).
    """
    c = _cells(arrays, cell)
    return np.einsum("rij,rj->ri", arrays.gain[c], np.asarray(y, float).reshape(len(c), arrays.gain.shape[2]))


def field(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The certified field ``u = gain[c] @ (landmarks − x).ravel()``, shape (R, 2), map units / s.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: landmarks and every cell's gain.
    cell : ndarray of int, shape (R,)
        The cell whose field each robot follows.
    x : ndarray, shape (R, 2)
        Positions (map units).
    """
    return apply_gain(arrays, cell, displacement(arrays, x))


def affine_field(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The same field through its affine form ``a_c − M_c x``, shape (R, 2).

    Equal to :func:`field` up to rounding; the stall test (ALGORITHMS §7.2) uses it
    with the position estimate ``x̂`` whatever the output mode.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: every cell's ``a_c`` (map units / s) and ``M_c`` (1/s).
    cell : ndarray of int, shape (R,)
        The cell whose field each robot follows.
    x : ndarray, shape (R, 2)
        Positions or their estimates (map units).
    """
    c, p = _cells(arrays, cell), points(x)
    return arrays.field_a[c] - np.einsum("rij,rj->ri", arrays.field_M[c], p)
