"""Benchmark: synthesis against bare HiGHS on the same LPs (DESIGN §7).

The kitchen map's cells come from running ``map → rrtstar → simplify → decompose``
in-process with the map's parameters (funnel cells by default, ALGORITHMS §11). Each cell
is solved as the stage solves it: the certificate comes from the cells
(``cells.is_funnel``), so funnel cells go through Lemma 4's κ sweep with strict margins and
the more tolerant of the LP's and Lemma 4's fields (§11.2, §11.4), paper cells through the
§5.3 loop. Four things are timed on the same LPs:

* **stage**: ``synthesize.run(cells)``, the whole stage (every cell, goal cell included,
  the gain layout and the statistics);
* **solve_cell**: the per-cell function, cell by cell, with ``funnel=cells.is_funnel``
  (build the LP with numpy, solve it through ``LpSolver``, recover the gain, re-check the
  margins at the vertices; funnel: pick the more tolerant field);
* **bare arrays**: ``passModel`` with the pre-built numpy arrays (the array form that
  ``LpSolver`` uses) and ``run``, for exactly the LPs ``solve_cell`` solved;
* **bare HighsLp**: ``passModel`` of ``HighsLp`` objects built before timing, and ``run``.

The bare variants use a fresh ``highspy.Highs`` with bearnav's solver options. Each round
makes one pass over the cells per variant (no call meets the LP it just solved, which would
run faster from warm caches), and the order of the passes rotates between rounds. Times are
medians over the rounds (per cell for the per-cell variants). The number of LPs recorded
from ``solve_cell`` is checked against the stage's own ``stats["lp_solves"]``. The budget is
under 2 ms per cell and at most 1.5× bare HiGHS.

Run from the repository root::

    PYTHONPATH=. python bench/synthesize.py [--quick] [--readme]

The markdown goes to stdout; ``--readme`` replaces the ``synthesize`` section of
``bench/README.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import highspy
import numpy as np
from common import (
    README,
    REPO_DIR,
    load_line,
    load_map,
    load_snapshot,
    machine_line,
    markdown_table,
    replace_section,
)

from bearnav_cli import cell_lp, pipeline
from bearnav_cli import lp as lp_module
from bearnav_cli.datatypes import Cells
from bearnav_cli.stages import synthesize

SECTION = "synthesize"
MAP = REPO_DIR / "maps" / "kitchen.yaml"
#: (gain_structure, lp_form) configurations; the first is the default.
CONFIGS = (("full", "vertex"), ("full", "dual"), ("diag", "vertex"), ("scalar", "vertex"))
ROUNDS = 9
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
    return pipeline.compute(load_map(MAP), through="decompose")["cells"]


def edge_problems(cells: Cells) -> list[cell_lp.CellProblem]:
    """One :class:`~bearnav_cli.stages.cell_lp.CellProblem` per edge cell (the goal cell has no LP)."""
    problems = []
    for c in range(cells.n_cells):
        if cells.parent[cells.cell_node[c]] == -1:
            continue
        A, b = cells.rows(c)
        n, q = cells.barrier(c)
        used = cells.cell_landmarks[c]
        problems.append(
            cell_lp.CellProblem(
                cells.vertices(c), A, b, cells.exit_dir[c], cells.exit_point[c], n, q, cells.map.landmarks[used]
            )
        )
    return problems


def highs_lp(arrays: tuple[np.ndarray, ...]) -> highspy.HighsLp:
    """A ``HighsLp`` from the arguments of :meth:`LpSolver.solve`."""
    cost, indptr, indices, values, row_lower, row_upper, col_lower, col_upper = arrays
    return lp_module.highs_lp(
        len(cost), len(row_lower), cost, indptr, indices, values, row_lower, row_upper, col_lower, col_upper
    )


def raw_args(arrays: tuple[np.ndarray, ...]) -> tuple:
    """Arguments of the array form of ``Highs.passModel`` (what ``LpSolver`` calls)."""
    cost, indptr, indices, values, row_lower, row_upper, col_lower, col_upper = arrays
    return (
        len(cost),
        len(row_lower),
        len(values),
        int(highspy.MatrixFormat.kRowwise),
        int(highspy.ObjSense.kMinimize),
        0.0,
        cost,
        col_lower,
        col_upper,
        row_lower,
        row_upper,
        indptr.astype(np.int32),
        indices.astype(np.int32),
        values,
        np.zeros(len(cost), np.int32),
    )


def bare_highs() -> highspy.Highs:
    highs = highspy.Highs()
    for name, value in lp_module.OPTIONS.items():
        highs.setOptionValue(name, value)
    return highs


def compare(cells: Cells, params: synthesize.Params, rounds: int, also: synthesize.Params | None = None) -> dict:
    """Median times (s): the stage (total), ``solve_cell`` and the bare variants (per cell); LP counts.

    Every cell is solved as :func:`synthesize.run` solves it: ``funnel=cells.is_funnel``. With
    ``also``, the stage with those parameters is timed side by side too (``"stage_also"``, total).
    """
    problems = edge_problems(cells)
    funnel = cells.is_funnel
    recorder = RecordingSolver()
    per_cell_lps = []
    for problem in problems:
        start = len(recorder.calls)
        synthesize.solve_cell(problem, params, recorder, funnel=funnel)
        per_cell_lps.append(recorder.calls[start:])
    prebuilt = [[highs_lp(arrays) for arrays in lps] for lps in per_cell_lps]
    raw = [[raw_args(arrays) for arrays in lps] for lps in per_cell_lps]
    solver, highs = lp_module.LpSolver(), bare_highs()
    clock = time.perf_counter

    def stage(out: np.ndarray) -> None:
        t0 = clock()
        synthesize.run(cells, params)
        out[:] = (clock() - t0) / len(problems)

    def stage_also(out: np.ndarray) -> None:
        t0 = clock()
        synthesize.run(cells, also)
        out[:] = (clock() - t0) / len(problems)

    def per_cell(fn):
        def timed(out: np.ndarray) -> None:
            for c in range(len(problems)):
                t0 = clock()
                fn(c)
                out[c] = clock() - t0

        return timed

    def ours(c: int) -> None:
        synthesize.solve_cell(problems[c], params, solver, funnel=funnel)

    def arrays(c: int) -> None:
        for args in raw[c]:
            highs.passModel(*args)
            highs.run()

    def bare(c: int) -> None:
        for lp in prebuilt[c]:
            highs.passModel(lp)
            highs.run()

    variants = [
        ("stage", stage),
        ("solve_cell", per_cell(ours)),
        ("arrays", per_cell(arrays)),
        ("highs_lp", per_cell(bare)),
    ]
    if also is not None:
        variants.append(("stage_also", stage_also))
    times = {name: np.zeros((rounds, len(problems))) for name, _ in variants}
    for r in range(rounds):
        k = r % len(variants)
        for name, fn in variants[k:] + variants[:k]:
            fn(times[name][r])
    out = {name: np.median(t, axis=0) for name, t in times.items()}
    for name in ("stage", "stage_also"):
        if name in out:
            out[name] = float(out[name][0] * len(problems))
    out["lps"] = np.array([len(lps) for lps in per_cell_lps])
    flat = [arrays for lps in per_cell_lps for arrays in lps]
    out["shape"] = (float(np.mean([len(a[4]) for a in flat])), float(np.mean([len(a[0]) for a in flat])))
    return out


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

    load_before = load_snapshot()
    log("building the kitchen cells …")
    cells = kitchen_cells()
    n_edge = cells.n_cells - 1
    certificate = "funnel" if cells.is_funnel else "paper"
    rows, verdict, mismatches = [], "", []
    for structure, form in configs:
        params = synthesize.Params(gain_structure=structure, lp_form=form)
        log(f"{structure}/{form}: {cells.n_cells} {certificate} cells × {rounds} rounds …")
        plan = synthesize.run(cells, params)  # warm-up: imports, caches, HiGHS' first run
        default = (structure, form) == CONFIGS[0]
        # the default funnel run also times the stage without the tolerant choice (Params.tolerant)
        also = dataclasses.replace(params, tolerant=False) if default and cells.is_funnel else None
        t = compare(cells, params, rounds, also)
        if int(t["lps"].sum()) != plan.stats["lp_solves"]:
            mismatches.append(
                f"{structure} / {form}: solve_cell solved {int(t['lps'].sum())} LPs, the stage "
                f"{plan.stats['lp_solves']}"
            )
        stage_ms = 1e3 * t["stage"] / cells.n_cells
        ours_ms, arrays_ms, lp_ms = 1e3 * t["solve_cell"], 1e3 * t["arrays"], 1e3 * t["highs_lp"]
        rows.append(
            [
                f"{structure} / {form}" + (" (default)" if (structure, form) == CONFIGS[0] else ""),
                f"{t['lps'].sum() / n_edge:.2f}",
                f"{stage_ms:.3f}",
                f"{ours_ms.mean():.3f}",
                f"{np.median(ours_ms):.3f}",
                f"{arrays_ms.mean():.3f}",
                f"{lp_ms.mean():.3f}",
                f"{t['stage'] / (t['arrays'].sum()):.2f}",
                f"{ours_ms.sum() / arrays_ms.sum():.2f}",
                f"{ours_ms.sum() / lp_ms.sum():.2f}",
            ]
        )
        if (structure, form) == CONFIGS[0]:
            ratio = t["stage"] / t["arrays"].sum()
            verdict = (
                f"Default configuration: the stage takes {stage_ms:.3f} ms per cell (budget {BUDGET_MS:g} ms: "
                f"{'met' if stage_ms < BUDGET_MS else 'NOT met'}) and {ratio:.2f}× bare HiGHS on the same LPs "
                f"(budget {BUDGET_RATIO:g}×: {'met' if ratio <= BUDGET_RATIO else 'NOT met'}). A bare solve of these "
                f"LPs ({t['shape'][0]:.0f} rows × {t['shape'][1]:.0f} columns on average) takes "
                f"{1e3 * t['arrays'].mean():.2f} ms, so the ratio budget leaves "
                f"{1e3 * t['arrays'].mean() * (BUDGET_RATIO - 1):.2f} ms per cell for everything Python does: "
                "building the LP, the gain of Lemma 3 and the vertex re-check"
                + (
                    ", the choice of the more tolerant field and the tolerances δ_c (stage only)."
                    if cells.is_funnel
                    else "."
                )
            )
            if also is not None:
                also_ratio = t["stage_also"] / t["arrays"].sum()
                verdict += (
                    f" Side by side in the same rounds, the stage with `tolerant=False` (no choice of the more "
                    f"tolerant field; δ_c and δ* are still computed) takes {1e3 * t['stage_also'] / cells.n_cells:.3f}"
                    f" ms per cell, {also_ratio:.2f}× bare HiGHS: the tolerant choice costs "
                    f"{1e3 * (t['stage'] - t['stage_also']) / cells.n_cells:.3f} ms per cell."
                )

    headers = [
        "gain / LP form",
        "LPs per edge cell",
        "stage ms/cell",
        "solve_cell mean ms",
        "solve_cell median ms",
        "bare arrays mean ms",
        "bare HighsLp mean ms",
        "stage / bare arrays",
        "solve_cell / bare arrays",
        "solve_cell / bare HighsLp",
    ]
    command = f"`bench/synthesize.py{' --quick' if args.quick else ''}`"
    if cells.is_funnel:
        how = (
            "funnel cells (ALGORITHMS §11; `decompose` default), so every cell is solved as the stage solves it, "
            "`solve_cell(..., funnel=True)`: Lemma 4's κ sweep with `c_h ≥ c_v` and strict margins (§11.2), then "
            "the more tolerant of the LP's and Lemma 4's fields (§11.4)"
        )
    else:
        how = "paper cells (`decompose --cells paper`), solved by the §5.3 loop (`solve_cell(..., funnel=False)`)"
    text = (
        f"{command}: the {cells.n_cells} cells ({n_edge} edge cells) of `maps/kitchen.yaml`, built in-process by "
        f"map → rrtstar → simplify → decompose with the map's parameters: {how}. Synthesis with default "
        "parameters except the gain structure and LP form. *stage*: `synthesize.run` (all cells, goal cell and "
        "statistics included), per cell. *solve_cell*: the per-cell function (numpy LP build, `LpSolver`, gain "
        "recovery, vertex re-check). *bare arrays*: `Highs.passModel` with the pre-built numpy arrays (the array "
        "form `LpSolver` uses) + `run`; *bare HighsLp*: `passModel` of pre-built `HighsLp` objects + `run`; both "
        "on exactly the LPs `solve_cell` solved (recorded by a wrapping `LpSolver`), per edge cell. "
        + (
            "The number of recorded LPs equals the stage's `stats['lp_solves']` in every configuration. "
            if not mismatches
            else "The recorded LPs do NOT match the stage's `lp_solves`: " + "; ".join(mismatches) + ". "
        )
        + "Ratios are of total times. One pass over the cells per variant and round, the order rotating; medians "
        f"over {rounds} rounds. Budget: under {BUDGET_MS:g} ms per cell and at most {BUDGET_RATIO:g}× bare HiGHS."
    )
    parts = [
        "## Synthesis",
        text,
        machine_line(("numpy", "highspy")),
        load_line(load_before, load_snapshot()),
        markdown_table(headers, rows),
    ]
    body = "\n\n".join(parts + ([verdict] if verdict else []))
    print(body)
    if args.readme:
        replace_section(SECTION, body, README)


if __name__ == "__main__":
    main()
