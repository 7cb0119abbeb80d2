"""The vertex form of (P): each group stated at every vertex of the cell, one cell or many cells at once.

The field-space form (``L`` = :data:`~bearnav_cli.cell_lp.fields.FIELD_MAP`), every cell's default
LP, is built for many cells in one numpy pass (:func:`field_vertex_templates`); its sparsity
patterns and column blocks are cached by size.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from bearnav_cli.cell_lp.fields import FIELD_MAP, CellProblem, field_map
from bearnav_cli.cell_lp.form import CellLp, LpTemplate, assemble, filled
from bearnav_cli.lp import INF

__all__ = [
    "field_vertex_templates",
    "FieldTemplates",
    "vertex_lp",
    "vertex_lp_field",
    "vertex_lp_gain",
    "vertex_template",
]

_EYE2 = np.eye(2)
_EYE2.setflags(write=False)


def _frozen(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    for array in arrays:
        array.setflags(write=False)
    return arrays


@functools.lru_cache(maxsize=256)
def _slack_columns(n_theta: int, n_h: int, w_h: float, w_v: float) -> tuple[np.ndarray, ...]:
    """Bounds and costs of the columns ``(θ, S_h, S_V)``: θ free, ``S ≤ 0``, cost ``w`` on the slacks."""
    n_cols = n_theta + n_h + 1
    col_upper = filled(n_cols, INF)
    col_upper[n_theta:] = 0.0
    cost = np.zeros(n_cols)
    cost[n_theta:-1] = w_h
    cost[-1] = w_v
    return _frozen(filled(n_cols, -INF), col_upper, cost)


@functools.lru_cache(maxsize=256)
def _vertex_row_bounds(slack_rows: int, box_rows: int, u_max: float) -> tuple[np.ndarray, ...]:
    """``lower`` of the vertex rows (−∞, then −u_max on the box rows) and the box rows' ``rhs_const``."""
    lower = filled(slack_rows + box_rows, -INF)
    lower[slack_rows:] = -u_max
    return _frozen(lower, filled(box_rows, u_max))


@functools.lru_cache(maxsize=256)
def _slack_block(n_slack: int, p: int, rows: int) -> np.ndarray:
    """``−1`` in column ``g`` of the ``p`` rows of group ``g``, zero below row ``n_slack·p``: shape (rows, n_slack)."""
    block = np.zeros((rows, n_slack))
    block[: n_slack * p] = np.repeat(-np.eye(n_slack), p, axis=0)
    return _frozen(block)[0]


def _box_pattern(L: np.ndarray) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """The θ each field row can move: ``(columns of u_1, columns of u_2)``."""
    moves = np.any(L != 0, axis=1)  # (2, n_θ)
    return tuple(np.flatnonzero(moves[0]).tolist()), tuple(np.flatnonzero(moves[1]).tolist())


_FIELD_PATTERN = ((0, 1, 2), (3, 4, 5))


@functools.lru_cache(maxsize=512)
def _vertex_sparsity(pattern, n_theta: int, n_h: int, p: int, box: int) -> tuple[np.ndarray, ...]:
    """CSR ``indptr``, ``indices`` and the positions in the dense ``(rows, n_θ + h + 1)`` block.

    Rows of the barrier and CLF groups hold every θ a field row can move plus their slack;
    the box rows of ``u_i`` hold the θ of ``pattern[i]`` only.
    """
    n_slack = n_h + 1
    n_cols = n_theta + n_slack
    both = sorted(set(pattern[0]) | set(pattern[1]))
    row_cols = [both + [n_theta + g] for g in range(n_slack) for _ in range(p)]
    row_cols += [list(pattern[i]) for i in range(box) for _ in range(p)]
    counts = [len(c) for c in row_cols]
    indptr = np.zeros(len(row_cols) + 1, np.int32)
    indptr[1:] = np.cumsum(counts)
    indices = np.array([c for cols in row_cols for c in cols], np.int32)
    gather = np.repeat(np.arange(len(row_cols)) * n_cols, counts) + indices
    return _frozen(indptr, indices, gather)


