"""The safety rules of the control step: how fast, and which way, a robot may move on what it knows.

Numpy only. With the set estimator (ALGORITHMS §12.3) a step is taken only at
:func:`certified_pace`, which keeps the truth in its cell's barrier set exactly, bent inward near a
face by :func:`bend_inward`. With the filter, a step the certificate does not cover is slowed so
that the error ball stays off the obstacles (:func:`error_ball_pace`) and bent away from the nearest
one (:func:`steer_clear`), and a robot without a fix drives on blind while its error ball lies in
one cell (:func:`carry_inside`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from bearnav_cli.runtime.cell_policy import cell_slack, least_rank_cell
from bearnav_cli.runtime.estimate import Estimate
from bearnav_cli.runtime.plan_arrays import PlanArrays
from bearnav_cli.runtime.settings import ControlSettings, ControlState
from bearnav_cli.runtime.sight import obstacle_clearance

__all__ = ["StepError", "bend_inward", "carry_inside", "certified_pace", "error_ball_pace", "steer_clear"]


@dataclasses.dataclass(frozen=True)
class StepError:
    """The bound on the motion's own error over one step at the pace ``p`` (ALGORITHMS §12.3, §12.6).

    The true displacement of the point the plan is about lies within
    ``w(p) = ν + κpℓ + p²·curvature`` of ``pℓ·d``: the odometry bound ``κ‖d̂‖ + ν`` (the floor ``ν``
    only when the robot translates), and for a look-ahead point the arc it swings through while the
    axle turns at ``ω = pα (d·h^⊥)/λ``: ``‖Δp − pℓd‖ ≤ λ(ωdt)²/2`` for a step integrated at its start
    (the simulated base) and ``≤ pℓ·|ω|dt/2`` for one the wheels drive continuously, both at most
    ``p²ℓ²|d·h^⊥|/(2λ)``.

    Attributes
    ----------
    step : float
        ``ℓ``, a full step's length (map units).
    slip : float
        ``κ`` (dimensionless).
    floor : float
        ``ν`` (map units).
    curvature : ndarray, shape (R,)
        The coefficient of ``p²`` (map units): ``ℓ²|d·h^⊥(θ)|/(2λ)`` for a look-ahead point, 0 for a
        single integrator.
    """

    step: float
    slip: float
    floor: float
    curvature: np.ndarray

    @classmethod
    def of(cls, step: float, slip: float, floor: float, direction: np.ndarray, heading=None, lookahead: float = 0.0):
        """The bound of steps along the unit ``direction`` (R, 2); a look-ahead point's at ``heading`` (R,) rad."""
        r = len(direction)
        if lookahead <= 0.0 or heading is None:
            return cls(step, slip, floor, np.zeros(r))
        across = np.abs(-direction[:, 0] * np.sin(heading) + direction[:, 1] * np.cos(heading))
        return cls(step, slip, floor, step**2 * across / (2.0 * lookahead))

    def at(self, pace: np.ndarray) -> np.ndarray:
        """``w(p)`` for the paces ``p`` (R,) in [0, 1] (0 where ``p = 0``: a robot that stands does not slip)."""
        pace = np.asarray(pace, float)
        return np.where(pace > 0.0, self.floor + self.slip * pace * self.step + pace**2 * self.curvature, 0.0)


def _row_terms(arrays: PlanArrays, cell: np.ndarray, x_hat: np.ndarray, error: np.ndarray, direction: np.ndarray):
    """Per barrier row of each robot's cell: its depth ``H = max(0, h(x̂) − e‖A‖)`` the truth is sure to have,
    the step's inward rate ``A·d``, the row norm ``‖A‖`` and which rows are real (not padding), all (R, Q)."""
    c = np.asarray(cell, np.int64)
    A, b = arrays.bar_A[c], arrays.bar_b[c]
    real = np.isfinite(b)
    norm = np.hypot(A[..., 0], A[..., 1])
    with np.errstate(invalid="ignore"):
        depth = np.where(real, np.maximum(np.einsum("rqi,ri->rq", A, x_hat) + b - error[:, None] * norm, 0.0), np.inf)
    return depth, np.einsum("rqi,ri->rq", A, direction), norm, real


