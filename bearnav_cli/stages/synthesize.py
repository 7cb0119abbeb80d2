"""``bearnav synthesize``: one robust LP per cell, giving a gain and its certificate (ALGORITHMS §5).

The LP (P) of §5.2 and its builders live in :mod:`bearnav_cli.cell_lp` (re-exported here);
this module solves it: SOLVE_CELL's κ loop (§5.3), the goal cell (§5.6), the gain recovery
and the run over all cells.

Every stored margin is recomputed at the vertices from the stored gain, and equals the
independent check :func:`vertex_margins` (ALGORITHMS §8). Per-cell building blocks
(:func:`solve_cell`, :func:`goal_cell_solution`, the LP builders) are public and need
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
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from bearnav_cli.cell_lp import (
    FIELD_MAP,
    CellProblem,
    FieldTemplates,
    LpTemplate,
    dual_template,
    field_map,
    field_vertex_templates,
    gain_from_theta,
    min_norm_gain,
    min_norm_gains,
    theta_from_gain,
    vertex_template,
)
from bearnav_cli.datatypes import CellFlag, Cells, CellStatus, Plan, tolerance_by_area
from bearnav_cli.errors import ArtifactError, InvalidParamsError
from bearnav_cli.funnel import cell_tolerance, exit_sinks, plan_tolerance_of, usable_tolerances
from bearnav_cli.lp import LpResult, LpSolver, LpStatus

__all__ = [
    "CellSolution", "DELTA_FRACTION", "GAIN_STRUCTURES", "LP_FORMS", "Margins", "Params", "PreparedCell",
    "SolveOutcome", "VERSION", "cell_constants", "field_margins", "finish_cell", "goal_cell_solution",
    "prepare_cell", "run", "solve_cell", "solve_prepared", "summary", "vertex_margins",
]  # fmt: skip

VERSION = 3
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
        Initial scale of the rates in each cell's barrier and exit conditions, halved while the LP
        is infeasible. It is ``κ_h = κ_v`` of the constants ``c_h``, ``c_v`` (§5.3).
    halvings : int
        How many times ``kappa`` may be halved after an infeasible LP before the
        least-violation solve (so ``halvings + 1`` feasibility attempts).
    gain_structure : {"full", "diag", "scalar"}
        The controller gain of each cell: any 2×2 matrix, diagonal, or a multiple of the identity.
        ``full`` is solved in field space (the minimum-norm gain ``K_k`` by Lemma 3), the others in
        gain space.
    lp_form : {"vertex", "dual"}
        Constraints at the cell's vertices, or through LP duality (§5.2).
    w_h, w_v : float
        Objective weights of the CBF and CLF slacks.
    clf_margin : float
        The CLF slack must satisfy ``S_V <= −clf_margin·u_max`` (a finite-time exit and no
        equilibrium in the cell); ``0`` is ALGORITHMS §5.2 as written. A cell that cannot
        meet it at any κ is solved with ``S_V <= 0`` and gets status 1.
    goal_tolerance : float or None
        Success radius around the goal (map units); ``None`` means ``0.01·D``.
    tolerant : bool
        Funnel cells: keep whichever of two fields tolerates the larger position error, the LP's or
        one that heads straight for the exit point (ALGORITHMS §11.4). The second is Lemma 4's
        field ``c_v(x_j − x) − εz`` (``ε`` chosen for the largest tolerance ``δ_c``). The LP
        maximises the sum of its margins, which leaves ``δ_c`` at a fraction of a millimetre on
        the example maps; Lemma 4's field tolerates half the depth of
        ``x_j`` in the cell. ``False``: the LP's field always.
    """

    u_max: float = 1.0
    kappa: float = 0.5
    halvings: int = 6
    gain_structure: str = "full"
    lp_form: str = "vertex"
    w_h: float = 1.0
    w_v: float = 1.0
    clf_margin: float = 0.01
    goal_tolerance: float | None = None
    tolerant: bool = True

    def __post_init__(self) -> None:
        for name in ("u_max", "kappa", "w_h", "w_v", "clf_margin", "goal_tolerance"):
            value = getattr(self, name)
            if value is None and name == "goal_tolerance":
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise InvalidParamsError(f"must be a finite number, got {value!r}", field=name)
            object.__setattr__(self, name, float(value))
        for name in ("u_max", "kappa"):
            if getattr(self, name) <= 0:
                raise InvalidParamsError(f"must be positive, got {getattr(self, name)}", field=name)
        for name in ("w_h", "w_v", "clf_margin"):
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
        if not isinstance(self.tolerant, bool):
            raise InvalidParamsError(f"must be true or false, got {self.tolerant!r}", field="tolerant")
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
        Positions of the landmarks ``K`` reads (map units).
    vertices : ndarray, shape (p, 2)
        The cell's vertices ``v_q`` (map units).
    z, x_j : ndarray, shape (2,)
        Unit exit direction (into the cell) and exit point (map units): ``V(x) = zᵀ(x − x_j)``.
    cbf_n, cbf_q : ndarray, shapes (h, 2), (h,)
        Barrier rows ``h_k(x) = n_kᵀx + q_k``; there may be none.
    c_h, c_v : float
        Barrier and Lyapunov constants (1/s).
    u_max : float
        Input bound (map units/s).

    Returns
    -------
    Margins
    """
    K = np.asarray(K, float)
    landmarks = np.asarray(landmarks, float)
    return field_margins(K.reshape(2, -1, 2).sum(axis=1), K @ landmarks.ravel(), vertices, z, x_j, cbf_n, cbf_q,
                         c_h, c_v, u_max)  # fmt: skip


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


# --------------------------------------------------------------------------- one cell


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
    h_scale, v_scale = _constant_scales(V, h_values, (problem.x_j - V) @ problem.z)
    return kappa * u_max / h_scale, kappa * u_max / v_scale


def _constant_scales(V: np.ndarray, h_values: np.ndarray, minus_v: np.ndarray) -> tuple[float, float]:
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
    v_max = _checked_v_max(-float(minus_v.min()))
    if h_values.size == 0:
        return math.nan, v_max
    diff = V[:, None, :] - V  # (p, p, 2); the squared distances are d₀² + d₁², the order a sum over axis 2 uses
    diff *= diff
    diam = math.sqrt(float((diff[..., 0] + diff[..., 1]).max()))
    return max(DELTA_FRACTION * diam, -float(h_values.min())), v_max


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
        ``(min_k h_k(x_j), diam(P))`` when computed with the other cells' (:func:`_batched_scales`).
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


def _checked_v_max(v_max: float) -> float:
    """``max_q V(v_q)``, which must be positive (``c_v`` divides by it)."""
    if not v_max > 0:
        raise ArtifactError("exit_dir does not point into the cell (V ≤ 0 at every vertex)", field="exit_dir")
    return v_max


def _batched_scales(cells: Cells, built: FieldTemplates, which: list[int]) -> dict[int, tuple[float, float, tuple]]:
    """``(h_scale, max V, (min_k h_k(x_j), diam))`` of :func:`_constant_scales` and :func:`_lemma4_terms`
    for the cells ``which``, in a few numpy passes.

    The same numbers: minima and maxima are exact in any grouping, the squared distances are
    the same ``d₀² + d₁²`` (cells grouped by vertex count, so no padding), and ``np.sqrt`` rounds
    as ``math.sqrt`` does. ``max V`` is not checked here (see :func:`_checked_v_max`).
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
    for c in which:  # the Python max of _constant_scales, on the same two floats
        h_scale = max(DELTA_FRACTION * diam_list[c], -h_min_list[c]) if n_h_list[c] else math.nan
        out[c] = (h_scale, v_max[c], (exit_list[c], diam_list[c]))
    return out


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
    h_scale, v_scale = _constant_scales(problem.vertices, checker.rhs_h, checker.rhs_v)
    return _prepared(problem, params, space, L, checker, h_scale, v_scale)


