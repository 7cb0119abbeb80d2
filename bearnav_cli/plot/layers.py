"""The layers under every figure: the map, a tree and its collision samples, and the field a robot runs.

Each ``plot_<layer>(ax, artifact, ...)`` draws one layer on an existing axes and returns it. The
field is the runtime's own (:func:`bearnav_cli.runtime.locate` and :func:`bearnav_cli.runtime.field`
on a grid), so the figure shows what a robot runs.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import shapely
from matplotlib.collections import LineCollection
from matplotlib.patches import Patch

from bearnav_cli import runtime
from bearnav_cli.datatypes import Cells, Map, Plan, Simulation, Tree
from bearnav_cli.palette import PALETTE, ROLE_COLORS
from bearnav_cli.plot.labels import LANDMARKS_LABEL, label_landmarks
from bearnav_cli.plot.style import (
    ADDED_COLOR,
    GOAL_COLOR,
    INFLATED_COLOR,
    LANDMARK_COLOR,
    RAW_COLOR,
    TREE_COLOR,
    add_geometry,
    polygon_patch,
    shared_label,
)

__all__ = ["field_samples", "map_handles", "plot_field", "plot_map", "plot_samples", "plot_tree"]


def plot_map(
    ax: plt.Axes,
    map_: Map,
    *,
    landmarks: bool = True,
    starts: bool = True,
    labels: bool | None = None,
    walls: bool = True,
) -> plt.Axes:
    """Bounds, inflated and raw obstacles, landmarks, goal and starts.

    Also sets the limits (the bounds with a 2 % pad of the diagonal) and an equal aspect. Every
    mark carries its legend label (one obstacle patch of each kind; the others ``_`` and the label).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (map units on both axes).
    map_ : Map
        The map to draw.
    landmarks : bool
        Draw the landmarks (triangles) and, per ``labels``, their ids.
    starts : bool
        Draw the map's starts (white circles).
    labels : bool or None
        Landmark ids for every landmark (True), none (False) or only those that fit without
        covering another label or landmark (None, :func:`label_landmarks`).
    walls : bool
        Shade the band within the robot radius of the bounds, which the centre of the robot
        cannot enter either.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.
    """
    xmin, ymin, xmax, ymax = map_.bounds
    ax.plot(
        [xmin, xmax, xmax, xmin, xmin],
        [ymin, ymin, ymax, ymax, ymin],
        color=ROLE_COLORS["bounds"],
        lw=1.2,
        gid="bounds",
        label="_bounds",
    )  # the frame of the map: no legend entry
    inflated = _inflated_label(map_)
    seen: set = set()
    # the raw obstacles' entry first: it is the one a reader looks for
    for poly in map_.raw_obstacles:
        ax.add_patch(
            polygon_patch(
                poly,
                facecolor=RAW_COLOR,
                edgecolor="none",
                zorder=2,
                gid="obstacles",
                label=shared_label("obstacles", seen),
            )
        )
    if walls and map_.planning_radius > 0:
        band = shapely.difference(shapely.box(*map_.bounds), shapely.box(*map_.free_bounds))
        add_geometry(
            ax,
            band,
            facecolor=INFLATED_COLOR,
            edgecolor="none",
            zorder=1,
            gid="inflated",
            label=shared_label(inflated, seen),
        )
    for poly in map_.obstacles:
        ax.add_patch(
            polygon_patch(
                poly,
                facecolor=INFLATED_COLOR,
                edgecolor="none",
                zorder=1,
                gid="inflated",
                label=shared_label(inflated, seen),
            )
        )
    if landmarks and len(map_.landmarks):
        ax.scatter(
            *map_.landmarks.T,
            marker="^",
            s=40,
            color=LANDMARK_COLOR,
            edgecolor=ROLE_COLORS["edge"],
            linewidths=0.5,
            zorder=6,
            gid="landmarks",
            label=LANDMARKS_LABEL,
        )
    if starts and len(map_.starts):
        ax.scatter(
            *map_.starts.T,
            marker="o",
            s=36,
            facecolor=ROLE_COLORS["edge"],
            edgecolor=ROLE_COLORS["start"],
            linewidths=1.0,
            zorder=6,
            gid="map-starts",
            label="map starts",
        )
    ax.scatter(
        *map_.goal,
        marker="*",
        s=200,
        color=GOAL_COLOR,
        edgecolor=PALETTE["black"],
        linewidths=0.6,
        zorder=7,
        gid="goal",
        label="goal",
    )
    pad = 0.02 * map_.diagonal
    ax.set_xlim(xmin - pad, xmax + pad)
    ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_aspect("equal")
    if landmarks and labels is not False:
        label_landmarks(ax, map_, every=bool(labels))
    return ax


def _inflated_label(map_: Map) -> str:
    if map_.lookahead > 0:
        return f"inflated by radius + look-ahead ({map_.robot_radius:g} + {map_.lookahead:g})"
    return f"inflated by the robot radius ({map_.robot_radius:g})"


def map_handles(map_: Map) -> list:
    """Legend proxies for the raw obstacles and their inflation by the robot radius (plus the look-ahead).

    :func:`plot_map` labels its obstacle patches with these labels, so a figure built on it needs none;
    this is for a legend of a figure drawn otherwise.
    """
    return [Patch(color=RAW_COLOR, label="obstacles"), Patch(color=INFLATED_COLOR, label=_inflated_label(map_))]


def _edges(nodes: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """Child → parent segments, shape (N−1, 2, 2)."""
    child = np.flatnonzero(parent >= 0)
    return np.stack([nodes[child], nodes[parent[child]]], axis=1)


def field_samples(plan: Plan, *, arrows: int = 28) -> tuple[np.ndarray, np.ndarray]:
    """Grid points in the free space and in some cell, and the unit direction the runtime drives there.

    The grid has ``arrows`` points along the longer side of ``B_r``; a point is kept when it is
    free (in ``B_r``, not in ``O``) and :func:`runtime.least_rank_cell` finds a cell containing it.
    The direction is :func:`runtime.field` of the cell :func:`runtime.locate` picks, normalised
    (points where the field vanishes are dropped). Returns ``(points (K, 2), directions (K, 2))``.
    """
    map_ = plan.map
    if arrows < 1:  # no arrows asked for
        return np.zeros((0, 2)), np.zeros((0, 2))
    xmin, ymin, xmax, ymax = map_.free_bounds
    step = max(xmax - xmin, ymax - ymin) / arrows
    xs = np.arange(xmin + step / 2, xmax, step)
    ys = np.arange(ymin + step / 2, ymax, step)
    points = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    obstacles = shapely.union_all([shapely.Polygon(p.exterior, p.holes) for p in map_.obstacles])
    free = ~shapely.intersects_xy(obstacles, points[:, 0], points[:, 1]) if not obstacles.is_empty else True
    arrays = runtime.PlanArrays.from_plan(plan)
    points = points[free & (runtime.least_rank_cell(arrays, points) >= 0)]
    u = runtime.field(arrays, runtime.locate(arrays, points), points)
    norm = np.hypot(u[:, 0], u[:, 1])
    keep = norm > 0
    return points[keep], u[keep] / norm[keep, None]


def plot_field(ax: plt.Axes, plan: Plan, *, arrows: int = 28) -> plt.Axes:
    """Unit arrows of the field a robot runs (:func:`field_samples`), based at free points in the cells.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (map units on both axes).
    plan : Plan
        The plan whose runtime policy is sampled.
    arrows : int
        Grid points along the longer side of ``B_r``; each arrow is 0.6 grid steps long.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.
    """
    points, directions = field_samples(plan, arrows=arrows)
    if len(points):
        fb = plan.map.free_bounds
        step = max(fb[2] - fb[0], fb[3] - fb[1]) / arrows
        ax.quiver(
            *points.T,
            *directions.T,
            angles="xy",
            scale_units="xy",
            scale=1.0 / (0.6 * step),
            pivot="tail",
            width=0.002,
            headwidth=4,
            headlength=4.5,
            color=ROLE_COLORS["field"],
            alpha=0.6,
            zorder=3.8,
            label="field direction (runtime policy)",
            gid="field",
        )
    return ax


def plot_tree(
    ax: plt.Axes,
    tree: Tree | Cells | Simulation,
    *,
    color: str = TREE_COLOR,
    lw: float = 0.8,
    alpha: float = 1.0,
    nodes: bool = False,
    label: str | None = "tree",
) -> plt.Axes:
    """Tree edges (child → parent) and, optionally, its nodes (nodes added by densification in orange).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (map units on both axes).
    tree : Tree, Cells or Simulation
        Anything with ``nodes`` (N, 2) and ``parent`` (N,); ``node_added`` (N,), when present,
        marks the densification nodes.
    color : str
        Matplotlib colour of the edges and of the original nodes.
    lw : float
        Edge width (points).
    alpha : float
        Opacity of edges and nodes.
    nodes : bool
        Also draw the nodes.
    label : str or None
        Legend label of the edges and nodes; None for no legend entry.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.
    """
    key = label if label else "_tree"
    if len(tree.nodes) > 1:
        segments = _edges(tree.nodes, tree.parent)
        ax.add_collection(
            LineCollection(segments, colors=color, linewidths=lw, alpha=alpha, zorder=4, label=key, gid="tree")
        )
    if nodes:
        added = np.asarray(getattr(tree, "node_added", np.zeros(len(tree.nodes), bool)), bool)
        # the nodes share the edges' legend entry
        ax.scatter(
            *tree.nodes[~added].T,
            s=5,
            color=color,
            alpha=alpha,
            zorder=5,
            label="_" + key.lstrip("_"),
            gid="tree-nodes",
        )
        if added.any():
            ax.scatter(
                *tree.nodes[added].T,
                s=14,
                marker="D",
                color=ADDED_COLOR,
                edgecolor=ROLE_COLORS["edge"],
                linewidths=0.4,
                alpha=alpha,
                zorder=5,
                gid="added-nodes",
                label=f"added nodes ({int(added.sum())}, densification)",
            )
    return ax


def plot_samples(ax: plt.Axes, tree: Tree | Cells, *, color: str = ROLE_COLORS["collision sample"]) -> plt.Axes:
    """The collision samples kept by RRT* (random ones and border pseudo-samples).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (map units on both axes).
    tree : Tree or Cells
        Anything with ``collision_samples``, shape (S, 2), map units.
    color : str
        Matplotlib colour of the crosses.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.
    """
    if len(tree.collision_samples):
        ax.scatter(
            *tree.collision_samples.T,
            s=3,
            marker="x",
            linewidths=0.6,
            color=color,
            zorder=3,
            gid="collision-samples",
            label="collision samples",
        )
    return ax
