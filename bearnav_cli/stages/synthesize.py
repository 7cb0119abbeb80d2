"""``bearnav synthesize``: one robust LP per cell, giving a gain and its certificate (ALGORITHMS §5).

The LP (P) of §5.2 and its builders live in :mod:`bearnav_cli.cell_lp` (re-exported here);
this module solves it: SOLVE_CELL's κ loop (§5.3), the goal cell (§5.6), the gain recovery
and the run over all cells.

Every stored margin is recomputed at the vertices from the stored gain, and equals the
independent check :func:`vertex_margins` (ALGORITHMS §8). Per-cell building blocks
(:func:`solve_cell`, :func:`goal_cell_solution`, the LP builders) are public and need
no artifact; :func:`run` applies them to :class:`~bearnav_cli.datatypes.Cells` in three
passes (build every LP, solve them all, recover the gains), which keeps each kind of
code cache-warm.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bearnav_cli.cell_lp import (
    BOX_DIRECTIONS,
    COND_WARNING,
    FIELD_MAP,
    CellLp,
    CellProblem,
    LpTemplate,
    dual_lp,
    dual_template,
    field_map,
    gain_from_theta,
    gram_condition,
    landmark_matrix,
    min_norm_gain,
    theta_from_gain,
    vertex_lp,
    vertex_lp_field,
    vertex_lp_gain,
    vertex_template,
)
from bearnav_cli.datatypes import CellFlag, Cells, CellStatus, Plan
from bearnav_cli.errors import ArtifactError, InvalidParamsError
from bearnav_cli.lp import LpResult, LpSolver, LpStatus

__all__ = [
    "BOX_DIRECTIONS", "COND_WARNING", "DELTA_FRACTION", "FIELD_MAP", "GAIN_STRUCTURES", "LP_FORMS", "VERSION",
    "CellLp", "CellProblem", "CellSolution", "LpTemplate", "Margins", "Params", "PreparedCell", "SolveOutcome",
    "cell_constants", "dual_lp", "dual_template", "field_map", "finish_cell", "gain_from_theta", "goal_cell_solution",
    "gram_condition", "landmark_matrix", "min_norm_gain", "prepare_cell", "run", "solve_cell", "solve_prepared",
    "summary", "theta_from_gain", "vertex_lp", "vertex_lp_field", "vertex_lp_gain", "vertex_margins",
    "vertex_template",
]  # fmt: skip

VERSION = 1
log = logging.getLogger(__name__)

GAIN_STRUCTURES = ("full", "diag", "scalar")
LP_FORMS = ("vertex", "dual")
#: ``δ = DELTA_FRACTION · diam(X)`` floors the worst barrier violation in ``c_h`` (§5.3).
DELTA_FRACTION = 0.05


@dataclass(frozen=True)
class Params:
    """Parameters of the synthesis (ALGORITHMS §5).

    Attributes
    ----------
    u_max : float
        Input box ``|u_1|, |u_2| ≤ u_max`` (map units per second).
    kappa : float
        Initial ``κ_h = κ_v`` of the constants ``c_h``, ``c_v`` (§5.3).
    halvings : int
        How many times ``κ`` may be halved after an infeasible LP before the
        least-violation solve (so ``halvings + 1`` feasibility attempts).
    gain_structure : {"full", "diag", "scalar"}
        ``K_k`` any 2×2 matrix (solved in field space, minimum-norm gain by Lemma 3),
        diagonal, or a multiple of the identity (both solved in gain space).
    lp_form : {"vertex", "dual"}
        Constraints at the cell's vertices, or through LP duality (§5.2).
    w_h, w_v : float
        Objective weights of the CBF and CLF slacks.
    goal_tolerance : float or None
        Success radius around the goal (map units); ``None`` means ``0.01·D``.
    """

    u_max: float = 1.0
    kappa: float = 0.5
    halvings: int = 6
    gain_structure: str = "full"
    lp_form: str = "vertex"
    w_h: float = 1.0
    w_v: float = 1.0
    goal_tolerance: float | None = None

    def __post_init__(self) -> None:
        for name in ("u_max", "kappa", "w_h", "w_v", "goal_tolerance"):
            value = getattr(self, name)
            if value is None and name == "goal_tolerance":
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise InvalidParamsError(f"must be a finite number, got {value!r}", field=name)
            object.__setattr__(self, name, float(value))
        for name in ("u_max", "kappa"):
            if getattr(self, name) <= 0:
                raise InvalidParamsError(f"must be positive, got {getattr(self, name)}", field=name)
        for name in ("w_h", "w_v"):
            if getattr(self, name) < 0:
                raise InvalidParamsError(f"must be zero or positive, got {getattr(self, name)}", field=name)
        if self.goal_tolerance is not None and self.goal_tolerance <= 0:
            raise InvalidParamsError(f"must be positive, got {self.goal_tolerance}", field="goal_tolerance")
        if isinstance(self.halvings, bool) or not isinstance(self.halvings, int) or self.halvings < 0:
            raise InvalidParamsError(f"must be an integer of at least 0, got {self.halvings!r}", field="halvings")
        if self.gain_structure not in GAIN_STRUCTURES:
            raise InvalidParamsError(
                f"must be one of {', '.join(GAIN_STRUCTURES)}, got {self.gain_structure!r}", field="gain_structure"
            )
        if self.lp_form not in LP_FORMS:
            raise InvalidParamsError(f"must be one of {', '.join(LP_FORMS)}, got {self.lp_form!r}", field="lp_form")


# --------------------------------------------------------------------------- certificates


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
    vertices : ndarray, shape (p, 2)
    z, x_j : ndarray, shape (2,)
    cbf_n, cbf_q : ndarray, shapes (h, 2), (h,)
    c_h, c_v, u_max : float

    Returns
    -------
    Margins
    """
    K = np.asarray(K, float)
    landmarks = np.asarray(landmarks, float)
    V = np.asarray(vertices, float)
    cbf_n = np.asarray(cbf_n, float).reshape(-1, 2)
    a = K @ landmarks.ravel()
    M = K.reshape(2, -1, 2).sum(axis=1)
    U = a - V @ M.T  # u at each vertex, (p, 2)
    if len(cbf_n):
        values = -(U @ cbf_n.T + c_h * (V @ cbf_n.T + np.asarray(cbf_q, float)))
        rows = values.max(axis=0)
        cbf = float(rows.max())
    else:
        rows, cbf = np.zeros(0), math.nan
    clf = float(np.max(U @ z + c_v * ((V - x_j) @ z)))
    return Margins(cbf, rows, clf, float(np.abs(U).max() - u_max))