def vertex_template(
    problem: CellProblem,
    L: np.ndarray,
    u_max: float | None,
    w_h: float = 1.0,
    w_v: float = 1.0,
    least_violation: bool = False,
) -> LpTemplate:
    """The vertex form of (P) with open constants (see :func:`vertex_lp`).

    Groups ``g`` in order: the ``h`` barrier rows (``d = −n_k``), the CLF (``d = z``), then
    the box as two ranged groups ``−u_max ≤ e_iᵀu ≤ u_max``. Row ``g·p + q`` reads
    ``d_gᵀu(v_q) − S_g ≤ r_g − ρ_gᵀv_q``, that is ``c_h·h_k(v_q)``, ``−c_v·V(v_q)`` or ``u_max``.

    Parameters
    ----------
    problem : CellProblem
        The cell: vertices ``v_q``, barrier rows, exit direction ``z`` and point ``x_j``.
    L : ndarray, shape (2, 3, n_θ)
        The variable map ``[M, a] = L θ`` (:func:`field_map`); :data:`FIELD_MAP` itself takes
        the batched field-space builder (:func:`field_vertex_templates`).
    u_max : float or None
        Input bound ``|u_i| ≤ u_max`` (map units/s); None drops the box rows.
    w_h, w_v : float
        Objective weights of the CBF slacks ``S_h`` and of the CLF slack ``S_V``.
    least_violation : bool
        Free slacks and minimise ``Σ w·max(S, 0)`` instead (§5.3).

    Returns
    -------
    LpTemplate
        With ``vertex_rows`` set, for re-checking a gain at the vertices.
    """
    if L is FIELD_MAP and not least_violation:
        return _field_vertex_template(problem, u_max, w_h, w_v)
    V = problem.vertices
    p, n_theta = len(V), L.shape[2]
    n_h = len(problem.cbf_q)
    n_slack = n_h + 1
    box = 2 if u_max is not None else 0
    n_groups = n_slack + box
    D = np.empty((n_groups, 2))
    np.negative(problem.cbf_n, out=D[:n_h])
    D[n_h] = problem.z
    D[n_slack:] = _EYE2[:box]
    W = np.empty((p, 3))  # u(v_q) = [M, a] @ W[q]
    np.negative(V, out=W[:, :2])
    W[:, 2] = 1.0
    # the coefficient of θ_j in d_gᵀu(v_q) is Σ_c W_qc (Σ_i d_gi L_icj)
    DL = (D @ L.reshape(2, 3 * n_theta)).reshape(n_groups, 3, n_theta)
    rows = n_groups * p
    coef = (W @ DL).reshape(rows, n_theta)
    rhs_h = (problem.cbf_n @ V.T + problem.cbf_q[:, None]).ravel()  # h_k(v_q), barrier-major
    rhs_v = (problem.x_j - V) @ problem.z  # −V(v_q)
    lower, rhs_const = _vertex_row_bounds(n_slack * p, box * p, float(u_max) if box else 0.0)
    dense = np.empty((rows, n_theta + n_slack))
    dense[:, :n_theta] = coef
    dense[:, n_theta:] = _slack_block(n_slack, p, rows)
    vertex_rows = coef[: n_slack * p]
    if least_violation:
        return assemble(dense, lower, None, rhs_h, rhs_v, rhs_const, n_theta, n_h, 0, w_h, w_v, True, vertex_rows)
    # The sparsity pattern depends only on the sizes and on which θ each box side can move.
    # Exact zeros inside it (a vertex on x = 0, say) are passed on explicitly; HiGHS drops them.
    pattern = _FIELD_PATTERN if L is FIELD_MAP else _box_pattern(L)
    indptr, indices, gather = _vertex_sparsity(pattern, n_theta, n_h, p, box)
    col_lower, col_upper, cost = _slack_columns(n_theta, n_h, float(w_h), float(w_v))
    return LpTemplate(
        cost,
        indptr,
        indices,
        dense.ravel()[gather],
        col_lower,
        col_upper,
        lower,
        None,
        rhs_h,
        rhs_v,
        rhs_const,
        n_theta,
        n_h,
        vertex_rows,
    )


def _field_vertex_template(problem: CellProblem, u_max: float | None, w_h: float, w_v: float) -> LpTemplate:
    """:func:`vertex_template` in field space (``L`` = :data:`FIELD_MAP`), the default LP of every cell:
    :func:`field_vertex_templates` of this one cell (one builder for both)."""
    p, n_h = len(problem.vertices), len(problem.cbf_q)
    built = field_vertex_templates(
        problem.vertices,
        np.array([0, p]),
        np.asarray(problem.cbf_n, float).reshape(-1, 2),
        np.asarray(problem.cbf_q, float),
        np.array([0, n_h]),
        problem.z[None, :],
        problem.x_j[None, :],
        [0],
        u_max,
        w_h,
        w_v,
    )
    return built.templates[0]


@dataclass(frozen=True)
class FieldTemplates:
    """The field-space vertex templates of many cells, from :func:`field_vertex_templates`.

    Attributes
    ----------
    templates : dict of int to LpTemplate
        One per requested cell, each equal (same bytes) to ``vertex_template(problem, FIELD_MAP, …)``.
    h_values : ndarray, shape (Σ_c h_c·p_c,)
        ``h_k(v_q)`` of every cell, cell after cell (barrier-major within a cell); the
        templates' ``rhs_h`` are views into it. Cells not requested hold ``q_k`` only.
    h_value_offsets : ndarray of int64, shape (C + 1,)
        Cell ``c`` owns ``h_values[h_value_offsets[c]:h_value_offsets[c + 1]]``.
    minus_v : ndarray, shape (P,)
        ``−V(v_q)`` of every vertex, in vertex order; the templates' ``rhs_v`` are views into it
        (zero for cells not requested).
    """

    templates: dict
    h_values: np.ndarray
    h_value_offsets: np.ndarray
    minus_v: np.ndarray


