"""A cell's field without the LP: constants, the goal cell's field, Lemma 6's field, ``δ_c`` (ALGORITHMS §5, §12.4).

What ``bearnav synthesize`` computes around the LPs of :mod:`bearnav_cli.cell_lp`, from a cell's
geometry or a gain alone:

- :class:`CellSolution` — a cell's controller and certificate, what the stage stores per cell;
- :func:`cell_constants` — ``(c_h, c_v)`` of §5.3, cell by cell (:func:`constant_scales`) or for
  every cell in a few numpy passes (:func:`batched_scales`; the same numbers, bit for bit);
- :func:`lemma4_terms` / :func:`lemma4_margin` — Lemma 4's geometric terms and margin;
- :func:`goal_cell_solution` — the goal cell's straight-to-goal field (§5.6);
- :func:`more_tolerant` / :func:`more_tolerant_all` — of a certified funnel cell's LP field and
  Lemma 6's field, the one with the larger ``δ_c`` (§12.4), their margins re-checked;
- :func:`cell_tolerances` — ``δ_c`` of every funnel cell from its gain (§11.4).

Margins are re-checked with :mod:`bearnav_cli.runtime.certificate`, the one re-check.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bearnav_cli.cell_lp import CellProblem, FieldTemplates, min_norm_gain, min_norm_gains
from bearnav_cli.datatypes import Cells, CellStatus
from bearnav_cli.errors import ArtifactError
from bearnav_cli.funnel import cell_tolerance, exit_sinks
from bearnav_cli.runtime.certificate import field_margins, gain_field, vertex_margins

__all__ = [
    "DELTA_FRACTION",
    "CellSolution",
    "batched_scales",
    "cell_constants",
    "cell_sinks",
    "cell_tolerances",
    "checked_v_max",
    "constant_scales",
    "goal_cell_solution",
    "grouped_gains",
    "lemma4_margin",
    "lemma4_terms",
    "more_tolerant",
    "more_tolerant_all",
]

#: ``δ = DELTA_FRACTION · diam(X)`` floors the worst barrier violation in ``c_h`` (§5.3).
DELTA_FRACTION = 0.05


@dataclass(frozen=True)
class CellSolution:
    """A cell's controller and certificate.

    Attributes
    ----------
    status : CellStatus
        Certified at the first ``κ``, relaxed (after halvings), not certified (least violation)
        or solver failure.
    K : ndarray, shape (2, 2n)
        Gain over the problem's landmarks: ``u(x) = K @ (landmarks − x).ravel()``.
    c_h, c_v : float
        Constants of the certificate (1/s); ``c_h`` NaN without barrier rows.
    margin_h, margin_v : float
        ``max_k S_h,k`` and ``S_V`` recomputed at the vertices from ``K`` (NaN where no row).
    attempts : int
        LPs solved for the cell (feasibility attempts plus the least-violation solve).
    kappa : float
        The ``κ`` of the stored constants.
    objective : float
        The last LP's optimal value (NaN when it failed or for the goal cell).
    tolerance : float
        ``δ_c`` of the stored field when :func:`more_tolerant` chose it (NaN otherwise).
    """

    status: CellStatus
    K: np.ndarray
    c_h: float
    c_v: float
    margin_h: float
    margin_v: float
    attempts: int
    kappa: float = math.nan
    objective: float = math.nan
    tolerance: float = math.nan


def cell_constants(problem: CellProblem, kappa: float, u_max: float) -> tuple[float, float]:
    """``(c_h, c_v)`` of §5.3: ``c_v = κ u_max / max_q V(v_q)``, ``c_h = κ u_max / max(δ, max −h)``.

    ``δ = 0.05·diam(X)`` (:data:`DELTA_FRACTION`); ``c_h`` is NaN without barrier rows.

    Parameters
    ----------
    problem : CellProblem
        The cell: its vertices, barrier rows, exit direction ``z`` and exit point ``x_j``.
    kappa : float
        ``κ_h = κ_v`` (dimensionless, §5.3): at ``κ = 1`` the decay terms ``c_v V`` and ``c_h h`` at
        their worst vertex ask for the whole input bound ``u_max``.
    u_max : float
        Input bound (map units/s).

    Returns
    -------
    c_h, c_v : float
        Barrier and Lyapunov constants (1/s).

    Raises
    ------
    ArtifactError
        If ``V ≤ 0`` at every vertex (``z`` does not point into the cell).
    """
    V = problem.vertices
    h_values = problem.cbf_n @ V.T + problem.cbf_q[:, None]
    h_scale, v_scale = constant_scales(V, h_values, (problem.x_j - V) @ problem.z)
    return kappa * u_max / h_scale, kappa * u_max / v_scale


def constant_scales(V: np.ndarray, h_values: np.ndarray, minus_v: np.ndarray) -> tuple[float, float]:
    """Denominators ``max(δ, max −h)`` (NaN without barrier rows) and ``max V`` of :func:`cell_constants`.

    Parameters
    ----------
    V : ndarray, shape (p, 2)
        The cell's vertices.
    h_values : ndarray, shape (h, p) or (h·p,)
        ``h_k(v_q)``.
    minus_v : ndarray, shape (p,)
        ``−V(v_q)``, as the vertex template's ``rhs_v`` holds it (``max V = −min(−V)`` exactly).
    """
    v_max = checked_v_max(-float(minus_v.min()))
    if h_values.size == 0:
        return math.nan, v_max
    diff = V[:, None, :] - V  # (p, p, 2); the squared distances are d₀² + d₁², the order a sum over axis 2 uses
    diff *= diff
    diam = math.sqrt(float((diff[..., 0] + diff[..., 1]).max()))
    return max(DELTA_FRACTION * diam, -float(h_values.min())), v_max


def checked_v_max(v_max: float) -> float:
    """``max_q V(v_q)``, which must be positive (``c_v`` divides by it)."""
    if not v_max > 0:
        raise ArtifactError("exit_dir does not point into the cell (V ≤ 0 at every vertex)", field="exit_dir")
    return v_max


def batched_scales(cells: Cells, built: FieldTemplates, which: list[int]) -> dict[int, tuple[float, float, tuple]]:
    """``(h_scale, max V, (min_k h_k(x_j), diam))`` of :func:`constant_scales` and :func:`lemma4_terms`
    for the cells ``which``, in a few numpy passes.

    The same numbers: minima and maxima are exact in any grouping, the squared distances are
    the same ``d₀² + d₁²`` (cells grouped by vertex count, so no padding), and ``np.sqrt`` rounds
    as ``math.sqrt`` does. ``max V`` is not checked here (see :func:`checked_v_max`).

    Parameters
    ----------
    cells : Cells
        The decomposition (its flat vertex, barrier-row and exit arrays).
    built : FieldTemplates
        Every cell's field-space vertex rows (:func:`~bearnav_cli.cell_lp.field_vertex_templates`): their
        ``h_k(v_q)`` and ``−V(v_q)``.
    which : list of int
        The cells wanted (edge cells).
    """
    vo = cells.cell_vertex_offsets
    p = np.diff(vo)
    n_h = np.diff(cells.cbf_offsets)
    v_max = (-np.minimum.reduceat(built.minus_v, vo[:-1])).tolist()
    h_min = np.full(len(p), np.nan)  # stays NaN without barrier rows
    has_rows = np.flatnonzero(n_h)
    if len(has_rows):  # empty segments in between reduce to nothing, as they should
        h_min[has_rows] = np.minimum.reduceat(built.h_values, built.h_value_offsets[has_rows])
    which_arr = np.asarray(which, np.int64)
    diam = np.zeros(len(p))
    for n in np.unique(p[which_arr]).tolist():
        group = which_arr[p[which_arr] == n]
        V = cells.cell_vertices[vo[group][:, None] + np.arange(n)]  # (k, n, 2)
        diff = V[:, :, None, :] - V[:, None, :, :]
        diff *= diff
        diam[group] = np.sqrt((diff[..., 0] + diff[..., 1]).max(axis=(1, 2)))
    # Lemma 4's min_k h_k(x_j): every barrier row at its cell's exit point
    at_exit = np.full(len(p), math.inf)
    if len(has_rows):
        row_cell = np.repeat(np.arange(len(p)), n_h)
        h_exit = np.einsum("ki,ki->k", cells.cbf_A, cells.exit_point[row_cell]) + cells.cbf_b
        at_exit[has_rows] = np.minimum.reduceat(h_exit, cells.cbf_offsets[has_rows])
    diam_list, h_min_list, n_h_list, exit_list = diam.tolist(), h_min.tolist(), n_h.tolist(), at_exit.tolist()
    out = {}
    for c in which:  # the Python max of constant_scales, on the same two floats
        h_scale = max(DELTA_FRACTION * diam_list[c], -h_min_list[c]) if n_h_list[c] else math.nan
        out[c] = (h_scale, v_max[c], (exit_list[c], diam_list[c]))
    return out


def lemma4_margin(problem: CellProblem, c_v: float, u_max: float) -> float:
    """``ε_max = min(c·min_k h_k(x_j), u_max − c·diam(P))`` of ALGORITHMS §11.2 (Lemma 4) with ``c = c_v``.

    When positive, the field ``c(x_j − x) − εz`` with ``0 < ε < ε_max`` meets (L1)–(L3) with
    margins of at least ``min(ε, ε_max − ε)``; the LP's strict margin bounds are set from it.

    Parameters
    ----------
    problem : CellProblem
        The cell: vertices, barrier rows and exit point.
    c_v : float
        The Lyapunov constant ``c`` (1/s).
    u_max : float
        Input bound (map units/s).
    """
    h_min, diam = lemma4_terms(problem)
    return min(c_v * h_min, u_max - c_v * diam)


def lemma4_terms(problem: CellProblem) -> tuple[float, float]:
    """``min_k h_k(x_j)`` and ``diam(P)`` of a cell (map units), the two geometric terms of Lemma 4.

    The numbers of :func:`batched_scales`: ``h_k(x_j)`` as the same ``einsum`` (a matrix product may
    round it differently in the last place).
    """
    V = problem.vertices
    diff = V[:, None, :] - V
    diam = math.sqrt(float((diff * diff).sum(axis=2).max()))
    h_exit = np.einsum("ki,i->k", problem.cbf_n, problem.x_j) + problem.cbf_q
    h_min = float(np.min(h_exit)) if len(problem.cbf_q) else math.inf
    return h_min, diam


def goal_cell_solution(
    vertices: np.ndarray, goal: np.ndarray, landmarks: np.ndarray, cbf_n: np.ndarray, cbf_q: np.ndarray, u_max: float
) -> CellSolution:
    """The goal cell's straight-to-goal field ``u = c(g − x)`` (ALGORITHMS §5.6).

    ``c = u_max / max_q ‖g − v_q‖_∞``; ``c_h = c_v = c``; ``K = [cI, cg](GᵀG)⁻¹Gᵀ``;
    ``margin_h`` from the barrier rows at the vertices, ``margin_v`` NaN. Without barrier
    rows ``c_h`` and ``margin_h`` are NaN, as in every cell (§5.6, edge cases).

    Parameters
    ----------
    vertices : ndarray, shape (p, 2)
        The goal cell's vertices (map units).
    goal : ndarray, shape (2,)
        ``g`` (map units), the field's equilibrium and the CLF's exit point.
    landmarks : ndarray, shape (n, 2)
        Positions of the cell's landmarks (map units), over which ``K`` is written.
    cbf_n, cbf_q : ndarray, shapes (h, 2), (h,)
        The goal cell's barrier rows ``h_k(x) = n_kᵀx + q_k``; there may be none.
    u_max : float
        Input bound (map units/s): ``c`` makes ``‖u‖_∞`` reach it at the farthest vertex.

    Returns
    -------
    CellSolution
        Status 4.
    """
    vertices = np.asarray(vertices, float)
    goal = np.asarray(goal, float)
    c = u_max / float(np.max(np.abs(goal - vertices)))
    K = min_norm_gain(c * np.eye(2), c * goal, landmarks)
    m = vertex_margins(K, landmarks, vertices, np.zeros(2), goal, cbf_n, cbf_q, c, c, u_max)
    c_h = c if len(np.asarray(cbf_q)) else math.nan  # like every cell without barrier rows
    return CellSolution(CellStatus.GOAL, K, c_h, c, m.cbf, math.nan, 0)


def more_tolerant(
    solution: CellSolution, problem: CellProblem, u_max: float, terms: tuple[float, float] | None = None
) -> CellSolution:
    """Of a certified funnel cell's LP field and Lemma 6's field, the one with the larger ``δ_c`` (§12.4).

    One cell of :func:`more_tolerant_all`.

    Parameters
    ----------
    solution : CellSolution
        The cell's certified LP solution.
    problem : CellProblem
        The cell.
    u_max : float
        Input bound (map units/s).
    terms : tuple of float, optional
        Lemma 4's ``(min_k h_k(x_j), diam)`` when already computed (only ``diam`` is read).
    """
    return more_tolerant_all([solution], [problem], u_max, [terms])[0]


def more_tolerant_all(
    solutions: Sequence[CellSolution],
    problems: Sequence[CellProblem],
    u_max: float,
    terms: Sequence[tuple[float, float] | None] | None = None,
) -> list[CellSolution]:
    """:func:`more_tolerant` of many certified funnel cells at once (every cell's vertices and rows in one pass).

    Lemma 6's field (ALGORITHMS §12.4) ``u = c(x* − x) − εz`` with ``c = c_v`` and its sink ``x*``
    at the point of the exit face of largest side depth ``h*`` (:func:`~bearnav_cli.funnel.exit_sink`)
    has ``M = cI``, barrier margins at least ``c·h* − ε`` and progress margin ``ε``, so it
    tolerates ``min(h* − ε/c, ε/c)``; the best ``ε = c·h*/2``, lowered to keep
    ``|u|_∞ ≤ c·diam + ε ≤ u_max``. Since ``x_j`` lies on the face, ``h* ≥ min_k h_k(x_j)``: it
    never tolerates less than Lemma 4's field with its sink at ``x_j``. Both fields (the LP's and
    Lemma 6's) are re-checked at the vertices (the numbers of
    :func:`~bearnav_cli.runtime.certificate.field_margins`) and their ``δ_c`` is
    :func:`bearnav_cli.funnel.cell_tolerance`'s; each returned solution carries the chosen gain, its
    margins and its ``δ_c``, with the same status and constants.

    Parameters
    ----------
    solutions, problems : sequences of length C
        Certified funnel edge cells and their problems.
    u_max : float
        Input bound (map units/s).
    terms : sequence of length C, optional
        Lemma 4's ``(h_min, diam)`` per cell (None: computed); ``diam`` bounds the field.

    Returns
    -------
    list of CellSolution, length C
    """
    C = len(solutions)
    if not C:
        return []
    terms = [None] * C if terms is None else list(terms)
    terms = [lemma4_terms(p) if t is None else t for p, t in zip(problems, terms, strict=True)]
    diam = np.array([t[1] for t in terms], float)
    z = np.array([p.z for p in problems], float)
    x_j = np.array([p.x_j for p in problems], float)
    # ragged vertices and barrier rows (CellProblem holds them as float64 (p, 2), (h, 2), (h,))
    n_v = np.array([len(p.vertices) for p in problems])
    n_h = np.array([len(p.cbf_q) for p in problems])
    V = np.concatenate([p.vertices for p in problems])
    N = np.concatenate([p.cbf_n for p in problems])
    Q = np.concatenate([p.cbf_q for p in problems])
    sink, h_star = cell_sinks(V, n_v, N, Q, n_h, z, x_j)
    c_h = np.array([s.c_h for s in solutions], float)
    c_lp = np.array([s.c_v for s in solutions], float)
    # Lemma 6 takes c ≤ c_v ≤ c_h, and c_v only sets the time bound: lower both where the input
    # box binds (c·diam + ε ≤ u_max with ε = c·h*/2 needs c ≤ u_max/(diam + h*/2)), so that
    # δ_c = h*/2 (the certificate of that field is stated with c_v = c)
    c = np.minimum(c_lp, (1.0 - 1e-9) * u_max / (diam + h_star))
    eps = np.minimum(0.5 * c * h_star, 0.5 * (u_max - c * diam))
    c_v = np.stack([c_lp, c])  # (2, C): the constant (L2) is checked with, per field
    # the two fields u = a − M x of every cell: the LP's (from its gain) and Lemma 6's
    M = np.empty((2, C, 2, 2))
    a = np.empty((2, C, 2))
    # The LP's field [K𝟙, Kℓ], one stacked call per landmark count: the sum runs over the
    # landmarks in the same order, and each item of the stacked matmul is the per-cell product.
    n_lm = np.array([len(p.landmarks) for p in problems])
    for n in np.unique(n_lm).tolist():
        group = np.flatnonzero(n_lm == n).tolist()
        K = np.stack([solutions[k].K for k in group])  # (g, 2, 2n)
        ell = np.stack([problems[k].landmarks for k in group]).reshape(len(group), 2 * n, 1)
        M[0, group] = K.reshape(len(group), 2, n, 2).sum(axis=2)
        a[0, group] = np.matmul(K, ell)[..., 0]
    M[1] = c[:, None, None] * np.eye(2)
    a[1] = c[:, None] * sink - np.where(eps > 0, eps, 0.0)[:, None] * z
    v_cell, h_cell = np.repeat(np.arange(C), n_v), np.repeat(np.arange(C), n_h)
    v_start, h_start = np.cumsum(n_v) - n_v, np.cumsum(n_h) - n_h
    # every (row, vertex) pair of the same cell, row after row: each row's pairs and each cell's
    # rows and vertices are contiguous, so the maxima are segment reductions (reduceat)
    row_len = n_v[h_cell]
    row_start = np.cumsum(row_len) - row_len
    pair_row = np.repeat(np.arange(len(Q)), row_len)
    pair_vertex = np.arange(int(row_len.sum())) + np.repeat(v_start[h_cell] - row_start, row_len)
    has_rows = n_h > 0
    U = a[:, v_cell] - np.einsum("fcij,cj->fci", M[:, v_cell], V)  # (2, ΣP, 2): u at every vertex
    pair_n = N[pair_row]
    values = -(
        np.einsum("fpi,pi->fp", U[:, pair_vertex], pair_n)
        + c_h[h_cell[pair_row]] * (np.einsum("pi,pi->p", V[pair_vertex], pair_n) + Q[pair_row])
    )
    cbf = np.full((2, C), -np.inf)
    if len(Q):
        row_max = np.maximum.reduceat(values, row_start, axis=1)
        cbf[:, has_rows] = np.maximum.reduceat(row_max, h_start[has_rows], axis=1)
    else:
        row_max = np.zeros((2, 0))
    progress = np.einsum("fpi,pi->fp", U, z[v_cell]) + c_v[:, v_cell] * np.einsum(
        "pi,pi->p", V - x_j[v_cell], z[v_cell]
    )
    clf = np.maximum.reduceat(progress, v_start, axis=1)
    peak = np.maximum.reduceat(np.abs(U).max(axis=2), v_start, axis=1)
    # δ_c = min over the barrier rows and the exit direction of margin / ‖Mᵀn‖ (funnel.cell_tolerance)
    row_gain = np.hypot(*np.einsum("ri,frij->frj", N, M[:, h_cell]).transpose(2, 0, 1))  # (2, ΣH)
    z_gain = np.hypot(*np.einsum("ci,fcij->fcj", z, M).transpose(2, 0, 1))  # (2, C)
    sigma_h, sigma_v = -row_max, -clf
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio_h = np.where(row_gain > 0, sigma_h / row_gain, np.inf)
        ratio_v = np.where(z_gain > 0, sigma_v / z_gain, np.inf)
    delta = ratio_v.copy()
    positive = sigma_v > 0
    if len(Q):
        starts = h_start[has_rows]
        delta[:, has_rows] = np.minimum(delta[:, has_rows], np.minimum.reduceat(ratio_h, starts, axis=1))
        positive[:, has_rows] &= ~np.logical_or.reduceat(~(sigma_h > 0), starts, axis=1)
    # the LP's own solution sits on its bounds up to the solver's rounding
    valid = (cbf <= 1e-9 * u_max) & (clf < 0) & (peak - u_max <= 1e-9 * u_max)
    delta = np.where(valid & positive, delta, 0.0)
    delta[1, ~(eps > 0)] = -np.inf  # Lemma 6's field exists only for ε > 0
    lemma6 = delta[1] > delta[0]  # else the LP's field, with its margins re-checked here
    gains = grouped_gains(M[1], a[1], [p.landmarks for p in problems], np.flatnonzero(lemma6).tolist())
    # Python floats for the per-cell results (the same numbers as float() of each entry)
    cbf_l, clf_l, delta_l, c_l = cbf.tolist(), clf.tolist(), delta.tolist(), c.tolist()
    n_h_l, lemma6_l = n_h.tolist(), lemma6.tolist()
    out = []
    for k, sol in enumerate(solutions):
        f = int(lemma6_l[k])
        K, c_k = (gains[k], c_l[k]) if f else (sol.K, sol.c_v)
        out.append(
            CellSolution(
                sol.status,
                K,
                sol.c_h,
                c_k,
                cbf_l[f][k] if n_h_l[k] else math.nan,
                clf_l[f][k],
                sol.attempts,
                sol.kappa,
                sol.objective,
                delta_l[f][k],
            )
        )
    return out


def grouped_gains(M: np.ndarray, a: np.ndarray, landmarks: Sequence[np.ndarray], which: list[int]) -> dict:
    """:func:`~bearnav_cli.cell_lp.min_norm_gains` of the fields ``which``, one call per landmark count.

    Returns ``{k: K}`` with ``K`` of shape (2, 2n_k) for every ``k`` in ``which``.

    Parameters
    ----------
    M : ndarray, shape (C, 2, 2)
        The fields' linear parts.
    a : ndarray, shape (C, 2)
        Their constant parts.
    landmarks : sequence of ndarray, shape (n_k, 2) each
        The landmarks of field ``k``.
    which : list of int
        The fields wanted.
    """
    counts = [len(landmarks[k]) for k in which]
    out = {}
    for n in sorted(set(counts)):
        group = [k for k, count in zip(which, counts, strict=True) if count == n]
        K = min_norm_gains(M[group], a[group], np.stack([landmarks[k] for k in group]))
        out.update(zip(group, K, strict=True))
    return out


def cell_sinks(
    V: np.ndarray, n_v: np.ndarray, N: np.ndarray, Q: np.ndarray, n_h: np.ndarray, z: np.ndarray, x_j: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Lemma 6's sink ``x*`` (C, 2) and side depth ``h*`` (C,) of every cell (:func:`funnel.exit_sinks`).

    The cells come ragged. Each exit face is :func:`funnel.exit_face`'s (the two vertices nearest the
    exit line, in polygon order, ties to the first), taken for all cells in one sort.

    Parameters
    ----------
    V : ndarray, shape (ΣP, 2)
        Every cell's vertices, cell after cell.
    n_v : ndarray of int, shape (C,)
        How many vertices each cell has.
    N, Q : ndarray, shapes (ΣH, 2), (ΣH,)
        Every cell's barrier rows ``n·x + q ≥ 0``, cell after cell.
    n_h : ndarray of int, shape (C,)
        How many rows each cell has.
    z, x_j : ndarray, shape (C, 2)
        Exit directions and exit points.
    """
    C = len(n_v)
    v_cell = np.repeat(np.arange(C), n_v)
    v_start, h_start = np.cumsum(n_v) - n_v, np.cumsum(n_h) - n_h
    gap = np.abs(np.einsum("pi,pi->p", V - x_j[v_cell], z[v_cell]))
    nearest = np.lexsort((gap, v_cell))  # per cell, its vertices by gap (stable: ties keep polygon order)
    faces = V[np.sort(np.stack([nearest[v_start], nearest[v_start + 1]], axis=1), axis=1)]
    # exit_sinks costs C·H³ with every cell padded to the largest row count H: one call per row
    # count instead (a cell without rows has h* = +inf anywhere on its face, and no Lemma 6 field)
    sinks, depths = np.empty((C, 2)), np.empty(C)
    for k in np.unique(n_h).tolist():
        group = np.flatnonzero(n_h == k)
        rows = h_start[group][:, None] + np.arange(k)
        sinks[group], depths[group] = exit_sinks(faces[group], N[rows], Q[rows])
    return sinks, depths


