"""The bounded-error robot (ALGORITHMS §12.2–§12.3, issue 22) against the filter, on the same starts.

For each example map (planned once, rrtstar seed 0, with the look-ahead λ given; 0: the single
integrator), ``N`` starts uniform in ``D`` run with a 60° camera and world-frame bearing errors
bounded by ``η``: the set estimator with errors uniform within the bound and with every error at
the bound (``--noise-worst``), and the ``kalman`` runtime on the same starts and errors; for the
single integrator also both under Gaussian σ = 1° noise (the stress test: the set estimator then
assumes the map's η = 0.2°, and its bounds are broken). Reported per run set: success from D,
collisions, steps with the truth outside the set (containment violations), empty sets, the
certified share of the steps that moved, looks per run and their mean length, the mean run time,
and the wall time of the whole simulation with its ratio to ``kalman``'s (the budget: at most 2×).

    PYTHONPATH=. python bench/bounded.py [--starts 1000] [--eta 0.25] [--maps kitchen,...] [--readme]
"""

from __future__ import annotations

import argparse

from bearnav_cli.stages import simulate
from bench.common import REPO_DIR, machine_line, markdown_table, replace_section, run_stages, timed

SECTION = "bounded"
#: Example maps and the look-ahead each is planned with for the unicycle rows (map units).
MAPS = {"kitchen": 0.1, "paper_sim_circles": 0.5, "paper_b_circles": 0.5}


def plan_for(name: str, lookahead: float):
    """The example map's plan, rrtstar seed 0, with the robot's look-ahead set to ``lookahead``."""
    import yaml

    from bearnav_cli import pipeline
    from bearnav_cli.stages import map_ as map_stage

    path = REPO_DIR / "maps" / f"{name}.yaml"
    spec = yaml.safe_load(path.read_text())
    spec["robot"] = {**(spec.get("robot") or {}), "lookahead": lookahead}
    map_obj = pipeline.compute(map_stage.MapSource(spec=spec, file=path.name, sha256="bench"), through="map")["map"]
    return run_stages(map_obj, ["rrtstar", "simplify", "decompose", "synthesize"])


def one(plan, label: str, starts: str, **options) -> tuple[list, float]:
    params = simulate.Params(starts=starts, fov=60.0, record_trajectories=False, **options)
    seconds, sim = timed(simulate.run, plan, params)
    m = sim.stats
    looks = m.get("looks_per_run")
    row = [label, f"{100 * (m['success_rate_in_domain'] or 0):.1f}%", m["outcomes"]["collision"],
           m["containment_violations"], m["inconsistencies"], f"{100 * m['certified_step_fraction']:.1f}%",
           "—" if looks is None else f"{looks:.1f}",
           "—" if m.get("look_time_mean_s") is None else f"{m['look_time_mean_s']:.2f} s",
           f"{m['time_mean_s']:.0f} s" if m.get("time_mean_s") else "—", f"{seconds:.1f} s"]  # fmt: skip
    return row, seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=1000)
    parser.add_argument("--eta", type=float, default=0.25, help="world-frame bearing error bound, degrees")
    parser.add_argument("--maps", default=",".join(MAPS))
    parser.add_argument("--readme", action="store_true", help=f"replace the '{SECTION}' section of bench/README.md")
    args = parser.parse_args()
    starts = f"domain:{args.starts}"
    rows = []
    for name in args.maps.split(","):
        for dynamics, lam in (("single", 0.0), ("unicycle", MAPS[name])):
            plan = plan_for(name, lam)
            tag = f"{name}, {dynamics}" + (f" λ={lam:g}" if lam else "")
            base = {"dynamics": dynamics, "noise_bound_deg": args.eta}
            kalman, t_kalman = one(plan, f"{tag}: kalman", starts, estimator="kalman", **base)
            uniform, t_set = one(plan, f"{tag}: set", starts, estimator="set", **base)
            worst, _ = one(plan, f"{tag}: set, worst", starts, estimator="set", noise_worst=True, **base)
            uniform[-1] += f" ({t_set / t_kalman:.2f}×)"
            rows += [kalman, uniform, worst]
            if dynamics == "single":  # the stress test: Gaussian σ = 1°, beyond any bound the robot assumes
                stress = {"dynamics": dynamics, "noise_deg": 1.0}
                rows += [one(plan, f"{tag}: kalman, Gaussian σ=1°", starts, estimator="kalman", **stress)[0],
                         one(plan, f"{tag}: set, Gaussian σ=1°", starts, estimator="set", **stress)[0]]  # fmt: skip
            print(*(" | ".join(map(str, r)) for r in rows[-5:]), sep="\n", flush=True)
    headers = ["plan: estimator", "success from D", "collisions", "truth outside set", "empty sets",
               "certified moving steps", "looks / run", "mean look", "mean run", "wall (set/kalman)"]  # fmt: skip
    body = (f"{args.starts} starts uniform in D, 60° camera, bearing errors within η = {args.eta}° (world frame), "
            f"odometry within κ‖d̂‖ + ν (κ = 0.03, ν = 1e-4·D); rrtstar seed 0. {machine_line(('numpy', 'shapely'))}\n\n"
            + markdown_table(headers, rows))  # fmt: skip
    print(body)
    if args.readme:
        replace_section(SECTION, body)


if __name__ == "__main__":
    main()
