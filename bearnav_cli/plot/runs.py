"""The layers of a simulation: every run's path by outcome over its faint cells and tree; one run's estimate sets."""

from __future__ import annotations

from typing import Any, Sequence

import matplotlib.pyplot as plt
import numpy as np
import shapely
from matplotlib import colors as mcolors
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection

from bearnav_cli.datatypes import CellStatus, Simulation
from bearnav_cli.palette import OUTCOME_COLORS, ROLE_COLORS, STATUS_COLORS
from bearnav_cli.plot.cells import status_name
from bearnav_cli.plot.layers import plot_tree
from bearnav_cli.plot.style import AXIS_UNITS, OUTLINE_COLOR, add_geometry, shared_label

__all__ = ["OUTCOME_NAMES", "plot_estimate_trace", "plot_sim_background", "plot_trajectories"]


OUTCOME_NAMES = {0: "success", 1: "collision", 2: "stall", 3: "timeout", 4: "lost"}


def plot_estimate_trace(ax: plt.Axes, trace: Any, *, cmap: str = "viridis", scale: float = 1.0) -> plt.Axes:
    """One run's estimate sets along its path (``simulate.estimate_trace``), coloured by their error radius.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (map units on both axes).
    trace : EstimateTrace
        The recorded sets, the true positions and the error radii.
    cmap : str
        Colour map of the error radius ``e`` (a colour bar is added).
    scale : float
        Each set drawn enlarged by this factor about its estimate (sets of centimetres vanish on a
        map of metres); the legend says so when it is not 1.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.
    """
    norm = mcolors.Normalize(vmin=0.0, vmax=float(np.max(trace.error)) if len(trace.error) else 1.0)
    colours = plt.get_cmap(cmap)
    ax.plot(*trace.truth.T, color=ROLE_COLORS["estimate path"], lw=0.8, zorder=4, label="true path")
    label = "estimate sets" + (f" (drawn {scale:g}× enlarged)" if scale != 1.0 else "")
    seen: set = set()
    for k in range(len(trace.error)):
        ring = trace.set_coords[trace.set_offsets[k] : trace.set_offsets[k + 1]]
        if len(ring) >= 3:
            ring = trace.x_hat[k] + scale * (ring - trace.x_hat[k])
            colour = colours(norm(trace.error[k]))
            patch = add_geometry(
                ax, shapely.Polygon(ring), facecolor=colour, alpha=0.55, edgecolor=colour, lw=0.4, zorder=5
            )
            if patch is not None:
                patch.set_label(shared_label(label, seen))
    looked = trace.looking
    if looked.any():
        ax.plot(
            *trace.truth[looked].T,
            "o",
            ms=2.5,
            mfc="none",
            mec=ROLE_COLORS["looked"],
            zorder=6,
            label="stopped to look",
        )
    bar = plt.colorbar(ScalarMappable(norm=norm, cmap=colours), ax=ax, fraction=0.04, pad=0.02)
    bar.set_label(f"error radius e ({AXIS_UNITS})")
    return ax


def _draw_cells(
    ax: plt.Axes,
    vertices: np.ndarray,
    offsets: np.ndarray,
    status: np.ndarray | None,
    *,
    fill: float = 0.25,
    line: float = 0.6,
    lw: float = 0.4,
    legend: bool = True,
    skip: Sequence[int] = (),
) -> plt.Axes:
    """Cells given as coords + offsets: outlines, and fills by status when given (labelled ``cells: <status>``;
    none for the statuses in ``skip``)."""
    seen: set = set()
    for c in range(len(offsets) - 1):
        v = vertices[offsets[c] : offsets[c + 1]]
        if status is not None and int(status[c]) not in skip:
            name = status_name(status[c])
            ax.fill(
                *v.T,
                color=STATUS_COLORS[CellStatus(int(status[c]))],
                alpha=fill,
                lw=0,
                zorder=0.5,
                gid="cell-fill",
                label=shared_label(name, seen) if legend else "_" + name,
            )
    rings = [np.vstack([vertices[a:b], vertices[a : a + 1]]) for a, b in zip(offsets[:-1], offsets[1:], strict=True)]
    ax.add_collection(
        LineCollection(
            rings,
            colors=OUTLINE_COLOR,
            linewidths=lw,
            alpha=line,
            zorder=0.6,
            gid="cell-outlines",
            label="cell outlines" if legend else "_cell outlines",
        )
    )
    return ax


def plot_sim_background(ax: plt.Axes, sim: Simulation) -> plt.Axes:
    """The simulation's cells and tree, faintly: outlines, and a fill by status for the cells not plainly certified.

    Certified cells are left unfilled (their green would be the success paths' colour, and overlapping
    cells stack into a shade that hides the runs); the goal cell, relaxed and uncertified cells are
    filled. The tree is dark grey, apart from every outcome's colour.
    """
    status = np.asarray(sim.cell_status)
    _draw_cells(
        ax,
        sim.cell_vertices,
        sim.cell_vertex_offsets,
        status,
        fill=0.25,
        line=0.35,
        lw=0.3,
        skip=(CellStatus.CERTIFIED,),
    )
    return plot_tree(ax, sim, color=ROLE_COLORS["background tree"], lw=0.6, alpha=0.5, label="simplified tree")


def plot_trajectories(ax: plt.Axes, sim: Simulation, *, limit: int = 400) -> plt.Axes:
    """Every run's path coloured by its outcome, with its start (circle) and end (cross); at most ``limit`` runs.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (map units on both axes).
    sim : Simulation
        The runs; colours follow :data:`OUTCOME_COLORS`, and only failed runs get an end cross.
    limit : int
        Largest number of runs drawn (the first ones); runs without a trajectory are skipped.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.
    """
    seen: set = set()
    for r in range(min(len(sim.outcome), limit)):
        path = sim.trajectory(r)
        if not len(path):
            continue
        outcome = int(sim.outcome[r])
        color = OUTCOME_COLORS[outcome]
        ax.plot(
            *path.T,
            color=color,
            lw=0.9,
            alpha=0.85,
            zorder=4,
            label=shared_label(OUTCOME_NAMES[outcome], seen),
            gid="run",
        )
        ax.plot(
            *path[0],
            "o",
            ms=3,
            color=color,
            mfc=ROLE_COLORS["edge"],
            mec=color,
            zorder=5,
            label=shared_label("run starts", seen),
            gid="run-start",
        )
        if outcome != 0:
            ax.plot(
                *path[-1],
                "x",
                ms=5,
                color=color,
                zorder=5,
                label=shared_label("where a failed run ended", seen),
                gid="run-end",
            )
    return ax
