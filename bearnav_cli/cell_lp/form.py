"""The solver form of a cell's LP: :class:`CellLp`, and :class:`LpTemplate` with the constants ``c_h``, ``c_v`` open.

Only the row bounds depend on ``c_h`` and ``c_v``, so a κ halving re-solves a template without
rebuilding its matrix; :func:`assemble` adds the column bounds and the objective to a dense block.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bearnav_cli.lp import INF, LpResult, LpSolver, dense_to_csr

__all__ = ["assemble", "CellLp", "filled", "LpTemplate"]


@dataclass(frozen=True)
class CellLp:
    """One LP in solver form plus where its variables are.

    ``x[:n_theta]`` are the variables ``θ``; ``x[n_theta:n_theta + n_h]`` the CBF slacks
    ``S_h``; ``x[n_theta + n_h]`` the CLF slack ``S_V``; further columns are multipliers
    (dual form) or the least-violation variables ``t``. The LP reads: minimise ``cost @ x``
    subject to ``row_lower <= A x <= row_upper`` and ``col_lower <= x <= col_upper``.

    Attributes
    ----------
    cost : ndarray, shape (n,)
        Objective coefficients of the ``n`` columns (the weights ``w_h``, ``w_v`` on the slacks
        or on ``t``, zero elsewhere).
    A_indptr, A_indices, A_values : ndarray, shapes (m + 1,), (nnz,), (nnz,)
        The constraint matrix ``A`` (m, n) in CSR form (:func:`~bearnav_cli.lp.dense_to_csr`).
    row_lower, row_upper : ndarray, shape (m,)
        Row bounds; ``-INF`` / ``INF`` where a row is one-sided, equal on equality rows.
    col_lower, col_upper : ndarray, shape (n,)
        Column bounds (``θ`` free, slacks ``<= 0`` unless least violation, multipliers ``>= 0``).
    n_theta : int
        Number of variables ``θ`` (the first columns).
    n_h : int
        Number of barrier rows, hence of CBF slacks after ``θ``.
    """

    cost: np.ndarray
    A_indptr: np.ndarray
    A_indices: np.ndarray
    A_values: np.ndarray
    row_lower: np.ndarray
    row_upper: np.ndarray
    col_lower: np.ndarray
    col_upper: np.ndarray
    n_theta: int
    n_h: int

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The arguments of :meth:`LpSolver.solve`, in order."""
        return (
            self.cost,
            self.A_indptr,
            self.A_indices,
            self.A_values,
            self.row_lower,
            self.row_upper,
            self.col_lower,
            self.col_upper,
        )

    def solve(self, solver: LpSolver) -> LpResult:
        return solver.solve(*self.arrays())

    def slacks(self, x: np.ndarray) -> tuple[np.ndarray, float]:
        """``(S_h, S_V)`` from a solution vector."""
        return x[self.n_theta : self.n_theta + self.n_h], float(x[self.n_theta + self.n_h])


@dataclass(frozen=True)
class LpTemplate:
    """A cell's LP with the constants left open: only the row bounds depend on ``c_h`` and ``c_v``.

    Rows come in three blocks: those scaled by ``c_h``, those scaled by ``c_v``, then
    constant ones, so ``row_upper = [c_h·rhs_h, c_v·rhs_v, rhs_const]``. ``row_lower`` equals
    ``row_upper`` on the equality rows and ``lower`` elsewhere. The matrix, costs and column
    bounds are shared by every :meth:`instantiate` call, so κ halvings cost a few vector
    operations. ``vertex_rows`` (vertex form only), shape ``((n_h + 1)·p, n_θ)``, is the dense
    ``θ`` block of the barrier and CLF rows, used to re-check a gain at the vertices.

    Attributes
    ----------
    cost : ndarray, shape (n,)
        Objective coefficients of the ``n`` columns, as in :class:`CellLp`.
    A_indptr, A_indices, A_values : ndarray, shapes (m + 1,), (nnz,), (nnz,)
        The constraint matrix (m, n) in CSR form, shared by every instance.
    col_lower, col_upper : ndarray, shape (n,)
        Column bounds, shared by every instance.
    lower : ndarray, shape (m,)
        Lower row bounds of the inequality rows (``-INF`` for one-sided rows, ``-u_max`` on the
        box rows of the vertex form).
    equality : ndarray of bool, shape (m,) or None
        Rows whose lower bound equals their upper bound (the dual form's equalities); None when
        there are none (vertex form).
    rhs_h : ndarray
        Upper bounds of the ``c_h``-scaled block, before scaling (``h_k(v_q)`` in the vertex
        form; ``(−n_k, q_k)`` per barrier in the dual form).
    rhs_v : ndarray
        Upper bounds of the ``c_v``-scaled block, before scaling (``−V(v_q)`` per vertex in the
        vertex form; ``(z, zᵀx_j)`` in the dual form).
    rhs_const : ndarray
        Upper bounds of the remaining rows (``u_max`` on the box rows, ``INF`` on the
        least-violation rows).
    n_theta : int
        Number of variables ``θ`` (the first columns).
    n_h : int
        Number of barrier rows; with none the ``c_h`` block is empty and ``c_h`` is ignored.
    vertex_rows : ndarray, shape ((n_h + 1)·p, n_θ) or None
        Dense ``θ`` block of the barrier and CLF rows (vertex form only).
    """

    cost: np.ndarray
    A_indptr: np.ndarray
    A_indices: np.ndarray
    A_values: np.ndarray
    col_lower: np.ndarray
    col_upper: np.ndarray
    lower: np.ndarray
    equality: np.ndarray | None
    rhs_h: np.ndarray
    rhs_v: np.ndarray
    rhs_const: np.ndarray
    n_theta: int
    n_h: int
    vertex_rows: np.ndarray | None = None

    def row_upper(self, c_h: float, c_v: float) -> np.ndarray:
        """Upper row bounds for the constants ``c_h`` (ignored without barrier rows) and ``c_v``."""
        if self.n_h:
            return np.concatenate((self.rhs_h * c_h, self.rhs_v * c_v, self.rhs_const))
        return np.concatenate((self.rhs_v * c_v, self.rhs_const))

    def row_bounds(self, c_h: float, c_v: float) -> tuple[np.ndarray, np.ndarray]:
        """``(row_lower, row_upper)`` for the constants ``c_h`` and ``c_v``, each of shape (m,)."""
        upper = self.row_upper(c_h, c_v)
        return (self.lower if self.equality is None else np.where(self.equality, upper, self.lower)), upper

    def instantiate(self, c_h: float, c_v: float) -> CellLp:
        """The LP with the constants ``c_h`` and ``c_v``."""
        lower, upper = self.row_bounds(c_h, c_v)
        return CellLp(
            self.cost,
            self.A_indptr,
            self.A_indices,
            self.A_values,
            lower,
            upper,
            self.col_lower,
            self.col_upper,
            self.n_theta,
            self.n_h,
        )


