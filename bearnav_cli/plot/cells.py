"""The cells' layers: fills by rank, tolerance, status or liveness, outlines, exit faces, barriers, indices.

A funnel cell is drawn where it is active (:func:`cell_regions`, where the funnel policy drives
with it); the uncovered free space and the barrier lines are layers of their own.
"""

from __future__ import annotations

from typing import Any, Sequence

import matplotlib.pyplot as plt
import numpy as np
import shapely
from matplotlib import colors as mcolors
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection
from matplotlib.patches import PathPatch
from matplotlib.path import Path as MplPath

from bearnav_cli.datatypes import Cells, CellStatus, active_regions, cell_polygons
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.palette import PALETTE, ROLE_COLORS, STATUS_COLORS
from bearnav_cli.plot.labels import CENTRED, label_key, place_labels
from bearnav_cli.plot.style import (
    AXIS_UNITS,
    EXIT_COLOR,
    OUTLINE_COLOR,
    UNCERTIFIED_COLOR,
    UNCOVERED_COLOR,
    UNREACHED_COLOR,
    add_geometry,
    shared_label,
)

__all__ = [
    "cell_regions",
    "cell_anchors",
    "CELL_NUMBER_LABEL",
    "cell_number_keys",
    "COLOR_BY",
    "label_cells",
    "LIVE_COLORS",
    "NEVER_ACTIVE_LABEL",
    "plot_barriers",
    "plot_cells",
    "plot_uncovered",
    "status_name",
]


#: ``--color-by`` choices: the cell's rank (cost-to-go), its usable tolerance ``τ_c``, its synthesis status,
#: or whether it is live (ALGORITHMS §12.5, a ``liveness.Liveness`` the caller measured).
COLOR_BY = ("rank", "tolerance", "status", "live")
#: The fills of ``--color-by live``.
LIVE_COLORS = {True: ROLE_COLORS["live"], False: ROLE_COLORS["not live"]}


def cell_regions(cells: Cells) -> list[shapely.Geometry]:
    """:func:`~bearnav_cli.datatypes.active_regions` of ``cells``: where each cell drives the robot."""
    return active_regions(cell_polygons(cells), cells.cell_rank)


def _cell_colors(
    cells: Cells, color_by: str, status: np.ndarray | None, tolerance: np.ndarray | None, live: np.ndarray | None = None
):
    """``(face colours (C, 4), mappable or None, colour-bar label)`` of the cells."""
    if color_by == "live":
        if live is None or len(live) != cells.n_cells:
            raise InvalidParamsError("live needs a funnel plan's liveness (liveness.measure)", field="color_by")
        return np.array([mcolors.to_rgba(LIVE_COLORS[bool(v)]) for v in live]), None, ""
    if color_by == "status":
        if status is None:
            raise InvalidParamsError("status needs a plan (cells.npz has no synthesis status)", field="color_by")
        faces = [mcolors.to_rgba(STATUS_COLORS[CellStatus(int(s))]) for s in status]
        return np.array(faces), None, ""
    if color_by == "rank":
        values, label = np.asarray(cells.cell_rank, float), f"rank: cost-to-go of the cell's node ({AXIS_UNITS})"
        norm = mcolors.Normalize(0.0, max(float(values.max()), 1e-12))
        cmap = plt.get_cmap("viridis")
    elif color_by == "tolerance":
        if tolerance is None:
            raise InvalidParamsError("tolerance needs a plan (cells.npz has no τ_c)", field="color_by")
        values = np.asarray(tolerance, float)
        if not np.any(np.isfinite(values) & (values > 0)):
            raise InvalidParamsError("tolerance needs a funnel plan (τ_c is NaN for paper cells)", field="color_by")
        finite = values[np.isfinite(values) & (values > 0)]
        values = np.clip(np.where(np.isnan(values), finite.min(), values), finite.min(), finite.max())
        lo, hi = float(finite.min()), float(finite.max())
        norm = mcolors.LogNorm(lo, hi) if hi > 3 * lo else mcolors.Normalize(lo, max(hi, lo * (1 + 1e-9)))
        cmap = mcolors.ListedColormap(plt.get_cmap("plasma")(np.linspace(0.08, 0.92, 256)))  # no near-black end
        label = f"τ_c = min(δ_c, δ_e,c/2): error under which the robot may move ({AXIS_UNITS})"
    else:
        raise InvalidParamsError(f"must be one of {', '.join(COLOR_BY)}, got {color_by!r}", field="color_by")
    return cmap(norm(values)), ScalarMappable(norm=norm, cmap=cmap), label


