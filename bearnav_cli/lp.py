"""The one door to the LP solver (DESIGN §1.7): HiGHS through ``highspy``.

This is the only module that imports ``highspy``. It fixes every solver option
in one place (:data:`OPTIONS`), maps HiGHS model statuses to :class:`LpStatus`,
and feeds a single reused ``highspy.Highs`` object with numpy arrays (no
modelling layer). Problems have the form::

    minimise    costᵀx
    subject to  row_lower ≤ A x ≤ row_upper,   col_lower ≤ x ≤ col_upper

with ``A`` given row-wise (CSR: ``indptr``, ``indices``, ``values``) and
``±`` :data:`INF` for missing bounds. The model reaches HiGHS in one
``Highs.passModel`` call: the array form (numpy buffers handed over as they are)
when this highspy has it, else a ``HighsLp`` with a ``kRowwise`` matrix
(:func:`highs_lp`), whose attributes are converted element by element.
"""

from __future__ import annotations

import enum
import functools
import logging
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass

import highspy
import numpy as np

__all__ = [
    "dense_to_csr",
    "highs_lp",
    "INF",
    "LpResult",
    "LpSolver",
    "LpStatus",
    "OPTIONS",
]

log = logging.getLogger(__name__)

#: Infinite bound understood by the solver (``highspy.kHighsInf``, i.e. ``math.inf``).
INF: float = float(highspy.kHighsInf)

#: Every HiGHS option bearnav sets, applied once when a :class:`LpSolver` is built.
#: The cell LPs are tiny (tens of rows): presolve costs more than it saves, and primal
#: simplex ran about 25 % faster than dual simplex on the kitchen map's cells
#: (bench/synthesize.py). One thread and a fixed seed make results reproducible; the tight
#: tolerances let certificates be re-checked independently to 1e-7 (ALGORITHMS §8).
OPTIONS: dict[str, object] = {
    "output_flag": False,
    "log_to_console": False,
    "solver": "simplex",
    "simplex_strategy": 4,  # primal simplex
    "presolve": "off",
    "threads": 1,
    "random_seed": 0,
    "primal_feasibility_tolerance": 1e-9,
    "dual_feasibility_tolerance": 1e-9,
}


class LpStatus(enum.Enum):
    """Outcome of one LP solve."""

    OPTIMAL = "optimal"
    INFEASIBLE = "infeasible"
    UNBOUNDED = "unbounded"
    ERROR = "error"


@dataclass(frozen=True)
class LpResult:
    """The result of :meth:`LpSolver.solve`.

    Attributes
    ----------
    status : LpStatus
        Optimal, infeasible, unbounded, or a solver error.
    x : ndarray, shape (n,)
        Primal solution; all NaN unless ``status`` is OPTIMAL.
    objective : float
        Optimal objective value; NaN unless ``status`` is OPTIMAL.
    """

    status: LpStatus
    x: np.ndarray
    objective: float


# Enum members looked up once: a pybind11 enum attribute costs microseconds per access.
_MS = highspy.HighsModelStatus
_OPTIMAL, _INFEASIBLE, _UNBOUNDED = int(_MS.kOptimal), int(_MS.kInfeasible), int(_MS.kUnbounded)
_AMBIGUOUS = int(_MS.kUnboundedOrInfeasible)
_MODEL_ERROR, _SOLVE_ERROR = int(_MS.kModelError), int(_MS.kSolveError)
_ERROR = highspy.HighsStatus.kError
_STATUS_MAP = {_OPTIMAL: LpStatus.OPTIMAL, _INFEASIBLE: LpStatus.INFEASIBLE, _UNBOUNDED: LpStatus.UNBOUNDED}


#: LPs :meth:`LpSolver.solve_each` converts to ``passModel`` arguments at a time.
_CHUNK = 16

_ROWWISE = int(highspy.MatrixFormat.kRowwise)
_MINIMIZE = int(highspy.ObjSense.kMinimize)


def _has_raw_pass_model(highs: highspy.Highs) -> bool:
    """Whether ``Highs.passModel`` accepts numpy arrays directly (the 15-argument LP form)."""
    empty = np.zeros(0)
    try:
        highs.passModel(
            0,
            0,
            0,
            _ROWWISE,
            _MINIMIZE,
            0.0,
            empty,
            empty,
            empty,
            empty,
            empty,
            np.zeros(1, np.int32),
            np.zeros(0, np.int32),
            empty,
            np.zeros(0, np.int32),
        )
    except TypeError:
        return False
    return True


