"""``bearnav synthesize``: one robust LP per cell, giving a gain and its certificate (ALGORITHMS §5).

The LP (P) of §5.2 and its builders live in :mod:`bearnav_cli.cell_lp` (re-exported here);
this module solves it: SOLVE_CELL's κ loop (§5.3), the gain recovery and the run over all
cells. What needs no LP (the constants, the goal cell's field of §5.6, Lemma 6's field and
``δ_c``) is in :mod:`bearnav_cli.cell_fields`.

Every stored margin is recomputed at the vertices from the stored gain, and equals the
independent check :func:`~bearnav_cli.runtime.certificate.vertex_margins` (ALGORITHMS §8; to 1e-7: synthesize
re-checks through the LP's vertex rows, or every funnel cell's two fields at once). Per-cell building blocks
(:func:`solve_cell`, :func:`~bearnav_cli.cell_fields.goal_cell_solution`, the LP builders) are public and need
no artifact; :func:`run` applies them to :class:`~bearnav_cli.datatypes.Cells` in three
passes (build every LP, solve them all, recover the gains), which keeps each kind of
code cache-warm. With the full gain (field space) the build pass makes every cell's vertex
rows and constant scales in a few numpy passes over the flat ``Cells`` arrays
(:func:`~bearnav_cli.cell_lp.field_vertex_templates`); the LPs are the same bytes as
:func:`prepare_cell` builds one cell at a time. Every cell's first LP is built before the
solves, which run back to back (:meth:`~bearnav_cli.lp.LpSolver.solve_each`), and the gains
of Lemma 3 are recovered for all cells at once (:func:`~bearnav_cli.cell_lp.min_norm_gains`);
the numbers are those of the cell-by-cell functions.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from bearnav_cli import verdicts
from bearnav_cli.cell_fields import (
    CellSolution,
    batched_scales,
    cell_tolerances,
    checked_v_max,
    constant_scales,
    goal_cell_solution,
    grouped_gains,
    lemma4_terms,
    more_tolerant,
    more_tolerant_all,
)
from bearnav_cli.cell_lp import (
    FIELD_MAP,
    CellProblem,
    LpTemplate,
    dual_template,
    field_map,
    field_vertex_templates,
    gain_from_theta,
    theta_from_gain,
    vertex_template,
)
from bearnav_cli.datatypes import (
    CLAIMS_CERTIFICATE,
    CellFlag,
    Cells,
    CellStatus,
    Plan,
    cell_list,
    plural,
    tolerance_by_area,
)
from bearnav_cli.errors import ArtifactError
from bearnav_cli.funnel import plan_tolerance_of, usable_tolerances
from bearnav_cli.lp import LpResult, LpSolver, LpStatus
from bearnav_cli.params.synthesize import Params
from bearnav_cli.runtime.certificate import barrier_fault

__all__ = [
    "PreparedCell",
    "SolveOutcome",
    "VERSION",
    "finish_cell",
    "judged",
    "prepare_cell",
    "problems",
    "run",
    "solve_cell",
    "solve_prepared",
    "summary",
]

VERSION = 3
log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- one cell


@dataclass(frozen=True)
class PreparedCell:
    """A cell's LP templates and constant scales, built before any solve (see :func:`prepare_cell`).

    Attributes
    ----------
    problem : CellProblem
        The cell's data.
    space : str
        Variable space: ``field`` for the full gain, else the gain structure.
    L : ndarray, shape (2, 3, n_θ)
        The field map of ``space``.
    checker : LpTemplate
        The vertex-form template: solved when ``lp_form`` is ``vertex``; its rows re-check
        the gain at the vertices in every case.
    template : LpTemplate
        The template that is solved (``checker`` itself, or the dual form).
    h_scale, v_scale : float
        ``c_h = κ u_max / h_scale`` (NaN without barrier rows) and ``c_v = κ u_max / v_scale``.
    lemma4_terms : tuple of float, optional
        ``(min_k h_k(x_j), diam(P))`` when computed with the other cells'
        (:func:`~bearnav_cli.cell_fields.batched_scales`).
    """

    problem: CellProblem
    space: str
    L: np.ndarray
    checker: LpTemplate
    template: LpTemplate
    h_scale: float
    v_scale: float
    lemma4_terms: tuple[float, float] | None = None


@dataclass(frozen=True)
class SolveOutcome:
    """What the κ loop of :func:`solve_prepared` ended with.

    Attributes
    ----------
    status : CellStatus
        Certified (first ``κ``), relaxed (after halvings), not certified (the least-violation LP
        solved) or solver failure.
    result : LpResult
        The last LP solved.
    row_upper : ndarray, shape (m,)
        Upper row bounds of the checker's rows (:attr:`PreparedCell.checker`) with the final
        constants, for re-checking the gain at the vertices.
    c_h, c_v : float
        The final barrier and Lyapunov constants (1/s); ``c_h`` NaN without barrier rows.
    kappa : float
        The final ``κ``.
    attempts : int
        LPs solved, the least-violation solve included.
    lemma4_terms : tuple of float, optional
        Funnel cells: ``(min_k h_k(x_j), diam(P))`` of Lemma 4 (map units); None otherwise.
    """

    status: CellStatus
    result: LpResult
    row_upper: np.ndarray
    c_h: float
    c_v: float
    kappa: float
    attempts: int
    lemma4_terms: tuple[float, float] | None = None


def prepare_cell(problem: CellProblem, params: Params) -> PreparedCell:
    """Build a cell's LP templates and the denominators of its constants (no solve).

    Raises
    ------
    ArtifactError
        If ``z`` does not point into the cell.
    """
    space = "field" if params.gain_structure == "full" else params.gain_structure
    L = field_map(space, problem.landmarks)
    checker = vertex_template(problem, L, params.u_max, params.w_h, params.w_v)
    h_scale, v_scale = constant_scales(problem.vertices, checker.rhs_h, checker.rhs_v)
    return _prepared(problem, params, space, L, checker, h_scale, v_scale)


def _prepared(
    problem: CellProblem,
    params: Params,
    space: str,
    L: np.ndarray,
    checker: LpTemplate,
    h_scale: float,
    v_scale: float,
    lemma4_terms: tuple[float, float] | None = None,
) -> PreparedCell:
    """The :class:`PreparedCell` of a built checker: the solved template is the checker or the dual form."""
    if params.lp_form == "vertex":
        template = checker
    else:
        template = dual_template(problem, L, params.u_max, params.w_h, params.w_v)
    return PreparedCell(problem, space, L, checker, template, h_scale, v_scale, lemma4_terms)


def _kappa_lp(prepared: PreparedCell, params: Params, attempt: int, columns: tuple) -> tuple:
    """Attempt ``attempt`` of :func:`_kappa_sweep`: ``(κ, c_h, c_v, bounds)``, ``bounds`` the row and column
    bounds of its LP (the last four arguments of :meth:`LpSolver.solve`)."""
    kappa = params.kappa * 0.5**attempt
    c_h, c_v = kappa * params.u_max / prepared.h_scale, kappa * params.u_max / prepared.v_scale
    return (kappa, c_h, c_v, prepared.template.row_bounds(c_h, c_v) + tuple(columns))


def _kappa_sweep(
    prepared: PreparedCell, params: Params, solver: LpSolver, fixed: tuple, columns: tuple, first: tuple | None = None
) -> tuple:
    """Solve with ``κ, κ/2, …`` (``halvings`` times) until the LP is not infeasible.

    ``first`` is ``(attempt 0 of _kappa_lp, its result)`` when that LP is solved already. Returns the
    last result, its ``κ``, ``c_h``, ``c_v``, row upper bounds and the number of solves.
    """
    for attempt in range(params.halvings + 1):
        if attempt == 0 and first is not None:
            (kappa, c_h, c_v, bounds), result = first
        else:
            kappa, c_h, c_v, bounds = _kappa_lp(prepared, params, attempt, columns)
            result = solver.solve(*fixed, *bounds)
        if result.status is not LpStatus.INFEASIBLE:
            break
    return result, kappa, c_h, c_v, bounds[1], attempt + 1


#: A funnel cell halves ``κ`` at most this often looking for constants Lemma 4 covers (``κ·2⁻⁶⁰``).
FUNNEL_HALVINGS = 60


def _funnel_lp(prepared: PreparedCell, params: Params, halving: int, terms: tuple[float, float]) -> tuple:
    """Halving ``halving`` of :func:`_funnel_sweep`: ``(κ, c_h, c_v, bounds)``.

    ``terms`` are Lemma 4's ``(min_k h_k(x_j), diam(P))``; ``bounds`` are the row and column bounds
    of the LP (the last four arguments of :meth:`LpSolver.solve`), None when ``ε_max ≤ 0`` at
    this ``κ`` (no LP).
    """
    template, u_max = prepared.template, params.u_max
    n_theta, n_h = template.n_theta, template.n_h
    h_min, diam = terms
    kappa = params.kappa * 0.5**halving
    c_v = kappa * u_max / prepared.v_scale
    c_h = max(kappa * u_max / prepared.h_scale, c_v)
    eps = min(c_v * h_min, u_max - c_v * diam)  # lemma4_margin
    if not eps > 0:
        return kappa, c_h, c_v, None
    columns = template.col_upper.copy()
    columns[n_theta : n_theta + n_h] = -0.25 * eps
    strict = min(params.clf_margin * u_max, 0.25 * eps) if params.clf_margin > 0 else 0.25 * eps
    columns[n_theta + n_h] = -strict
    return kappa, c_h, c_v, template.row_bounds(c_h, c_v) + (template.col_lower, columns)


def _funnel_sweep(
    prepared: PreparedCell, params: Params, solver: LpSolver, fixed: tuple, first: tuple | None = None
) -> SolveOutcome:
    """ALGORITHMS §11.2 for a funnel cell: ``c_h ≥ c_v`` enforced and ``κ`` halved until Lemma 4 holds.

    The LP is then feasible with strict margins ``S_h,k ≤ −ε/4`` (every barrier row) and
    ``S_V ≤ −min(clf_margin·u_max, ε/4)`` (``ε = ε_max``), and maximises them as §5.2 weighs them.
    ``first`` is ``(halving 0 of _funnel_lp, its result)`` when that LP is solved already.
    """
    template, u_max = prepared.template, params.u_max
    result, upper, c_h, c_v, kappa, attempts = None, None, math.nan, math.nan, params.kappa, 0
    halving = 0
    # geometry: the same at every κ
    h_min, diam = prepared.lemma4_terms if prepared.lemma4_terms is not None else lemma4_terms(prepared.problem)
    for halving in range(FUNNEL_HALVINGS + 1):
        if halving == 0 and first is not None:
            (kappa, c_h, c_v, bounds), result = first
        else:
            kappa, c_h, c_v, bounds = _funnel_lp(prepared, params, halving, (h_min, diam))
            if bounds is None:
                continue
            result = solver.solve(*fixed, *bounds)
        upper = bounds[1]
        attempts += 1
        if result.status is LpStatus.OPTIMAL:
            break
    if result is not None and result.status is LpStatus.OPTIMAL:
        status = CellStatus.CERTIFIED if halving == 0 else CellStatus.RELAXED
        if template is not prepared.checker:
            upper = prepared.checker.row_upper(c_h, c_v)
        return SolveOutcome(status, result, upper, c_h, c_v, kappa, attempts, (h_min, diam))
    # Lemma 4 rules this out for a cell that meets (C2): a bug, or a cell whose exit point is not
    # strictly inside its rows. Store the least violation so verify can name the cell.
    log.error(
        "funnel cell not certifiable (Lemma 4 says this cannot happen): %s",
        "no κ gives ε > 0" if result is None else f"LP {result.status.name.lower()}",
    )
    build = vertex_template if params.lp_form == "vertex" else dual_template
    lv = build(prepared.problem, prepared.L, u_max, params.w_h, params.w_v, least_violation=True)
    result = lv.instantiate(c_h, c_v).solve(solver)
    status = CellStatus.NOT_CERTIFIED if result.status is LpStatus.OPTIMAL else CellStatus.SOLVER_FAILURE
    return SolveOutcome(status, result, prepared.checker.row_upper(c_h, c_v), c_h, c_v, kappa, attempts + 1)


def _strict_columns(prepared: PreparedCell, params: Params) -> np.ndarray:
    """Column upper bounds of §5.3's first CLF bound, ``S_V ≤ −clf_margin·u_max``, shape (n,)."""
    # A strictly negative CLF slack, S_V <= −clf_margin·u_max, leaves the field no equilibrium
    # in the cell and bounds the time to the exit face; a cell where no κ allows it is solved
    # again with S_V <= 0 (status 1, listed in stats.zero_clf_margin).
    template = prepared.template
    strict = template.col_upper.copy()
    strict[template.n_theta + template.n_h] = -params.clf_margin * params.u_max  # the S_V column
    return strict


