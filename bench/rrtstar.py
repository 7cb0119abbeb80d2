"""Benchmark: bearnav's RRT* against OMPL's ``RRTstar`` on the same maps (DESIGN §7).

For each map and iteration count both planners run the same number of iterations
with seeds 0–4 and the median wall time is reported, with tree sizes and the best
cost to the map's first start. OMPL gets a Python state-validity callback doing one
prepared shapely point query, as in DESIGN §7; its other settings stay at their
defaults. A growth table checks that our RRT* time grows no faster than n log n,
and times the ``simplify`` stage on the same trees when that stage exists.

Run from the repository root::

    PYTHONPATH=. python bench/rrtstar.py [--quick]

The markdown goes to stdout and, unless ``--quick``, replaces the ``rrtstar``
section of ``bench/README.md``. OMPL (PyPI ``ompl``) is needed only here; bearnav
itself never imports it.
"""

from __future__ import annotations

import argparse
import importlib
import math
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Callable

import numpy as np
import shapely
from common import (
    BENCH_DIR,
    MADE_SEED,
    README,
    REPO_DIR,
    load_map,
    machine_line,
    markdown_table,
    replace_section,
    timed,
)
from made_maps import KINDS
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from bearnav_cli import pipeline
from bearnav_cli.datatypes import Map, Tree
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.stages import map_ as map_stage
from bearnav_cli.stages import rrtstar

#: (name, map file or ``made_maps.py`` kind, RRT* step) of the compared maps; the growth table uses the first.
MAPS = (
    ("kitchen", REPO_DIR / "maps" / "kitchen.yaml", 1.0),
    ("box500", BENCH_DIR / "maps" / "box500.yaml", 25.0),
    ("office", "office", 1.0),  # rooms off a corridor, 14 × 9 m, that nobody tuned bearnav for
)
ITERATIONS = (1500, 10_000)
SEEDS = (0, 1, 2, 3, 4)
GROWTH = (2000, 5000, 20_000)
GROWTH_RUNS = 3
#: OMPL's goal region radius, as a fraction of the step.
GOAL_THRESHOLD = 0.01
SECTION = "rrtstar"
DESCRIPTION = (
    "bearnav's RRT* (exact edge checks, tree rooted at the goal) against OMPL's `RRTstar` with a Python "
    "validity callback (one prepared shapely point query), the same number of iterations, range = our "
    "step, other OMPL settings default. Times are medians over the runs; planner setup is timed for "
    "both, map loading for neither."
)
COMPARE_HEADERS = (
    "map",
    "iterations",
    "our median s",
    "OMPL median s",
    "ratio (ours/OMPL)",
    "our vertices",
    "OMPL vertices",
    "our best cost to the start",
    "OMPL best cost",
)
COUNT_HEADERS = ("map", "iterations", "OMPL validity calls", "calls per iteration", "OMPL motions checked")
MOTION_NOTE = (
    "Note: OMPL's default motion check is discrete (states every 1% of the space's maximum extent "
    "are tested) and can clip obstacle corners; ours tests every edge exactly (segment against polygon)."
)


@dataclass(frozen=True)
class Result:
    """One planner run.

    Attributes
    ----------
    seconds : float
        Wall time of the planner call.
    vertices : int
        Vertices in the final tree.
    cost : float
        Best path length to the map's first start (``inf`` if none was found).
    """

    seconds: float
    vertices: int
    cost: float


def log(message: str) -> None:
    """Progress on stderr, so stdout holds only the markdown."""
    print(message, file=sys.stderr, flush=True)


def best_cost_to(tree: Tree, space: FreeSpace, target: np.ndarray) -> float:
    """Cheapest way to reach ``target`` through the tree: ``min cost(v) + ‖target − x_v‖``.

    Only nodes with a free straight segment to ``target`` count.

    Parameters
    ----------
    tree : Tree
        A tree rooted at the goal.
    space : FreeSpace
        The map's free space.
    target : ndarray, shape (2,)
        The point to reach (map units).

    Returns
    -------
    float
        Path length in map units, ``inf`` if no node sees ``target``.
    """
    free = space.segments_free(tree.nodes, target)
    if not free.any():
        return math.inf
    reach = tree.cost[free] + np.hypot(*(tree.nodes[free] - target).T)
    return float(reach.min())


def map_of(source: Path | str) -> Map:
    """The normalised map of a map file, or of a ``made_maps.py`` kind (seed :data:`MADE_SEED`)."""
    if isinstance(source, Path):
        return load_map(source)
    spec = KINDS[source](MADE_SEED)
    made = map_stage.MapSource(spec=spec, file=f"{spec['name']}.yaml", sha256="bench")
    return pipeline.compute(made, through="map")["map"]