def filled(n: int, value: float) -> np.ndarray:
    """A new array of ``n`` floats, every one ``value`` (``±INF`` bounds, say)."""
    out = np.empty(n)
    out.fill(value)
    return out


def assemble(
    dense, lower, equality, rhs_h, rhs_v, rhs_const, n_theta, n_h, n_extra, w_h, w_v, least_violation, vertex_rows=None
) -> LpTemplate:
    """Add column bounds, the objective and (for least violation) the ``t`` variables; compress the matrix.

    Parameters
    ----------
    dense : ndarray, shape (m, n)
        The constraint matrix: columns ``θ``, the ``n_h + 1`` slacks, then ``n_extra`` multipliers.
    lower : ndarray, shape (m,)
        Lower row bounds of the inequality rows.
    equality : ndarray of bool, shape (m,) or None
        The rows whose lower bound is their upper bound; None when there are none.
    rhs_h, rhs_v, rhs_const : ndarray
        Upper row bounds of the ``c_h``-scaled, the ``c_v``-scaled and the constant rows (:class:`LpTemplate`).
    n_theta : int
        Number of variables ``θ`` (the first columns).
    n_h : int
        Number of barrier rows, hence of CBF slacks.
    n_extra : int
        Multipliers after the slacks (the dual form's ``λ``), bounded below by 0.
    w_h, w_v : float
        Objective weights of the CBF slacks and of the CLF slack.
    least_violation : bool
        Free slacks and minimise ``Σ w·max(S, 0)`` through ``t ≥ S``, ``t ≥ 0`` (§5.3) instead.
    vertex_rows : ndarray, optional
        The vertex form's dense ``θ`` block, kept on the template.

    Returns
    -------
    LpTemplate
    """
    n_slack = n_h + 1
    n_rows, n_cols = dense.shape
    col_lower = filled(n_cols, -INF)
    col_upper = filled(n_cols, INF)
    col_lower[n_theta + n_slack : n_theta + n_slack + n_extra] = 0.0  # multipliers λ, μ, ν ≥ 0
    cost = np.zeros(n_cols)
    if least_violation:  # slacks free, t ≥ S, t ≥ 0, minimise Σ w t
        extra = np.zeros((n_rows + n_slack, n_cols + n_slack))
        extra[:n_rows, :n_cols] = dense
        extra[n_rows:, n_theta : n_theta + n_slack] = -np.eye(n_slack)
        extra[n_rows:, n_cols:] = np.eye(n_slack)
        dense = extra
        lower = np.concatenate([lower, np.zeros(n_slack)])
        if equality is not None:
            equality = np.concatenate([equality, np.zeros(n_slack, bool)])
        rhs_const = np.concatenate([rhs_const, filled(n_slack, INF)])
        col_lower = np.concatenate([col_lower, np.zeros(n_slack)])
        col_upper = np.concatenate([col_upper, filled(n_slack, INF)])
        cost = np.concatenate([cost, np.zeros(n_slack)])
        first = n_cols
    else:
        col_upper[n_theta : n_theta + n_slack] = 0.0
        first = n_theta
    cost[first : first + n_h] = w_h
    cost[first + n_h] = w_v
    indptr, indices, values = dense_to_csr(dense)
    return LpTemplate(
        cost,
        indptr,
        indices,
        values,
        col_lower,
        col_upper,
        lower,
        equality,
        rhs_h,
        rhs_v,
        rhs_const,
        n_theta,
        n_h,
        vertex_rows,
    )
