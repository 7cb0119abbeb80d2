"""The position error a cell tolerates (ALGORITHMS §11.4, §12.3, §12.4): exit faces, their sinks, δ_c, τ_c, δ*."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["cell_tolerance", "exit_face", "exit_sink", "exit_sinks", "plan_tolerance_of", "usable_tolerances"]


def exit_sink(face: np.ndarray, normals: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, float]:
    """The sink of Lemma 6 (ALGORITHMS §12.4): the point of the exit face of largest side depth.

    One cell of :func:`exit_sinks`.

    Parameters
    ----------
    face : ndarray, shape (2, 2)
        The two ends of the exit face ``E_c`` (map units).
    normals, offsets : ndarray, shapes (h, 2), (h,)
        The non-exit rows as barriers, ``h_k(x) = n_k·x + q_k ≥ 0`` in the cell (unit normals,
        so ``h_k`` is the distance to row k's line).

    Returns
    -------
    sink : ndarray, shape (2,)
        ``x*`` on the face (map units).
    depth : float
        ``h* = min_k h_k(x*)`` (map units); ``inf`` without rows.
    """
    face = np.asarray(face, float).reshape(1, 2, 2)
    sink, depth_ = exit_sinks(face, np.asarray(normals, float).reshape(1, -1, 2), np.asarray(offsets).reshape(1, -1))
    return sink[0], float(depth_[0])


def exit_sinks(faces: np.ndarray, normals: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lemma 6's sink of many cells at once: per cell, the point of its exit face of largest side depth.

    ``h*(x) = min_k (n_k·x + q_k)`` over a cell's non-exit rows is concave and piecewise affine
    along the face, so its maximum is at an end of the face or where two rows' values cross; every
    such point is evaluated (exact, no search).

    Parameters
    ----------
    faces : ndarray, shape (C, 2, 2)
        The two ends of each cell's exit face (map units).
    normals, offsets : ndarray, shapes (C, H, 2), (C, H)
        Each cell's non-exit rows as barriers, ``h_k(x) = n_k·x + q_k ≥ 0`` in the cell (unit
        normals); pad a cell with fewer rows with zero normals and ``+inf`` offsets.

    Returns
    -------
    sinks : ndarray, shape (C, 2)
        ``x*`` on each face (map units).
    depths : ndarray, shape (C,)
        ``h*`` (map units); ``inf`` for a cell without rows.
    """
    faces = np.asarray(faces, float).reshape(-1, 2, 2)
    n = np.asarray(normals, float).reshape(len(faces), -1, 2)
    q = np.asarray(offsets, float).reshape(len(faces), -1)
    if not q.shape[1]:  # no rows: every point of the face is as deep (inf)
        return faces.mean(axis=1), np.full(len(faces), np.inf)
    along = faces[:, 1] - faces[:, 0]
    alpha = np.einsum("chi,ci->ch", n, faces[:, 0]) + q  # h_k at t = 0
    beta = np.einsum("chi,ci->ch", n, along)  # its slope along t ∈ [0, 1]
    t = np.zeros((len(faces), 2 + q.shape[1] ** 2))  # the face's ends, then every pair's crossing
    t[:, 1] = 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = (alpha[:, None, :] - alpha[:, :, None]) / (beta[:, :, None] - beta[:, None, :])
        cross = cross.reshape(len(faces), -1)
        inner = (cross > 0.0) & (cross < 1.0)  # false for NaN and ±inf too
        t[:, 2:][inner] = cross[inner]
        # rows first: a minimum over the outer axis is one pass of elementwise minima, several times
        # faster than over a short inner one (the same exact minimum)
        values = np.min(alpha.T[:, :, None] + t[None] * beta.T[:, :, None], axis=0)
    best = np.argmax(values, axis=1)
    rows = np.arange(len(faces))
    t_best = t[rows, best]
    return faces[:, 0] + t_best[:, None] * along, values[rows, best]


def exit_face(vertices: np.ndarray, z: np.ndarray, x_j: np.ndarray) -> np.ndarray:
    """The two ends of a funnel cell's exit face ``E_c = P_c ∩ {z·(x − x_j) = 0}``, shape (2, 2).

    Parameters
    ----------
    vertices : ndarray, shape (p, 2)
        The cell's CCW vertices (map units); the exit face is one of its edges.
    z, x_j : ndarray, shape (2,)
        Unit exit direction into the cell and the exit point (map units).

    Returns
    -------
    ndarray, shape (2, 2)
        The two vertices nearest the exit line, in polygon order.
    """
    V = np.asarray(vertices, float).reshape(-1, 2)
    gap = np.abs((V - x_j) @ z)
    ends = np.sort(np.argsort(gap, kind="stable")[:2])
    return V[ends]


def cell_tolerance(
    M: np.ndarray, normals: np.ndarray, sigma_h: np.ndarray, z: np.ndarray | None, sigma_v: float | None
) -> float:
    """``δ_c = min(min_k σ_h,k / ‖Mᵀn_k‖, σ_v / ‖Mᵀz‖)`` of ALGORITHMS §11.4 (map units).

    A robot acting on ``x̂`` with ``‖x̂ − x‖ ≤ δ`` applies ``u(x) − M(x̂ − x)``, which changes
    ``n_k·u`` by at most ``‖Mᵀn_k‖δ``; the margins absorb that while ``δ ≤ δ_c``.

    Parameters
    ----------
    M : ndarray, shape (2, 2)
        The field is ``a − M x``.
    normals : ndarray, shape (h, 2)
        Unit normals of the barrier rows (either sign: only norms enter).
    sigma_h : ndarray, shape (h,)
        Margin of (L1) of each row (``−S_h,k``), map units / s.
    z : ndarray, shape (2,) or None
        Exit direction; ``None`` for the goal cell (no (L2)).
    sigma_v : float or None
        Margin of (L2) (``−S_V``), map units / s; ``None`` with ``z``.

    Returns
    -------
    float
        ``0`` when a margin is not positive; ``inf`` when ``M = 0`` and every margin is positive.
    """
    rows = np.asarray(normals, float).reshape(-1, 2)
    sigma = np.asarray(sigma_h, float)
    if z is not None:  # (L2) is one more row: direction z, margin σ_v
        rows = np.vstack([rows, np.asarray(z, float).reshape(1, 2)])
        sigma = np.append(sigma, float(sigma_v))
    if not len(sigma) or not np.all(sigma > 0):
        return 0.0
    gain = rows @ M  # ‖Mᵀn‖ of each row
    gain = np.sqrt(gain[:, 0] * gain[:, 0] + gain[:, 1] * gain[:, 1])
    with np.errstate(divide="ignore"):
        return float(np.min(np.where(gain > 0, sigma / gain, math.inf)))


def usable_tolerances(tolerance: np.ndarray, exit_inset: np.ndarray) -> np.ndarray:
    """``τ_c = min(δ_c, δ_e,c / 2)`` of every cell (ALGORITHMS §12.3), shape (C,), map units.

    Parameters
    ----------
    tolerance : ndarray, shape (C,)
        ``δ_c`` of each cell (map units; ``+inf`` for a constant field, NaN without a certificate).
    exit_inset : ndarray, shape (C,)
        ``δ_e,c`` of each cell (map units); NaN for the goal cell, which has no exit: there
        ``τ_c = δ_c``.

    Returns
    -------
    ndarray, shape (C,)
        NaN where ``δ_c`` is NaN.
    """
    tolerance, half = np.asarray(tolerance, float), 0.5 * np.asarray(exit_inset, float)
    return np.where(np.isnan(half), tolerance, np.minimum(tolerance, half))


def plan_tolerance_of(usable: np.ndarray) -> float:
    """``min_c τ_c`` over the cells with a tolerance (ALGORITHMS §12.3), map units; NaN when none has one.

    Parameters
    ----------
    usable : ndarray, shape (C,)
        ``τ_c`` of each cell (:func:`usable_tolerances`; NaN entries are ignored).

    Returns
    -------
    float
    """
    values = np.asarray(usable, float)
    values = values[~np.isnan(values)]
    return float(values.min()) if len(values) else math.nan