def _first_attempt(prepared: PreparedCell, params: Params, funnel: bool) -> tuple | None:
    """The first LP :func:`solve_prepared` solves: ``(κ, c_h, c_v, bounds)`` of :func:`_funnel_lp` or
    :func:`_kappa_lp`; None for a funnel cell without an LP at the first ``κ`` (``ε_max ≤ 0``)."""
    if funnel:
        terms = prepared.lemma4_terms if prepared.lemma4_terms is not None else lemma4_terms(prepared.problem)
        attempt = _funnel_lp(prepared, params, 0, terms)
        return attempt if attempt[3] is not None else None
    return _kappa_lp(prepared, params, 0, (prepared.template.col_lower, _strict_columns(prepared, params)))


def solve_prepared(
    prepared: PreparedCell, params: Params, solver: LpSolver, funnel: bool = False, first: tuple | None = None
) -> SolveOutcome:
    """SOLVE_CELL's loop (§5.3): halve ``κ`` while infeasible, then the least-violation LP.

    Without ``funnel``, the CLF slack is first bounded by ``S_V ≤ −clf_margin·u_max`` and, when
    no ``κ`` allows that, by ``S_V ≤ 0``; a cell infeasible at every ``κ`` with either bound gets
    the least-violation LP.

    Parameters
    ----------
    prepared : PreparedCell
        The cell's templates and constant scales (:func:`prepare_cell`).
    params : Params
        ``u_max``, ``kappa``, ``halvings``, ``clf_margin``, weights and LP form.
    solver : LpSolver
        The run's reused solver.
    funnel : bool
        The cell is a funnel cell (ALGORITHMS §11.2): ``c_h ≥ c_v``, ``κ`` halved until Lemma 4
        holds, strict margins from ``ε_max``.
    first : tuple, optional
        ``(attempt, result)`` when the cell's first LP is solved already: ``attempt`` from
        :func:`_first_attempt`, ``result`` its :class:`LpResult`. The loop goes on from there.

    Returns
    -------
    SolveOutcome
    """
    u_max = params.u_max
    template = prepared.template
    # Only the row bounds change between attempts: the template's own arrays go to the solver
    # as they are, without a CellLp per attempt.
    fixed = (template.cost, template.A_indptr, template.A_indices, template.A_values)
    if funnel:
        return _funnel_sweep(prepared, params, solver, fixed, first)
    bounds = [(template.col_lower, _strict_columns(prepared, params))]
    if params.clf_margin > 0:
        bounds.append((template.col_lower, template.col_upper))
    attempts = 0
    for columns in bounds:
        result, kappa, c_h, c_v, upper, tries = _kappa_sweep(prepared, params, solver, fixed, columns, first)
        first = None  # the first LP is the strict bound's
        attempts += tries
        if result.status is not LpStatus.INFEASIBLE:  # optimal, or a failure relaxing cannot mend
            break
    if result.status is LpStatus.OPTIMAL:
        status = CellStatus.CERTIFIED if attempts == 1 else CellStatus.RELAXED
    else:
        status = CellStatus.SOLVER_FAILURE
    if result.status is LpStatus.INFEASIBLE:  # at every κ with either CLF bound: the least violation
        build = vertex_template if params.lp_form == "vertex" else dual_template
        lv = build(prepared.problem, prepared.L, u_max, params.w_h, params.w_v, least_violation=True)
        result = lv.instantiate(c_h, c_v).solve(solver)
        attempts += 1
        if result.status is LpStatus.OPTIMAL:
            status = CellStatus.NOT_CERTIFIED
    if template is not prepared.checker:
        upper = prepared.checker.row_upper(c_h, c_v)
    return SolveOutcome(status, result, upper, c_h, c_v, kappa, attempts)


