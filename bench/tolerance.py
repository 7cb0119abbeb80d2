"""Usable tolerances and the coverage of F, before and after (ALGORITHMS §12.3–§12.4, §12.7; issue 21).

For every example map and the three maps made for the bearings work (``made_maps.py``, seed 0:
office, maze, clutter, with their own 12 tags), rrtstar seeds 0–4: the least ``τ_c``
(``plan_tolerance``), the median ``τ_c`` over ``D`` by cell area
(:func:`bearnav_cli.datatypes.tolerance_by_area`), the coverage of ``F`` and of ``F_m``, the cells,
the cells not certified and the whole in-memory plan time (``pipeline.compute``, map included).
The "before" columns are ``ebb27c2``'s (one plan-wide exit inset, Lemma 4's sink at ``x_j``, ``D``
only in ``F_m``): ``δ* = min(min_c δ_c, δ_e/2)`` and the area-weighted median of
``min(δ_c, δ_e/2)``, measured per seed from a worktree of that commit with the same map files and
recorded below; the code that made them is gone. Ratios are the worst seed's.

    PYTHONPATH=. python bench/tolerance.py [--seeds 0,1,2,3,4] [--cover F] [--readme]

``--cover``: the ``decompose.cover`` domains measured, a row each per map (``F``, the default, or
``F_m``, the band along the walls left out).
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np
from common import MADE_SEED, machine_line, markdown_table, measured_maps, replace_section, timed

from bearnav_cli import pipeline
from bearnav_cli.datatypes import replace, tolerance_by_area
from bearnav_cli.stages.map_ import MapSource

SECTION = "tolerance"
#: ebb27c2, rrtstar seeds 0–4: (δ* per seed, area-weighted median of min(δ_c, δ_e/2) per seed), map units.
BEFORE = {
    "kitchen": ((0.0066804, 0.00822343, 0.00644271, 0.00847306, 0.00104566),
                (0.00831721, 0.00950618, 0.0085172, 0.00879865, 0.00944834)),
    "paper_sim_circles": ((0.0265754, 0.0369296, 0.0261625, 0.0291622, 0.0242777),
                          (0.036934, 0.0520808, 0.0357967, 0.0377162, 0.0324744)),
    "paper_b_circles": ((0.0256997, 0.0299701, 0.0392036, 0.0294467, 0.0305997),
                        (0.0360844, 0.0374241, 0.0420423, 0.0415018, 0.0410052)),
    "storeroom": ((0.00375724, 0.0054392, 0.00720834, 0.00467507, 0.00404216),
                  (0.00375724, 0.0054392, 0.00970296, 0.0052341, 0.00551999)),
    "office0": ((0.00782434, 0.00148866, 0.00851286, 0.00771195, 0.00692717),
                (0.0108056, 0.00822501, 0.0114053, 0.0106694, 0.00702285)),
    "maze0": ((0.00560994, 0.00663558, 0.00842012, 0.00777843, 0.00642136),
              (0.00786593, 0.0087693, 0.00842012, 0.00939379, 0.00842912)),
    "clutter0": ((0.00648037, 0.0030017, 0.00654673, 0.00191827, 0.00670012),
                 (0.00865284, 0.0030017, 0.00860553, 0.00191827, 0.00855049)),
}  # fmt: skip


def measure(source: MapSource, seed: int, cover: str) -> dict:
    """One plan of ``source`` at rrtstar ``seed`` with ``decompose.cover = cover``, in memory."""

    def plan_it():
        map_obj = pipeline.compute(source, through="map")["map"]
        params = {k: dict(v) for k, v in map_obj.params.items()}
        params.setdefault("rrtstar", {})["seed"] = seed
        params.setdefault("decompose", {})["cover"] = cover
        return pipeline.compute(replace(map_obj, params=params))["plan"]

    seconds, plan = timed(plan_it)
    cells = plan.cells
    return {
        "least": plan.plan_tolerance,
        "median": tolerance_by_area(cells, plan.usable_tolerance)["median"],
        "F": cells.free_coverage,
        "F_m": cells.stats["free_coverage_m"],
        "cells": cells.n_cells,
        "bad": int(np.isin(plan.status, [2, 3]).sum()),
        "s": seconds,
    }


def row(name: str, cover: str, runs: list[dict], seeds: list[int]) -> list[str]:
    """One table row: before (per seed) against after."""
    least = [r["least"] for r in runs]
    median = [r["median"] for r in runs]
    before = BEFORE.get(name)
    if before is not None and set(seeds) <= set(range(len(before[0]))):
        old_least, old_median = [before[0][s] for s in seeds], [before[1][s] for s in seeds]
        before_least = ", ".join(f"{1e3 * v:.1f}" for v in old_least)
        least_ratio = f"{min(a / b for a, b in zip(least, old_least, strict=True)):.2f}×"
        medians = f"{1e2 * statistics.median(old_median):.2f} → {1e2 * statistics.median(median):.2f}"
        median_ratio = f"{min(a / b for a, b in zip(median, old_median, strict=True)):.2f}×"
    else:
        before_least, least_ratio, median_ratio = "—", "—", "—"
        medians = f"— → {1e2 * statistics.median(median):.2f}"
    return [
        name,
        cover,
        before_least,
        ", ".join(f"{1e3 * v:.1f}" for v in least),
        least_ratio,
        medians,
        median_ratio,
        f"{100 * min(r['F'] for r in runs):.1f}–{100 * max(r['F'] for r in runs):.1f}%",
        f"{100 * min(r['F_m'] for r in runs):.1f}%",
        f"{statistics.median(r['cells'] for r in runs):.0f}",
        str(sum(r["bad"] for r in runs)),
        f"{statistics.median(r['s'] for r in runs):.2f} s",
    ]


def main() -> None:
    """Measure every map at every seed and print (``--readme``: record) the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2,3,4")
    parser.add_argument("--cover", default="F", help="decompose.cover domains, comma-separated (F, F_m)")
    parser.add_argument("--readme", action="store_true", help=f"replace the '{SECTION}' section of bench/README.md")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    rows = []
    for name, source in measured_maps().items():
        for cover in args.cover.split(","):
            rows.append(row(name, cover, [measure(source, s, cover) for s in seeds], seeds))
            print(" | ".join(rows[-1]), flush=True)
    headers = [
        "map",
        "cover",
        "δ* before, per seed (mm)",
        "least τ_c after, per seed (mm)",
        "least / δ* (worst seed)",
        "median τ_c by area, before → after (cm)",
        "ratio (worst seed)",
        "F covered",
        "F_m covered",
        "cells (median)",
        "not certified",
        "plan in memory (median)",
    ]
    body = (
        f"`bench/tolerance.py`, rrtstar seeds {args.seeds}; made maps `made_maps.py` seed {MADE_SEED}; "
        f"medians by cell area, then over the seeds. {machine_line()}\n\n" + markdown_table(headers, rows)
    )
    print(body)
    if args.readme:
        replace_section(SECTION, body)


if __name__ == "__main__":
    main()
