"""Benchmark: the vectorised closed loop against a per-robot Python loop of the same step (DESIGN §7).

The kitchen plan is built in-process by ``map → rrtstar → simplify → decompose →
synthesize`` with the map's parameters, and ``simulate.Params(starts="random:N")`` draws
the starts through ``simulate.resolve_starts``. For three configurations (the defaults:
bearings, 360° field of view, occlusion, noise-free bearings, 2% wheel slip, single
integrator; ``odometry_noise=0``; ``fov=60`` with the unicycle; ``noise_deg=1``), all with
``record_trajectories=False``, three things are timed side by side in each round:

* **vectorised**: ``simulate.rollout(plan, starts, params)``, every robot advanced
  together as arrays;
* **per-robot loop**: the anchor. The same setup as ``rollout`` (``simulate.start_loop``:
  plan arrays, the simulated world, settings, step limits, initial headings), then, robot
  by robot, ``loop.step(np.array([i]))`` until that robot has finished: exactly the
  step ``rollout`` runs, with ``R = 1`` arrays;
* **rollout per robot**: ``simulate.rollout(plan, starts[i:i + 1], params)`` for each
  robot, per-call setup included (nothing subtracted).

The two per-robot variants run on the first ``--loop-robots`` starts (they are drawn
uniformly, so any subset is a random one) and their times are scaled linearly to all
the starts. The order of the variants rotates between rounds; times are medians over the
rounds. Noise-free and with exact motion, the per-robot runs must end exactly as the
vectorised ones (outcome and step count of every compared robot); with bearing noise or wheel
slip the random streams differ, so there is nothing to compare. The budget is 1,000 starts in under 5 s.

Run from the repository root::

    PYTHONPATH=. python bench/simulate.py [--quick] [--readme]

The markdown goes to stdout; ``--readme`` replaces the ``simulate`` section of
``bench/README.md``.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from common import README, REPO_DIR, load_map, machine_line, markdown_table, replace_section

from bearnav_cli import pipeline
from bearnav_cli.datatypes import Plan
from bearnav_cli.stages import simulate

SECTION = "simulate"
MAP = REPO_DIR / "maps" / "kitchen.yaml"
#: (label, Params overrides); the first is the default configuration the budget applies to.
CONFIGS = (
    ("default (bearing, 360°, occlusion, noise-free bearings, 2% wheel slip, single integrator)", {}),
    ("exact motion (odometry_noise 0)", {"odometry_noise": 0.0}),
    ("fov 60°, unicycle", {"fov": 60.0, "dynamics": "unicycle"}),
    ("noise 1°", {"noise_deg": 1.0}),
)
ROBOTS = 1000
ROUNDS = 5
LOOP_ROBOTS = 100
BUDGET_S = 5.0
BUDGET_ROBOTS = 1000


def kitchen_plan() -> Plan:
    """The kitchen map's plan, built in-process with the map's stage parameters."""
    return pipeline.compute(load_map(MAP))["plan"]


def per_robot_loop(plan: Plan, starts: np.ndarray, params: simulate.Params) -> tuple[np.ndarray, np.ndarray]:
    """Outcome and steps of every start, one robot at a time through ``world.loop.Loop.step``.

    The setup is ``simulate.rollout``'s (``simulate.start_loop``), done once for all the starts;
    then each robot is stepped alone (``R = 1`` arrays) until it has an outcome.
    """
    loop, active, _ = simulate.start_loop(plan, starts, params)
    for i in active:
        one = np.array([i])
        while one.size:
            one = loop.step(one)
    return loop.outcome.copy(), loop.steps.copy()


def rollout_per_robot(plan: Plan, starts: np.ndarray, params: simulate.Params) -> tuple[np.ndarray, np.ndarray]:
    """Outcome and steps of every start, ``simulate.rollout`` called with one start at a time."""
    runs = [simulate.rollout(plan, starts[i : i + 1], params) for i in range(len(starts))]
    return np.concatenate([r.outcome for r in runs]), np.concatenate([r.steps for r in runs])


def compare(
    plan: Plan, starts: np.ndarray, params: simulate.Params, n_loop: int, rounds: int
) -> tuple[dict[str, float], dict]:
    """Median seconds of the three variants (the per-robot ones on ``starts[:n_loop]``), and their results."""
    clock = time.perf_counter
    subset = starts[:n_loop]
    results: dict = {}

    def vectorised() -> None:
        results["vectorised"] = simulate.rollout(plan, starts, params)

    def loop() -> None:
        results["loop"] = per_robot_loop(plan, subset, params)

    def per_call() -> None:
        results["per_call"] = rollout_per_robot(plan, subset, params)

    variants = [("vectorised", vectorised), ("loop", loop), ("per_call", per_call)]
    times = {name: [] for name, _ in variants}
    for r in range(rounds):
        k = r % len(variants)
        for name, fn in variants[k:] + variants[:k]:
            t0 = clock()
            fn()
            times[name].append(clock() - t0)
    return {name: float(np.median(t)) for name, t in times.items()}, results


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark, print the table and, with ``--readme``, record it."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smoke test: 1 round, 100 starts, 20 per-robot runs")
    parser.add_argument("--readme", action="store_true", help=f"replace the '{SECTION}' section of {README}")
    parser.add_argument("--robots", type=int, default=None, help=f"random starts (default {ROBOTS}; 100 quick)")
    parser.add_argument("--rounds", type=int, default=None, help=f"rounds (default {ROUNDS}; 1 quick)")
    parser.add_argument(
        "--loop-robots",
        type=int,
        default=None,
        help=f"starts run one at a time, scaled to all (default {LOOP_ROBOTS}; 20 quick)",
    )
    args = parser.parse_args(argv)
    n = args.robots or (100 if args.quick else ROBOTS)
    rounds = args.rounds or (1 if args.quick else ROUNDS)
    n_loop = min(n, args.loop_robots or (20 if args.quick else LOOP_ROBOTS))
    scale = n / n_loop

    log("building the kitchen plan …")
    plan = kitchen_plan()
    starts = simulate.resolve_starts(plan, simulate.Params(starts=f"random:{n}"))
    simulate.rollout(plan, starts[:10], simulate.Params(record_trajectories=False))  # warm-up
    rows, verdict, checks = [], "", []
    for label, overrides in CONFIGS:
        params = simulate.Params(starts=f"random:{n}", record_trajectories=False, **overrides)
        log(f"{label}: {n} robots (per-robot variants on {n_loop}) × {rounds} rounds …")
        t, res = compare(plan, starts, params, n_loop, rounds)
        vec = res["vectorised"]
        loop_s, call_s = t["loop"] * scale, t["per_call"] * scale
        ratio, call_ratio = loop_s / t["vectorised"], call_s / t["vectorised"]
        counts = vec.counts()
        outcomes = ", ".join(f"{k} {v}" for k, v in counts.items() if v)
        if params.noise_deg == 0 and params.odometry_noise == 0:
            same = [
                bool(np.array_equal(vec.outcome[:n_loop], o) and np.array_equal(vec.steps[:n_loop], s))
                for o, s in (res["loop"], res["per_call"])
            ]
            identical = "yes" if all(same) else f"NO (loop {same[0]}, rollout per robot {same[1]})"
            checks.append((label, all(same)))
        else:
            identical = "n/a (noise or slip)"
        share = vec.steps[:n_loop].sum() / max(1, vec.steps.sum())
        rows.append(
            [
                label,
                f"{n:,}",
                outcomes,
                f"{int(vec.steps.max()):,}",
                f"{int(vec.steps.sum()):,}",
                f"{t['vectorised']:.2f}",
                f"{loop_s:.1f}",
                f"{call_s:.1f}",
                f"{ratio:.1f}",
                f"{call_ratio:.1f}",
                f"{share * n / n_loop:.2f}",
                identical,
            ]
        )
        log(
            f"  vectorised {t['vectorised']:.2f} s, per-robot loop {loop_s:.1f} s (×{ratio:.1f}), "
            f"rollout per robot {call_s:.1f} s (×{call_ratio:.1f}), identical: {identical}"
        )
        if not overrides:
            if n >= BUDGET_ROBOTS:
                met = "met" if t["vectorised"] < BUDGET_S else "NOT met"
                budget = f"budget {BUDGET_S:g} s for {BUDGET_ROBOTS:,} starts: {met}"
            else:
                budget = f"the {BUDGET_S:g} s budget is for {BUDGET_ROBOTS:,} starts, not judged here"
            verdict = (
                f"Default configuration: {n:,} robots in {t['vectorised']:.2f} s vectorised ({budget}); "
                f"the per-robot loop of the same step takes {loop_s:.1f} s (scaled from {n_loop}), a speed-up of "
                f"{ratio:.1f}×; calling `rollout` once per robot takes {call_s:.1f} s ({call_ratio:.1f}×)."
            )

    headers = [
        "configuration",
        "robots",
        "outcomes (vectorised)",
        "lock-step iterations",
        "robot-steps",
        "vectorised median s",
        "per-robot loop median s (scaled)",
        "rollout per robot median s (scaled)",
        "speed-up (loop / vectorised)",
        "speed-up (rollout per robot / vectorised)",
        "subset step share × scale",
        "same outcomes and steps",
    ]
    command = f"`bench/simulate.py{' --quick' if args.quick else ''}`"
    text = (
        f"{command}: the plan of `maps/kitchen.yaml`, built in-process by map → rrtstar → simplify → decompose → "
        f"synthesize with the map's parameters; {n:,} starts from `simulate.Params(starts='random:{n}')` "
        "(`resolve_starts`, seed 0), the same starts for every configuration; `record_trajectories=False`, "
        "other parameters default unless named. *vectorised*: `simulate.rollout(plan, starts, params)`, all robots "
        "as arrays. *per-robot loop*: `rollout`'s setup once, then `world.loop.Loop.step` called with one robot "
        "(`R = 1` arrays) until that robot finishes, robot after robot: the same step function, one robot at a "
        "time. *rollout per robot*: `simulate.rollout(plan, starts[i:i+1], params)` for each robot, per-call "
        f"setup included, nothing subtracted. Both per-robot variants run on the first {n_loop} starts and are "
        f"scaled linearly by {scale:g} to all {n:,}; *subset step share × scale* is that subset's share of the "
        "robot-steps times the scale (1 means the subset is representative; the per-robot time is about "
        "proportional to robot-steps). Speed-ups are (per-robot total) / (vectorised total). Noise-free, "
        "every compared robot must end with the same outcome after the same number of steps in all variants; "
        "with noise the random streams differ. The variants run side by side in each round, the order "
        f"rotating; medians over {rounds} round{'s' if rounds > 1 else ''}. Budget: {BUDGET_ROBOTS:,} starts "
        f"in under {BUDGET_S:g} s."
    )
    parts = ["## Simulation", text, machine_line(("numpy", "shapely")), markdown_table(headers, rows)]
    body = "\n\n".join(parts + ([verdict] if verdict else []))
    print(body)
    if args.readme:
        replace_section(SECTION, body, README)
    if not all(ok for _, ok in checks):
        log("the per-robot runs did not end as the vectorised ones: " + ", ".join(lb for lb, ok in checks if not ok))
        sys.exit(1)


if __name__ == "__main__":
    main()
