"""Bearing measurements, the field of view and the reconstruction of the scaled output (ALGORITHMS §6).

This module needs numpy only (and :mod:`bearnav_cli.errors`): the robot-side
:mod:`bearnav_cli.runtime` imports it. Everything is vectorised over ``R`` robots:
positions are arrays of shape ``(R, 2)``, bearings ``(R, L, 2)``, masks ``(R, L)``;
a single robot is ``R = 1``. Landmarks ``(L, 2)`` are shared by all robots. Positions
and distances are in map units, angles in radians. Bearings are world-frame unit
vectors (the compass is assumed, the paper §I).

Measurement (§6.1):

- :func:`directions` — true unit directions ``unit(l_k − x)`` and distances;
- :func:`in_field_of_view` — rules (a) and (b) of §6.1: not within ``tol`` of the
  landmark, and ``|wrap(atan2(l_k − x) − φ_c)| ≤ fov/2`` on the true direction;
- :func:`in_range` — rule (d), ``‖l_k − x‖ ≤ range``;
- :func:`noisy_bearings` — ``β_k = R(ε_k)·unit(l_k − x)``, ``ε_k ~ N(0, σ²)``.

Line of sight (rule (c)) is not computed here: it needs the obstacles, which a robot
does not carry. The caller combines the masks, e.g.
``visible = in_field_of_view(...) & in_range(...) & line_of_sight``.

Reconstruction (§6.2–6.5): :func:`reconstruct` turns the bearings of the visible
landmarks into the scaled output ``ỹ_k ≈ (l_k − x)/‖l_f − x‖`` of *every* landmark (the
closed form covers the invisible ones) and a position estimate ``x̂``, by ``lsq`` (the
default), ``pair`` or ``rescale``. A controller then calls
``runtime.switch(arrays, cell, rec.x_hat, ...)`` and ``runtime.apply_gain(arrays, cell, rec.y)``
for the robots with ``rec.usable``, and applies the hold policy (§7.5) to the others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.runtime.defaults import METHODS, MIN_SPREAD_DEG
from bearnav_cli.runtime.pairs import pair_output, rescale_output
from bearnav_cli.runtime.planar import dot, norm, points, safe

__all__ = [
    "ANGLE_SLACK",
    "DEFAULT_MIN_SPREAD",
    "directions",
    "fix_variance",
    "in_field_of_view",
    "in_range",
    "noisy_bearings",
    "reconstruct",
    "Reconstruction",
    "refine_fix",
    "scaled_output",
    "wrap",
]

#: Default ``θ_min = min_bearing_spread`` (§6.2): 2°, in radians.
DEFAULT_MIN_SPREAD = math.radians(MIN_SPREAD_DEG)
#: Rounding allowance of the field-of-view test (radians): ``atan2`` of a difference of
#: positions and the subtraction of the heading each round by a few ulps, so without it a
#: landmark placed exactly on the edge of the field of view would be visible or not at random.
ANGLE_SLACK = 1e-12


# --------------------------------------------------------------------------- small helpers


def wrap(theta: Any) -> np.ndarray:
    """Angles mapped to ``(−π, π]`` (§0), same shape as ``theta`` (radians)."""
    return math.pi - np.mod(math.pi - np.asarray(theta, float), 2.0 * math.pi)


def _per_robot(value: Any, r: int, dtype: Any, name: str) -> np.ndarray:
    """A scalar or an array of shape (R,) as an array of shape (R,)."""
    array = np.asarray(value, dtype)
    if array.ndim == 0:
        return np.full(r, array, dtype)
    if array.shape != (r,):
        raise ValueError(f"{name} must be a scalar or have shape ({r},), got {array.shape}")
    return array


# --------------------------------------------------------------------------- measurement (§6.1)


def directions(x: Any, landmarks: Any) -> tuple[np.ndarray, np.ndarray]:
    """True directions and distances from each robot to each landmark (ALGORITHMS §6.1).

    Parameters
    ----------
    x : array_like, shape (R, 2)
        Robot positions (map units).
    landmarks : array_like, shape (L, 2)
        Landmark positions (map units).

    Returns
    -------
    unit : ndarray, shape (R, L, 2)
        ``unit(l_k − x)``; the zero vector where the robot sits exactly on the landmark.
    distance : ndarray, shape (R, L)
        ``‖l_k − x‖`` (map units).
    """
    d = points(landmarks)[None, :, :] - points(x)[:, None, :]
    distance = norm(d)
    return d / safe(distance)[..., None], distance


def in_field_of_view(x: Any, heading: Any, landmarks: Any, fov: float, *, tol: float) -> np.ndarray:
    """Rules (a) and (b) of ALGORITHMS §6.1: a defined bearing inside the camera's field of view.

    Landmark ``k`` passes iff ``‖l_k − x‖ ≥ tol`` (a) and
    ``|wrap(atan2(l_k − x) − heading)| ≤ fov/2`` (b), tested on the *true* direction (noise
    does not move a landmark in or out of view). A landmark exactly on the edge of the field
    of view is inside (up to :data:`ANGLE_SLACK`). Line of sight (c) and range (d) are
    separate (see the module docstring).

    Parameters
    ----------
    x : array_like, shape (R, 2)
        Robot positions (map units).
    heading : float or array_like, shape (R,)
        Camera heading ``φ_c`` of each robot (radians, world frame).
    landmarks : array_like, shape (L, 2)
        Landmark positions (map units).
    fov : float
        Full horizontal field of view (radians); ``fov ≥ 2π`` (or ``inf``) sees all around.
    tol : float
        Rule (a) distance (map units), ``1e-9·D``.

    Returns
    -------
    ndarray of bool, shape (R, L)

    Raises
    ------
    InvalidParamsError
        ``fov`` is negative or NaN.
    """
    if not fov >= 0:
        raise InvalidParamsError(f"the field of view must be >= 0, got {fov}", field="fov")
    p, lm = points(x), points(landmarks)
    d = lm[None, :, :] - p[:, None, :]
    visible = norm(d) >= tol
    if fov >= 2.0 * math.pi:
        return visible
    phi = _per_robot(heading, len(p), float, "heading")
    off = wrap(np.arctan2(d[..., 1], d[..., 0]) - phi[:, None])
    # A NaN heading compares False: nothing is visible, no NaN leaks out.
    return visible & (np.abs(off) <= 0.5 * fov + ANGLE_SLACK)


def in_range(x: Any, landmarks: Any, max_range: float) -> np.ndarray:
    """Rule (d) of ALGORITHMS §6.1: ``‖l_k − x‖ ≤ max_range``, shape (R, L) bool.

    Parameters
    ----------
    x : array_like, shape (R, 2)
        Robot positions (map units).
    landmarks : array_like, shape (L, 2)
        Landmark positions (map units).
    max_range : float
        Sensing range (map units); ``inf`` (the default of §6.1) means unlimited.

    Raises
    ------
    InvalidParamsError
        ``max_range`` is negative or NaN.
    """
    if not max_range >= 0:
        raise InvalidParamsError(f"the range must be >= 0, got {max_range}", field="range")
    return directions(x, landmarks)[1] <= max_range


def noisy_bearings(x: Any, landmarks: Any, sigma: float, rng: np.random.Generator | None) -> np.ndarray:
    """Measured bearings ``β_k = R(ε_k)·unit(l_k − x)``, ``ε_k ~ N(0, σ²)`` (ALGORITHMS §6.1).

    One angle is drawn for every robot and landmark, visible or not, in C order over
    ``(R, L)``, so the noise a robot sees does not depend on what the others see.

    Parameters
    ----------
    x : array_like, shape (R, 2)
        Robot positions (map units).
    landmarks : array_like, shape (L, 2)
        Landmark positions (map units).
    sigma : float
        Standard deviation of the angular noise (radians); ``0`` gives the exact
        directions and draws nothing from ``rng``.
    rng : numpy.random.Generator or None
        Source of the noise; may be ``None`` when ``sigma == 0``.

    Returns
    -------
    ndarray, shape (R, L, 2)
        World-frame unit vectors; the zero vector where the robot sits exactly on the
        landmark (the bearing is undefined there, rule (a) of §6.1).

    Raises
    ------
    InvalidParamsError
        ``sigma`` is negative or NaN, or ``sigma > 0`` without a generator.
    """
    if not sigma >= 0:
        raise InvalidParamsError(f"the bearing noise must be >= 0, got {sigma}", field="noise")
    unit = directions(x, landmarks)[0]
    if sigma == 0:
        return unit
    if rng is None:
        raise InvalidParamsError("bearing noise needs a random generator", field="noise")
    return rotated(unit, rng.normal(0.0, sigma, size=unit.shape[:2]))


def rotated(unit: np.ndarray, eps: np.ndarray) -> np.ndarray:
    """Unit bearings ``unit`` (R, L, 2) turned counter-clockwise by the angles ``eps`` (R, L) rad; any plane vectors
    ``(..., 2)`` with angles that broadcast to their leading shape."""
    c, s = np.cos(eps), np.sin(eps)
    return np.stack([c * unit[..., 0] - s * unit[..., 1], s * unit[..., 0] + c * unit[..., 1]], axis=-1)


# --------------------------------------------------------------------------- reconstruction (§6.2–6.5)


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """The output of :func:`reconstruct` for ``R`` robots and ``L`` landmarks.

    Attributes
    ----------
    y : ndarray, shape (R, 2L)
        The scaled output ``ỹ``: columns ``2k, 2k+1`` hold ``ỹ_k ≈ (l_k − x)/‖l_f − x‖``
        (dimensionless) for every landmark, visible or not; zeros where not ``usable``.
        Ready for ``runtime.apply_gain``.
    x_hat : ndarray, shape (R, 2)
        Position estimate ``x̂`` (map units) consistent with ``y``:
        ``ỹ_k = (l_k − x̂)/max(‖l_f − x̂‖, tol)`` for ``lsq`` and ``pair``; zeros where not
        ``usable``.
    usable : ndarray of bool, shape (R,)
        Whether the reconstruction may be used; otherwise the hold policy (§7.5) applies.
    """

    y: np.ndarray
    x_hat: np.ndarray
    usable: np.ndarray


def reconstruct(
    bearings: Any,
    visible: Any,
    landmarks: Any,
    fixed: Any,
    *,
    method: str = "lsq",
    min_spread: float = DEFAULT_MIN_SPREAD,
    tol: float,
) -> Reconstruction:
    """The scaled output ``ỹ`` and the position estimate ``x̂`` from bearings (ALGORITHMS §6.2–6.5).

    ``ỹ_k`` targets ``(l_k − x)/‖l_f − x‖`` for every landmark ``k``, with ``f`` the fixed
    landmark of the robot's cell (§5.5); then ``ũ = gain[c] @ ỹ``. The methods:

    - ``lsq`` (§6.2): least-squares intersection of the visible bearing lines,
      ``(Σ P_k) x̂ = Σ P_k l_k`` with ``P_k = I − β_kβ_kᵀ``; usable iff at least two are
      visible, ``λ_min(Σ P_k) ≥ 1 − cos θ_min`` and ``β_kᵀ(l_k − x̂) > 0`` for every visible
      ``k``. Then ``ỹ_k = (l_k − x̂)/max(‖l_f − x̂‖, tol)``.
    - ``pair`` (§6.4): the visible ordered pair ``(a, b)`` maximising
      ``κ_ab = min(|cross(β_a, β_b)|, |cross(β_b, β^a_b)|)``; usable iff
      ``κ_ab ≥ sin θ_min`` and the solve ``β_a + t·β^a_b = r·β_b`` gives ``t, r > 0``. Then
      ``ρ = t/‖l_b − l_a‖``, ``p_k = β_a + ρ(l_k − l_a)``, ``ỹ_k = p_k/max(‖p_f‖, ρ·tol)``
      and ``x̂ = l_a − β_a/ρ``.
    - ``rescale`` (§6.3): needs ``f`` visible; ``p_f = β_f`` and, for each visible
      ``k ≠ f``, the 2×2 solve ``p_f + a_k β^f_k = b_k β_k``, consistent iff
      ``|cross(β_k, β^f_k)| ≥ sin θ_min``, ``a_k > 0`` and ``b_k > 0``; then ``ỹ_k = b_k β_k``.
      The other landmarks get the closed form ``β_f + ρ(l_k − l_f)`` with
      ``ρ = a_k/‖l_k − l_f‖`` from the consistent ``k`` with the largest ``|det|``, and
      ``x̂ = l_f − β_f/ρ``. Without ``f`` visible or any consistent ``k``, the robot's
      result is that of ``pair``.

    Degenerate cases (§6.5) never produce NaN or inf: fewer than two visible, all visible
    bearings (nearly) parallel, or an inconsistent estimate give ``usable = False``; a
    ``k`` on the line through ``l_f`` and the robot takes the closed form (``rescale``);
    ``‖l_f − x̂‖ < tol`` divides by ``tol``. A visible landmark whose bearing is zero or
    not finite counts as not visible.

    Parameters
    ----------
    bearings : array_like, shape (R, L, 2)
        Measured world-frame unit bearings (entries of invisible landmarks are ignored).
    visible : array_like of bool, shape (R, L)
        Landmarks each robot sees (field of view, range and line of sight combined by the
        caller). Every visible landmark is used; pass ``visible & cell_landmarks[c]`` to
        restrict the estimate to the cell's landmarks.
    landmarks : array_like, shape (L, 2)
        Landmark positions (map units).
    fixed : int or array_like of int, shape (R,)
        Fixed landmark ``f`` of each robot's cell (``fixed_landmark[c]``).
    method : {"lsq", "pair", "rescale"}
        Reconstruction (§6.5 *Our choice*); default ``lsq``.
    min_spread : float
        ``θ_min`` (radians), in ``(0, π/2]``; default 2°.
    tol : float
        Geometric tolerance (map units), ``1e-9·D``.

    Returns
    -------
    Reconstruction

    Raises
    ------
    InvalidParamsError
        Unknown ``method``, ``min_spread`` outside ``(0, π/2]`` or ``tol ≤ 0``.
    ValueError
        Inconsistent shapes, or ``fixed`` not a landmark index.
    """
    if method not in METHODS:
        expected = ", ".join(METHODS)
        raise InvalidParamsError(f"unknown reconstruction {method!r} (expected {expected})", field="reconstruction")
    if not 0 < min_spread <= 0.5 * math.pi:
        message = f"min_bearing_spread must be in (0, π/2] rad, got {min_spread}"
        raise InvalidParamsError(message, field="min_bearing_spread")
    if not tol > 0:
        raise InvalidParamsError(f"tol must be > 0, got {tol}", field="tol")
    lm = points(landmarks)
    n_lm = len(lm)
    beta = np.asarray(bearings, float)
    if beta.ndim != 3 or beta.shape[1:] != (n_lm, 2):
        raise ValueError(f"bearings must have shape (R, {n_lm}, 2), got {beta.shape}")
    r = len(beta)
    vis = np.asarray(visible, bool)
    if vis.shape != (r, n_lm):
        raise ValueError(f"visible must have shape ({r}, {n_lm}), got {vis.shape}")
    f = _per_robot(fixed, r, np.int64, "fixed")
    if np.any((f < 0) | (f >= n_lm)):
        raise ValueError(f"fixed landmark index out of range 0..{n_lm - 1}")
    if n_lm == 0 or r == 0:
        return Reconstruction(np.zeros((r, 2 * n_lm)), np.zeros((r, 2)), np.zeros(r, bool))

    # A zero or non-finite bearing has no direction: drop it rather than let it poison a sum.
    length = norm(beta)
    vis = vis & np.isfinite(length) & (length > 0)
    beta = np.where(vis[..., None], beta / np.where(vis, length, 1.0)[..., None], 0.0)

    if method == "lsq":
        y, x_hat, usable = _lsq(beta, vis, lm, f, 1.0 - math.cos(min_spread), tol)
    elif method == "pair":
        y, x_hat, usable = pair_output(beta, vis, lm, f, math.sin(min_spread), tol)
    else:
        y, x_hat, usable = rescale_output(beta, vis, lm, f, math.sin(min_spread), tol)
    # Unusable rows carry finite garbage from the masked solves; zero them so no caller uses it by accident.
    usable = usable & np.all(np.isfinite(y), axis=(1, 2)) & np.all(np.isfinite(x_hat), axis=1)
    y = np.where(usable[:, None, None], y, 0.0).reshape(r, 2 * n_lm)
    x_hat = np.where(usable[:, None], x_hat, 0.0)
    return Reconstruction(y=y, x_hat=x_hat, usable=usable)


def _scaled(x_hat: np.ndarray, lm: np.ndarray, f: np.ndarray, tol: float) -> np.ndarray:
    """``(l_k − x̂)/max(‖l_f − x̂‖, tol)``, shape (R, L, 2): near ``l_f`` only the speed changes (§6.2)."""
    d = lm[None, :, :] - x_hat[:, None, :]
    s = norm(d[np.arange(len(f)), f])
    return d / np.maximum(s, tol)[:, None, None]


def _projector_sum(beta: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, ...]:
    """``Σ_k w_k P_k`` with ``P_k = I − β_kβ_kᵀ`` as ``(a11, a22, a12)``, and its smallest eigenvalue, each (R,)."""
    bx, by = beta[..., 0], beta[..., 1]
    a11 = np.sum(w * (1.0 - bx * bx), axis=1)
    a22 = np.sum(w * (1.0 - by * by), axis=1)
    a12 = -np.sum(w * bx * by, axis=1)
    return a11, a22, a12, 0.5 * (a11 + a22) - np.hypot(0.5 * (a11 - a22), a12)


def refine_fix(bearings: Any, visible: Any, landmarks: Any, x_hat: Any, tol: float, iterations: int = 2) -> np.ndarray:
    """The distance-weighted intersection of the bearing lines, started from a fix, shape (R, 2).

    ``lsq`` (§6.2) weighs every line alike, but angle noise moves a line by ``d_k·ε_k``: far
    landmarks' lines wander most, and with landmarks at very different distances the plain
    intersection is several times noisier than it need be (``tests/test_bearing.py``). Weighting
    each line by ``1/d_k²`` (distances from the previous iterate, or from a given point)
    minimises the angular residuals: the estimate of least variance, ``σ²(Σ_k P_k/d_k²)⁻¹``,
    what :func:`fix_variance` predicts. Exact bearings give the exact point either way.

    Parameters
    ----------
    bearings : array_like, shape (R, L, 2)
        World-frame unit bearings ``β_k`` (entries of invisible landmarks are ignored).
    visible : array_like of bool, shape (R, L)
        Landmarks each robot's fix uses.
    landmarks : array_like, shape (L, 2)
        Landmark positions (map units).
    x_hat : array_like, shape (R, 2)
        The starting fixes (map units), e.g. :func:`reconstruct`'s ``lsq`` ``x_hat``.
    tol : float
        Geometric tolerance (map units): distances below it count as ``tol``.
    iterations : int
        Reweighting passes (each recomputes the distances at the last iterate).

    Returns
    -------
    ndarray, shape (R, 2)
        The refined fixes (map units); rows whose weighted system is singular keep ``x_hat``.
    """
    beta, vis = np.asarray(bearings, float), np.asarray(visible, bool)
    lm, x = points(landmarks), points(x_hat).copy()
    for _ in range(iterations):
        d = lm[None] - x[:, None, :]
        w = np.where(vis, 1.0 / np.maximum(np.einsum("rlk,rlk->rl", d, d), tol * tol), 0.0)
        refined, ok = _intersection(beta, w, lm)
        x = np.where(ok[:, None], refined, x)
    return x


def fix_variance(bearings: Any, visible: Any, landmarks: Any, x_hat: Any, sigma: float, tol: float) -> np.ndarray:
    """Variance of a bearing fix in its worst direction (map units²), shape (R,).

    A bearing with angle noise ``σ`` (radians) places the robot on its line to within
    ``σ·d`` at distance ``d``, so the information of the fix is ``Σ_k P_k/(σ d_k)²``; the
    inverse of its smallest eigenvalue bounds the variance of the distance-weighted fix
    (:func:`refine_fix`, what the runtime uses under noise). Two nearly parallel bearings,
    or landmarks far away, give a large one.

    Parameters
    ----------
    bearings : array_like, shape (R, L, 2)
        World-frame unit bearings ``β_k`` (entries of invisible landmarks are ignored).
    visible : array_like of bool, shape (R, L)
        Landmarks each robot's fix uses.
    landmarks : array_like, shape (L, 2)
        Landmark positions (map units).
    x_hat : array_like, shape (R, 2)
        The fixes ``x̂`` (map units), for the distances ``d_k = ‖l_k − x̂‖``.
    sigma : float
        Bearing noise ``σ``, 1σ (rad).
    tol : float
        Geometric tolerance (map units): distances below it count as ``tol``.

    Returns
    -------
    ndarray, shape (R,)
        ``σ² / λ_min(Σ_k P_k/d_k²)`` (map units²); about ``σ²/1e-300`` where fewer than two
        visible bearings span the plane.
    """
    beta, vis = np.asarray(bearings, float), np.asarray(visible, bool)
    d = points(landmarks)[None] - points(x_hat)[:, None, :]
    dist2 = np.maximum(np.einsum("rlk,rlk->rl", d, d), tol * tol)
    lam = _projector_sum(beta, np.where(vis, 1.0 / dist2, 0.0))[3]
    return sigma * sigma / np.maximum(lam, 1e-300)


def scaled_output(x_hat: Any, landmarks: Any, fixed: Any, tol: float) -> np.ndarray:
    """``ỹ_k = (l_k − x̂)/max(‖l_f − x̂‖, tol)`` for every landmark (§6.2).

    The output the gains read when the position is known (or estimated) instead of measured: near
    ``l_f`` only the speed changes.

    Parameters
    ----------
    x_hat : array_like, shape (R, 2)
        Positions ``x̂`` (map units).
    landmarks : array_like, shape (L, 2)
        Landmark positions (map units).
    fixed : int or array_like of int, shape (R,)
        Fixed landmark ``f`` of each robot's cell (``fixed_landmark[c]``).
    tol : float
        Geometric tolerance (map units), the smallest divisor.

    Returns
    -------
    ndarray, shape (R, 2L)
        ``stack(ỹ_k)`` per robot (dimensionless).

    Raises
    ------
    ValueError
        If ``fixed`` is neither a scalar nor of shape (R,).
    """
    x = points(x_hat)
    return _scaled(x, points(landmarks), _per_robot(fixed, len(x), np.int64, "fixed"), tol).reshape(len(x), -1)


def _lsq(beta: np.ndarray, vis: np.ndarray, lm: np.ndarray, f: np.ndarray, threshold: float, tol: float):
    """§6.2. Returns ``(ỹ (R, L, 2), x̂ (R, 2), usable (R,))``; rows not usable hold finite garbage."""
    lam_min = _projector_sum(beta, vis.astype(float))[3]
    x_hat, ok = _intersection(beta, vis.astype(float), lm)
    solvable = (vis.sum(axis=1) >= 2) & (lam_min >= threshold) & ok
    # Noise can put the intersection behind a camera: every visible landmark must lie ahead.
    ahead = dot(beta, lm[None, :, :] - x_hat[:, None, :]) > 0
    usable = solvable & np.all(ahead | ~vis, axis=1)
    return _scaled(x_hat, lm, f, tol), x_hat, usable


def _intersection(beta: np.ndarray, w: np.ndarray, lm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``argmin_x Σ_k w_k ‖P_k(x − l_k)‖²``, shape (R, 2), and where it is unique (R,); the rest hold garbage."""
    a11, a22, a12, _ = _projector_sum(beta, w)
    # Solve about the (weighted) centroid of the landmarks used: far from the map origin,
    # Σ P_k l_k would cancel most of its digits.
    total = np.sum(w, axis=1)
    centre = (w @ lm) / np.where(total > 0, total, 1.0)[:, None]
    rel = lm[None, :, :] - centre[:, None, :]
    rhs = np.sum(w[..., None] * (rel - beta * dot(beta, rel)[..., None]), axis=1)
    det = a11 * a22 - a12 * a12
    ok = det > 0
    det = np.where(ok, det, 1.0)
    adj_rhs = np.stack([a22 * rhs[:, 0] - a12 * rhs[:, 1], a11 * rhs[:, 1] - a12 * rhs[:, 0]], axis=1)
    return centre + adj_rhs / det[:, None], ok
