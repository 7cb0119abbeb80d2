"""Looking for landmarks (ALGORITHMS §7.5, §12.5): who looks around, and which way to turn.

Numpy only. :func:`look_around` decides which robots stop to look, which are lost and how they
turn; a look on purpose turns first to the heading the map promises the best fix from
(:func:`best_view_heading`, the filter) or the smallest one-look bound (:func:`best_bound_heading`,
the set estimator); :func:`views` says which landmarks a camera sees at each heading.
"""

from __future__ import annotations

import math

import numpy as np

from bearnav_cli.runtime import bearing
from bearnav_cli.runtime.estimate import Estimate, axle_bounds
from bearnav_cli.runtime.look_bound import one_look_bound
from bearnav_cli.runtime.plan_arrays import PlanArrays
from bearnav_cli.runtime.settings import ControlSettings, ControlState
from bearnav_cli.runtime.sight import in_sight

__all__ = ["LOOK_HEADINGS", "best_bound_heading", "best_view_heading", "look_around", "look_time", "views"]

#: Headings tried when a look chooses where to turn (ALGORITHMS §12.5).
LOOK_HEADINGS = 36


def look_around(
    s: ControlSettings,
    state: ControlState,
    est: Estimate,
    last_dir: np.ndarray,
    heading: np.ndarray,
    arrays: PlanArrays | None = None,
) -> tuple[np.ndarray, ...]:
    """Who looks around in place, who is lost, and how they turn (ALGORITHMS §7.5 with docs/choices.md).

    With odometry, a robot without an estimate never moves blind: it looks around at once, for
    one revolution at ``β``, then it is lost; without odometry §7.5's hold comes first. A
    look-around starts toward the last command and keeps its direction. Looking on purpose
    (``s.look_on_purpose``, a camera narrower than 2π and ``arrays`` given), it first turns by the
    shorter way to :func:`best_view_heading` at its estimate and stops there; if no fix comes, the
    revolution follows from there (lost after ``3π/β`` in all: half a turn, then a whole one).

    Parameters
    ----------
    s : ControlSettings
        ``odometry``, ``hold_time`` (s), ``beta`` (rad / s), ``dt`` (s), ``look_on_purpose`` and
        ``fov`` (rad).
    state : ControlState
        The previous step's ``known``, ``scanning``, ``scan_from``, ``spin`` and ``look``.
    est : Estimate
        This step's estimate: the robots without ``steer`` look around; ``hold`` (s) is their clock.
    last_dir : ndarray, shape (R, 2)
        Unit direction of the last command (after :func:`~bearnav_cli.runtime.step.follow_fields`): a look-around starts
        turning toward it.
    heading : ndarray, shape (R,)
        The camera's heading ``φ`` (rad).
    arrays : PlanArrays, optional
        The plan, to look on purpose (:func:`best_view_heading`); ``None``: the revolution at once.

    Returns
    -------
    scanning, lost : ndarray of bool, shape (R,)
    spin : ndarray, shape (R,)
        ``±1``, the direction of each look-around.
    turn : ndarray, shape (R,)
        The turn rate of the robots looking around (rad / s; 0 for the others).
    look : ndarray, shape (R,)
        The heading each look on purpose turns to (rad; NaN for none).
    """
    holding = ~est.steer
    if s.odometry:
        scanning = holding
        # a look-around's clock starts with it: odometry may have carried the robot blind for longer
        # than hold_time (while its error bound stayed within blind_error)
        begun = np.where(state.scanning, state.scan_from, est.hold - s.dt)
        scan_time = est.hold - np.where(state.known, begun, 0.0)
    else:
        scanning = holding & (est.hold > s.hold_time)
        scan_time = est.hold - s.hold_time
    bounded = s.estimator == "set"
    purposeful = _purposeful(s, arrays)
    lost = scanning & (scan_time > look_time(s, arrays))
    phi = np.asarray(heading, float).reshape(len(holding))
    # a scan that always turned one way undid the unicycle's turn toward its field
    toward = bearing.wrap(np.arctan2(last_dir[:, 1], last_dir[:, 0]) - phi)
    starting = scanning & ~state.scanning  # a scan keeps the direction it started with
    spin = np.where(starting, np.where(toward < 0, -1.0, 1.0), state.spin)
    look = np.where(scanning & ~starting, state.look, np.nan)
    if purposeful and starting.any() and np.all(np.isfinite(est.x_hat[starting])):
        idx = np.flatnonzero(starting)
        want = np.arctan2(last_dir[idx, 1], last_dir[idx, 0])  # where the robot was driving
        aim = best_bound_heading if bounded else best_view_heading
        look[idx] = aim(arrays, s, est.x_hat[idx], phi[idx] if bounded else want)
    turn = np.where(scanning, spin * s.beta, 0.0)
    aiming = scanning & np.isfinite(look)
    if aiming.any():
        error = bearing.wrap(look[aiming] - phi[aiming])
        # turn the shorter way and stop on the heading (no overshoot within one step)
        turn[aiming] = np.clip(error / s.dt, -s.beta, s.beta)
        spin[aiming] = np.where(error < 0, -1.0, 1.0)
        arrived = np.abs(error) <= s.beta * s.dt * 1e-6 + 1e-12
        done = np.flatnonzero(aiming)[arrived]
        look[done] = np.nan  # reached without a fix: the revolution follows, in the same direction
    return scanning, lost, spin, turn, look


