"""Perception coverage: where a camera looking along the plan's field gets a usable fix (issue 11, part 2).

The **perception rule** at a point ``x`` (docs/algorithms.md, "Perception coverage and tag
placement"): the camera looks where the robot drives there, and the tags it sees give a fix the
runtime would use, noise-free, with an acceptable predicted error. Concretely, with the runtime's
own code (:mod:`bearnav_cli.runtime`):

1. **Heading** (:func:`camera_headings`). Inside the certified domain ``D`` the robot follows the
   field ``u(x) = a_c − M_c x`` of the containing cell of least rank (ALGORITHMS §11.3,
   ``cell_policy.least_rank_cell``); the camera looks along ``u(x)`` (the unicycle turns first, so
   along the field). Outside ``D`` the robot drives straight to the node of
   ``cell_policy.approach_target`` (ALGORITHMS §11.5 step 4), and the camera looks that way.
2. **Visible tags** (:func:`visible_landmarks`, ALGORITHMS §6.1): in the field of view
   (``bearing.in_field_of_view`` on the true direction), within range (``bearing.in_range``) and in
   line of sight through the raw obstacles (``FreeSpace.visibility_regions``, as ``simulate`` does).
3. **Usable fix** (:func:`fix_quality`): the runtime's ``lsq`` fix of the exact bearings
   (``bearing.reconstruct(..., method="lsq", min_spread=θ_min)``) is usable: two or more tags,
   spread by ``λ_min(Σ P_k) ≥ 1 − cos θ_min`` (ALGORITHMS §6.2). Its predicted error is the
   runtime's error bound ``3·sqrt(bearing.fix_variance(..., σ))`` (map units; 0 noise-free,
   ``inf`` without a usable fix).
4. With an **error target** ``E`` the rule also needs predicted error ``≤ E``.

:func:`perception_coverage` evaluates the rule on a grid over ``D`` (the union of the plan's cells)
and over the free space ``F`` and returns a :class:`PerceptionCoverage`; ``plot.plot_perception``
draws it. Before a plan there is no field and the heading is free: :func:`heading_coverage` gives,
over ``F``, where some heading and where every heading of the camera passes steps 2 and 3 (a
:class:`HeadingCoverage`, ``bearnav map --fov``). Nothing here prints, plots or writes files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from bearnav_cli import composition
from bearnav_cli.datatypes import percent, plural
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.runtime import bearing, cell_policy
from bearnav_cli.runtime.invariants import is_number
from bearnav_cli.runtime.plan_arrays import PlanArrays

__all__ = [
    "GRID_CELLS",
    "MAX_GRID_POINTS",
    "EvaluationGrid",
    "HeadingCoverage",
    "PerceptionCoverage",
    "camera_headings",
    "check_params",
    "evaluation_grid",
    "evaluate",
    "fix_quality",
    "heading_coverage",
    "perception_coverage",
    "visible_landmarks",
]

#: Default grid spacing of the evaluation: ``D / GRID_CELLS`` (D the bounds' diagonal), as the map
#: stage's landmark-coverage check (ALGORITHMS §1).
GRID_CELLS = 100
#: Largest evaluation grid :func:`evaluation_grid` builds (points over the bounds box).
MAX_GRID_POINTS = 2_000_000


def check_params(fov_deg: float, noise_deg: float, max_range: float = math.inf, error_target: float | None = None,
                 min_spread_deg: float = 2.0, spacing: float | None = None) -> None:  # fmt: skip
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

    bearing.check_camera(fov_deg, noise_deg, min_spread_deg)
    if not is_number(max_range) or not max_range > 0:
        raise InvalidParamsError(f"must be positive, got {max_range!r}", field="range")
    if error_target is not None and (not is_number(error_target) or not (error_target > 0 and
                                                                       math.isfinite(error_target))):  # fmt: skip
        raise InvalidParamsError(f"must be positive, got {error_target!r}", field="error_target")
    _check_spacing(spacing)


def _check_spacing(spacing: float | None) -> None:
    if spacing is None:
        return
    if not is_number(spacing) or not (spacing > 0 and math.isfinite(spacing)):
        raise InvalidParamsError(f"must be positive, got {spacing!r}", field="spacing")


# --------------------------------------------------------------------------- the evaluation grid


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


def _bounds_grid(map_: Any, spacing: float | None) -> tuple[np.ndarray, float]:
    """The centres of a square grid's squares over the map's bounds, shape (n, 2), and its spacing.

    Spacing ``spacing`` (map units), default ``D/GRID_CELLS``; :class:`InvalidParamsError` (field
    ``spacing``) when it is not positive or gives more than :data:`MAX_GRID_POINTS` points.
    """
    _check_spacing(spacing)
    xmin, ymin, xmax, ymax = (float(v) for v in map_.bounds)
    step = map_.diagonal / GRID_CELLS if spacing is None else float(spacing)
    nx, ny = math.ceil((xmax - xmin) / step - 0.5), math.ceil((ymax - ymin) / step - 0.5)
    if max(nx, 1) * max(ny, 1) > MAX_GRID_POINTS:
        raise InvalidParamsError(f"{step:g} gives more than {MAX_GRID_POINTS} grid points; use a larger one",
                                 field="spacing")  # fmt: skip
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
    grid, step = _bounds_grid(map_, spacing)
    space = FreeSpace.from_map(map_)
    in_free = space.points_free(grid)
    cells = composition.cell_polygons(plan.cells)
    domain = shapely.union_all(cells) if len(cells) else shapely.Polygon()
    shapely.prepare(domain)
    in_domain = np.zeros(len(grid), bool)
    if not domain.is_empty:
        in_domain = shapely.intersects_xy(domain, grid[:, 0], grid[:, 1])
    keep = in_free | in_domain
    points = grid[keep]
    arrays = PlanArrays.from_plan(plan)
    return EvaluationGrid(points=points, in_domain=in_domain[keep], in_free=in_free[keep],
                          heading=camera_headings(arrays, points), spacing=step, arrays=arrays, space=space,
                          plan_tolerance=float(plan.plan_tolerance), tol=map_.tol)  # fmt: skip


# --------------------------------------------------------------------------- the rule


def visible_landmarks(points: Any, heading: Any, landmarks: Any, fov_deg: float, max_range: float,
                      sight: list, tol: float) -> np.ndarray:  # fmt: skip
    """Step 2 of the rule: which landmarks the camera sees from each point (ALGORITHMS §6.1).

    Parameters
    ----------
    points : array_like, shape (P, 2)
        Positions (map units).
    heading : array_like, shape (P,)
        Camera headings (radians); NaN sees nothing unless ``fov_deg == 360``.
    landmarks : array_like, shape (L, 2)
        Landmark positions (map units).
    fov_deg : float
        Field of view (degrees), in ``(0, 360]``.
    max_range : float
        Sensing range (map units); ``inf`` for unlimited.
    sight : list of shapely geometries, length L
        ``FreeSpace.visibility_regions(landmarks)`` (line of sight through the raw obstacles).
    tol : float
        ``1e-9·D`` (map units): rule (a) of §6.1.

    Returns
    -------
    ndarray of bool, shape (P, L)
    """
    p = np.asarray(points, float).reshape(-1, 2)
    lm = np.asarray(landmarks, float).reshape(-1, 2)
    if not len(p) or not len(lm):
        return np.zeros((len(p), len(lm)), bool)
    seen = bearing.in_field_of_view(p, np.asarray(heading, float), lm, math.radians(fov_deg), tol=tol)
    if math.isfinite(max_range):
        seen &= bearing.in_range(p, lm, max_range)
    for k in np.flatnonzero(seen.any(axis=0)):
        rows = np.flatnonzero(seen[:, k])
        seen[rows, k] = shapely.intersects_xy(sight[k], p[rows, 0], p[rows, 1])
    return seen


def fix_quality(points: Any, visible: Any, landmarks: Any, noise_deg: float, min_spread_deg: float,
                tol: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Step 3 of the rule: is the runtime's ``lsq`` fix of exact bearings usable, and its predicted error.

    Parameters
    ----------
    points : array_like, shape (P, 2)
        Positions (map units).
    visible : array_like of bool, shape (P, L)
        What the camera sees (:func:`visible_landmarks`).
    landmarks : array_like, shape (L, 2)
        Landmark positions (map units).
    noise_deg : float
        Bearing noise σ (degrees).
    min_spread_deg : float
        ``θ_min`` of ALGORITHMS §6.2 (degrees).
    tol : float
        ``1e-9·D`` (map units).

    Returns
    -------
    usable : ndarray of bool, shape (P,)
        ``bearing.reconstruct(exact bearings, visible, method="lsq", min_spread=θ_min).usable``.
    predicted_error : ndarray, shape (P,)
        ``3·sqrt(bearing.fix_variance(..., σ))`` at the fix (map units): the runtime's error bound;
        0 noise-free, ``inf`` where the fix is not usable.
    """
    p = np.asarray(points, float).reshape(-1, 2)
    lm = np.asarray(landmarks, float).reshape(-1, 2)
    vis = np.asarray(visible, bool).reshape(len(p), len(lm))
    error = np.full(len(p), math.inf)
    if not len(p) or len(lm) < 2:
        return np.zeros(len(p), bool), error
    unit = bearing.directions(p, lm)[0]
    rec = bearing.reconstruct(unit, vis, lm, 0, method="lsq", min_spread=math.radians(min_spread_deg), tol=tol)
    usable = rec.usable
    sigma = math.radians(noise_deg)
    error[usable] = 0.0
    if sigma > 0 and usable.any():
        var = bearing.fix_variance(unit[usable], vis[usable], lm, rec.x_hat[usable], sigma, tol)
        error[usable] = 3.0 * np.sqrt(var)
    return usable, error


