"""The bearing paper's simulation figure (§IV-A) on the kitchen map, four panels.

(a) the configuration space: raw obstacles, the same inflated by the robot radius, landmarks,
goal and starts; (b) the RRT* tree rooted at the goal with the samples that hit obstacles
(random ones and border pseudo-samples); (c) the simplified tree over the RRT* tree; (d) the
closed loop from the map's four starts to the goal: single integrator, bearing measurements,
full (360°) view, occlusion by the raw obstacles, the map's own ``simulate`` parameters.

Usage::

    .venv/bin/python repro/kitchen_figure.py plans/kitchen/tree.npz plans/kitchen/simplified.npz \\
        plans/kitchen/plan.npz -o docs/figures/kitchen_paper.png

writes the figure and ``kitchen_paper.json`` next to it: node and sample counts, and every
start's outcome, time and path length.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
from common import arguments, draw_runs, experiment, load, outcome_handles, sim_params, write_json
from matplotlib.patches import Patch

from bearnav_cli import plot
from bearnav_cli.stages import simulate

BORDER_COLOR = "#9467bd"


def legend_below(ax: plt.Axes, handles: list | None = None) -> None:
    """A compact legend under ``ax`` (the map itself stays unobstructed)."""
    found, _ = ax.get_legend_handles_labels()
    ax.legend(
        handles=found + (handles or []),
        loc="upper center",
        bbox_to_anchor=(0.5, -0.04),
        ncol=4,
        fontsize=7,
        frameon=False,
    )


def panel_samples(ax: plt.Axes, tree) -> None:
    """The RRT* tree, its random collision samples and its border pseudo-samples in two colours."""
    n_random = int(tree.stats.get("random_collision_samples", len(tree.collision_samples)))
    plot.plot_map(ax, tree.map, landmarks=False, starts=False)
    plot.plot_tree(ax, tree, lw=0.5, label="RRT* tree")
    random, border = tree.collision_samples[:n_random], tree.collision_samples[n_random:]
    ax.scatter(*random.T, s=5, marker="x", linewidths=0.6, color="#ff7f0e", zorder=3, label="collision samples")
    if len(border):
        ax.scatter(*border.T, s=2, marker=".", color=BORDER_COLOR, zorder=3, label="border samples")


def main() -> None:
    """Draw the four panels and write the numbers."""
    args = arguments(
        __doc__.splitlines()[0],
        [
            ("tree", "tree.npz (RRT*)"),
            ("simplified", "simplified.npz"),
            ("plan", "plan.npz"),
        ],
    )
    tree, tree_src = load(args.tree, "tree")
    simplified, simplified_src = load(args.simplified, "simplified")
    plan, plan_src = load(args.plan, "plan")
    map_ = plan.map

    params = sim_params(plan, dynamics="single", measurement="bearing", fov=360.0, starts="map")
    runs = simulate.rollout(plan, simulate.resolve_starts(plan, params), params)

    xmin, ymin, xmax, ymax = map_.bounds
    width = 6.0
    fig, axes = plt.subplots(2, 2, figsize=(2 * width, 2 * width * (ymax - ymin) / (xmax - xmin) + 1.6))
    (a, b), (c, d) = axes

    plot.plot_map(a, map_)
    a.set_title(f"(a) configuration space (robot radius {map_.robot_radius:g}), {len(map_.landmarks)} landmarks")

    panel_samples(b, tree)
    n_random = int(tree.stats.get("random_collision_samples", len(tree.collision_samples)))
    b.set_title(
        f"(b) RRT*: {len(tree.nodes)} nodes, {n_random} collision samples "
        f"(+{len(tree.collision_samples) - n_random} on the border)"
    )

    plot.plot_map(c, map_, landmarks=False, starts=False)
    plot.plot_tree(c, tree, color="#9ecae1", lw=0.5, alpha=0.8, label="RRT* tree")
    plot.plot_tree(c, simplified, nodes=True, lw=1.1, label="simplified tree")
    c.set_title(f"(c) simplified tree: {len(simplified.nodes)} nodes (from {len(tree.nodes)})")

    plot.plot_map(d, map_, landmarks=True)
    plot.plot_tree(d, plan.cells, color="#9ecae1", lw=0.6, alpha=0.7, label="simplified tree")
    draw_runs(d, runs)
    d.set_title(f"(d) {runs.counts()['success']}/{len(runs)} starts reach the goal (single integrator, bearings, 360°)")

    legend_below(
        a,
        [
            Patch(color=plot.RAW_COLOR, label="obstacles"),
            Patch(color=plot.INFLATED_COLOR, label="inflated by the robot radius"),
        ],
    )
    for ax in (b, c):
        legend_below(ax)
    legend_below(d, outcome_handles(runs))
    for ax in axes.ravel():
        ax.title.set_fontsize(9)
        ax.tick_params(labelsize=7)
    fig.tight_layout()
    plot.save_figure(fig, str(args.out))

    write_json(
        args.out.with_suffix(".json"),
        {
            "figure": str(args.out),
            "map": map_.name,
            "inputs": {"tree": tree_src, "simplified": simplified_src, "plan": plan_src},
            "configuration_space": {
                "raw_obstacles": len(map_.raw_obstacles),
                "obstacles": len(map_.obstacles),
                "robot_radius": float(map_.robot_radius),
                "landmarks": len(map_.landmarks),
                "starts": len(map_.starts),
            },
            "rrtstar": {
                "nodes": len(tree.nodes),
                "collision_samples": len(tree.collision_samples),
                "random_collision_samples": n_random,
                "border_samples": len(tree.collision_samples) - n_random,
                "iterations": tree.stats.get("iterations"),
            },
            "simplified": {"nodes": len(simplified.nodes), "rounds": simplified.stats.get("rounds")},
            "plan": {"cells": plan.cells.n_cells, "status_counts": plan.stats.get("status_counts")},
            "trajectories": experiment(runs, params),
        },
    )
    print(f"wrote {args.out} and {args.out.with_suffix('.json')}: {simulate.summary(runs)}")


if __name__ == "__main__":
    main()