def finish_cell(
    prepared: PreparedCell, outcome: SolveOutcome, recheck: bool = True, K: np.ndarray | None = None
) -> CellSolution:
    """The gain of the solved LP (Lemma 3 in field space; zero after a failure) and its re-checked margins.

    Parameters
    ----------
    prepared : PreparedCell
        The cell that was solved.
    outcome : SolveOutcome
        What :func:`solve_prepared` ended with; a non-optimal LP turns the status into solver
        failure with a zero gain.
    recheck : bool
        Re-check the margins at the vertices through the checker's rows. False leaves them NaN
        for a certified or relaxed cell, for :func:`~bearnav_cli.cell_fields.more_tolerant_all`, which re-checks every
        cell's field at its vertices in one pass.
    K : ndarray, shape (2, 2n), optional
        The gain of the optimal LP's variables when already recovered (:func:`run` recovers
        those of field space for all cells at once); None: recovered here.

    Returns
    -------
    CellSolution
        ``tolerance`` NaN (only :func:`~bearnav_cli.cell_fields.more_tolerant` sets it).
    """
    problem = prepared.problem
    status, result = outcome.status, outcome.result
    if result.status is LpStatus.OPTIMAL:
        if K is None:
            K = gain_from_theta(prepared.space, result.x[: prepared.L.shape[2]], problem.landmarks)
    else:
        status, K = CellStatus.SOLVER_FAILURE, np.zeros((2, 2 * len(problem.landmarks)))
    margin_h = margin_v = math.nan
    if recheck or status not in (CellStatus.CERTIFIED, CellStatus.RELAXED):
        margin_h, margin_v = _template_margins(
            prepared.checker, outcome.row_upper, prepared.space, K, problem.landmarks, len(problem.vertices)
        )
    return CellSolution(
        status, K, outcome.c_h, outcome.c_v, margin_h, margin_v, outcome.attempts, outcome.kappa, result.objective
    )


