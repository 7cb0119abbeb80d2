"""The one re-check of a cell's certificate: its conditions at the cell's vertices, numpy only (ALGORITHMS §8).

A cell's field ``u(x) = a − M x`` is certified when, at every vertex ``v_q`` (the conditions are
affine in ``x``, so the vertices decide), the barrier conditions ``n_kᵀu_q + c_h h_k(v_q) ≥ 0``, the
progress condition ``zᵀu_q + c_v V(v_q) < 0`` and the input bound ``‖u_q‖_∞ ≤ u_max`` hold, on barrier
rows that can carry a certificate at all (:func:`barrier_fault`).
:func:`vertex_margins` (of a gain) and :func:`field_margins` (of a field) compute their worst
values without an LP. ``bearnav verify`` re-checks every plan with them, ``bearnav synthesize``
certifies the goal cell and computes ``δ_c`` with them, and the tests compare synthesize's own
(faster) re-checks with them; both judge the barrier rows with :func:`barrier_fault`. It needs
nothing but numpy, as everything under ``runtime/`` does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Margins", "UNIT_TOL", "barrier_fault", "field_margins", "gain_field", "vertex_margins"]

#: Allowed deviation of a barrier normal's norm from 1.
UNIT_TOL = 1e-9


@dataclass(frozen=True)
class Margins:
    """Worst-case values of the certificate conditions over a cell's vertices (ALGORITHMS §8).

    Attributes
    ----------
    cbf : float
        ``max_{q,k} −(n_kᵀu_q + c_h h_k(v_q))``; NaN without barrier rows.
    cbf_rows : ndarray, shape (h,)
        The same maximum per barrier row (``S_h,k``).
    clf : float
        ``max_q zᵀu_q + c_v V(v_q)``.
    input : float
        ``max_q ‖u_q‖_∞ − u_max``.
    """

    cbf: float
    cbf_rows: np.ndarray
    clf: float
    input: float


def vertex_margins(K, landmarks, vertices, z, x_j, cbf_n, cbf_q, c_h, c_v, u_max) -> Margins:
    """Re-check a gain at the vertices, without an LP (ALGORITHMS §8).

    Parameters
    ----------
    K : ndarray, shape (2, 2n)
        Gain over ``landmarks`` (the full ``gain[c]`` with all map landmarks works too).
    landmarks : ndarray, shape (n, 2)
        Positions of the landmarks ``K`` reads (map units).
    vertices, z, x_j, cbf_n, cbf_q, c_h, c_v, u_max
        The cell and its constants, as in :func:`field_margins`.

    Returns
    -------
    Margins
    """
    M, a = gain_field(K, landmarks)
    return field_margins(M, a, vertices, z, x_j, cbf_n, cbf_q, c_h, c_v, u_max)


def gain_field(K, landmarks) -> tuple[np.ndarray, np.ndarray]:
    """The affine field ``u(x) = a − M x`` of a gain: ``M = Σ_k K_k``, ``a = Σ_k K_k l_k``.

    Parameters
    ----------
    K : ndarray, shape (2, 2n)
        Gain over ``landmarks``: ``u(x) = K @ (landmarks − x).ravel()``.
    landmarks : ndarray, shape (n, 2)
        Their positions (map units).

    Returns
    -------
    M : ndarray, shape (2, 2)
    a : ndarray, shape (2,)
    """
    K = np.asarray(K, float)
    landmarks = np.asarray(landmarks, float)
    return K.reshape(2, -1, 2).sum(axis=1), K @ landmarks.ravel()


def field_margins(M, a, vertices, z, x_j, cbf_n, cbf_q, c_h, c_v, u_max) -> Margins:
    """:func:`vertex_margins` of the affine field ``u(x) = a − M x`` itself.

    Parameters
    ----------
    M : ndarray, shape (2, 2)
        The field's linear part (1/s).
    a : ndarray, shape (2,)
        The field's constant part (map units/s).
    vertices : ndarray, shape (p, 2)
        The cell's vertices ``v_q`` (map units), where ``u_q = a − M v_q`` is evaluated.
    z, x_j : ndarray, shape (2,)
        Unit exit direction (into the cell) and exit point (map units): ``V(x) = zᵀ(x − x_j)``.
    cbf_n, cbf_q : ndarray, shapes (h, 2), (h,)
        Barrier rows ``h_k(x) = n_kᵀx + q_k``; with none, ``cbf`` is NaN.
    c_h, c_v : float
        Barrier and Lyapunov constants (1/s).
    u_max : float
        Input bound (map units/s).

    Returns
    -------
    Margins
    """
    V = np.asarray(vertices, float)
    cbf_n = np.asarray(cbf_n, float).reshape(-1, 2)
    U = a - V @ M.T  # u at each vertex, (p, 2)
    if len(cbf_n):
        values = -(U @ cbf_n.T + c_h * (V @ cbf_n.T + np.asarray(cbf_q, float)))
        rows = values.max(axis=0)
        cbf = float(rows.max())
    else:
        rows, cbf = np.zeros(0), math.nan
    clf = float(np.max(U @ z + c_v * ((V - x_j) @ z)))
    return Margins(cbf, rows, clf, float(np.abs(U).max() - u_max))


def barrier_fault(normals, offsets, x_j=None) -> str | None:
    """Why a cell's barrier rows cannot carry its certificate, in words; None when they can (ALGORITHMS §8).

    Every normal ``n_k`` must be of unit norm (within :data:`UNIT_TOL`: the margins and the tolerance are
    distances), and in an edge cell every row must be positive at the exit point, ``h_k(x_j) > 0``: the
    field drives the robot to ``x_j``, where a row that is zero or negative leaves the barrier and the
    progress conditions no margin (the paper's wedge with its apex at ``x_j``, ``cbf_apex=parent``, is
    zero there). ``synthesize`` certifies no cell with a fault, and ``verify`` refutes a certified one.

    Parameters
    ----------
    normals, offsets : ndarray, shapes (h, 2), (h,)
        The barrier rows ``h_k(x) = n_kᵀx + q_k``; none is no fault.
    x_j : ndarray, shape (2,), optional
        The edge's parent node ``x_j`` (map units); None for the goal cell, which has no exit.

    Returns
    -------
    str or None
    """
    normals = np.asarray(normals, float).reshape(-1, 2)
    if not len(normals):
        return None
    off_unit = np.flatnonzero(~(np.abs(np.hypot(normals[:, 0], normals[:, 1]) - 1.0) <= UNIT_TOL))  # NaN too
    if off_unit.size:
        return f"barrier row {int(off_unit[0])} is not unit-norm"
    if x_j is None:
        return None
    at_exit = normals @ np.asarray(x_j, float) + np.asarray(offsets, float)
    not_positive = np.flatnonzero(~(at_exit > 0))  # a NaN offset too
    if not_positive.size:
        k = int(not_positive[0])
        return f"barrier row {k} is not positive at the exit point, h(x_j) = {at_exit[k]:.3g}"
    return None
