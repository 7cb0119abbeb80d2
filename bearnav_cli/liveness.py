"""Liveness of a funnel plan at a bearing error, a camera and a slip (ALGORITHMS §12.5, §12.8).

A robot at ``x`` whose camera looks along the heading ``θ`` sees the landmarks ``S_fov(x, θ)`` (in
the field of view, in range, in line of sight: ``runtime.step.views``). A look's set then errs by
at most ``ε(x, S)`` (``runtime.bounded.one_look_bound``: §12.2's static bound, tightened, see its
docstring). A look (§12.5, ``runtime.step.look_around``) turns to the best heading and, when that
view is not enough, turns all around; turning in place does not grow the set, so it ends inside the
cones of every landmark in sight, ``S_all(x)``. Per cell ``c``:

- ``ε_c^look = max_{x ∈ P_c} ε(x, S_all(x))``, the worst over the cell of the look. §12.5 takes
  the best single view, ``min_θ ε(x, S_fov(x, θ))``, which ignores the turn all around that §12.5's
  own look ends with; that is kept as ``eps_view`` (a look of one view, no turn all around);
- the **margin** ``τ_c − κℓ − ν`` (``τ_c`` the plan's usable tolerance, ``ℓ = v·dt`` one step,
  ``κ`` the slip, ``ν`` its floor; a look-ahead plan also loses the swing ``2λ sin(ψ/2)`` of its
  point, §12.6);
- the cell is **live** when ``ε_c^look`` is below the margin: after every look the robot may move
  on (Theorem 2's proviso);
- ``η*_c``, its largest live bearing error: ``ε`` scales about linearly with ``η``, so the
  estimate ``η·margin/ε_c^look`` is re-evaluated on the same grid and shrunk (by the measured
  ratio, at least ×0.9 a step) until the cell is live; 0 where the margin is not positive or no
  step made it live. The plan's **certified bearing error** ``η*`` is the least ``η*_c``.

``ε_c^look`` is evaluated on a grid, not proved: the points of a square grid of spacing
``resolution`` inside each cell, and every cell's vertices (pulled ``0.1%`` toward its centroid)
and its centroid, so that small cells get points and corners are seen. A look-ahead plan's cells
hold the point ``p`` ahead of the axle, but the camera looks from the axle, anywhere within
``λ`` of ``p``: there the grid covers ``P_c ⊕ B_λ``, a superset of the axle's places. The one-view
minimum over headings takes ``headings`` evenly spaced headings (1 for a camera that sees all
around); a heading whose view is a subset of another's at the same point can only do worse and is
not evaluated.

The **live fraction** of ``D`` is the area where the cell the funnel policy uses (the least-rank
cell holding the point, ``plot.active_regions``'s regions) is live, over the area of ``D``
(shapely, exact for the polygons); :attr:`Liveness.cover_fraction` is the area some live cell
covers. The cells of a plan overlap a great deal (the kitchen's areas sum to 4.5 times its ``D``),
so neither is a sum of cell areas.

:func:`measure` returns a :class:`Liveness`; ``bearnav verify --live-fov`` prints it and
``bearnav plot --color-by live`` draws it. Nothing here prints, plots or writes files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from bearnav_cli.datatypes import Plan, percent
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.runtime import PlanArrays, bounded, estimate, robot, step

__all__ = ["HEADINGS", "MAX_ETA_DEG", "MAX_GRID_POINTS", "POINTS_PER_CELL", "RESOLUTION_PER_DIAGONAL", "SHRINK",
           "SHRINK_STEPS", "VERTEX_INSET", "LiveGrid", "Liveness", "default_resolution", "evaluate", "grid",
           "measure"]  # fmt: skip

#: Headings of the minimum over headings for a camera narrower than 360° (every 10°).
HEADINGS = step.LOOK_HEADINGS
#: The default grid gives about this many points to the median cell ...
POINTS_PER_CELL = 25
#: ... and is never coarser than this fraction of the map's diagonal D.
RESOLUTION_PER_DIAGONAL = 0.01
#: Vertices are pulled this fraction of the way toward their cell's centroid (strictly inside).
VERTEX_INSET = 1e-3
#: ``η*_c`` shrinks by at least this factor per re-evaluation ...
SHRINK = 0.9
#: ... at most this many times (then ``η*_c`` is 0, or ``η`` for a cell live at ``η``).
SHRINK_STEPS = 12
#: Largest ``η*_c`` reported (degrees): the 2η cones stay below 90°.
MAX_ETA_DEG = 22.5
#: Most grid points (summed over the cells) a measurement may take: about 1 kB each.
MAX_GRID_POINTS = 2_000_000
#: Point-heading rows per batch of the one-look bound (memory: about 10 kB a row).
_ROWS = 1 << 14
#: Points per batch of the visibility masks.
_POINTS = 1 << 11


@dataclass(frozen=True, eq=False)
class Liveness:
    """The liveness of a funnel plan's cells at ``(η, fov, κ)`` (ALGORITHMS §12.5), measured on a grid.

    Attributes
    ----------
    eps_look : ndarray, shape (C,)
        ``ε_c^look``: the largest over the cell's grid points of the bound after a look, which ends
        with a turn all around: every landmark in sight and in range (map units).
    eps_view : ndarray, shape (C,)
        The same for the look's first view alone: the least one-view bound over the headings
        (``eps_look`` for a camera that sees all around; map units).
    live : ndarray of bool, shape (C,)
        ``eps_look < margin``.
    view_live : ndarray of bool, shape (C,)
        ``eps_view < margin``: one view at the best heading is enough, no turn all around.
    cell_eta_star : ndarray, shape (C,)
        ``η*_c`` (rad): the largest bearing error at which the grid found the cell live; 0 where
        it is never live.
    points : ndarray of int, shape (C,)
        Grid points of each cell.
    eta_star : float
        The plan's certified bearing error ``η* = min_c η*_c`` (rad).
    live_fraction : float
        Area of ``D`` whose active cell (the least-rank cell holding the point) is live, over the
        area of ``D``, in [0, 1].
    view_fraction : float
        The same for ``view_live`` (``≤ live_fraction``).
    cover_fraction : float
        Area of the union of the live cells over the area of ``D``, in [0, 1] (``≥ live_fraction``).
    grid : LiveGrid
        Where and at what it was measured: the bearing error ``η``, the camera, the slip, the grid,
        and each cell's ``margin`` and ``tolerance`` (also properties of this object).
    """

    eps_look: np.ndarray
    eps_view: np.ndarray
    live: np.ndarray
    view_live: np.ndarray
    cell_eta_star: np.ndarray
    points: np.ndarray
    eta_star: float
    live_fraction: float
    view_fraction: float
    cover_fraction: float
    grid: LiveGrid

    @property
    def margin(self) -> np.ndarray:
        """``τ_c − κℓ − ν`` (less ``2λ sin(ψ/2)`` with a look-ahead), shape (C,) map units."""
        return self.grid.margin

    @property
    def tolerance(self) -> np.ndarray:
        """``τ_c``, the plan's usable tolerance, shape (C,) map units."""
        return self.grid.tolerance

    @property
    def n_live(self) -> int:
        """Live cells."""
        return int(np.count_nonzero(self.live))

    def summary(self) -> str:
        """One plain sentence: the live fraction, η* and how it was measured."""
        g = self.grid
        camera = "360° camera" if g.fov >= 2.0 * math.pi - 1e-12 else f"{math.degrees(g.fov):g}° camera"
        reach = "" if math.isinf(g.max_range) else f" of range {g.max_range:g}"
        heads = "1 heading (all around)" if g.headings == 1 else f"{g.headings} headings"
        return (f"liveness at a bearing error of {math.degrees(g.eta):.3g}°, {camera}{reach}, wheel slip {g.kappa:g}: "
                f"{percent(self.live_fraction)} of the certified area live ({self.n_live}/{len(self.live)} cells; "
                f"{percent(self.view_fraction)} after one view, without turning all around); the largest bearing error "
                f"every cell is live at: {math.degrees(self.eta_star):.3g}°; measured on a {g.resolution:.3g}-map-unit "
                f"grid with {heads}, a measurement, not a proof")  # fmt: skip

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict: degrees for angles, map units for lengths, ``null`` for non-finite numbers."""

        def finite(values: np.ndarray, scale: float = 1.0) -> list:
            return [float(v) * scale if math.isfinite(v) else None for v in np.asarray(values, float)]

        deg = math.degrees(1.0)
        return {
            "eta_deg": round(math.degrees(self.grid.eta), 12),
            "fov_deg": round(math.degrees(self.grid.fov), 12),
            "max_range": None if math.isinf(self.grid.max_range) else self.grid.max_range,
            "kappa": self.grid.kappa,
            "nu": self.grid.nu,
            "step": self.grid.step,
            "swing": self.grid.swing,
            "resolution": self.grid.resolution,
            "headings": self.grid.headings,
            "measured": "on a grid of the stated resolution: a measurement, not a proof",
            "live_fraction": self.live_fraction,
            "view_fraction": self.view_fraction,
            "cover_fraction": self.cover_fraction,
            "live_cells": self.n_live,
            "eta_star_deg": math.degrees(self.eta_star),
            "per_cell": {
                "eps_look": finite(self.eps_look),
                "eps_view": finite(self.eps_view),
                "margin": finite(self.margin),
                "tolerance": finite(self.tolerance),
                "live": [bool(v) for v in self.live],
                "view_live": [bool(v) for v in self.view_live],
                "eta_star_deg": finite(self.cell_eta_star, deg),
                "points": [int(v) for v in self.points],
            },
            "summary": self.summary(),
        }


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
    pair_cell, pair_point : ndarray of int, shape (M,)
        Which cell holds which point, sorted by cell (a point of several cells is in several pairs).
    tolerance, margin : ndarray, shape (C,)
        ``τ_c`` and ``τ_c − κℓ − ν − 2λ sin(ψ/2)`` (map units).
    eta : float
        The bearing error bound ``η`` (rad).
    fov : float
        The camera's full field of view (rad).
    kappa : float
        The slip ``κ`` (fraction of a step).
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
    pair_cell: np.ndarray
    pair_point: np.ndarray
    tolerance: np.ndarray
    margin: np.ndarray
    eta: float
    fov: float
    kappa: float
    nu: float
    step: float
    swing: float
    resolution: float
    headings: int
    max_range: float

    def point_margin(self) -> np.ndarray:
        """The least margin of the cells holding each point, shape (P,) map units: below it, every such cell
        is live there."""
        out = np.full(len(self.points), np.inf)
        np.minimum.at(out, self.pair_point, self.margin[self.pair_cell])
        return out

    def bounds(self, points: np.ndarray, visible: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
        """``ε(x, S)`` of each point with the landmarks it sees, shape (P,) map units.

        ``points`` (P, 2); ``visible`` (P, L) which of ``landmarks`` (L, 2) each sees.
        """
        x = np.asarray(points, float).reshape(-1, 2)
        return _bounds_of(self.arrays, x, np.asarray(visible, bool), np.full(len(x), self.eta),
                          np.asarray(landmarks, float).reshape(-1, 2))  # fmt: skip

    def look(self, landmarks: np.ndarray, points: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """What a look all around sees, (P, L) bool, and its bound ``ε(x, S_all(x))``, (P,) map units (§12.5)."""
        x = self.points if points is None else np.asarray(points, float).reshape(-1, 2)
        lm = np.asarray(landmarks, float).reshape(-1, 2)
        visible = _views(self.arrays, x, 2.0 * math.pi, self.max_range, 1, lm)[1]
        return visible, self.bounds(x, visible, lm)


def _number(value: Any, name: str, *, low: float = 0.0, low_open: bool = False, high: float = math.inf,
            high_open: bool = False) -> float:  # fmt: skip
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


def _samples(polygons: list[shapely.Polygon], grow: float, spacing: float,
             origin: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The points of every cell: shared grid points (deduplicated) and each cell's own extras.

    Returns the points (P, 2), and the pairs ``(cell, point)`` as two index arrays sorted by cell.
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
    return points, cell[order], point[order]


def _views(arrays: PlanArrays, points: np.ndarray, fov: float, max_range: float, headings: int,
           landmarks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The views worth evaluating: per point, its distinct maximal visible sets over the headings.

    Returns ``(row_point (M,), row_visible (M, L))``: a view that is a subset of another view of the
    same point (or equal to an earlier one) is dropped, since more cones give a smaller ``K``. A
    point that sees nothing at any heading keeps one empty view (``ε`` is then the bounds' diagonal).
    """
    out_point, out_vis = [], []
    n_lm = len(landmarks)
    for start in range(0, len(points), _POINTS):
        p = points[start : start + _POINTS]
        vis = step.views(arrays, p, fov, max_range, headings, landmarks)  # (P, H, L)
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


