"""The perception rule on a plan (steps 2 to 4 of :mod:`bearnav_cli.perception`): tags in view, a usable fix, its
predicted error, and where the rule holds in ``D`` and ``F`` (:class:`PerceptionCoverage`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from bearnav_cli.datatypes import percent, plural
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.perception.grid import EvaluationGrid, check_params, evaluation_grid
from bearnav_cli.runtime import bearing

__all__ = ["evaluate", "fix_quality", "perception_coverage", "PerceptionCoverage", "share", "visible_landmarks"]


def visible_landmarks(
    points: Any, heading: Any, landmarks: Any, fov_deg: float, max_range: float, sight: list, tol: float
) -> np.ndarray:
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


def fix_quality(
    points: Any, visible: Any, landmarks: Any, noise_deg: float, min_spread_deg: float, tol: float
) -> tuple[np.ndarray, np.ndarray]:
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
        return (
            f"{plural(len(self.landmarks), 'tag')}, {self.fov_deg:g}° camera{rng}, {self.noise_deg:g}° noise"
            f"{target}: two usable tags in view from {percent(self.fraction_domain)} of the certified area and "
            f"{percent(self.fraction_free)} of the free space; "
            f"one fix's median predicted error {self.median_error_domain:.3g} in the certified area, below the "
            f"plan's least position tolerance {self.plan_tolerance:.3g} on "
            f"{percent(self.fraction_within_tolerance)} of it "
            "(a run does not rest on one fix: it fuses fixes with odometry, which `bearnav simulate` measures "
            "and nothing here proves)"
        )


def share(mask: np.ndarray, where: np.ndarray) -> float:
    """The share of the points ``where`` at which ``mask`` holds (NaN when there are none)."""
    n = int(where.sum())
    return float(np.sum(mask & where)) / n if n else math.nan


def evaluate(
    grid: EvaluationGrid,
    landmarks: Any,
    landmark_ids: Any = None,
    *,
    fov_deg: float,
    noise_deg: float,
    max_range: float = math.inf,
    error_target: float | None = None,
    min_spread_deg: float = 2.0,
    sight: list | None = None,
) -> PerceptionCoverage:
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
        points=grid.points,
        heading=grid.heading,
        in_domain=grid.in_domain,
        in_free=grid.in_free,
        visible=visible,
        visible_count=visible.sum(axis=1).astype(np.int64),
        usable=usable,
        predicted_error=error,
        holds=holds,
        fraction_domain=share(holds, grid.in_domain),
        fraction_free=share(holds, grid.in_free),
        plan_tolerance=delta,
        fraction_within_tolerance=share(within, grid.in_domain),
        landmarks=lm,
        landmark_ids=ids,
        fov_deg=float(fov_deg),
        noise_deg=float(noise_deg),
        max_range=float(max_range),
        min_spread_deg=float(min_spread_deg),
        error_target=None if error_target is None else float(error_target),
        spacing=grid.spacing,
    )


def perception_coverage(
    plan: Any,
    fov_deg: float,
    noise_deg: float,
    max_range: float = math.inf,
    error_target: float | None = None,
    spacing: float | None = None,
    landmarks: Any = None,
    *,
    landmark_ids: Any = None,
    min_spread_deg: float = 2.0,
) -> PerceptionCoverage:
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
    return evaluate(
        grid,
        landmarks,
        landmark_ids,
        fov_deg=fov_deg,
        noise_deg=noise_deg,
        max_range=max_range,
        error_target=error_target,
        min_spread_deg=min_spread_deg,
    )
