"""Usable tolerances of the example plans (ALGORITHMS §12.3–§12.4, issue 21): τ_c and the coverage of F.

For every example map and rrtstar seeds 0–4: the least ``τ_c`` (``plan_tolerance``), the median
``τ_c`` over ``D`` by cell area (:func:`bearnav_cli.composition.tolerance_by_area`), the median
``δ_c``, the coverage of ``F`` and of ``F_m``, and the whole in-memory plan time. The "before"
columns are ``ebb27c2``'s (one plan-wide inset, Lemma 4's sink at ``x_j``), measured with the same
definitions and recorded here: the code that made them is gone.

    PYTHONPATH=. python bench/tolerance.py [--seeds 0,1,2,3,4] [--cover F_m,F] [--readme]

``--cover``: the ``decompose.cover`` domains measured, a row each (§12.7: ``F`` adds the band along
the walls, whose cells never lower the least ``τ_c`` of the cells before it).
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np

from bearnav_cli import composition
from bench.common import REPO_DIR, load_map, markdown_table, replace_section, run_stages, timed

SECTION = "tolerance"
MAPS = ("kitchen", "paper_sim_circles", "paper_b_circles")
#: ebb27c2 on the same maps and seeds: (least δ* over the seeds, median over the seeds of the median
#: τ_c = min(δ_c, δ_e/2) by area), map units; measured before this change with /tmp scripts.
BEFORE = {"kitchen": (0.00105, 0.0088), "paper_sim_circles": (0.0243, 0.0369), "paper_b_circles": (0.0257, 0.0410)}


def measure(name: str, seed: int, cover: str = "F_m") -> dict:
    map_obj = load_map(REPO_DIR / "maps" / f"{name}.yaml")
    params = {k: dict(v) for k, v in map_obj.params.items()}
    params.setdefault("rrtstar", {})["seed"] = seed
    params.setdefault("decompose", {})["cover"] = cover
    from bearnav_cli.datatypes import replace

    map_obj = replace(map_obj, params=params)
    seconds, plan = timed(run_stages, map_obj, ["rrtstar", "simplify", "decompose", "synthesize"])
    cells = plan.cells
    by_area = composition.tolerance_by_area(cells, plan.usable_tolerance)
    finite = plan.tolerance[np.isfinite(plan.tolerance)]
    return {"min": plan.plan_tolerance, "median": by_area["median"], "delta": float(np.median(finite)),
            "F": cells.free_coverage, "F_m": cells.stats.get("free_coverage_m", float("nan")),
            "cells": cells.n_cells, "s": seconds}  # fmt: skip


def main() -> None:
    """Measure every example map at every seed and print (``--readme``: record) the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2,3,4")
    parser.add_argument("--cover", default="F_m,F", help="decompose.cover domains, comma-separated")
    parser.add_argument("--readme", action="store_true", help=f"replace the '{SECTION}' section of bench/README.md")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    rows = []
    for name, cover in ((n, c) for n in MAPS for c in args.cover.split(",")):
        runs = [measure(name, s, cover) for s in seeds]
        before = BEFORE.get(name)
        rows.append([
            name,
            cover,
            "—" if before is None else f"{1e3 * before[0]:.2f} mm",
            f"{1e3 * min(r['min'] for r in runs):.2f}–{1e3 * max(r['min'] for r in runs):.2f} mm",
            "—" if before is None else f"{1e2 * before[1]:.2f} cm",
            f"{1e2 * statistics.median(r['median'] for r in runs):.2f} cm",
            f"{1e2 * statistics.median(r['delta'] for r in runs):.2f} cm",
            f"{100 * min(r['F'] for r in runs):.1f}–{100 * max(r['F'] for r in runs):.1f}%",
            f"{100 * min(r['F_m'] for r in runs):.1f}%",
            f"{statistics.median(r['cells'] for r in runs):.0f}",
            f"{statistics.median(r['s'] for r in runs):.2f} s",
        ])  # fmt: skip
    headers = ["map", "cover", "δ* before (least)", "min τ_c after", "median τ_c by area before", "after", "median δ_c",
               "F covered", "F_m covered", "cells (median)", "plan (median)"]  # fmt: skip
    body = (f"rrtstar seeds {args.seeds}; τ_c medians by cell area, then the median over the seeds.\n\n"
            + markdown_table(headers, rows))  # fmt: skip
    print(body)
    if args.readme:
        replace_section(SECTION, body)


if __name__ == "__main__":
    main()
