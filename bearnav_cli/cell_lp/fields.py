"""The data of one cell's LP and the maps between fields and gains (ALGORITHMS §5.1, §5.6).

:class:`CellProblem` holds a cell's data independent of any artifact; :func:`field_map` gives the
fixed linear map ``F = L θ`` from the LP's variables to the field ``F = [M, a]``; the landmark
matrix ``G`` of Lemma 3 and the minimum-norm gain that realises a field go back from a field to a gain.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from bearnav_cli.errors import ArtifactError

__all__ = [
    "CellProblem",
    "COND_WARNING",
    "FIELD_MAP",
    "field_map",
    "gain_from_theta",
    "landmark_matrix",
    "min_norm_gain",
    "min_norm_gains",
    "theta_from_gain",
]

log = logging.getLogger(__name__)

#: Warn when ``cond(GᵀG)`` exceeds this (nearly coincident landmarks, §5.6).
COND_WARNING = 1e12
#: ``L`` of the field space (:func:`field_map`): ``θ = vec([M, a])`` row-major.
FIELD_MAP = np.eye(6).reshape(2, 3, 6)
FIELD_MAP.setflags(write=False)


@dataclass(frozen=True)
class CellProblem:
    """The data of one cell's LP, independent of any artifact.

    Attributes
    ----------
    vertices : ndarray, shape (p, 2)
        CCW vertices of the convex cell (map units).
    A, b : ndarray, shapes (p, 2), (p,)
        The same cell as ``{x : A x ≤ b}`` (used by the dual form).
    z : ndarray, shape (2,)
        Unit exit direction into the cell; ``V(x) = zᵀ(x − x_j)``.
    x_j : ndarray, shape (2,)
        Exit point (the parent node).
    cbf_n, cbf_q : ndarray, shapes (h, 2), (h,)
        Barrier rows ``h_k(x) = n_kᵀx + q_k``, safe where ``h_k ≥ 0``; there may be none.
    landmarks : ndarray, shape (n, 2)
        Positions of the landmarks the controller uses, ``n ≥ 2``.
    """

    vertices: np.ndarray
    A: np.ndarray
    b: np.ndarray
    z: np.ndarray
    x_j: np.ndarray
    cbf_n: np.ndarray
    cbf_q: np.ndarray
    landmarks: np.ndarray

    def __post_init__(self) -> None:
        for name, shape, ndim in _PROBLEM_SHAPES:
            value = getattr(self, name)
            # a float64 array's dtype is (almost always) the one native instance: ``is`` first,
            # the cheap test for the arrays run() slices from Cells
            if type(value) is not np.ndarray or value.ndim != ndim or (value.dtype is not _F64 and value.dtype != _F64):
                object.__setattr__(self, name, np.asarray(value, dtype=float).reshape(shape))


_F64 = np.dtype(np.float64)
_PROBLEM_SHAPES = tuple(
    (name, shape, len(shape))
    for name, shape in (
        ("vertices", (-1, 2)),
        ("A", (-1, 2)),
        ("b", (-1,)),
        ("z", (2,)),
        ("x_j", (2,)),
        ("cbf_n", (-1, 2)),
        ("cbf_q", (-1,)),
        ("landmarks", (-1, 2)),
    )
)


def landmark_matrix(landmarks: np.ndarray) -> np.ndarray:
    """``G = [𝟙, ℓ]`` of Lemma 3, with ``𝟙 = 1_n ⊗ I_2`` and ``ℓ = stack(l_k)``.

    Parameters
    ----------
    landmarks : ndarray, shape (n, 2)
        Landmark positions ``l_k`` (map units).

    Returns
    -------
    ndarray, shape (2n, 3)
        ``K G = [M, a]`` for any gain ``K`` of shape (2, 2n).
    """
    n = len(landmarks)
    G = np.empty((2 * n, 3))
    G[:, :2] = np.tile(np.eye(2), (n, 1))
    G[:, 2] = np.ravel(landmarks)
    return G


def field_map(space: str, landmarks: np.ndarray) -> np.ndarray:
    """The linear map ``θ ↦ F = [M, a]`` of a variable space, as an array ``L`` with ``F = L @ θ``.

    Parameters
    ----------
    space : {"field", "full", "diag", "scalar"}
        ``field``: ``θ = vec(F)`` row-major (6 numbers). ``full``: ``θ = vec(K)`` row-major
        (4n). ``diag``: ``θ = (K[0, 2k] for k, K[1, 2k+1] for k)`` (2n). ``scalar``:
        ``K_k = θ_k I`` (n).
    landmarks : ndarray, shape (n, 2)
        Landmark positions (map units); they enter ``L`` through ``G`` (:func:`landmark_matrix`)
        in the gain spaces, and only their number matters for the size.

    Returns
    -------
    ndarray, shape (2, 3, n_θ)
        ``F[i, c] = L[i, c] @ θ``.
    """
    n = len(landmarks)
    if space == "field":
        return FIELD_MAP
    G = landmark_matrix(landmarks)
    if space == "full":
        L = np.zeros((2, 3, 4 * n))
        L[0, :, : 2 * n] = G.T
        L[1, :, 2 * n :] = G.T
    elif space == "diag":
        L = np.zeros((2, 3, 2 * n))
        L[0, :, :n] = G[0::2].T
        L[1, :, n:] = G[1::2].T
    elif space == "scalar":
        L = np.stack([G[0::2].T, G[1::2].T])
    else:
        raise ValueError(f"unknown variable space {space!r}")
    return L


def gain_from_theta(space: str, theta: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """The gain ``K`` (2, 2n) of the LP variables ``θ`` (see :func:`field_map`); field space uses Lemma 3.

    Parameters
    ----------
    space : {"field", "full", "diag", "scalar"}
        The variable space ``θ`` lives in (:func:`field_map`). In field space ``θ = vec([M, a])``
        and the gain is the minimum-norm one that realises the field (:func:`min_norm_gain`).
    theta : ndarray, shape (n_θ,)
        The LP variables: 6 numbers in field space, 4n, 2n or n in the gain spaces.
    landmarks : ndarray, shape (n, 2)
        Positions of the cell's landmarks (map units); only their number matters in the gain
        spaces.

    Returns
    -------
    ndarray, shape (2, 2n)
        ``K``, with ``u = K y`` and ``y = stack(l_k − x)``; block ``k`` is columns ``2k, 2k + 1``.

    Raises
    ------
    ValueError
        If ``space`` is none of the four.
    ArtifactError
        In field space, if all landmarks coincide (:func:`min_norm_gain`).
    """
    n = len(landmarks)
    if space == "field":
        F = theta.reshape(2, 3)
        return min_norm_gain(F[:, :2], F[:, 2], landmarks)
    if space == "full":
        return theta.reshape(2, 2 * n).copy()
    K = np.zeros((2, 2 * n))
    if space == "diag":
        K[0, 0::2], K[1, 1::2] = theta[:n], theta[n:]
    elif space == "scalar":
        K[0, 0::2], K[1, 1::2] = theta, theta
    else:
        raise ValueError(f"unknown variable space {space!r}")
    return K


def theta_from_gain(space: str, K: np.ndarray) -> np.ndarray:
    """The gain-space variables ``θ`` of a structured gain ``K`` (2, 2n); inverse of :func:`gain_from_theta`."""
    if space == "full":
        return K.ravel()
    if space == "diag":
        return np.concatenate([K[0, 0::2], K[1, 1::2]])
    if space == "scalar":
        return K[0, 0::2].copy()
    raise ValueError(f"no gain-space variables for {space!r}")


def min_norm_gain(M: np.ndarray, a: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """The minimum-Frobenius-norm gain realising the field ``u = a − M x`` (Lemma 3).

    ``K* = [M, a] (GᵀG)⁻¹Gᵀ``, in closed form: with ``l̄`` the landmarks' mean,
    ``δ_k = l_k − l̄`` and ``σ = Σ‖δ_k‖²``, block ``k`` is ``K_k = M/n + (a − M l̄) δ_kᵀ/σ``
    (so ``Σ K_k = M`` and ``Σ K_k l_k = a``). Logs a warning when ``cond(GᵀG) > 1e12``
    (nearly coincident landmarks). One field of :func:`min_norm_gains`.

    Parameters
    ----------
    M : ndarray, shape (2, 2)
        The field's linear part (1/s).
    a : ndarray, shape (2,)
        The field's constant part (map units/s).
    landmarks : ndarray, shape (n, 2)
        Positions of the landmarks the gain reads (map units), ``n ≥ 2``.

    Returns
    -------
    ndarray, shape (2, 2n)
        ``K* = [K_1 … K_n]``, with ``u = K* y`` and ``y = stack(l_k − x)``.

    Raises
    ------
    ArtifactError
        If all landmarks coincide (``G`` loses rank; map landmarks are distinct).
    """
    landmarks = np.asarray(landmarks, float)
    return min_norm_gains(np.reshape(M, (1, 2, 2)), np.reshape(a, (1, 2)), landmarks[None])[0]


def min_norm_gains(M: np.ndarray, a: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """:func:`min_norm_gain` of ``g`` fields at once, each over its own ``n`` landmarks.

    Every number is computed as for one field alone (elementwise operations in the same order,
    the means summed landmark by landmark from 0), so a gain does not depend on the fields it
    is computed with.

    Parameters
    ----------
    M : ndarray, shape (g, 2, 2)
        The fields' linear parts (1/s).
    a : ndarray, shape (g, 2)
        The fields' constant parts (map units/s).
    landmarks : ndarray, shape (g, n, 2)
        Positions of each field's landmarks (map units), ``n ≥ 2``.

    Returns
    -------
    ndarray, shape (g, 2, 2n)
        The gains ``K*``.

    Raises
    ------
    ArtifactError
        If all landmarks of a field coincide.
    """
    M, a = np.asarray(M, float), np.asarray(a, float)
    landmarks = np.asarray(landmarks, float)
    g, n = landmarks.shape[:2]
    mean = np.zeros((g, 2))
    for k in range(n):
        mean += landmarks[:, k]
    mean /= n
    delta = landmarks - mean[:, None, :]  # δ_k, (g, n, 2)
    sigma = []
    for offsets in delta.tolist():
        # Python's ** (the C library's pow), which does not always round as numpy's x·x does
        s = 0.0
        for ex, ey in offsets:
            s += ex**2 + ey**2
        if not s > 0:
            raise ArtifactError("the cell's landmarks coincide: no gain realises a general field", field="landmarks")
        sigma.append(s)
    sigma = np.array(sigma)
    cond = _gram_conditions(n, mean, sigma)
    for value in cond[~(cond <= COND_WARNING)].tolist():
        log.warning("nearly coincident landmarks: cond(GᵀG) = %.3g", value)
    offset = (a - M[:, :, 0] * mean[:, :1] - M[:, :, 1] * mean[:, 1:]) / sigma[:, None]  # (a − M l̄)/σ, (g, 2)
    K = M[:, :, None, :] / n + offset[:, :, None, None] * delta[:, None, :, :]  # K_k = M/n + (a − M l̄) δ_kᵀ/σ
    return K.reshape(g, 2, 2 * n)


def _gram_conditions(n: int, mean: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """``cond(GᵀG)`` of ``g`` landmark sets of ``n`` landmarks each: ``mean`` (g, 2), ``σ`` (g,) as in
    :func:`min_norm_gains`; shape (g,).

    ``GᵀG = [[nI, s], [sᵀ, t]]`` (``s = n·mean``, ``t = σ + n‖mean‖²``) has the eigenvalue ``n``
    and the two of ``[[n, ‖s‖], [‖s‖, t]]``: ``λ₊`` and ``λ₋ = nσ/λ₊``.
    """
    norm_s = n * np.hypot(mean[:, 0], mean[:, 1])
    t = sigma + norm_s * norm_s / n
    big = 0.5 * (n + t) + np.hypot(0.5 * (n - t), norm_s)
    small = np.minimum(float(n), n * sigma / big)
    with np.errstate(divide="ignore"):
        return np.where(small > 0, big / small, np.inf)
