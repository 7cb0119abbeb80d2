"""Every example map with RRT* seeds 0–4: is the composition proved (ALGORITHMS §11.6)?

For each of ``maps/kitchen.yaml``, ``maps/paper_sim_circles.yaml``, ``maps/paper_b_circles.yaml``
and ``maps/storeroom.yaml`` and each seed, the chain map → rrtstar (that seed, the map's other
parameters) → simplify → decompose → synthesize runs in-process, then:

* the cells with status 2 or 3 (Lemma 4 says none for funnel cells);
* :func:`bearnav_cli.composition.check`: every §11.6 check from the plan alone, the coverage of
  the reached part of ``F_m`` and ``δ*``;
* :func:`bearnav_cli.verify.run` with its default closed loop (displacements, full view) from
  ``--starts`` random free starts (seed 0): the success rate from the certified domain ``D``
  (anything short of 100% is a bug) and apart from ``F \\ D``.

Plan time is the in-process time of the five stages (no interpreter start-up). Not a timing
benchmark: it records that the issue's "every example map with seeds 0–4" holds.

Run from the repository root::

    PYTHONPATH=. python bench/examples.py [--starts 100] [--readme]
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np
from common import REPO_DIR, machine_line, markdown_table, replace_section

from bearnav_cli import composition, pipeline, verify
from bearnav_cli.cli import read_map_source
from bearnav_cli.datatypes import CellStatus

SECTION = "examples"
MAPS = ("kitchen", "paper_sim_circles", "paper_b_circles", "storeroom")
SEEDS = range(5)


def measure(name: str, seed: int, starts: int) -> list:
    """One table row: the plan of ``name`` with RRT* seed ``seed`` and what verify proves of it."""
    base = pipeline.compute(read_map_source(REPO_DIR / "maps" / f"{name}.yaml"), through="map")["map"]
    started = time.perf_counter()
    plan = pipeline.compute(base, overrides={"rrtstar": {"seed": seed}})["plan"]
    elapsed = time.perf_counter() - started
    cells = plan.cells
    comp = composition.check(plan, verify.Params().speed)
    failed = int(np.isin(plan.status, [CellStatus.NOT_CERTIFIED, CellStatus.SOLVER_FAILURE]).sum())
    report = verify.run(plan, verify.Params(n_starts=starts))
    inside = int(report.in_domain.sum())
    outside = len(report.in_domain) - inside
    return [
        f"`{name}`",
        seed,
        cells.n_cells,
        int(cells.node_added.sum()),
        failed,
        "all pass" if comp.ok else "; ".join(comp.problems),
        f"{comp.coverage:.1%}",
        f"{cells.stats.get('unreached_area', 0.0):.3g}",
        f"{plan.plan_tolerance:.3g}",
        "pass" if not report.failed else "FAIL: " + "; ".join(report.reasons),
        f"{report.success_in_domain:.0%} of {inside}",
        outside,
        f"{elapsed:.2f}",
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=100, help="verify's random starts per plan")
    parser.add_argument("--readme", action="store_true", help="write the table into bench/README.md")
    args = parser.parse_args()
    logging.disable(logging.WARNING)  # each plan's own warnings (landmark flags) are not the subject here
    rows = []
    for name in MAPS:
        for seed in SEEDS:
            rows.append(measure(name, seed, args.starts))
            print(" | ".join(str(c) for c in rows[-1]), flush=True)
    headers = [
        "map",
        "seed",
        "cells",
        "added",
        "status 2/3",
        "§11.6 checks",
        "F_m covered (reached part)",
        "F_m cut off (units²)",
        "δ*",
        "verify",
        "success from D",
        "starts outside D",
        "plan s",
    ]
    ok = sum(r[4] == 0 and r[5] == "all pass" and r[9] == "pass" for r in rows)
    body = "\n\n".join(
        [
            "## Example maps × seeds 0–4",
            "`bench/examples.py`: " + __doc__.split("\n\n")[1].replace("\n", " ").strip(),
            machine_line(("numpy", "shapely", "highspy")),
            markdown_table(headers, rows),
            f"{ok} of {len(rows)} plans: no cell with status 2 or 3, every §11.6 check passes, verify passes.",
        ]
    )
    print(body)
    if args.readme:
        replace_section(SECTION, body)


if __name__ == "__main__":
    main()