# --------------------------------------------------------------------------- one cell


@dataclass(frozen=True)
class CellSolution:
    """A cell's controller and certificate.

    Attributes
    ----------
    status : CellStatus
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


def cell_constants(problem: CellProblem, kappa: float, u_max: float) -> tuple[float, float]:
    """``(c_h, c_v)`` of §5.3: ``c_v = κ u_max / max_q V(v_q)``, ``c_h = κ u_max / max(δ, max −h)``.

    ``δ = 0.05·diam(X)``; ``c_h`` is NaN without barrier rows.

    Raises
    ------
    ArtifactError
        If ``V ≤ 0`` at every vertex (``z`` does not point into the cell).
    """
    V = problem.vertices
    h_values = problem.cbf_n @ V.T + problem.cbf_q[:, None]
    h_scale, v_scale = _constant_scales(V, h_values, (V - problem.x_j) @ problem.z)
    return kappa * u_max / h_scale, kappa * u_max / v_scale


def _constant_scales(V: np.ndarray, h_values: np.ndarray, v_values: np.ndarray) -> tuple[float, float]:
    """Denominators ``max(δ, max −h)`` (NaN without barrier rows) and ``max V`` of :func:`cell_constants`."""
    v_max = float(v_values.max())
    if not v_max > 0:
        raise ArtifactError("exit_dir does not point into the cell (V ≤ 0 at every vertex)", field="exit_dir")
    if h_values.size == 0:
        return math.nan, v_max
    diff = V[:, None, :] - V[None, :, :]
    diam = math.sqrt(float((diff * diff).sum(axis=2).max()))
    return max(DELTA_FRACTION * diam, -float(h_values.min())), v_max


@dataclass(frozen=True)
class PreparedCell:
    """A cell's LP templates and constant scales, built before any solve (see :func:`prepare_cell`).

    Attributes
    ----------
    problem : CellProblem
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
    """

    problem: CellProblem
    space: str
    L: np.ndarray
    checker: LpTemplate
    template: LpTemplate
    h_scale: float
    v_scale: float


@dataclass(frozen=True)
class SolveOutcome:
    """What the κ loop of :func:`solve_prepared` ended with."""

    status: CellStatus
    result: LpResult
    row_upper: np.ndarray  # of the checker's rows, with the final constants
    c_h: float
    c_v: float
    kappa: float
    attempts: int


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
    if params.lp_form == "vertex":
        template = checker
    else:
        template = dual_template(problem, L, params.u_max, params.w_h, params.w_v)
    h_scale, v_scale = _constant_scales(problem.vertices, checker.rhs_h, -checker.rhs_v)
    return PreparedCell(problem, space, L, checker, template, h_scale, v_scale)


def solve_prepared(prepared: PreparedCell, params: Params, solver: LpSolver) -> SolveOutcome:
    """SOLVE_CELL's loop (§5.3): halve ``κ`` while infeasible, then the least-violation LP."""
    u_max = params.u_max
    template = prepared.template
    status, attempts = CellStatus.SOLVER_FAILURE, 0
    for attempt in range(params.halvings + 1):
        kappa = params.kappa * 0.5**attempt
        c_h, c_v = kappa * u_max / prepared.h_scale, kappa * u_max / prepared.v_scale
        lp = template.instantiate(c_h, c_v)
        result = lp.solve(solver)
        attempts += 1
        if result.status is LpStatus.OPTIMAL:
            status = CellStatus.CERTIFIED if attempt == 0 else CellStatus.RELAXED
            break
        if result.status is not LpStatus.INFEASIBLE:
            break
    else:
        build = vertex_template if params.lp_form == "vertex" else dual_template
        lv = build(prepared.problem, prepared.L, u_max, params.w_h, params.w_v, least_violation=True)
        result = lv.instantiate(c_h, c_v).solve(solver)
        attempts += 1
        if result.status is LpStatus.OPTIMAL:
            status = CellStatus.NOT_CERTIFIED
    upper = lp.row_upper if template is prepared.checker else prepared.checker.row_upper(c_h, c_v)
    return SolveOutcome(status, result, upper, c_h, c_v, kappa, attempts)


