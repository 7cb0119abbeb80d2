"""Drawing every artifact with matplotlib; nothing else in bearnav imports matplotlib.

Each ``plot_<layer>(ax, artifact, ...)`` draws one layer on an existing axes and
returns it, in the manner of python-control's ``*_plot`` functions: compute
elsewhere, draw here. :func:`figure_for` composes the layers that suit an artifact.
The vector field is the runtime's own (:func:`bearnav_cli.runtime.locate` and
:func:`bearnav_cli.runtime.field` on a grid), so the figure shows what a robot runs.
"""

from __future__ import annotations

import math
import textwrap
from typing import Any, Mapping, Sequence

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import shapely
from matplotlib import colors as mcolors
from matplotlib import patheffects
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, PathPatch
from matplotlib.path import Path as MplPath
from matplotlib.quiver import Quiver
from shapely.geometry.polygon import orient

from bearnav_cli import runtime
from bearnav_cli.datatypes import Cells, CellStatus, Map, Plan, Polygon, Simulation, Tree, tolerance_by_area
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.palette import OUTCOME_COLORS, PALETTE, ROLE_COLORS, STATUS_COLORS

__all__ = [
    "active_regions",
    "ADDED_COLOR",
    "AXIS_UNITS",
    "cell_number_keys",
    "CELL_NUMBER_LABEL",
    "cell_polygons",
    "CENTRED",
    "COLOR_BY",
    "CORNERS",
    "EXISTING_TAG_COLOR",
    "EXISTING_TAGS_LABEL",
    "EXIT_COLOR",
    "field_samples",
    "figure_for",
    "figure_title",
    "GOAL_COLOR",
    "HALO",
    "INFLATED_COLOR",
    "label_cells",
    "label_key",
    "label_landmarks",
    "label_tags",
    "LANDMARK_COLOR",
    "LANDMARKS_LABEL",
    "LIVE_COLORS",
    "map_handles",
    "MARKER_HALF",
    "NEVER_ACTIVE_LABEL",
    "OUTCOME_NAMES",
    "OUTLINE_COLOR",
    "PERCEPTION_FAIL_COLOR",
    "PERCEPTION_FAIL_FREE_COLOR",
    "place_labels",
    "plot_barriers",
    "plot_cells",
    "plot_estimate_trace",
    "plot_field",
    "plot_map",
    "plot_perception",
    "plot_samples",
    "plot_sim_background",
    "plot_tags",
    "plot_trajectories",
    "plot_tree",
    "plot_uncovered",
    "PROPOSED_TAG_COLOR",
    "PROPOSED_TAGS_LABEL",
    "RAW_COLOR",
    "save_animation",
    "save_figure",
    "simulation_config",
    "sweep_plot",
    "tags_figure",
    "TREE_COLOR",
    "UNCERTIFIED_COLOR",
    "UNCOVERED_COLOR",
    "UNREACHED_COLOR",
    "use_file_backend",
]


def use_file_backend() -> None:
    """Switch matplotlib to its file backend (Agg), as the command line does before drawing.

    Importing this module leaves the backend alone, so a notebook that imports it keeps its own.
    """
    matplotlib.use("Agg")


# Every colour is the palette's (bearnav_cli.palette, one source for figures and bags); these names are
# the roles this module and the figure scripts of repro/ draw with.
RAW_COLOR = ROLE_COLORS["raw obstacle"]
INFLATED_COLOR = ROLE_COLORS["inflated obstacle"]
OUTLINE_COLOR = ROLE_COLORS["cell outline"]
EXIT_COLOR = ROLE_COLORS["exit face"]
UNCERTIFIED_COLOR = ROLE_COLORS["uncertified"]
UNCOVERED_COLOR = ROLE_COLORS["uncovered"]
ADDED_COLOR = ROLE_COLORS["added node"]
LANDMARK_COLOR = ROLE_COLORS["landmark"]
GOAL_COLOR = ROLE_COLORS["goal"]
TREE_COLOR = ROLE_COLORS["tree"]
#: ``--color-by`` choices: the cell's rank (cost-to-go), its usable tolerance ``τ_c``, its synthesis status,
#: or whether it is live (ALGORITHMS §12.5, a ``liveness.Liveness`` the caller measured).
COLOR_BY = ("rank", "tolerance", "status", "live")
#: The fills of ``--color-by live``.
LIVE_COLORS = {True: ROLE_COLORS["live"], False: ROLE_COLORS["not live"]}
#: Parts of ``F_m`` that no cell reaches (cut off by passages narrower than ``2m``).
UNREACHED_COLOR = ROLE_COLORS["unreached"]
AXIS_UNITS = "map units"


def _polygon_patch(polygon: Polygon, **style: Any) -> PathPatch:
    rings = [polygon.exterior, *polygon.holes]
    vertices = np.concatenate([np.vstack([r, r[:1]]) for r in rings])
    codes = np.concatenate([[MplPath.MOVETO] + [MplPath.LINETO] * (len(r) - 1) + [MplPath.CLOSEPOLY] for r in rings])
    return PathPatch(MplPath(vertices, codes), **style)


def _geometry_path(geom: shapely.Geometry) -> MplPath | None:
    """The polygons of a shapely geometry as one matplotlib path (holes cut out), or None if empty."""
    vertices, codes = [], []
    for part in shapely.get_parts(geom):
        if not isinstance(part, shapely.Polygon) or part.is_empty:
            continue
        part = orient(part, 1.0)
        for ring in (part.exterior, *part.interiors):
            xy = np.asarray(ring.coords)
            vertices.append(xy)
            codes.append([MplPath.MOVETO] + [MplPath.LINETO] * (len(xy) - 2) + [MplPath.CLOSEPOLY])
    return MplPath(np.concatenate(vertices), np.concatenate(codes)) if vertices else None


def _add_geometry(ax: plt.Axes, geom: shapely.Geometry, **style: Any) -> PathPatch | None:
    path = _geometry_path(geom)
    return None if path is None else ax.add_patch(PathPatch(path, **style))


#: Legend label of the map's landmarks; their ids are written beside them where they fit.
LANDMARKS_LABEL = "landmarks (ids beside them where they fit)"
#: The white outline behind every label, so that it reads over fills, arrows and lines.
HALO = (patheffects.withStroke(linewidth=2, foreground=PALETTE["white"]),)
#: A label's places around its point: (dx, dy) offset in points, horizontal and vertical alignment.
CORNERS = ((3.5, 3.5, "left", "bottom"), (-3.5, 3.5, "right", "bottom"), (3.5, -3.5, "left", "top"),
           (-3.5, -3.5, "right", "top"))  # fmt: skip