def status_name(value: int) -> str:
    """The legend label of the cells of a synthesis status: ``"cells: not certified"``."""
    return "cells: " + CellStatus(int(value)).name.lower().replace("_", " ")


#: Legend labels of the cell indices :func:`label_cells` writes.
CELL_NUMBER_LABEL = "cell index, where the cell is active (where it fits)"
NEVER_ACTIVE_LABEL = "index of a cell never active (lower-rank cells cover it)"
_NEVER_ACTIVE_STYLE = {"color": PALETTE["dark grey"], "fontstyle": "italic"}


def plot_cells(
    ax: plt.Axes,
    cells: Cells,
    status: np.ndarray | None = None,
    *,
    color_by: str | None = None,
    tolerance: np.ndarray | None = None,
    fill: float = 0.45,
    exit_faces: bool = True,
    numbers: bool = False,
    colorbar: bool = True,
    legend: bool = True,
    live: np.ndarray | None = None,
) -> plt.Axes:
    """Cells: thin outlines, exit faces, a fill by ``color_by`` and uncertified cells hatched vermillion.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (map units on both axes).
    cells : Cells
        The decomposition (or a plan's ``cells``) to draw.
    status : ndarray, shape (C,), optional
        Synthesis status of each cell (a plan's ``status``); status 2 or 3 is always highlighted.
    color_by : {"rank", "tolerance", "status", "live"}, optional
        Fill colour; default ``rank`` for funnel cells, else ``status`` when given (else outlines only);
        ``live``: green where the cell is live, vermillion where it is not (``live``).
        Each point is filled once, with the colour of its least-rank cell (:func:`cell_regions`, where
        the funnel policy drives with that cell); paper cells by status fill each status's union, the
        worst on top.
    tolerance : ndarray, shape (C,), optional
        ``δ_c`` of each cell, for ``color_by="tolerance"``.
    fill : float
        Opacity of the fill.
    exit_faces : bool
        Draw each cell's exit face (its edge on the exit row) as a dark line.
    numbers : bool
        Write each cell's index where it fits (:func:`label_cells`, in the layout as it stands).
    colorbar, legend : bool
        Add a colour bar (rank, tolerance) and legend labels (the fills by status or liveness carry
        theirs; the fills by rank or ``τ_c`` are read off the colour bar).
    live : ndarray of bool, shape (C,), optional
        Whether each cell is live (``liveness.Liveness.live``), for ``color_by="live"``.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.
    """

    seen: set = set()

    def key(name: str | None) -> str:
        return shared_label(name, seen) if legend and name else "_" + (name or "")

    if color_by is None:
        color_by = "rank" if cells.is_funnel else ("status" if status is not None else "")
    regions = cell_regions(cells) if cells.is_funnel else None
    if color_by:
        faces, mappable, label = _cell_colors(cells, color_by, status, tolerance, live)

        def name(c: int) -> str | None:
            if color_by == "status":
                return status_name(status[c])
            if color_by == "live":
                return "cells: live" if live[c] else "cells: not live (a look may not let it move on)"
            return None  # the colour bar says what the colour is

        if regions is not None or color_by != "status":
            for c, region in enumerate(regions if regions is not None else cell_regions(cells)):
                add_geometry(
                    ax,
                    region,
                    facecolor=faces[c],
                    alpha=fill,
                    edgecolor=PALETTE["white"],
                    lw=0.5,
                    zorder=0.5,
                    gid="cell-fill",
                    label=key(name(c)),
                )
        else:  # paper cells by status: each status's union once, the worst on top
            polys = cell_polygons(cells)
            for value in (
                CellStatus.CERTIFIED,
                CellStatus.GOAL,
                CellStatus.RELAXED,
                CellStatus.NOT_CERTIFIED,
                CellStatus.SOLVER_FAILURE,
            ):
                chosen = [polys[c] for c in np.flatnonzero(np.asarray(status) == value)]
                if chosen:
                    add_geometry(
                        ax,
                        shapely.union_all(chosen),
                        facecolor=STATUS_COLORS[value],
                        alpha=fill,
                        edgecolor="none",
                        zorder=0.5,
                        gid="cell-fill",
                        label=key(status_name(value)),
                    )
        if mappable is not None and colorbar:
            bar = ax.figure.colorbar(mappable, ax=ax, fraction=0.04, pad=0.015, shrink=0.9)
            bar.set_label(label, fontsize=8)
            bar.ax.tick_params(labelsize=7)
            bar.solids.set_alpha(fill)
    rings = [np.vstack([cells.vertices(c), cells.vertices(c)[:1]]) for c in range(cells.n_cells)]
    # faint: the cells overlap, and the fill's white edges already part the regions where each is used
    ax.add_collection(
        LineCollection(
            rings,
            colors=OUTLINE_COLOR,
            linewidths=0.3,
            alpha=0.3,
            zorder=0.8,
            label=key("cell outlines"),
            gid="cell-outlines",
        )
    )
    if exit_faces:
        faces_xy = []
        for c in np.flatnonzero(cells.cell_exit_row >= 0):
            v, k = cells.vertices(c), int(cells.cell_exit_row[c])
            faces_xy.append(np.stack([v[k], v[(k + 1) % len(v)]]))
        if faces_xy:
            ax.add_collection(
                LineCollection(
                    faces_xy, colors=EXIT_COLOR, linewidths=0.9, zorder=0.9, label=key("exit faces"), gid="exit-faces"
                )
            )
    if status is not None:
        bad = np.flatnonzero(np.isin(status, [CellStatus.NOT_CERTIFIED, CellStatus.SOLVER_FAILURE]))
        for c in bad:
            ring = np.vstack([cells.vertices(c), cells.vertices(c)[:1]])
            ax.add_patch(
                PathPatch(
                    MplPath(ring, closed=True),
                    facecolor="none",
                    edgecolor=UNCERTIFIED_COLOR,
                    hatch="xxx",
                    lw=1.6,
                    zorder=3.3,
                    gid=f"uncertified-cell-{c}",
                    label=key("uncertified cell (status 2/3)"),
                )
            )
    if numbers:
        label_cells(ax, cells, regions=regions, legend=legend)
    return ax


