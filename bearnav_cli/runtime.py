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
import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from bearnav_cli import bearing
from bearnav_cli.plan_arrays import CHUNK, RUNTIME_KEYS, PlanArrays, ring_edges, tree_costs

__all__ = ["RUNTIME_KEYS", "PlanArrays", "ring_edges", "tree_costs"]  # re-exported: the runtime's one import

log = logging.getLogger(__name__)


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
    step = max(1, CHUNK // max(1, len(nodes)))
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


def locate(arrays: PlanArrays, x: np.ndarray, tol: float | None = None, eps_sw: float = 0.0) -> np.ndarray:
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
    near_exit = np.einsum("rck,rck->rc", gap, gap) <= eps_sw * eps_sw
    leaving = edge[None] & ((np.einsum("ck,rck->rc", arrays.exit_dir, gap) <= tol) | near_exit)
    candidate = inside & ~leaving
    # barrier rows only where they matter: a point lies in a handful of the C cells
    h = np.full(candidate.shape, -math.inf)
    r_idx, c_idx = np.nonzero(candidate)
    if len(r_idx):
        rows_h = np.einsum("nqk,nk->nq", arrays.bar_A[c_idx], p[r_idx]) + arrays.bar_b[c_idx]
        h[r_idx, c_idx] = np.min(rows_h, axis=1, initial=math.inf)
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
        c[move] = locate(arrays, p[move], tol, eps_sw)
    return c, outside


def in_safe_set(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Whether each robot lies in its cell's safe set (every barrier row ``h(x) >= 0``), shape (R,)."""
    c, p = _cells(arrays, cell), _points(x)
    rows = np.einsum("rqk,rk->rq", arrays.bar_A[c], p) + arrays.bar_b[c]
    return np.min(rows, axis=1, initial=math.inf) >= 0


def _on_segment(orientation: np.ndarray, point: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> np.ndarray:
    """Collinear (``orientation == 0``) and inside the bounding box of ``[s0, s1]`` (broadcast arrays)."""
    inside = orientation == 0
    for k in (0, 1):
        low, high = np.minimum(s0[..., k], s1[..., k]), np.maximum(s0[..., k], s1[..., k])
        inside &= (low <= point[..., k]) & (point[..., k] <= high)
    return inside


def segments_clear(arrays: PlanArrays, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact test that each segment ``[a_r, b_r]`` stays in the bounds and touches no obstacle edge, shape (R,).

    Both endpoints are assumed free, so a segment meets the (closed) obstacles exactly when it
    crosses or touches one of their ring edges.
    """
    a, b = _points(a), _points(b)
    lo, hi = arrays.bounds[:2], arrays.bounds[2:]
    ok = np.all((a >= lo) & (a <= hi) & (b >= lo) & (b <= hi), axis=1)
    edges = arrays.obstacle_edges
    if not len(edges) or not ok.any():
        return ok
    p, q = edges[:, 0], edges[:, 1]
    step = max(1, CHUNK // len(edges))
    for s in range(0, len(a), step):
        A, Bp = a[s : s + step, None, :], b[s : s + step, None, :]
        d = Bp - A
        o1 = d[..., 0] * (p[None, :, 1] - A[..., 1]) - d[..., 1] * (p[None, :, 0] - A[..., 0])
        o2 = d[..., 0] * (q[None, :, 1] - A[..., 1]) - d[..., 1] * (q[None, :, 0] - A[..., 0])
        e = q - p
        o3 = e[None, :, 0] * (A[..., 1] - p[None, :, 1]) - e[None, :, 1] * (A[..., 0] - p[None, :, 0])
        o4 = e[None, :, 0] * (Bp[..., 1] - p[None, :, 1]) - e[None, :, 1] * (Bp[..., 0] - p[None, :, 0])
        proper = (o1 * o2 < 0) & (o3 * o4 < 0)
        # touching counts as a collision: an endpoint of one segment on the other (orientation 0
        # and inside the other's bounding box)
        touch = (
            _on_segment(o1, p[None], A, Bp) | _on_segment(o2, q[None], A, Bp)
            | _on_segment(o3, A, p[None], q[None]) | _on_segment(o4, Bp, p[None], q[None])
        )  # fmt: skip
        ok[s : s + step] &= ~np.any(proper | touch, axis=1)
    return ok


def approach_target(arrays: PlanArrays, x: np.ndarray, nearest: int = 8) -> np.ndarray:
    """The tree node a robot outside every safe set drives to in a straight line, shape (R,); ``-1`` if none.

    Among the ``nearest`` closest nodes (all nodes if none of those qualifies), the one with a
    clear straight segment from ``x`` and the shortest route ``‖x − x_n‖ + cost(n)``. The node
    lies strictly inside its own cell's safe set, so the robot is certified once it arrives.
    """
    p = _points(x)
    out = np.full(len(p), -1, np.int64)
    if not len(p):
        return out
    nodes = arrays.nodes
    cost = tree_costs(nodes, arrays.parent)
    dist = np.hypot(*(p[:, None, :] - nodes[None]).transpose(2, 0, 1))
    order = np.argsort(dist, axis=1, kind="stable")
    for width in (min(nearest, len(nodes)), len(nodes)):
        todo = np.flatnonzero(out < 0)
        if not len(todo):
            break
        cand = order[todo, :width]
        clear = segments_clear(arrays, np.repeat(p[todo], width, axis=0), nodes[cand.ravel()]).reshape(-1, width)
        route = np.where(clear, dist[todo[:, None], cand] + cost[cand], math.inf)
        best = np.argmin(route, axis=1)
        found = np.isfinite(route[np.arange(len(todo)), best])
        out[todo[found]] = cand[found, best[found]]
    return out


def update(
    arrays: PlanArrays, cell: np.ndarray, target: np.ndarray, x: np.ndarray, eps_sw: float, tol: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One control update of the cell policy for every robot (ALGORITHMS §7.3 with docs/choices.md).

    A robot is either in a cell (``target == -1``), following its certified field, or
    approaching a tree node in a straight line (``target >= 0``). In a cell it switches and
    relocates by :func:`switch`; whenever its cell changes (or at the start, ``cell == -1``)
    and it is not inside the new cell's safe set, it approaches the node of
    :func:`approach_target` instead, if one exists. An approach ends within ``eps_sw`` of the
    node or as soon as some cell's safe set holds the robot; the robot is then located again.

    Parameters
    ----------
    arrays : PlanArrays
    cell, target : ndarray of int, shape (R,)
        Current cell (``-1`` before the first update) and approach node (``-1`` for none).
    x : ndarray, shape (R, 2)
        Positions or their estimates (map units).
    eps_sw : float
        Switching and arrival radius (map units).
    tol : float, optional
        Membership slack; default ``arrays.tol``.

    Returns
    -------
    cell, target : ndarray of int64, shape (R,)
    relocated : ndarray of bool, shape (R,)
        Robots found outside their cell and relocated (``left_cell`` events).
    """
    c, t, p = _cells(arrays, cell).copy(), _cells(arrays, target).copy(), _points(x)
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


# --------------------------------------------------------------------------- the control step

DYNAMICS = ("single", "unicycle")
MEASUREMENTS = ("bearing", "displacement")


@dataclass(frozen=True)
class ControlSettings:
    """Constants of the control step shared by :class:`Controller` and ``bearnav simulate`` (ALGORITHMS §7).

    Attributes
    ----------
    speed : float
        ``v_ref`` of the single integrator (map units / s).
    dt : float
        Control period (s): the hold timer advances by it on every step without a fix.
    eps_sw : float
        Switching and arrival radius (map units).
    tol : float
        Membership slack (map units), ``1e-9·D``.
    dynamics : {"single", "unicycle"}
    alpha, beta : float
        Unicycle gains: ``v = α cos e`` (map units / s), ``ω = β sin e`` (rad / s).
    clamp_reverse : bool
        Unicycle: clamp ``v`` at 0 (never reverse).
    turn_first : bool
        Unicycle: ``v = α cos³ e`` (slow down to turn) instead of §7.1's ``α cos e``.
    measurement : {"bearing", "displacement"}
        ``bearing``: reconstruct ``ỹ`` and ``x̂`` from bearings (§6); ``displacement``: the
        true displacements, ``x̂ = x`` (paper B).
    reconstruction : {"lsq", "pair", "rescale"}
    min_spread : float
        ``θ_min`` of §6.2 (radians).
    hold_time : float
        Seconds without a usable reconstruction before the robot stops to look around; it
        is ``lost`` after one more revolution, ``2π/β`` (§7.5).
    odometry : bool
        Between fixes, carry ``x̂`` forward with the commanded motion and keep following the
        fields (for at most ``hold_time``); off: the hold policy of §7.5 as written.
    odometry_drift : float
        Standard deviation of the odometry's position error per unit travelled: the filter's
        process noise (:func:`control`).
    blind_error : float
        Without a fix, the robot keeps following the fields on odometry beyond ``hold_time``
        while its estimate's 3σ stays below this (map units; the barrier margin in
        ``bearnav simulate``); 0: ``hold_time`` only.
    """

    speed: float
    dt: float
    eps_sw: float
    tol: float
    dynamics: str = "single"
    alpha: float = 0.1
    beta: float = 0.5
    clamp_reverse: bool = False
    turn_first: bool = True
    measurement: str = "bearing"
    reconstruction: str = "lsq"
    min_spread: float = bearing.DEFAULT_MIN_SPREAD
    hold_time: float = 2.0
    odometry: bool = True
    odometry_drift: float = 0.05
    blind_error: float = 0.0
    bearing_sigma: float = 0.0
    max_fix_error: float = math.inf


@dataclass(frozen=True)
class ControlState:
    """What a controller remembers between steps, for ``R`` robots.

    Attributes
    ----------
    cell, target : ndarray of int64, shape (R,)
        Active cell (``-1`` before the first fix) and approached node (``-1`` for none).
    last_dir : ndarray, shape (R, 2)
        Unit direction of the last command (the initial heading before the first).
    hold : ndarray, shape (R,)
        Seconds since the last usable reconstruction.
    x_hat : ndarray, shape (R, 2)
        The last position estimate, carried forward by odometry between fixes (map units).
    motion : ndarray, shape (R, 2)
        World-frame velocity of the last command (map units / s): what odometry integrates.
    known : ndarray of bool, shape (R,)
        Whether the robot has had a fix yet.
    var : ndarray, shape (R,)
        Variance of the estimate (map units²), isotropic; ``inf`` before the first fix.
    scanning : ndarray of bool, shape (R,)
        Looking around at the last step.
    spin : ndarray, shape (R,)
        ``±1``: the direction of the current look-around.
    """

    cell: np.ndarray
    target: np.ndarray
    last_dir: np.ndarray
    hold: np.ndarray
    x_hat: np.ndarray
    motion: np.ndarray
    known: np.ndarray
    var: np.ndarray
    scanning: np.ndarray
    spin: np.ndarray

    @classmethod
    def initial(cls, heading: np.ndarray) -> ControlState:
        """Robots that have not had a fix yet, facing ``heading`` (rad, shape (R,))."""
        h = np.asarray(heading, float).reshape(-1)
        r = len(h)
        return cls(np.full(r, -1, np.int64), np.full(r, -1, np.int64), np.column_stack([np.cos(h), np.sin(h)]),
                   np.zeros(r), np.zeros((r, 2)), np.zeros((r, 2)), np.zeros(r, bool), np.full(r, np.inf),
                   np.zeros(r, bool), np.ones(r))  # fmt: skip

    def take(self, idx: np.ndarray) -> ControlState:
        """The state of the robots ``idx``."""
        return ControlState(*(getattr(self, f.name)[idx] for f in dataclasses.fields(self)))

    def put(self, idx: np.ndarray, other: ControlState) -> None:
        """Write ``other`` (the robots ``idx``) back into this state's arrays."""
        for f in dataclasses.fields(self):
            getattr(self, f.name)[idx] = getattr(other, f.name)


@dataclass(frozen=True)
class ControlOutput:
    """One control step for ``R`` robots.

    Attributes
    ----------
    velocity : ndarray, shape (R, 2)
        Single integrator: the commanded velocity (map units / s), ``v_ref·unit(ũ)``.
    forward, turn : ndarray, shape (R,)
        Unicycle: ``v`` (map units / s) and ``ω`` (rad / s). ``turn`` is also the rate at
        which a single integrator that is looking around turns its camera.
    scanning : ndarray of bool, shape (R,)
        Looking around in place: no fix for longer than ``hold_time``.
    state : ControlState
        The state after the step.
    fix : ndarray of bool, shape (R,)
        A usable reconstruction (or displacement measurement) was available.
    lost : ndarray of bool, shape (R,)
        No fix for longer than ``hold_time`` plus one revolution of looking around.
    stalled : ndarray of bool, shape (R,)
        The certified field vanishes at ``x̂`` (``‖a − M x̂‖ < 1e-6·u_max``).
    relocated : ndarray of bool, shape (R,)
        Left the cell through a side face this step (a ``left_cell`` event).
    x_hat : ndarray, shape (R, 2)
        The position estimate used (measured or carried by odometry; zeros before the first fix).
    """

    velocity: np.ndarray
    forward: np.ndarray
    turn: np.ndarray
    scanning: np.ndarray
    state: ControlState
    fix: np.ndarray
    lost: np.ndarray
    stalled: np.ndarray
    relocated: np.ndarray
    x_hat: np.ndarray


#: ``‖a − M x̂‖ < STALL_FIELD · u_max`` is a stall: the field has (almost) an equilibrium there.
STALL_FIELD = 1e-6
#: A unicycle approaching a node drives only when its heading is this close to the segment (rad).
APPROACH_ALIGNMENT = math.radians(10.0)


def _scaled_output(arrays: PlanArrays, x_hat: np.ndarray, fixed: np.ndarray, tol: float) -> np.ndarray:
    """``ỹ_k = (l_k − x̂)/max(‖l_f − x̂‖, tol)`` for every landmark, shape (R, 2L) (ALGORITHMS §6.2)."""
    d = arrays.landmarks[None] - x_hat[:, None, :]
    scale = np.maximum(np.hypot(*d[np.arange(len(x_hat)), fixed].T), tol)
    return (d / scale[:, None, None]).reshape(len(x_hat), -1)


def fix_error(arrays: PlanArrays, bearings: np.ndarray, visible: np.ndarray, x_hat: np.ndarray,
              sigma: float) -> np.ndarray:  # fmt: skip
    """Predicted 3-sigma position error of an ``lsq`` fix (map units), shape (R,).

    A bearing with angle noise ``σ`` places the robot on its line to within ``σ·d`` at
    distance ``d``, so the information of the fix is ``Σ_k P_k/(σ d_k)²`` (``P_k`` the
    projector across bearing ``k``); its smallest eigenvalue bounds the worst direction.
    Two nearly parallel bearings, or landmarks far away, give a large error.
    """
    d = arrays.landmarks[None] - x_hat[:, None, :]
    dist2 = np.maximum(np.einsum("rlk,rlk->rl", d, d), arrays.tol**2)
    w = np.where(visible, 1.0 / dist2, 0.0)
    bx, by = bearings[..., 0], bearings[..., 1]
    a11, a22, a12 = np.sum(w * (1 - bx * bx), 1), np.sum(w * (1 - by * by), 1), -np.sum(w * bx * by, 1)
    lam = 0.5 * (a11 + a22) - np.hypot(0.5 * (a11 - a22), a12)
    return 3.0 * sigma / np.sqrt(np.maximum(lam, 1e-300))


def control(
    arrays: PlanArrays,
    settings: ControlSettings,
    state: ControlState,
    bearings: np.ndarray,
    visible: np.ndarray,
    heading: np.ndarray,
    x_true: np.ndarray | None = None,
    displacements: np.ndarray | None = None,
) -> ControlOutput:
    """One step of ALGORITHMS §7.2 for every robot: measurement → cell → command.

    The position estimate ``x̂`` comes from ``lsq`` whatever the reconstruction (§7.2); the
    cell policy is :func:`update`; the output ``ỹ`` is rebuilt for the (new) cell's fixed
    landmark and ``ũ = gain[c] @ ỹ``, or ``x_n − x̂`` while approaching node ``n``.

    Without a usable reconstruction (§7.5), for up to ``hold_time`` seconds the robot carries
    its last estimate forward with its own commanded motion (odometry, ``settings.odometry``)
    and keeps following the fields; without any estimate (before its first fix, or once
    odometry has expired) it stops and looks around, turning in place at ``β``, for one
    revolution, and is then lost. With ``odometry`` off it holds as §7.5 says (the single
    integrator keeps ``last_dir``, the unicycle turns toward it) for ``hold_time``, then looks
    around the same way.

    Parameters
    ----------
    arrays : PlanArrays
    settings : ControlSettings
    state : ControlState
    bearings : ndarray, shape (R, L, 2)
        World-frame unit bearings (ignored in displacement mode).
    visible : ndarray of bool, shape (R, L)
    heading : ndarray, shape (R,)
        Yaw ``φ`` (rad) from the compass: the unicycle's heading, the single integrator's camera.
    x_true : ndarray, shape (R, 2), optional
        True positions; required in displacement mode (``x̂ = x``), ignored otherwise.
    displacements : ndarray, shape (R, L, 2), optional
        Displacement mode in a world that differs from the plan's (deformation tests): the
        measured ``l_k − x``; the field uses them as they are and ``x̂`` is the position that
        fits them best against the plan's landmarks, ``mean_k(l_k − d_k)``.

    Returns
    -------
    ControlOutput
    """
    s = settings
    r = len(state.cell)
    if s.measurement == "displacement":
        if displacements is not None:
            measured = np.mean(arrays.landmarks[None] - displacements, axis=1)
        elif x_true is None:
            raise ValueError("displacement measurement needs the true positions")
        else:
            measured = _points(x_true).copy()
        fix = np.ones(r, bool)
    else:
        estimate = bearing.reconstruct(bearings, visible, arrays.landmarks, 0, method="lsq",
                                       min_spread=s.min_spread, tol=s.tol)  # fmt: skip
        measured, fix = estimate.x_hat, estimate.usable.copy()
    # A scalar Kalman filter fuses the fixes with odometry: the prediction moves the last
    # estimate by the last command (its variance grows with the distance, odometry_drift per
    # unit), a fix of variance σ_fix² (from σ and the bearing geometry, fix_error/3) corrects it,
    # and a fix farther than 3 standard deviations from the prediction is rejected. Noise-free
    # (σ = 0) every fix is taken as it is.
    sigma_fix2 = np.zeros(r)
    if s.bearing_sigma > 0 and fix.any():
        sigma_fix2[fix] = (fix_error(arrays, bearings[fix], visible[fix], measured[fix], s.bearing_sigma) / 3.0) ** 2
        fix &= sigma_fix2 <= (s.max_fix_error / 3.0) ** 2
    cell, target, last_dir = state.cell.copy(), state.target.copy(), state.last_dir.copy()
    known = state.known.copy()
    predicted = state.x_hat + s.dt * state.motion
    recent = known & s.odometry  # a prediction exists; its variance says how far to trust it
    travelled = s.dt * np.hypot(state.motion[:, 0], state.motion[:, 1])
    var_pred = state.var + (s.odometry_drift * travelled) ** 2
    innovation = np.einsum("rk,rk->r", measured - predicted, measured - predicted)
    fix &= ~(recent & (innovation > 9.0 * (var_pred + sigma_fix2)))
    with np.errstate(invalid="ignore", divide="ignore"):
        gain = np.where(recent & (var_pred + sigma_fix2 > 0), var_pred / (var_pred + sigma_fix2), 1.0)
    gain = np.where(np.isfinite(gain), gain, 1.0)
    corrected = np.where(recent[:, None], predicted + gain[:, None] * (measured - predicted), measured)
    hold = np.where(fix, 0.0, state.hold + s.dt)
    # moving on odometry alone: for hold_time, and on as long as the estimate stays within the
    # barrier margin (3σ <= blind_error; turning in place adds no uncertainty)
    carried = ~fix & recent & ((hold <= s.hold_time) | (9.0 * var_pred <= s.blind_error**2))
    x_hat = np.where(fix[:, None], corrected, predicted)
    with np.errstate(invalid="ignore"):
        posterior = np.where(np.isfinite(var_pred), (1.0 - gain) * var_pred, sigma_fix2)
    var = np.where(fix, np.where(recent, posterior, sigma_fix2), var_pred)
    steer = fix | carried  # robots with a position estimate this step
    known |= fix
    relocated = np.zeros(r, bool)
    stalled = np.zeros(r, bool)
    u = np.zeros((r, 2))
    if steer.any():
        idx = np.flatnonzero(steer)
        c, t, moved = update(arrays, cell[idx], target[idx], x_hat[idx], s.eps_sw, s.tol)
        cell[idx], target[idx], relocated[idx] = c, t, moved
        f = arrays.fixed_landmark[c]
        if s.measurement == "displacement":
            y = displacement(arrays, x_hat[idx]) if displacements is None else displacements[idx].reshape(len(idx), -1)
        elif s.reconstruction == "lsq" or not fix[idx].all():
            y = _scaled_output(arrays, x_hat[idx], f, s.tol)
        else:
            rec = bearing.reconstruct(bearings[idx], visible[idx], arrays.landmarks, f, method=s.reconstruction,
                                      min_spread=s.min_spread, tol=s.tol)  # fmt: skip
            y = np.where(rec.usable[:, None], rec.y, _scaled_output(arrays, x_hat[idx], f, s.tol))
        ui = apply_gain(arrays, c, y)
        stalled[idx] = np.hypot(*affine_field(arrays, c, x_hat[idx]).T) < STALL_FIELD * arrays.u_max[c]
        going = t >= 0
        ui[going] = arrays.nodes[t[going]] - x_hat[idx[going]]
        stalled[idx[going]] = False
        norm = np.hypot(ui[:, 0], ui[:, 1])
        stalled[idx[~(norm > 0)]] = True
        ok = norm > 0
        u[idx[ok]] = ui[ok] / norm[ok, None]
        last_dir[idx[ok]] = u[idx[ok]]
    holding = ~steer  # no position estimate this step
    if s.odometry:
        # never move blind: without an estimate look around at once, for one revolution
        scanning = holding
        scan_time = hold - np.where(state.known, s.hold_time, 0.0)
    else:
        scanning = holding & (hold > s.hold_time)  # §7.5's hold first, then look around
        scan_time = hold - s.hold_time
    lost = scanning & (scan_time > 2.0 * math.pi / s.beta)
    direction = np.where(holding[:, None], last_dir, u)
    velocity = s.speed * direction
    velocity[scanning] = 0.0
    phi = np.asarray(heading, float).reshape(r)
    forward = np.zeros(r)
    # look around starting toward the last command (a scan that always turned one way undid
    # the unicycle's turn toward its field)
    toward = bearing.wrap(np.arctan2(last_dir[:, 1], last_dir[:, 0]) - phi)
    starting = scanning & ~state.scanning  # a scan keeps the direction it started with
    spin = np.where(starting, np.where(toward < 0, -1.0, 1.0), state.spin)
    turn = np.where(scanning, spin * s.beta, 0.0)
    motion = velocity.copy()
    if s.dynamics == "unicycle":
        e = bearing.wrap(np.arctan2(direction[:, 1], direction[:, 0]) - phi)
        # §7.1's v = α cos e; turn_first uses α cos³ e: a unicycle that is far off its field slows
        # down to turn instead of sweeping a wide arc past an obstacle corner (hold: turn in place)
        gain = np.cos(e) ** 3 if s.turn_first else np.cos(e)
        forward = np.where(holding | scanning, 0.0, s.alpha * gain)
        # a straight approach is certified only along its segment: turn on the spot first
        forward[(target >= 0) & (np.abs(e) > APPROACH_ALIGNMENT)] = 0.0
        if s.clamp_reverse:
            forward = np.maximum(forward, 0.0)
        turn = np.where(scanning, turn, s.beta * np.sin(e))
        motion = forward[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    # the estimate always moves on with the robot's own motion, steering with it or not
    new = ControlState(cell, target, last_dir, hold, np.where(known[:, None], x_hat, state.x_hat), motion, known,
                       var, scanning, spin)  # fmt: skip
    return ControlOutput(velocity, forward, turn, scanning, new, fix, lost, stalled, relocated,
                         np.where(steer[:, None], x_hat, 0.0))  # fmt: skip


class Controller:
    """The controller a robot runs: load ``plan.npz``, feed bearings at camera rate, get a command.

    Numpy only. One robot; the step is :func:`control`, the same function ``bearnav
    simulate`` advances its robots with.

    Parameters
    ----------
    arrays : PlanArrays
    settings : ControlSettings
    heading : float
        Initial heading (rad) standing in for the last command until the first fix.
    """

    def __init__(self, arrays: PlanArrays, settings: ControlSettings, heading: float = 0.0) -> None:
        self.arrays = arrays
        self.settings = settings
        self.state = ControlState.initial(np.array([heading]))
        self.last: ControlOutput | None = None

    @classmethod
    def from_plan(cls, path: str, *, speed: float = 0.1, dt: float | None = None, dynamics: str = "single",
                  heading: float = 0.0, **options: Any) -> Controller:  # fmt: skip
        """Load ``plan.npz``; ``options`` are further :class:`ControlSettings` fields.

        ``dt`` is the camera period (s); by default the simulation's, ``min(0.0025·D/v, 0.2)``
        with ``v`` = ``speed`` (``alpha`` for the unicycle), and ``eps_sw`` defaults to
        ``2·v·dt``, as in ``bearnav simulate``.
        """
        arrays = PlanArrays.from_npz(path)
        v = options.get("alpha", 0.1) if dynamics == "unicycle" else speed
        if dt is None:
            xmin, ymin, xmax, ymax = arrays.bounds
            dt = min(0.0025 * math.hypot(xmax - xmin, ymax - ymin) / v, 0.2)
        options.setdefault("eps_sw", 2.0 * v * dt)
        options.setdefault("blind_error", 0.01 * math.hypot(*(arrays.bounds[2:] - arrays.bounds[:2])))
        # a real camera is never exact: with σ = 0 the filter would trust odometry over every
        # noisy fix (set it to the camera's angular noise)
        options.setdefault("bearing_sigma", math.radians(1.0))
        return cls(arrays, ControlSettings(speed=speed, dt=dt, tol=arrays.tol, dynamics=dynamics, **options), heading)

    def command(self, bearings: np.ndarray, visible: np.ndarray, heading: float | None = None) -> np.ndarray:
        """The command for one camera frame.

        Parameters
        ----------
        bearings : array_like, shape (L, 2)
            World-frame unit bearing of each landmark (rows of invisible ones are ignored).
        visible : array_like of bool, shape (L,)
        heading : float, optional
            The robot's yaw (rad) from the compass: required by the unicycle; for the single
            integrator, the camera's heading (default 0).

        Returns
        -------
        ndarray
            Single integrator: the velocity ``(vx, vy)`` (map units / s); while looking around
            it is zero and ``self.last.turn`` is the rate to turn the camera. Unicycle:
            ``(v, ω)``. Zero once the robot is lost (``self.lost``).

        Raises
        ------
        ValueError
            A unicycle without ``heading``.
        """
        if heading is None and self.settings.dynamics == "unicycle":
            raise ValueError("the unicycle needs its heading (rad) on every frame")
        out = control(self.arrays, self.settings, self.state, np.asarray(bearings, float)[None],
                      np.asarray(visible, bool)[None], np.array([0.0 if heading is None else heading]))  # fmt: skip
        self.state, self.last = out.state, out
        if out.lost[0]:
            return np.zeros(2)
        if self.settings.dynamics == "unicycle":
            return np.array([out.forward[0], out.turn[0]])
        return out.velocity[0].copy()

    @property
    def lost(self) -> bool:
        """No position estimate after looking around for a whole revolution (``2π/β`` s past the
        odometry's ``hold_time``); a later fix clears it."""
        return bool(self.last is not None and self.last.lost[0])

    @property
    def arrived(self) -> bool:
        """The current estimate lies within the plan's goal tolerance of the goal: stop."""
        if self.last is None or not (self.last.fix[0] or self.state.known[0]):
            return False
        return bool(np.hypot(*(self.last.x_hat[0] - self.arrays.goal)) <= self.arrays.goal_tolerance)

    @property
    def cell(self) -> int:
        """The active cell (``-1`` before the first fix)."""
        return int(self.state.cell[0])
