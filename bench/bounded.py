"""The bounded-error robot (ALGORITHMS §12.2–§12.5, issue 22) after ``bearnav tags --for live``, against the filter.

For each map (the example maps and the three made for the bearings work, ``made_maps.py`` seed 0;
rrtstar seed 0) and each robot (the single integrator, and the unicycle planned for its look-ahead
point ``λ``, :data:`LOOKAHEAD`):

1. plan it, measure the liveness at ``η`` (a 60° camera; the look goes all around), and place tags
   with ``tags.propose_live_tags`` (``bearnav tags --for live``) until every cell is live;
2. re-plan the map with those tags and measure the liveness again, at ``η`` and at 0.5°;
3. run ``N`` starts uniform in ``D`` with a 60° camera and world-frame bearing errors within ``η``:
   the set estimator with errors uniform within the bound and with every error at the bound
   (``--noise-worst``), and the ``kalman`` runtime on the same starts and errors; for the single
   integrator also both under Gaussian σ = 1° noise (the stress test: the set estimator then assumes
   the map's η = 0.2°, and its bounds are broken); and the set estimator with a camera that errs by
   0.2° and a compass that errs by ``ψ`` (``--compass``, a bias per run): the heading is bounded from
   the bearings too (``bounded.common_rotation``).

Reported per run set: success from D, collisions, steps with the truth outside the set (containment
violations), empty sets, the certified share of the steps that moved, the runs that took a step that was
not, and how many of those started where ``bearnav verify``'s liveness says a start is sure to find its
cell after a look (``LiveGrid.sure_start``; the table of liveness gives that share of ``D``), looks per run
and their mean length, the mean run time, and the wall time of the whole simulation with its ratio to ``kalman``'s
(the budget: at most 2×).

    PYTHONPATH=. python bench/bounded.py [--starts 1000] [--eta 0.25] [--compass 3] [--maps kitchen,...] [--readme]
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from common import machine_line, markdown_table, measured_maps, replace_section, timed

from bearnav_cli import liveness, pipeline, tags
from bearnav_cli.runtime import PlanArrays, robot
from bearnav_cli.stages import simulate
from bearnav_cli.stages.map_ import MapSource
from bearnav_cli.world.motion import initial_headings

SECTION = "bounded"
#: The camera's own bound in the compass rows (degrees): ALGORITHMS §12.1's default ``η_cam``.
CAMERA = 0.2
#: The look-ahead λ each map's unicycle is planned with (map units): about 1% of its diagonal, and
#: at least its speed over a turn rate of 1 rad/s.
LOOKAHEAD = {
    "kitchen": 0.1,
    "paper_sim_circles": 0.5,
    "paper_b_circles": 0.5,
    "storeroom": 0.1,
    "office0": 0.1,
    "maze0": 0.1,
    "clutter0": 0.1,
}


def plan_of(source: MapSource, spec: dict, lookahead: float):
    """The plan of ``spec`` (read as ``source``) with the robot's look-ahead set to ``lookahead``, in memory."""
    spec = {**spec, "robot": {**(spec.get("robot") or {}), "lookahead": lookahead}}
    return pipeline.compute(MapSource(spec=spec, file=source.file, sha256="bench", grid=source.grid))["plan"]


def certified_cell(m: dict) -> str:
    """The certified share of the moving steps, and how many were not (a rounded 100.00% hides a few)."""
    moved = m.get("estimator_counts", {}).get("moved_steps")
    share = f"{100 * m['certified_step_fraction']:.2f}%"
    if not moved:
        return share
    uncertified = moved - round(m["certified_step_fraction"] * moved)
    return f"{share} ({uncertified:,} of {moved:,} not)"


