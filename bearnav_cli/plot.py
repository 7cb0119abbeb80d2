"""Drawing every artifact with matplotlib; nothing else in bearnav imports matplotlib.

Each ``plot_<layer>(ax, artifact, ...)`` draws one layer on an existing axes and
returns it, in the manner of python-control's ``*_plot`` functions: compute
elsewhere, draw here. :func:`figure_for` composes the layers that suit an artifact.
The vector field is the runtime's own (:func:`bearnav_cli.runtime.locate` and
:func:`bearnav_cli.runtime.field` on a grid), so the figure shows what a robot runs.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import shapely
from matplotlib import colors as mcolors
from matplotlib import patheffects
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection
from matplotlib.patches import Patch, PathPatch
from matplotlib.path import Path as MplPath
from shapely.geometry.polygon import orient

from bearnav_cli import runtime
from bearnav_cli.datatypes import Cells, CellStatus, Map, Plan, Polygon, Simulation, Tree, tolerance_by_area
from bearnav_cli.errors import InvalidParamsError

__all__ = [
    "active_regions",
    "ADDED_COLOR",
    "AXIS_UNITS",
    "cell_polygons",
    "COLOR_BY",
    "EXISTING_TAG_COLOR",
    "EXIT_COLOR",
    "field_samples",
    "figure_for",
    "INFLATED_COLOR",
    "label_landmarks",
    "map_handles",
    "OUTCOME_COLORS",
    "OUTCOME_NAMES",
    "OUTLINE_COLOR",
    "PERCEPTION_FAIL_COLOR",
    "PERCEPTION_FAIL_FREE_COLOR",
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
    "RAW_COLOR",
    "save_animation",
    "save_figure",
    "STATUS_COLORS",
    "sweep_plot",
    "tags_figure",
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


RAW_COLOR = "#4d4d4d"
INFLATED_COLOR = "#c9c9c9"
OUTLINE_COLOR = "#525252"
EXIT_COLOR = "#08306b"
UNCERTIFIED_COLOR = "#d62728"
UNCOVERED_COLOR = "#e6550d"
ADDED_COLOR = "#e7298a"
#: ``--color-by`` choices: the cell's rank (cost-to-go), its usable tolerance ``τ_c``, its synthesis status,
#: or whether it is live (ALGORITHMS §12.5, a ``liveness.Liveness`` the caller measured).
COLOR_BY = ("rank", "tolerance", "status", "live")
#: The fills of ``--color-by live``.
LIVE_COLORS = {True: "#74c476", False: "#de2d26"}
#: Parts of ``F_m`` that no cell reaches (cut off by passages narrower than ``2m``).
UNREACHED_COLOR = "#969696"
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


def plot_map(ax: plt.Axes, map_: Map, *, landmarks: bool = True, starts: bool = True, labels: bool | None = None,
             walls: bool = True) -> plt.Axes:  # fmt: skip
    """Bounds, inflated and raw obstacles, landmarks, goal and starts.

    Also sets the limits (the bounds with a 2 % pad of the diagonal) and an equal aspect.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (map units on both axes).
    map_ : Map
        The map to draw.
    landmarks : bool
        Draw the landmarks (red triangles) and, per ``labels``, their ids.
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
    ax.plot([xmin, xmax, xmax, xmin, xmin], [ymin, ymin, ymax, ymax, ymin], color="black", lw=1.2)
    if walls and map_.planning_radius > 0:
        band = shapely.difference(shapely.box(*map_.bounds), shapely.box(*map_.free_bounds))
        _add_geometry(ax, band, facecolor=INFLATED_COLOR, edgecolor="none", zorder=1)
    for poly in map_.obstacles:
        ax.add_patch(_polygon_patch(poly, facecolor=INFLATED_COLOR, edgecolor="none", zorder=1))
    for poly in map_.raw_obstacles:
        ax.add_patch(_polygon_patch(poly, facecolor=RAW_COLOR, edgecolor="none", zorder=2))
    if landmarks and len(map_.landmarks):
        ax.scatter(*map_.landmarks.T, marker="^", s=40, color="#d62728", edgecolor="white", linewidths=0.5,
                   zorder=6, label="landmarks")  # fmt: skip
    if starts and len(map_.starts):
        ax.scatter(
            *map_.starts.T, marker="o", s=36, facecolor="white", edgecolor="#1f77b4", zorder=6, label="map starts"
        )
    ax.scatter(*map_.goal, marker="*", s=180, color="#2ca02c", edgecolor="white", linewidths=0.5, zorder=7,
               label="goal")  # fmt: skip
    pad = 0.02 * map_.diagonal
    ax.set_xlim(xmin - pad, xmax + pad)
    ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_aspect("equal")
    if landmarks and labels is not False:
        label_landmarks(ax, map_, every=bool(labels))
    return ax