def field_vertex_templates(
    vertices: np.ndarray,
    vertex_offsets: np.ndarray,
    cbf_n: np.ndarray,
    cbf_q: np.ndarray,
    cbf_offsets: np.ndarray,
    z: np.ndarray,
    x_j: np.ndarray,
    cells,
    u_max: float | None,
    w_h: float = 1.0,
    w_v: float = 1.0,
) -> FieldTemplates:
    """:func:`vertex_template` in field space for many cells at once, from flat arrays (the ``Cells`` layout).

    The coefficients ``d_g ⊗ w_q`` of every row of every cell come from one numpy pass (the
    single products ``d_g ⊗ w_q``, with ``w_q = (−v_q, 1)``), as do the ``+ q_k`` of the barrier
    right-hand sides. What stays per cell is slicing, one concatenation of the CSR values and
    the two small matrix products ``n @ Vᵀ`` and ``(x_j − V) @ z``: those are the very BLAS calls
    of the per-cell builder, on the same views, so that the right-hand sides round the same way
    (a batched product could fuse multiply and add differently).

    Parameters
    ----------
    vertices : ndarray, shape (P, 2)
        Every cell's CCW vertices; cell ``c`` owns rows ``vertex_offsets[c]:vertex_offsets[c + 1]``.
    vertex_offsets : ndarray of int, shape (C + 1,)
        Start of each cell's vertices in ``vertices``, and their total ``P`` last.
    cbf_n, cbf_q : ndarray, shapes (H, 2), (H,)
        Barrier rows ``h = n @ x + q``; cell ``c`` owns rows ``cbf_offsets[c]:cbf_offsets[c + 1]``.
    cbf_offsets : ndarray of int, shape (C + 1,)
        Start of each cell's barrier rows in ``cbf_n``, ``cbf_q``, and their total ``H`` last.
    z, x_j : ndarray, shape (C, 2)
        Exit direction and exit point per cell.
    cells : sequence of int
        The cells to build templates for (rows of every cell are computed, which is cheaper
        than gathering a subset; cells not listed may hold any finite or NaN data).
    u_max, w_h, w_v : float
        As in :func:`vertex_template` (``u_max`` None drops the box rows).

    Returns
    -------
    FieldTemplates
    """
    n_cells = len(z)
    vo, ho = np.asarray(vertex_offsets, np.int64), np.asarray(cbf_offsets, np.int64)
    p, h = np.diff(vo), np.diff(ho)
    box = 2 if u_max is not None else 0
    W = np.empty((len(vertices), 3))  # as in _field_vertex_template, with zeros +0
    np.subtract(0.0, vertices, out=W[:, :2])
    W[:, 2] = 1.0
    # Groups with a slack, cell after cell: the cell's barrier rows (d = −n), then its CLF (d = z).
    go = ho + np.arange(n_cells + 1)
    D = np.empty((go[-1], 2))
    D[go[1:] - 1] = z
    D[np.arange(len(cbf_q)) + np.repeat(np.arange(n_cells), h)] = -cbf_n
    # Slack rows: group g of cell c has one row per vertex of c.
    group_rows = np.repeat(p, h + 1)
    ro = np.zeros(len(group_rows) + 1, np.int64)
    np.cumsum(group_rows, out=ro[1:])
    row_group = np.repeat(np.arange(len(group_rows)), group_rows)
    row_vertex = np.arange(ro[-1]) + np.repeat(np.repeat(vo[:-1], h + 1) - ro[:-1], group_rows)
    # Column by column: a broadcast (R, 2, 1) × (R, 1, 3) product runs numpy's slow tiny-inner-loop path.
    d, w = np.take(D, row_group, axis=0), np.take(W, row_vertex, axis=0)
    coef = np.empty((len(row_group), 6))
    for i in range(2):
        for k in range(3):
            np.multiply(d[:, i], w[:, k], out=coef[:, 3 * i + k])
    coef += 0.0
    slack_values = np.empty((len(coef), 7))
    slack_values[:, :6] = coef
    slack_values[:, 6] = -1.0
    # Right-hand sides: the per-cell products into flat buffers, then the offsets q_k at once.
    hvo = np.zeros(n_cells + 1, np.int64)
    np.cumsum(h * p, out=hvo[1:])
    h_values = np.zeros(hvo[-1])
    minus_v = np.zeros(len(vertices))
    exit_minus_vertex = np.repeat(x_j, p, axis=0) - vertices  # x_j − v_q, elementwise as per cell
    v_off, h_off, hv_off, r_off = vo.tolist(), ho.tolist(), hvo.tolist(), ro[go].tolist()
    cells = list(cells)
    for c in cells:
        v0, v1, h0, h1 = v_off[c], v_off[c + 1], h_off[c], h_off[c + 1]
        np.matmul(cbf_n[h0:h1], vertices[v0:v1].T, out=h_values[hv_off[c] : hv_off[c + 1]].reshape(h1 - h0, v1 - v0))
        np.matmul(exit_minus_vertex[v0:v1], z[c], out=minus_v[v0:v1])
    h_values += np.repeat(cbf_q, np.repeat(p, h))
    _frozen(h_values, minus_v, coef)
    templates = {}
    for c in cells:
        v0, v1, n_h = v_off[c], v_off[c + 1], h_off[c + 1] - h_off[c]
        n = v1 - v0
        r0, r1 = r_off[c], r_off[c + 1]
        w_cell = W[v0:v1].ravel()  # the box rows of u_1, then of u_2
        values = np.concatenate((slack_values[r0:r1].ravel(),) + (w_cell,) * box)
        lower, rhs_const = _vertex_row_bounds(r1 - r0, box * n, float(u_max) if box else 0.0)
        indptr, indices, _ = _vertex_sparsity(_FIELD_PATTERN, 6, n_h, n, box)
        col_lower, col_upper, cost = _slack_columns(6, n_h, float(w_h), float(w_v))
        templates[c] = LpTemplate(
            cost,
            indptr,
            indices,
            values,
            col_lower,
            col_upper,
            lower,
            None,
            h_values[hv_off[c] : hv_off[c + 1]],
            minus_v[v0:v1],
            rhs_const,
            6,
            n_h,
            coef[r0:r1],
        )
    return FieldTemplates(templates, h_values, hvo, minus_v)


