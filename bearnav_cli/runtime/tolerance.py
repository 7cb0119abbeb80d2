"""The position error a cell's certificate tolerates where the robot is, not only at its worst vertex (§11.4, §12.3).

Numpy only. §11.4's argument is pointwise: at the true position ``x`` a field applied at ``x̂`` with
``‖x̂ − x‖ ≤ δ`` changes ``n·u`` by at most ``‖Mᵀn‖δ``, so the conditions hold at ``x`` while ``δ`` is at
most ``δ(x) = min(min_k σ_h,k(x)/‖Mᵀn_k‖, σ_v(x)/‖Mᵀz‖)``, with the margins

- ``σ_h,k(x) = n_k·u(x) + c_h h_k(x)`` of the barrier rows (L1), and
- ``σ_v(x) = −z·u(x)`` of the progress condition (L2) taken with rate 0: ``V`` still decreases at a rate
  of at least ``σ_v − ‖Mᵀz‖δ > 0`` (only the time bound depends on ``c_v``), and
  ``σ_v(x) = σ_v,c_v(x) + c_v V(x)`` is at least the rated margin wherever ``V ≥ 0``.

Both are affine in ``x``, so ``δ`` is concave: its least value over a convex set is at the set's
vertices, and over a set grown by a disc of radius ``ρ`` it is at least each row's value less
``ρ‖∇σ‖``. ``δ_c`` of the cell is its least value over the cell's vertices, the value the robot must
keep wherever it is; inside the cell ``δ(x)`` is larger, on a long cell far larger. What ``δ_c`` also
carries, ``τ_c ≤ δ_e,c/2`` for the switch at the exit (Theorem 2's progress step), is needed only when
the truth can reach the exit face: a set farther from it than one step keeps ``δ(X)`` alone.
"""

from __future__ import annotations

import numpy as np

from bearnav_cli.runtime.plan_arrays import PlanArrays

__all__ = ["set_tolerance", "step_reach"]


def _rows(arrays: PlanArrays, cell: np.ndarray):
    """Each robot's cell as margin rows ``σ(x) = g·x + s`` over the gain norms ``‖Mᵀn‖`` (R, Q + 1) of its barrier
    rows and its progress row, padding rows with ``g = 0``, ``s = +inf``."""
    M, a = arrays.field_M[cell], arrays.field_a[cell]  # (R, 2, 2), (R, 2)
    n, q = arrays.bar_A[cell], arrays.bar_b[cell]  # (R, Q, 2), (R, Q)
    real = np.isfinite(q)
    c_h = np.where(np.isfinite(arrays.c_h[cell]), arrays.c_h[cell], 0.0)[:, None, None]
    # σ_h = n·(a − Mx) + c_h(n·x + q) = (c_h n − Mᵀn)·x + n·a + c_h q
    mt_n = np.einsum("rji,rqj->rqi", M, n)  # Mᵀn per row
    slope_h = c_h * n - mt_n
    const_h = np.einsum("rqi,ri->rq", n, a) + c_h[..., 0] * np.where(real, q, 0.0)
    norm_h = np.hypot(mt_n[..., 0], mt_n[..., 1])
    # σ_v = −z·(a − Mx) = (Mᵀz)·x − z·a
    z = arrays.exit_dir[cell]
    mt_z = np.einsum("rji,rj->ri", M, z)
    slope = np.concatenate([np.where(real[..., None], slope_h, 0.0), mt_z[:, None, :]], axis=1)
    const = np.concatenate([np.where(real, const_h, np.inf), -np.einsum("ri,ri->r", z, a)[:, None]], axis=1)
    norm = np.concatenate([np.where(real, norm_h, 0.0), np.hypot(mt_z[:, 0], mt_z[:, 1])[:, None]], axis=1)
    return slope, const, norm


def step_reach(step: float, slip: float, floor: float, lookahead: float = 0.0) -> float:
    """How far the truth can move in one step at most (map units): ``ℓ``, the odometry's ``κℓ + ν``, and a look-ahead
    point's swing ``ℓ²/2λ`` on the arc of its largest turn (:class:`~bearnav_cli.runtime.safety.StepError`).

    Parameters
    ----------
    step : float
        ``ℓ``, a full step's length (map units).
    slip : float
        ``κ`` (with a heading error, ``κ + 2 sin(ψ/2)``; dimensionless).
    floor : float
        ``ν`` (map units).
    lookahead : float
        ``λ`` (map units); 0 for a robot that is its own reference point.
    """
    return step * (1.0 + slip) + floor + (step * step / (2.0 * lookahead) if lookahead > 0.0 else 0.0)


def set_tolerance(
    arrays: PlanArrays,
    cell: np.ndarray,
    vertices: np.ndarray,
    valid: np.ndarray,
    grow: np.ndarray | float = 0.0,
    reach: np.ndarray | float = 0.0,
) -> np.ndarray:
    """The error the certificate of each robot's cell tolerates over its whole set of positions, shape (R,), map units.

    ``min(δ(X ⊕ B(grow)), δ_e,c/2 if the set comes within reach of the exit face)``, at least ``τ_c`` for
    a set inside the cell (see the module). The goal cell, which has no exit, keeps ``τ_c``.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: fields, barrier rows, exit rows and insets of a funnel plan.
    cell : ndarray of int, shape (R,)
        Each robot's active cell (``>= 0``).
    vertices : ndarray, shape (R, W, 2)
        Points whose convex hull holds the truth (a set's vertices, map units).
    valid : ndarray of bool, shape (R, W)
        Which of them are real (not padding).
    grow : float or ndarray, shape (R,)
        The hull grown by this radius holds the truth (map units).
    reach : float or ndarray, shape (R,)
        How far the truth may move toward the exit face before the next check (a step and its error,
        map units): within it the switch's ``δ_e,c/2`` applies.
    """
    c = np.asarray(cell, np.int64).reshape(-1)
    r = len(c)
    grow = np.broadcast_to(np.asarray(grow, float), (r,))
    reach = np.broadcast_to(np.asarray(reach, float), (r,))
    slope, const, norm = _rows(arrays, c)
    sigma = np.einsum("rqi,rwi->rwq", slope, vertices) + const[:, None, :]  # (R, W, Q + 1)
    sigma = sigma - grow[:, None, None] * np.hypot(slope[..., 0], slope[..., 1])[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        per_row = np.where(norm[:, None, :] > 0.0, sigma / norm[:, None, :], np.where(sigma > 0.0, np.inf, 0.0))
    per_row = np.where(sigma > 0.0, per_row, 0.0)  # a margin that is not positive tolerates nothing
    delta = np.min(np.where(valid[..., None], per_row, np.inf), axis=(1, 2))
    # the exit face: V(x) = z·(x − x_j), least over the set, less the growth
    z, x_j = arrays.exit_dir[c], arrays.exit_point[c]
    depth = np.einsum("ri,rwi->rw", z, vertices - x_j[:, None, :])
    nearest = np.min(np.where(valid, depth, np.inf), axis=1) - grow
    half = 0.5 * arrays.exit_inset[c]
    near_exit = nearest <= reach
    local = np.where(near_exit, np.minimum(delta, half), delta)
    goal = ~np.isfinite(half)
    tau = arrays.tolerance_in(c)
    return np.where(goal, tau, np.maximum(local, tau))