def solve_cell(problem: CellProblem, params: Params, solver: LpSolver, funnel: bool = False) -> CellSolution:
    """SOLVE_CELL of ALGORITHMS §5.3 (``funnel``: §11.2) for one cell: prepare, solve, recover the gain, re-check.

    Parameters
    ----------
    problem : CellProblem
        The cell's data.
    params : Params
        ``u_max``, ``kappa``, ``halvings``, weights, gain structure and LP form.
    solver : LpSolver
        The run's reused solver.
    funnel : bool
        A funnel cell (its barrier rows are its own non-exit rows): Lemma 4's κ sweep and strict
        margins, then (``params.tolerant``) the more tolerant of the LP's and Lemma 4's fields, as
        :func:`run` does.

    Returns
    -------
    CellSolution
        Status 0 (first attempt), 1 (after halvings), 2 (least violation, or barrier rows that
        cannot carry a certificate: :func:`judged`) or 3 (unbounded or solver error: the gain is
        then zero). Margins are recomputed at the vertices from ``K`` (equal to
        :func:`~bearnav_cli.runtime.certificate.vertex_margins`).
    """
    prepared = prepare_cell(problem, params)
    solution = finish_cell(prepared, solve_prepared(prepared, params, solver, funnel=funnel))
    solution, fault = judged(solution, problem.cbf_n, problem.cbf_q, problem.x_j)
    if fault is not None:
        log.warning("cell not certified: %s", fault)
    certified = solution.status in (CellStatus.CERTIFIED, CellStatus.RELAXED)
    if funnel and params.tolerant and certified:
        return more_tolerant(solution, problem, params.u_max)
    return solution