def label_landmarks(ax: plt.Axes, map_: Map, *, every: bool = False) -> list:
    """Write landmark ids beside their markers; unless ``every``, skip those that would collide.

    Each label tries the four corners around its landmark and takes the first whose text box
    meets no earlier label and no landmark marker (in display space, as the axes stand now: call
    it after the layout is settled). Labels an earlier call wrote are removed first.

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
        The label artists (gid ``landmark-label``).
    """
    for text in [t for t in ax.texts if t.get_gid() == "landmark-label"]:
        text.remove()
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    ax.apply_aspect()
    marks = ax.transData.transform(map_.landmarks) if len(map_.landmarks) else np.zeros((0, 2))
    r = 5.0 * fig.dpi / 72  # marker half-size, pixels
    taken = [np.array([x - r, y - r, x + r, y + r]) for x, y in marks]
    corners = [(3, 3, "left", "bottom"), (-3, 3, "right", "bottom"), (3, -3, "left", "top"), (-3, -3, "right", "top")]
    placed: list[np.ndarray] = []
    for i, (name, point) in enumerate(zip(map_.landmark_ids, map_.landmarks, strict=True)):
        others = taken[:i] + taken[i + 1 :] + placed
        for dx, dy, ha, va in corners:
            text = ax.annotate(name, point, xytext=(dx, dy), textcoords="offset points", ha=ha, va=va, fontsize=6.5,
                               color="#a50f15", zorder=8, gid="landmark-label",
                               path_effects=[patheffects.withStroke(linewidth=2, foreground="white")])  # fmt: skip
            box = text.get_window_extent(renderer)
            box = np.array([box.x0, box.y0, box.x1, box.y1])
            clash = any(box[0] < t[2] and t[0] < box[2] and box[1] < t[3] and t[1] < box[3] for t in others)
            if every or not clash:
                placed.append(box)
                break
            text.remove()
    return [t for t in ax.texts if t.get_gid() == "landmark-label"]


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