def _prepared(problem: CellProblem, params: Params, space: str, L: np.ndarray, checker: LpTemplate, h_scale: float,
              v_scale: float, lemma4_terms: tuple[float, float] | None = None) -> PreparedCell:  # fmt: skip
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


def _kappa_sweep(prepared: PreparedCell, params: Params, solver: LpSolver, fixed: tuple, columns: tuple,
                 first: tuple | None = None) -> tuple:  # fmt: skip
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


def lemma4_margin(problem: CellProblem, c_v: float, u_max: float) -> float:
    """``ε_max = min(c·min_k h_k(x_j), u_max − c·diam(P))`` of ALGORITHMS §11.2 (Lemma 4) with ``c = c_v``.

    When positive, the field ``c(x_j − x) − εz`` with ``0 < ε < ε_max`` meets (L1)–(L3) with
    margins of at least ``min(ε, ε_max − ε)``; the LP's strict margin bounds are set from it.
    """
    h_min, diam = _lemma4_terms(problem)
    return min(c_v * h_min, u_max - c_v * diam)


def _lemma4_terms(problem: CellProblem) -> tuple[float, float]:
    """``min_k h_k(x_j)`` and ``diam(P)`` of a cell (map units), the two geometric terms of Lemma 4."""
    V = problem.vertices
    diff = V[:, None, :] - V
    diam = math.sqrt(float((diff * diff).sum(axis=2).max()))
    h_min = float(np.min(problem.cbf_n @ problem.x_j + problem.cbf_q)) if len(problem.cbf_q) else math.inf
    return h_min, diam


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