def judged(
    solution: CellSolution, cbf_n: np.ndarray, cbf_q: np.ndarray, x_j: np.ndarray | None
) -> tuple[CellSolution, str | None]:
    """``solution``, not certified (status 2, the gain kept) when its cell's barrier rows cannot carry a
    certificate, and why: ``verify``'s judgement of the rows, :func:`~bearnav_cli.runtime.certificate.barrier_fault`.

    The LP's conditions hold at the vertices whatever the rows are; the rows themselves are what
    ``verify`` refutes (the paper's wedge with its apex at ``x_j``, ``cbf_apex=parent``, is zero
    there), so a cell with such rows is never certified.

    Parameters
    ----------
    solution : CellSolution
        The cell's solution; one that claims no certificate is returned as it is.
    cbf_n, cbf_q : ndarray, shapes (h, 2), (h,)
        The cell's barrier rows.
    x_j : ndarray, shape (2,), or None
        The edge's parent node; None for the goal cell.

    Returns
    -------
    tuple of CellSolution and (str or None)
        The solution, and the fault that took its certificate away (None: none did).
    """
    if solution.status not in CLAIMS_CERTIFICATE:
        return solution, None
    fault = barrier_fault(cbf_n, cbf_q, x_j)
    return (solution, None) if fault is None else (replace(solution, status=CellStatus.NOT_CERTIFIED), fault)


def _template_margins(checker: LpTemplate, upper: np.ndarray, space: str, K, landmarks, p) -> tuple[float, float]:
    """``max_k S_h,k`` and ``S_V`` of the gain ``K`` at the vertices, through the vertex rows of ``checker``.

    The field ``[M, a] = [K𝟙, Kℓ]`` (in gain space: ``K``'s free entries) is put into the rows
    ``d_gᵀu(v_q) ≤ r_g − ρ_gᵀv_q`` (right-hand sides ``upper``); the slack of group ``g`` is
    its largest excess over its ``p`` rows. The same numbers as
    :func:`~bearnav_cli.runtime.certificate.vertex_margins` (to rounding).
    """
    if space == "field":
        theta = np.empty((2, 3))
        theta[:, :2] = K.reshape(2, -1, 2).sum(axis=1)
        theta[:, 2] = K @ landmarks.ravel()
        theta = theta.ravel()
    else:
        theta = theta_from_gain(space, K)
    n_h = checker.n_h
    excess = checker.vertex_rows @ theta
    excess -= upper[: len(excess)]
    # Python's max of the n_h + 1 group maxima: the same numbers (all finite), fewer numpy calls.
    worst = excess.reshape(n_h + 1, p).max(axis=1).tolist()
    return (max(worst[:n_h]) if n_h else math.nan), worst[n_h]


# --------------------------------------------------------------------------- the stage


