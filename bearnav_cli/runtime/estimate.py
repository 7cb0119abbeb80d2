"""Where the robot is: the bearing fix and its fusion with odometry (ALGORITHMS §6.2, §7.2, §11.4).

Numpy only. :func:`measure` turns one frame's bearings (or displacements) into a position fix
and its variance; :func:`fuse` runs the scalar Kalman filter that carries the estimate on the
robot's own motion between fixes, rejects outliers, and says whether the robot has an estimate
to steer by this step. The error bound ``3σ`` it returns is what the funnel policy erodes cells
by and what a certified step is measured against (§11.4).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bearnav_cli.runtime import bearing
from bearnav_cli.runtime.plan_arrays import PlanArrays
from bearnav_cli.runtime.settings import ControlSettings, ControlState

__all__ = [
    "BOUND_DOUBLINGS",
    "MAX_BOUND",
    "Estimate",
    "Fix",
    "SetEstimate",
    "axle_bounds",
    "bounded_update",
    "fuse",
    "measure",
]

#: The widest bearing bound a robot widens its ``η`` to when its set comes out empty (rad): the cones
#: stay well inside a half-plane.
MAX_BOUND = math.radians(30.0)
#: At most this many doublings of ``η`` per empty set (0.2° reaches :data:`MAX_BOUND` in 8).
BOUND_DOUBLINGS = 12


@dataclass(frozen=True)
class Fix:
    """One frame's position fix for ``R`` robots.

    Attributes
    ----------
    position : ndarray, shape (R, 2)
        ``lsq`` fix from the bearings (§6.2), or the displacement measurement (map units).
    usable : ndarray of bool, shape (R,)
        A fix was made (two or more well-spread bearings) and its predicted error is acceptable.
    variance : ndarray, shape (R,)
        Its variance (map units²), from the bearing noise and geometry; 0 noise-free.
    """

    position: np.ndarray
    usable: np.ndarray
    variance: np.ndarray


def measure(
    arrays: PlanArrays,
    s: ControlSettings,
    bearings: np.ndarray,
    visible: np.ndarray,
    x_true: np.ndarray | None = None,
    displacements: np.ndarray | None = None,
    prior: np.ndarray | None = None,
) -> Fix:
    """The position fix of one frame, for ``R`` robots (ALGORITHMS §6.2, §7.2).

    Bearing mode: the ``lsq`` intersection of the visible bearing lines
    (:func:`bearnav_cli.runtime.bearing.reconstruct`), whatever ``s.reconstruction`` is. With
    ``s.bearing_sigma > 0`` it is refined to the distance-weighted intersection
    (:func:`bearnav_cli.runtime.bearing.refine_fix`), its variance is
    :func:`bearnav_cli.runtime.bearing.fix_variance`, and a fix whose 3σ exceeds
    ``s.max_fix_error`` is not usable. Where a ``prior`` position is given, the weights and the
    variance take their distances there, not at the fix: a fix that errs toward the landmarks
    would otherwise claim a smaller variance, win more weight in the filter, and pull the
    average of many fixes toward them (2 map units of bias beside a row of wall tags on
    paper_sim at 2°). Displacement mode: ``mean_k(l_k − d_k)`` of the measured
    ``displacements``, else the true position, always usable with variance 0.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's run-time arrays: the fix is made against its ``landmarks`` (L, 2), and its
        ``tol`` bounds the distances of the fix variance from below.
    s : ControlSettings
        Its ``measurement`` picks the mode; ``min_spread`` (rad) and ``tol`` (map units) decide
        whether an ``lsq`` fix is usable, ``bearing_sigma`` (rad) gives its variance and
        ``max_fix_error`` (map units) rejects the poor ones.
    bearings : ndarray, shape (R, L, 2)
        World-frame unit bearings from each robot to every landmark (ignored in displacement mode).
    visible : ndarray of bool, shape (R, L)
        Which landmarks each robot sees (only those enter the fix).
    x_true : ndarray, shape (R, 2), optional
        True positions (map units): the measurement in displacement mode when ``displacements``
        is not given; ignored in bearing mode.
    displacements : ndarray, shape (R, L, 2), optional
        Measured ``l_k − x`` (map units) in displacement mode, for a world that differs from the
        plan's: the fix is the position that fits them best against the plan's landmarks.
    prior : ndarray, shape (R, 2), optional
        Where each robot's filter predicts it is (map units; NaN rows: no prediction), for the
        distances of a noisy fix's weights and variance.

    Returns
    -------
    Fix

    Raises
    ------
    ValueError
        Displacement mode with neither ``displacements`` nor ``x_true``.
    """
    r = len(visible)
    if s.measurement == "displacement":
        if displacements is not None:
            measured = np.mean(arrays.landmarks[None] - displacements, axis=1)
        elif x_true is None:
            raise ValueError("displacement measurement needs the true positions")
        else:
            measured = np.array(x_true, float).reshape(-1, 2)
        fix = np.ones(r, bool)
    else:
        estimate = bearing.reconstruct(
            bearings, visible, arrays.landmarks, 0, method="lsq", min_spread=s.min_spread, tol=s.tol
        )
        measured, fix = estimate.x_hat, estimate.usable.copy()
    at = measured  # where a fix's variance takes its distances
    if s.measurement != "displacement" and s.bearing_sigma > 0 and fix.any():
        # noisy bearings: the distance-weighted fix (exact bearings give the same point), weighed
        # once at the prediction where there is one, else reweighted from the lsq fix
        p = np.full((r, 2), np.nan) if prior is None else np.asarray(prior, float).reshape(-1, 2)
        known = np.all(np.isfinite(p), axis=1)
        start = np.where(known[:, None], p, measured)
        refined = measured.copy()
        for rows, passes in ((fix & known, 1), (fix & ~known, 2)):
            if rows.any():
                refined[rows] = bearing.refine_fix(
                    bearings[rows], visible[rows], arrays.landmarks, start[rows], s.tol, iterations=passes
                )
        at = np.where(known[:, None], start, refined)  # no prediction: the variance at the refined fix
        measured = refined
    sigma_fix2 = np.zeros(r)
    if s.bearing_sigma > 0 and fix.any():
        sigma_fix2[fix] = bearing.fix_variance(
            bearings[fix], visible[fix], arrays.landmarks, at[fix], s.bearing_sigma, arrays.tol
        )
        fix &= sigma_fix2 <= (s.max_fix_error / 3.0) ** 2
    return Fix(measured, fix, sigma_fix2)


@dataclass(frozen=True)
class Estimate:
    """The fused estimate after one step, ``R`` robots.

    Attributes
    ----------
    x_hat : ndarray, shape (R, 2)
        The estimate (the fix where one was taken, else odometry's prediction), map units.
    var : ndarray, shape (R,)
        Its variance (map units²), ``inf`` before the first fix.
    fix : ndarray of bool, shape (R,)
        A fix was taken (usable and within 3σ of the prediction).
    steer : ndarray of bool, shape (R,)
        The robot has an estimate to steer by: a fix, or odometry still trusted (``hold_time``, or
        3σ within ``blind_error``).
    known : ndarray of bool, shape (R,)
        The robot has had a fix.
    hold : ndarray, shape (R,)
        Seconds since the last fix.
    error_bound : ndarray, shape (R,)
        ``3σ`` of the estimate (map units; 0 for exact fixes, ``inf`` before the first).
    """

    x_hat: np.ndarray
    var: np.ndarray
    fix: np.ndarray
    steer: np.ndarray
    known: np.ndarray
    hold: np.ndarray
    error_bound: np.ndarray


def fuse(s: ControlSettings, state: ControlState, fix: Fix) -> Estimate:
    """One step of the scalar Kalman filter that fuses fixes with odometry.

    The prediction moves the last estimate by the last command; its standard deviation grows
    linearly with the distance, ``odometry_drift`` per unit (``σ ← σ + drift·ℓ`` for a step of length
    ``ℓ``), because wheel slip is mostly systematic over a run (a scale and heading error: its error
    grows like ``d``, not ``√d``). A fix of variance σ_fix² corrects it, and a fix farther
    than 3 standard deviations from the prediction is rejected; a rejected fix widens the
    prediction's variance to the gap (``3σ = ‖fix − prediction‖``), so an estimate that has
    drifted off is not kept for sure: the next consistent fix passes and pulls it back. Noise-free
    (σ = 0) every fix is taken as it is.

    Without a fix the robot still steers by the prediction for ``hold_time`` seconds, and after
    that while its 3σ stays within ``blind_error``; with ``s.odometry`` off nothing is predicted
    and only a fix lets the robot steer.

    Parameters
    ----------
    s : ControlSettings
        The filter's constants: ``dt`` (s), ``odometry`` (predict between fixes or not),
        ``odometry_drift`` (σ per unit travelled), ``hold_time`` (s) and ``blind_error`` (map units).
    state : ControlState
        The previous step's estimate ``x_hat``, its variance ``var``, the last command's ``motion``
        (map units / s, what the prediction integrates over ``dt``), ``known`` and ``hold``.
    fix : Fix
        This frame's fix from :func:`measure`.

    Returns
    -------
    Estimate
    """
    measured, sigma_fix2 = fix.position, fix.variance
    fix = fix.usable.copy()
    known = state.known.copy()
    predicted = state.x_hat + s.dt * state.motion
    recent = known & s.odometry  # a prediction exists; its variance says how far to trust it
    travelled = s.dt * np.hypot(state.motion[:, 0], state.motion[:, 1])
    # wheel slip is mostly systematic (a per-run scale and heading error), so the odometry error
    # since the last fix grows linearly with the distance: σ grows by drift·travelled per step
    with np.errstate(invalid="ignore"):
        var_pred = (np.sqrt(np.maximum(state.var, 0.0)) + s.odometry_drift * travelled) ** 2
    innovation = np.einsum("rk,rk->r", measured - predicted, measured - predicted)
    rejected = fix & recent & (innovation > 9.0 * (var_pred + sigma_fix2))
    fix &= ~rejected
    # a usable fix this far off says the prediction may be as wrong as the gap between them: without
    # this, an estimate that has drifted beyond its 3σ rejects every later fix while the robot stands
    # (its variance grows only with motion) and stays wrong and sure of itself; with it, the next
    # consistent fix passes the gate and pulls the estimate back
    with np.errstate(invalid="ignore"):
        var_pred = np.where(rejected, np.maximum(var_pred, innovation / 9.0), var_pred)
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
    with np.errstate(invalid="ignore"):  # 3σ; 0 for exact fixes, inf before the first
        error_bound = np.where(np.isfinite(var), 3.0 * np.sqrt(np.maximum(var, 0.0)), np.inf)
    return Estimate(x_hat, var, fix, steer, known, hold, error_bound)


@dataclass(frozen=True)
class SetEstimate:
    """The estimate sets after one step, ``R`` robots (ALGORITHMS §12.2, Lemma 5).

    Attributes
    ----------
    vertices : ndarray, shape (R, W, 2)
        ``X_t``, counter-clockwise convex polygons padded to :data:`~bearnav_cli.runtime.bounded.MAX_VERTICES`
        (map units; :mod:`~bearnav_cli.runtime.bounded` reads only the first ``count`` of each).
    count : ndarray of int64, shape (R,)
        Vertices of each set.
    x_hat : ndarray, shape (R, 2)
        The estimate, a point of ``X_t`` (map units).
    error : ndarray, shape (R,)
        ``e_t = max_v ‖v − x̂_t‖`` (map units), exact: ``‖x_t − x̂_t‖ ≤ e_t`` whenever ``x_t ∈ X_t``.
    inconsistent : ndarray of bool, shape (R,)
        ``X_t⁻ ∩ ∩_k W_k`` was empty this step: a bound was broken; the set restarted from the bearing
        sets alone (``B_r ∩ ∩_k W_k``), or stayed ``X_t⁻`` where those were empty too.
    seen : ndarray of bool, shape (R,)
        Some bearing entered the set this step.
    bound_scale : ndarray, shape (R,)
        The factor on ``η`` each robot assumes from now on (widened where the set came out empty).
    """

    vertices: np.ndarray
    count: np.ndarray
    x_hat: np.ndarray
    error: np.ndarray
    inconsistent: np.ndarray
    seen: np.ndarray
    bound_scale: np.ndarray


def bounded_update(
    arrays: PlanArrays,
    s: ControlSettings,
    state: ControlState,
    bearings: np.ndarray,
    visible: np.ndarray,
    x_true: np.ndarray | None = None,
) -> SetEstimate:
    """One step of the bounded-error estimator for ``R`` robots (ALGORITHMS §12.2).

    Predict: ``X_t⁻ = (X_{t−1} + d̂_t) ⊕ B(κ‖d̂_t‖ + ν)`` with ``d̂_t = dt·motion`` the last command's
    displacement (rows moved outward, :func:`~bearnav_cli.runtime.bounded.grow`); a step that does not
    translate (standing, or a unicycle turning about its axle) adds nothing. Update: ``X_t = X_t⁻ ∩
    ∩_{k visible} W(l_k, φ̃_k)`` with the cones of half-angle ``η`` (``s.bearing_bound``); with a compass
    bound ``ψ > 0`` (``s.heading_bound``, a share of ``η``), the view's bearings bound the common heading
    error themselves (:func:`~bearnav_cli.runtime.bounded.common_rotation`): the cones turn back by its
    middle and have the half-angle ``η − ψ`` plus its half-width, never more than ``η``. A robot
    without a set yet (``state.known`` False) starts from ``B_r`` (:func:`axle_bounds`).
    Displacement mode measures the position itself: ``X_t = {x}``, ``e_t = 0``.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's ``landmarks``, ``free_bounds`` and ``tol``.
    s : ControlSettings
        ``dt`` (s), ``bearing_bound`` η (rad), ``slip`` κ, ``slip_floor`` ν (map units) and ``measurement``.
    state : ControlState
        The previous ``set_vertices``/``set_count``, ``motion`` (map units / s) and ``known``.
    bearings : ndarray, shape (R, L, 2)
        Measured world-frame unit bearings.
    visible : ndarray of bool, shape (R, L)
        Which landmarks each robot sees (only their cones clip the sets).
    x_true : ndarray, shape (R, 2), optional
        True positions: the measurement in displacement mode.

    Returns
    -------
    SetEstimate
    """
    from bearnav_cli.runtime import bounded

    r, tol = len(visible), arrays.tol
    if s.measurement == "displacement":
        if x_true is None:
            raise ValueError("displacement measurement needs the true positions")
        x = np.asarray(x_true, float).reshape(-1, 2)
        vertices = np.repeat(x[:, None, :], bounded.MAX_VERTICES, axis=1)
        exact = np.ones(r, bool)
        return SetEstimate(vertices, exact.astype(np.int64), x.copy(), np.zeros(r), ~exact, exact, state.bound_scale)
    width = bounded.MAX_VERTICES  # every stored set has this width (operations cap their counts at it)
    d = s.dt * state.motion
    travelled = np.hypot(d[:, 0], d[:, 1])
    radius = np.where(travelled > 0.0, s.drift * travelled + s.slip_floor, 0.0)
    box = axle_bounds(arrays)
    start_v, start_n = bounded.box(box, r)
    known = state.known
    vertices = np.where(known[:, None, None], bounded.translate(state.set_vertices, d), bounded.fit(start_v, width))
    count = np.where(known, state.set_count, start_n)
    moving = np.flatnonzero(known & (radius > 0.0))
    if len(moving):
        grown_v, grown_n = bounded.grow(vertices[moving], count[moving], radius[moving], tol)
        # the axle is always within B_r: the grown set is cut back to it (a robot by a wall keeps a set that
        # does not reach through the wall, so it can lie wholly in a cell that reaches the wall, §12.7)
        grown_v = bounded.fit(grown_v, width)  # grow's own new array: written in place below
        valid = bounded.valid_vertices(grown_v, grown_n)[..., None]
        out = np.flatnonzero(np.any(valid & ((grown_v < box[:2] - tol) | (grown_v > box[2:] + tol)), axis=(1, 2)))
        if len(out):  # few: only these are cut, by x ≥ x0, x ≤ x1, y ≥ y0, y ≤ y1 as four rows a·y ≤ b
            rows = np.broadcast_to(np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]]), (len(out), 4, 2))
            offsets = np.broadcast_to(np.array([-box[0], box[2], -box[1], box[3]]), (len(out), 4))
            cut_v, cut_n = bounded.clip_pairs(grown_v[out], grown_n[out], np.arange(len(out)), rows, offsets, tol)
            grown_v[out], grown_n[out] = bounded.fit(cut_v, width), cut_n
        vertices[moving], count[moving] = grown_v, grown_n
    angle = np.arctan2(bearings[..., 1], bearings[..., 0])
    scale = state.bound_scale.copy()
    eta = s.bearing_bound * scale
    if s.heading_bound > 0.0:
        # every bearing of a view shares the compass's error: where the view bounds it more tightly than ψ, the cones
        # turn back by the middle of that bound and widen by its half-width only (§12.1's heading from bearings)
        camera = (s.bearing_bound - s.heading_bound) * scale
        middle, half = bounded.common_rotation(
            vertices, count, arrays.landmarks, angle, visible, camera, s.heading_bound * scale, tol
        )
        angle = angle - middle[:, None]
        eta = camera + half
    updated_v, updated_n = bounded.intersect_cones(vertices, count, arrays.landmarks, angle, visible, eta, tol)
    updated_v, updated_n = bounded.fit(updated_v, width).copy(), updated_n.copy()
    inconsistent = (updated_n == 0) & (count > 0)
    if inconsistent.any():
        # a bound was broken: the bearing sets alone, at the least doubling of this robot's η for which they
        # meet (kept from now on: a robot that has seen its bound broken no longer trusts it), or the
        # prediction where no doubling up to MAX_BOUND does
        idx = np.flatnonzero(inconsistent)
        fresh_v, fresh_n = bounded.fit(start_v[idx], width).copy(), np.zeros(len(idx), np.int64)
        for _ in range(BOUND_DOUBLINGS):
            todo = np.flatnonzero((fresh_n == 0) & (2.0 * eta[idx] <= MAX_BOUND))
            if not len(todo):
                break
            who = idx[todo]
            scale[who] *= 2.0
            eta[who] *= 2.0
            got_v, got_n = bounded.intersect_cones(
                start_v[who], start_n[who], arrays.landmarks, angle[who], visible[who], eta[who], tol
            )
            fresh_v[todo], fresh_n[todo] = bounded.fit(got_v, width), got_n
        empty = fresh_n == 0
        fresh_v[empty], fresh_n[empty] = vertices[idx[empty]], count[idx[empty]]
        updated_v[idx], updated_n[idx] = fresh_v, fresh_n
    x_hat, error = bounded.centre(updated_v, updated_n)
    return SetEstimate(updated_v, updated_n, x_hat, error, inconsistent, visible.any(axis=1), scale)


def axle_bounds(arrays: PlanArrays) -> np.ndarray:
    """``B_r`` of the robot's own centre: the bounds shrunk by its radius ρ alone, ``[xmin, ymin, xmax, ymax]``.

    Not ``free_bounds`` (shrunk by ``ρ + λ``): a look-ahead unicycle's axle may come within ρ of a wall.
    """
    rho = arrays.robot_radius
    return np.asarray(arrays.bounds, float) + np.array([rho, rho, -rho, -rho])