def _holding_interval(c0: np.ndarray, c1: np.ndarray, c2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where ``c0 + c1·p − c2·p² ≥ 0`` (``c2 ≥ 0``): the interval ``[lo, hi]`` of ``p``, elementwise; ``lo > hi``
    where it holds nowhere."""
    with np.errstate(divide="ignore", invalid="ignore"):
        # affine (c2 = 0): one root, and the slope's sign says which side holds
        root = -c0 / c1
        lo = np.where(c1 > 0.0, root, -np.inf)
        hi = np.where(c1 < 0.0, root, np.where((c1 == 0.0) & (c0 < 0.0), -np.inf, np.inf))
        # concave: between the roots of c2·p² − c1·p − c0, without cancellation: q/c2 and −c0/q with
        # q = (c1 + sign(c1)·√disc)/2 (q = 0 only where c1 = 0 = c0, and then the root is 0)
        disc = c1 * c1 + 4.0 * c2 * c0
        q = 0.5 * (c1 + np.copysign(np.sqrt(np.maximum(disc, 0.0)), c1))
        r1, r2 = q / c2, np.where(q != 0.0, -c0 / q, 0.0)
        curved, real = c2 > 0.0, disc >= 0.0
        lo = np.where(curved, np.where(real, np.minimum(r1, r2), np.inf), lo)
        hi = np.where(curved, np.where(real, np.maximum(r1, r2), -np.inf), hi)
    return lo, hi


def certified_pace(
    arrays: PlanArrays,
    cell: np.ndarray,
    x_hat: np.ndarray,
    error: np.ndarray,
    direction: np.ndarray,
    motion: StepError,
) -> np.ndarray:
    """The largest fraction of a step that keeps the truth in its cell's barrier set, shape (R,) in [0, 1].

    The discrete-time part of Theorem 2 (ALGORITHMS §12.3), done exactly: the true position ``x``
    lies within ``e`` of ``x̂`` and, by induction, in the cell (every barrier row ``h_k = A_k·x + b_k
    ≥ 0``), so ``h_k(x) ≥ H_k = max(0, h_k(x̂) − e‖A_k‖)``. A step at the fraction ``p`` moves it by
    ``pℓ·d`` plus an error of at most ``w(p)`` (:class:`StepError`), so row ``k`` holds after it if

        ``H_k + pℓ (A_k·d) − ‖A_k‖ w(p) ≥ 0``,

    a concave quadratic in ``p`` whose solutions form an interval. The pace is the largest ``p ≤ 1``
    in every row's interval (0: no step is safe; standing still is). The exit row is not a barrier:
    crossing it is the progress the cell is for.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's barrier rows ``bar_A``, ``bar_b`` (padding rows are ``0·x + inf``).
    cell : ndarray of int, shape (R,)
        Active cells (all ``>= 0``).
    x_hat : ndarray, shape (R, 2)
        Estimates of the point the plan is about (map units).
    error : ndarray, shape (R,)
        Their error bounds ``e`` (map units).
    direction : ndarray, shape (R, 2)
        Unit step directions.
    motion : StepError
        The bound ``w(p)`` of the step's own error.
    """
    depth, inward, norm, real = _row_terms(arrays, cell, x_hat, error, direction)
    curvature = motion.curvature[:, None] * norm
    # f(p) = c0 + c1·p − c2·p² ≥ 0 on (0, 1]
    c0 = np.where(real, depth - norm * motion.floor, 1.0)
    c1 = np.where(real, motion.step * (inward - norm * motion.slip), 0.0)
    c2 = np.where(real, curvature, 0.0)
    lo, hi = _holding_interval(c0, c1, c2)
    top = np.minimum(np.min(hi, axis=1, initial=np.inf), 1.0)
    bottom = np.max(lo, axis=1, initial=-np.inf)
    # a hair inside the interval: its ends are roots, where round-off decides the sign
    pace = np.clip(np.where(top < 1.0, top * (1.0 - 1e-9), top), 0.0, 1.0)
    # the exact check of every row at the pace chosen (a root found wrong by round-off gives 0, not a step)
    holds = np.all(c0 + pace[:, None] * (c1 - c2 * pace[:, None]) >= 0.0, axis=1)
    return np.where((pace > 0.0) & (pace >= bottom) & holds, pace, 0.0)


def bend_inward(
    arrays: PlanArrays,
    cell: np.ndarray,
    x_hat: np.ndarray,
    error: np.ndarray,
    direction: np.ndarray,
    motion: StepError,
) -> np.ndarray:
    """The unit step directions turned toward the inside of the faces that :func:`certified_pace` finds near, (R, 2).

    For every barrier row ``k`` that a full step along ``d`` would not keep (``H_k + ℓ(A_k·d) <
    ‖A_k‖w(1)``, :func:`certified_pace`'s test at ``p = 1``), the direction gains ``(‖A_k‖w(1) − H_k)/ℓ −
    A_k·d + 0.01`` times ``A_k``; the sum is normalised. The exit direction is kept: a bend that would stop
    the progress (``z·d' ≥ 0`` in a cell with an exit) gives the field's direction back. Safety does not
    rest on the bend: the step it gives is taken only at :func:`certified_pace`'s pace, which checks
    every row exactly.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's barrier rows and exit directions.
    cell : ndarray of int, shape (R,)
        Active cells.
    x_hat : ndarray, shape (R, 2)
        Estimates (map units).
    error : ndarray, shape (R,)
        Their error bounds (map units).
    direction : ndarray, shape (R, 2)
        The field's unit directions.
    motion : StepError
        The bound of the step's own error, for ``direction``.
    """
    c = np.asarray(cell, np.int64)
    depth, inward, norm, real = _row_terms(arrays, c, x_hat, error, direction)
    needed = (norm * motion.at(np.ones(len(c)))[:, None] - depth) / motion.step
    gain = np.where(real & (inward < needed), needed - inward + 0.01, 0.0)
    bent = direction + np.einsum("rq,rqi->ri", gain, np.where(real[..., None], arrays.bar_A[c], 0.0))
    size = np.hypot(bent[:, 0], bent[:, 1])
    out = np.where(size[:, None] > 0, bent / np.where(size > 0, size, 1.0)[:, None], direction)
    exit_ = arrays.parent_cell[c] >= 0
    stops = exit_ & (np.einsum("ri,ri->r", arrays.exit_dir[c], out) >= 0.0)
    out[stops] = direction[stops]
    return out


def error_ball_pace(
    arrays: PlanArrays, s: ControlSettings, cell: np.ndarray, x_hat: np.ndarray, error_bound: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """How fast each robot may drive without its error ball reaching an obstacle, and which way is away.

    The true position lies within ``e`` (the estimate's error bound, 3σ) of ``x̂``, and a step at
    the fraction ``p`` of full speed moves it by at most ``p·ℓ`` with ``ℓ = v·dt·(1 + odometry_drift)``
    (``v`` = ``v_ref``, or ``α`` for the unicycle). So with ``k`` the clearance of ``x̂`` from the
    inflated obstacles and the walls, every position the robot can be in during a step at
    ``p = clip((k − e)/ℓ, 0, 1)`` is free, whichever way it drives. ``p = 0``: the robot waits for
    fixes that shrink ``e`` (standing still adds no odometry error); a slower robot also drifts
    less, so its filter settles to a smaller ``e``. A step the certificate covers (``e ≤ δ*`` on a
    funnel plan, ALGORITHMS §11.4) is taken at full speed as it is, and so is every step on a
    paper plan (which runs as the papers ran it). The cheap bound first: the slack of ``x̂`` in its
    own funnel cell (cells are free, C1); the exact distance
    (:func:`~bearnav_cli.runtime.sight.obstacle_clearance`) only where that bound slows it.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: cells, ``usable_tolerance`` (τ_c), obstacle edges and ``B_r``.
    s : ControlSettings
        ``top_speed`` (map units / s), ``dt`` (s) and ``odometry_drift``.
    cell : ndarray of int, shape (R,)
        Each robot's active cell (``-1`` for none).
    x_hat : ndarray, shape (R, 2)
        Position estimates (map units).
    error_bound : ndarray, shape (R,)
        Their error bounds ``e`` (map units; ``inf`` before the first fix: pace 0).

    Returns
    -------
    pace : ndarray, shape (R,)
        The fraction of full speed allowed, in ``[0, 1]``.
    away : ndarray, shape (R, 2)
        Where the pace is below 1: the unit direction away from the nearest obstacle piece
        (:func:`~bearnav_cli.runtime.sight.obstacle_clearance`); zero elsewhere.
    """
    e = np.asarray(error_bound, float).reshape(-1)
    away = np.zeros((len(e), 2))
    if not arrays.funnel:  # paper plans run as the papers ran them
        return np.ones(len(e)), away
    pace = np.where(e <= arrays.tolerance_in(cell) + s.tol, 1.0, 0.0)
    step = s.top_speed * s.dt * (1.0 + s.odometry_drift)
    todo = (pace < 1.0) & np.isfinite(e)
    cell = np.asarray(cell, np.int64).reshape(-1)
    quick = todo & (cell >= 0)
    if quick.any():
        idx = np.flatnonzero(quick)
        pace[idx] = np.clip((cell_slack(arrays, cell[idx], x_hat[idx]) - e[idx]) / step, 0.0, 1.0)
        todo[idx[pace[idx] >= 1.0]] = False
    if todo.any():
        idx = np.flatnonzero(todo)
        clearance, away[idx] = obstacle_clearance(arrays, x_hat[idx])
        pace[idx] = np.maximum(pace[idx], np.clip((clearance - e[idx]) / step, 0.0, 1.0))
        away[idx[pace[idx] >= 1.0]] = 0.0
    return pace, away


def steer_clear(u: np.ndarray, pace: np.ndarray, away: np.ndarray) -> np.ndarray:
    """The unit command bent away from the nearest obstacle as the pace drops, shape (R, 2).

    ``u − (1 − p)·min(u·a, 0)·a + (1 − p)·a``, normalised: at full pace (``p = 1``) the command
    is ``u``; below, its component toward the obstacle fades and a push along ``away`` grows, so a
    robot slowed by its error ball (:func:`error_ball_pace`) also gains clearance, and its pace
    recovers, instead of creeping along the obstacle. At ``p = 0`` the push dominates. Rows with
    no command (``u = 0``) or no ``away`` stay as they are.

    Parameters
    ----------
    u : ndarray, shape (R, 2)
        Unit commands (zero rows: none).
    pace : ndarray, shape (R,)
        Allowed fraction of full speed, in ``[0, 1]``.
    away : ndarray, shape (R, 2)
        Unit directions away from the nearest obstacle piece (zero rows: no push).
    """
    w = (1.0 - np.asarray(pace, float))[:, None]
    toward = np.minimum(np.einsum("rk,rk->r", u, away), 0.0)[:, None]
    bent = u - w * toward * away + w * away
    norm = np.hypot(bent[:, 0], bent[:, 1])
    ok = (w[:, 0] > 0) & (norm > 0) & np.any(u != 0.0, axis=1) & np.any(away != 0.0, axis=1)
    out = u.copy()
    out[ok] = bent[ok] / norm[ok, None]
    return out


def carry_inside(arrays: PlanArrays, s: ControlSettings, state: ControlState, est: Estimate) -> Estimate:
    """Odometry also carries a robot that lost its fix while its whole error ball lies in one funnel cell.

    :func:`~bearnav_cli.runtime.estimate.fuse` stops blind travel once the estimate's 3σ exceeds
    ``blind_error`` (after ``hold_time``). A robot in the middle of a large cell may still drive on:
    where some cell eroded by the error bound holds ``x̂`` (``least_rank_cell`` with that erosion),
    the true position lies (within 3σ) in that cell, which is free (C1). Robots approaching a node
    and plans that are not funnels are left to ``fuse``'s rule.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: only a funnel plan's cells (``arrays.funnel``) let a robot drive on this way.
    s : ControlSettings
        Only with ``s.odometry`` on (without it there is no estimate between fixes).
    state : ControlState
        The previous step's state: the robot must be following a cell (``cell >= 0``), not
        approaching a node (``target == -1``).
    est : Estimate
        This step's estimate from :func:`~bearnav_cli.runtime.estimate.fuse`, with a finite
        ``error_bound`` (map units).

    Returns
    -------
    Estimate
        ``est`` with ``steer`` also set for the robots whose eroded cell holds ``x̂``.
    """
    wait = ~est.steer & est.known & s.odometry & (state.cell >= 0) & (state.target < 0) & np.isfinite(est.error_bound)
    if not arrays.funnel or not wait.any():
        return est
    idx = np.flatnonzero(wait)
    inside = least_rank_cell(arrays, est.x_hat[idx], est.error_bound[idx]) >= 0
    if not inside.any():
        return est
    steer = est.steer.copy()
    steer[idx[inside]] = True
    return dataclasses.replace(est, steer=steer)