# --------------------------------------------------------------------------- coverage


@dataclass(frozen=True, eq=False)
class PerceptionCoverage:
    """Where the perception rule holds on a plan, for one camera and one set of landmarks.

    ``P`` grid points, ``L`` landmarks. Fractions are of grid points (the grid's spacing makes them
    area fractions to within the grid's resolution); NaN for an empty set.

    Attributes
    ----------
    points : ndarray, shape (P, 2)
        Grid points in ``D ∪ F`` (map units).
    heading : ndarray, shape (P,)
        Camera heading at each point (radians; NaN where the motion has no direction).
    in_domain : ndarray of bool, shape (P,)
        The point lies in the certified domain ``D``.
    in_free : ndarray of bool, shape (P,)
        The point lies in the free space ``F``.
    visible : ndarray of bool, shape (P, L)
        Landmarks the camera sees there (field of view, range, line of sight).
    visible_count : ndarray of int64, shape (P,)
        ``visible.sum(axis=1)``.
    usable : ndarray of bool, shape (P,)
        The noise-free ``lsq`` fix is usable (two or more tags, spread by ``θ_min``).
    predicted_error : ndarray, shape (P,)
        The fix's error bound ``3σ`` (map units; 0 noise-free, ``inf`` where not usable).
    holds : ndarray of bool, shape (P,)
        The rule holds: ``usable`` and, with an error target, ``predicted_error ≤ error_target``.
    fraction_domain, fraction_free : float
        Share of the points of ``D`` (of ``F``) where the rule holds.
    plan_tolerance : float
        The plan's ``δ*`` (map units; NaN for a paper plan).
    fraction_within_tolerance : float
        Share of the points of ``D`` with a usable fix whose predicted error is at most ``δ*``.
    landmarks : ndarray, shape (L, 2)
        The landmarks evaluated (map units).
    landmark_ids : tuple of str, length L
        Their ids (the map's, or ``"0"``, ``"1"``, ... when none were given).
    fov_deg, noise_deg, max_range, min_spread_deg : float
        The camera (degrees, degrees, map units, degrees).
    error_target : float or None
        ``E`` (map units), if the rule had one.
    spacing : float
        Grid spacing (map units).
    """

    points: np.ndarray
    heading: np.ndarray
    in_domain: np.ndarray
    in_free: np.ndarray
    visible: np.ndarray
    visible_count: np.ndarray
    usable: np.ndarray
    predicted_error: np.ndarray
    holds: np.ndarray
    fraction_domain: float
    fraction_free: float
    plan_tolerance: float
    fraction_within_tolerance: float
    landmarks: np.ndarray
    landmark_ids: tuple
    fov_deg: float
    noise_deg: float
    max_range: float
    min_spread_deg: float
    error_target: float | None
    spacing: float

    @property
    def failing_domain(self) -> np.ndarray:
        """Points of ``D`` where the rule fails, shape (n, 2) (map units)."""
        return self.points[self.in_domain & ~self.holds]

    @property
    def failing_free(self) -> np.ndarray:
        """Points of ``F`` outside ``D`` where the rule fails, shape (n, 2) (map units)."""
        return self.points[self.in_free & ~self.in_domain & ~self.holds]

    @property
    def median_error_domain(self) -> float:
        """Median predicted error over the points of ``D`` with a usable fix (map units; NaN if none)."""
        e = self.predicted_error[self.in_domain & self.usable]
        return float(np.median(e)) if len(e) else math.nan

    def summary(self) -> str:
        """One line: the camera, the fractions of ``D`` and ``F`` where the rule holds, and one fix against ``τ_c``."""
        target = "" if self.error_target is None else f", error ≤ {self.error_target:g}"
        rng = "" if not math.isfinite(self.max_range) else f", range {self.max_range:g}"
        return (f"{plural(len(self.landmarks), 'tag')}, {self.fov_deg:g}° camera{rng}, {self.noise_deg:g}° noise"
                f"{target}: two usable tags in view from {percent(self.fraction_domain)} of the certified area and "
                f"{percent(self.fraction_free)} of the free space; "
                f"one fix's median predicted error {self.median_error_domain:.3g} in the certified area, below the "
                f"plan's least position tolerance {self.plan_tolerance:.3g} on "
                f"{percent(self.fraction_within_tolerance)} of it "
                "(a run does not rest on one fix: it fuses fixes with odometry, which `bearnav simulate` measures "
                "and nothing here proves)")  # fmt: skip