def sure_starts(plan, params, x0: np.ndarray) -> np.ndarray:
    """Whether each start is one ``bearnav verify``'s liveness calls sure to find its cell after a look all around
    (``LiveGrid.sure_start`` at the start's axle, the camera's place, at the world-frame bound: camera and
    compass), shape (R,) bool; bounded noise only."""
    arrays = PlanArrays.from_plan(plan)
    lam = arrays.lookahead if params.dynamics == "unicycle" else 0.0
    axle = robot.lookahead_point(x0, initial_headings(arrays, x0), -lam)
    g = liveness.grid(plan, params.noise_bound_deg + (params.compass_error_deg or 0.0))
    return g.sure_start(axle, g.look(arrays.landmarks, axle)[1])


def uncertified_cell(uncertified: np.ndarray, sure: np.ndarray | None) -> str:
    """The runs that took a step that was not certified, and how many of them started where a start is sure."""
    count = f"{int(np.count_nonzero(uncertified))}"
    return count if sure is None else f"{count} ({int(np.count_nonzero(uncertified & sure))})"


def one(plan, label: str, starts: str, **options) -> tuple[list, float]:
    # defaults, then the map's own `params: simulate` (the paper maps drive at 1 unit/s), then these, as `bearnav
    # simulate` resolves them
    overrides = {"starts": starts, "fov": 60.0, "record_trajectories": False, **options}
    params = pipeline.resolve_params("simulate", plan.map.params, overrides)
    not_certified: list[np.ndarray] = []

    def watch(runs, x, certified):
        not_certified.append(runs[~certified])

    seconds, sim = timed(simulate.run, plan, params, on_step=watch)
    uncertified = np.zeros(len(sim), bool)
    uncertified[np.concatenate([np.zeros(0, np.int64), *not_certified])] = True
    # which of them started sure of their cell; Gaussian noise has no bound to be sure within
    sure = None
    if params.noise_bound_deg is not None:
        sure = sure_starts(plan, params, sim.starts) if uncertified.any() else uncertified
    m = sim.stats
    looks = m.get("looks_per_run")
    row = [
        label,
        f"{100 * (m['success_rate_in_domain'] or 0):.1f}%",
        m["outcomes"]["collision"],
        m["containment_violations"],
        m["inconsistencies"],
        certified_cell(m),
        uncertified_cell(uncertified, sure),
        "—" if looks is None else f"{looks:.1f}",
        "—" if m.get("look_time_mean_s") is None else f"{m['look_time_mean_s']:.2f} s",
        f"{m['time_mean_s']:.0f} s" if m.get("time_mean_s") else "—",
        f"{seconds:.1f} s",
    ]
    return row, seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=1000)
    parser.add_argument("--eta", type=float, default=0.25, help="world-frame bearing error bound, degrees")
    parser.add_argument("--compass", type=float, default=3.0, help="the compass's error bound ψ, degrees (0: no row)")
    parser.add_argument("--maps", default=",".join(LOOKAHEAD))
    parser.add_argument("--live-only", action="store_true", help="liveness and tags only: no closed-loop runs")
    parser.add_argument("--readme", action="store_true", help=f"replace the '{SECTION}' section of bench/README.md")
    args = parser.parse_args()
    if args.live_only and args.readme:
        parser.error("--readme writes the runs' table too: leave out --live-only")
    starts = f"domain:{args.starts}"
    every = measured_maps()
    rows, live_rows = [], []
    for name in args.maps.split(","):
        source = every[name]
        for dynamics, lam in (("single", 0.0), ("unicycle", LOOKAHEAD[name])):
            tag = f"{name}, {dynamics}" + (f" λ={lam:g}" if lam else "")
            first = plan_of(source, source.spec, lam)
            seconds, proposal = timed(
                tags.propose_live_tags, first, tags.Params(target="live", bearing_error_deg=args.eta)
            )
            plan = plan_of(source, tags.map_spec_with_tags(source.spec, proposal), lam)
            now, wider = liveness.measure(plan, args.eta), liveness.measure(plan, 0.5)
            before = proposal.live_before
            live_rows.append(
                [
                    tag,
                    len(first.map.landmarks),
                    proposal.count,
                    f"{seconds:.0f} s",
                    f"{100 * before.live_fraction:.1f}% → {100 * now.live_fraction:.1f}%",
                    f"{math.degrees(before.eta_star):.3f}° → {math.degrees(now.eta_star):.3f}°",
                    f"{100 * now.view_fraction:.1f}%",
                    f"{100 * now.start_fraction:.1f}%",
                    f"{100 * wider.live_fraction:.1f}%",
                    f"{math.degrees(wider.eta_star):.3f}°",
                ]
            )
            print(" | ".join(map(str, live_rows[-1])), flush=True)
            if args.live_only:
                continue
            base = {"dynamics": dynamics, "noise_bound_deg": args.eta}
            kalman, t_kalman = one(plan, f"{tag}: kalman", starts, estimator="kalman", **base)
            uniform, t_set = one(plan, f"{tag}: set", starts, estimator="set", **base)
            worst, _ = one(plan, f"{tag}: set, worst", starts, estimator="set", noise_worst=True, **base)
            uniform[-1] += f" ({t_set / t_kalman:.2f}×)"
            rows += [kalman, uniform, worst]
            # a camera within 0.2° and a compass within ψ: η = 0.2° + ψ, narrowed by the bearings
            if args.compass > 0.0:
                bias = {"dynamics": dynamics, "noise_bound_deg": CAMERA, "compass_error_deg": args.compass}
                rows += [
                    one(
                        plan,
                        f"{tag}: set, camera {CAMERA}° + compass {args.compass:g}°{w}",
                        starts,
                        estimator="set",
                        noise_worst=bool(w),
                        **bias,
                    )[0]
                    for w in ("", ", worst")
                ]
            if dynamics == "single":  # the stress test: Gaussian σ = 1°, beyond any bound the robot assumes
                stress = {"dynamics": dynamics, "noise_deg": 1.0}
                rows += [
                    one(plan, f"{tag}: kalman, Gaussian σ=1°", starts, estimator="kalman", **stress)[0],
                    one(plan, f"{tag}: set, Gaussian σ=1°", starts, estimator="set", **stress)[0],
                ]
            shown = (5 if dynamics == "single" else 3) + (2 if args.compass > 0.0 else 0)
            print(*(" | ".join(map(str, r)) for r in rows[-shown:]), sep="\n", flush=True)
    live_headers = [
        "plan",
        "tags of the map",
        "added (--for live)",
        "placing took",
        f"live at η = {args.eta}° (before → after)",
        "η* (before → after)",
        "live after one view (no turn all around)",
        "sure start (after a look)",
        "live at η = 0.5°",
        "η* measured at 0.5°",
    ]
    headers = [
        "plan: estimator",
        "success from D",
        "collisions",
        "truth outside set",
        "empty sets",
        "certified moving steps",
        "runs not certified (from sure starts)",
        "looks / run",
        "mean look",
        "mean run",
        "wall (set/kalman)",
    ]
    body = (
        f"Each map planned (rrtstar seed 0), then `bearnav tags --for live --bearing-error-deg {args.eta}` "
        f"(`tags.propose_live_tags`), then planned again with those tags. Liveness measured by "
        f"`bearnav verify --live-fov 60` on the default grid; a look turns all around.\n\n"
        + markdown_table(live_headers, live_rows)
    )
    if not args.live_only:
        body += (
            f"\n\n{args.starts} starts uniform in D, 60° camera, bearing errors within η = {args.eta}° "
            f"(world frame), "
            f"odometry within κ‖d̂‖ + ν (κ = 0.03, ν = 1e-4·D); in the compass rows the camera errs within {CAMERA}° "
            f"and the compass by a bias per run within ψ = {args.compass:g}° (±ψ under worst), and the robot bounds "
            f"its heading from the bearings as well. {machine_line(('numpy', 'shapely'))}\n\n"
            + markdown_table(headers, rows)
        )
    print(body)
    if args.readme:
        replace_section(SECTION, body)


if __name__ == "__main__":
    main()
