"""Whole figures: :func:`figure_for` composes the layers that suit an artifact, :func:`save_animation` a GIF of runs."""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import matplotlib.pyplot as plt
import numpy as np

from bearnav_cli.datatypes import Cells, CellStatus, Map, Plan, Simulation, Tree, tolerance_by_area
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.palette import OUTCOME_COLORS, ROLE_COLORS
from bearnav_cli.plot.cells import (
    COLOR_BY,
    cell_anchors,
    cell_number_keys,
    cell_regions,
    label_cells,
    plot_barriers,
    plot_cells,
    plot_uncovered,
)
from bearnav_cli.plot.frame import figure_title, finish, map_frame, simulation_config
from bearnav_cli.plot.labels import label_landmarks
from bearnav_cli.plot.layers import plot_field, plot_samples, plot_tree
from bearnav_cli.plot.runs import OUTCOME_NAMES, plot_sim_background, plot_trajectories
from bearnav_cli.plot.style import shared_label
from bearnav_cli.plot.tags import plot_perception

__all__ = ["figure_for", "save_animation"]


def _simulation_title(sim: Simulation, params: Mapping[str, Any] | None) -> str:
    runs = len(sim.outcome)
    reached = int(np.sum(np.asarray(sim.outcome) == 0))
    summary = f"{reached} of {runs} runs reached the goal ({reached / runs:.1%})" if runs else "no runs"
    return figure_title(sim.map.name, "simulate", summary, simulation_config(params, sim.stats))


def save_animation(
    sim: Simulation, path: str, *, frames: int = 80, limit: int = 60, params: Mapping[str, Any] | None = None
) -> None:
    """Write a GIF of the runs (at most ``limit``) advancing together, ``frames`` frames.

    Each frame shows every run's path so far and its current position (and heading, when every
    shown run records one); the frames are evenly spaced in time up to the longest run.

    Parameters
    ----------
    sim : Simulation
        The runs, drawn over its cells and tree (:func:`plot_sim_background`).
    path : str
        The GIF file to write (Pillow writer, 12 frames/s, 60 dpi).
    frames : int
        Number of frames.
    limit : int
        Largest number of runs animated (the first ones).
    params : mapping, optional
        The simulate stage's parameters, for the title's configuration (:func:`simulation_config`).
    """
    from matplotlib.animation import FuncAnimation, PillowWriter

    fig, ax = map_frame(sim.map, _simulation_title(sim, params))
    plot_sim_background(ax, sim)
    runs = [r for r in range(min(len(sim.outcome), limit)) if len(sim.trajectory(r))]
    seen: set = set()
    lines = [
        ax.plot(
            [],
            [],
            color=OUTCOME_COLORS[int(sim.outcome[r])],
            lw=0.9,
            zorder=4,
            label=shared_label(OUTCOME_NAMES[int(sim.outcome[r])], seen),
        )[0]
        for r in runs
    ]
    colors = [OUTCOME_COLORS[int(sim.outcome[r])] for r in runs]
    heads = ax.scatter(np.zeros(len(runs)), np.zeros(len(runs)), s=12, zorder=5, c=colors)
    offsets = sim.trajectory_offsets
    headings = [np.asarray(sim.trajectory_heading[offsets[r] : offsets[r + 1]], float) for r in runs]
    has_heading = all(len(h) == len(sim.trajectory(r)) for h, r in zip(headings, runs, strict=True)) and runs
    xmin, ymin, xmax, ymax = sim.map.bounds
    size = 0.03 * max(xmax - xmin, ymax - ymin)  # each robot's heading, an arrow this long
    arrows = (
        ax.quiver(
            np.zeros(len(runs)),
            np.zeros(len(runs)),
            np.ones(len(runs)),
            np.zeros(len(runs)),
            color=colors,
            angles="xy",
            scale_units="xy",
            scale=1.0 / size,
            width=0.004,
            zorder=5.5,
        )
        if has_heading
        else None
    )
    longest = max((len(sim.trajectory(r)) for r in runs), default=1)
    finish(fig, ax)
    label_landmarks(ax, sim.map)

    def draw(k: int) -> list:
        upto = max(1, int(round((k + 1) / frames * longest)))
        tips, angles = [], []
        for i, (line, r) in enumerate(zip(lines, runs, strict=True)):
            path = sim.trajectory(r)[:upto]
            line.set_data(path[:, 0], path[:, 1])
            tips.append(path[-1])
            if arrows is not None:
                angles.append(headings[i][len(path) - 1])
        if tips:
            heads.set_offsets(np.array(tips))
            if arrows is not None:
                arrows.set_offsets(np.array(tips))
                arrows.set_UVC(np.cos(angles), np.sin(angles))
        return [*lines, heads] + ([arrows] if arrows is not None else [])

    FuncAnimation(fig, draw, frames=frames, blit=False).save(path, writer=PillowWriter(fps=12), dpi=60)
    plt.close(fig)