def run_ours(map_: Map, space: FreeSpace, step: float, iterations: int, seed: int) -> tuple[Result, Tree]:
    """Time one call of our ``rrtstar.run`` (the map is built beforehand)."""
    params = rrtstar.Params(iterations=iterations, step=step, seed=seed, clearance=0.0)  # the validity OMPL checks
    seconds, tree = timed(rrtstar.run, map_, params)
    return Result(seconds, len(tree.nodes), best_cost_to(tree, space, map_.starts[0])), tree


def validity_checker(obstacles: shapely.Geometry, calls: list[int] | None = None) -> Callable[[object], bool]:
    """OMPL state-validity callback: one prepared point query against the inflated obstacles.

    Parameters
    ----------
    obstacles : shapely.Geometry
        Prepared union of the inflated obstacles (``FreeSpace.obstacles``).
    calls : list of int, optional
        If given, ``calls[0]`` is incremented on every call (for counting runs only).
    """
    intersects_xy = shapely.intersects_xy

    def valid(state: object) -> bool:
        return not intersects_xy(obstacles, state[0], state[1])

    if calls is None:
        return valid

    def counted(state: object) -> bool:
        calls[0] += 1
        return valid(state)

    return counted


def run_ompl(
    map_: Map, obstacles: shapely.Geometry, step: float, iterations: int, calls: list[int] | None = None
) -> tuple[Result, int]:
    """Time OMPL's ``RRTstar`` for exactly ``iterations`` iterations.

    The tree is rooted at the map's goal (OMPL's start) and aims at the map's first
    start (OMPL's goal, radius ``GOAL_THRESHOLD · step``). Setup and solve are timed.

    Returns
    -------
    result : Result
        Time, tree size and solution length (``inf`` without an exact solution).
    motions : int
        Motions checked by OMPL's motion validator.
    """
    t0 = time.perf_counter()
    space = ob.RealVectorStateSpace(2)
    bounds = ob.RealVectorBounds(2)
    for k in range(2):
        bounds.setLow(k, float(map_.bounds[k]))
        bounds.setHigh(k, float(map_.bounds[k + 2]))
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    si.setStateValidityChecker(validity_checker(obstacles, calls))
    si.setup()
    start, goal = si.allocState(), si.allocState()
    for k in range(2):
        start[k] = float(map_.goal[k])
        goal[k] = float(map_.starts[0][k])
    problem = ob.ProblemDefinition(si)
    problem.setStartAndGoalStates(start, goal, GOAL_THRESHOLD * step)
    planner = og.RRTstar(si)
    planner.setRange(step)
    planner.setProblemDefinition(problem)
    planner.setup()
    planner.solve(ob.PlannerTerminationCondition(lambda: planner.numIterations() >= iterations))
    seconds = time.perf_counter() - t0

    if planner.numIterations() != iterations:
        raise RuntimeError(f"OMPL ran {planner.numIterations()} iterations, expected {iterations}")
    data = ob.PlannerData(si)
    planner.getPlannerData(data)
    cost = problem.getSolutionPath().length() if problem.hasExactSolution() else math.inf
    return Result(seconds, data.numVertices(), cost), si.getCheckedMotionCount()


def cost_cell(costs: list[float]) -> str:
    """Median of the finite costs, with how many runs found one when not all did."""
    found = [c for c in costs if math.isfinite(c)]
    if not found:
        return "none"
    text = f"{statistics.median(found):.3f}"
    return text if len(found) == len(costs) else f"{text} ({len(found)}/{len(costs)} runs)"


def compare(iteration_counts: tuple[int, ...], seeds: tuple[int, ...]) -> str:
    """Side-by-side table of our RRT* and OMPL's RRTstar, plus OMPL's callback counts."""
    rows, count_rows = [], []
    for name, source, step in MAPS:
        map_ = map_of(source)
        space = FreeSpace.from_map(map_)
        for n in iteration_counts:
            ours, theirs = [], []
            for seed in seeds:  # alternate the planners so load from elsewhere hits both alike
                ours.append(run_ours(map_, space, step, n, seed)[0])
                theirs.append(run_ompl(map_, space.obstacles, step, n)[0])
            t_ours = statistics.median(r.seconds for r in ours)
            t_ompl = statistics.median(r.seconds for r in theirs)
            log(f"{name} {n}: ours {t_ours:.3f} s, OMPL {t_ompl:.3f} s")
            times = [f"{t_ours:.3f}", f"{t_ompl:.3f}", f"{t_ours / t_ompl:.2f}"]
            vertices = [f"{statistics.median(r.vertices for r in runs):.0f}" for runs in (ours, theirs)]
            costs = [cost_cell([r.cost for r in runs]) for runs in (ours, theirs)]
            rows.append([name, f"{n:,}", *times, *vertices, *costs])
            calls = [0]
            _, motions = run_ompl(map_, space.obstacles, step, n, calls)  # untimed counting run
            count_rows.append([name, f"{n:,}", f"{calls[0]:,}", f"{calls[0] / n:.1f}", f"{motions:,}"])
    table = markdown_table(COMPARE_HEADERS, rows)
    counts = markdown_table(COUNT_HEADERS, count_rows)
    return f"{table}\n\n{MOTION_NOTE}\n\nOMPL validity-callback calls in one extra, untimed run:\n\n{counts}"


