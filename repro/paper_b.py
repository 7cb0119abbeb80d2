"""Paper B's simulation (Bahreinian, Mitjans, Tron, IROS 2021) on its circle map, and its deformation test.

Left: the map's four starts driven to the goal by the plan's controllers from bearings,
with the default single integrator (full view, solid) and with a unicycle and a 60° camera
(dashed). Right: the deformation experiment. The obstacles, landmarks and starts are
rotated by −15° about (130, 110) while the controllers, cells and goal of the undeformed
plan are kept; the robots drive in the rotated world (its obstacles stop them and hide
landmarks, its landmark positions are what they measure), fed either the true
displacements to the landmarks (paper B's measurement, solid) or bearings (dashed).

Usage::

    .venv/bin/python repro/paper_b.py plans/paper_b_circles/plan.npz -o docs/figures/paper_b.png

writes the figure and ``paper_b.json`` next to it: success rates and every run's outcome.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
from common import arguments, draw_runs, experiment, load, outcome_handles, rotate_map, sim_params, write_json
from matplotlib.lines import Line2D

from bearnav_cli import plot
from bearnav_cli.datatypes import Simulation
from bearnav_cli.stages import simulate

#: The deformation: a rotation by ANGLE_DEG (counter-clockwise positive) about CENTER.
ANGLE_DEG = -15.0
CENTER = (130.0, 110.0)


def style_handles(solid: str, dashed: str) -> list[Line2D]:
    """Legend entries saying what the solid and the dashed paths are."""
    return [
        Line2D([], [], color="black", lw=1.1, ls="-", label=solid),
        Line2D([], [], color="black", lw=1.1, ls="--", label=dashed),
    ]


def outline(ax: plt.Axes, map_) -> None:
    """The undeformed raw obstacles as dotted outlines (for comparison with the rotated ones)."""
    for k, poly in enumerate(map_.raw_obstacles):
        ring = list(poly.exterior) + [poly.exterior[0]]
        ax.plot(
            *zip(*ring, strict=True),
            color="#4d4d4d",
            lw=0.8,
            ls=":",
            zorder=3,
            label="undeformed obstacles" if k == 0 else None,
        )


def rate(runs: Simulation) -> str:
    return f"{runs.counts()['success']}/{len(runs)}"


def main() -> None:
    """Run the original and the deformed experiments, draw both panels and write the numbers."""
    args = arguments(__doc__.splitlines()[0], [("plan", "plan.npz of maps/paper_b_circles.yaml")])
    plan, plan_src = load(args.plan, "plan")
    map_ = plan.map
    starts = simulate.resolve_starts(plan, sim_params(plan, starts="map"))

    single = sim_params(plan, dynamics="single", measurement="bearing", fov=360.0)
    unicycle = sim_params(plan, dynamics="unicycle", measurement="bearing", fov=60.0)
    original = {
        "single_bearing": (single, simulate.rollout(plan, starts, single)),
        "unicycle_bearing_fov60": (unicycle, simulate.rollout(plan, starts, unicycle)),
    }

    world = rotate_map(map_, ANGLE_DEG, CENTER)
    displacement = sim_params(plan, dynamics="single", measurement="displacement", fov=360.0)
    deformed = {
        name: (params, simulate.rollout(plan, world.starts, params, world=world))
        for name, params in (("single_displacement", displacement), ("single_bearing", single))
    }

    xmin, ymin, xmax, ymax = map_.bounds
    fig, (left, right) = plt.subplots(1, 2, figsize=(14.0, 7.0 * (ymax - ymin) / (xmax - xmin) + 1.0))
    for ax, world_map, runs, labels in (
        (left, map_, original, ("single integrator, 360°", "unicycle, 60° camera")),
        (right, world, deformed, ("displacements (paper B)", "bearings")),
    ):
        plot.plot_map(ax, world_map)
        (_, solid), (_, dashed) = runs.values()
        draw_runs(ax, solid)
        draw_runs(ax, dashed, linestyle="--")
        found, _ = ax.get_legend_handles_labels()
        handles = found + outcome_handles(solid, dashed) + style_handles(*labels)
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.05), ncol=4, fontsize=7, frameon=False)
        ax.tick_params(labelsize=7)
    plot.plot_tree(left, plan.cells, color="#9ecae1", lw=0.6, alpha=0.7, label=None)
    outline(right, map_)
    (_, s), (_, u) = original.values()
    left.set_title(
        f"(a) {map_.name}, bearings: {rate(s)} reach the goal (single integrator), {rate(u)} (unicycle, 60°)",
        fontsize=9,
    )
    (_, d), (_, b) = deformed.values()
    right.set_title(
        f"(b) rotated {ANGLE_DEG:g}° about {CENTER}, undeformed controllers: "
        f"{rate(d)} (displacements), {rate(b)} (bearings)",
        fontsize=9,
    )
    fig.tight_layout()
    plot.save_figure(fig, str(args.out))

    write_json(
        args.out.with_suffix(".json"),
        {
            "figure": str(args.out),
            "map": map_.name,
            "inputs": {"plan": plan_src},
            "original": {name: experiment(r, p) for name, (p, r) in original.items()},
            "deformation": {
                "rotation_deg": ANGLE_DEG,
                "center": list(CENTER),
                "rotated": ["obstacles", "raw_obstacles", "landmarks", "starts"],
                "kept": ["bounds", "goal", "cells", "controllers"],
                "starts": world.starts.tolist(),
                "runs": {name: experiment(r, p) for name, (p, r) in deformed.items()},
            },
        },
    )
    for name, (_, runs) in {**original, **{f"deformed_{k}": v for k, v in deformed.items()}}.items():
        print(f"{name}: {simulate.summary(runs)}")
    print(f"wrote {args.out} and {args.out.with_suffix('.json')}")


if __name__ == "__main__":
    main()