def vertex_lp(
    problem: CellProblem,
    L: np.ndarray,
    c_h: float,
    c_v: float,
    u_max: float | None,
    w_h: float = 1.0,
    w_v: float = 1.0,
    least_violation: bool = False,
) -> CellLp:
    """The vertex form of (P) in the variables ``θ`` with ``[M, a] = L θ`` (ALGORITHMS §5.2).

    Parameters
    ----------
    problem : CellProblem
        The cell's data.
    L : ndarray, shape (2, 3, n_θ)
        From :func:`field_map`.
    c_h, c_v : float
        Barrier and Lyapunov constants (1/s); ``c_h`` is unused without barrier rows.
    u_max : float or None
        Input box; ``None`` drops the input rows (Appendix A, T1).
    w_h, w_v : float
        Objective weights.
    least_violation : bool
        Free slacks and minimise ``Σ w·max(S, 0)`` instead (§5.3).

    Returns
    -------
    CellLp
        Rows (see :func:`vertex_template`): per group one row per vertex; the box as
        ranged rows ``−u_max ≤ u_i(v_q) ≤ u_max``.
    """
    return vertex_template(problem, L, u_max, w_h, w_v, least_violation).instantiate(c_h, c_v)


def vertex_lp_field(problem: CellProblem, c_h: float, c_v: float, u_max: float | None, **kw) -> CellLp:
    """Field-space vertex form: ``θ = vec([M, a])`` (row-major), 6 + n_h + 1 variables.

    Parameters
    ----------
    problem : CellProblem
        The cell's data.
    c_h, c_v : float
        Barrier and Lyapunov constants (1/s).
    u_max : float or None
        Input box (map units/s); ``None`` drops the input rows.
    **kw
        ``w_h``, ``w_v`` and ``least_violation`` of :func:`vertex_lp`.

    Returns
    -------
    CellLp
    """
    return vertex_lp(problem, FIELD_MAP, c_h, c_v, u_max, **kw)


def vertex_lp_gain(
    problem: CellProblem, c_h: float, c_v: float, u_max: float | None, structure: str = "full", **kw
) -> CellLp:
    """Gain-space vertex form for a gain structure (``full``, ``diag`` or ``scalar``).

    Parameters
    ----------
    problem : CellProblem
        The cell's data; its landmarks fix the gain's size (2, 2n).
    c_h, c_v : float
        Barrier and Lyapunov constants (1/s).
    u_max : float or None
        Input box (map units/s); ``None`` drops the input rows.
    structure : {"full", "diag", "scalar"}
        Which gain entries are variables (:func:`field_map`).
    **kw
        ``w_h``, ``w_v`` and ``least_violation`` of :func:`vertex_lp`.

    Returns
    -------
    CellLp
    """
    return vertex_lp(problem, field_map(structure, problem.landmarks), c_h, c_v, u_max, **kw)
