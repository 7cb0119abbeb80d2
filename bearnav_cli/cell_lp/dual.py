"""The dual form of (P): multipliers ``λ_g ≥ 0`` per group over the cell's half-planes instead of vertex rows."""

from __future__ import annotations

import numpy as np

from bearnav_cli.cell_lp.fields import CellProblem
from bearnav_cli.cell_lp.form import CellLp, LpTemplate, assemble, filled
from bearnav_cli.lp import INF

__all__ = ["BOX_DIRECTIONS", "dual_lp", "dual_template"]

#: Input-box directions ``e_r``.
BOX_DIRECTIONS = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
BOX_DIRECTIONS.setflags(write=False)


def dual_template(
    problem: CellProblem,
    L: np.ndarray,
    u_max: float | None,
    w_h: float = 1.0,
    w_v: float = 1.0,
    least_violation: bool = False,
) -> LpTemplate:
    """The dual form of (P) with open constants (see :func:`dual_lp`).

    Groups: the ``h`` barrier rows (``d = −n_k``), the CLF (``d = z``), then the four box
    sides ``e_r``, each with its own multipliers ``λ_g ≥ 0`` (``m`` each).

    Parameters
    ----------
    problem : CellProblem
        The cell; the dual form uses its half-planes ``A x ≤ b`` instead of its vertices.
    L : ndarray, shape (2, 3, n_θ)
        The variable map ``[M, a] = L θ`` (:func:`field_map`).
    u_max : float or None
        Input bound ``|u_i| ≤ u_max`` (map units/s); None drops the four box groups.
    w_h, w_v : float
        Objective weights of the CBF slacks ``S_h`` and of the CLF slack ``S_V``.
    least_violation : bool
        Free slacks and minimise ``Σ w·max(S, 0)`` instead (§5.3).

    Returns
    -------
    LpTemplate
        Three rows per group (two equalities, one inequality), ``vertex_rows`` None.
    """
    A, b = problem.A, problem.b
    m = len(b)
    n_theta = L.shape[2]
    n_h = len(problem.cbf_q)
    n_slack = n_h + 1
    D = np.concatenate([-problem.cbf_n, problem.z[None, :]] + ([BOX_DIRECTIONS] if u_max is not None else []))
    n_groups = len(D)
    n_mult = n_groups * m
    head = np.zeros((n_groups, 3, n_theta + n_slack))
    head[:, :, :n_theta] = (D @ L.reshape(2, 3 * n_theta)).reshape(n_groups, 3, n_theta)  # Mᵀd and dᵀa
    head[range(n_slack), 2, range(n_theta, n_theta + n_slack)] = -1.0
    lam = np.zeros((n_groups, 3, n_groups, m))
    g = np.arange(n_groups)
    lam[g, :2, g, :] = A.T
    lam[g, 2, g, :] = b
    dense = np.concatenate([head, lam.reshape(n_groups, 3, n_mult)], axis=2).reshape(3 * n_groups, -1)
    # per group: equalities A_xᵀλ_g + Mᵀd_g = ρ_g (ρ = c_h·d for CBF, c_v·z for CLF, 0 for the box)
    # and b_xᵀλ_g + d_gᵀa − S_g ≤ r_g (r = c_h·q_k, c_v·zᵀx_j, u_max)
    rhs_h = np.column_stack([D[:n_h], problem.cbf_q]).ravel()
    rhs_v = np.array([problem.z[0], problem.z[1], problem.z @ problem.x_j])
    rhs_const = np.zeros((n_groups - n_slack, 3))
    rhs_const[:, 2] = u_max if u_max is not None else 0.0
    equality = np.ones((n_groups, 3), bool)
    equality[:, 2] = False
    return assemble(
        dense,
        filled(3 * n_groups, -INF),
        equality.ravel(),
        rhs_h,
        rhs_v,
        rhs_const.ravel(),
        n_theta,
        n_h,
        n_mult,
        w_h,
        w_v,
        least_violation,
    )


def dual_lp(
    problem: CellProblem,
    L: np.ndarray,
    c_h: float,
    c_v: float,
    u_max: float | None,
    w_h: float = 1.0,
    w_v: float = 1.0,
    least_violation: bool = False,
) -> CellLp:
    """The dual form of (P): multipliers ``λ_g ≥ 0`` per group instead of vertex rows (§5.2).

    Rows per group ``g``: ``A_xᵀλ_g + Mᵀd_g = ρ_g`` (two equalities) and
    ``b_xᵀλ_g + d_gᵀa − S_g ≤ r_g``. Columns after the slacks: ``λ_g`` (m each, ``m`` =
    number of cell rows), group by group.

    Parameters
    ----------
    problem : CellProblem
        The cell's data; its half-planes ``A x ≤ b`` give the multipliers' rows.
    L : ndarray, shape (2, 3, n_θ)
        From :func:`field_map`.
    c_h, c_v : float
        Barrier and Lyapunov constants (1/s); ``c_h`` is unused without barrier rows.
    u_max : float or None
        Input box (map units/s); ``None`` drops the four box groups.
    w_h, w_v : float
        Objective weights of the CBF and CLF slacks.
    least_violation : bool
        Free slacks and minimise ``Σ w·max(S, 0)`` instead (§5.3).

    Returns
    -------
    CellLp
    """
    return dual_template(problem, L, u_max, w_h, w_v, least_violation).instantiate(c_h, c_v)
