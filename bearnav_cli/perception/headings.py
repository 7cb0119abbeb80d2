"""Before a plan there is no field and the heading is free: where some heading, and where every heading, of a
camera gives a usable fix over the free space (:func:`heading_coverage`, ``bearnav map --fov``)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from bearnav_cli.datatypes import percent, plural
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.perception.grid import bounds_grid, check_params
from bearnav_cli.perception.rule import fix_quality, share, visible_landmarks
from bearnav_cli.runtime import bearing

__all__ = ["heading_coverage", "HeadingCoverage"]


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
        return (
            f"{plural(len(self.landmarks), 'tag')}, {self.fov_deg:g}° camera{rng}: two usable tags in view from "
            f"{percent(self.fraction_some)} of the free space with some heading and {percent(self.fraction_every)} "
            f"of it with every heading; {len(self.blind)} of {len(self.points)} grid points blind"
        )


def _critical_headings(
    points: np.ndarray, reach: np.ndarray, landmarks: np.ndarray, fov_deg: float
) -> tuple[np.ndarray, np.ndarray]:
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


def _views(
    points: np.ndarray, reach: np.ndarray, landmarks: np.ndarray, headings: np.ndarray, fov_deg: float, tol: float
) -> np.ndarray:
    """What the camera sees from each point at each heading, shape (n, H, L) bool (``headings`` (n, H)).

    :func:`visible_landmarks` at that heading, computed as its field-of-view test on the landmarks
    ``reach`` says are in range and in line of sight (those two tests do not depend on the heading).
    """
    n, h = headings.shape
    x = np.repeat(points, h, axis=0)
    seen = bearing.in_field_of_view(x, headings.reshape(-1), landmarks, math.radians(fov_deg), tol=tol)
    return (seen & np.repeat(reach, h, axis=0)).reshape(n, h, len(landmarks))


def _usable(
    points: np.ndarray,
    views: np.ndarray,
    i: np.ndarray,
    j: np.ndarray,
    landmarks: np.ndarray,
    min_spread_deg: float,
    tol: float,
) -> np.ndarray:
    """:func:`fix_quality`'s ``usable`` of view ``j[m]`` from point ``i[m]``, shape (M,) bool (< 2 tags: False)."""
    ok = np.zeros(len(i), bool)
    two = views[i, j].sum(axis=1) >= 2
    if two.any():
        ok[two] = fix_quality(points[i[two]], views[i[two], j[two]], landmarks, 0.0, min_spread_deg, tol)[0]
    return ok


def _any_all_usable(
    points: np.ndarray, reach: np.ndarray, landmarks: np.ndarray, fov_deg: float, min_spread_deg: float, tol: float
) -> tuple[np.ndarray, np.ndarray]:
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


def heading_coverage(
    map_: Any, fov_deg: float, max_range: float = math.inf, spacing: float | None = None, *, min_spread_deg: float = 2.0
) -> HeadingCoverage:
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
    grid, step = bounds_grid(map_, spacing)
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
    return HeadingCoverage(
        points=points,
        reachable_count=count,
        some=some,
        every=every,
        fraction_some=share(some, everywhere),
        fraction_every=share(every, everywhere),
        landmarks=lm,
        fov_deg=float(fov_deg),
        max_range=float(max_range),
        min_spread_deg=float(min_spread_deg),
        spacing=step,
    )