def finish_cell(prepared: PreparedCell, outcome: SolveOutcome) -> CellSolution:
    """The gain of the solved LP (Lemma 3 in field space; zero after a failure) and its re-checked margins."""
    problem = prepared.problem
    status, result = outcome.status, outcome.result
    if result.status is LpStatus.OPTIMAL:
        K = gain_from_theta(prepared.space, result.x[: prepared.L.shape[2]], problem.landmarks)
    else:
        status, K = CellStatus.SOLVER_FAILURE, np.zeros((2, 2 * len(problem.landmarks)))
    margin_h, margin_v = _template_margins(prepared.checker, outcome.row_upper, prepared.space, K, problem.landmarks,
                                           len(problem.vertices))  # fmt: skip
    return CellSolution(status, K, outcome.c_h, outcome.c_v, margin_h, margin_v, outcome.attempts, outcome.kappa,
                        result.objective)  # fmt: skip


def solve_cell(problem: CellProblem, params: Params, solver: LpSolver) -> CellSolution:
    """SOLVE_CELL of ALGORITHMS §5.3 for one cell: prepare, solve, recover the gain, re-check.

    Parameters
    ----------
    problem : CellProblem
    params : Params
        ``u_max``, ``kappa``, ``halvings``, weights, gain structure and LP form.
    solver : LpSolver
        The run's reused solver.

    Returns
    -------
    CellSolution
        Status 0 (first attempt), 1 (after halvings), 2 (least violation) or 3 (unbounded
        or solver error: the gain is then zero). Margins are recomputed at the vertices
        from ``K`` (equal to :func:`vertex_margins`).
    """
    prepared = prepare_cell(problem, params)
    return finish_cell(prepared, solve_prepared(prepared, params, solver))