def _share(mask: np.ndarray, where: np.ndarray) -> float:
    n = int(where.sum())
    return float(np.sum(mask & where)) / n if n else math.nan


def evaluate(grid: EvaluationGrid, landmarks: Any, landmark_ids: Any = None, *, fov_deg: float, noise_deg: float,
             max_range: float = math.inf, error_target: float | None = None, min_spread_deg: float = 2.0,
             sight: list | None = None) -> PerceptionCoverage:  # fmt: skip
    """The rule on a prepared :class:`EvaluationGrid` for one set of landmarks.

    Parameters
    ----------
    grid : EvaluationGrid
        The points, their camera headings and the plan's free space (:func:`evaluation_grid`).
    landmarks : array_like, shape (L, 2)
        Landmark positions (map units).
    landmark_ids : sequence of str, length L, optional
        Their ids (default ``"0"``, ``"1"``, ...).
    fov_deg, noise_deg, max_range, error_target, min_spread_deg
        As :func:`perception_coverage`.
    sight : list of shapely geometries, optional
        ``grid.space.visibility_regions(landmarks)``, when already built.

    Returns
    -------
    PerceptionCoverage
    """
    check_params(fov_deg, noise_deg, max_range, error_target, min_spread_deg)
    lm = np.asarray(landmarks, float).reshape(-1, 2)
    ids = tuple(str(i) for i in (range(len(lm)) if landmark_ids is None else landmark_ids))
    if len(ids) != len(lm):
        raise InvalidParamsError(f"{len(ids)} ids for {len(lm)} landmarks", field="landmark_ids")
    if sight is None:
        sight = grid.space.visibility_regions(lm)
    visible = visible_landmarks(grid.points, grid.heading, lm, fov_deg, max_range, sight, grid.tol)
    usable, error = fix_quality(grid.points, visible, lm, noise_deg, min_spread_deg, grid.tol)
    holds = usable if error_target is None else usable & (error <= error_target)
    delta = grid.plan_tolerance
    within = usable & (error <= delta) if math.isfinite(delta) else np.zeros(len(usable), bool)
    return PerceptionCoverage(
        points=grid.points, heading=grid.heading, in_domain=grid.in_domain, in_free=grid.in_free, visible=visible,
        visible_count=visible.sum(axis=1).astype(np.int64), usable=usable, predicted_error=error, holds=holds,
        fraction_domain=_share(holds, grid.in_domain), fraction_free=_share(holds, grid.in_free),
        plan_tolerance=delta, fraction_within_tolerance=_share(within, grid.in_domain), landmarks=lm,
        landmark_ids=ids, fov_deg=float(fov_deg), noise_deg=float(noise_deg), max_range=float(max_range),
        min_spread_deg=float(min_spread_deg), error_target=None if error_target is None else float(error_target),
        spacing=grid.spacing,
    )  # fmt: skip