def cell_tolerances(
    cells: Cells, gain: np.ndarray, c_h: np.ndarray, c_v: np.ndarray, u_max: float, known: np.ndarray | None = None
) -> np.ndarray:
    """``δ_c`` of every funnel cell from its gain and rows (ALGORITHMS §11.4), shape (C,), map units.

    The margins are recomputed at the vertices (:func:`~bearnav_cli.runtime.certificate.field_margins`); a cell
    whose margins are not all positive tolerates no error (``δ_c = 0``).

    Parameters
    ----------
    cells : Cells
        The decomposition.
    gain : ndarray, shape (C, 2, 2L)
        Every cell's gain over all the map's landmarks.
    c_h, c_v : ndarray, shape (C,)
        Barrier and Lyapunov constants (1/s).
    u_max : float
        Input bound (map units/s).
    known : ndarray, shape (C,), optional
        The ``δ_c`` already known (NaN elsewhere); default: compute every cell's.
    """
    landmarks = cells.map.landmarks
    out = np.zeros(cells.n_cells) if known is None else np.array(known, float)
    for c in range(cells.n_cells):
        if not math.isnan(out[c]):
            continue  # computed with the field that was chosen (more_tolerant)
        normals, offsets = cells.barrier(c)
        goal = cells.parent[cells.cell_node[c]] == -1
        z, x_j = cells.exit_dir[c], cells.exit_point[c]
        M, a = gain_field(gain[c], landmarks)
        m = field_margins(M, a, cells.vertices(c), z, x_j, normals, offsets, c_h[c], c_v[c], u_max)
        out[c] = cell_tolerance(M, normals, -m.cbf_rows, None if goal else z, None if goal else -m.clf)
    return out