#: Half the side of the box a marker of ``avoid`` keeps clear (points): a landmark triangle's, so that a
#: label at a corner touches its own marker but covers no other.
MARKER_HALF = 3.0
#: Centred on its point, else nudged a little up, down, right or left (a cell's index inside its region).
CENTRED = ((0, 0, "center", "center"), (0, 4, "center", "center"), (0, -4, "center", "center"),
           (5, 0, "center", "center"), (-5, 0, "center", "center"))  # fmt: skip


def plot_map(ax: plt.Axes, map_: Map, *, landmarks: bool = True, starts: bool = True, labels: bool | None = None,
             walls: bool = True) -> plt.Axes:  # fmt: skip
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
    ax.plot([xmin, xmax, xmax, xmin, xmin], [ymin, ymin, ymax, ymax, ymin], color=ROLE_COLORS["bounds"], lw=1.2,
            gid="bounds", label="_bounds")  # the frame of the map: no legend entry  # fmt: skip
    inflated = f"inflated by the robot radius ({map_.robot_radius:g})"
    if map_.lookahead > 0:
        inflated = f"inflated by radius + look-ahead ({map_.robot_radius:g} + {map_.lookahead:g})"
    seen: set = set()
    # the raw obstacles' entry first: it is the one a reader looks for
    for poly in map_.raw_obstacles:
        ax.add_patch(_polygon_patch(poly, facecolor=RAW_COLOR, edgecolor="none", zorder=2, gid="obstacles",
                                    label=_shared("obstacles", seen)))  # fmt: skip
    if walls and map_.planning_radius > 0:
        band = shapely.difference(shapely.box(*map_.bounds), shapely.box(*map_.free_bounds))
        _add_geometry(ax, band, facecolor=INFLATED_COLOR, edgecolor="none", zorder=1, gid="inflated",
                      label=_shared(inflated, seen))  # fmt: skip
    for poly in map_.obstacles:
        ax.add_patch(_polygon_patch(poly, facecolor=INFLATED_COLOR, edgecolor="none", zorder=1, gid="inflated",
                                    label=_shared(inflated, seen)))  # fmt: skip
    if landmarks and len(map_.landmarks):
        ax.scatter(*map_.landmarks.T, marker="^", s=40, color=LANDMARK_COLOR, edgecolor=ROLE_COLORS["edge"],
                   linewidths=0.5, zorder=6, gid="landmarks", label=LANDMARKS_LABEL)  # fmt: skip
    if starts and len(map_.starts):
        ax.scatter(*map_.starts.T, marker="o", s=36, facecolor=ROLE_COLORS["edge"], edgecolor=ROLE_COLORS["start"],
                   linewidths=1.0, zorder=6, gid="map-starts", label="map starts")  # fmt: skip
    ax.scatter(*map_.goal, marker="*", s=200, color=GOAL_COLOR, edgecolor=PALETTE["black"], linewidths=0.6, zorder=7,
               gid="goal", label="goal")  # fmt: skip
    pad = 0.02 * map_.diagonal
    ax.set_xlim(xmin - pad, xmax + pad)
    ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_aspect("equal")
    if landmarks and labels is not False:
        label_landmarks(ax, map_, every=bool(labels))
    return ax


def _shared(label: str, seen: set) -> str:
    """``label`` for the first artist of a legend entry, ``_label`` for the others that share it.

    matplotlib leaves labels starting with ``_`` out of a legend, so the entry appears once; the
    underscore form still names the entry the artist belongs to (what the tests read).
    """
    if label in seen:
        return "_" + label
    seen.add(label)
    return label


def _boxes(boxes: Sequence[Any]) -> np.ndarray:
    """Bounding boxes (matplotlib ``Bbox`` or ``(x0, y0, x1, y1)``) as an (n, 4) array."""
    rows = [(b.x0, b.y0, b.x1, b.y1) if hasattr(b, "x0") else tuple(b) for b in boxes]
    return np.array(rows, float).reshape(-1, 4)


def place_labels(ax: plt.Axes, texts: Sequence[str], points: Any, *, gid: str, label: str | None = None,
                 avoid: Any = None, offsets: Sequence[tuple] = CORNERS, every: bool = False, replace: bool = True,
                 **style: Any) -> list:  # fmt: skip
    """Write short texts beside points, leaving out those that would collide: every figure's one label placement.

    Each text tries ``offsets`` in turn and takes the first place whose box meets no visible text
    of the axes (an earlier call's labels too, so what is labelled first wins), no marker around
    ``avoid``, no legend or other axes (a colour bar) and stays in the figure. Boxes are the
    renderer's window extents as the figure stands now: call it after the layout is settled
    (:func:`figure_for` does).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to write into (map units on both axes).
    texts : sequence of str
        The labels, in order of priority.
    points : array_like, shape (n, 2)
        Where each label belongs (map units).
    gid : str
        The gid of every text written (what a later call with this gid replaces).
    label : str, optional
        The legend label each text carries (:func:`label_key` draws its legend entry).
    avoid : array_like, shape (m, 2), optional
        Marker positions (map units) no label may cover (a box of :data:`MARKER_HALF` points around each).
    offsets : sequence of (dx, dy, ha, va)
        The places to try: offsets in points from the point and the text's alignment
        (:data:`CORNERS` beside a marker, :data:`CENTRED` on a spot).
    every : bool
        Keep a text that fits nowhere, at its first place (labels may then collide).
    replace : bool
        Remove the texts an earlier call wrote with this ``gid`` first (a redraw after the layout
        changed); False adds to them.
    **style
        Text properties (default 6.5 pt, black, with a white :data:`HALO`).

    Returns
    -------
    list of matplotlib.text.Annotation
        The texts written (those that fit, or all with ``every``).
    """
    for text in [t for t in ax.texts if replace and t.get_gid() == gid]:
        text.remove()
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    ax.apply_aspect()
    style = {"fontsize": 6.5, "color": ROLE_COLORS["text"], "zorder": 8, "path_effects": list(HALO)} | style
    taken = [t.get_window_extent(renderer) for t in ax.texts if t.get_visible() and t.get_text()]
    taken += [other.get_window_extent(renderer) for other in fig.axes if other is not ax]
    if ax.get_legend() is not None:
        taken.append(ax.get_legend().get_window_extent(renderer))
    r = MARKER_HALF * fig.dpi / 72
    marks = ax.transData.transform(np.asarray(avoid, float).reshape(-1, 2)) if avoid is not None else np.zeros((0, 2))
    boxes = np.vstack([_boxes(taken), np.column_stack([marks - r, marks + r])])
    page = fig.bbox
    placed = []
    for name, point in zip(texts, np.asarray(points, float).reshape(-1, 2), strict=True):
        text = ax.annotate(str(name), point, xytext=offsets[0][:2], textcoords="offset points", gid=gid,
                           label=label or "_label", ha=offsets[0][2], va=offsets[0][3], **style)  # fmt: skip
        for dx, dy, ha, va in offsets:
            text.xyann = (dx, dy)
            text.set(ha=ha, va=va)
            b = text.get_window_extent(renderer)
            inside = page.x0 <= b.x0 and b.x1 <= page.x1 and page.y0 <= b.y0 and b.y1 <= page.y1
            if inside and not np.any((b.x0 < boxes[:, 2]) & (boxes[:, 0] < b.x1) & (b.y0 < boxes[:, 3])
                                     & (boxes[:, 1] < b.y1)):  # fmt: skip
                break
        else:
            if not every:
                text.remove()
                continue
            text.xyann = offsets[0][:2]
            text.set(ha=offsets[0][2], va=offsets[0][3])
            b = text.get_window_extent(renderer)
        boxes = np.vstack([boxes, [[b.x0, b.y0, b.x1, b.y1]]])
        placed.append(text)
    return placed


