"""The runs of the bearing paper's simulation figure (§IV-A, panel d) on a unicycle with a 60° camera.

The kitchen plan's four starts, driven by bearings seen through a 60° field of view centred
on the unicycle's heading (occlusion by the raw obstacles, the map's own ``simulate``
parameters otherwise). The camera's view cone is drawn at regular intervals along each
path.

Usage::

    .venv/bin/python repro/kitchen_unicycle.py plans/kitchen/plan.npz -o docs/figures/kitchen_unicycle.png

writes the figure and ``kitchen_unicycle.json`` next to it (every start's outcome, time,
path length, time without a fix).
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
from common import arguments, draw_runs, experiment, load, outcome_handles, sim_params, write_json
from matplotlib.patches import Wedge

from bearnav_cli import plot
from bearnav_cli.datatypes import Simulation
from bearnav_cli.stages import simulate

FOV_DEG = 60.0
#: View cones drawn per path.
CONES = 9


def draw_cones(ax: plt.Axes, runs: Simulation, fov: float, radius: float) -> None:
    """The camera's view cone at ``CONES`` evenly spaced points of every path."""
    offsets = runs.trajectory_offsets
    for r in range(len(runs)):
        path = runs.trajectory(r)
        heading = runs.trajectory_heading[offsets[r] : offsets[r + 1]]
        for k in np.linspace(0, len(path) - 1, CONES + 2)[1:-1].astype(int):
            yaw = math.degrees(heading[k])
            ax.add_patch(
                Wedge(tuple(path[k]), radius, yaw - fov / 2, yaw + fov / 2, color="#1f77b4", alpha=0.18, lw=0, zorder=3)
            )


def main() -> None:
    """Run the four starts on the unicycle, draw them and write the numbers."""
    args = arguments(__doc__.splitlines()[0], [("plan", "plan.npz of the kitchen map")])
    plan, plan_src = load(args.plan, "plan")
    map_ = plan.map
    params = sim_params(plan, dynamics="unicycle", measurement="bearing", fov=FOV_DEG, starts="map")
    runs = simulate.rollout(plan, simulate.resolve_starts(plan, params), params)

    xmin, ymin, xmax, ymax = map_.bounds
    fig, ax = plt.subplots(figsize=(8.0, 8.0 * (ymax - ymin) / (xmax - xmin) + 0.8))
    plot.plot_map(ax, map_)
    plot.plot_tree(ax, plan.cells, color="#9ecae1", lw=0.6, alpha=0.7, label="simplified tree")
    draw_cones(ax, runs, params.fov, 0.05 * map_.diagonal)
    draw_runs(ax, runs)
    ax.set_title(
        f"{map_.name}: {runs.counts()['success']}/{len(runs)} starts reach the goal "
        f"(unicycle, bearings, {params.fov:g}° field of view)",
        fontsize=10,
    )
    found, _ = ax.get_legend_handles_labels()
    cone = Wedge((0, 0), 1, 0, 60, color="#1f77b4", alpha=0.3, label=f"camera view ({params.fov:g}°)")
    ax.legend(
        handles=found + outcome_handles(runs) + [cone],
        loc="upper center",
        bbox_to_anchor=(0.5, -0.05),
        ncol=4,
        fontsize=7,
        frameon=False,
    )
    fig.tight_layout()
    plot.save_figure(fig, str(args.out))

    record = experiment(runs, params)
    for row, held in zip(record["per_run"], runs.hold_steps, strict=True):
        row["time_without_fix_s"] = round(float(held * runs.dt), 6)
    write_json(
        args.out.with_suffix(".json"),
        {
            "figure": str(args.out),
            "map": map_.name,
            "inputs": {"plan": plan_src},
            "trajectories": record,
        },
    )
    print(f"wrote {args.out} and {args.out.with_suffix('.json')}: {simulate.summary(runs)}")


if __name__ == "__main__":
    main()