def _purposeful(s: ControlSettings, arrays: PlanArrays | None) -> bool:
    # the set estimator always looks on purpose: toward the least one-look bound (ALGORITHMS §12.5)
    return (s.look_on_purpose or s.estimator == "set") and arrays is not None and s.fov < 2.0 * math.pi


def look_time(s: ControlSettings, arrays: PlanArrays | None = None) -> float:
    """How long a look may last before the robot is lost (s): one revolution at ``β``, and half a turn more when
    it first turns on purpose to the best heading (:func:`look_around`)."""
    return (3.0 if _purposeful(s, arrays) else 2.0) * math.pi / s.beta


def best_view_heading(
    arrays: PlanArrays, s: ControlSettings, x: np.ndarray, phi: np.ndarray, headings: int = 72
) -> np.ndarray:
    """The camera heading at ``x`` from which the map promises the best fix, shape (R,) rad; NaN if none.

    Among ``headings`` evenly spaced headings, those where at least two landmarks are in the field
    of view, in range and in line of sight (``sight.in_sight``) and spread enough for the
    ``lsq`` fix (``λ_min(Σ P_k) ≥ 1 − cos θ_min``, as :func:`bearing.reconstruct` requires); of
    those, the one nearest to ``phi`` (the direction the robot was driving: a fix there lasts when
    it drives on), ties to the largest ``λ_min(Σ P_k / d_k²)`` (the smallest predicted fix
    variance, :func:`bearing.fix_variance`).

    Parameters
    ----------
    arrays : PlanArrays
        The plan's landmarks (L, 2) and the raw obstacle edges that hide them.
    s : ControlSettings
        The camera's ``fov`` (rad) and ``max_range`` (map units), and ``min_spread`` (rad).
    x : ndarray, shape (R, 2)
        Where each robot looks from: its position estimate (map units).
    phi : ndarray, shape (R,)
        The direction each robot was driving (rad): the heading preferred among the usable ones.
    headings : int
        How many evenly spaced candidate headings over ``[−π, π)`` are tried.
    """
    p = np.asarray(x, float).reshape(-1, 2)
    phi = np.asarray(phi, float).reshape(len(p))
    lm = arrays.landmarks
    d = lm[None] - p[:, None, :]  # (R, L, 2)
    dist2 = np.maximum(np.einsum("rlk,rlk->rl", d, d), arrays.tol**2)
    beta = d / np.sqrt(dist2)[..., None]
    seen = in_sight(arrays, p)
    if math.isfinite(s.max_range):
        seen &= dist2 <= s.max_range**2
    theta = np.linspace(-math.pi, math.pi, headings, endpoint=False)
    angle = np.arctan2(d[..., 1], d[..., 0])  # (R, L)
    in_view = np.abs(bearing.wrap(angle[:, None, :] - theta[None, :, None])) <= 0.5 * s.fov  # (R, H, L)
    vis = in_view & seen[:, None, :]
    bx, by = beta[..., 0][:, None, :], beta[..., 1][:, None, :]

    def lam(weight: np.ndarray) -> np.ndarray:
        a11 = np.sum(weight * (1.0 - bx * bx), axis=2)
        a22 = np.sum(weight * (1.0 - by * by), axis=2)
        a12 = -np.sum(weight * bx * by, axis=2)
        return 0.5 * (a11 + a22) - np.hypot(0.5 * (a11 - a22), a12)

    usable = (vis.sum(axis=2) >= 2) & (lam(vis.astype(float)) >= 1.0 - math.cos(s.min_spread))
    score = np.where(usable, lam(np.where(vis, 1.0 / dist2[:, None, :], 0.0)), -np.inf)
    turn = np.abs(bearing.wrap(theta[None, :] - phi[:, None]))
    turn = np.where(usable, turn, np.inf)
    best = np.lexsort((-score, turn), axis=1)[:, 0] if score.size else np.zeros(len(p), np.int64)
    out = theta[best]
    out[~usable.any(axis=1)] = np.nan
    return out


