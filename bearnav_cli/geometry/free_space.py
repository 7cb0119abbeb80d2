""":class:`FreeSpace`: every collision, clearance and line-of-sight query, built once from a map (DESIGN §1.6).

Vectorised over numpy arrays with shapely 2. Edge tests are exact (segment against polygon);
touching an obstacle counts as a collision. Spaces are cached by the map's geometry, and each
keeps a few results (visibility regions, the landmark-coverage grid).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import shapely

from bearnav_cli.datatypes import Map
from bearnav_cli.geometry.shapes import inflate, to_shapely

__all__ = [
    "barrier_margin",
    "DEFAULT_CLEARANCE",
    "FreeSpace",
    "GOAL_OPENING",
    "landmark_coverage",
    "MEMO_ENTRIES",
    "SPACE_CACHE",
]


#: Default clearance of tree edges and barrier margin, as a fraction of the bounds' diagonal D.
DEFAULT_CLEARANCE = 0.01
#: The radius, in planning clearances, of the neighbourhood of a goal near a wall in which the tree keeps only half
#: the goal's own clearance (:meth:`FreeSpace.planning_space`). From a goal with clearance ``g`` a path must travel
#: at least ``c − g`` to reach clearance ``c`` (the clearance is 1-Lipschitz), ``(c − g)/sin(α/2)`` out of a
#: corner of angle ``α``; four clearances cover every corner wider than 29°.
GOAL_OPENING = 4.0


def barrier_margin(requested: float | None, diagonal: float) -> float:
    """The barrier margin ``m`` (map units): ``requested``, or ``DEFAULT_CLEARANCE·D`` when ``None``.

    Decomposition keeps every cell this far from the obstacles where it can, and ``F_m`` (the part
    of the free space the funnel cells must cover, ALGORITHMS §11.1) is the free space less it.
    """
    return DEFAULT_CLEARANCE * diagonal if requested is None else float(requested)


#: Free spaces :meth:`FreeSpace.from_map` keeps, least recently used first out.
SPACE_CACHE = 8
#: Results one space keeps (visibility regions of a landmark set, a coverage grid): ``bearnav tags`` asks for
#: the regions of hundreds of candidate tags once, and a long-lived process must not hold every set it saw.
MEMO_ENTRIES = 4
_SPACES: dict[bytes, FreeSpace] = {}


def _space_key(map_: Map) -> bytes:
    """A digest of everything :meth:`FreeSpace.from_map` builds a space from (obstacles, bounds, tolerance)."""
    digest = hashlib.blake2b(digest_size=16)
    for polygons in (map_.obstacles, map_.raw_obstacles):
        digest.update(len(polygons).to_bytes(8, "little"))
        for polygon in polygons:
            for ring in (polygon.exterior, *polygon.holes):
                digest.update(len(ring).to_bytes(8, "little"))
                digest.update(np.ascontiguousarray(ring, float).tobytes())
            digest.update(b"|")
    for values in (map_.free_bounds, map_.bounds, [map_.tol]):
        digest.update(np.asarray(values, float).tobytes())
    return digest.digest()


@dataclass(frozen=True)
class FreeSpace:
    """Free space ``B \\ O`` of a map, with exact vectorised queries.

    Build it with :meth:`from_map`. All inputs are arrays of points in map units;
    all outputs are numpy arrays.

    Attributes
    ----------
    bounds : ndarray, shape (4,)
        ``B_r`` as ``(xmin, ymin, xmax, ymax)``: the map's bounds shrunk by the robot radius, the
        walls every robot query (free points, segments, clearance, starts) uses (map units).
    tol : float
        The map's geometric tolerance ``1e-9·D`` (map units).
    obstacles : shapely geometry
        Union of the inflated obstacles ``O`` (prepared), or ``O`` grown further by
        :meth:`with_clearance`.
    raw_obstacles : shapely geometry
        Union of the obstacles as drawn, before inflation (prepared): what blocks line of sight.
    sight_bounds : ndarray, shape (4,)
        The map's own bounds ``B`` (map units), where landmarks live and sight lines run.
    """

    bounds: np.ndarray
    tol: float
    obstacles: shapely.Geometry
    raw_obstacles: shapely.Geometry
    sight_bounds: np.ndarray

    @classmethod
    def from_map(cls, map_: Map) -> FreeSpace:
        """Prepare the union of the map's inflated and raw obstacles.

        ``bounds`` is ``B_r``, the map's bounds shrunk by the robot radius (the bounds are walls,
        ALGORITHMS §11.1): every robot query (free points, segments, clearance, starts) uses it.
        ``sight_bounds`` keeps the map's own ``B``, where landmarks live and sight lines run.

        One space per free space: the stages of a plan, which pass the map on or read it back from
        the previous artifact, share its unions, visibility regions and coverage grid (the last
        :data:`SPACE_CACHE` free spaces are kept, by the content of what they are built from).
        """
        key = _space_key(map_)
        space = _SPACES.pop(key, None)
        if space is None:
            space = cls._build(map_)
            while len(_SPACES) >= SPACE_CACHE:
                _SPACES.pop(next(iter(_SPACES)))
        _SPACES[key] = space  # the most recent last
        return space

    @classmethod
    def _build(cls, map_: Map) -> FreeSpace:
        obstacles = shapely.union_all([to_shapely(p) for p in map_.obstacles])
        raw = shapely.union_all([to_shapely(p) for p in map_.raw_obstacles])
        shapely.prepare(obstacles)
        shapely.prepare(raw)
        return cls(map_.free_bounds, map_.tol, obstacles, raw, np.asarray(map_.bounds, float))

    def with_clearance(self, clearance: float) -> FreeSpace:
        """The space a planner keeps ``clearance`` away from: ``O`` grown by it, and a band of that width along ``∂B``.

        Segment tests against the result accept exactly the segments at distance at least
        ``clearance`` (up to the polygonal buffer, which is rounded outward) from ``O`` and
        from the walls. Line of sight (raw obstacles) is unchanged.

        Parameters
        ----------
        clearance : float
            Map units; ``0`` returns ``self``.
        """
        if clearance <= 0:
            return self
        # the band covers B \ B_r too, so a segment leaving B_r meets it even when the caller
        # skips the box test (samples are drawn in B)
        inner = shapely.buffer(shapely.box(*self.bounds), -clearance, join_style="mitre")
        band = shapely.difference(shapely.box(*self.sight_bounds), inner)
        grown = shapely.union(inflate(self.obstacles, clearance), band)
        shapely.prepare(grown)
        return FreeSpace(self.bounds, self.tol, grown, self.raw_obstacles, self.sight_bounds)

    def wall_clearance(self, point: np.ndarray) -> float:
        """Distance from a point to ``O`` and to the walls ``∂B`` (map units)."""
        return float(self.clearance(np.asarray(point, float).reshape(1, 2))[0])

    def planning_space(self, requested: float | None, goal: np.ndarray, diagonal: float) -> FreeSpace:
        """The space a planner keeps its edges in: clear by ``requested`` (``None``: ``DEFAULT_CLEARANCE·D``),
        except near a goal that is itself nearer ``O`` or the walls than twice that.

        There, within :data:`GOAL_OPENING` clearances of the goal, the edges keep half the goal's own
        clearance instead, so that the root can connect. Only that neighbourhood is relaxed: a goal
        in a corner no longer lowers the clearance of the whole tree (which set every node near a
        wall, and so every cell's exit inset and tolerance, by the goal's corner: the paper maps'
        goals lie 1 unit from two walls).

        Parameters
        ----------
        requested : float or None
            The clearance asked for (map units; ``None``: :func:`barrier_margin`'s default).
        goal : ndarray, shape (2,)
            The tree's root (map units).
        diagonal : float
            ``D``, the diagonal of the map's bounds (map units).

        Returns
        -------
        FreeSpace
            :meth:`with_clearance` of the clearance, with the goal's opening carved out of it.
        """
        clearance = max(0.0, barrier_margin(requested, diagonal))
        grown = self.with_clearance(clearance)
        near = 0.5 * self.wall_clearance(goal)
        if near >= clearance:
            return grown
        disc = shapely.buffer(shapely.Point(np.asarray(goal, float)), GOAL_OPENING * clearance, quad_segs=32)
        opening = shapely.difference(disc, self.with_clearance(near).obstacles)
        obstacles = shapely.difference(grown.obstacles, opening)
        shapely.prepare(obstacles)
        return FreeSpace(self.bounds, self.tol, obstacles, self.raw_obstacles, self.sight_bounds)

    @cached_property
    def _no_obstacles(self) -> bool:
        """Whether ``O`` is empty (asked by every segment test, so RRT* once per iteration)."""
        return bool(self.obstacles.is_empty)

    @cached_property
    def box(self) -> shapely.Polygon:
        """The robot's bounds ``B_r`` (:attr:`bounds`) as a polygon."""
        return shapely.box(*self.bounds)

    @cached_property
    def free_area(self) -> float:
        """``A_free = area(B) − area(O ∩ B)`` (map units²)."""
        return float(self.box.area - shapely.intersection(self.obstacles, self.box).area)

    @cached_property
    def free_region(self) -> shapely.Geometry:
        """``B \\ O`` as a shapely geometry (possibly several components)."""
        return shapely.difference(self.box, self.obstacles)

    @cached_property
    def _box_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper limits of ``B`` repeated for a segment's two endpoints, shape (4,)."""
        return np.tile(self.bounds[:2], 2), np.tile(self.bounds[2:], 2)

    def in_bounds(self, points: np.ndarray) -> np.ndarray:
        """Whether each point lies in the closed box ``B_r`` (the bounds less the robot radius); shape (n,) bool."""
        p = np.asarray(points, float).reshape(-1, 2)
        return ((p >= self.bounds[:2]) & (p <= self.bounds[2:])).all(axis=1)

    def in_obstacle(self, points: np.ndarray) -> np.ndarray:
        """Whether each point lies in the closed obstacle set ``O``; shape (n,) bool."""
        p = np.asarray(points, float).reshape(-1, 2)
        if self.obstacles.is_empty:
            return np.zeros(len(p), bool)
        return shapely.intersects_xy(self.obstacles, p[:, 0], p[:, 1])

    def points_free(self, points: np.ndarray) -> np.ndarray:
        """Free points: in ``B`` and not in ``O`` (ALGORITHMS §1); shape (n,) bool."""
        p = np.asarray(points, float).reshape(-1, 2)
        free = self.in_bounds(p)
        if free.any():
            free[free] = ~self.in_obstacle(p[free])
        return free

    def points_strictly_free(self, points: np.ndarray) -> np.ndarray:
        """Free points in the interior of ``B`` at positive distance from ``O``."""
        p = np.asarray(points, float).reshape(-1, 2)
        xmin, ymin, xmax, ymax = self.bounds
        inside = (p[:, 0] > xmin) & (p[:, 0] < xmax) & (p[:, 1] > ymin) & (p[:, 1] < ymax)
        return inside & ~self.in_obstacle(p)

    def segments_free(self, starts: np.ndarray, ends: np.ndarray, *, known_in_box: bool = False) -> np.ndarray:
        """Exact segment test: each segment lies in ``B`` and does not touch ``O``.

        Parameters
        ----------
        starts, ends : ndarray, shape (n, 2)
            Segment endpoints (either may be a single point, broadcast against the other).
        known_in_box : bool
            The caller guarantees every endpoint lies in ``B`` (samples drawn in ``B``):
            skip that check.

        Returns
        -------
        ndarray of bool, shape (n,)
        """
        a = np.asarray(starts, float).reshape(-1, 2)
        b = np.asarray(ends, float).reshape(-1, 2)
        coords = np.empty((max(len(a), len(b)), 2, 2))
        coords[:, 0] = a
        coords[:, 1] = b
        if known_in_box:
            free = np.ones(len(coords), bool)
        else:
            lo, hi = self._box_limits
            # B is convex, so both endpoints in B put the whole segment in B
            flat = coords.reshape(-1, 4)
            free = ((flat >= lo) & (flat <= hi)).all(axis=1)
        if self._no_obstacles:
            return free
        if free.all():
            return ~shapely.intersects(self.obstacles, shapely.linestrings(coords))
        if free.any():
            free[free] = ~shapely.intersects(self.obstacles, shapely.linestrings(coords[free]))
        return free

    def segment_free(self, ax: float, ay: float, bx: float, by: float) -> bool:
        """:meth:`segments_free` of one segment whose ends lie in ``B`` (``known_in_box``), from four floats.

        The same exact test, without the array handling: RRT* asks it once per iteration.
        """
        if self._no_obstacles:
            return True
        return not shapely.intersects(self.obstacles, shapely.linestrings([[(ax, ay), (bx, by)]]))[0]

    def visible(self, points: np.ndarray, targets: np.ndarray, *, from_boundary: bool = False) -> np.ndarray:
        """Line of sight from points to landmarks through the raw obstacles.

        The segment from ``p`` to ``l' = l − tol·unit(l − p)`` must not meet ``P_raw``,
        so a landmark on a wall is visible (ALGORITHMS §1).

        Parameters
        ----------
        points : ndarray, shape (n, 2)
        targets : ndarray, shape (n, 2)
            Paired with ``points`` row by row (broadcast one side to test many).
        from_boundary : bool
            Also shorten the segment by ``tol`` at ``p``. Vertices of a cell's free part
            may lie on an obstacle's boundary (on ``P_raw`` itself when the robot radius
            is 0); seen from just off the wall they see what the wall does not hide.

        Returns
        -------
        ndarray of bool, shape (n,)
        """
        p, t = np.broadcast_arrays(np.asarray(points, float), np.asarray(targets, float))
        p = p.reshape(-1, 2)
        t = t.reshape(-1, 2)
        delta = t - p
        length = np.hypot(delta[:, 0], delta[:, 1])
        ok = length > self.tol
        result = np.zeros(len(p), bool)
        if not ok.any():
            return result
        step = self.tol * delta[ok] / length[ok, None]
        shortened = t[ok] - step
        start = p[ok] + step if from_boundary else p[ok]
        if self.raw_obstacles.is_empty:
            result[ok] = True
            return result
        lines = shapely.linestrings(np.stack([start, shortened], axis=1))
        result[ok] = ~shapely.intersects(self.raw_obstacles, lines)
        return result

    @cached_property
    def _memo(self) -> dict:
        """Results of :meth:`visibility_regions` and :func:`landmark_coverage` for this space, by their inputs."""
        return {}

    def _remember(self, key: tuple, value: object) -> None:
        """Keep ``value`` under ``key`` in :attr:`_memo`, with at most :data:`MEMO_ENTRIES` entries (oldest out)."""
        while len(self._memo) >= MEMO_ENTRIES:
            self._memo.pop(next(iter(self._memo)))
        self._memo[key] = value

    def visibility_regions(self, landmarks: np.ndarray) -> list[shapely.Geometry]:
        """For each landmark, the part of ``B`` from which it is in line of sight (prepared polygons).

        The shadow of a raw obstacle seen from ``l`` is the union, over its boundary edges
        ``(a, b)``, of the quadrilaterals ``a, b, b + F·u_b, a + F·u_a`` (``u_a``, ``u_b`` the unit
        vectors from ``l`` to ``a`` and ``b``, ``F`` beyond the bounds), with a fifth corner
        ``l + F·unit(u_a + u_b)`` for an edge that spans more than 120° from ``l`` (its straight far
        side would stop short of the bounds), plus the obstacle; the region is ``B`` minus every
        shadow. A point test against it is :meth:`visible` with the same tolerance for a tag on a
        wall (edges through the landmark cast no shadow), except on shadow boundaries, a set of
        measure zero; it costs one prepared point query instead of a segment test per step.

        Parameters
        ----------
        landmarks : ndarray, shape (L, 2)

        Returns
        -------
        list of shapely.Geometry, length L
        """
        landmarks = np.asarray(landmarks, float).reshape(-1, 2)
        key = ("sight", landmarks.tobytes())
        if key not in self._memo:
            self._remember(key, self._visibility_regions(landmarks))
        return list(self._memo[key])

    def _visibility_regions(self, landmarks: np.ndarray) -> list[shapely.Geometry]:
        outer = self.sight_bounds
        box = shapely.box(*outer)
        far = 4.0 * float(np.hypot(*(outer[2:] - outer[:2])))
        rings = []
        for part in shapely.get_parts(self.raw_obstacles):
            part = shapely.orient_polygons(part)  # exterior CCW, holes CW: the obstacle is on every edge's left
            for ring in (part.exterior, *part.interiors):
                xy = np.asarray(ring.coords)
                rings.append(np.stack([xy[:-1], xy[1:]], axis=1))
        edges = np.concatenate(rings) if rings else np.zeros((0, 2, 2))
        regions = []
        for lm in np.asarray(landmarks, float).reshape(-1, 2):
            if not len(edges):
                regions.append(box)
                continue
            da, db = edges[:, 0] - lm, edges[:, 1] - lm
            na, nb = np.hypot(*da.T), np.hypot(*db.T)
            # a segment from the tag that meets an obstacle leaves it last through an edge whose obstacle side
            # faces the tag: those edges' shadows and the obstacle make the whole shadow (half the pieces)
            back = da[:, 0] * db[:, 1] - da[:, 1] * db[:, 0] > 0.0  # the tag on the edge's left: (a−l)×(b−l) > 0
            keep = (na > self.tol) & (nb > self.tol) & back  # an edge ending at the tag casts no shadow
            a, b = edges[keep, 0], edges[keep, 1]
            ua, ub = da[keep] / na[keep, None], db[keep] / nb[keep, None]
            quads = np.stack([a, b, b + far * ub, a + far * ua], axis=1)
            # the far side a + F·u_a → b + F·u_b passes F·cos(θ/2) from the tag, θ the angle the edge spans:
            # short of the bounds for a long face close to the tag (the back of a thin wall, θ near 180°).
            # Such an edge's far side bends at the bisector instead (each half within 45° of it); the
            # others keep four corners, half the union's work
            e = b - a
            off_line = np.abs(e[:, 0] * da[keep, 1] - e[:, 1] * da[keep, 0]) > self.tol * np.hypot(*e.T)
            bisector = ua + ub
            norm = np.hypot(*bisector.T)
            bend = off_line & (norm < 1.0)  # cos(θ/2) = |u_a + u_b|/2 < 1/2; an edge through the tag stays flat
            mid = lm + far * bisector[bend] / norm[bend, None]
            wide = np.stack([a[bend], b[bend], quads[bend, 2], mid, quads[bend, 3]], axis=1)
            pieces = np.concatenate([shapely.polygons(quads[~bend]), shapely.polygons(wide), [self.raw_obstacles]])
            shadow = shapely.union_all(pieces)
            region = shapely.difference(box, shadow)
            shapely.prepare(region)
            regions.append(region)
        return regions

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """Distance from each point to ``O`` and to the walls ``∂B_r`` (0 inside ``O``), shape (n,)."""
        p = np.asarray(points, float).reshape(-1, 2)
        xmin, ymin, xmax, ymax = self.bounds
        walls = np.min(np.column_stack([p[:, 0] - xmin, xmax - p[:, 0], p[:, 1] - ymin, ymax - p[:, 1]]), axis=1)
        if self.obstacles.is_empty:
            return walls
        return np.minimum(walls, shapely.distance(self.obstacles, shapely.points(p)))

    def component_of(self, point: np.ndarray) -> shapely.Geometry:
        """The connected component of ``B \\ O`` that contains ``point`` (empty if none)."""
        target = shapely.Point(point)
        for part in shapely.get_parts(self.free_region):
            if part.intersects(target):
                return part
        return shapely.Polygon()


def landmark_coverage(map_: Map, space: FreeSpace, cells: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Count the landmarks in line of sight from a grid over the free space (ALGORITHMS §1).

    Parameters
    ----------
    map_ : Map
        The map: its landmarks, and its diagonal ``D`` for the grid spacing.
    space : FreeSpace
        Built from ``map_``.
    cells : int
        Grid spacing ``D / cells`` (D the bounds' diagonal); points at cell centres. The space
        keeps the result, and the landmarks' visibility regions it counts with.

    Returns
    -------
    points : ndarray, shape (P, 2)
        Free grid points.
    counts : ndarray of int, shape (P,)
        Landmarks in line of sight from each point.
    """
    key = ("coverage", cells, np.asarray(map_.landmarks, float).tobytes(), np.asarray(map_.bounds, float).tobytes())
    if key not in space._memo:
        space._remember(key, _landmark_coverage(map_, space, cells))
    points, counts = space._memo[key]
    return points.copy(), counts.copy()


def _landmark_coverage(map_: Map, space: FreeSpace, cells: int) -> tuple[np.ndarray, np.ndarray]:
    xmin, ymin, xmax, ymax = map_.bounds
    spacing = map_.diagonal / cells
    xs = np.arange(xmin + spacing / 2, xmax, spacing)
    ys = np.arange(ymin + spacing / 2, ymax, spacing)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    points = grid[space.points_free(grid)]
    # one prepared point query per landmark (the segment test's answers away from shadow
    # boundaries, a null set): half the time of a segment per point and landmark
    counts = np.zeros(len(points), np.int64)
    for region in space.visibility_regions(map_.landmarks):
        counts += shapely.intersects_xy(region, points[:, 0], points[:, 1])
    return points, counts