def cell_anchors(cells: Cells, regions: Sequence[shapely.Geometry] | None) -> tuple[np.ndarray, np.ndarray]:
    """Where each cell's index goes, and whether the cell is ever active.

    A funnel cell's index goes inside the largest part of its active region; a cell whose region is
    empty (never active) and a paper cell at its centroid. Returns ``(points (C, 2), active (C,))``.
    """
    points, active = np.zeros((cells.n_cells, 2)), np.ones(cells.n_cells, bool)
    for c in range(cells.n_cells):
        region = regions[c] if regions is not None else None
        if region is None or region.area <= 1e-12 * cells.map.diagonal**2:
            where = shapely.centroid(shapely.Polygon(cells.vertices(c)))
            active[c] = region is None
        else:
            where = shapely.point_on_surface(max(shapely.get_parts(region), key=lambda g: g.area))
        points[c] = (where.x, where.y)
    return points, active


def label_cells(
    ax: plt.Axes,
    cells: Cells,
    *,
    regions: Sequence[shapely.Geometry] | None = None,
    legend: bool = True,
    avoid: Any = None,
) -> list:
    """Write each cell's index where it fits (:func:`place_labels`, after the labels already written).

    The cells used somewhere come first (black, inside their active region), then those never active
    (dark grey italic, at their centroid). An index that would cover another label is left out, so
    call it once the layout is settled and after the labels that matter more (the landmarks').

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to write into (map units on both axes).
    cells : Cells
        The cells whose indices are written.
    regions : sequence of shapely geometry, optional
        :func:`cell_regions` of funnel cells (computed when not given; paper cells have none).
    legend : bool
        Add legend entries for the two kinds of index (:func:`label_key`).
    avoid : array_like, shape (m, 2), optional
        Markers no index may cover (map units).

    Returns
    -------
    list of matplotlib.text.Annotation
        The indices written (gid ``cell-number``).
    """
    if regions is None and cells.is_funnel:
        regions = cell_regions(cells)
    points, active = cell_anchors(cells, regions)
    if legend:
        cell_number_keys(ax, cells, active)
    for t in [t for t in ax.texts if t.get_gid() == "cell-number"]:
        t.remove()
    order = [np.flatnonzero(active), np.flatnonzero(~active)]
    texts = []
    for chosen, label, style in zip(
        order, (CELL_NUMBER_LABEL, NEVER_ACTIVE_LABEL), ({}, _NEVER_ACTIVE_STYLE), strict=True
    ):
        texts += place_labels(
            ax,
            [str(c) for c in chosen],
            points[chosen],
            gid="cell-number",
            label=label,
            avoid=avoid,
            offsets=CENTRED,
            replace=False,
            fontsize=5.5,
            zorder=8.5,
            **style,
        )
    return texts