def label_key(ax: plt.Axes, sample: str, label: str, **style: Any) -> None:
    """A legend entry for labels: ``sample`` drawn as text in the labels' ``style`` (colour, font style).

    An empty line whose marker is the text, so that :func:`figure_for`'s legend shows it like any
    other mark; a second call with the same ``label`` adds nothing.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes whose legend gets the entry.
    sample : str
        The text the key shows (e.g. ``"12"`` for cell indices).
    label : str
        The entry's text (the label :func:`place_labels` gives the texts it stands for).
    **style
        ``color`` and ``fontstyle`` (``"italic"``) of those texts.
    """
    if label in [h.get_label() for h in ax.lines]:
        return
    weight = r"\mathit" if style.get("fontstyle") == "italic" else r"\mathrm"
    ax.plot([], [], ls="none", marker=f"${weight}{{{sample}}}$", markersize=9 if len(sample) < 3 else 12,
            color=style.get("color", ROLE_COLORS["text"]), label=label, gid="label-key")  # fmt: skip


def label_landmarks(ax: plt.Axes, map_: Map, *, every: bool = False) -> list:
    """Write landmark ids beside their markers (:func:`place_labels`); unless ``every``, skip those that would collide.

    Each label tries the four corners around its landmark and takes the first whose text box meets no
    earlier label and no landmark marker. Call it after the layout is settled.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (map units on both axes).
    map_ : Map
        The map whose ``landmark_ids`` are written at its ``landmarks``.
    every : bool
        Label every landmark, at its first corner, even where labels collide.

    Returns
    -------
    list of matplotlib.text.Annotation
        The label artists (gid ``landmark-label``, legend label :data:`LANDMARKS_LABEL`).
    """
    return place_labels(ax, map_.landmark_ids, map_.landmarks, gid="landmark-label", label=LANDMARKS_LABEL,
                        avoid=map_.landmarks, every=every, color=LANDMARK_COLOR)  # fmt: skip