def perception_coverage(plan: Any, fov_deg: float, noise_deg: float, max_range: float = math.inf,
                        error_target: float | None = None, spacing: float | None = None, landmarks: Any = None,
                        *, landmark_ids: Any = None, min_spread_deg: float = 2.0) -> PerceptionCoverage:  # fmt: skip
    """Where the perception rule holds on a plan: the fractions of ``D`` and of ``F`` (issue 11).

    The rule at ``x`` (module docstring): the camera looks along the runtime's motion at ``x``, and
    the tags in view, in range and in line of sight give a usable noise-free ``lsq`` fix whose
    predicted error ``3σ`` is at most ``error_target`` (when given).

    Parameters
    ----------
    plan : Plan
        The plan (``bearnav.plan/2``): its fields, cells (``D``), map and ``δ*``.
    fov_deg : float
        Camera field of view (degrees), in ``(0, 360]``.
    noise_deg : float
        Bearing noise σ (degrees, ``≥ 0``); only the predicted error depends on it.
    max_range : float
        Sensing range (map units, ``> 0``); default unlimited.
    error_target : float, optional
        ``E`` (map units, ``> 0``): the rule also needs predicted error ``≤ E``.
    spacing : float, optional
        Grid spacing (map units); default ``D/100``.
    landmarks : array_like, shape (L, 2), optional
        Evaluate these landmarks instead of the plan's (e.g. with proposed tags); the fields do not
        depend on the landmarks (ALGORITHMS Lemma 3), so the plan's headings still apply.
    landmark_ids : sequence of str, optional
        Ids of ``landmarks`` (default: the plan's ids, or ``"0"``, ``"1"``, ... for overrides).
    min_spread_deg : float
        ``θ_min`` of ALGORITHMS §6.2 (degrees); default 2°, the runtime's.

    Returns
    -------
    PerceptionCoverage

    Raises
    ------
    InvalidParamsError
        ``fov_deg`` outside ``(0, 360]``, negative ``noise_deg``, a ``max_range``,
        ``error_target`` or ``spacing`` that is not positive (the message names the field).
    """
    check_params(fov_deg, noise_deg, max_range, error_target, min_spread_deg, spacing)
    grid = evaluation_grid(plan, spacing)
    if landmarks is None:
        landmarks = plan.map.landmarks
        landmark_ids = plan.map.landmark_ids if landmark_ids is None else landmark_ids
    return evaluate(grid, landmarks, landmark_ids, fov_deg=fov_deg, noise_deg=noise_deg, max_range=max_range,
                    error_target=error_target, min_spread_deg=min_spread_deg)  # fmt: skip


