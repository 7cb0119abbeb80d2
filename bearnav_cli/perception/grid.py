"""Where the perception rule is evaluated: the camera's parameters checked, the grid over ``D`` and ``F``, and
the heading of the camera at each point (step 1 of the rule, :mod:`bearnav_cli.perception`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from bearnav_cli.datatypes import cell_polygons
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.runtime import cell_policy
from bearnav_cli.runtime.defaults import check_camera
from bearnav_cli.runtime.invariants import is_number
from bearnav_cli.runtime.plan_arrays import PlanArrays

__all__ = [
    "bounds_grid",
    "camera_headings",
    "check_params",
    "evaluation_grid",
    "EvaluationGrid",
    "GRID_CELLS",
    "MAX_GRID_POINTS",
]


#: Default grid spacing of the evaluation: ``D / GRID_CELLS`` (D the bounds' diagonal), as the map
#: stage's landmark-coverage check (ALGORITHMS §1).
GRID_CELLS = 100
#: Largest evaluation grid :func:`evaluation_grid` builds (points over the bounds box).
MAX_GRID_POINTS = 2_000_000


def check_params(
    fov_deg: float,
    noise_deg: float,
    max_range: float = math.inf,
    error_target: float | None = None,
    min_spread_deg: float = 2.0,
    spacing: float | None = None,
) -> None:
    """Raise :class:`InvalidParamsError` (naming the field) for a parameter outside its range.

    Parameters
    ----------
    fov_deg : float
        Field of view (degrees), in ``(0, 360]``.
    noise_deg : float
        Bearing noise σ (degrees), finite and ``≥ 0``.
    max_range : float
        Sensing range (map units), ``> 0`` (``inf``: unlimited).
    error_target : float or None
        Largest acceptable predicted error (map units), ``> 0``; ``None``: no target.
    min_spread_deg : float
        ``θ_min`` (degrees), in ``(0, 90]``.
    spacing : float or None
        Grid spacing (map units), finite and ``> 0``; ``None``: ``D/100``.
    """

    check_camera(fov_deg, noise_deg, min_spread_deg)
    if not is_number(max_range) or not max_range > 0:
        raise InvalidParamsError(f"must be positive, got {max_range!r}", field="range")
    if error_target is not None and (
        not is_number(error_target) or not (error_target > 0 and math.isfinite(error_target))
    ):
        raise InvalidParamsError(f"must be positive, got {error_target!r}", field="error_target")
    _check_spacing(spacing)


def _check_spacing(spacing: float | None) -> None:
    if spacing is None:
        return
    if not is_number(spacing) or not (spacing > 0 and math.isfinite(spacing)):
        raise InvalidParamsError(f"must be positive, got {spacing!r}", field="spacing")


@dataclass(frozen=True, eq=False)
class EvaluationGrid:
    """The points the rule is evaluated at, with what does not depend on the landmarks.

    ``P`` points. Build it with :func:`evaluation_grid`; :func:`evaluate` reuses it for several
    sets of landmarks (before and after :func:`bearnav_cli.tags.propose_tags`).

    Attributes
    ----------
    points : ndarray, shape (P, 2)
        Grid points (map units) in ``D ∪ F``, at cell centres of a square grid over the bounds.
    in_domain : ndarray of bool, shape (P,)
        In the certified domain ``D`` (the closed union of the plan's cells).
    in_free : ndarray of bool, shape (P,)
        In the free space ``F`` (``FreeSpace.points_free``: in ``B_r`` and outside ``O``).
    heading : ndarray, shape (P,)
        Camera heading (radians, world frame) of :func:`camera_headings`; NaN where none.
    spacing : float
        Grid spacing (map units).
    arrays : PlanArrays
        The plan's run-time arrays.
    space : FreeSpace
        The plan's free space (line of sight through its raw obstacles).
    plan_tolerance : float
        The plan's ``δ*`` (map units; NaN for a paper plan).
    tol : float
        ``1e-9·D`` (map units).
    """

    points: np.ndarray
    in_domain: np.ndarray
    in_free: np.ndarray
    heading: np.ndarray
    spacing: float
    arrays: PlanArrays
    space: FreeSpace
    plan_tolerance: float
    tol: float


def camera_headings(arrays: PlanArrays, points: Any) -> np.ndarray:
    """Where the camera looks at each point: along the runtime's own motion there (step 1 of the rule).

    In ``D`` (a cell holds the point): the field ``u(x) = a_c − M_c x`` of the containing cell of
    least rank (``cell_policy.least_rank_cell``, ALGORITHMS §11.3; ``cell_policy.locate`` for a
    paper plan). Outside: toward the node of ``cell_policy.approach_target`` (the straight approach
    of ALGORITHMS §11.5 step 4).

    Parameters
    ----------
    arrays : PlanArrays
        The plan's run-time arrays (cells, fields, ranks, tree).
    points : array_like, shape (P, 2)
        Positions (map units).

    Returns
    -------
    ndarray, shape (P,)
        Heading (radians, in ``(−π, π]``); NaN where the motion has no direction (the field
        vanishes, which a funnel plan allows only at the goal, or no node can be approached): a
        limited field of view then sees nothing there.
    """
    p = np.asarray(points, float).reshape(-1, 2)
    heading = np.full(len(p), math.nan)
    if not len(p):
        return heading
    cell = cell_policy.least_rank_cell(arrays, p) if arrays.funnel else cell_policy.locate(arrays, p)
    inside = cell >= 0
    direction = np.zeros((len(p), 2))
    if inside.any():
        direction[inside] = cell_policy.affine_field(arrays, cell[inside], p[inside])
    if (~inside).any():
        out = np.flatnonzero(~inside)
        target = cell_policy.approach_target(arrays, p[out])
        ok = target >= 0
        direction[out[ok]] = arrays.nodes[target[ok]] - p[out[ok]]
    norm = np.hypot(direction[:, 0], direction[:, 1])
    moving = norm > 0
    heading[moving] = np.arctan2(direction[moving, 1], direction[moving, 0])
    return heading


def bounds_grid(map_: Any, spacing: float | None) -> tuple[np.ndarray, float]:
    """The centres of a square grid's squares over the map's bounds, shape (n, 2), and its spacing.

    Spacing ``spacing`` (map units), default ``D/GRID_CELLS``; :class:`InvalidParamsError` (field
    ``spacing``) when it is not positive or gives more than :data:`MAX_GRID_POINTS` points.
    """
    _check_spacing(spacing)
    xmin, ymin, xmax, ymax = (float(v) for v in map_.bounds)
    step = map_.diagonal / GRID_CELLS if spacing is None else float(spacing)
    nx, ny = math.ceil((xmax - xmin) / step - 0.5), math.ceil((ymax - ymin) / step - 0.5)
    if max(nx, 1) * max(ny, 1) > MAX_GRID_POINTS:
        raise InvalidParamsError(
            f"{step:g} gives more than {MAX_GRID_POINTS} grid points; use a larger one", field="spacing"
        )
    xs = np.arange(xmin + step / 2, xmax, step)
    ys = np.arange(ymin + step / 2, ymax, step)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2), step


def evaluation_grid(plan: Any, spacing: float | None = None) -> EvaluationGrid:
    """The grid of points over ``D ∪ F`` and the camera heading at each (what the landmarks do not change).

    Parameters
    ----------
    plan : Plan
        A plan (``bearnav.plan/2``; funnel cells give ``D``).
    spacing : float, optional
        Grid spacing (map units); default ``D/100`` (``D`` the bounds' diagonal). Points sit at the
        centres of the grid's squares.

    Returns
    -------
    EvaluationGrid

    Raises
    ------
    InvalidParamsError
        ``spacing`` not positive, or a grid of more than :data:`MAX_GRID_POINTS` points.
    """
    map_ = plan.map
    grid, step = bounds_grid(map_, spacing)
    space = FreeSpace.from_map(map_)
    in_free = space.points_free(grid)
    cells = cell_polygons(plan.cells)
    domain = shapely.union_all(cells) if len(cells) else shapely.Polygon()
    shapely.prepare(domain)
    in_domain = np.zeros(len(grid), bool)
    if not domain.is_empty:
        in_domain = shapely.intersects_xy(domain, grid[:, 0], grid[:, 1])
    keep = in_free | in_domain
    points = grid[keep]
    arrays = PlanArrays.from_plan(plan)
    return EvaluationGrid(
        points=points,
        in_domain=in_domain[keep],
        in_free=in_free[keep],
        heading=camera_headings(arrays, points),
        spacing=step,
        arrays=arrays,
        space=space,
        plan_tolerance=float(plan.plan_tolerance),
        tol=map_.tol,
    )