def best_bound_heading(
    arrays: PlanArrays, s: ControlSettings, x: np.ndarray, phi: np.ndarray, headings: int = LOOK_HEADINGS
) -> np.ndarray:
    """The camera heading at ``x`` whose view promises the smallest one-look bound ``ε``, shape (R,) rad.

    Among ``headings`` evenly spaced headings, the landmarks in the field of view, in range and in
    line of sight from ``x`` (``sight.in_sight``) give
    :func:`~bearnav_cli.runtime.look_bound.one_look_bound` at ``η = s.bearing_bound``; the least ``ε``
    wins, ties to the smallest turn from ``phi`` (ALGORITHMS §12.5). NaN where no heading sees a
    landmark.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's landmarks, sight edges and bounds.
    s : ControlSettings
        ``fov`` (rad), ``max_range`` (map units) and ``bearing_bound`` (rad).
    x : ndarray, shape (R, 2)
        Where each robot looks from (its estimate, map units).
    phi : ndarray, shape (R,)
        Its heading now (rad).
    headings : int
        Candidate headings over ``[−π, π)``.
    """
    p = np.asarray(x, float).reshape(-1, 2)
    phi = np.asarray(phi, float).reshape(len(p))
    visible = views(arrays, p, s.fov, s.max_range, headings)  # (R, H, L)
    r, h, n_lm = visible.shape
    # more cones give a smaller set: only the views no other heading's view contains (the first of
    # equal ones) need their bound; a heading whose view lies in another's is never better
    within = np.all(visible[:, :, None, :] <= visible[:, None, :, :], axis=3)  # (R, H, H): view h ⊆ view h'
    earlier = np.arange(h)[None, :] < np.arange(h)[:, None]  # h' < h
    dominated = np.any(within & (~np.swapaxes(within, 1, 2) | earlier[None]) & ~np.eye(h, dtype=bool)[None], axis=2)
    todo = ~dominated & visible.any(axis=2)
    rr, hh = np.nonzero(todo)
    eps = np.full((r, h), np.inf)
    if len(rr):
        eps[rr, hh] = one_look_bound(
            p[rr], arrays.landmarks, visible[rr, hh], s.bearing_bound, axle_bounds(arrays), arrays.tol
        )
    theta = np.linspace(-math.pi, math.pi, h, endpoint=False)
    turn = np.abs(bearing.wrap(theta[None, :] - phi[:, None]))
    best = np.lexsort((turn, eps), axis=1)[:, 0] if eps.size else np.zeros(len(p), np.int64)
    out = theta[best]
    out[~np.isfinite(eps).any(axis=1)] = np.nan
    return out


def views(
    arrays: PlanArrays, x: np.ndarray, fov: float, max_range: float, headings: int, landmarks: np.ndarray | None = None
) -> np.ndarray:
    """Which landmarks a camera at ``x`` sees at each of ``headings`` evenly spaced headings, (R, H, L).

    In the field of view ``fov`` (rad) around the heading, within ``max_range`` (map units; ``inf``:
    any) and in line of sight (``sight.in_sight``); heading ``k`` is ``−π + 2πk/H``.
    ``landmarks`` (L, 2): other positions than the plan's (tags proposed for it).

    Parameters
    ----------
    arrays : PlanArrays
        The plan's landmarks and the raw obstacle edges that hide them.
    x : ndarray, shape (R, 2)
        Camera positions (map units).
    fov : float
        Full field of view (rad).
    max_range : float
        Range (map units).
    headings : int
        ``H``.
    landmarks : ndarray, shape (L, 2), optional
        The landmarks (map units); default the plan's.
    """
    p = np.asarray(x, float).reshape(-1, 2)
    lm = arrays.landmarks if landmarks is None else np.asarray(landmarks, float).reshape(-1, 2)
    d = lm[None] - p[:, None, :]
    seen = in_sight(arrays, p, lm)
    if math.isfinite(max_range):
        seen &= np.einsum("rlk,rlk->rl", d, d) <= max_range**2
    theta = np.linspace(-math.pi, math.pi, headings, endpoint=False)
    angle = np.arctan2(d[..., 1], d[..., 0])
    in_view = np.abs(bearing.wrap(angle[:, None, :] - theta[None, :, None])) <= 0.5 * fov + 1e-12
    return in_view & seen[:, None, :]