# --------------------------------------------------------------------------- before a plan: any heading

#: Largest number of (point, heading, landmark) entries :func:`heading_coverage` evaluates at once.
_CHUNK_ENTRIES = 1 << 21


@dataclass(frozen=True, eq=False)
class HeadingCoverage:
    """Where some heading, and where every heading, of a camera gives a usable fix (a map, before a plan).

    ``P`` grid points of the free space ``F``, ``L`` landmarks. Fractions are of grid points (the
    grid's spacing makes them area fractions to within its resolution); NaN when ``F`` holds none.

    Attributes
    ----------
    points : ndarray, shape (P, 2)
        Grid points in ``F`` (map units), the centres of a square grid's squares over the bounds.
    reachable_count : ndarray of int64, shape (P,)
        Landmarks in range and in line of sight from each point, whatever the heading.
    some : ndarray of bool, shape (P,)
        Some heading of the camera sees a usable pair there (the noise-free ``lsq`` fix of
        :func:`fix_quality` is usable).
    every : ndarray of bool, shape (P,)
        Every heading does (a subset of ``some``).
    fraction_some, fraction_every : float
        Share of the points of ``F`` where ``some`` (``every``) holds.
    landmarks : ndarray, shape (L, 2)
        The landmarks evaluated (map units).
    fov_deg, max_range, min_spread_deg : float
        The camera: field of view (degrees), range (map units; ``inf`` unlimited), ``θ_min`` (degrees).
    spacing : float
        Grid spacing (map units).
    """

    points: np.ndarray
    reachable_count: np.ndarray
    some: np.ndarray
    every: np.ndarray
    fraction_some: float
    fraction_every: float
    landmarks: np.ndarray
    fov_deg: float
    max_range: float
    min_spread_deg: float
    spacing: float

    @property
    def blind(self) -> np.ndarray:
        """Points of ``F`` from which no heading gives a usable fix (blind spots of this camera), shape (n, 2)."""
        return self.points[~self.some]

    @property
    def heading_dependent(self) -> np.ndarray:
        """Points of ``F`` where some heading gives a usable fix and another does not, shape (n, 2)."""
        return self.points[self.some & ~self.every]

    def summary(self) -> str:
        """One line: the camera and the fractions of ``F`` where some heading and where every heading sees a pair."""
        rng = "" if not math.isfinite(self.max_range) else f", range {self.max_range:g}"
        return (f"{plural(len(self.landmarks), 'tag')}, {self.fov_deg:g}° camera{rng}: two usable tags in view from "
                f"{percent(self.fraction_some)} of the free space with some heading and {percent(self.fraction_every)} "
                f"of it with every heading; {len(self.blind)} of {len(self.points)} grid points blind")  # fmt: skip


