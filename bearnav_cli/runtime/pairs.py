"""The reconstructions from bearing pairs (ALGORITHMS §6.3–6.4): ``pair`` and ``rescale``.

Numpy only, vectorised over ``R`` robots; :func:`bearnav_cli.runtime.bearing.reconstruct` calls
:func:`pair_output` and :func:`rescale_output` on bearings it has already checked and normalised.
Each returns ``(ỹ (R, L, 2), x̂ (R, 2), usable (R,))``; rows not usable hold finite garbage.
"""

from __future__ import annotations

import numpy as np

from bearnav_cli.runtime.planar import cross, norm, safe

__all__ = ["pair_output", "rescale_output"]

#: Largest number of robot × landmark-pair entries :func:`pair_output` builds at once.
_CHUNK = 1 << 20


def _inter(lm: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Inter-landmark bearings ``g[a, b] = β^a_b = unit(l_b − l_a)`` (L, L, 2) and distances (L, L).

    Landmarks closer than ``tol`` count as coincident: ``g = 0`` there, so every solve that
    needs that line has a zero determinant and is rejected, instead of dividing by a
    distance that may be as small as a subnormal.
    """
    d = lm[None, :, :] - lm[:, None, :]
    dist = norm(d)
    apart = dist >= tol
    return np.where(apart[..., None], d / np.where(apart, dist, 1.0)[..., None], 0.0), np.where(apart, dist, 0.0)


def _best_pairs(beta: np.ndarray, vis: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat index ``a·L + b`` of the visible ordered pair maximising ``κ_ab`` (§6.4) and that ``κ``, shapes (R,).

    ``κ = −1`` when no pair of distinct visible landmarks exists. Ties go to the lowest index.
    """
    r, n_lm = vis.shape
    best = np.zeros(r, np.int64)
    kappa = np.full(r, -1.0)
    distinct = ~np.eye(n_lm, dtype=bool)
    step = max(1, _CHUNK // (n_lm * n_lm))
    for s in range(0, r, step):  # chunks of robots bound the (R, L, L) temporaries, not a loop per robot
        bt, vt = beta[s : s + step], vis[s : s + step]
        at_robot = np.abs(cross(bt[:, :, None, :], bt[:, None, :, :]))  # sin of the angle at x
        at_b = np.abs(cross(bt[:, None, :, :], g[None]))  # sin of the angle at l_b
        pairs = vt[:, :, None] & vt[:, None, :] & distinct[None]
        k = np.where(pairs, np.minimum(at_robot, at_b), -1.0).reshape(len(bt), -1)
        best[s : s + step] = np.argmax(k, axis=1)
        kappa[s : s + step] = k[np.arange(len(bt)), best[s : s + step]]
    return best, kappa


def pair_output(beta: np.ndarray, vis: np.ndarray, lm: np.ndarray, f: np.ndarray, sin_min: float, tol: float):
    """§6.4. Returns ``(ỹ (R, L, 2), x̂ (R, 2), usable (R,))``; rows not usable hold finite garbage.

    Parameters
    ----------
    beta : ndarray, shape (R, L, 2)
        Unit bearings, zero where not visible.
    vis : ndarray of bool, shape (R, L)
        Visible landmarks (with a usable bearing).
    lm : ndarray, shape (L, 2)
        Landmark positions (map units).
    f : ndarray of int, shape (R,)
        Each robot's fixed landmark.
    sin_min : float
        ``sin θ_min``: the least sine of an angle a solve accepts.
    tol : float
        Geometric tolerance (map units).
    """
    r, n_lm = vis.shape
    rows = np.arange(r)
    g, dist = _inter(lm, tol)
    best, kappa = _best_pairs(beta, vis, g)
    a, b = best // n_lm, best % n_lm
    beta_a, beta_b, g_ab = beta[rows, a], beta[rows, b], g[a, b]
    # β_a + t·β^a_b = r·β_b, by Cramer's rule on [β^a_b, −β_b]: det = cross(β_b, β^a_b).
    conditioned = kappa >= sin_min
    det = np.where(conditioned, cross(beta_b, g_ab), 1.0)
    t = cross(beta_a, beta_b) / det
    along = cross(beta_a, g_ab) / det
    usable = conditioned & (t > 0) & (along > 0)
    rho = np.where(usable, t / safe(dist[a, b]), 1.0)  # = 1/‖l_a − x‖
    p = beta_a[:, None, :] + rho[:, None, None] * (lm[None, :, :] - lm[a][:, None, :])
    # ỹ_k = p_k/‖p_f‖ = (l_k − x̂)/‖l_f − x̂‖, with ‖l_f − x̂‖ floored at tol as in §6.2.
    scale = np.maximum(norm(p[rows, f]), rho * tol)
    y = p / safe(scale)[:, None, None]
    x_hat = lm[a] - beta_a / rho[:, None]
    return y, x_hat, usable


def rescale_output(beta: np.ndarray, vis: np.ndarray, lm: np.ndarray, f: np.ndarray, sin_min: float, tol: float):
    """§6.3, falling back to :func:`pair_output` row by row. Returns ``(ỹ, x̂, usable)`` like :func:`pair_output`.

    Parameters
    ----------
    beta, vis, lm, f, sin_min, tol
        As in :func:`pair_output`.
    """
    r, n_lm = vis.shape
    rows = np.arange(r)
    g, dist = _inter(lm, tol)
    g_f, d_f = g[f], dist[f]  # (R, L, 2), (R, L): β^f_k and ‖l_k − l_f‖
    beta_f = beta[rows, f]
    # p_f + a_k β^f_k = b_k β_k, by Cramer's rule on [β^f_k, −β_k]: det = cross(β_k, β^f_k).
    det = cross(beta, g_f)
    conditioned = np.abs(det) >= sin_min
    det_safe = np.where(conditioned, det, 1.0)
    a_k = cross(beta_f[:, None, :], beta) / det_safe
    b_k = cross(beta_f[:, None, :], g_f) / det_safe
    others = vis & (np.arange(n_lm)[None, :] != f[:, None]) & vis[rows, f][:, None]
    consistent = others & conditioned & (a_k > 0) & (b_k > 0)
    own = consistent.any(axis=1)
    k = np.argmax(np.where(consistent, np.abs(det), -1.0), axis=1)
    rho = np.where(own, a_k[rows, k] / safe(d_f[rows, k]), 1.0)  # = 1/‖l_f − x‖
    closed = beta_f[:, None, :] + rho[:, None, None] * (lm[None, :, :] - lm[f][:, None, :])
    y = np.where(consistent[..., None], b_k[..., None] * beta, closed)
    # ρ = a_k/‖l_k − l_f‖ has no lower bound (a robot far away, or crafted bearings): 1/ρ may
    # overflow, and the caller's final finiteness check then marks the robot unusable.
    with np.errstate(over="ignore"):
        x_hat = lm[f] - beta_f / rho[:, None]
    usable = own.copy()
    if not own.all():
        back = ~own
        y_p, x_p, usable_p = pair_output(beta[back], vis[back], lm, f[back], sin_min, tol)
        y[back], x_hat[back], usable[back] = y_p, x_p, usable_p
    return y, x_hat, usable
