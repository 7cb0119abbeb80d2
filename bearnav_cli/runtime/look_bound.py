"""The static bound ``ε(x, S)`` of one look (ALGORITHMS §12.2, §12.5): no set a look at the landmarks ``S`` from
``x`` gives errs by more.

Numpy only, on :mod:`~bearnav_cli.runtime.bounded`'s padded polygons. :func:`one_look_bound` is what looking
(§12.5, which heading to turn to) and ``bearnav verify``'s liveness measure; :func:`look_bound` keeps the sets the
bound is made of (:class:`LookBound`), so that ``bearnav tags --for live`` can score a candidate tag cheaply with
:func:`bound_with`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from bearnav_cli.runtime.bounded import (
    RADIUS_PER_WIDTH,
    box,
    clip_pairs,
    diameter,
    intersect_cones,
    valid_vertices,
)

__all__ = ["LookBound", "bound_with", "look_bound", "one_look_bound"]


class LookBound(NamedTuple):
    """One look's bound ``ε(x, S)`` and the sets it is made of (:func:`look_bound`), for ``R`` looks.

    Attributes
    ----------
    bound : ndarray, shape (R,)
        ``ε`` (map units; ``inf`` where ``K`` is empty).
    width, rho : ndarray, shape (R,)
        ``diam K`` (0 where ``K`` is empty) and ``ρ = max_{v∈K} ‖v − x‖`` (map units).
    half : ndarray, shape (R,)
        The cones' half-angle ``2η`` (rad).
    diff_vertices, diff_count : ndarray, shapes (R, W, 2), (R,)
        The difference-body polygon ``{d : |n_k·d| ≤ h_k} ∩ [−diam K, diam K]²`` (map units).
    """

    bound: np.ndarray
    width: np.ndarray
    rho: np.ndarray
    half: np.ndarray
    diff_vertices: np.ndarray
    diff_count: np.ndarray

    def take(self, rows: np.ndarray) -> LookBound:
        """The looks ``rows``."""
        return LookBound(*(field[rows] for field in self))


def _strip_rows(
    x: np.ndarray, landmark: np.ndarray, width: np.ndarray, rho: np.ndarray, half: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The strip ``|n·d| ≤ h`` of one landmark per look (fact 1 of :func:`one_look_bound`): ``a`` (P, 2, 2), ``b``
    (P, 2), and which pairs have one (a landmark on the point has none)."""
    d = landmark - x
    reach = np.hypot(d[:, 0], d[:, 1])
    ok = reach > 0.0
    n = np.stack([-d[:, 1], d[:, 0]], axis=-1) / np.where(ok, reach, 1.0)[:, None]
    h = (reach + rho) * np.sin(half) + 2.0 * np.sin(0.5 * half) * width
    return np.stack([n, -n], axis=1), np.stack([h, h], axis=1), ok


def _spread(vertices: np.ndarray, count: np.ndarray) -> np.ndarray:
    """The largest norm of a vertex of each polygon (R,) map units."""
    norm2 = np.einsum("rwk,rwk->rw", vertices, vertices)
    return np.sqrt(np.max(np.where(valid_vertices(vertices, count), norm2, 0.0), axis=1, initial=0.0))


