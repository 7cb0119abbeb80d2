"""Drawing every artifact with matplotlib; nothing else in bearnav imports matplotlib.

Each ``plot_<layer>(ax, artifact, ...)`` draws one layer on an existing axes and
returns it, in the manner of python-control's ``*_plot`` functions: compute
elsewhere, draw here. :func:`figure_for` composes the layers that suit an artifact.
"""

from __future__ import annotations

from typing import Any, Sequence

import matplotlib

matplotlib.use("Agg")  # files only: bearnav never opens windows

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.patches import PathPatch  # noqa: E402
from matplotlib.path import Path as MplPath  # noqa: E402

from bearnav_cli.datatypes import Map, Polygon, Tree  # noqa: E402

RAW_COLOR = "#4d4d4d"
INFLATED_COLOR = "#c9c9c9"


def _polygon_patch(polygon: Polygon, **style: Any) -> PathPatch:
    rings = [polygon.exterior, *polygon.holes]
    vertices = np.concatenate([np.vstack([r, r[:1]]) for r in rings])
    codes = np.concatenate(
        [[MplPath.MOVETO] + [MplPath.LINETO] * (len(r) - 1) + [MplPath.CLOSEPOLY] for r in rings]
    )
    return PathPatch(MplPath(vertices, codes), **style)


def plot_map(ax: plt.Axes, map_: Map, *, landmarks: bool = True, starts: bool = True) -> plt.Axes:
    """Bounds, inflated and raw obstacles, landmarks with ids, goal and starts."""
    xmin, ymin, xmax, ymax = map_.bounds
    ax.plot([xmin, xmax, xmax, xmin, xmin], [ymin, ymin, ymax, ymax, ymin], color="black", lw=1.2)
    for poly in map_.obstacles:
        ax.add_patch(_polygon_patch(poly, facecolor=INFLATED_COLOR, edgecolor="none", zorder=1))
    for poly in map_.raw_obstacles:
        ax.add_patch(_polygon_patch(poly, facecolor=RAW_COLOR, edgecolor="none", zorder=2))
    if landmarks and len(map_.landmarks):
        ax.scatter(*map_.landmarks.T, marker="^", s=40, color="#d62728", zorder=6, label="landmarks")
        offset = 0.008 * map_.diagonal
        for name, (x, y) in zip(map_.landmark_ids, map_.landmarks, strict=True):
            ax.annotate(name, (x, y), (x + offset, y + offset), fontsize=7, color="#d62728", zorder=6)
    if starts and len(map_.starts):
        ax.scatter(*map_.starts.T, marker="o", s=36, facecolor="white", edgecolor="#1f77b4", zorder=6,
                   label="starts")
    ax.scatter(*map_.goal, marker="*", s=160, color="#2ca02c", zorder=7, label="goal")
    pad = 0.02 * map_.diagonal
    ax.set_xlim(xmin - pad, xmax + pad)
    ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_aspect("equal")
    return ax


def plot_tree(ax: plt.Axes, tree: Tree, *, color: str = "#1f77b4", lw: float = 0.8, alpha: float = 1.0,
              nodes: bool = False, label: str | None = "tree") -> plt.Axes:
    """Tree edges (child → parent) and, optionally, its nodes."""
    if len(tree.nodes) > 1:
        ax.add_collection(LineCollection(tree.edges, colors=color, linewidths=lw, alpha=alpha, zorder=4,
                                         label=label))
    if nodes:
        ax.scatter(*tree.nodes.T, s=6, color=color, alpha=alpha, zorder=5)
    return ax


def plot_samples(ax: plt.Axes, tree: Tree, *, color: str = "#ff7f0e") -> plt.Axes:
    """The collision samples kept by RRT* (random ones and border pseudo-samples)."""
    if len(tree.collision_samples):
        ax.scatter(*tree.collision_samples.T, s=3, marker="x", linewidths=0.6, color=color, zorder=3,
                   label="collision samples")
    return ax


def figure_for(artifact: Any, *, background: Sequence[Any] = (), title: str | None = None) -> plt.Figure:
    """A figure with the layers that suit ``artifact`` (Map or Tree).

    Parameters
    ----------
    artifact : Map or Tree
        The main artifact.
    background : sequence of Tree
        Trees drawn faintly underneath (e.g. the RRT* tree under its simplification).
    title : str, optional
        Figure title (default: map name and artifact kind).
    """
    map_ = artifact if isinstance(artifact, Map) else artifact.map
    xmin, ymin, xmax, ymax = map_.bounds
    width = 8.0
    height = max(3.0, width * (ymax - ymin) / (xmax - xmin))
    fig, ax = plt.subplots(figsize=(width + 1.8, height))  # the extra width holds the legend
    plot_map(ax, map_)
    for extra in background:
        plot_tree(ax, extra, color="#9ecae1", lw=0.5, alpha=0.8, label="RRT* tree")
    if isinstance(artifact, Tree):
        plot_samples(ax, artifact)
        plot_tree(ax, artifact, nodes=len(artifact.nodes) < 400, lw=1.0 if background else 0.7)
    ax.set_title(title or map_.name)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, framealpha=0.85)
    fig.tight_layout()
    return fig


def save_figure(fig: plt.Figure, path: str) -> None:
    """Write ``fig`` to ``path`` (format from the suffix) and close it."""
    fig.savefig(path, dpi=150)
    plt.close(fig)