def _funnel_sweep(prepared: PreparedCell, params: Params, solver: LpSolver, fixed: tuple,
                  first: tuple | None = None) -> SolveOutcome:  # fmt: skip
    """ALGORITHMS §11.2 for a funnel cell: ``c_h ≥ c_v`` enforced and ``κ`` halved until Lemma 4 holds.

    The LP is then feasible with strict margins ``S_h,k ≤ −ε/4`` (every barrier row) and
    ``S_V ≤ −min(clf_margin·u_max, ε/4)`` (``ε = ε_max``), and maximises them as §5.2 weighs them.
    ``first`` is ``(halving 0 of _funnel_lp, its result)`` when that LP is solved already.
    """
    template, u_max = prepared.template, params.u_max
    result, upper, c_h, c_v, kappa, attempts = None, None, math.nan, math.nan, params.kappa, 0
    halving = 0
    # geometry: the same at every κ
    h_min, diam = prepared.lemma4_terms if prepared.lemma4_terms is not None else _lemma4_terms(prepared.problem)
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
    log.error("funnel cell not certifiable (Lemma 4 says this cannot happen): %s", "no κ gives ε > 0"
              if result is None else f"LP {result.status.name.lower()}")  # fmt: skip
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
        terms = prepared.lemma4_terms if prepared.lemma4_terms is not None else _lemma4_terms(prepared.problem)
        attempt = _funnel_lp(prepared, params, 0, terms)
        return attempt if attempt[3] is not None else None
    return _kappa_lp(prepared, params, 0, (prepared.template.col_lower, _strict_columns(prepared, params)))


def solve_prepared(prepared: PreparedCell, params: Params, solver: LpSolver, funnel: bool = False,
                   first: tuple | None = None) -> SolveOutcome:  # fmt: skip
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