def look_bound(
    x: np.ndarray,
    landmarks: np.ndarray,
    visible: np.ndarray,
    eta: float | np.ndarray,
    bounds: np.ndarray,
    tol: float = 0.0,
) -> LookBound:
    """The static bound ``ε(x, S)`` of one look: no set a look at ``S`` from ``x`` gives errs by more, shape (R,).

    A robot at ``x`` that sees ``S`` with bearing errors within ``η`` gets a set ``X`` (§12.2) whose
    error radius :func:`centre` returns as ``e``. ALGORITHMS §12.2 bounds ``e`` by ``diam K``,
    ``K = B_r ∩ ∩_{k∈S} cone(l_k, φ_k(x), 2η)``; that is about 2.7 times too large, and this bound
    is the product of three facts (docs/algorithms.md, "the one-look bound"):

    1. **X is half as wide as K.** Two points ``y, z ∈ X`` lie in one cone of half-angle ``η`` at
       ``l_k``, so ``z`` is within ``‖z − l_k‖ sin 2η`` of the line ``l_k y``; that line's normal is
       within ``2η`` of ``n_k``, the normal of the line ``l_k x`` (``y ∈ K``). Hence
       ``|n_k·(z − y)| ≤ h_k = (r_k + ρ) sin 2η + 2 sin η · diam K`` (``r_k = ‖l_k − x‖``,
       ``ρ = max_{v∈K} ‖v − x‖``), and ``diam X ≤ max ‖d‖`` over the polygon
       ``{d : |n_k·d| ≤ h_k ∀k} ∩ [−diam K, diam K]²``, which is about ``diam K / 2``.
    2. **Jung's theorem** in the plane: the smallest circle around ``X`` has radius
       ``R ≤ diam X / √3``.
    3. **Bădoiu–Clarkson**: :func:`centre` starts in the set's hull and takes
       :data:`CENTRE_STEPS` steps, so ``‖x̂ − c*‖ ≤ R/√(CENTRE_STEPS + 1)`` and
       ``e ≤ (1 + 1/√(CENTRE_STEPS + 1)) R``; also ``e ≤ diam X`` (``x̂ ∈ X``).

    So ``e ≤ ε = min(1, (1 + 1/√(CENTRE_STEPS + 1))/√3) · min(diam K, max ‖d‖)`` (:data:`RADIUS_PER_WIDTH`
    is the factor). With fewer than two well-spread bearings ``K`` reaches the bounds and ``ε`` is large.

    Parameters
    ----------
    x : ndarray, shape (R, 2)
        Where the robot is (map units).
    landmarks : ndarray, shape (L, 2)
        Landmark positions (map units).
    visible : ndarray of bool, shape (R, L)
        ``S``: which landmarks it sees from ``x``.
    eta : float or ndarray, shape (R,)
        The bearing error bound (rad), one or one per point.
    bounds : ndarray, shape (4,)
        ``B_r`` (map units).
    tol : float
        Outside slack of the clips (map units).
    """
    p = np.asarray(x, float).reshape(-1, 2)
    lm = np.asarray(landmarks, float)
    visible = np.asarray(visible, bool).reshape(len(p), len(lm))
    d = lm[None] - p[:, None, :]
    angle = np.arctan2(d[..., 1], d[..., 0])
    half = np.minimum(2.0 * np.broadcast_to(np.asarray(eta, float), (len(p),)), 0.5 * math.pi - 1e-9)
    vertices, count = intersect_cones(*box(bounds, len(p)), lm, angle, visible, half, tol)  # K: the 2η cones
    width = diameter(vertices, count)
    valid = valid_vertices(vertices, count)
    off = vertices - p[:, None, :]
    rho = np.sqrt(np.max(np.where(valid, off[..., 0] ** 2 + off[..., 1] ** 2, 0.0), axis=1, initial=0.0))
    bounded_k = np.isfinite(width)
    # the difference body of X: strips |n_k·d| ≤ h_k around 0, in the box of side 2·diam K
    span = np.where(bounded_k, width, 0.0)
    square = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    diff_v, diff_n = square[None] * span[:, None, None], np.full(len(p), 4, np.int64)
    rob, k = np.nonzero(visible & bounded_k[:, None])
    if len(rob):
        a, b, ok = _strip_rows(p[rob], lm[k], span[rob], rho[rob], half[rob])
        diff_v, diff_n = clip_pairs(diff_v, diff_n, rob[ok], a[ok], b[ok], tol)
    bound = np.where(bounded_k, RADIUS_PER_WIDTH * np.minimum(width, _spread(diff_v, diff_n)), np.inf)
    return LookBound(bound, span, rho, half, diff_v, diff_n)


def one_look_bound(
    x: np.ndarray,
    landmarks: np.ndarray,
    visible: np.ndarray,
    eta: float | np.ndarray,
    bounds: np.ndarray,
    tol: float = 0.0,
) -> np.ndarray:
    """:func:`look_bound`'s ``ε(x, S)`` alone, shape (R,) map units.

    Parameters
    ----------
    x, landmarks, visible, eta, bounds, tol
        As :func:`look_bound`.
    """
    return look_bound(x, landmarks, visible, eta, bounds, tol).bound


def bound_with(look: LookBound, x: np.ndarray, landmark: np.ndarray, tol: float = 0.0) -> np.ndarray:
    """An upper bound on ``ε`` when each look also sees one more landmark, shape (R,) map units.

    The new landmark's strip clips the difference body; ``diam K`` and ``ρ`` are kept (with the
    landmark they only shrink, and so do the strips they widen), so this is at least the bound
    :func:`look_bound` computes with it: a cheap score for placing tags.

    Parameters
    ----------
    look : LookBound
        The looks without it.
    x : ndarray, shape (R, 2)
        Where they are taken (map units).
    landmark : ndarray, shape (R, 2)
        The landmark each one also sees (map units).
    tol : float
        Outside slack of the clips (map units).
    """
    p = np.asarray(x, float).reshape(-1, 2)
    a, b, ok = _strip_rows(p, np.asarray(landmark, float).reshape(-1, 2), look.width, look.rho, look.half)
    rows = np.flatnonzero(ok & np.isfinite(look.bound))
    vertices, count = look.diff_vertices, look.diff_count
    if len(rows):
        vertices, count = clip_pairs(vertices, count, rows, a[rows], b[rows], tol)
    tighter = np.minimum(look.bound, RADIUS_PER_WIDTH * np.minimum(look.width, _spread(vertices, count)))
    return np.where(np.isfinite(look.bound), tighter, np.inf)
