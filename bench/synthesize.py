"""Benchmark: per-cell synthesis against bare HiGHS on the same LPs (DESIGN §7).

The kitchen map's cells come from running ``map → rrtstar → simplify → decompose``
in-process with the map's parameters. For every edge cell, ``solve_cell`` (building
the LP from the cell with numpy, solving it through ``LpSolver``, recovering the gain
and re-checking the margins at the vertices) is timed against bare ``highspy`` calls
on exactly the LPs ``solve_cell`` passed to the solver, in two variants:

* **pass+run**: ``passModel(lp); run()`` on ``HighsLp`` objects built before timing;
* **arrays**: ``HighsLp`` filled from the pre-built numpy arrays, then ``passModel``
  and ``run`` (what any numpy caller of highspy must do).

Both use a fresh ``highspy.Highs`` with bearnav's solver options. Runs are interleaved
cell by cell, repeated, and each cell's time is its median over the rounds. The budget
is under 2 ms per cell and at most 1.5× bare HiGHS.

Run from the repository root::

    PYTHONPATH=. python bench/synthesize.py [--quick] [--readme]

The markdown goes to stdout; ``--readme`` replaces the ``synthesize`` section of
``bench/README.md``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import highspy
import numpy as np
from common import README, REPO_DIR, load_map, machine_line, markdown_table, replace_section

from bearnav_cli import lp as lp_module
from bearnav_cli import pipeline
from bearnav_cli.datatypes import Cells
from bearnav_cli.stages import decompose, rrtstar, simplify, synthesize

SECTION = "synthesize"
MAP = REPO_DIR / "maps" / "kitchen.yaml"
#: (gain_structure, lp_form) configurations; the first is the default.
CONFIGS = (("full", "vertex"), ("full", "dual"), ("diag", "vertex"), ("scalar", "vertex"))
ROUNDS = 9
STAGE_RUNS = 5
BUDGET_MS = 2.0
BUDGET_RATIO = 1.5


class RecordingSolver(lp_module.LpSolver):
    """An :class:`LpSolver` that keeps the arguments of every solve."""

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[tuple[np.ndarray, ...]] = []

    def solve(self, *args: np.ndarray) -> lp_module.LpResult:
        self.calls.append(tuple(np.array(a) for a in args))
        return super().solve(*args)


def kitchen_cells() -> Cells:
    """The kitchen map's cells, built in-process with the map's stage parameters."""
    map_ = load_map(MAP)
    tree = rrtstar.run(map_, pipeline.resolve_params("rrtstar", map_.params))
    simplified = simplify.run(tree, pipeline.resolve_params("simplify", map_.params))
    return decompose.run(simplified, pipeline.resolve_params("decompose", map_.params))


def edge_problems(cells: Cells) -> list[synthesize.CellProblem]:
    """One :class:`~bearnav_cli.stages.synthesize.CellProblem` per edge cell (the goal cell has no LP)."""
    problems = []
    for c in range(cells.n_cells):
        if cells.parent[cells.cell_node[c]] == -1:
            continue
        A, b = cells.rows(c)
        n, q = cells.barrier(c)
        used = cells.cell_landmarks[c]
        problems.append(synthesize.CellProblem(cells.vertices(c), A, b, cells.exit_dir[c], cells.exit_point[c], n, q,
                                               cells.map.landmarks[used]))  # fmt: skip
    return problems


def highs_lp(arrays: tuple[np.ndarray, ...]) -> highspy.HighsLp:
    """A ``HighsLp`` from the arguments of :meth:`LpSolver.solve`."""
    cost, indptr, indices, values, row_lower, row_upper, col_lower, col_upper = arrays
    return lp_module.highs_lp(len(cost), len(row_lower), cost, indptr, indices, values, row_lower, row_upper,
                              col_lower, col_upper)  # fmt: skip


def raw_args(arrays: tuple[np.ndarray, ...]) -> tuple:
    """Arguments of the array form of ``Highs.passModel`` (what ``LpSolver`` calls)."""
    cost, indptr, indices, values, row_lower, row_upper, col_lower, col_upper = arrays
    return (len(cost), len(row_lower), len(values), int(highspy.MatrixFormat.kRowwise), int(highspy.ObjSense.kMinimize),
            0.0, cost, col_lower, col_upper, row_lower, row_upper, indptr.astype(np.int32), indices.astype(np.int32),
            values, np.zeros(len(cost), np.int32))  # fmt: skip


def bare_highs() -> highspy.Highs:
    highs = highspy.Highs()
    for name, value in lp_module.OPTIONS.items():
        highs.setOptionValue(name, value)
    return highs


def compare(problems: list[synthesize.CellProblem], params: synthesize.Params, rounds: int) -> dict:
    """Median per-cell times (s) of ``solve_cell`` and of the two bare variants, plus LP counts."""
    recorder = RecordingSolver()
    per_cell_lps = []
    for problem in problems:
        start = len(recorder.calls)
        synthesize.solve_cell(problem, params, recorder)
        per_cell_lps.append(recorder.calls[start:])
    prebuilt = [[highs_lp(arrays) for arrays in lps] for lps in per_cell_lps]
    raw = [[raw_args(arrays) for arrays in lps] for lps in per_cell_lps]
    solver, highs = lp_module.LpSolver(), bare_highs()
    ours, bare, arrays_times = (np.zeros((rounds, len(problems))) for _ in range(3))
    clock = time.perf_counter
    for r in range(rounds):
        for c, problem in enumerate(problems):
            t0 = clock()
            synthesize.solve_cell(problem, params, solver)
            t1 = clock()
            for lp in prebuilt[c]:
                highs.passModel(lp)
                highs.run()
            t2 = clock()
            for args in raw[c]:
                highs.passModel(*args)
                highs.run()
            t3 = clock()
            ours[r, c], bare[r, c], arrays_times[r, c] = t1 - t0, t2 - t1, t3 - t2
    return {
        "ours": np.median(ours, axis=0),
        "bare": np.median(bare, axis=0),
        "arrays": np.median(arrays_times, axis=0),
        "lps": np.array([len(lps) for lps in per_cell_lps]),
    }


def stage_time(cells: Cells, params: synthesize.Params, runs: int) -> float:
    """Median wall time (s) of the whole stage ``synthesize.run``."""
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        synthesize.run(cells, params)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark, print the table and, with ``--readme``, record it."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smoke test: 2 rounds, default configuration only")
    parser.add_argument("--readme", action="store_true", help=f"replace the '{SECTION}' section of {README}")
    args = parser.parse_args(argv)
    rounds = 2 if args.quick else ROUNDS
    configs = CONFIGS[:1] if args.quick else CONFIGS

    log("building the kitchen cells …")
    cells = kitchen_cells()
    problems = edge_problems(cells)
    rows = []
    for structure, form in configs:
        params = synthesize.Params(gain_structure=structure, lp_form=form)
        log(f"{structure}/{form}: {len(problems)} cells × {rounds} rounds …")
        synthesize.run(cells, params)  # warm-up: imports, caches, HiGHS' first run
        t = compare(problems, params, rounds)
        stage = stage_time(cells, params, 1 if args.quick else STAGE_RUNS)
        ours_ms, bare_ms, arrays_ms = 1e3 * t["ours"], 1e3 * t["bare"], 1e3 * t["arrays"]
        rows.append([
            f"{structure} / {form}",
            f"{t['lps'].sum() / len(problems):.2f}",
            f"{ours_ms.mean():.3f}",
            f"{np.median(ours_ms):.3f}",
            f"{bare_ms.mean():.3f}",
            f"{arrays_ms.mean():.3f}",
            f"{ours_ms.sum() / bare_ms.sum():.2f}",
            f"{ours_ms.sum() / arrays_ms.sum():.2f}",
            f"{1e3 * stage / cells.n_cells:.3f}",
        ])  # fmt: skip

    headers = ["gain / LP form", "LPs per cell", "ours mean ms/cell", "ours median ms/cell", "bare pass+run ms/cell",
               "bare arrays ms/cell", "ratio to pass+run", "ratio to arrays", "whole stage ms/cell"]  # fmt: skip
    command = f"`bench/synthesize.py{' --quick' if args.quick else ''}`"
    text = (
        f"{command}: `solve_cell` on the {len(problems)} edge cells of `maps/kitchen.yaml` (default stage "
        "parameters; cells built in-process by map → rrtstar → simplify → decompose) against bare `highspy` on "
        "the identical LPs, interleaved cell by cell. *pass+run*: `passModel` + `run` on pre-built `HighsLp` "
        "objects; *arrays*: `HighsLp` filled from the pre-built numpy arrays, then `passModel` + `run`. Each "
        f"cell's time is its median over {rounds} rounds; means and ratios are over cells. *Whole stage*: "
        f"`synthesize.run` (goal cell, gain layout and statistics included), median of "
        f"{1 if args.quick else STAGE_RUNS} runs, divided by all {cells.n_cells} cells. "
        f"Budget: under {BUDGET_MS:g} ms per cell and at most {BUDGET_RATIO:g}× bare HiGHS."
    )
    body = "\n\n".join(["## Synthesis", text, machine_line(("numpy", "highspy")), markdown_table(headers, rows)])
    print(body)
    if args.readme:
        replace_section(SECTION, body, README)


if __name__ == "__main__":
    main()
