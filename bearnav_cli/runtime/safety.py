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

__all__ = ["bend_inward", "carry_inside", "certified_pace", "error_ball_pace", "steer_clear"]


def certified_pace(
    arrays: PlanArrays,
    cell: np.ndarray,
    x_hat: np.ndarray,
    error: np.ndarray,
    direction: np.ndarray,
    step: float,
    disturbance: float,
) -> np.ndarray:
    """The largest fraction of a step that keeps the truth in its cell's barrier set, shape (R,) in [0, 1].

    The discrete-time part of Theorem 2 (ALGORITHMS §12.3), done exactly: the true position ``x``
    lies within ``e`` of ``x̂`` and, by induction, in the cell (every barrier row ``h_k = A_k·x + b_k
    ≥ 0``); a step at the fraction ``p`` moves it by ``pℓ·d`` plus an error of at most ``w``
    (``κpℓ + ν``, and for a look-ahead point the Euler error ``ℓ²/2λ``). Row ``k`` stays satisfied if

    - the step moves inward fast enough: ``pℓ (A_k·d) ≥ w`` (then ``h_k`` does not decrease), or
    - the row is far enough whichever way: ``h_k(x̂) − e ≥ pℓ + w``.

    The first holds for every ``p`` once ``A_k·d ≥ w/ℓ`` (with ``w`` at ``p = 1``, an upper bound); the
    second bounds ``p``. The pace is the least bound over the rows that need it (0: no step is safe).
    The exit row is not a barrier: crossing it is the progress the cell is for.

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
    step : float
        ``ℓ``, a full step's length (map units).
    disturbance : float
        ``w``: the bound on a step's motion error at full length (map units).
    """
    c = np.asarray(cell, np.int64)
    A, b = arrays.bar_A[c], arrays.bar_b[c]
    with np.errstate(invalid="ignore"):
        h = np.einsum("rqi,ri->rq", A, x_hat) + b
    inward = np.einsum("rqi,ri->rq", A, direction)
    free = ~np.isfinite(b) | (step * inward >= disturbance)
    with np.errstate(invalid="ignore"):
        room = (h - error[:, None] - disturbance) / step
    bound = np.where(free, 1.0, np.clip(room, 0.0, 1.0))
    return np.min(bound, axis=1, initial=1.0)


def bend_inward(
    arrays: PlanArrays,
    cell: np.ndarray,
    x_hat: np.ndarray,
    error: np.ndarray,
    direction: np.ndarray,
    step: float,
    disturbance: float,
) -> np.ndarray:
    """The unit step directions turned toward the inside of the faces that :func:`certified_pace` finds near, (R, 2).

    For every barrier row ``k`` within reach (``h_k(x̂) − e < ℓ + w``) that the step does not leave
    fast enough (``A_k·d < w/ℓ``), the direction gains ``(w/ℓ − A_k·d + 0.01)·A_k``; the sum is
    normalised. The exit direction is kept: a bend that would stop the progress (``z·d' ≥ 0`` in a cell
    with an exit) gives the field's direction back. Safety does not rest on the bend: the step it
    gives is taken only at :func:`certified_pace`'s pace, which checks every row exactly.

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
    step, disturbance : float
        ``ℓ`` and ``w`` as in :func:`certified_pace` (map units).
    """
    c = np.asarray(cell, np.int64)
    A, b = arrays.bar_A[c], arrays.bar_b[c]
    with np.errstate(invalid="ignore"):
        h = np.einsum("rqi,ri->rq", A, x_hat) + b
    inward = np.einsum("rqi,ri->rq", A, direction)
    need = np.isfinite(b) & (h - error[:, None] < step + disturbance) & (inward < disturbance / step)
    gain = np.where(need, disturbance / step - inward + 0.01, 0.0)
    bent = direction + np.einsum("rq,rqi->ri", gain, np.where(np.isfinite(b)[..., None], A, 0.0))
    norm = np.hypot(bent[:, 0], bent[:, 1])
    out = np.where(norm[:, None] > 0, bent / np.where(norm > 0, norm, 1.0)[:, None], direction)
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