def finish_cell(prepared: PreparedCell, outcome: SolveOutcome, recheck: bool = True,
                K: np.ndarray | None = None) -> CellSolution:  # fmt: skip
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
        for a certified or relaxed cell, for :func:`more_tolerant_all`, which re-checks every
        cell's field at its vertices in one pass.
    K : ndarray, shape (2, 2n), optional
        The gain of the optimal LP's variables when already recovered (:func:`run` recovers
        those of field space for all cells at once); None: recovered here.

    Returns
    -------
    CellSolution
        ``tolerance`` NaN (only :func:`more_tolerant` sets it).
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
        margin_h, margin_v = _template_margins(prepared.checker, outcome.row_upper, prepared.space, K,
                                               problem.landmarks, len(problem.vertices))  # fmt: skip
    return CellSolution(status, K, outcome.c_h, outcome.c_v, margin_h, margin_v, outcome.attempts, outcome.kappa,
                        result.objective)  # fmt: skip


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
        Status 0 (first attempt), 1 (after halvings), 2 (least violation) or 3 (unbounded
        or solver error: the gain is then zero). Margins are recomputed at the vertices
        from ``K`` (equal to :func:`vertex_margins`).
    """
    prepared = prepare_cell(problem, params)
    solution = finish_cell(prepared, solve_prepared(prepared, params, solver, funnel=funnel))
    certified = solution.status in (CellStatus.CERTIFIED, CellStatus.RELAXED)
    if funnel and params.tolerant and certified:
        return more_tolerant(solution, problem, params.u_max)
    return solution


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
    excess = checker.vertex_rows @ theta
    excess -= upper[: len(excess)]
    # Python's max of the n_h + 1 group maxima: the same numbers (all finite), fewer numpy calls.
    worst = excess.reshape(n_h + 1, p).max(axis=1).tolist()
    return (max(worst[:n_h]) if n_h else math.nan), worst[n_h]


def goal_cell_solution(vertices: np.ndarray, goal: np.ndarray, landmarks: np.ndarray, cbf_n: np.ndarray,
                       cbf_q: np.ndarray, u_max: float) -> CellSolution:  # fmt: skip
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
        built = field_vertex_templates(cells.cell_vertices, cells.cell_vertex_offsets, cells.cbf_A, cells.cbf_b,
                                       cells.cbf_offsets, cells.exit_dir, cells.exit_point, edge, params.u_max,
                                       params.w_h, params.w_v)  # fmt: skip
        scales = _batched_scales(cells, built, edge)
    for c in range(C):
        if lo[c + 1] - lo[c] < 2:
            raise ArtifactError(f"cell {c} uses {lo[c + 1] - lo[c]} landmark(s); at least 2 needed",
                                field="cell_landmarks")  # fmt: skip
        vertices, used = cells.cell_vertices[vo[c] : vo[c + 1]], cell_landmarks[lo[c] : lo[c + 1]]
        cbf_n, cbf_q = cells.cbf_A[ho[c] : ho[c + 1]], cells.cbf_b[ho[c] : ho[c + 1]]
        if is_goal[c]:
            solutions[c] = goal_cell_solution(vertices, cells.nodes[cells.cell_node[c]], used, cbf_n, cbf_q,
                                              params.u_max)  # fmt: skip
            continue
        problem = CellProblem(vertices, cells.cell_A[ro[c] : ro[c + 1]], cells.cell_b[ro[c] : ro[c + 1]],
                              cells.exit_dir[c], cells.exit_point[c], cbf_n, cbf_q, used)  # fmt: skip
        try:
            if built is None:
                prepared[c] = prepare_cell(problem, params)
            else:
                h_scale, v_max, terms = scales[c]
                prepared[c] = _prepared(problem, params, "field", FIELD_MAP, built.templates[c], h_scale,
                                        _checked_v_max(v_max), terms)  # fmt: skip
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
        gains = _grouped_gains(fields[:, :, :2], fields[:, :, 2], [cell_landmarks[lo[c] : lo[c + 1]] for c in range(C)],
                               optimal)  # fmt: skip
    for c, outcome in outcomes.items():
        solutions[c] = sol = finish_cell(prepared[c], outcome, recheck=not tolerant, K=gains.get(c))
        if sol.status == CellStatus.NOT_CERTIFIED:
            log.warning("cell %d not certified: least-violation margins h %.3g, V %.3g", c, sol.margin_h, sol.margin_v)
        elif sol.status == CellStatus.SOLVER_FAILURE:
            log.warning("cell %d: solver failure (unbounded or error)", c)
    if tolerant:
        chosen = [c for c in outcomes if solutions[c].status in (CellStatus.CERTIFIED, CellStatus.RELAXED)]
        picked = more_tolerant_all([solutions[c] for c in chosen], [prepared[c].problem for c in chosen],
                                   params.u_max, [outcomes[c].lemma4_terms for c in chosen])  # fmt: skip
        for c, sol in zip(chosen, picked, strict=True):
            solutions[c] = sol
    gain = np.zeros((C, 2, 2 * n_lm))
    if C:  # K_k of landmark k in columns 2k, 2k + 1: every cell's blocks in one scatter
        blocks = np.concatenate([sol.K.reshape(2, -1, 2) for sol in solutions], axis=1)  # (2, Σ n_c, 2)
        gain.reshape(C, 2, n_lm, 2)[lm_cell, :, lm_index, :] = blocks.transpose(1, 0, 2)
    c_h, c_v, margin_h, margin_v = (np.array([getattr(sol, name) for sol in solutions], float)
                                    for name in ("c_h", "c_v", "margin_h", "margin_v"))  # fmt: skip
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
    return Plan(cells=cells, gain=gain, c_h=c_h, c_v=c_v, u_max=np.full(C, params.u_max), margin_h=margin_h,
                margin_v=margin_v, status=status, goal_tolerance=goal_tolerance, tolerance=delta,
                usable_tolerance=usable, plan_tolerance=plan_tolerance, stats=stats)  # fmt: skip


def _solve_all(prepared: dict, params: Params, solver: LpSolver, funnel: bool,
               progress: Callable[[int, int], None] | None, C: int) -> dict:  # fmt: skip
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


def more_tolerant(solution: CellSolution, problem: CellProblem, u_max: float,
                  terms: tuple[float, float] | None = None) -> CellSolution:  # fmt: skip
    """Of a certified funnel cell's LP field and Lemma 6's field, the one with the larger ``δ_c`` (§12.4).

    One cell of :func:`more_tolerant_all`; ``terms`` are Lemma 4's ``(min_k h_k(x_j), diam)`` when
    already computed (only ``diam`` is read).
    """
    return more_tolerant_all([solution], [problem], u_max, [terms])[0]


def more_tolerant_all(solutions: Sequence[CellSolution], problems: Sequence[CellProblem], u_max: float,
                      terms: Sequence[tuple[float, float] | None] | None = None) -> list[CellSolution]:  # fmt: skip
    """:func:`more_tolerant` of many certified funnel cells at once (every cell's vertices and rows in one pass).

    Lemma 6's field (ALGORITHMS §12.4) ``u = c(x* − x) − εz`` with ``c = c_v`` and its sink ``x*``
    at the point of the exit face of largest side depth ``h*`` (:func:`~bearnav_cli.funnel.exit_sink`)
    has ``M = cI``, barrier margins at least ``c·h* − ε`` and progress margin ``ε``, so it
    tolerates ``min(h* − ε/c, ε/c)``; the best ``ε = c·h*/2``, lowered to keep
    ``|u|_∞ ≤ c·diam + ε ≤ u_max``. Since ``x_j`` lies on the face, ``h* ≥ min_k h_k(x_j)``: it
    never tolerates less than Lemma 4's field with its sink at ``x_j``. Both fields (the LP's and
    Lemma 6's) are re-checked at the vertices (the numbers of :func:`field_margins`) and their
    ``δ_c`` is :func:`bearnav_cli.funnel.cell_tolerance`'s; each returned solution carries the
    chosen gain, its margins and its ``δ_c``, with the same status and constants.

    Parameters
    ----------
    solutions, problems : sequences of length C
        Certified funnel edge cells and their problems.
    u_max : float
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
    terms = [_lemma4_terms(p) if t is None else t for p, t in zip(problems, terms, strict=True)]
    diam = np.array([t[1] for t in terms], float)
    z = np.array([p.z for p in problems], float)
    x_j = np.array([p.x_j for p in problems], float)
    # ragged vertices and barrier rows (CellProblem holds them as float64 (p, 2), (h, 2), (h,))
    n_v = np.array([len(p.vertices) for p in problems])
    n_h = np.array([len(p.cbf_q) for p in problems])
    V = np.concatenate([p.vertices for p in problems])
    N = np.concatenate([p.cbf_n for p in problems])
    Q = np.concatenate([p.cbf_q for p in problems])
    sink, h_star = _sinks(V, n_v, N, Q, n_h, z, x_j)
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
    values = -(np.einsum("fpi,pi->fp", U[:, pair_vertex], pair_n)
               + c_h[h_cell[pair_row]] * (np.einsum("pi,pi->p", V[pair_vertex], pair_n) + Q[pair_row]))  # fmt: skip
    cbf = np.full((2, C), -np.inf)
    if len(Q):
        row_max = np.maximum.reduceat(values, row_start, axis=1)
        cbf[:, has_rows] = np.maximum.reduceat(row_max, h_start[has_rows], axis=1)
    else:
        row_max = np.zeros((2, 0))
    progress = np.einsum("fpi,pi->fp", U, z[v_cell]) + c_v[:, v_cell] * np.einsum("pi,pi->p", V - x_j[v_cell],
                                                                                  z[v_cell])  # fmt: skip
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
    gains = _grouped_gains(M[1], a[1], [p.landmarks for p in problems], np.flatnonzero(lemma6).tolist())
    # Python floats for the per-cell results (the same numbers as float() of each entry)
    cbf_l, clf_l, delta_l, c_l = cbf.tolist(), clf.tolist(), delta.tolist(), c.tolist()
    n_h_l, lemma6_l = n_h.tolist(), lemma6.tolist()
    out = []
    for k, sol in enumerate(solutions):
        f = int(lemma6_l[k])
        K, c_k = (gains[k], c_l[k]) if f else (sol.K, sol.c_v)
        out.append(CellSolution(sol.status, K, sol.c_h, c_k, cbf_l[f][k] if n_h_l[k] else math.nan, clf_l[f][k],
                                sol.attempts, sol.kappa, sol.objective, delta_l[f][k]))  # fmt: skip
    return out


def _grouped_gains(M: np.ndarray, a: np.ndarray, landmarks: Sequence[np.ndarray], which: list[int]) -> dict:
    """:func:`~bearnav_cli.cell_lp.min_norm_gains` of the fields ``which``, one call per landmark count.

    ``M`` (C, 2, 2) and ``a`` (C, 2) are the fields, ``landmarks[k]`` (n_k, 2) those of field ``k``;
    returns ``{k: K}`` with ``K`` of shape (2, 2n_k) for every ``k`` in ``which``.
    """
    counts = [len(landmarks[k]) for k in which]
    out = {}
    for n in sorted(set(counts)):
        group = [k for k, count in zip(which, counts, strict=True) if count == n]
        K = min_norm_gains(M[group], a[group], np.stack([landmarks[k] for k in group]))
        out.update(zip(group, K, strict=True))
    return out


def _sinks(V: np.ndarray, n_v: np.ndarray, N: np.ndarray, Q: np.ndarray, n_h: np.ndarray, z: np.ndarray,
           x_j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Lemma 6's sink ``x*`` (C, 2) and side depth ``h*`` (C,) of every cell (:func:`funnel.exit_sinks`).

    The cells come ragged: ``V`` (ΣP, 2) their vertices, ``n_v`` (C,) how many per cell; ``N``, ``Q``
    (ΣH, 2), (ΣH,) their barrier rows ``n·x + q ≥ 0``, ``n_h`` (C,) per cell; ``z``, ``x_j`` (C, 2).
    Each exit face is :func:`funnel.exit_face`'s (the two vertices nearest the exit line, in polygon
    order, ties to the first), taken for all cells in one sort.
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


def cell_tolerances(cells: Cells, gain: np.ndarray, c_h: np.ndarray, c_v: np.ndarray, u_max: float,
                    known: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """``δ_c`` of every funnel cell from its gain and rows (ALGORITHMS §11.4), shape (C,), map units.

    The margins are recomputed at the vertices (:func:`vertex_margins`); a cell whose margins are
    not all positive tolerates no error (``δ_c = 0``). ``known`` (C,) gives the cells whose ``δ_c``
    is already known (NaN elsewhere, and all are computed without it).
    """
    landmarks = cells.map.landmarks
    out = np.zeros(cells.n_cells) if known is None else np.array(known, float)
    for c in range(cells.n_cells):
        if not math.isnan(out[c]):
            continue  # computed with the field that was chosen (more_tolerant)
        normals, offsets = cells.barrier(c)
        goal = cells.parent[cells.cell_node[c]] == -1
        z, x_j = cells.exit_dir[c], cells.exit_point[c]
        m = vertex_margins(gain[c], landmarks, cells.vertices(c), z, x_j, normals, offsets, c_h[c], c_v[c], u_max)
        M = gain[c].reshape(2, -1, 2).sum(axis=1)
        out[c] = cell_tolerance(M, normals, -m.cbf_rows, None if goal else z, None if goal else -m.clf)
    return out


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
    words = {CellStatus.CERTIFIED: "certified", CellStatus.RELAXED: "certified after relaxing",
             CellStatus.NOT_CERTIFIED: "not certified", CellStatus.SOLVER_FAILURE: "solver failures",
             CellStatus.GOAL: "goal"}  # fmt: skip
    text = f"{len(plan.status)} cells: " + ", ".join(f"{counts[s]} {words[s]}" for s in CellStatus)
    if plan.cells.is_funnel:
        by_area = tolerance_by_area(plan.cells, plan.usable_tolerance)
        text += (f"; funnel certificate: a position error of {plan.plan_tolerance:.3g} tolerated everywhere "
                 f"({by_area['median']:.3g} at the median point, under {by_area['p10']:.3g} on 10% of the area), "
                 f"{100 * plan.cells.free_coverage:.1f}% of the free space covered")  # fmt: skip
    flags = plan.cells.cell_flags
    if plan.cells.is_funnel:  # harmless for the funnel certificate (docs/cli.md "Words"): no alarm to print
        flags = flags & ~CellFlag.DEGENERATE_RISK
    flagged = int(np.count_nonzero(flags))
    if flagged:
        parts = [f"{f.name.lower()} {np.count_nonzero(flags & f)}" for f in CellFlag if f and np.any(flags & f)]
        text += f"; {flagged} flagged cells ({', '.join(parts)})"
    return text


def problems(plan: Plan) -> list:
    """Why the plan is not usable (a list of :class:`~bearnav_cli.verdicts.Problem`, worst first): its cells'
    problems (no route, blind spots), then the cells not certified (status 2 or 3)."""
    from bearnav_cli import verdicts

    cells = plan.cells
    return (verdicts.no_route(cells.nodes, cells.node_added) + verdicts.blind_spots(cells)
            + verdicts.not_certified(plan.status))  # fmt: skip


__all__ += ["problems"]