def _template_margins(checker: LpTemplate, upper: np.ndarray, space: str, K, landmarks, p) -> tuple[float, float]:
    """``max_k S_h,k`` and ``S_V`` of the gain ``K`` at the vertices, through the vertex rows of ``checker``.

    The field ``[M, a] = [K𝟙, Kℓ]`` (in gain space: ``K``'s free entries) is put into the rows
    ``d_gᵀu(v_q) ≤ r_g − ρ_gᵀv_q`` (right-hand sides ``upper``); the slack of group ``g`` is
    its largest excess over its ``p`` rows. The same numbers as :func:`vertex_margins`.
    """
    if space == "field":
        theta = np.empty((2, 3))
        theta[:, :2] = K.reshape(2, -1, 2).sum(axis=1)
        theta[:, 2] = K @ landmarks.ravel()
        theta = theta.ravel()
    else:
        theta = theta_from_gain(space, K)
    n_h = checker.n_h
    rows = (n_h + 1) * p
    excess = checker.vertex_rows[:rows] @ theta
    excess -= upper[:rows]
    worst = excess.reshape(n_h + 1, p).max(axis=1)
    return (float(worst[:n_h].max()) if n_h else math.nan), float(worst[n_h])


def goal_cell_solution(vertices: np.ndarray, goal: np.ndarray, landmarks: np.ndarray, cbf_n: np.ndarray,
                       cbf_q: np.ndarray, u_max: float) -> CellSolution:  # fmt: skip
    """The goal cell's straight-to-goal field ``u = c(g − x)`` (ALGORITHMS §5.6).

    ``c = u_max / max_q ‖g − v_q‖_∞``; ``c_h = c_v = c``; ``K = [cI, cg](GᵀG)⁻¹Gᵀ``;
    ``margin_h`` from the barrier rows at the vertices, ``margin_v`` NaN. Without barrier
    rows ``c_h`` and ``margin_h`` are NaN, as in every cell (§5.6, edge cases).

    Parameters
    ----------
    vertices : ndarray, shape (p, 2)
    goal : ndarray, shape (2,)
    landmarks : ndarray, shape (n, 2)
    cbf_n, cbf_q : ndarray, shapes (h, 2), (h,)
    u_max : float

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
    gain = np.zeros((C, 2, 2 * n_lm))
    c_h, c_v, margin_h, margin_v = (np.full(C, math.nan) for _ in range(4))
    status = np.zeros(C, np.int8)
    attempts = np.zeros(C, np.int64)
    started = time.perf_counter()
    # Three passes (build every LP, solve them all, then recover and re-check): each pass runs
    # one kind of code, which keeps it cache-warm; interleaving numpy and HiGHS per cell is slower.
    used, solutions, prepared = [], [None] * C, {}
    for c in range(C):
        used.append(np.flatnonzero(cells.cell_landmarks[c]))
        if len(used[c]) < 2:
            raise ArtifactError(f"cell {c} uses {len(used[c])} landmark(s); at least 2 needed", field="cell_landmarks")
        cbf_n, cbf_q = cells.barrier(c)
        node = cells.cell_node[c]
        if cells.parent[node] == -1:
            solutions[c] = goal_cell_solution(cells.vertices(c), cells.nodes[node], landmarks[used[c]], cbf_n, cbf_q,
                                              params.u_max)  # fmt: skip
            continue
        A, b = cells.rows(c)
        problem = CellProblem(cells.vertices(c), A, b, cells.exit_dir[c], cells.exit_point[c], cbf_n, cbf_q,
                              landmarks[used[c]])  # fmt: skip
        try:
            prepared[c] = prepare_cell(problem, params)
        except ArtifactError as exc:
            raise ArtifactError(f"cell {c}: {exc}", field=exc.field) from exc
    outcomes = {}
    report_every = max(1, len(prepared) // 100)
    for done, c in enumerate(prepared, 1):
        outcomes[c] = solve_prepared(prepared[c], params, solver)
        if progress is not None and (done % report_every == 0 or done == len(prepared)):
            progress(C - len(prepared) + done, C)
    for c, outcome in outcomes.items():
        solutions[c] = sol = finish_cell(prepared[c], outcome)
        if sol.status == CellStatus.NOT_CERTIFIED:
            log.warning("cell %d not certified: least-violation margins h %.3g, V %.3g", c, sol.margin_h, sol.margin_v)
        elif sol.status == CellStatus.SOLVER_FAILURE:
            log.warning("cell %d: solver failure (unbounded or error)", c)
    blocks = gain.reshape(C, 2, n_lm, 2)  # K_k of landmark k in columns 2k, 2k + 1
    for c, sol in enumerate(solutions):
        blocks[c][:, used[c], :] = sol.K.reshape(2, -1, 2)
        c_h[c], c_v[c], margin_h[c], margin_v[c] = sol.c_h, sol.c_v, sol.margin_h, sol.margin_v
        status[c], attempts[c] = int(sol.status), sol.attempts
    if progress is not None and not prepared:
        progress(C, C)
    elapsed = time.perf_counter() - started
    stats = _stats(cells, status, attempts, c_h, c_v, margin_v)
    stats["solve_ms_per_cell"] = round(1e3 * elapsed / C, 4)
    tolerance = params.goal_tolerance if params.goal_tolerance is not None else 0.01 * cells.map.diagonal
    return Plan(cells=cells, gain=gain, c_h=c_h, c_v=c_v, u_max=np.full(C, params.u_max), margin_h=margin_h,
                margin_v=margin_v, status=status, goal_tolerance=tolerance, stats=stats)  # fmt: skip


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
    stats["flagged"] = {
        f.name.lower(): cells.flagged(f) for f in CellFlag if f != CellFlag.NONE
    }
    stats["c_tilde_h"] = [_json_number(v) for v in tilde_h]
    stats["c_tilde_v"] = [_json_number(v) for v in tilde_v]
    stats["c_h_over_s_max"] = [_json_number(v) for v in h_over_max]
    stats["attempts"] = attempts.tolist()
    stats["lp_solves"] = int(attempts.sum())
    certified = (status == CellStatus.CERTIFIED) | (status == CellStatus.RELAXED)
    stats["zero_clf_margin"] = np.flatnonzero(certified & (margin_v > -1e-9)).tolist()
    return stats


def summary(plan: Plan) -> str:
    """One line: cells per status and flagged cells (deterministic: no timings)."""
    counts = {s: int(np.count_nonzero(plan.status == s)) for s in CellStatus}
    words = {CellStatus.CERTIFIED: "certified", CellStatus.RELAXED: "certified after relaxing",
             CellStatus.NOT_CERTIFIED: "not certified", CellStatus.SOLVER_FAILURE: "solver failures",
             CellStatus.GOAL: "goal"}  # fmt: skip
    text = f"{len(plan.status)} cells: " + ", ".join(f"{counts[s]} {words[s]}" for s in CellStatus)
    flags = plan.cells.cell_flags
    flagged = int(np.count_nonzero(flags))
    if flagged:
        parts = [f"{f.name.lower()} {np.count_nonzero(flags & f)}" for f in CellFlag if f and np.any(flags & f)]
        text += f"; {flagged} flagged cells ({', '.join(parts)})"
    return text