def dense_to_csr(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row-wise compressed form of a dense matrix, keeping only the non-zero entries.

    Parameters
    ----------
    matrix : ndarray, shape (m, n)
        The dense matrix; converted to float64.

    Returns
    -------
    indptr : ndarray of int32, shape (m + 1,)
        Row ``r`` holds entries ``indptr[r]:indptr[r + 1]``.
    indices : ndarray of int32, shape (nnz,)
        Column of each entry, increasing within a row.
    values : ndarray of float64, shape (nnz,)
        The non-zero entries, row after row.
    """
    matrix = np.asarray(matrix, dtype=float)
    n_rows, n_cols = matrix.shape
    if n_cols == 0:
        return np.zeros(n_rows + 1, np.int32), np.zeros(0, np.int32), np.zeros(0)
    flat = np.flatnonzero(matrix)  # row-major positions of the non-zeros
    indptr = np.searchsorted(flat, np.arange(0, n_rows * n_cols + 1, n_cols)).astype(np.int32)
    return indptr, (flat % n_cols).astype(np.int32), matrix.ravel()[flat]


def _quiet_highs() -> highspy.Highs:
    """``highspy.Highs()`` without its banner: HiGHS prints it from C++ while constructing,
    before any option (``output_flag``) can be set, so stdout is pointed at /dev/null for
    the construction only."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):  # no real stdout (some embedded interpreters)
        return highspy.Highs()
    try:
        with open(os.devnull, "wb") as sink:
            os.dup2(sink.fileno(), 1)
            return highspy.Highs()
    finally:
        os.dup2(saved, 1)
        os.close(saved)


class LpSolver:
    """One reused HiGHS instance with the options of :data:`OPTIONS`.

    Build one per run and call :meth:`solve` for every LP; the object is not
    thread-safe. ``solves`` counts the calls to ``Highs.run``.
    """

    def __init__(self) -> None:
        self._highs = _quiet_highs()
        # looked up once: _run is the code between two HiGHS runs (see solve_each)
        self._methods = (self._highs.passModel, self._highs.run, self._highs.getModelStatus)
        for name, value in OPTIONS.items():
            self._set(name, value)
        self.solves = 0
        self._raw = _has_raw_pass_model(self._highs)

    def _set(self, name: str, value: object) -> None:
        status = self._highs.setOptionValue(name, value)
        if status != highspy.HighsStatus.kOk:
            raise RuntimeError(f"HiGHS rejected option {name}={value!r}")

    def solve(
        self,
        cost: np.ndarray,
        A_indptr: np.ndarray,
        A_indices: np.ndarray,
        A_values: np.ndarray,
        row_lower: np.ndarray,
        row_upper: np.ndarray,
        col_lower: np.ndarray,
        col_upper: np.ndarray,
    ) -> LpResult:
        """Minimise ``costᵀx`` subject to row and column bounds.

        Parameters
        ----------
        cost : ndarray, shape (n,)
            Objective coefficients.
        A_indptr, A_indices, A_values : ndarray, shapes (m + 1,), (nnz,), (nnz,)
            The constraint matrix, row-wise (see :func:`dense_to_csr`).
        row_lower, row_upper : ndarray, shape (m,)
            Row bounds; use ``-INF``/``INF`` for a missing side.
        col_lower, col_upper : ndarray, shape (n,)
            Column bounds, same convention.

        Returns
        -------
        LpResult
            Infeasible and unbounded are told apart: when HiGHS answers "unbounded
            or infeasible" the LP is solved once more with a zero objective (a
            feasibility test).
        """
        return self.solve_each([(cost, A_indptr, A_indices, A_values, row_lower, row_upper, col_lower, col_upper)])[0]

    def solve_each(self, problems: Sequence[tuple[np.ndarray, ...]]) -> list[LpResult]:
        """:meth:`solve` of each problem in turn, up to the first whose LP is not optimal.

        The solves run back to back and the results are made after the last: any work between
        two HiGHS runs costs several times what it costs apart (a few numpy calls between the
        kitchen map's LPs added about 20 µs per LP, against a few µs on their own), so a caller
        with many LPs whose inputs do not depend on each other's results hands them over together.

        Parameters
        ----------
        problems : sequence of tuples
            The arguments of :meth:`solve` of each LP, in order.

        Returns
        -------
        list of LpResult
            One per problem solved, in order: every problem while the LPs are optimal, and the
            first LP that is not (infeasible, unbounded or an error) last.
        """
        solved, status, models = [], _OPTIMAL, []
        solution, objective = self._highs.getSolution, self._highs.getObjectiveValue
        # Converted a chunk at a time: a caller meeting an LP that is not optimal hands the rest
        # over again, and converting them all each time would cost O(n²).
        for start in range(0, len(problems), _CHUNK):
            chunk = [(len(p[0]), len(p[4])) + tuple(p) for p in problems[start : start + _CHUNK]]
            models += chunk
            for args in [self._pass_args(model) for model in chunk]:  # the loop is all the code between two runs
                status = self._run(args)
                if status != _OPTIMAL:
                    break
                solved.append((solution().col_value, objective()))
            if status != _OPTIMAL:
                break
        results = [LpResult(LpStatus.OPTIMAL, np.array(x, dtype=float), float(value)) for x, value in solved]
        if status != _OPTIMAL:
            results.append(self._not_optimal(status, models[len(solved)]))
        return results

    def _not_optimal(self, status: int, model: tuple) -> LpResult:
        """The result of a model whose first run ended with ``status`` (not optimal)."""
        n, m = model[0], model[1]
        # presolve is off (OPTIONS), so "unbounded or infeasible" comes from the simplex itself:
        # solving with a zero objective tells the two apart
        if status == _AMBIGUOUS:
            feasible = self._run(self._pass_args((n, m, np.zeros(n)) + model[3:]))
            status = _UNBOUNDED if feasible == _OPTIMAL else feasible
        outcome = _STATUS_MAP.get(status, LpStatus.ERROR)  # not OPTIMAL: an optimal zero-objective run is UNBOUNDED
        if outcome is LpStatus.ERROR:
            log.warning("HiGHS returned model status %s", self._highs.modelStatusToString(_MS(status)))
        return LpResult(outcome, np.full(n, np.nan), float("nan"))

    def _run(self, args: tuple) -> int:
        """Pass the model (arguments of :meth:`_pass_args`) and run; the model status as an int, or an
        error status if a call fails."""
        self.solves += 1
        pass_model, run, model_status = self._methods
        if pass_model(*args) == _ERROR:
            return _MODEL_ERROR
        if run() == _ERROR:
            return _SOLVE_ERROR
        return int(model_status())

    def _pass_args(self, model: tuple) -> tuple:
        """Arguments of ``Highs.passModel``: the raw-array form when this highspy has it, else a ``HighsLp``.

        Both carry the same row-wise matrix; the raw form hands the numpy buffers over
        without the element-by-element conversion of ``HighsLp`` attributes.
        """
        n, m, cost, indptr, indices, values, row_lower, row_upper, col_lower, col_upper = model
        if self._raw:
            return (
                n,
                m,
                len(values),
                _ROWWISE,
                _MINIMIZE,
                0.0,
                _f64(cost),
                _f64(col_lower),
                _f64(col_upper),
                _f64(row_lower),
                _f64(row_upper),
                _i32(indptr),
                _i32(indices),
                _f64(values),
                _continuous(n),
            )
        return (highs_lp(*model),)


@functools.lru_cache(maxsize=64)
def _continuous(n: int) -> np.ndarray:
    """Integrality of ``n`` continuous columns (read-only, shared)."""
    out = np.zeros(n, np.int32)
    out.setflags(write=False)
    return out


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _i32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.int32)