def plot_cells(ax: plt.Axes, cells: Cells, status: np.ndarray | None = None, *, color_by: str | None = None,
               tolerance: np.ndarray | None = None, fill: float = 0.45, exit_faces: bool = True,
               numbers: bool = False, colorbar: bool = True, legend: bool = True,
               live: np.ndarray | None = None) -> plt.Axes:  # fmt: skip
    """Cells: thin outlines, exit faces, a fill by ``color_by`` and uncertified cells hatched red.

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
        ``live``: green where the cell is live, red where it is not (``live``).
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
        Write each cell's index inside its active region (funnel) or at its centroid (paper).
    colorbar, legend : bool
        Add a colour bar (rank, tolerance) and legend entries.
    live : ndarray of bool, shape (C,), optional
        Whether each cell is live (``liveness.Liveness.live``), for ``color_by="live"``.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.
    """
    if color_by is None:
        color_by = "rank" if cells.is_funnel else ("status" if status is not None else "")
    regions = active_regions(cells) if cells.is_funnel else None
    if color_by:
        faces, mappable, label = _cell_colors(cells, color_by, status, tolerance, live)
        if regions is not None or color_by != "status":
            for c, region in enumerate(regions if regions is not None else active_regions(cells)):
                _add_geometry(ax, region, facecolor=faces[c], alpha=fill, edgecolor="white", lw=0.5, zorder=0.5)
        else:  # paper cells by status: each status's union once, the worst on top
            polys = cell_polygons(cells)
            for value in (CellStatus.CERTIFIED, CellStatus.GOAL, CellStatus.RELAXED, CellStatus.NOT_CERTIFIED,
                          CellStatus.SOLVER_FAILURE):  # fmt: skip
                chosen = [polys[c] for c in np.flatnonzero(np.asarray(status) == value)]
                if chosen:
                    _add_geometry(ax, shapely.union_all(chosen), facecolor=STATUS_COLORS[value], alpha=fill,
                                  edgecolor="none", zorder=0.5)  # fmt: skip
        if color_by == "status" and legend:
            for value in sorted({int(s) for s in status}):
                name = CellStatus(value).name.lower().replace("_", " ")
                ax.fill([], [], color=STATUS_COLORS[CellStatus(value)], alpha=fill, label=f"cells: {name}")
        if color_by == "live" and legend:
            for value, name in ((True, "live"), (False, "not live (a look may not let it move on)")):
                ax.fill([], [], color=LIVE_COLORS[value], alpha=fill, label=f"cells: {name}")
        if mappable is not None and colorbar:
            bar = ax.figure.colorbar(mappable, ax=ax, fraction=0.04, pad=0.015, shrink=0.9)
            bar.set_label(label, fontsize=8)
            bar.ax.tick_params(labelsize=7)
            bar.solids.set_alpha(fill)
    rings = [np.vstack([cells.vertices(c), cells.vertices(c)[:1]]) for c in range(cells.n_cells)]
    ax.add_collection(LineCollection(rings, colors=OUTLINE_COLOR, linewidths=0.3, alpha=0.55, zorder=0.8,
                                     label="cell outlines", gid="cell-outlines"))  # fmt: skip
    if exit_faces:
        faces_xy = []
        for c in np.flatnonzero(cells.cell_exit_row >= 0):
            v, k = cells.vertices(c), int(cells.cell_exit_row[c])
            faces_xy.append(np.stack([v[k], v[(k + 1) % len(v)]]))
        if faces_xy:
            ax.add_collection(LineCollection(faces_xy, colors=EXIT_COLOR, linewidths=1.1, zorder=0.9,
                                             label="exit faces", gid="exit-faces"))  # fmt: skip
    if status is not None:
        bad = np.flatnonzero(np.isin(status, [CellStatus.NOT_CERTIFIED, CellStatus.SOLVER_FAILURE]))
        for i, c in enumerate(bad):
            label = "uncertified cell (status 2/3)" if i == 0 else None
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
                    label=label,
                )
            )
    if numbers:
        for c in range(cells.n_cells):
            region = regions[c] if regions is not None else None
            dim = region is not None and region.area <= 1e-12 * cells.map.diagonal**2
            if region is None or dim:
                where = shapely.centroid(shapely.Polygon(cells.vertices(c)))
            else:
                where = shapely.point_on_surface(max(shapely.get_parts(region), key=lambda g: g.area))
            ax.text(where.x, where.y, str(c), fontsize=5, ha="center", va="center", zorder=8.5, gid="cell-number",
                    color="#7f7f7f" if dim else "black", fontstyle="italic" if dim else "normal",
                    path_effects=[patheffects.withStroke(linewidth=1.5, foreground="white")])  # fmt: skip
    return ax


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
    _add_geometry(ax, uncovered, facecolor="none", edgecolor=UNCOVERED_COLOR, hatch="////", lw=0.6,
                  zorder=2.7, gid="uncovered", label="uncovered part of F")  # fmt: skip
    if unreached is not None and not unreached.is_empty:
        _add_geometry(ax, unreached, facecolor="none", edgecolor=UNREACHED_COLOR, hatch="\\\\", lw=0.6,
                      zorder=2.7, gid="unreached", label="free space no cell reaches")  # fmt: skip
    return ax


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
                  width=0.0022, headwidth=4, headlength=4.5, color="#252525", alpha=0.8, zorder=3.8,
                  label="field direction (runtime policy)", gid="field")  # fmt: skip
    return ax


