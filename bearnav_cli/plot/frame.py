"""The frame every figure shares: the map in a figure of its shape, the title, one legend below, a settled layout.

The layout is computed once and then fixed (:func:`finish`), so that labels placed afterwards in
display space (:func:`bearnav_cli.plot.labels.place_labels`) stay where they were put.
"""

from __future__ import annotations

import math
import textwrap
from typing import Any, Mapping

import matplotlib.pyplot as plt
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.quiver import Quiver

from bearnav_cli.datatypes import Map
from bearnav_cli.plot.layers import plot_map
from bearnav_cli.plot.style import axis_labels

__all__ = ["figure_title", "finish", "legend_below", "map_frame", "save_figure", "simulation_config"]


def figure_title(map_name: str, stage: str, summary: str, config: str | None = None) -> str:
    """Every figure's title: ``"<map> — <stage>: <summary>"`` and, on a second line, the configuration.

    Parameters
    ----------
    map_name : str
        The map's name.
    stage : str
        What is drawn: ``map``, ``RRT* tree``, ``simplified tree``, ``cells``, ``plan``,
        ``simulate``, ``tags``, ...
    summary : str
        The one-line result (counts, coverage, success).
    config : str, optional
        How it was made (for a simulation: starts, camera, noise, dynamics, estimator).
    """
    head = f"{map_name} — {stage}: {summary}"
    return f"{head}\n{config}" if config else head


def simulation_config(params: Mapping[str, Any] | None, stats: Mapping[str, Any] | None = None) -> str:
    """A simulation's configuration in a line: starts, field of view, bearing noise, dynamics, estimator.

    Parameters
    ----------
    params : mapping, optional
        The simulate stage's parameters (``sim.npz``'s manifest ``params``, as ``pipeline.load``
        returns it); without them the line says the configuration is not known.
    stats : mapping, optional
        The simulation's ``stats``: the estimator when ``params`` are missing.

    Returns
    -------
    str
        E.g. ``"starts random:100 · fov 60° · bearing noise 0° (1σ) · single-integrator dynamics ·
        kalman estimator"``.
    """
    p = dict(params or {})
    estimator = p.get("estimator") or dict(stats or {}).get("estimator")
    if not p:
        return "configuration not recorded (fov, noise and dynamics unknown)" + (
            f" · {estimator} estimator" if estimator else ""
        )
    starts = p.get("starts") or "map"
    parts = ["the map's starts" if starts == "map" else f"starts {starts}"]
    if p.get("measurement") == "displacement":
        parts.append("displacements measured (no camera)")
    else:
        rendered = " (rendered camera)" if p.get("camera") == "render" else ""
        parts.append(f"fov {float(p.get('fov', 360.0)):g}°{rendered}")
        bound = p.get("noise_bound_deg")
        parts.append(
            f"bearing noise ±{bound:g}° (bounded)"
            if bound is not None
            else f"bearing noise {float(p.get('noise_deg', 0.0)):g}° (1σ)"
        )
        if p.get("range") is not None:
            parts.append(f"range {p['range']:g}")
    dynamics = p.get("dynamics", "single")
    parts.append(f"{'single-integrator' if dynamics == 'single' else dynamics} dynamics")
    if estimator:
        parts.append(f"{estimator} estimator")
    return " · ".join(parts)


def legend_below(ax: plt.Axes, ncol: int = 3) -> None:
    """One legend of every labelled artist of the axes, each label once, below the axes in ``ncol`` columns.

    Below, not beside: a long entry then widens nothing, and the figure grows by its rows (:func:`finish`).

    The field's arrows get an arrow as their key (a quiver's own key is a rectangle, like an obstacle's),
    and a fill fainter than 0.3 a key at 0.3 (the faint fills of a simulation's cells overlap, so
    what a reader sees is deeper than one fill).
    """
    handles, labels = [], []
    for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
        if label in labels:
            continue
        if isinstance(handle, Quiver):
            handle = Line2D([], [], ls="none", marker=r"$\rightarrow$", markersize=11, color=handle.get_facecolor()[0])
        handles.append(handle)
        labels.append(label)
    if not handles:
        return
    legend = ax.legend(
        handles=handles,
        labels=labels,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.08),
        ncol=ncol,
        fontsize=7,
        frameon=False,
    )
    for key in legend.legend_handles:
        if isinstance(key, Patch) and key.get_alpha() is not None and key.get_alpha() < 0.3:
            key.set_alpha(0.3)


