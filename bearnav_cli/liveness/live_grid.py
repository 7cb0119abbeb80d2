"""Where and against what liveness is measured (:func:`grid`): the points of every cell, each cell's margin,
and the bound ``ε(x, S)`` of a look at each point (``runtime.look_bound.one_look_bound``)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from bearnav_cli.datatypes import Plan, active_regions
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.runtime import (
    PlanArrays,
    bounded,
    estimate,
    least_rank_cell,
    look_bound,
    looking,
    robot,
    settings,
    tolerance,
)

__all__ = [
    "bounds_of",
    "default_resolution",
    "distinct_views",
    "grid",
    "HEADINGS",
    "LiveGrid",
    "MAX_GRID_POINTS",
    "POINTS_PER_CELL",
    "RESOLUTION_PER_DIAGONAL",
    "VERTEX_INSET",
]


#: Headings of the minimum over headings for a camera narrower than 360° (every 10°).
HEADINGS = looking.LOOK_HEADINGS
#: The default grid gives about this many points to the median cell ...
POINTS_PER_CELL = 25
#: ... and is never coarser than this fraction of the map's diagonal D.
RESOLUTION_PER_DIAGONAL = 0.01
#: Vertices are pulled this fraction of the way toward their cell's centroid (strictly inside).
VERTEX_INSET = 1e-3


#: Most grid points (summed over the cells) a measurement may take: about 1 kB each.
MAX_GRID_POINTS = 2_000_000
#: Point-heading rows per batch of the one-look bound (memory: about 10 kB a row).
_ROWS = 1 << 14
#: Points per batch of the visibility masks.
_POINTS = 1 << 11


@dataclass(frozen=True, eq=False)
class LiveGrid:
    """Where and against what liveness is measured (:func:`grid`): ``P`` points, ``M`` (cell, point) pairs.

    Attributes
    ----------
    arrays : PlanArrays
        The plan's run-time arrays.
    polygons : tuple of shapely.Polygon, length C
        The cells.
    points : ndarray, shape (P, 2)
        The grid points and every cell's extra points (map units).
    grid_points : int
        How many of ``points`` come first and are the square grid's (evenly spread: fractions of area are
        counted on them).
    pair_cell, pair_point : ndarray of int, shape (M,)
        Which cell holds which point, sorted by cell (a point of several cells is in several pairs).
    tolerance, margin : ndarray, shape (C,)
        ``τ_c`` and ``τ_c − (κ + 2 sin(ψ/2))ℓ − ν − 2λ sin(ψ/2)`` (map units).
    eta : float
        The bearing error bound ``η`` (rad).
    fov : float
        The camera's full field of view (rad).
    kappa : float
        The slip ``κ`` (fraction of a step).
    drift : float
        ``κ + 2 sin(ψ/2)``: the slip and the turn a heading error ``ψ`` gives a step (fraction of a step,
        ``runtime.settings.ErrorBounds.drift``).
    nu : float
        The slip floor ``ν`` (map units).
    step : float
        ``ℓ = v·dt``, one step's length (map units).
    swing : float
        ``2λ sin(ψ/2)``, the look-ahead point's extra error (map units; 0 without a look-ahead).
    resolution : float
        Grid spacing (map units).
    headings : int
        Headings of the one-view minimum over headings.
    max_range : float
        The camera's range (map units; ``inf``: any).
    """

    arrays: PlanArrays
    polygons: tuple
    points: np.ndarray
    grid_points: int
    pair_cell: np.ndarray
    pair_point: np.ndarray
    tolerance: np.ndarray
    margin: np.ndarray
    eta: float
    fov: float
    kappa: float
    drift: float
    nu: float
    step: float
    swing: float
    resolution: float
    headings: int
    max_range: float

    # the cells do not depend on the tags: every evaluation on this grid (tags --for live: before and
    # after) shares their active regions and their area
    @functools.cached_property
    def regions(self) -> list:
        """Where each cell drives the robot (:func:`~bearnav_cli.datatypes.active_regions`), length C."""
        return active_regions(self.polygons, self.arrays.cell_rank)

    @functools.cached_property
    def area(self) -> float:
        """The area of ``D``, the union of the cells (map units²)."""
        return float(shapely.union_all(self.polygons).area)

    def pair_margin(self, eps: np.ndarray, pairs: Any = slice(None)) -> np.ndarray:
        """What a look's bound ``eps`` must stay below at each (cell, point) pair (of ``pairs``, an index of the
        pairs: default all), shape of ``eps``, map units.

        A look from the point ``x`` leaves a set within ``ε`` of it, and the point the plan is about within
        ``λ`` more: the cell's certificate tolerates, over the disc of radius ``λ + ε + 2λ sin(ψ/2)`` around
        ``x``, what :func:`~bearnav_cli.runtime.tolerance.set_tolerance` says (the runtime's own rule, at least
        ``τ_c``), less ``κℓ + ν + 2λ sin(ψ/2)``: never below the cell's ``margin``.
        """
        eps = np.asarray(eps, float).reshape(-1)
        cells, points = self.pair_cell[pairs], self.pair_point[pairs]
        arrays, lam = self.arrays, float(self.arrays.lookahead)
        reach = tolerance.step_reach(self.step, self.drift, self.nu, lam)
        out = np.empty(len(eps))
        for start in range(0, len(eps), _ROWS):
            sl = slice(start, start + _ROWS)
            cell, x = cells[sl], self.points[points[sl]][:, None, :]
            grow = lam + eps[sl] + self.swing
            tau = tolerance.set_tolerance(arrays, cell, x, np.ones((len(cell), 1), bool), grow, reach)
            out[sl] = tau - _allowance(self.drift, self.step, self.nu, self.swing)
        return np.maximum(out, self.margin[cells])

    def point_margin(self, eps: np.ndarray | None = None) -> np.ndarray:
        """The least margin of the cells holding each point, shape (P,) map units: below it, every such cell
        is live there; with the points' bounds ``eps`` (P,), the margins :meth:`pair_margin` gives at them."""
        margin = self.margin[self.pair_cell] if eps is None else self.pair_margin(np.asarray(eps)[self.pair_point])
        out = np.full(len(self.points), np.inf)
        np.minimum.at(out, self.pair_point, margin)
        return out

    def sure_start(self, points: np.ndarray, eps: np.ndarray) -> np.ndarray:
        """Whether a robot whose camera stands at each point, after a look that errs by at most ``eps`` there,
        is sure to find a cell that holds its whole set and lets it move, shape (P,) bool.

        ALGORITHMS §12.3 step 4 starts a robot only in a cell that holds its set (its estimate eroded by its
        error), and §12.5's liveness says nothing of that: within about ``ε`` of the edge of ``D`` no look
        places the set in a cell, though the truth is in one. A look's set ``X`` holds the truth and is at
        most ``ε/RADIUS_PER_WIDTH`` wide (:func:`~bearnav_cli.runtime.look_bound.look_bound`), so it lies in
        every cell that the disc of that radius around the truth (grown by the look-ahead point's swing)
        lies in, and the cell lets it move where ``ε`` is below the cell's margin. A look-ahead robot turns
        in place to place its point: any of :data:`HEADINGS` headings will do.

        Parameters
        ----------
        points : ndarray, shape (P, 2)
            Where the camera (the axle) stands (map units).
        eps : ndarray, shape (P,)
            The bound of the look there (map units; ``inf``: no fix).
        """
        x = np.asarray(points, float).reshape(-1, 2)
        eps = np.asarray(eps, float).reshape(-1)
        arrays, lam = self.arrays, float(self.arrays.lookahead)
        reach = np.where(np.isfinite(eps), eps / bounded.RADIUS_PER_WIDTH + self.swing, np.inf)
        sure = np.zeros(len(x), bool)
        turns = np.linspace(0.0, 2.0 * math.pi, HEADINGS, endpoint=False) if lam > 0 else np.zeros(1)
        for theta in turns:
            open_ = np.flatnonzero(~sure & np.isfinite(reach))
            if not len(open_):
                break
            k = least_rank_cell(arrays, robot.lookahead_point(x[open_], np.full(len(open_), theta), lam), reach[open_])
            held = k >= 0
            sure[open_[held]] = eps[open_[held]] < self.margin[k[held]]
        return sure

    def bounds(self, points: np.ndarray, visible: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
        """``ε(x, S)`` of each point with the landmarks it sees, shape (P,) map units.

        ``points`` (P, 2); ``visible`` (P, L) which of ``landmarks`` (L, 2) each sees.
        """
        x = np.asarray(points, float).reshape(-1, 2)
        return bounds_of(
            self.arrays,
            x,
            np.asarray(visible, bool),
            np.full(len(x), self.eta),
            np.asarray(landmarks, float).reshape(-1, 2),
        )

    def look(self, landmarks: np.ndarray, points: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """What a look all around sees, (P, L) bool, and its bound ``ε(x, S_all(x))``, (P,) map units (§12.5)."""
        x = self.points if points is None else np.asarray(points, float).reshape(-1, 2)
        lm = np.asarray(landmarks, float).reshape(-1, 2)
        visible = distinct_views(self.arrays, x, 2.0 * math.pi, self.max_range, 1, lm)[1]
        return visible, self.bounds(x, visible, lm)


def _number(
    value: Any, name: str, *, low: float = 0.0, low_open: bool = False, high: float = math.inf, high_open: bool = False
) -> float:
    """``value`` as a float in its interval (``inf`` only where ``high`` is ``inf`` and closed), else an error."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InvalidParamsError(f"expected a number, got {value!r}", field=name)
    v = float(value)
    inside = not math.isnan(v) and (v > low if low_open else v >= low) and (v < high if high_open else v <= high)
    if not inside or (math.isinf(v) and not (math.isinf(high) and not high_open)):
        lo, hi = "(" if low_open else "[", ")" if high_open or math.isinf(high) else "]"
        raise InvalidParamsError(f"must lie in {lo}{low:g}, {high:g}{hi}, got {value!r}", field=name)
    return v


def default_resolution(arrays: PlanArrays, diagonal: float) -> float:
    """The grid spacing of :func:`measure` by default (map units).

    ``sqrt(median cell area / 25)``, about :data:`POINTS_PER_CELL` points in the median cell, but
    never above :data:`RESOLUTION_PER_DIAGONAL` ``· D`` (for the kitchen, ``0.01·D = 0.128``).

    Parameters
    ----------
    arrays : PlanArrays
        The plan's cells.
    diagonal : float
        ``D``, the map's diagonal (map units).
    """
    from bearnav_cli.runtime.invariants import cell_areas

    areas = np.abs(cell_areas(arrays))
    median = float(np.median(areas)) if len(areas) else 0.0
    by_cells = math.sqrt(median / POINTS_PER_CELL) if median > 0 else math.inf
    return min(by_cells, RESOLUTION_PER_DIAGONAL * diagonal)


def _polygons(arrays: PlanArrays) -> list[shapely.Polygon]:
    offsets, verts = arrays.cell_vertex_offsets, arrays.cell_vertices
    return [shapely.Polygon(verts[offsets[c] : offsets[c + 1]]) for c in range(len(offsets) - 1)]


def _samples(
    polygons: list[shapely.Polygon], grow: float, spacing: float, origin: np.ndarray
) -> tuple[np.ndarray, int, np.ndarray, np.ndarray]:
    """The points of every cell: shared grid points (deduplicated) and each cell's own extras.

    Returns the points (P, 2), how many of them (first) are the grid's, and the pairs ``(cell, point)`` as
    two index arrays sorted by cell.
    """
    keys, key_cell, extra, extra_cell = [], [], [], []
    for c, poly in enumerate(polygons):
        region = shapely.buffer(poly, grow, quad_segs=4) if grow > 0 else poly
        x0, y0, x1, y1 = region.bounds
        i = np.arange(math.ceil((x0 - origin[0]) / spacing), math.floor((x1 - origin[0]) / spacing) + 1)
        j = np.arange(math.ceil((y0 - origin[1]) / spacing), math.floor((y1 - origin[1]) / spacing) + 1)
        ii, jj = (g.ravel() for g in np.meshgrid(i, j))
        inside = shapely.contains_xy(region, origin[0] + ii * spacing, origin[1] + jj * spacing)
        keys.append(np.column_stack([ii[inside], jj[inside]]))
        key_cell.append(np.full(int(inside.sum()), c))
        centroid = np.asarray(region.centroid.coords[0])
        corners = np.asarray(region.exterior.coords)[:-1]
        extra.append(np.vstack([corners + VERTEX_INSET * (centroid - corners), centroid]))
        extra_cell.append(np.full(len(corners) + 1, c))
    key = np.vstack(keys) if keys else np.zeros((0, 2), np.int64)
    unique, inverse = np.unique(key, axis=0, return_inverse=True)
    grid = origin + unique * spacing
    extras = np.vstack(extra)
    points = np.vstack([grid, extras])
    cell = np.concatenate([*key_cell, *extra_cell])
    point = np.concatenate([inverse.ravel(), len(grid) + np.arange(len(extras))])
    order = np.argsort(cell, kind="stable")
    return points, len(grid), cell[order], point[order]


def distinct_views(
    arrays: PlanArrays, points: np.ndarray, fov: float, max_range: float, headings: int, landmarks: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The views worth evaluating: per point, its distinct maximal visible sets over the headings.

    Returns ``(row_point (M,), row_visible (M, L))``: a view that is a subset of another view of the
    same point (or equal to an earlier one) is dropped, since more cones give a smaller ``K``. A
    point that sees nothing at any heading keeps one empty view (``ε`` is then the bounds' diagonal).

    Parameters
    ----------
    arrays : PlanArrays
        The plan (its obstacles for the line of sight).
    points : ndarray, shape (P, 2)
        Where the camera is (map units).
    fov : float
        The camera's full field of view (rad).
    max_range : float
        Its range (map units; ``inf``: any).
    headings : int
        Headings evenly spaced around the circle.
    landmarks : ndarray, shape (L, 2)
        The tags (map units).
    """
    out_point, out_vis = [], []
    n_lm = len(landmarks)
    for start in range(0, len(points), _POINTS):
        p = points[start : start + _POINTS]
        vis = looking.views(arrays, p, fov, max_range, headings, landmarks)  # (P, H, L)
        if headings == 1 or n_lm == 0:
            keep = np.ones(vis.shape[:2], bool)
        else:
            packed = np.packbits(vis, axis=2)  # (P, H, B)
            # outside[p, i, j]: view i has a landmark view j lacks
            outside = np.any(packed[:, :, None, :] & ~packed[:, None, :, :], axis=3)
            subset = ~outside  # i ⊆ j
            equal = subset & np.swapaxes(subset, 1, 2)
            h = np.arange(headings)
            dominated = (subset & ~equal) | (equal & (h[None, None, :] < h[None, :, None]))
            keep = ~np.any(dominated, axis=2)  # a point that sees nothing keeps its first (empty) view
        idx_p, idx_h = np.nonzero(keep)
        out_point.append(start + idx_p)
        out_vis.append(vis[idx_p, idx_h])
    if not out_point:
        return np.zeros(0, np.int64), np.zeros((0, n_lm), bool)
    return np.concatenate(out_point), np.concatenate(out_vis)


def bounds_of(
    arrays: PlanArrays, x: np.ndarray, visible: np.ndarray, eta: np.ndarray, landmarks: np.ndarray | None = None
) -> np.ndarray:
    """``ε(x, S)`` of every row (M,) map units, each row at its own ``η`` (rad): ``runtime.look_bound.one_look_bound``
    in batches of :data:`_ROWS` rows.

    Parameters
    ----------
    arrays : PlanArrays
        The plan (its bounds and tolerance).
    x : ndarray, shape (M, 2)
        Where each look is taken (map units).
    visible : ndarray of bool, shape (M, L)
        The landmarks each look sees.
    eta : ndarray, shape (M,)
        The bearing error bound of each row (rad).
    landmarks : ndarray, shape (L, 2), optional
        The landmarks (map units); default the plan's.
    """
    out = np.empty(len(x))
    box = estimate.axle_bounds(arrays)
    lm = arrays.landmarks if landmarks is None else landmarks
    for start in range(0, len(x), _ROWS):
        sl = slice(start, start + _ROWS)
        out[sl] = look_bound.one_look_bound(x[sl], lm, visible[sl], eta[sl], box, arrays.tol)
    return out


def _allowance(drift: float, step: float, nu: float, swing: float) -> float:
    """What a step (``(κ + 2 sin(ψ/2))ℓ + ν``) and a look-ahead point's swing (``2λ sin(ψ/2)``) take from the
    error a cell tolerates, map units: the margin a look's bound must stay below is the rest."""
    return drift * step + nu + swing


def grid(
    plan: Plan,
    eta_deg: float | None = None,
    fov_deg: float = 60.0,
    kappa: float | None = None,
    nu: float | None = None,
    speed: float | None = None,
    resolution: float | None = None,
    headings: int | None = None,
    max_range: float = math.inf,
) -> LiveGrid:
    """Where and against what :func:`measure` measures: the grid of every cell and each cell's margin.

    Parameters
    ----------
    plan : Plan
        A funnel plan (its ``usable_tolerance`` and embedded map).
    eta_deg : float, optional
        The bearing error bound ``η`` (degrees, in (0, 45)); default the map's
        ``robot.bearing_error_deg + robot.compass_error_deg`` (0.2° when neither is given).
    fov_deg : float
        The camera's full field of view (degrees, in (0, 360]).
    kappa : float, optional
        The slip ``κ`` (in [0, 1)); default the map's ``robot.slip`` (0.03).
    nu : float, optional
        The slip floor ``ν`` (map units, ≥ 0); default the map's ``robot.slip_floor``, else ``1e-4·D``.
    speed : float, optional
        ``v`` of ``ℓ = v·dt`` (map units / s, > 0; ``dt`` from ``runtime.settings.timing``); default the
        map's ``params: simulate: speed``, else ``runtime.settings.SPEED``.
    resolution : float, optional
        Grid spacing (map units, > 0); default :func:`default_resolution`.
    headings : int, optional
        Headings of the minimum over headings (≥ 1); default :data:`HEADINGS` (36), 1 for 360°.
    max_range : float
        The camera's range (map units, > 0; ``inf``: any).

    Returns
    -------
    LiveGrid

    Raises
    ------
    InvalidParamsError
        A value out of its range (the field names the parameter), or a plan without a funnel
        certificate (field ``plan``: ``τ_c`` is not defined).
    """
    map_ = plan.map
    diagonal = float(map_.diagonal)
    params = robot.robot_parameters(map_.robot)
    compass = params.get("compass_error_deg") or 0.0
    if eta_deg is None:
        eta_deg = float(params.get("bearing_error_deg") or 0.0) + compass
    eta_deg = _number(eta_deg, "eta_deg", low=0.0, low_open=True, high=45.0, high_open=True)
    fov_deg = _number(fov_deg, "fov_deg", low=0.0, low_open=True, high=360.0)
    kappa = _number(params.get("slip", 0.0) if kappa is None else kappa, "kappa", high=1.0, high_open=True)
    floor = params.get("slip_floor")
    if nu is None:
        nu = settings.SLIP_FLOOR_PER_DIAGONAL * diagonal if floor is None else floor
    nu = _number(nu, "nu", high=diagonal)
    if speed is None:
        given = (map_.params or {}).get("simulate") or {}
        speed = given.get("speed", settings.SPEED) if isinstance(given, dict) else settings.SPEED
    speed = _number(speed, "speed", low=0.0, low_open=True, high=1e3 * diagonal)
    max_range = _number(max_range, "max_range", low=0.0, low_open=True)  # inf: any range
    full = fov_deg >= 360.0
    if headings is None:
        headings = 1 if full else HEADINGS
    if isinstance(headings, bool) or int(headings) != headings or headings < 1 or headings > 3600:
        raise InvalidParamsError(f"must be an integer in [1, 3600], got {headings!r}", field="headings")
    headings = int(headings)

    arrays = PlanArrays.from_plan(plan)
    if not arrays.funnel:
        raise InvalidParamsError(
            "liveness needs a funnel plan (the papers' cells state no position error they tolerate)", field="plan"
        )
    if resolution is None:
        resolution = default_resolution(arrays, diagonal)
    resolution = _number(resolution, "resolution", low=1e-6 * diagonal, high=diagonal)
    polygons = _polygons(arrays)
    lam = float(arrays.lookahead)
    cover = sum(float(p.area) + float(p.length) * lam + math.pi * lam**2 for p in polygons)
    if cover / resolution**2 > MAX_GRID_POINTS:
        finest = math.sqrt(cover / MAX_GRID_POINTS)
        raise InvalidParamsError(
            f"a grid of {resolution:g} map units would take about {cover / resolution**2:.3g} "
            f"points (at most {MAX_GRID_POINTS:,}): give {finest:.3g} or more",
            field="resolution",
        )

    eta = math.radians(eta_deg)
    fov = math.radians(fov_deg)
    dt = settings.timing(diagonal, speed)[0]
    step_len = speed * dt
    swing = 2.0 * lam * math.sin(0.5 * math.radians(compass)) if lam > 0 else 0.0
    drift = settings.ErrorBounds(heading_bound=math.radians(compass), slip=kappa).drift
    tau = np.asarray(arrays.usable_tolerance, float)
    margin = tau - _allowance(drift, step_len, nu, swing)

    origin = np.asarray(arrays.bounds, float)[:2]
    points, grid_points, pair_cell, pair_point = _samples(polygons, lam, resolution, origin)
    return LiveGrid(
        arrays=arrays,
        polygons=tuple(polygons),
        points=points,
        grid_points=grid_points,
        pair_cell=pair_cell,
        pair_point=pair_point,
        tolerance=tau,
        margin=margin,
        eta=eta,
        fov=fov,
        kappa=kappa,
        drift=drift,
        nu=float(nu),
        step=step_len,
        swing=swing,
        resolution=float(resolution),
        headings=headings,
        max_range=max_range,
    )