def plot_tree(
    ax: plt.Axes,
    tree: Tree | Cells | Simulation,
    *,
    color: str = "#1f77b4",
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
        Legend label of the edges; None for no legend entry.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.
    """
    if len(tree.nodes) > 1:
        segments = _edges(tree.nodes, tree.parent)
        ax.add_collection(LineCollection(segments, colors=color, linewidths=lw, alpha=alpha, zorder=4, label=label))
    if nodes:
        added = np.asarray(getattr(tree, "node_added", np.zeros(len(tree.nodes), bool)), bool)
        ax.scatter(*tree.nodes[~added].T, s=6, color=color, alpha=alpha, zorder=5)
        if added.any():
            ax.scatter(*tree.nodes[added].T, s=14, marker="D", color=ADDED_COLOR, edgecolor="white", linewidths=0.4,
                       alpha=alpha, zorder=5, label=f"added nodes ({int(added.sum())}, densification)")  # fmt: skip
    return ax


def plot_samples(ax: plt.Axes, tree: Tree | Cells, *, color: str = "#ff7f0e") -> plt.Axes:
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
            *tree.collision_samples.T, s=3, marker="x", linewidths=0.6, color=color, zorder=3, label="collision samples"
        )
    return ax


#: Trajectory colour of each run outcome (``sim.npz`` ``outcome``).
OUTCOME_COLORS = {0: "#2ca25f", 1: "#de2d26", 2: "#fd8d3c", 3: "#756bb1", 4: "#636363"}
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
    ax.plot(*trace.truth.T, color="0.2", lw=0.8, zorder=4, label="true path")
    label = "estimate sets" + (f" (drawn {scale:g}× enlarged)" if scale != 1.0 else "")
    for k in range(len(trace.error)):
        ring = trace.set_coords[trace.set_offsets[k] : trace.set_offsets[k + 1]]
        if len(ring) >= 3:
            ring = trace.x_hat[k] + scale * (ring - trace.x_hat[k])
            colour = colours(norm(trace.error[k]))
            patch = _add_geometry(ax, shapely.Polygon(ring), facecolor=colour, alpha=0.55, edgecolor=colour, lw=0.4,
                                  zorder=5)  # fmt: skip
            if patch is not None and label:
                patch.set_label(label)
                label = ""
    looked = trace.looking
    if looked.any():
        ax.plot(*trace.truth[looked].T, "o", ms=2.5, mfc="none", mec="#d62728", zorder=6, label="stopped to look")
    bar = plt.colorbar(ScalarMappable(norm=norm, cmap=colours), ax=ax, fraction=0.04, pad=0.02)
    bar.set_label(f"error radius e ({AXIS_UNITS})")
    return ax


def plot_sim_background(ax: plt.Axes, sim: Simulation) -> plt.Axes:
    """The simulation's cells (outlines, filled by status) and tree, faintly."""
    _draw_cells(ax, sim.cell_vertices, sim.cell_vertex_offsets, sim.cell_status, fill=0.12, line=0.35, lw=0.3,
                legend=False)  # fmt: skip
    return plot_tree(ax, sim, lw=0.8, alpha=0.6, label="simplified tree")


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
        start_label = "run starts" if "start" not in shown else None
        shown.add("start")
        ax.plot(*path[0], "o", ms=3, mfc="white", mec=color, zorder=5, label=start_label)
        if outcome != 0:
            end_label = "where a failed run ended" if "end" not in shown else None
            shown.add("end")
            ax.plot(*path[-1], "x", ms=5, color=color, zorder=5, label=end_label)
    return ax


# --------------------------------------------------------------------------- figures


def map_handles(map_: Map) -> list:
    """Legend proxies for the raw obstacles and their inflation by the robot radius (plus the look-ahead)."""
    label = f"inflated by the robot radius ({map_.robot_radius:g})"
    if map_.lookahead > 0:
        label = f"inflated by radius + look-ahead ({map_.robot_radius:g} + {map_.lookahead:g})"
    return [Patch(color=RAW_COLOR, label="obstacles"), Patch(color=INFLATED_COLOR, label=label)]


def _frame(map_: Map, title: str, *, legend_rows: int = 0, landmarks: bool = True) -> tuple[plt.Figure, plt.Axes]:
    xmin, ymin, xmax, ymax = map_.bounds
    width = 8.0
    height = max(3.0, width * (ymax - ymin) / (xmax - xmin)) + 0.25 * legend_rows
    fig, ax = plt.subplots(figsize=(width + 1.8, height))  # the extra width holds the legend or colour bar
    plot_map(ax, map_, labels=False, landmarks=landmarks)
    ax.set_title(title)
    ax.set_xlabel(f"x ({AXIS_UNITS})")
    ax.set_ylabel(f"y ({AXIS_UNITS})")
    return fig, ax


def save_animation(sim: Simulation, path: str, *, frames: int = 80, limit: int = 60) -> None:
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
    """
    from matplotlib.animation import FuncAnimation, PillowWriter

    fig, ax = _frame(sim.map, f"{sim.map.name}: {len(sim.outcome)} runs")
    plot_sim_background(ax, sim)
    runs = [r for r in range(min(len(sim.outcome), limit)) if len(sim.trajectory(r))]
    lines = [ax.plot([], [], color=OUTCOME_COLORS[int(sim.outcome[r])], lw=0.9, zorder=4)[0] for r in runs]
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
    fig.tight_layout()

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


def _plan_title(map_: Map, cells: Cells, plan: Plan | None) -> str:
    kind = "funnel" if cells.is_funnel else "paper"
    text = f"{map_.name}: {cells.n_cells} {kind} cells"
    if cells.is_funnel:
        f_m = cells.stats.get("free_coverage_m")
        text += f" ({int(np.sum(cells.node_added))} added), cover {cells.free_coverage:.1%} of F"
        text += f" ({f_m:.1%} of F_m)" if isinstance(f_m, float) else ""
    if plan is not None and math.isfinite(plan.plan_tolerance):
        tau = tolerance_by_area(cells, plan.usable_tolerance)
        text += f", τ_c ≥ {plan.plan_tolerance:.3g} (median by area {tau['median']:.3g})"
    if plan is not None:
        bad = int(np.isin(plan.status, [CellStatus.NOT_CERTIFIED, CellStatus.SOLVER_FAILURE]).sum())
        text += f", {bad} uncertified" if bad else ", all certified"
    return text


def figure_for(artifact: Any, *, background: Sequence[Any] = (), title: str | None = None,
               color_by: str | None = None, barriers: bool = False, labels: bool | None = None,
               cell_numbers: bool = False, arrows: int = 28, coverage: Any = None,
               perception: Any = None, liveness: Any = None) -> plt.Figure:  # fmt: skip
    """A figure with the layers that suit ``artifact``.

    Parameters
    ----------
    artifact : Map, Tree, Cells, Plan or Simulation
        The main artifact: a map; a tree with its samples; cells (outlines, exit faces, fill by
        rank, uncovered free space hatched); a plan adds the synthesis status (uncertified cells
        hatched red) and the field the runtime drives; a simulation draws its runs over the tree
        and cells, coloured by outcome.
    background : sequence of Tree
        Trees drawn faintly underneath (e.g. the RRT* tree under its simplification).
    title : str, optional
        Figure title (default: map name and a one-line summary).
    color_by : {"rank", "tolerance", "status", "live"}, optional
        Cell fill (:func:`plot_cells`); default rank for funnel cells, status for paper plans; ``live``
        needs ``liveness``.
    barriers : bool
        Also draw every barrier line ``h = 0`` (for funnel cells these are the cell edges).
    labels : bool, optional
        Landmark ids: all (True), none (False), or those that do not collide (None).
    cell_numbers : bool
        Write each cell's index (funnel cells: inside the region where the cell is active).
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
    """
    if color_by is not None and color_by not in COLOR_BY:
        raise InvalidParamsError(f"must be one of {', '.join(COLOR_BY)}, got {color_by!r}", field="color_by")
    map_ = artifact if isinstance(artifact, Map) else artifact.map
    plan = artifact if isinstance(artifact, Plan) else None
    cells = plan.cells if plan is not None else artifact if isinstance(artifact, Cells) else None
    default_title = _plan_title(map_, cells, plan) if cells is not None else map_.name
    if liveness is not None and color_by == "live":
        default_title = f"{map_.name}: " + liveness.summary().replace("; ", "\n")
    rows = (4 if cells is not None else 0) + (1 if perception is not None else 0)
    fig, ax = _frame(map_, title or default_title, legend_rows=rows)
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
        simplified = "rounds" in artifact.stats  # simplified.npz (its stats count the rounds), not tree.npz
        plot_tree(ax, artifact, nodes=len(artifact.nodes) < 400, lw=1.0 if background else 0.7,
                  label="simplified tree" if simplified else "RRT* tree")  # fmt: skip
    if cells is not None:
        plot_cells(ax, cells, plan.status if plan is not None else None, color_by=color_by,
                   tolerance=plan.usable_tolerance if plan is not None else None, numbers=cell_numbers,
                   live=None if liveness is None else liveness.live)  # fmt: skip
        if cells.is_funnel and coverage is not None:
            plot_uncovered(ax, cells, coverage.uncovered, coverage.unreached)
        if barriers:
            plot_barriers(ax, cells)
        plot_tree(ax, cells, nodes=True, lw=0.5, alpha=0.75, color="#2171b5", label="simplified tree")
        if plan is not None and arrows > 0:
            plot_field(ax, plan, arrows=arrows)
    if perception is not None:
        plot_perception(ax, perception, landmarks=False, legend=False)
    handles, _ = ax.get_legend_handles_labels()
    handles += map_handles(map_)
    if cells is not None:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=4, fontsize=7,
                  frameon=False)  # fmt: skip
    else:
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, framealpha=0.85)
    fig.tight_layout()
    if labels is not False:
        label_landmarks(ax, map_, every=bool(labels))
    return fig


def save_figure(fig: plt.Figure, path: str) -> None:
    """Write ``fig`` to ``path`` (format from the suffix) and close it."""
    fig.savefig(path, dpi=150)
    plt.close(fig)


# --------------------------------------------------------------------------- perception and tags (issue 11)

PERCEPTION_FAIL_COLOR = "#d62728"
PERCEPTION_FAIL_FREE_COLOR = "#fd8d3c"
EXISTING_TAG_COLOR = "#a50f15"
PROPOSED_TAG_COLOR = "#6a3d9a"


def _perception_legend(ax: plt.Axes) -> None:
    """Axis labels, and one legend below the axes: the entries of a legend already drawn (e.g. by
    :func:`figure_for`, whose obstacle proxies are not artists of the axes) and then the new ones."""
    ax.set_xlabel(f"x ({AXIS_UNITS})")
    ax.set_ylabel(f"y ({AXIS_UNITS})")
    old = ax.get_legend()
    handles = list(getattr(old, "legend_handles", None) or getattr(old, "legendHandles", [])) if old else []
    labels = [t.get_text() for t in old.get_texts()] if old else []
    for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
        if label not in labels:
            handles.append(handle)
            labels.append(label)
    if handles:
        ax.legend(handles=handles, labels=labels, loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=3,
                  fontsize=7, frameon=False)  # fmt: skip


def _existing_tags(ax: plt.Axes, landmarks: Any, gid: str, label: str) -> None:
    """The tags a map already has, as red triangles labelled ``label (count)``."""
    lm = np.asarray(landmarks, float).reshape(-1, 2)
    ax.scatter(lm[:, 0], lm[:, 1], marker="^", s=40, color=EXISTING_TAG_COLOR, edgecolor="white", linewidths=0.5,
               zorder=6, gid=gid, label=f"{label} ({len(lm)})")  # fmt: skip


def plot_perception(ax: plt.Axes, coverage: Any, *, free: bool = True, landmarks: bool = True,
                    legend: bool = True) -> plt.Axes:  # fmt: skip
    """Where the perception rule fails: small red marks over the plan (issue 11; compute with ``perception``).

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
        Label the axes (map units) and draw the legend.

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
    ax.scatter(bad[:, 0], bad[:, 1], marker="x", s=6, lw=0.6, color=PERCEPTION_FAIL_COLOR, zorder=5.5,
               gid="perception-fail-domain", label=label)  # fmt: skip
    if free:
        out = coverage.failing_free
        ax.scatter(out[:, 0], out[:, 1], marker=".", s=4, lw=0, color=PERCEPTION_FAIL_FREE_COLOR, zorder=5.4,
                   gid="perception-fail-free", label="the same, in F outside D")  # fmt: skip
    if landmarks:
        _existing_tags(ax, coverage.landmarks, "perception-tags", "tags")
    if legend:
        _perception_legend(ax)
    return ax


def plot_tags(ax: plt.Axes, proposal: Any, *, failures: bool = True, labels: bool = True,
              uncoverable: bool = True, legend: bool = True) -> plt.Axes:  # fmt: skip
    """Where to glue the proposed tags: existing tags, new ones labelled with their ids, what still fails.

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
        Write each new tag's id beside it.
    uncoverable : bool
        Mark the points of ``D`` no placement can cover (grey).
    legend : bool
        Label the axes (map units) and draw the legend.

    Returns
    -------
    Axes
        Artists carry the gids ``existing-tags``, ``proposed-tags``, ``proposed-tag-label`` (one text
        per new tag), ``proposed-tag-facing`` and ``uncoverable``, besides those of :func:`plot_perception`.
    """
    if failures:
        plot_perception(ax, proposal.after, landmarks=False, legend=False)
    _existing_tags(ax, proposal.before.landmarks, "existing-tags", "existing tags")
    new = np.asarray(proposal.positions, float).reshape(-1, 2)
    normals = np.asarray(proposal.normals, float).reshape(-1, 2)
    ax.scatter(new[:, 0], new[:, 1], marker="D", s=34, color=PROPOSED_TAG_COLOR, edgecolor="white", linewidths=0.6,
               zorder=6.5, gid="proposed-tags", label=f"proposed tags ({len(new)})")  # fmt: skip
    if len(new):
        xmin, xmax = ax.get_xlim()
        scale = 0.02 * abs(xmax - xmin) if xmax != xmin else 0.1
        tips = new + scale * normals
        ax.add_collection(LineCollection(np.stack([new, tips], axis=1), colors=PROPOSED_TAG_COLOR, linewidths=1.0,
                                         zorder=6.4, gid="proposed-tag-facing"))  # fmt: skip
    if labels:
        for name, p, n in zip(proposal.ids, new, normals, strict=True):
            ha = "left" if n[0] >= 0 else "right"
            va = "bottom" if n[1] >= 0 else "top"
            ax.annotate(str(name), p, xytext=(4 * np.sign(n[0]), 4 * np.sign(n[1])), textcoords="offset points",
                        ha=ha, va=va, fontsize=6.5, color=PROPOSED_TAG_COLOR, zorder=8, gid="proposed-tag-label",
                        path_effects=[patheffects.withStroke(linewidth=2, foreground="white")])  # fmt: skip
    stuck = np.asarray(proposal.uncoverable, float).reshape(-1, 2)
    if uncoverable and len(stuck):
        ax.scatter(stuck[:, 0], stuck[:, 1], marker="s", s=5, lw=0, color=UNREACHED_COLOR, zorder=5.6,
                   gid="uncoverable", label=f"no placement covers ({len(stuck)} points)")  # fmt: skip
    if legend:
        _perception_legend(ax)
    return ax


def tags_figure(proposal: Any, map_: Map, title: str | None = None) -> plt.Figure:
    """Where to glue the proposed tags on the map (:func:`plot_map` without its tags, then :func:`plot_tags`).

    Parameters
    ----------
    proposal : TagProposal
        The proposal of :func:`bearnav_cli.tags.propose_tags` (its ``ids`` and placements).
    map_ : Map
        The map the tags are proposed for, drawn underneath.
    title : str, optional
        Figure title; default ``"<map name>: where to glue <n> new tags"``.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = _frame(map_, title or f"{map_.name}: where to glue {len(proposal.ids)} new tags", legend_rows=3,
                     landmarks=False)  # fmt: skip
    plot_tags(ax, proposal)
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- bearnav sweep

#: Colours and markers of the success figure's fields of view, in the order they first appear.
_SWEEP_COLORS = ("#1f77b4", "#2ca02c", "#ff7f0e", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf")
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