def cell_number_keys(ax: plt.Axes, cells: Cells, active: np.ndarray | None = None) -> None:
    """Legend entries for :func:`label_cells`' indices (the never-active kind only when some cell is).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes whose legend gets the entries (add them before the legend is drawn).
    cells : Cells
        The cells whose indices are written.
    active : ndarray of bool, shape (C,), optional
        Whether each cell is ever active (computed from :func:`cell_regions` when not given).
    """
    if active is None:
        active = cell_anchors(cells, cell_regions(cells) if cells.is_funnel else None)[1]
    label_key(ax, "12", CELL_NUMBER_LABEL)
    if not np.all(active):
        label_key(ax, "12", NEVER_ACTIVE_LABEL, **_NEVER_ACTIVE_STYLE)


def plot_uncovered(
    ax: plt.Axes, cells: Cells, uncovered: shapely.Geometry, unreached: shapely.Geometry | None = None
) -> plt.Axes:
    """Hatch the free space no certificate covers, as :func:`bearnav_cli.composition.coverage_regions` splits it.

    Parameters
    ----------
    ax : Axes
        The axes to draw into (map units on both axes).
    cells : Cells
        The cells; their ``free_coverage`` goes into the legend label.
    uncovered : shapely geometry
        The reached part of ``F`` less the cells.
    unreached : shapely geometry, optional
        The parts of ``F`` no cell reaches (drawn in grey).
    """
    add_geometry(
        ax,
        uncovered,
        facecolor="none",
        edgecolor=UNCOVERED_COLOR,
        hatch="///",
        lw=0.6,
        zorder=2.7,
        gid="uncovered",
        label="free space no cell covers (part of F)",
    )
    if unreached is not None and not unreached.is_empty:
        add_geometry(
            ax,
            unreached,
            facecolor="none",
            edgecolor=UNREACHED_COLOR,
            hatch="\\\\",
            lw=0.6,
            zorder=2.7,
            gid="unreached",
            label="free space no cell reaches",
        )
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


def plot_barriers(ax: plt.Axes, cells: Cells, *, color: str = ROLE_COLORS["barrier"]) -> plt.Axes:
    """Every barrier line ``h(x) = 0``, clipped to its cell.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (map units on both axes).
    cells : Cells
        The cells whose barrier rows (``cells.barrier(c)``) are drawn; a line that misses its
        cell is skipped.
    color : str
        Matplotlib colour of the dashed lines.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.
    """
    segments = []
    for c in range(cells.n_cells):
        A, b = cells.rows(c)
        normals, offsets = cells.barrier(c)
        for n, q in zip(normals, offsets, strict=True):
            seg = _line_in_polygon(n, q, A, b)
            if seg is not None:
                segments.append(seg)
    if segments:
        ax.add_collection(
            LineCollection(
                segments,
                colors=color,
                linewidths=0.5,
                linestyles="--",
                alpha=0.7,
                zorder=3.5,
                label="barrier lines",
                gid="barrier-lines",
            )
        )
    return ax