def highs_lp(n, m, cost, indptr, indices, values, row_lower, row_upper, col_lower, col_upper) -> highspy.HighsLp:
    """A ``highspy.HighsLp`` holding the LP (matrix row-wise, ``MatrixFormat.kRowwise``).

    The fallback of :meth:`LpSolver.solve` for a highspy whose ``passModel`` takes no raw arrays;
    the arguments are those of :meth:`LpSolver.solve` with the sizes first.

    Parameters
    ----------
    n : int
        Number of columns (variables).
    m : int
        Number of rows (constraints).
    cost : ndarray, shape (n,)
        Objective coefficients (minimised).
    indptr, indices, values : ndarray, shapes (m + 1,), (nnz,), (nnz,)
        The constraint matrix, row-wise (:func:`dense_to_csr`).
    row_lower, row_upper : ndarray, shape (m,)
        Row bounds; ``-INF``/``INF`` for a missing side.
    col_lower, col_upper : ndarray, shape (n,)
        Column bounds, same convention.

    Returns
    -------
    highspy.HighsLp
    """
    lp = highspy.HighsLp()
    lp.num_col_ = n
    lp.num_row_ = m
    lp.col_cost_ = cost
    lp.col_lower_ = col_lower
    lp.col_upper_ = col_upper
    lp.row_lower_ = row_lower
    lp.row_upper_ = row_upper
    matrix = lp.a_matrix_
    matrix.format_ = highspy.MatrixFormat.kRowwise
    matrix.num_col_ = n
    matrix.num_row_ = m
    matrix.start_ = indptr
    matrix.index_ = indices
    matrix.value_ = values
    return lp