def load_simplify() -> tuple[ModuleType | None, str]:
    """The ``simplify`` stage if it exists and imports, else ``None`` and the reason."""
    try:
        return importlib.import_module("bearnav_cli.stages.simplify"), ""
    except Exception as exc:  # a stage under construction may fail in any way
        return None, f"{type(exc).__name__}: {exc}"


def growth(iteration_counts: tuple[int, ...], runs: int) -> str:
    """Our RRT* time (and ``simplify`` time) against n log n on the kitchen map."""
    name, source, step = MAPS[0]
    map_ = map_of(source)
    space = FreeSpace.from_map(map_)
    simplify, reason = load_simplify()
    times: dict[int, list[float]] = {n: [] for n in iteration_counts}
    simplify_times: dict[int, list[float]] = {n: [] for n in iteration_counts}
    # round -1 is not timed: what a process does once (simplify imports scipy.spatial, a fifth of a second,
    # for its first k-d tree query at the largest size) is not growth, and with three runs it would decide
    # the median; then round-robin over the sizes so load from elsewhere hits all alike
    for seed in range(-1, runs):
        for n in iteration_counts:
            result, tree = run_ours(map_, space, step, n, seed if seed >= 0 else runs)
            seconds = None
            if simplify is not None:
                try:
                    seconds = timed(simplify.run, tree)[0]
                except Exception as exc:  # report, do not fail the benchmark
                    simplify, reason = None, f"simplify.run raised {type(exc).__name__}: {exc}"
            if seed >= 0:
                times[n].append(result.seconds)
                if seconds is not None:
                    simplify_times[n].append(seconds)
    t_rrt = {n: statistics.median(times[n]) for n in iteration_counts}
    log("growth: " + ", ".join(f"{n}: {t:.3f} s" for n, t in t_rrt.items()))

    base = iteration_counts[0]
    nlogn = {n: n * math.log(n) / (base * math.log(base)) for n in iteration_counts}
    headers = ["iterations", "our median s", "time ratio", "n log n ratio"]
    rows = [[f"{n:,}", f"{t_rrt[n]:.3f}", f"{t_rrt[n] / t_rrt[base]:.2f}", f"{nlogn[n]:.2f}"] for n in t_rrt]
    if simplify is not None:
        headers += ["simplify median s", "simplify time ratio"]
        t_simplify = {n: statistics.median(simplify_times[n]) for n in iteration_counts}
        for row, n in zip(rows, iteration_counts, strict=True):
            row += [f"{t_simplify[n]:.3f}", f"{t_simplify[n] / t_simplify[base]:.2f}"]
    text = (
        f"Growth on {name} (step {step:g}), median of {runs} run(s) after one untimed round, ratios relative to "
        f"{base:,} iterations:"
        f"\n\n{markdown_table(headers, rows)}"
    )
    if simplify is None:
        text += f"\n\nsimplify: not available ({reason})"
    return text


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark and print (and, unless ``--quick``, record) the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick", action="store_true", help="smoke test: 1 run, 1,500 iterations only; README untouched"
    )
    parser.add_argument(
        "--readme", type=Path, default=None, help=f"file to update (default {README}; also with --quick)"
    )
    args = parser.parse_args(argv)

    ou.setLogLevel(ou.LOG_WARN)
    ou.RNG.setSeed(1)  # once, before OMPL's first sampler: the sequence of OMPL runs is repeatable
    iteration_counts = ITERATIONS[:1] if args.quick else ITERATIONS
    seeds = SEEDS[:1] if args.quick else SEEDS
    runs = 1 if args.quick else GROWTH_RUNS
    growth_counts = GROWTH[:2] if args.quick else GROWTH

    command = f"`bench/rrtstar.py{' --quick' if args.quick else ''}`"
    seeding = f"Seeds {seeds[0]}–{seeds[-1]} for ours; OMPL's global seed is set once per process."
    parts = ["## RRT*", f"{command}: {DESCRIPTION} {seeding}", machine_line()]
    parts += [compare(iteration_counts, seeds), growth(growth_counts, runs)]
    body = "\n\n".join(parts)
    print(body)
    if args.readme is not None or not args.quick:
        replace_section(SECTION, body, args.readme or README)


if __name__ == "__main__":
    main()
