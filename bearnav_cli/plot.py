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

from bearnav_cli.datatypes import Cells, CellStatus, Map, Plan, Polygon, Simulation, Tree  # noqa: E402

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


#: Fill colour of each cell status (``plan.npz`` ``status``).
STATUS_COLORS = {
    CellStatus.CERTIFIED: "#a1d99b",
    CellStatus.RELAXED: "#fdd49e",
    CellStatus.NOT_CERTIFIED: "#fc9272",
    CellStatus.SOLVER_FAILURE: "#de2d26",
    CellStatus.GOAL: "#9ecae1",
}


def _edges(nodes: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """Child → parent segments, shape (N−1, 2, 2)."""
    child = np.flatnonzero(parent >= 0)
    return np.stack([nodes[child], nodes[parent[child]]], axis=1)


def plot_cells(ax: plt.Axes, cells: Cells, status: np.ndarray | None = None) -> plt.Axes:
    """Cell outlines; filled by synthesis status when ``status`` (shape (C,)) is given."""
    return _draw_cells(ax, cells.cell_vertices, cells.cell_vertex_offsets, status)


def _draw_cells(ax: plt.Axes, vertices: np.ndarray, offsets: np.ndarray, status: np.ndarray | None, *,
                fill: float = 0.25, line: float = 0.6, lw: float = 0.4, legend: bool = True) -> plt.Axes:  # fmt: skip
    """Cells given as coords + offsets: outlines, and fills by status when given."""
    for c in range(len(offsets) - 1):
        v = vertices[offsets[c] : offsets[c + 1]]
        if status is not None:
            ax.fill(*v.T, color=STATUS_COLORS[CellStatus(int(status[c]))], alpha=fill, lw=0, zorder=0.5)
        ax.plot(*np.vstack([v, v[:1]]).T, color="#6a51a3", lw=lw, alpha=line, zorder=0.6)
    if status is not None and legend:
        for value in sorted({int(s) for s in status}):
            name = CellStatus(value).name.lower().replace("_", " ")
            ax.fill([], [], color=STATUS_COLORS[CellStatus(value)], alpha=0.5, label=f"cells: {name}")
    return ax


def _line_in_polygon(normal: np.ndarray, offset: float, A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """The part of the line ``normal·x + offset = 0`` inside ``{A x <= b}``, shape (2, 2), or None."""
    point = -offset * normal
    direction = np.array([-normal[1], normal[0]])
    rate, slack = A @ direction, b - A @ point
    lo, hi = -np.inf, np.inf
    for r, s in zip(rate, slack, strict=True):
        if abs(r) < 1e-15:
            if s < 0:
                return None
        elif r > 0:
            hi = min(hi, s / r)
        else:
            lo = max(lo, s / r)
    if not lo < hi:
        return None
    return np.stack([point + lo * direction, point + hi * direction])


def plot_barriers(ax: plt.Axes, cells: Cells, *, color: str = "#e6550d") -> plt.Axes:
    """Every barrier line ``h(x) = 0``, clipped to its cell."""
    segments = []
    for c in range(cells.n_cells):
        A, b = cells.rows(c)
        normals, offsets = cells.barrier(c)
        for n, q in zip(normals, offsets, strict=True):
            seg = _line_in_polygon(n, q, A, b)
            if seg is not None:
                segments.append(seg)
    if segments:
        ax.add_collection(LineCollection(segments, colors=color, linewidths=0.7, linestyles="--", zorder=3.5,
                                         label="barrier lines"))
    return ax


def plot_field(ax: plt.Axes, plan: Plan, *, arrows: int = 40) -> plt.Axes:
    """Unit arrows of the controller a robot would run at each point: its Voronoi owner's cell."""
    map_ = plan.map
    xmin, ymin, xmax, ymax = map_.bounds
    step = max(xmax - xmin, ymax - ymin) / arrows
    xs, ys = np.meshgrid(np.arange(xmin + step / 2, xmax, step), np.arange(ymin + step / 2, ymax, step))
    points = np.column_stack([xs.ravel(), ys.ravel()])
    nodes = plan.cells.nodes
    owner = np.argmin(((points[:, None, :] - nodes[None, :, :]) ** 2).sum(axis=2), axis=1)
    y = (map_.landmarks[None, :, :] - points[:, None, :]).reshape(len(points), -1)
    u = np.einsum("pij,pj->pi", plan.gain[owner], y)
    norm = np.hypot(u[:, 0], u[:, 1])
    keep = norm > 0
    u = u[keep] / norm[keep, None]
    ax.quiver(*points[keep].T, *u.T, angles="xy", scale_units="xy", scale=1.6 / step, width=0.0018,
              color="#3f007d", alpha=0.7, zorder=3.8, label="vector field (direction)")
    return ax


def plot_tree(ax: plt.Axes, tree: Tree | Cells | Simulation, *, color: str = "#1f77b4", lw: float = 0.8,
              alpha: float = 1.0, nodes: bool = False, label: str | None = "tree") -> plt.Axes:
    """Tree edges (child → parent) and, optionally, its nodes."""
    if len(tree.nodes) > 1:
        segments = _edges(tree.nodes, tree.parent)
        ax.add_collection(LineCollection(segments, colors=color, linewidths=lw, alpha=alpha, zorder=4, label=label))
    if nodes:
        ax.scatter(*tree.nodes.T, s=6, color=color, alpha=alpha, zorder=5)
    return ax


def plot_samples(ax: plt.Axes, tree: Tree | Cells, *, color: str = "#ff7f0e") -> plt.Axes:
    """The collision samples kept by RRT* (random ones and border pseudo-samples)."""
    if len(tree.collision_samples):
        ax.scatter(*tree.collision_samples.T, s=3, marker="x", linewidths=0.6, color=color, zorder=3,
                   label="collision samples")
    return ax


#: Trajectory colour of each run outcome (``sim.npz`` ``outcome``).
OUTCOME_COLORS = {0: "#2ca25f", 1: "#de2d26", 2: "#fd8d3c", 3: "#756bb1", 4: "#636363"}
OUTCOME_NAMES = {0: "success", 1: "collision", 2: "stall", 3: "timeout", 4: "lost"}


def plot_sim_background(ax: plt.Axes, sim: Simulation) -> plt.Axes:
    """The simulation's cells (outlines, filled by status) and tree, faintly."""
    _draw_cells(ax, sim.cell_vertices, sim.cell_vertex_offsets, sim.cell_status, fill=0.12, line=0.35, lw=0.3,
                legend=False)  # fmt: skip
    return plot_tree(ax, sim, lw=0.8, alpha=0.6)


def plot_trajectories(ax: plt.Axes, sim: Simulation, *, limit: int = 400) -> plt.Axes:
    """Every run's path coloured by its outcome, with its start (circle) and end (cross); at most ``limit`` runs."""
    shown = set()
    for r in range(min(len(sim.outcome), limit)):
        path = sim.trajectory(r)
        if not len(path):
            continue
        outcome = int(sim.outcome[r])
        label = OUTCOME_NAMES[outcome] if outcome not in shown else None
        shown.add(outcome)
        color = OUTCOME_COLORS[outcome]
        ax.plot(*path.T, color=color, lw=0.9, alpha=0.85, zorder=4, label=label)
        ax.plot(*path[0], "o", ms=3, mfc="white", mec=color, zorder=5)
        if outcome != 0:
            ax.plot(*path[-1], "x", ms=5, color=color, zorder=5)
    return ax


def _frame(map_: Map, title: str) -> tuple[plt.Figure, plt.Axes]:
    xmin, ymin, xmax, ymax = map_.bounds
    width = 8.0
    height = max(3.0, width * (ymax - ymin) / (xmax - xmin))
    fig, ax = plt.subplots(figsize=(width + 1.8, height))  # the extra width holds the legend
    plot_map(ax, map_)
    ax.set_title(title)
    return fig, ax


def save_animation(sim: Simulation, path: str, *, frames: int = 80, limit: int = 60) -> None:
    """Write a GIF of the runs (at most ``limit``) advancing together, ``frames`` frames.

    Each frame shows every run's path so far and its current position; the frames are
    evenly spaced in time up to the longest run.
    """
    from matplotlib.animation import FuncAnimation, PillowWriter

    fig, ax = _frame(sim.map, f"{sim.map.name}: {len(sim.outcome)} runs")
    plot_sim_background(ax, sim)
    runs = [r for r in range(min(len(sim.outcome), limit)) if len(sim.trajectory(r))]
    lines = [ax.plot([], [], color=OUTCOME_COLORS[int(sim.outcome[r])], lw=0.9, zorder=4)[0] for r in runs]
    heads = ax.scatter(np.zeros(len(runs)), np.zeros(len(runs)), s=12, zorder=5,
                       c=[OUTCOME_COLORS[int(sim.outcome[r])] for r in runs])  # fmt: skip
    longest = max((len(sim.trajectory(r)) for r in runs), default=1)
    fig.tight_layout()

    def draw(k: int) -> list:
        upto = max(1, int(round((k + 1) / frames * longest)))
        tips = []
        for line, r in zip(lines, runs, strict=True):
            path = sim.trajectory(r)[:upto]
            line.set_data(path[:, 0], path[:, 1])
            tips.append(path[-1])
        if tips:
            heads.set_offsets(np.array(tips))
        return [*lines, heads]

    FuncAnimation(fig, draw, frames=frames, blit=False).save(path, writer=PillowWriter(fps=12), dpi=60)
    plt.close(fig)


def figure_for(artifact: Any, *, background: Sequence[Any] = (), title: str | None = None) -> plt.Figure:
    """A figure with the layers that suit ``artifact``.

    Parameters
    ----------
    artifact : Map, Tree, Cells, Plan or Simulation
        The main artifact: a map; a tree with its samples; cells with barrier lines; a
        plan adds the cells' status colours and its vector field; a simulation draws its
        runs over the tree and cells, coloured by outcome.
    background : sequence of Tree
        Trees drawn faintly underneath (e.g. the RRT* tree under its simplification).
    title : str, optional
        Figure title (default: map name and artifact kind).
    """
    map_ = artifact if isinstance(artifact, Map) else artifact.map
    fig, ax = _frame(map_, title or map_.name)
    if isinstance(artifact, Simulation):
        plot_sim_background(ax, artifact)
        plot_trajectories(ax, artifact)
        rate = artifact.stats.get("success_rate")
        if title is None and rate is not None:
            ax.set_title(f"{map_.name}: {rate:.1%} of {len(artifact.outcome)} runs reached the goal")
    for extra in background:
        plot_tree(ax, extra, color="#9ecae1", lw=0.5, alpha=0.8, label="RRT* tree")
    if isinstance(artifact, Tree):
        plot_samples(ax, artifact)
        plot_tree(ax, artifact, nodes=len(artifact.nodes) < 400, lw=1.0 if background else 0.7)
    cells = artifact.cells if isinstance(artifact, Plan) else artifact if isinstance(artifact, Cells) else None
    if cells is not None:
        plot_cells(ax, cells, artifact.status if isinstance(artifact, Plan) else None)
        plot_samples(ax, cells)
        plot_barriers(ax, cells)
        plot_tree(ax, cells, nodes=True, lw=1.0)
        if isinstance(artifact, Plan):
            plot_field(ax, artifact)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, framealpha=0.85)
    fig.tight_layout()
    return fig


def save_figure(fig: plt.Figure, path: str) -> None:
    """Write ``fig`` to ``path`` (format from the suffix) and close it."""
    fig.savefig(path, dpi=150)
    plt.close(fig)