def map_frame(map_: Map, title: str, *, landmarks: bool = True) -> tuple[plt.Figure, plt.Axes]:
    """A figure of the map's shape (room on the right for a colour bar) with the map drawn, titled.

    Parameters
    ----------
    map_ : Map
        The map, drawn without landmark ids (they are placed once the layout is settled).
    title : str
        The figure's title.
    landmarks : bool
        Draw the landmarks.

    Returns
    -------
    (Figure, Axes)
    """
    xmin, ymin, xmax, ymax = map_.bounds
    width = 8.0
    height = max(3.0, width * (ymax - ymin) / (xmax - xmin))
    # constrained layout keeps a two-line title and the legend below inside the figure (tight_layout
    # does not, for an axes of equal aspect); the extra width holds a colour bar (finish)
    fig, ax = plt.subplots(figsize=(width + 1.8, height), layout="constrained")
    plot_map(ax, map_, labels=False, landmarks=landmarks)
    ax.set_title(title, fontsize=10)
    axis_labels(ax)
    return fig, ax


def _fit_title(ax: plt.Axes) -> None:
    """Make a title wider than the figure fit: a smaller font down to 8 pt, then its lines wrapped."""
    title, page = ax.title, ax.figure.bbox.width * 0.97
    width = title.get_window_extent().width
    if width <= page:
        return
    size = max(8.0, title.get_fontsize() * page / width)
    title.set_fontsize(size)
    width = title.get_window_extent().width
    if width > page:
        lines = title.get_text().split("\n")
        chars = int(max(len(line) for line in lines) * page / width)
        title.set_text("\n".join(textwrap.fill(line, chars) for line in lines))


def finish(fig: plt.Figure, ax: plt.Axes) -> None:
    """Legend, a figure sized for it, the title and a colour bar, and the layout, settled for the labels.

    The layout is computed once and then fixed: labels are placed in display space after it
    (:func:`place_labels`), and a layout redone at save time would move them.
    """
    w, h = fig.get_size_inches()
    fig.set_size_inches(w - (1.2 if len(fig.axes) == 1 else 0.0), h)  # the extra width is a colour bar's
    ncol, page = 3, fig.bbox.width
    legend_below(ax, ncol)
    # long entries: fewer columns, or the layout narrows the axes to make room for the legend
    while ax.get_legend() is not None and ncol > 1 and ax.get_legend().get_window_extent().width > 0.97 * page:
        ncol -= 1
        legend_below(ax, ncol)
    _fit_title(ax)
    legend = ax.get_legend()
    extra = 0.3 * ax.get_title().count("\n")
    if legend is not None:
        extra += 0.22 * math.ceil(len(legend.get_texts()) / ncol)
    w, h = fig.get_size_inches()
    fig.set_size_inches(w, h + extra)
    engine = fig.get_layout_engine()
    for _ in range(3):  # an axes of equal aspect can leave the title or the legend out: grow the figure until not
        engine.execute(fig)  # the layout alone, without drawing every artist
        # the title is the top of the figure and the legend its bottom (pixels)
        top = ax.title.get_window_extent().y1 - fig.bbox.y1
        bottom = -ax.get_legend().get_window_extent().y0 if ax.get_legend() is not None else 0.0
        over = (max(0.0, top) + max(0.0, bottom)) / fig.dpi
        if over <= 0.01:
            break
        w, h = fig.get_size_inches()
        fig.set_size_inches(w, h + over + 0.05)
    fig.set_layout_engine("none")


def save_figure(fig: plt.Figure, path: str) -> None:
    """Write ``fig`` to ``path`` (format from the suffix) and close it."""
    fig.savefig(path, dpi=150)
    plt.close(fig)