def _plan_title(map_: Map, cells: Cells, plan: Plan | None, color_by: str | None) -> str:
    kind = "funnel" if cells.is_funnel else "paper"
    summary = f"{cells.n_cells} {kind} cells"
    if cells.is_funnel:
        summary += f" ({int(np.sum(cells.node_added))} added)"
    if plan is not None:
        bad = int(np.isin(plan.status, [CellStatus.NOT_CERTIFIED, CellStatus.SOLVER_FAILURE]).sum())
        summary += f", {bad} uncertified" if bad else ", all certified"
    shown = color_by or ("rank" if cells.is_funnel else "status" if plan is not None else "")
    config = [f"coloured by {shown}"] if shown else []
    if cells.is_funnel:
        f_m = cells.stats.get("free_coverage_m")
        f_m = f" ({f_m:.1%} of F_m)" if isinstance(f_m, float) else ""
        config.append(f"cover {cells.free_coverage:.1%} of F{f_m}")
    if plan is not None and math.isfinite(plan.plan_tolerance):
        tau = tolerance_by_area(cells, plan.usable_tolerance)
        config.append(f"τ_c ≥ {plan.plan_tolerance:.3g} (median by area {tau['median']:.3g})")
    return figure_title(map_.name, "plan" if plan is not None else "cells", summary, " · ".join(config))


def _tree_title(tree: Tree, background: Sequence[Any]) -> str:
    if "rounds" in tree.stats:  # simplified.npz (its stats count the rounds), not tree.npz
        before = tree.stats.get("nodes_before")
        summary = f"{len(tree.nodes)} nodes" + (f" (from {before})" if before else "")
        summary += f" after {tree.stats['rounds']} rounds"
        over = f"over the RRT* tree ({len(background[0].nodes)} nodes)" if background else None
        return figure_title(tree.map.name, "simplified tree", summary, over)
    summary = f"{len(tree.nodes)} nodes, {len(tree.collision_samples)} collision samples"
    return figure_title(tree.map.name, "RRT* tree", summary)


def _map_title(map_: Map) -> str:
    summary = (
        f"{len(map_.raw_obstacles)} obstacles, {len(map_.landmarks)} landmarks, {len(map_.starts)} starts, "
        f"robot radius {map_.robot_radius:g}"
    )
    return figure_title(map_.name, "map", summary)


def _perception_config(coverage: Any) -> str:
    target = coverage.error_target
    rule = "2 usable tags in view" if target is None else f"a fix within {target:g} in view"
    return (
        f"perception: {coverage.fov_deg:g}° camera, {coverage.noise_deg:g}° noise: {rule} on "
        f"{coverage.fraction_domain:.1%} of D"
    )