def _edges(nodes: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """Child → parent segments, shape (N−1, 2, 2)."""
    child = np.flatnonzero(parent >= 0)
    return np.stack([nodes[child], nodes[parent[child]]], axis=1)


# --------------------------------------------------------------------------- cells


def cell_polygons(cells: Cells) -> list[shapely.Polygon]:
    """Every cell as a shapely polygon."""
    return [shapely.Polygon(cells.vertices(c)) for c in range(cells.n_cells)]


def active_regions(cells: Cells) -> list[shapely.Geometry]:
    """Where each cell drives the robot under the funnel policy (ALGORITHMS §11.3).

    Cell ``c``'s region is ``P_c`` less every cell of smaller rank (ties: lower index), i.e. the
    points where :func:`bearnav_cli.runtime.least_rank_cell` returns ``c``. The regions do not
    overlap and their union is ``D``; a cell whose region is empty is never used.
    """
    polys = cell_polygons(cells)
    regions: list[shapely.Geometry] = [shapely.Polygon()] * cells.n_cells
    taken: shapely.Geometry = shapely.Polygon()
    for c in np.lexsort((np.arange(cells.n_cells), cells.cell_rank)):
        regions[c] = shapely.difference(polys[c], taken)
        taken = shapely.union(taken, polys[c])
    return regions


def _cell_colors(cells: Cells, color_by: str, status: np.ndarray | None, tolerance: np.ndarray | None,
                 live: np.ndarray | None = None):  # fmt: skip
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


def _status_name(value: int) -> str:
    return "cells: " + CellStatus(int(value)).name.lower().replace("_", " ")


#: Legend labels of the cell indices :func:`label_cells` writes.
CELL_NUMBER_LABEL = "cell index, where the cell is active (where it fits)"
NEVER_ACTIVE_LABEL = "index of a cell never active (lower-rank cells cover it)"
_NEVER_ACTIVE_STYLE = {"color": PALETTE["dark grey"], "fontstyle": "italic"}


def plot_cells(ax: plt.Axes, cells: Cells, status: np.ndarray | None = None, *, color_by: str | None = None,
               tolerance: np.ndarray | None = None, fill: float = 0.45, exit_faces: bool = True,
               numbers: bool = False, colorbar: bool = True, legend: bool = True,
               live: np.ndarray | None = None) -> plt.Axes:  # fmt: skip
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
        Each point is filled once, with the colour of its least-rank cell (:func:`active_regions`, where
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
        return _shared(name, seen) if legend and name else "_" + (name or "")

    if color_by is None:
        color_by = "rank" if cells.is_funnel else ("status" if status is not None else "")
    regions = active_regions(cells) if cells.is_funnel else None
    if color_by:
        faces, mappable, label = _cell_colors(cells, color_by, status, tolerance, live)

        def name(c: int) -> str | None:
            if color_by == "status":
                return _status_name(status[c])
            if color_by == "live":
                return "cells: live" if live[c] else "cells: not live (a look may not let it move on)"
            return None  # the colour bar says what the colour is

        if regions is not None or color_by != "status":
            for c, region in enumerate(regions if regions is not None else active_regions(cells)):
                _add_geometry(ax, region, facecolor=faces[c], alpha=fill, edgecolor=PALETTE["white"], lw=0.5,
                              zorder=0.5, gid="cell-fill", label=key(name(c)))  # fmt: skip
        else:  # paper cells by status: each status's union once, the worst on top
            polys = cell_polygons(cells)
            for value in (CellStatus.CERTIFIED, CellStatus.GOAL, CellStatus.RELAXED, CellStatus.NOT_CERTIFIED,
                          CellStatus.SOLVER_FAILURE):  # fmt: skip
                chosen = [polys[c] for c in np.flatnonzero(np.asarray(status) == value)]
                if chosen:
                    _add_geometry(ax, shapely.union_all(chosen), facecolor=STATUS_COLORS[value], alpha=fill,
                                  edgecolor="none", zorder=0.5, gid="cell-fill",
                                  label=key(_status_name(value)))  # fmt: skip
        if mappable is not None and colorbar:
            bar = ax.figure.colorbar(mappable, ax=ax, fraction=0.04, pad=0.015, shrink=0.9)
            bar.set_label(label, fontsize=8)
            bar.ax.tick_params(labelsize=7)
            bar.solids.set_alpha(fill)
    rings = [np.vstack([cells.vertices(c), cells.vertices(c)[:1]]) for c in range(cells.n_cells)]
    # faint: the cells overlap, and the fill's white edges already part the regions where each is used
    ax.add_collection(LineCollection(rings, colors=OUTLINE_COLOR, linewidths=0.3, alpha=0.3, zorder=0.8,
                                     label=key("cell outlines"), gid="cell-outlines"))  # fmt: skip
    if exit_faces:
        faces_xy = []
        for c in np.flatnonzero(cells.cell_exit_row >= 0):
            v, k = cells.vertices(c), int(cells.cell_exit_row[c])
            faces_xy.append(np.stack([v[k], v[(k + 1) % len(v)]]))
        if faces_xy:
            ax.add_collection(LineCollection(faces_xy, colors=EXIT_COLOR, linewidths=0.9, zorder=0.9,
                                             label=key("exit faces"), gid="exit-faces"))  # fmt: skip
    if status is not None:
        bad = np.flatnonzero(np.isin(status, [CellStatus.NOT_CERTIFIED, CellStatus.SOLVER_FAILURE]))
        for c in bad:
            ring = np.vstack([cells.vertices(c), cells.vertices(c)[:1]])
            ax.add_patch(PathPatch(MplPath(ring, closed=True), facecolor="none", edgecolor=UNCERTIFIED_COLOR,
                                   hatch="xxx", lw=1.6, zorder=3.3, gid=f"uncertified-cell-{c}",
                                   label=key("uncertified cell (status 2/3)")))  # fmt: skip
    if numbers:
        label_cells(ax, cells, regions=regions, legend=legend)
    return ax


def _cell_anchors(cells: Cells, regions: Sequence[shapely.Geometry] | None) -> tuple[np.ndarray, np.ndarray]:
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


def label_cells(ax: plt.Axes, cells: Cells, *, regions: Sequence[shapely.Geometry] | None = None,
                legend: bool = True, avoid: Any = None) -> list:  # fmt: skip
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
        :func:`active_regions` of funnel cells (computed when not given; paper cells have none).
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
        regions = active_regions(cells)
    points, active = _cell_anchors(cells, regions)
    if legend:
        cell_number_keys(ax, cells, active)
    for t in [t for t in ax.texts if t.get_gid() == "cell-number"]:
        t.remove()
    order = [np.flatnonzero(active), np.flatnonzero(~active)]
    texts = []
    for chosen, label, style in zip(order, (CELL_NUMBER_LABEL, NEVER_ACTIVE_LABEL), ({}, _NEVER_ACTIVE_STYLE),
                                    strict=True):  # fmt: skip
        texts += place_labels(ax, [str(c) for c in chosen], points[chosen], gid="cell-number", label=label,
                              avoid=avoid, offsets=CENTRED, replace=False, fontsize=5.5, zorder=8.5,
                              **style)  # fmt: skip
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
        Whether each cell is ever active (computed from :func:`active_regions` when not given).
    """
    if active is None:
        active = _cell_anchors(cells, active_regions(cells) if cells.is_funnel else None)[1]
    label_key(ax, "12", CELL_NUMBER_LABEL)
    if not np.all(active):
        label_key(ax, "12", NEVER_ACTIVE_LABEL, **_NEVER_ACTIVE_STYLE)


def plot_uncovered(ax: plt.Axes, cells: Cells, uncovered: shapely.Geometry,
                   unreached: shapely.Geometry | None = None) -> plt.Axes:  # fmt: skip
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
    _add_geometry(ax, uncovered, facecolor="none", edgecolor=UNCOVERED_COLOR, hatch="///", lw=0.6,
                  zorder=2.7, gid="uncovered", label="free space no cell covers (part of F)")  # fmt: skip
    if unreached is not None and not unreached.is_empty:
        _add_geometry(ax, unreached, facecolor="none", edgecolor=UNREACHED_COLOR, hatch="\\\\", lw=0.6,
                      zorder=2.7, gid="unreached", label="free space no cell reaches")  # fmt: skip
    return ax


def _draw_cells(ax: plt.Axes, vertices: np.ndarray, offsets: np.ndarray, status: np.ndarray | None, *,
                fill: float = 0.25, line: float = 0.6, lw: float = 0.4, legend: bool = True,
                skip: Sequence[int] = ()) -> plt.Axes:  # fmt: skip
    """Cells given as coords + offsets: outlines, and fills by status when given (labelled ``cells: <status>``;
    none for the statuses in ``skip``)."""
    seen: set = set()
    for c in range(len(offsets) - 1):
        v = vertices[offsets[c] : offsets[c + 1]]
        if status is not None and int(status[c]) not in skip:
            name = _status_name(status[c])
            ax.fill(*v.T, color=STATUS_COLORS[CellStatus(int(status[c]))], alpha=fill, lw=0, zorder=0.5,
                    gid="cell-fill", label=_shared(name, seen) if legend else "_" + name)  # fmt: skip
    rings = [np.vstack([vertices[a:b], vertices[a : a + 1]]) for a, b in zip(offsets[:-1], offsets[1:], strict=True)]
    ax.add_collection(LineCollection(rings, colors=OUTLINE_COLOR, linewidths=lw, alpha=line, zorder=0.6,
                                     gid="cell-outlines",
                                     label="cell outlines" if legend else "_cell outlines"))  # fmt: skip
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
        ax.add_collection(LineCollection(segments, colors=color, linewidths=0.5, linestyles="--", alpha=0.7,
                                         zorder=3.5, label="barrier lines", gid="barrier-lines"))  # fmt: skip
    return ax


# --------------------------------------------------------------------------- field, tree, samples


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
        ax.quiver(*points.T, *directions.T, angles="xy", scale_units="xy", scale=1.0 / (0.6 * step), pivot="tail",
                  width=0.002, headwidth=4, headlength=4.5, color=ROLE_COLORS["field"], alpha=0.6, zorder=3.8,
                  label="field direction (runtime policy)", gid="field")  # fmt: skip
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
        ax.add_collection(LineCollection(segments, colors=color, linewidths=lw, alpha=alpha, zorder=4, label=key,
                                         gid="tree"))  # fmt: skip
    if nodes:
        added = np.asarray(getattr(tree, "node_added", np.zeros(len(tree.nodes), bool)), bool)
        # the nodes share the edges' legend entry
        ax.scatter(*tree.nodes[~added].T, s=5, color=color, alpha=alpha, zorder=5, label="_" + key.lstrip("_"),
                   gid="tree-nodes")  # fmt: skip
        if added.any():
            ax.scatter(*tree.nodes[added].T, s=14, marker="D", color=ADDED_COLOR, edgecolor=ROLE_COLORS["edge"],
                       linewidths=0.4, alpha=alpha, zorder=5, gid="added-nodes",
                       label=f"added nodes ({int(added.sum())}, densification)")  # fmt: skip
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
        ax.scatter(*tree.collision_samples.T, s=3, marker="x", linewidths=0.6, color=color, zorder=3,
                   gid="collision-samples", label="collision samples")  # fmt: skip
    return ax


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
            patch = _add_geometry(ax, shapely.Polygon(ring), facecolor=colour, alpha=0.55, edgecolor=colour, lw=0.4,
                                  zorder=5)  # fmt: skip
            if patch is not None:
                patch.set_label(_shared(label, seen))
    looked = trace.looking
    if looked.any():
        ax.plot(*trace.truth[looked].T, "o", ms=2.5, mfc="none", mec=ROLE_COLORS["looked"], zorder=6,
                label="stopped to look")  # fmt: skip
    bar = plt.colorbar(ScalarMappable(norm=norm, cmap=colours), ax=ax, fraction=0.04, pad=0.02)
    bar.set_label(f"error radius e ({AXIS_UNITS})")
    return ax


def plot_sim_background(ax: plt.Axes, sim: Simulation) -> plt.Axes:
    """The simulation's cells and tree, faintly: outlines, and a fill by status for the cells not plainly certified.

    Certified cells are left unfilled (their green would be the success paths' colour, and overlapping
    cells stack into a shade that hides the runs); the goal cell, relaxed and uncertified cells are
    filled. The tree is dark grey, apart from every outcome's colour.
    """
    status = np.asarray(sim.cell_status)
    _draw_cells(ax, sim.cell_vertices, sim.cell_vertex_offsets, status, fill=0.25, line=0.35, lw=0.3,
                skip=(CellStatus.CERTIFIED,))  # fmt: skip
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
        ax.plot(*path.T, color=color, lw=0.9, alpha=0.85, zorder=4, label=_shared(OUTCOME_NAMES[outcome], seen),
                gid="run")  # fmt: skip
        ax.plot(*path[0], "o", ms=3, color=color, mfc=ROLE_COLORS["edge"], mec=color, zorder=5,
                label=_shared("run starts", seen), gid="run-start")  # fmt: skip
        if outcome != 0:
            ax.plot(*path[-1], "x", ms=5, color=color, zorder=5, label=_shared("where a failed run ended", seen),
                    gid="run-end")  # fmt: skip
    return ax


# --------------------------------------------------------------------------- figures


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
        parts.append(f"bearing noise ±{bound:g}° (bounded)" if bound is not None
                     else f"bearing noise {float(p.get('noise_deg', 0.0)):g}° (1σ)")  # fmt: skip
        if p.get("range") is not None:
            parts.append(f"range {p['range']:g}")
    dynamics = p.get("dynamics", "single")
    parts.append(f"{'single-integrator' if dynamics == 'single' else dynamics} dynamics")
    if estimator:
        parts.append(f"{estimator} estimator")
    return " · ".join(parts)


def _simulation_title(sim: Simulation, params: Mapping[str, Any] | None) -> str:
    runs = len(sim.outcome)
    reached = int(np.sum(np.asarray(sim.outcome) == 0))
    summary = f"{reached} of {runs} runs reached the goal ({reached / runs:.1%})" if runs else "no runs"
    return figure_title(sim.map.name, "simulate", summary, simulation_config(params, sim.stats))


def _legend(ax: plt.Axes, ncol: int = 3) -> None:
    """One legend of every labelled artist of the axes, each label once, below the axes in ``ncol`` columns.

    Below, not beside: a long entry then widens nothing, and the figure grows by its rows (:func:`_finish`).

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
    legend = ax.legend(handles=handles, labels=labels, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=ncol,
                       fontsize=7, frameon=False)  # fmt: skip
    for key in legend.legend_handles:
        if isinstance(key, Patch) and key.get_alpha() is not None and key.get_alpha() < 0.3:
            key.set_alpha(0.3)


def _frame(map_: Map, title: str, *, landmarks: bool = True) -> tuple[plt.Figure, plt.Axes]:
    xmin, ymin, xmax, ymax = map_.bounds
    width = 8.0
    height = max(3.0, width * (ymax - ymin) / (xmax - xmin))
    # constrained layout keeps a two-line title and the legend below inside the figure (tight_layout
    # does not, for an axes of equal aspect); the extra width holds a colour bar (_finish)
    fig, ax = plt.subplots(figsize=(width + 1.8, height), layout="constrained")
    plot_map(ax, map_, labels=False, landmarks=landmarks)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(f"x ({AXIS_UNITS})")
    ax.set_ylabel(f"y ({AXIS_UNITS})")
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


def _finish(fig: plt.Figure, ax: plt.Axes) -> None:
    """Legend, a figure sized for it, the title and a colour bar, and the layout, settled for the labels.

    The layout is computed once and then fixed: labels are placed in display space after it
    (:func:`place_labels`), and a layout redone at save time would move them.
    """
    w, h = fig.get_size_inches()
    fig.set_size_inches(w - (1.2 if len(fig.axes) == 1 else 0.0), h)  # the extra width is a colour bar's
    ncol, page = 3, fig.bbox.width
    _legend(ax, ncol)
    # long entries: fewer columns, or the layout narrows the axes to make room for the legend
    while ax.get_legend() is not None and ncol > 1 and ax.get_legend().get_window_extent().width > 0.97 * page:
        ncol -= 1
        _legend(ax, ncol)
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


def save_animation(sim: Simulation, path: str, *, frames: int = 80, limit: int = 60,
                   params: Mapping[str, Any] | None = None) -> None:  # fmt: skip
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

    fig, ax = _frame(sim.map, _simulation_title(sim, params))
    plot_sim_background(ax, sim)
    runs = [r for r in range(min(len(sim.outcome), limit)) if len(sim.trajectory(r))]
    seen: set = set()
    lines = [ax.plot([], [], color=OUTCOME_COLORS[int(sim.outcome[r])], lw=0.9, zorder=4,
                     label=_shared(OUTCOME_NAMES[int(sim.outcome[r])], seen))[0] for r in runs]  # fmt: skip
    colors = [OUTCOME_COLORS[int(sim.outcome[r])] for r in runs]
    heads = ax.scatter(np.zeros(len(runs)), np.zeros(len(runs)), s=12, zorder=5, c=colors)
    offsets = sim.trajectory_offsets
    headings = [np.asarray(sim.trajectory_heading[offsets[r] : offsets[r + 1]], float) for r in runs]
    has_heading = all(len(h) == len(sim.trajectory(r)) for h, r in zip(headings, runs, strict=True)) and runs
    xmin, ymin, xmax, ymax = sim.map.bounds
    size = 0.03 * max(xmax - xmin, ymax - ymin)  # each robot's heading, an arrow this long
    arrows = ax.quiver(np.zeros(len(runs)), np.zeros(len(runs)), np.ones(len(runs)), np.zeros(len(runs)),
                       color=colors, angles="xy", scale_units="xy", scale=1.0 / size, width=0.004,
                       zorder=5.5) if has_heading else None  # fmt: skip
    longest = max((len(sim.trajectory(r)) for r in runs), default=1)
    _finish(fig, ax)
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
    summary = (f"{len(map_.raw_obstacles)} obstacles, {len(map_.landmarks)} landmarks, {len(map_.starts)} starts, "
               f"robot radius {map_.robot_radius:g}")  # fmt: skip
    return figure_title(map_.name, "map", summary)


def _perception_config(coverage: Any) -> str:
    target = coverage.error_target
    rule = "2 usable tags in view" if target is None else f"a fix within {target:g} in view"
    return (f"perception: {coverage.fov_deg:g}° camera, {coverage.noise_deg:g}° noise: {rule} on "
            f"{coverage.fraction_domain:.1%} of D")  # fmt: skip


def figure_for(artifact: Any, *, background: Sequence[Any] = (), title: str | None = None,
               color_by: str | None = None, barriers: bool = False, labels: bool | None = None,
               cell_numbers: bool = False, arrows: int = 28, coverage: Any = None,
               perception: Any = None, liveness: Any = None,
               params: Mapping[str, Any] | None = None) -> plt.Figure:  # fmt: skip
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
    fig, ax = _frame(map_, title or default_title)
    if isinstance(artifact, Simulation):
        plot_sim_background(ax, artifact)
        plot_trajectories(ax, artifact)
    for extra in background:
        plot_tree(ax, extra, color=ROLE_COLORS["rrt tree"], lw=0.5, alpha=0.8, label="RRT* tree")
    if isinstance(artifact, Tree):
        plot_samples(ax, artifact)
        simplified = "rounds" in artifact.stats  # simplified.npz (its stats count the rounds), not tree.npz
        plot_tree(ax, artifact, nodes=len(artifact.nodes) < 400, lw=1.0 if background else 0.7,
                  label="simplified tree" if simplified else "RRT* tree")  # fmt: skip
    regions = None
    if cells is not None:
        plot_cells(ax, cells, plan.status if plan is not None else None, color_by=color_by,
                   tolerance=plan.usable_tolerance if plan is not None else None,
                   live=None if liveness is None else liveness.live)  # fmt: skip
        if cell_numbers:  # the legend entries now, the indices once the layout is settled
            regions = active_regions(cells) if cells.is_funnel else None
            cell_number_keys(ax, cells, _cell_anchors(cells, regions)[1])
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
    _finish(fig, ax)
    # the landmarks' ids first: a cell index never hides one
    if labels is not False:
        label_landmarks(ax, map_, every=bool(labels))
    if cells is not None and cell_numbers:
        marks = np.vstack([map_.landmarks.reshape(-1, 2), map_.starts.reshape(-1, 2), map_.goal.reshape(1, 2)])
        label_cells(ax, cells, regions=regions, legend=False, avoid=marks)
    return fig


def save_figure(fig: plt.Figure, path: str) -> None:
    """Write ``fig`` to ``path`` (format from the suffix) and close it."""
    fig.savefig(path, dpi=150)
    plt.close(fig)


# --------------------------------------------------------------------------- perception and tags (issue 11)

PERCEPTION_FAIL_COLOR = ROLE_COLORS["perception fail"]
PERCEPTION_FAIL_FREE_COLOR = ROLE_COLORS["perception fail outside"]
EXISTING_TAG_COLOR = LANDMARK_COLOR
PROPOSED_TAG_COLOR = ROLE_COLORS["proposed tag"]


def _axis_labels(ax: plt.Axes) -> None:
    ax.set_xlabel(f"x ({AXIS_UNITS})")
    ax.set_ylabel(f"y ({AXIS_UNITS})")


def _existing_tags(ax: plt.Axes, landmarks: Any, gid: str, label: str) -> None:
    """The tags a map already has, as vermillion triangles labelled ``label``."""
    lm = np.asarray(landmarks, float).reshape(-1, 2)
    ax.scatter(lm[:, 0], lm[:, 1], marker="^", s=40, color=EXISTING_TAG_COLOR, edgecolor=ROLE_COLORS["edge"],
               linewidths=0.5, zorder=6, gid=gid, label=label)  # fmt: skip


def plot_perception(ax: plt.Axes, coverage: Any, *, free: bool = True, landmarks: bool = True,
                    legend: bool = True) -> plt.Axes:  # fmt: skip
    """Where the perception rule fails: small marks over the plan (issue 11; compute with ``perception``).

    Draw it over :func:`figure_for` of the plan (or :func:`plot_map` with ``landmarks=False``).

    Parameters
    ----------
    ax : Axes
        The axes to draw into (map units on both axes).
    coverage : PerceptionCoverage
        :func:`bearnav_cli.perception.perception_coverage` (duck-typed: ``failing_domain`` and
        ``failing_free`` (n, 2), ``fraction_domain``, ``fraction_free``, ``error_target``,
        ``landmarks`` (L, 2), ``fov_deg``, ``noise_deg``), so this module does not import it.
    free : bool
        Also mark the failing points of the free space outside ``D`` (orange dots).
    landmarks : bool
        Draw the landmarks the rule was evaluated with (triangles).
    legend : bool
        Label the axes (map units) and draw the legend (every labelled artist of the axes, once).

    Returns
    -------
    Axes
        Artists carry the gids ``perception-fail-domain``, ``perception-fail-free`` and ``perception-tags``.
    """
    bad = coverage.failing_domain  # what perception computed, not a second selection of it
    share = 1.0 - coverage.fraction_domain
    target = coverage.error_target
    what = "fewer than 2 usable tags in view" if target is None else f"no fix within {target:g} in view"
    label = f"{what}, in D ({share:.1%} of D; {coverage.fov_deg:g}° camera)"
    ax.scatter(bad[:, 0], bad[:, 1], marker="x", s=8, lw=0.7, color=PERCEPTION_FAIL_COLOR, zorder=5.5,
               gid="perception-fail-domain", label=label)  # fmt: skip
    if free:
        out = coverage.failing_free
        ax.scatter(out[:, 0], out[:, 1], marker=".", s=5, lw=0, color=PERCEPTION_FAIL_FREE_COLOR, zorder=5.4,
                   gid="perception-fail-free", label="the same, in F outside D")  # fmt: skip
    if landmarks:
        _existing_tags(ax, coverage.landmarks, "perception-tags", f"tags ({len(coverage.landmarks)})")
    if legend:
        _axis_labels(ax)
        _legend(ax)
    return ax


#: Legend labels of the tags figure's two kinds of tag (their ids are written beside them where they fit).
PROPOSED_TAGS_LABEL = "proposed tags ({}): glue one at each, ids beside them"
EXISTING_TAGS_LABEL = "existing tags ({}), ids beside them where they fit"


def plot_tags(ax: plt.Axes, proposal: Any, *, failures: bool = True, labels: bool = True,
              uncoverable: bool = True, legend: bool = True) -> plt.Axes:  # fmt: skip
    """Where to glue the proposed tags: existing tags, new ones with the side they face, what still fails.

    Draw it over :func:`figure_for` of the plan (or :func:`plot_map` with ``landmarks=False``).

    Parameters
    ----------
    ax : Axes
        The axes to draw into (map units on both axes).
    proposal : TagProposal
        :func:`bearnav_cli.tags.propose_tags` (duck-typed: ``ids``, ``positions`` (K, 2),
        ``normals`` (K, 2), ``uncoverable`` (U, 2), ``before`` and ``after`` coverages as
        :func:`plot_perception` reads them).
    failures : bool
        Mark where the rule still fails with the new tags (:func:`plot_perception` of ``after``).
    labels : bool
        Write the tags' ids beside them, in the layout as it stands (:func:`label_tags`).
    uncoverable : bool
        Mark the points of ``D`` no placement can cover (grey).
    legend : bool
        Label the axes (map units) and draw the legend.

    Returns
    -------
    Axes
        Artists carry the gids ``existing-tags``, ``proposed-tags``, ``proposed-tag-facing`` and
        ``uncoverable``, the labels ``proposed-tag-label`` and ``existing-tag-label``, besides those of
        :func:`plot_perception`.
    """
    if failures:
        plot_perception(ax, proposal.after, landmarks=False, legend=False)
    before = proposal.before
    _existing_tags(ax, before.landmarks, "existing-tags", EXISTING_TAGS_LABEL.format(len(before.landmarks)))
    new = np.asarray(proposal.positions, float).reshape(-1, 2)
    normals = np.asarray(proposal.normals, float).reshape(-1, 2)
    ax.scatter(new[:, 0], new[:, 1], marker="D", s=34, color=PROPOSED_TAG_COLOR, edgecolor=ROLE_COLORS["edge"],
               linewidths=0.6, zorder=6.5, gid="proposed-tags",
               label=PROPOSED_TAGS_LABEL.format(len(new)))  # fmt: skip
    if len(new):
        xmin, xmax = ax.get_xlim()
        scale = 0.02 * abs(xmax - xmin) if xmax != xmin else 0.1
        tips = new + scale * normals
        ax.add_collection(LineCollection(np.stack([new, tips], axis=1), colors=PROPOSED_TAG_COLOR, linewidths=1.0,
                                         zorder=6.4, gid="proposed-tag-facing",
                                         label="the free side a proposed tag faces"))  # fmt: skip
    stuck = np.asarray(proposal.uncoverable, float).reshape(-1, 2)
    if uncoverable and len(stuck):
        ax.scatter(stuck[:, 0], stuck[:, 1], marker="s", s=5, lw=0, color=ROLE_COLORS["uncoverable"], zorder=5.6,
                   gid="uncoverable", label=f"no placement covers ({len(stuck)} points)")  # fmt: skip
    if legend:
        _axis_labels(ax)
        _legend(ax)
    if labels:
        label_tags(ax, proposal)
    return ax


def label_tags(ax: plt.Axes, proposal: Any) -> list:
    """The ids of the proposed tags, then of the existing ones, where they fit (:func:`place_labels`).

    A proposed tag's id goes on the side it faces first (the free side, away from the wall); every
    proposed id is written (``every``: the reader must find each tag to glue), an existing one only
    where it collides with nothing. Call it once the layout is settled.

    Parameters
    ----------
    ax : Axes
        The axes of :func:`plot_tags`.
    proposal : TagProposal
        The proposal drawn (``ids``, ``positions``, ``normals``, ``before.landmarks`` and
        ``before.landmark_ids``).

    Returns
    -------
    list of matplotlib.text.Annotation
        The texts written (gids ``proposed-tag-label`` and ``existing-tag-label``).
    """
    for t in [t for t in ax.texts if t.get_gid() in ("proposed-tag-label", "existing-tag-label")]:
        t.remove()
    new = np.asarray(proposal.positions, float).reshape(-1, 2)
    normals = np.asarray(proposal.normals, float).reshape(-1, 2)
    old = np.asarray(proposal.before.landmarks, float).reshape(-1, 2)
    marks = np.vstack([new, old])
    label = PROPOSED_TAGS_LABEL.format(len(new))
    texts = []
    for name, point, n in zip(proposal.ids, new, normals, strict=True):
        # the corner toward the free side first: there the label covers no wall
        facing = sorted(CORNERS, key=lambda o: -(np.sign(o[0]) * n[0] + np.sign(o[1]) * n[1]))
        texts += place_labels(ax, [str(name)], point[None], gid="proposed-tag-label", label=label, avoid=marks,
                              offsets=facing, every=True, replace=False, color=PROPOSED_TAG_COLOR)  # fmt: skip
    texts += place_labels(ax, proposal.before.landmark_ids, old, gid="existing-tag-label", avoid=marks,
                          label=EXISTING_TAGS_LABEL.format(len(old)), color=EXISTING_TAG_COLOR)  # fmt: skip
    return texts


def _tags_title(proposal: Any, map_: Map) -> str:
    before, after = proposal.before, proposal.after
    live = getattr(proposal, "live_after", None)
    if live is not None:
        config = (f"every cell live at η = {math.degrees(live.grid.eta):.3g}°: "
                  f"{proposal.live_before.live_fraction:.1%} → {live.live_fraction:.1%} of D")  # fmt: skip
        return figure_title(map_.name, "tags", f"where to glue {len(proposal.ids)} new tags", config)
    target = before.error_target
    rule = "2 usable tags in view" if target is None else f"a fix within {target:g} in view"
    config = (f"{before.fov_deg:g}° camera, {before.noise_deg:g}° noise: {rule} on {before.fraction_domain:.1%} "
              f"→ {after.fraction_domain:.1%} of D")  # fmt: skip
    return figure_title(map_.name, "tags", f"where to glue {len(proposal.ids)} new tags", config)


def tags_figure(proposal: Any, map_: Map, title: str | None = None) -> plt.Figure:
    """Where to glue the proposed tags on the map (:func:`plot_map` without its tags, then :func:`plot_tags`).

    Parameters
    ----------
    proposal : TagProposal
        The proposal of :func:`bearnav_cli.tags.propose_tags` (its ``ids`` and placements).
    map_ : Map
        The map the tags are proposed for, drawn underneath.
    title : str, optional
        Figure title; default :func:`figure_title` with the camera, the noise and the share of ``D``
        where the rule holds before and after.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = _frame(map_, title or _tags_title(proposal, map_), landmarks=False)
    # for liveness the perception rule's failures are beside the point: the grey marks say where no tag helps
    plot_tags(ax, proposal, failures=getattr(proposal, "live_after", None) is None, labels=False, legend=False)
    _finish(fig, ax)
    label_tags(ax, proposal)
    return fig


# --------------------------------------------------------------------------- bearnav sweep

#: Colours and markers of the success figure's fields of view, in the order they first appear.
#: One colour per field of view, the palette's Okabe–Ito colours in a fixed order.
_SWEEP_COLORS = tuple(PALETTE[name] for name in ("blue", "orange", "bluish green", "vermillion", "reddish purple",
                                                 "sky blue", "yellow", "black"))  # fmt: skip
_SWEEP_MARKERS = "osD^vP*X"
_SWEEP_STYLES = ("-", "--", ":", "-.")


def sweep_plot(panels: Sequence[Any], title: str | None = None) -> plt.Figure:
    """Success against bearing noise: a panel per map and dynamics, a colour per field of view.

    Draws the data of :func:`bearnav_cli.sweep.success_curves` and computes nothing. Lines of one
    field of view that differ in another axis of the sweep (the tags, the estimator ...) differ
    in style: solid with filled markers for the first variant, dashed with open ones for the next.

    Parameters
    ----------
    panels : sequence of Panel
        Each with ``map``, ``dynamics``, ``tags`` (a caption) and ``lines`` (dicts with ``fov``,
        ``variant``, ``variant_index``, ``noise`` in degrees and ``success`` in [0, 1]).
    title : str, optional
        The figure's title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.lines import Line2D

    maps = list(dict.fromkeys(p.map for p in panels)) or [""]
    dynamics = list(dict.fromkeys(p.dynamics for p in panels)) or [""]
    fovs = list(dict.fromkeys(line["fov"] for p in panels for line in p.lines))
    color = {f: _SWEEP_COLORS[i % len(_SWEEP_COLORS)] for i, f in enumerate(fovs)}
    marker = {f: _SWEEP_MARKERS[i % len(_SWEEP_MARKERS)] for i, f in enumerate(fovs)}
    ncol = 2 if len(dynamics) == 1 else 4
    n_handles = len(fovs) + len({line["variant_index"] for p in panels for line in p.lines if line["variant"]})
    legend_rows = -(-n_handles // ncol)
    height = 3.1 * len(maps) + 0.6 + 0.22 * legend_rows
    fig, axes = plt.subplots(len(maps), len(dynamics), figsize=(max(6.4, 5.2 * len(dynamics)), height),
                             sharex=True, sharey=True, squeeze=False)  # fmt: skip
    variants: dict[int, str] = {}
    noises: set[float] = set()
    for panel in panels:
        ax = axes[maps.index(panel.map), dynamics.index(panel.dynamics)]
        for line in panel.lines:
            k = line["variant_index"]
            variants.setdefault(k, line["variant"])
            noises.update(line["noise"])
            ax.plot(line["noise"], [100 * v for v in line["success"]], ls=_SWEEP_STYLES[k % len(_SWEEP_STYLES)],
                    marker=marker[line["fov"]], ms=4, lw=1.3, color=color[line["fov"]],
                    mfc=color[line["fov"]] if k == 0 else "white")  # fmt: skip
        caption = f"{panel.map}, {panel.dynamics}" + (f": {panel.tags}" if panel.tags else "")
        ax.set_title(caption, fontsize=9)
    for ax in axes.flat:
        ax.set_ylim(0, 102)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=8)
        if noises:
            ax.set_xticks(sorted(noises))
    for ax in axes[:, 0]:
        ax.set_ylabel("runs reaching the goal (%)", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("bearing noise (°; σ, or the bound of a bounded noise)", fontsize=8)
    handles = [Line2D([], [], color=color[f], marker=marker[f], ms=4, label=f"{f:g}° field of view") for f in fovs]
    handles += [Line2D([], [], color="black", ls=_SWEEP_STYLES[k % len(_SWEEP_STYLES)], marker="o", ms=4,
                       mfc="black" if k == 0 else "white", label=label)
                for k, label in sorted(variants.items()) if label]  # fmt: skip
    if handles:
        fig.legend(handles=handles, loc="lower center", ncol=min(ncol, len(handles)), fontsize=8, frameon=False)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, (0.22 * legend_rows + 0.1) / height, 1, 1 - 0.3 / height))
    return fig