def _critical_headings(points: np.ndarray, reach: np.ndarray, landmarks: np.ndarray,
                       fov_deg: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Headings that give each point its largest and its smallest views, shapes (n, R) and (n, 2R) (radians).

    The view of heading ``φ`` is the reachable landmarks ``k`` with ``|wrap(θ_k − φ)| ≤ fov/2``
    (``θ_k`` the direction to ``k``); ``R`` is the largest number of reachable landmarks of a point.
    Every view lies in the view of ``φ = θ_k + fov/2`` for one of its landmarks ``k`` (the one at the
    clockwise end of the arc), so those headings give the largest views. The view changes only at
    the events ``θ_k ± fov/2``, is constant between two consecutive ones and at an event holds the
    views on both sides (the arc is closed), so the midpoints between consecutive events give the
    smallest. Rows with fewer reachable landmarks repeat their first heading. Every row needs one.
    """
    d = landmarks[None] - points[:, None]
    theta = np.where(reach, np.arctan2(d[..., 1], d[..., 0]), math.nan)
    half = 0.5 * math.radians(fov_deg)
    count = reach.sum(axis=1)[:, None]
    most = int(count.max())
    largest = np.sort(theta + half, axis=1)[:, :most]  # NaN (not reachable) sorts last
    largest = np.where(np.isnan(largest), largest[:, :1], largest)
    events = np.sort(np.concatenate([theta - half, theta + half], axis=1) % (2 * math.pi), axis=1)[:, : 2 * most]
    j = np.arange(2 * most)[None]
    after = np.take_along_axis(events, np.where(j + 1 < 2 * count, j + 1, 0), axis=1)
    after = after + np.where(j + 1 == 2 * count, 2 * math.pi, 0.0)
    smallest = np.where(j < 2 * count, 0.5 * (events + after), math.nan)
    return largest, np.where(np.isnan(smallest), smallest[:, :1], smallest)


def _views(points: np.ndarray, reach: np.ndarray, landmarks: np.ndarray, headings: np.ndarray, fov_deg: float,
           tol: float) -> np.ndarray:  # fmt: skip
    """What the camera sees from each point at each heading, shape (n, H, L) bool (``headings`` (n, H)).

    :func:`visible_landmarks` at that heading, computed as its field-of-view test on the landmarks
    ``reach`` says are in range and in line of sight (those two tests do not depend on the heading).
    """
    n, h = headings.shape
    x = np.repeat(points, h, axis=0)
    seen = bearing.in_field_of_view(x, headings.reshape(-1), landmarks, math.radians(fov_deg), tol=tol)
    return (seen & np.repeat(reach, h, axis=0)).reshape(n, h, len(landmarks))


def _usable(points: np.ndarray, views: np.ndarray, i: np.ndarray, j: np.ndarray, landmarks: np.ndarray,
            min_spread_deg: float, tol: float) -> np.ndarray:  # fmt: skip
    """:func:`fix_quality`'s ``usable`` of view ``j[m]`` from point ``i[m]``, shape (M,) bool (< 2 tags: False)."""
    ok = np.zeros(len(i), bool)
    two = views[i, j].sum(axis=1) >= 2
    if two.any():
        ok[two] = fix_quality(points[i[two]], views[i[two], j[two]], landmarks, 0.0, min_spread_deg, tol)[0]
    return ok


def _any_all_usable(points: np.ndarray, reach: np.ndarray, landmarks: np.ndarray, fov_deg: float,
                    min_spread_deg: float, tol: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Whether some heading, and whether every heading, gives each point a usable fix, shapes (n,) and (n,).

    Each point's largest view is tried first, the other largest views only where it fails; every
    smallest view only where some heading works and each of them holds two tags. Every row of
    ``reach`` needs two reachable landmarks.
    """
    largest, smallest = _critical_headings(points, reach, landmarks, fov_deg)
    n = len(points)
    big = _views(points, reach, landmarks, largest, fov_deg, tol)
    count = big.sum(axis=2)
    best = np.argmax(count, axis=1)
    some = _usable(points, big, np.arange(n), best, landmarks, min_spread_deg, tol)
    i, j = np.nonzero((~some)[:, None] & (count >= 2) & (np.arange(largest.shape[1])[None] != best[:, None]))
    np.logical_or.at(some, i, _usable(points, big, i, j, landmarks, min_spread_deg, tol))
    small = _views(points, reach, landmarks, smallest, fov_deg, tol)
    every = some & np.all(small.sum(axis=2) >= 2, axis=1)
    i, j = np.nonzero(every[:, None] & np.ones(smallest.shape, bool))
    every[i[~_usable(points, small, i, j, landmarks, min_spread_deg, tol)]] = False
    return some, every


def heading_coverage(map_: Any, fov_deg: float, max_range: float = math.inf, spacing: float | None = None,
                     *, min_spread_deg: float = 2.0) -> HeadingCoverage:  # fmt: skip
    """Where some heading, and every heading, of a camera sees a usable pair of tags: a map before its plan.

    Before a plan there is no field, so the heading of the perception rule (module docstring) is
    free. At each grid point of the free space ``F`` the camera's views are the landmarks in range
    and line of sight (:func:`visible_landmarks`) within ``fov/2`` of a heading; a view is usable
    when :func:`fix_quality` (the runtime's noise-free ``lsq`` fix: two or more tags spread by
    ``θ_min``) says so. Usability only grows with the view, so "some heading" and "every heading"
    are decided exactly on finitely many headings per point, those of the largest and the smallest
    views (one with each landmark at an edge of the arc, and one between each two consecutive edge
    events), not on a sample of headings.

    Parameters
    ----------
    map_ : Map
        The map (``map.json`` or ``map_.run``): bounds, obstacles for line of sight, landmarks.
    fov_deg : float
        Camera field of view (degrees), in ``(0, 360]``; at 360 every heading sees the same.
    max_range : float
        Sensing range (map units, ``> 0``); default unlimited.
    spacing : float, optional
        Grid spacing (map units); default ``D/100`` (``D`` the bounds' diagonal), as
        :func:`perception_coverage`.
    min_spread_deg : float
        ``θ_min`` of ALGORITHMS §6.2 (degrees); default 2°, the runtime's.

    Returns
    -------
    HeadingCoverage

    Raises
    ------
    InvalidParamsError
        ``fov_deg`` outside ``(0, 360]``, or a ``max_range`` or ``spacing`` that is not positive
        (the message names the field).
    """
    check_params(fov_deg, 0.0, max_range, None, min_spread_deg, spacing)
    grid, step = _bounds_grid(map_, spacing)
    space = FreeSpace.from_map(map_)
    points = grid[space.points_free(grid)]
    lm = np.asarray(map_.landmarks, float).reshape(-1, 2)
    tol = map_.tol
    sight = space.visibility_regions(lm) if len(lm) else []
    reach = visible_landmarks(points, np.full(len(points), math.nan), lm, 360.0, max_range, sight, tol)
    count = reach.sum(axis=1).astype(np.int64)
    some = np.zeros(len(points), bool)
    every = np.zeros(len(points), bool)
    rows = np.flatnonzero(count >= 2)  # fewer reachable tags: no heading gives a fix
    if len(rows) and fov_deg >= 360:  # every heading sees every reachable tag
        some[rows] = every[rows] = fix_quality(points[rows], reach[rows], lm, 0.0, min_spread_deg, tol)[0]
    elif len(rows):
        per_point = 3 * int(count.max()) * len(lm)
        for start in range(0, len(rows), max(1, _CHUNK_ENTRIES // per_point)):
            chunk = rows[start : start + max(1, _CHUNK_ENTRIES // per_point)]
            cols = reach[chunk].any(axis=0)  # only the landmarks this chunk reaches
            p, r, sub = points[chunk], reach[chunk][:, cols], lm[cols]
            some[chunk], every[chunk] = _any_all_usable(p, r, sub, fov_deg, min_spread_deg, tol)
    everywhere = np.ones(len(points), bool)
    return HeadingCoverage(points=points, reachable_count=count, some=some, every=every,
                           fraction_some=_share(some, everywhere), fraction_every=_share(every, everywhere),
                           landmarks=lm, fov_deg=float(fov_deg), max_range=float(max_range),
                           min_spread_deg=float(min_spread_deg), spacing=step)  # fmt: skip
