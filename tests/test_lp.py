"""The LP door (DESIGN §1.7): statuses, the CSR helper, and both ways of passing a model."""

from __future__ import annotations

import numpy as np
import pytest

from bearnav_cli import lp as lp_module
from bearnav_cli.lp import INF, LpSolver, LpStatus, dense_to_csr


def _solve(solver, cost, A, row_lower, row_upper, col_lower, col_upper):
    bounds = (np.asarray(b, float) for b in (row_lower, row_upper, col_lower, col_upper))
    return solver.solve(np.asarray(cost, float), *dense_to_csr(np.asarray(A, float)), *bounds)


@pytest.mark.parametrize("shape", [(5, 4), (1, 3), (3, 1), (0, 3), (4, 0), (7, 7)])
def test_dense_to_csr_round_trip(shape):
    rng = np.random.default_rng(sum(shape))
    matrix = rng.normal(size=shape)
    matrix[rng.random(shape) < 0.5] = 0.0
    indptr, indices, values = dense_to_csr(matrix)
    assert indptr.dtype == indices.dtype == np.int32 and len(indptr) == shape[0] + 1 and indptr[0] == 0
    assert np.all(values != 0) and len(values) == np.count_nonzero(matrix)
    back = np.zeros(shape)
    for r in range(shape[0]):
        span = slice(indptr[r], indptr[r + 1])
        assert np.all(np.diff(indices[span]) > 0)
        back[r, indices[span]] = values[span]
    assert np.array_equal(back, matrix)


@pytest.fixture(params=["arrays", "HighsLp"])
def solver(request):
    """A solver using the raw-array ``passModel`` or, forced, the ``HighsLp`` fallback."""
    s = LpSolver()
    if request.param == "HighsLp":
        s._raw = False
    return s


def test_statuses(solver):
    # max x + y on x + y ≤ 1, x, y ≥ 0
    ok = _solve(solver, [-1, -1], [[1, 1]], [-INF], [1], [0, 0], [INF, INF])
    assert ok.status is LpStatus.OPTIMAL and ok.objective == pytest.approx(-1) and ok.x.sum() == pytest.approx(1)
    unbounded = _solve(solver, [-1, -1], [[1, -1]], [-INF], [1], [0, 0], [INF, INF])
    assert unbounded.status is LpStatus.UNBOUNDED and np.isnan(unbounded.x).all() and np.isnan(unbounded.objective)
    infeasible = _solve(solver, [-1, -1], [[1, 1]], [-INF], [-1], [0, 0], [INF, INF])
    assert infeasible.status is LpStatus.INFEASIBLE
    ranged = _solve(solver, [1, 0], [[1, 1], [1, -1]], [2, -1], [3, 1], [-INF, -INF], [INF, INF])
    assert ranged.status is LpStatus.OPTIMAL and ranged.x == pytest.approx([0.5, 1.5])


def test_ambiguous_answers_are_resolved(monkeypatch):
    """HiGHS's "unbounded or infeasible" is settled by a feasibility solve."""
    solver = LpSolver()
    real = solver._run
    first = {"done": False}

    def ambiguous_once(model):
        if not first["done"]:
            first["done"] = True
            return lp_module._AMBIGUOUS
        return real(model)

    monkeypatch.setattr(solver, "_run", ambiguous_once)
    unbounded = _solve(solver, [-1, -1], [[1, -1]], [-INF], [1], [0, 0], [INF, INF])
    assert unbounded.status is LpStatus.UNBOUNDED
    first["done"] = False
    infeasible = _solve(solver, [-1, -1], [[1, 1]], [-INF], [-1], [0, 0], [INF, INF])
    assert infeasible.status is LpStatus.INFEASIBLE


def test_other_statuses_are_errors(monkeypatch, caplog):
    solver = LpSolver()
    monkeypatch.setattr(solver, "_run", lambda model: lp_module._SOLVE_ERROR)
    result = _solve(solver, [1], [[1]], [0], [1], [0], [1])
    assert result.status is LpStatus.ERROR and np.isnan(result.x).all()
    assert "HiGHS" in caplog.text


def test_the_solver_is_reused_and_quiet(capfd):
    solver = LpSolver()
    for k in range(3):
        _solve(solver, [1], [[1]], [k], [k + 1], [-INF], [INF])
    assert solver.solves == 3
    out, err = capfd.readouterr()
    assert out == "" and err == ""