def _bounds_of(arrays: PlanArrays, x: np.ndarray, visible: np.ndarray, eta: np.ndarray,
               landmarks: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """``ε(x, S)`` of every row (M,) map units, each row at its own ``η`` (rad): ``runtime.bounded.one_look_bound``
    in batches of :data:`_ROWS` rows (``landmarks``: default the plan's)."""
    out = np.empty(len(x))
    box = estimate.axle_bounds(arrays)
    lm = arrays.landmarks if landmarks is None else landmarks
    for start in range(0, len(x), _ROWS):
        sl = slice(start, start + _ROWS)
        out[sl] = bounded.one_look_bound(x[sl], lm, visible[sl], eta[sl], box, arrays.tol)
    return out


def _cell_max(values: np.ndarray, cell: np.ndarray, n_cells: int) -> np.ndarray:
    out = np.full(n_cells, -np.inf)
    np.maximum.at(out, cell, values)
    return out


def _point_min(values: np.ndarray, row_point: np.ndarray, n_points: int) -> np.ndarray:
    out = np.full(n_points, np.inf)
    np.minimum.at(out, row_point, values)
    return out


def _active_regions(polygons: list[shapely.Polygon], rank: np.ndarray) -> list[shapely.Geometry]:
    """``P_c`` less every cell of smaller rank (ties: lower index): where the policy uses cell ``c``."""
    regions: list[shapely.Geometry] = [shapely.Polygon()] * len(polygons)
    taken: shapely.Geometry = shapely.Polygon()
    for c in np.lexsort((np.arange(len(polygons)), rank)):
        regions[c] = shapely.difference(polygons[c], taken)
        taken = shapely.union(taken, polygons[c])
    return regions


def grid(plan: Plan, eta_deg: float | None = None, fov_deg: float = 60.0, kappa: float | None = None,
         nu: float | None = None, speed: float | None = None, resolution: float | None = None,
         headings: int | None = None, max_range: float = math.inf) -> LiveGrid:  # fmt: skip
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
        ``v`` of ``ℓ = v·dt`` (map units / s, > 0; ``dt`` from ``runtime.step.timing``); default the
        map's ``params: simulate: speed``, else ``runtime.step.SPEED``.
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
        nu = step.SLIP_FLOOR_PER_DIAGONAL * diagonal if floor is None else floor
    nu = _number(nu, "nu", high=diagonal)
    if speed is None:
        given = (map_.params or {}).get("simulate") or {}
        speed = given.get("speed", step.SPEED) if isinstance(given, dict) else step.SPEED
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
        raise InvalidParamsError("liveness needs a funnel plan (the papers' cells state no position error they "
                                 "tolerate)", field="plan")  # fmt: skip
    if resolution is None:
        resolution = default_resolution(arrays, diagonal)
    resolution = _number(resolution, "resolution", low=1e-6 * diagonal, high=diagonal)
    polygons = _polygons(arrays)
    lam = float(arrays.lookahead)
    cover = sum(float(p.area) + float(p.length) * lam + math.pi * lam**2 for p in polygons)
    if cover / resolution**2 > MAX_GRID_POINTS:
        finest = math.sqrt(cover / MAX_GRID_POINTS)
        raise InvalidParamsError(f"a grid of {resolution:g} map units would take about {cover / resolution**2:.3g} "
                                 f"points (at most {MAX_GRID_POINTS:,}): give {finest:.3g} or more",
                                 field="resolution")  # fmt: skip

    eta = math.radians(eta_deg)
    fov = math.radians(fov_deg)
    dt = step.timing(diagonal, speed)[0]
    step_len = speed * dt
    swing = 2.0 * lam * math.sin(0.5 * math.radians(compass)) if lam > 0 else 0.0
    tau = np.asarray(arrays.usable_tolerance, float)
    margin = tau - kappa * step_len - nu - swing

    origin = np.asarray(arrays.bounds, float)[:2]
    points, pair_cell, pair_point = _samples(polygons, lam, resolution, origin)
    return LiveGrid(arrays=arrays, polygons=tuple(polygons), points=points, pair_cell=pair_cell,
                    pair_point=pair_point, tolerance=tau, margin=margin, eta=eta, fov=fov, kappa=kappa,
                    nu=float(nu), step=step_len, swing=swing, resolution=float(resolution), headings=headings,
                    max_range=max_range)  # fmt: skip


def measure(plan: Plan, eta_deg: float | None = None, fov_deg: float = 60.0, kappa: float | None = None,
            nu: float | None = None, speed: float | None = None, resolution: float | None = None,
            headings: int | None = None, max_range: float = math.inf,
            landmarks: np.ndarray | None = None) -> Liveness:  # fmt: skip
    """Measure the liveness of a funnel plan's cells on a grid (ALGORITHMS §12.5; see the module docstring).

    Parameters
    ----------
    plan, eta_deg, fov_deg, kappa, nu, speed, resolution, headings, max_range
        As :func:`grid`.
    landmarks : ndarray, shape (L, 2), optional
        The tags to measure with (map units); default the plan's. The cells and their tolerances
        do not depend on them, so proposed tags are measured on the same plan.

    Returns
    -------
    Liveness

    Raises
    ------
    InvalidParamsError
        As :func:`grid`.
    """
    return evaluate(grid(plan, eta_deg, fov_deg, kappa, nu, speed, resolution, headings, max_range), landmarks)


def evaluate(g: LiveGrid, landmarks: np.ndarray | None = None,
             look: tuple[np.ndarray, np.ndarray] | None = None) -> Liveness:  # fmt: skip
    """The liveness of the cells on a grid with a set of landmarks.

    Parameters
    ----------
    g : LiveGrid
        The grid, the plan and the bounds (:func:`grid`).
    landmarks : ndarray, shape (L, 2), optional
        The landmarks (map units); default the plan's.
    look : tuple of ndarray, optional
        ``g.look(landmarks)``, when the caller has it already.
    """
    arrays, points, pair_cell, pair_point, margin, eta = g.arrays, g.points, g.pair_cell, g.pair_point, g.margin, g.eta
    lm = arrays.landmarks if landmarks is None else np.asarray(landmarks, float).reshape(-1, 2)
    n_cells = len(margin)
    polygons = list(g.polygons)
    # a look ends with a turn all around (§12.5): its set lies in the cones of every landmark in sight
    all_vis, eps_all = g.look(lm) if look is None else look
    eps_look = _cell_max(eps_all[pair_point], pair_cell, n_cells)
    live = eps_look < margin
    cell_eta = _eta_star(arrays, lm, points, pair_cell, pair_point, all_vis, eps_look, margin, eta, live)
    if g.fov >= 2.0 * math.pi:
        eps_view = eps_look
    else:  # the look's first view, at the best heading
        row_point, row_vis = _views(arrays, points, g.fov, g.max_range, g.headings, lm)
        row_eps = _bounds_of(arrays, points[row_point], row_vis, np.full(len(row_point), eta), lm)
        eps_view = _cell_max(_point_min(row_eps, row_point, len(points))[pair_point], pair_cell, n_cells)
    view_live = eps_view < margin

    rank = np.asarray(arrays.cell_rank, float)
    domain = shapely.union_all(polygons)
    area = float(domain.area)
    regions = _active_regions(polygons, rank)
    live_area = sum(float(regions[c].area) for c in np.flatnonzero(live))
    view_area = sum(float(regions[c].area) for c in np.flatnonzero(view_live))
    cover = float(shapely.union_all([polygons[c] for c in np.flatnonzero(live)]).area) if live.any() else 0.0
    points_per_cell = np.bincount(pair_cell, minlength=n_cells)
    return Liveness(
        eps_look=eps_look, eps_view=eps_view, live=live, view_live=view_live, cell_eta_star=cell_eta,
        points=points_per_cell, eta_star=float(np.min(cell_eta)) if n_cells else 0.0,
        live_fraction=min(1.0, live_area / area) if area > 0 else 0.0,
        view_fraction=min(1.0, view_area / area) if area > 0 else 0.0,
        cover_fraction=min(1.0, cover / area) if area > 0 else 0.0,
        grid=g,
    )  # fmt: skip


def _eta_star(arrays: PlanArrays, landmarks: np.ndarray, points: np.ndarray, pair_cell: np.ndarray,
              pair_point: np.ndarray, visible: np.ndarray, eps_look: np.ndarray, margin: np.ndarray, eta: float,
              live: np.ndarray) -> np.ndarray:  # fmt: skip
    """``η*_c`` per cell (rad): the linear estimate, re-evaluated on the grid and shrunk until live.

    Every point looks at the landmarks ``visible`` (P, L) (its look all around).
    """
    n_cells = len(margin)
    out = np.zeros(n_cells)
    ok = (margin > 0) & (eps_look > 0) & np.isfinite(eps_look)
    guess = np.zeros(n_cells)
    guess[ok] = np.minimum(eta * margin[ok] / eps_look[ok], math.radians(MAX_ETA_DEG))
    out[live] = eta  # live at η already: η*_c ≥ η
    pending = ok & (guess > out)
    for _ in range(SHRINK_STEPS):
        cells = np.flatnonzero(pending)
        if not len(cells):
            break
        sel = np.isin(pair_cell, cells)
        pc, pp = pair_cell[sel], pair_point[sel]
        eps_pair = _bounds_of(arrays, points[pp], visible[pp], guess[pc], landmarks)
        eps_cell = _cell_max(eps_pair, pc, n_cells)[cells]
        good = eps_cell < margin[cells]
        out[cells[good]] = np.maximum(out[cells[good]], guess[cells[good]])
        pending[cells[good]] = False
        bad = cells[~good]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(eps_cell[~good] > 0, margin[bad] / eps_cell[~good], 0.0)
        guess[bad] *= np.minimum(SHRINK, ratio)
        pending[bad] &= guess[bad] > out[bad]  # a cell live at η stops once the guess falls to η
    return out