def figure_for(
    artifact: Any,
    *,
    background: Sequence[Any] = (),
    title: str | None = None,
    color_by: str | None = None,
    barriers: bool = False,
    labels: bool | None = None,
    cell_numbers: bool = False,
    arrows: int = 28,
    coverage: Any = None,
    perception: Any = None,
    liveness: Any = None,
    params: Mapping[str, Any] | None = None,
) -> plt.Figure:
    """A figure with the layers that suit ``artifact``, a legend entry for every mark and a title that says what.

    The title is :func:`figure_title`'s: map, stage, summary and, for a simulation, the configuration
    (:func:`simulation_config`). Labels (landmark ids, then cell indices) are placed once the layout
    is settled, where they collide with nothing (:func:`place_labels`).

    Parameters
    ----------
    artifact : Map, Tree, Cells, Plan or Simulation
        The main artifact: a map; a tree with its samples; cells (outlines, exit faces, fill by
        rank, uncovered free space hatched); a plan adds the synthesis status (uncertified cells
        hatched) and the field the runtime drives; a simulation draws its runs over the tree
        and cells, coloured by outcome.
    background : sequence of Tree
        Trees drawn faintly underneath (e.g. the RRT* tree under its simplification).
    title : str, optional
        Figure title (default: :func:`figure_title` of the artifact).
    color_by : {"rank", "tolerance", "status", "live"}, optional
        Cell fill (:func:`plot_cells`); default rank for funnel cells, status for paper plans; ``live``
        needs ``liveness``.
    barriers : bool
        Also draw every barrier line ``h = 0`` (for funnel cells these are the cell edges).
    labels : bool, optional
        Landmark ids: all (True), none (False), or those that do not collide (None).
    cell_numbers : bool
        Write each cell's index where it fits (:func:`label_cells`; funnel cells: inside the region
        where the cell is active).
    arrows : int
        Field arrows along the longer side of the map.
    coverage : CoverageRegions, optional
        :func:`bearnav_cli.composition.coverage_regions` of funnel cells: the uncovered free space
        is hatched (none without it).
    perception : PerceptionCoverage, optional
        :func:`bearnav_cli.perception.perception_coverage` of the plan: where the perception rule
        fails is marked over it (:func:`plot_perception`, without a second copy of the tags).
    liveness : Liveness, optional
        :func:`bearnav_cli.liveness.measure` of the plan, for ``color_by="live"``; its summary is the
        default title.
    params : mapping, optional
        A simulation's stage parameters (``sim.npz``'s manifest ``params``): the title states its
        starts, field of view, noise, dynamics and estimator (ignored for other artifacts).
    """
    if color_by is not None and color_by not in COLOR_BY:
        raise InvalidParamsError(f"must be one of {', '.join(COLOR_BY)}, got {color_by!r}", field="color_by")
    map_ = artifact if isinstance(artifact, Map) else artifact.map
    plan = artifact if isinstance(artifact, Plan) else None
    cells = plan.cells if plan is not None else artifact if isinstance(artifact, Cells) else None
    if isinstance(artifact, Simulation):
        default_title = _simulation_title(artifact, params)
    elif isinstance(artifact, Tree):
        default_title = _tree_title(artifact, background)
    elif cells is not None:
        default_title = _plan_title(map_, cells, plan, color_by)
    else:
        default_title = _map_title(map_)
    if liveness is not None and color_by == "live":
        head, _, rest = liveness.summary().partition("; ")
        default_title = figure_title(map_.name, "liveness", head, rest.replace("; ", "\n") or None)
    if perception is not None:
        default_title += "\n" + _perception_config(perception)
    fig, ax = map_frame(map_, title or default_title)
    if isinstance(artifact, Simulation):
        plot_sim_background(ax, artifact)
        plot_trajectories(ax, artifact)
    for extra in background:
        plot_tree(ax, extra, color=ROLE_COLORS["rrt tree"], lw=0.5, alpha=0.8, label="RRT* tree")
    if isinstance(artifact, Tree):
        plot_samples(ax, artifact)
        simplified = "rounds" in artifact.stats  # simplified.npz (its stats count the rounds), not tree.npz
        plot_tree(
            ax,
            artifact,
            nodes=len(artifact.nodes) < 400,
            lw=1.0 if background else 0.7,
            label="simplified tree" if simplified else "RRT* tree",
        )
    regions = None
    if cells is not None:
        plot_cells(
            ax,
            cells,
            plan.status if plan is not None else None,
            color_by=color_by,
            tolerance=plan.usable_tolerance if plan is not None else None,
            live=None if liveness is None else liveness.live,
        )
        if cell_numbers:  # the legend entries now, the indices once the layout is settled
            regions = cell_regions(cells) if cells.is_funnel else None
            cell_number_keys(ax, cells, cell_anchors(cells, regions)[1])
        if cells.is_funnel and coverage is not None:
            plot_uncovered(ax, cells, coverage.uncovered, coverage.unreached)
        if barriers:
            plot_barriers(ax, cells)
        # thin and light: the tree is what the cells were built on, the arrows are what the robot runs
        plot_tree(ax, cells, nodes=True, lw=0.45, alpha=0.45, label="simplified tree")
        if plan is not None and arrows > 0:
            plot_field(ax, plan, arrows=arrows)
    if perception is not None:
        plot_perception(ax, perception, landmarks=False, legend=False)
    finish(fig, ax)
    # the landmarks' ids first: a cell index never hides one
    if labels is not False:
        label_landmarks(ax, map_, every=bool(labels))
    if cells is not None and cell_numbers:
        marks = np.vstack([map_.landmarks.reshape(-1, 2), map_.starts.reshape(-1, 2), map_.goal.reshape(1, 2)])
        label_cells(ax, cells, regions=regions, legend=False, avoid=marks)
    return fig