def _json_number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def run(cells: Cells, params: Params = Params(), progress: Callable[[int, int], None] | None = None) -> Plan:
    """Synthesise and certify one controller per cell.

    Parameters
    ----------
    cells : Cells
        The decomposition; cell ``c`` with ``parent[cell_node[c]] == -1`` is the goal cell.
    params : Params
        ``u_max``, ``kappa``, ``halvings``, weights, gain structure, LP form, ``clf_margin``,
        ``goal_tolerance`` and ``tolerant``.
    progress : callable, optional
        ``progress(done, total)`` about a hundred times while the LPs are solved (``total = C``;
        goal cells count as done from the start).

    Returns
    -------
    Plan
        Gains (C, 2, 2L), constants, recomputed margins and statuses.

    Raises
    ------
    ArtifactError
        A cell with fewer than two landmarks or an exit direction that does not point into it.
    """
    solver = LpSolver()
    landmarks = cells.map.landmarks
    C, n_lm = cells.n_cells, len(landmarks)
    started = time.perf_counter()
    # Three passes (build every LP, solve them all, then recover and re-check): each pass runs
    # one kind of code, which keeps it cache-warm; interleaving numpy and HiGHS per cell is slower.
    solutions, prepared = [None] * C, {}
    # Per-cell slices of the flat Cells arrays (DESIGN §3.2) from Python offsets: cheaper than
    # the accessors' numpy-scalar indexing, and the same views.
    vo, ro, ho = cells.cell_vertex_offsets.tolist(), cells.cell_row_offsets.tolist(), cells.cbf_offsets.tolist()
    lm_cell, lm_index = np.nonzero(cells.cell_landmarks)  # row-major: each cell's landmarks in increasing order
    lo = np.zeros(C + 1, np.int64)
    np.cumsum(np.bincount(lm_cell, minlength=C), out=lo[1:])
    lo = lo.tolist()
    cell_landmarks = landmarks[lm_index]  # cell c's landmarks are rows lo[c]:lo[c + 1]
    goal_mask = cells.parent[cells.cell_node] == -1
    is_goal = goal_mask.tolist()
    built = None
    if params.gain_structure == "full":  # field space: every cell's vertex rows in one numpy pass
        edge = np.flatnonzero(~goal_mask).tolist()
        built = field_vertex_templates(
            cells.cell_vertices,
            cells.cell_vertex_offsets,
            cells.cbf_A,
            cells.cbf_b,
            cells.cbf_offsets,
            cells.exit_dir,
            cells.exit_point,
            edge,
            params.u_max,
            params.w_h,
            params.w_v,
        )
        scales = batched_scales(cells, built, edge)
    for c in range(C):
        if lo[c + 1] - lo[c] < 2:
            raise ArtifactError(
                f"cell {c} uses {lo[c + 1] - lo[c]} landmark(s); at least 2 needed", field="cell_landmarks"
            )
        vertices, used = cells.cell_vertices[vo[c] : vo[c + 1]], cell_landmarks[lo[c] : lo[c + 1]]
        cbf_n, cbf_q = cells.cbf_A[ho[c] : ho[c + 1]], cells.cbf_b[ho[c] : ho[c + 1]]
        if is_goal[c]:
            solutions[c] = goal_cell_solution(
                vertices, cells.nodes[cells.cell_node[c]], used, cbf_n, cbf_q, params.u_max
            )
            continue
        problem = CellProblem(
            vertices,
            cells.cell_A[ro[c] : ro[c + 1]],
            cells.cell_b[ro[c] : ro[c + 1]],
            cells.exit_dir[c],
            cells.exit_point[c],
            cbf_n,
            cbf_q,
            used,
        )
        try:
            if built is None:
                prepared[c] = prepare_cell(problem, params)
            else:
                h_scale, v_max, terms = scales[c]
                prepared[c] = _prepared(
                    problem, params, "field", FIELD_MAP, built.templates[c], h_scale, checked_v_max(v_max), terms
                )
        except ArtifactError as exc:
            raise ArtifactError(f"cell {c}: {exc}", field=exc.field) from exc
    outcomes = _solve_all(prepared, params, solver, cells.is_funnel, progress, C)
    tolerant = cells.is_funnel and params.tolerant  # more_tolerant_all re-checks those cells' margins
    gains = {}
    if built is not None:  # field space: Lemma 3's gains of every optimal LP at once (gain_from_theta)
        optimal = [c for c, outcome in outcomes.items() if outcome.result.status is LpStatus.OPTIMAL]
        rows, width, n_theta = FIELD_MAP.shape  # θ holds the field [M | a] row by row
        theta = np.array([outcomes[c].result.x[:n_theta] for c in optimal]).reshape(-1, rows, width)
        fields = np.zeros((C, rows, width))
        fields[optimal] = theta
        gains = grouped_gains(
            fields[:, :, :2], fields[:, :, 2], [cell_landmarks[lo[c] : lo[c + 1]] for c in range(C)], optimal
        )
    for c, outcome in outcomes.items():
        solutions[c] = sol = finish_cell(prepared[c], outcome, recheck=not tolerant, K=gains.get(c))
        if sol.status == CellStatus.NOT_CERTIFIED:
            log.warning("cell %d not certified: least-violation margins h %.3g, V %.3g", c, sol.margin_h, sol.margin_v)
        elif sol.status == CellStatus.SOLVER_FAILURE:
            log.warning("cell %d: solver failure (unbounded or error)", c)
    faults = {}  # verify's judgement of the barrier rows, before any cell counts as certified
    for c in range(C):
        j = cells.parent[cells.cell_node[c]]
        solutions[c], fault = judged(
            solutions[c],
            cells.cbf_A[ho[c] : ho[c + 1]],
            cells.cbf_b[ho[c] : ho[c + 1]],
            cells.nodes[j] if j >= 0 else None,
        )
        if fault is not None:
            faults[c] = fault
    if faults:
        first = min(faults)
        log.warning(
            "%s not certified, their barrier rows unfit for a certificate (cell %d: %s): %s",
            plural(len(faults), "cell"),
            first,
            faults[first],
            cell_list(sorted(faults)),
        )
    if tolerant:
        chosen = [c for c in outcomes if solutions[c].status in (CellStatus.CERTIFIED, CellStatus.RELAXED)]
        picked = more_tolerant_all(
            [solutions[c] for c in chosen],
            [prepared[c].problem for c in chosen],
            params.u_max,
            [outcomes[c].lemma4_terms for c in chosen],
        )
        for c, sol in zip(chosen, picked, strict=True):
            solutions[c] = sol
    gain = np.zeros((C, 2, 2 * n_lm))
    if C:  # K_k of landmark k in columns 2k, 2k + 1: every cell's blocks in one scatter
        blocks = np.concatenate([sol.K.reshape(2, -1, 2) for sol in solutions], axis=1)  # (2, Σ n_c, 2)
        gain.reshape(C, 2, n_lm, 2)[lm_cell, :, lm_index, :] = blocks.transpose(1, 0, 2)
    c_h, c_v, margin_h, margin_v = (
        np.array([getattr(sol, name) for sol in solutions], float) for name in ("c_h", "c_v", "margin_h", "margin_v")
    )
    status = np.array([int(sol.status) for sol in solutions], np.int8)
    attempts = np.array([sol.attempts for sol in solutions], np.int64)
    if progress is not None and not prepared:
        progress(C, C)
    elapsed = time.perf_counter() - started
    stats = _stats(cells, status, attempts, c_h, c_v, margin_v)
    stats["solve_ms_per_cell"] = round(1e3 * elapsed / C, 4)
    if "barrier_margin" in (cells.stats or {}):  # the m of F_m, for verify (plan.npz has no key for it)
        stats["barrier_margin"] = cells.stats["barrier_margin"]
    goal_tolerance = params.goal_tolerance if params.goal_tolerance is not None else 0.01 * cells.map.diagonal
    delta = np.full(C, np.nan)
    plan_tolerance = math.nan
    if cells.is_funnel:
        known = np.array([sol.tolerance for sol in solutions], float)
        delta = cell_tolerances(cells, gain, c_h, c_v, params.u_max, known)
        usable = usable_tolerances(delta, cells.exit_inset)
        plan_tolerance = plan_tolerance_of(usable)
        stats["plan_tolerance"] = _json_number(plan_tolerance)
        stats["tolerance_limited_by"] = int(np.nanargmin(usable)) if np.isfinite(usable).any() else None
        stats["constant_field_cells"] = np.flatnonzero(delta == np.inf).tolist()
    else:
        usable = np.full(C, np.nan)
    return Plan(
        cells=cells,
        gain=gain,
        c_h=c_h,
        c_v=c_v,
        u_max=np.full(C, params.u_max),
        margin_h=margin_h,
        margin_v=margin_v,
        status=status,
        goal_tolerance=goal_tolerance,
        tolerance=delta,
        usable_tolerance=usable,
        plan_tolerance=plan_tolerance,
        stats=stats,
    )


def _solve_all(
    prepared: dict, params: Params, solver: LpSolver, funnel: bool, progress: Callable[[int, int], None] | None, C: int
) -> dict:
    """:func:`solve_prepared` of every prepared cell in order (``{cell: SolveOutcome}``); ``progress(done, C)``
    about a hundred times, goal cells counted as done.

    Every cell's first LP (:func:`_first_attempt`) is built first, and runs of them go to
    :meth:`LpSolver.solve_each` together, up to the next progress report: the solves run back to
    back, which saves most of the cost of work between two HiGHS runs. A cell whose first LP is
    not optimal is finished (its further LPs solved) before the next cell's LP, so the solver
    sees the LPs in the order of a cell-by-cell loop.
    """
    order = list(prepared)
    attempts = [_first_attempt(prepared[c], params, funnel) for c in order]
    problems = []  # the arguments of LpSolver.solve of each first LP
    for c, attempt in zip(order, attempts, strict=True):
        t = prepared[c].template
        problems.append(None if attempt is None else (t.cost, t.A_indptr, t.A_indices, t.A_values) + attempt[3])
    gap = [len(order)] * (len(order) + 1)  # gap[i]: the first cell from i on without a first LP
    for i in range(len(order) - 1, -1, -1):
        gap[i] = i if problems[i] is None else gap[i + 1]
    report_every = max(1, len(order) // 100)
    outcomes, done = {}, 0
    while done < len(order):
        stop = min(len(order), (done // report_every + 1) * report_every) if progress is not None else len(order)
        results = solver.solve_each(problems[done : min(stop, gap[done])]) if gap[done] > done else []
        for i, result in enumerate(results, done):
            outcomes[order[i]] = solve_prepared(prepared[order[i]], params, solver, funnel, (attempts[i], result))
        end = done + len(results)
        if not results:  # a funnel cell whose first κ gives no LP
            outcomes[order[end]] = solve_prepared(prepared[order[end]], params, solver, funnel)
            end += 1
        if progress is not None:
            for d in range(done + 1, end + 1):
                if d % report_every == 0 or d == len(order):
                    progress(C - len(order) + d, C)
        done = end
    return outcomes


def _stats(cells: Cells, status, attempts, c_h, c_v, margin_v) -> dict:
    """JSON-safe statistics: counts per status, flagged cells, bearing constants, attempts.

    ``zero_clf_margin`` lists certified cells whose CLF margin is 0 (to 1e-9): there
    ``V̇ ≤ −c_v V`` only, so ``V`` decays exponentially but the exit line is not reached in a
    bounded time (§4.4 needs ``S_V < 0``); the objective traded that margin for CBF margin.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        tilde_h = c_h / cells.s_min
        tilde_v = c_v / cells.s_max
        h_over_max = c_h / cells.s_max
    stats: dict = {"cells": int(cells.n_cells)}
    stats["status_counts"] = {s.name.lower(): int(np.count_nonzero(status == s)) for s in CellStatus}
    stats["flagged"] = {f.name.lower(): cells.flagged(f) for f in CellFlag if f != CellFlag.NONE}
    stats["c_tilde_h"] = [_json_number(v) for v in tilde_h]
    stats["c_tilde_v"] = [_json_number(v) for v in tilde_v]
    stats["c_h_over_s_max"] = [_json_number(v) for v in h_over_max]
    stats["attempts"] = attempts.tolist()
    stats["lp_solves"] = int(attempts.sum())
    certified = (status == CellStatus.CERTIFIED) | (status == CellStatus.RELAXED)
    stats["zero_clf_margin"] = np.flatnonzero(certified & (margin_v > -1e-9)).tolist()
    return stats


def summary(plan: Plan) -> str:
    """One line: cells per status, the certified tolerance and flagged cells (deterministic: no timings)."""
    counts = {s: int(np.count_nonzero(plan.status == s)) for s in CellStatus}
    words = {
        CellStatus.CERTIFIED: "certified",
        CellStatus.RELAXED: "certified after relaxing",
        CellStatus.NOT_CERTIFIED: "not certified",
        CellStatus.SOLVER_FAILURE: "solver failures",
        CellStatus.GOAL: "goal",
    }
    text = f"{len(plan.status)} cells: " + ", ".join(f"{counts[s]} {words[s]}" for s in CellStatus)
    if plan.cells.is_funnel:
        by_area = tolerance_by_area(plan.cells, plan.usable_tolerance)
        text += (
            f"; funnel certificate: a position error of {plan.plan_tolerance:.3g} tolerated everywhere "
            f"({by_area['median']:.3g} at the median point, under {by_area['p10']:.3g} on 10% of the area), "
            f"{100 * plan.cells.free_coverage:.1f}% of the free space covered"
        )
    flags = plan.cells.cell_flags
    if plan.cells.is_funnel:  # harmless for the funnel certificate (docs/cli.md "Words"): no alarm to print
        flags = flags & ~CellFlag.DEGENERATE_RISK
    flagged = int(np.count_nonzero(flags))
    if flagged:
        parts = [f"{f.name.lower()} {np.count_nonzero(flags & f)}" for f in CellFlag if f and np.any(flags & f)]
        text += f"; {flagged} flagged cells ({', '.join(parts)})"
    return text


def problems(plan: Plan) -> list[verdicts.Problem]:
    """Why the plan is not usable (a list of :class:`~bearnav_cli.verdicts.Problem`, worst first): its cells'
    problems (no route, blind spots), then the cells not certified (status 2 or 3)."""
    return verdicts.cell_problems(plan.cells) + verdicts.not_certified(plan.status)
