"""Stage ``map``: validate a map description and normalise it (ALGORITHMS §1, DESIGN §4).

Input is a :class:`MapSource` (the parsed YAML plus any occupancy grid bytes,
read by the CLI); output is a :class:`~bearnav_cli.datatypes.Map` with circles
and rectangles turned into polygons, occupancy grids vectorised and obstacles
inflated by the robot radius. Every problem raises
:class:`~bearnav_cli.errors.InvalidMapError` naming the file and the field.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely

from bearnav_cli import occupancy
from bearnav_cli.datatypes import NEGLIGIBLE_SHARE, Map, plural, replace
from bearnav_cli.errors import InvalidMapError
from bearnav_cli.geometry import (
    FreeSpace,
    box_polygon,
    circle_polygon,
    from_shapely,
    inflate,
    landmark_coverage,
    to_shapely,
)
from bearnav_cli.params.map_ import Params
from bearnav_cli.runtime.plan_arrays import ring_edges
from bearnav_cli.runtime.robot import ROBOT_DEFAULTS, ROBOT_KEYS

__all__ = [
    "GridSource",
    "MAP_KEYS",
    "MapSource",
    "VERSION",
    "infer_facing",
    "listed_obstacles",
    "run",
    "spec_of",
    "summary",
]

VERSION = 2  # 2: landmarks have a facing
log = logging.getLogger(__name__)

#: Top-level keys of a bearnav map YAML.
MAP_KEYS = (
    "name",
    "description",
    "bounds",
    "robot_radius",
    "goal",
    "starts",
    "obstacles",
    "landmarks",
    "occupancy",
    "params",
    "robot",
)


@dataclass(frozen=True)
class GridSource:
    """An occupancy grid as read from disk: the map_server YAML and the image bytes.

    Attributes
    ----------
    meta : dict
        The parsed map_server YAML (``image``, ``resolution``, ``origin``, ``negate``,
        ``occupied_thresh``, ``free_thresh``, ``mode``), checked by
        :func:`bearnav_cli.occupancy.grid_obstacles`.
    image : bytes
        The content of the image file (PGM or PNG).
    file : str
        The YAML file's name, for error messages.
    image_name : str
        The image file's resolved path, for error messages.
    """

    meta: dict
    image: bytes
    file: str
    image_name: str


@dataclass(frozen=True)
class MapSource:
    """A map description as read by the CLI.

    Attributes
    ----------
    spec : dict
        The parsed bearnav map YAML (or one assembled from CLI options for a bare grid).
    file : str
        Name of the file, for error messages.
    sha256 : str
        Hash of every byte read (map, grid YAML, image): the map stage's input hash.
    grid : GridSource, optional
        The occupancy grid referenced by ``occupancy:``.
    extra : dict
        Free-form data a caller attaches to the source; the map stage does not read it (empty by
        default).
    """

    spec: dict
    file: str
    sha256: str
    grid: GridSource | None = None
    extra: dict = field(default_factory=dict)


class _Reader:
    """Typed field access with errors that name the file and the field path."""

    def __init__(self, file: str):
        self.file = file

    def fail(self, field: str, message: str) -> InvalidMapError:
        return InvalidMapError(message, file=self.file, field=field)

    def number(self, value: Any, field: str) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(field, f"expected a number, got {_describe(value)}")
        if not math.isfinite(value):
            raise self.fail(field, "must be finite")
        return float(value)

    def point(self, value: Any, field: str) -> np.ndarray:
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            raise self.fail(field, f"expected [x, y], got {_describe(value)}")
        return np.array([self.number(v, f"{field}[{k}]") for k, v in enumerate(value)])

    def points(self, value: Any, field: str, minimum: int = 0) -> np.ndarray:
        if not isinstance(value, (list, tuple)):
            raise self.fail(field, f"expected a list of [x, y] points, got {_describe(value)}")
        if len(value) < minimum:
            raise self.fail(field, f"needs at least {minimum} points, got {len(value)}")
        pts = [self.point(v, f"{field}[{k}]") for k, v in enumerate(value)]
        return np.array(pts, float).reshape(-1, 2)

    def mapping(self, value: Any, field: str, allowed: tuple[str, ...]) -> dict:
        if not isinstance(value, dict):
            raise self.fail(field, f"expected a mapping, got {_describe(value)}")
        for key in value:
            if key not in allowed:
                prefix = f"{field}." if field else ""
                raise self.fail(f"{prefix}{key}", f"unknown key (expected one of: {', '.join(allowed)})")
        return value


def _describe(value: Any) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text[:40]}"


def _obstacle(reader: _Reader, item: Any, field: str, segments: int) -> shapely.Polygon:
    """One entry of ``obstacles:`` as a shapely polygon (raw, not inflated)."""
    entry = reader.mapping(item, field, ("polygon", "rectangle", "circle"))
    if len(entry) != 1:
        raise reader.fail(field, "give exactly one of polygon, rectangle, circle")
    kind, value = next(iter(entry.items()))
    where = f"{field}.{kind}"
    if kind == "polygon":
        pts = reader.points(value, where, minimum=3)
        poly = shapely.Polygon(pts)
        if not poly.is_valid:
            raise reader.fail(where, f"polygon is not simple ({shapely.is_valid_reason(poly)})")
        if poly.area <= 0:
            raise reader.fail(where, "polygon has zero area")
        return shapely.orient_polygons(poly)
    if kind == "rectangle":
        if not isinstance(value, (list, tuple)) or len(value) != 4:
            raise reader.fail(where, f"expected [xmin, ymin, xmax, ymax], got {_describe(value)}")
        x0, y0, x1, y1 = (reader.number(v, f"{where}[{k}]") for k, v in enumerate(value))
        if not (x0 < x1 and y0 < y1):
            raise reader.fail(where, "needs xmin < xmax and ymin < ymax")
        return shapely.box(x0, y0, x1, y1)
    circle = reader.mapping(value, where, ("center", "radius"))
    if "center" not in circle or "radius" not in circle:
        raise reader.fail(where, "needs center and radius")
    center = reader.point(circle["center"], f"{where}.center")
    radius = reader.number(circle["radius"], f"{where}.radius")
    if radius <= 0:
        raise reader.fail(f"{where}.radius", "must be positive")
    return shapely.Polygon(circle_polygon(tuple(center), radius, segments))


def _landmarks(reader: _Reader, value: Any) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Ids, positions and facings (radians; NaN: explicitly free-standing; None: infer from the walls)."""
    if not isinstance(value, list):
        raise reader.fail("landmarks", f"expected a list, got {_describe(value)}")
    ids, positions, facing = [], [], []
    for k, item in enumerate(value):
        where = f"landmarks[{k}]"
        if isinstance(item, dict):
            entry = reader.mapping(item, where, ("id", "position", "facing"))
            if "position" not in entry:
                raise reader.fail(where, "needs a position")
            positions.append(reader.point(entry["position"], f"{where}.position"))
            if "facing" not in entry:
                facing.append(None)
            elif entry["facing"] is None:
                facing.append(math.nan)
            else:
                facing.append(math.radians(reader.number(entry["facing"], f"{where}.facing")))
            raw_id = entry.get("id", k)
            if not isinstance(raw_id, (str, int)) or isinstance(raw_id, bool):
                raise reader.fail(f"{where}.id", f"expected a string or integer, got {_describe(raw_id)}")
            ids.append(str(raw_id))
        else:
            positions.append(reader.point(item, where))
            ids.append(str(k))
            facing.append(None)
    for k, name in enumerate(ids):
        if name in ids[:k]:
            raise reader.fail(f"landmarks[{k}].id", f"duplicate id {name!r}")
    return tuple(ids), np.array(positions, float).reshape(-1, 2), np.array(facing, object)


def infer_facing(points: np.ndarray, bounds: np.ndarray, raw: shapely.Geometry, tol: float) -> np.ndarray:
    """The facing of tags on walls: the direction into free space (rad in ``[0, 2π)``; NaN elsewhere).

    A point within ``tol`` of edges of the raw obstacles' rings or of the bounds lies on a wall. The
    edges through it split the directions around it into sectors; the free one (inside the bounds,
    outside every raw obstacle) is the side the printed face looks toward, and the facing is its
    middle: on a straight wall the outward normal, at a corner the bisector of the two edges'
    normals (at a convex corner the free sector spans 270°, at a concave one 90°). When several
    sectors are free (two obstacles touching at the point) the widest wins. A point on no edge, or
    with no free sector, gets NaN: a free-standing tag, seen from every side.

    Parameters
    ----------
    points : ndarray, shape (L, 2)
        Tag positions (map units).
    bounds : ndarray, shape (4,)
        The map's bounds ``(xmin, ymin, xmax, ymax)`` (map units): their edges are walls too.
    raw : shapely geometry
        The raw (not inflated) obstacles.
    tol : float
        How far from an edge a point still lies on it (map units; the map's ``tol``).

    Returns
    -------
    ndarray, shape (L,)
        Facing of each point (rad), NaN for a free-standing tag.
    """
    xmin, ymin, xmax, ymax = (float(v) for v in bounds)
    rings = [(box_polygon(np.asarray(bounds, float)),)]
    for poly in shapely.get_parts(raw) if not raw.is_empty else ():
        rings.append((np.asarray(poly.exterior.coords)[:-1], *(np.asarray(h.coords)[:-1] for h in poly.interiors)))
    edges = ring_edges(rings)
    a, b = edges[:, 0], edges[:, 1]
    d = b - a
    length = np.hypot(d[:, 0], d[:, 1])
    a, b, d, length = a[length > 0], b[length > 0], d[length > 0], length[length > 0]
    unit = d / length[:, None]
    radius = 1e3 * tol  # the free-side probes: far beyond the tolerance, far below any feature size
    out = np.full(len(points), np.nan)
    for k, p in enumerate(np.asarray(points, float).reshape(-1, 2)):
        t = np.clip(((p - a) * unit).sum(axis=1), 0.0, length)
        near = np.hypot(*(a + t[:, None] * unit - p).T) <= tol
        if not near.any():
            continue
        at_a = np.hypot(*(p - a[near]).T) <= tol
        at_b = np.hypot(*(p - b[near]).T) <= tol
        rays = np.concatenate([unit[near][~at_b], -unit[near][~at_a]])  # along each edge, away from p
        angles = np.unique(np.round(np.mod(np.arctan2(rays[:, 1], rays[:, 0]), 2 * math.pi), 12))
        if len(angles) < 2:
            continue
        width = np.diff(np.append(angles, angles[0] + 2 * math.pi))
        middle = angles + width / 2
        probe = p + radius * np.column_stack([np.cos(middle), np.sin(middle)])
        free = (probe[:, 0] > xmin) & (probe[:, 0] < xmax) & (probe[:, 1] > ymin) & (probe[:, 1] < ymax)
        if not raw.is_empty:
            free &= ~shapely.intersects_xy(raw, probe[:, 0], probe[:, 1])
        if free.any():
            best = np.flatnonzero(free)[np.argmax(width[free])]
            out[k] = math.fmod(middle[best], 2 * math.pi)
    return out


def _facing(
    reader: _Reader, given: np.ndarray, landmarks: np.ndarray, bounds: np.ndarray, raw: shapely.Geometry, tol: float
) -> np.ndarray:
    """Each landmark's facing: the one given, else the one its wall implies (:func:`infer_facing`)."""
    inferred = infer_facing(landmarks, bounds, raw, tol)
    facing = np.array([inferred[k] if f is None else f for k, f in enumerate(given)], float)
    for k in np.flatnonzero([f is not None for f in given]):
        f = facing[k]
        if math.isfinite(f) and math.isfinite(inferred[k]) and math.cos(f - inferred[k]) < 0:
            log.warning(
                "%s: landmarks[%d].facing %.4g° points into the wall it is on (its free side faces "
                "%.4g°): the tag cannot be seen",
                reader.file,
                k,
                math.degrees(f) % 360,
                math.degrees(inferred[k]),
            )
    return facing


def run(source: MapSource, params: Params = Params(), progress: object = None) -> Map:
    """Validate and normalise a map description.

    Parameters
    ----------
    source : MapSource
        The parsed description.
    params : Params
        Stage parameters.
    progress : callable, optional
        Accepted for the common stage signature; the map stage is quick and does not report.

    Returns
    -------
    Map
        The normalised map (obstacles inflated, polygons only).

    Raises
    ------
    InvalidMapError
        On any malformed or inconsistent field (the message names file and field).
    """
    reader = _Reader(source.file)
    spec = reader.mapping(source.spec, "", MAP_KEYS)
    if params.unknown not in ("obstacle", "free"):
        raise reader.fail("params.map.unknown", "must be 'obstacle' or 'free'")
    if params.circle_segments < 8:
        raise reader.fail("params.map.circle_segments", "must be at least 8")

    name = spec.get("name", "map")
    if not isinstance(name, str) or not name or any(c in name for c in "/\\:") or name.startswith("."):
        raise reader.fail("name", "must be a non-empty name without path separators")

    raw_parts: list[shapely.Geometry] = []
    grid_extent = None
    if source.grid is not None:
        grid = source.grid
        polys, info = occupancy.grid_obstacles(
            grid.meta, grid.image, file=grid.file, image_name=grid.image_name, unknown=params.unknown
        )
        raw_parts.extend(polys)
        grid_extent = info["extent"]
    elif "occupancy" in spec:
        raise reader.fail("occupancy", "the occupancy grid was not loaded")

    if "bounds" in spec:
        bounds = spec["bounds"]
        if not isinstance(bounds, (list, tuple)) or len(bounds) != 4:
            raise reader.fail("bounds", f"expected [xmin, ymin, xmax, ymax], got {_describe(bounds)}")
        bounds = np.array([reader.number(v, f"bounds[{k}]") for k, v in enumerate(bounds)])
    elif grid_extent is not None:
        bounds = np.array(grid_extent, float)
    else:
        raise reader.fail("bounds", "missing (required unless an occupancy grid gives the extent)")
    if not (bounds[0] < bounds[2] and bounds[1] < bounds[3]):
        raise reader.fail("bounds", "needs xmin < xmax and ymin < ymax")

    robot_radius, robot = _robot(reader, spec)
    planning_radius = robot_radius + robot.get("lookahead", ROBOT_DEFAULTS["lookahead"])

    obstacles = spec.get("obstacles", [])
    if not isinstance(obstacles, list):
        raise reader.fail("obstacles", f"expected a list, got {_describe(obstacles)}")
    raw_parts.extend(
        _obstacle(reader, item, f"obstacles[{k}]", params.circle_segments) for k, item in enumerate(obstacles)
    )
    raw = shapely.union_all(raw_parts) if raw_parts else shapely.Polygon()
    inflated = inflate(raw, planning_radius)

    if "goal" not in spec:
        raise reader.fail("goal", "missing")
    goal = reader.point(spec["goal"], "goal")
    starts = reader.points(spec.get("starts", []), "starts")
    if "landmarks" not in spec:
        raise reader.fail("landmarks", "missing (at least 2 are needed)")
    landmark_ids, landmarks, given_facing = _landmarks(reader, spec["landmarks"])
    stage_params = spec.get("params", {})
    if not isinstance(stage_params, dict) or not all(isinstance(v, dict) for v in stage_params.values()):
        raise reader.fail("params", "expected a mapping of stage name to a mapping of options")

    map_ = Map(
        name=name,
        bounds=bounds,
        robot_radius=robot_radius,
        goal=goal,
        starts=starts,
        landmark_ids=landmark_ids,
        landmarks=landmarks,
        obstacles=from_shapely(inflated),
        raw_obstacles=from_shapely(raw),
        params=stage_params,
        source={"file": source.file, "sha256": source.sha256},
        landmark_facing=_facing(reader, given_facing, landmarks, bounds, raw, 1e-9 * math.dist(bounds[:2], bounds[2:])),
        robot=robot,
    )
    if map_.lookahead > 0:
        # the map must make sense for the body first (its errors name the field at fault), then for
        # the look-ahead point: what only the larger inflation breaks is the look-ahead's fault
        body = replace(map_, obstacles=from_shapely(inflate(raw, robot_radius)), robot={**robot, "lookahead": 0.0})
        _validate(reader, body, params, warn=False)
        _validate(reader, map_, params, culprit="robot.lookahead")
    else:
        _validate(reader, map_, params)
    return map_


def _robot(reader: _Reader, spec: dict) -> tuple[float, dict]:
    """The robot radius and the other parameters of the ``robot:`` section that the map gives.

    ``robot_radius`` and ``robot.radius`` are two spellings of ρ (both given: they must agree).
    Numbers must be finite, zero or positive, the angles below 90°; ``compass_error_deg``,
    ``slip_floor`` and ``max_turn_rate`` may be null (unknown, their default); ``reverse`` is true or false. The
    defaults are :data:`~bearnav_cli.runtime.robot.ROBOT_DEFAULTS`.
    """
    section = spec.get("robot")
    section = {} if section is None else reader.mapping(section, "robot", ROBOT_KEYS)
    given: dict[str, Any] = {}
    for key, value in section.items():
        where = f"robot.{key}"
        if key == "reverse":
            if not isinstance(value, bool):
                raise reader.fail(where, f"expected true or false, got {_describe(value)}")
            given[key] = value
            continue
        if value is None and ROBOT_DEFAULTS[key] is None:  # explicitly unknown
            given[key] = None
            continue
        number = reader.number(value, where)
        if number < 0:
            raise reader.fail(where, "must be zero or positive")
        if key.endswith("_deg") and number >= 90:
            raise reader.fail(where, f"must be below 90 degrees (a bearing cone is convex only then), got {number:g}")
        given[key] = number
    radius = reader.number(spec.get("robot_radius", ROBOT_DEFAULTS["radius"]), "robot_radius")
    if radius < 0:
        raise reader.fail("robot_radius", "must be zero or positive")
    if "radius" in given:
        if "robot_radius" in spec and given["radius"] != radius:
            raise reader.fail("robot.radius", f"{given['radius']:g} differs from robot_radius {radius:g} (give one)")
        radius = given.pop("radius")
    return radius, given


def _validate(reader: _Reader, map_: Map, params: Params, culprit: str | None = None, warn: bool = True) -> None:
    """The consistency checks of ALGORITHMS §1 on a built map.

    ``culprit`` names the field every free-space failure is blamed on (``robot.lookahead``: the map
    passed these checks without it, so only the look-ahead's inflation can break them); ``warn``
    off skips the landmark-coverage warning.
    """
    blame = (
        ""
        if culprit is None
        else (f" once the obstacles are inflated by the robot radius plus the look-ahead, {map_.planning_radius:g}")
    )

    def fail(field: str, message: str) -> InvalidMapError:
        return reader.fail(field if culprit is None else culprit, message + blame)

    lo, hi = map_.free_bounds[:2], map_.free_bounds[2:]
    if culprit is not None and not np.all(lo < hi):
        raise fail("bounds", "the bounds leave no room for the look-ahead point")
    space = FreeSpace.from_map(map_)
    if space.free_area <= 0:
        raise fail("obstacles", "the free space is empty")
    # the free space a message names is the planned point's: say what it is less than the map's
    free = (
        f"the free space (the bounds less the walls and obstacles grown by the {map_.inflation_text}, where the "
        "robot's centre may go)"
    )
    if not space.points_strictly_free(map_.goal)[0]:
        what = "the goal " if culprit else ""
        raise fail("goal", f"{what}{map_.goal.tolist()} is not strictly inside {free}")
    component = space.component_of(map_.goal)
    for k, start in enumerate(map_.starts):
        where = f"starts[{k}]"
        what = f"{where} " if culprit else ""
        if not space.points_strictly_free(start)[0]:
            raise fail(where, f"{what}{start.tolist()} is not strictly inside {free}")
        if not component.intersects(shapely.Point(start)):
            raise fail(where, f"{what}{start.tolist()} cannot reach the goal (another free component)")

    L = len(map_.landmarks)
    if L < 2:
        raise reader.fail("landmarks", f"at least 2 landmarks are needed, got {L}")
    for k, lm in enumerate(map_.landmarks):
        where = f"landmarks[{k}]"
        lo, hi = map_.bounds[:2], map_.bounds[2:]
        if not np.all((lm >= lo) & (lm <= hi)):
            raise reader.fail(where, f"{lm.tolist()} is outside the bounds")
        dup = np.flatnonzero(np.all(map_.landmarks[:k] == lm, axis=1))
        if dup.size:
            raise reader.fail(where, f"same position as landmarks[{dup[0]}]")
        # A tag drawn on a wall may sit a rounding error inside it (grid maps scale pixel
        # corners by the resolution): only a tag deeper than the map tolerance is rejected.
        if (
            not space.raw_obstacles.is_empty
            and shapely.contains_xy(space.raw_obstacles, *lm)
            and shapely.distance(space.raw_obstacles.boundary, shapely.points(lm)) > map_.tol
        ):
            raise reader.fail(where, f"{lm.tolist()} lies inside an obstacle (a tag must be on its boundary)")
    if warn:
        _coverage_warning(map_, space, params.coverage_cells)


def _coverage_warning(map_: Map, space: FreeSpace, cells: int) -> None:
    points, counts = landmark_coverage(map_, space, cells)
    poor = points[counts < 2]
    if len(poor) == 0 or len(points) == 0 or len(poor) < NEGLIGIBLE_SHARE * len(points):
        return
    share = 100.0 * len(poor) / len(points)
    lo, hi = poor.min(axis=0), poor.max(axis=0)
    log.warning(
        "fewer than 2 landmarks are in line of sight from %.1f%% of the free space, within "
        "x in [%.3g, %.3g], y in [%.3g, %.3g] (e.g. at (%.3g, %.3g))",
        share,
        lo[0],
        hi[0],
        lo[1],
        hi[1],
        poor[0][0],
        poor[0][1],
    )


def spec_of(map_: Map) -> dict:
    """A map description (DESIGN §4, as ``yaml.safe_load`` gives it) that this stage turns back into
    ``map_``'s free space: bounds, radius, goal, starts, landmarks, params, and the raw obstacles as
    simple polygons (one with holes, such as an occupancy grid's wall frame around its rooms, as
    the triangles of its constrained Delaunay triangulation, which this stage merges back). For a
    map whose source file is gone, or to write a map elsewhere (an occupancy map's image path is
    relative to its YAML)."""

    def numbers(values) -> list:
        return [float(v) for v in values]

    def simple_parts(polygon) -> list:
        if not polygon.holes:
            return [np.asarray(polygon.exterior, float)]
        triangles = shapely.get_parts(shapely.constrained_delaunay_triangles(to_shapely(polygon)))
        return [np.asarray(t.exterior.coords)[:-1] for t in triangles if t.area > 0]

    return {
        "name": map_.name,
        "bounds": numbers(map_.bounds),
        "robot_radius": float(map_.robot_radius),
        "goal": numbers(map_.goal),
        "starts": [numbers(p) for p in map_.starts],
        "obstacles": [{"polygon": [numbers(v) for v in part]} for o in map_.raw_obstacles for part in simple_parts(o)],
        "landmarks": [
            {"id": i, "position": numbers(p), "facing": None if math.isnan(f) else round(math.degrees(f), 9)}
            for i, p, f in zip(map_.landmark_ids, map_.landmarks, map_.landmark_facing, strict=True)
        ],
        "params": {stage: dict(values) for stage, values in (map_.params or {}).items()},
        **({"robot": map_.robot_json()} if map_.robot_json() else {}),
    }


def listed_obstacles(source: MapSource) -> int | None:
    """How many obstacles the description lists (None when an occupancy grid adds its own)."""
    if source.grid is not None or not isinstance(source.spec, dict):
        return None
    listed = source.spec.get("obstacles", [])
    return len(listed) if isinstance(listed, list) else None


def summary(map_: Map, listed: int | None = None) -> str:
    """One line for ``inspect`` and ``plan``; with ``listed`` (:func:`listed_obstacles`) it says what was merged."""
    xmin, ymin, xmax, ymax = map_.bounds
    raw, inflated = len(map_.raw_obstacles), len(map_.obstacles)
    radius = map_.inflation_text
    if listed is None or (listed == raw == inflated):
        shapes = f"{plural(inflated, 'obstacle')} ({radius})"
    else:
        merged = []
        if raw != listed:
            merged.append(f"into {raw} (touching or overlapping)")
        if inflated != raw:
            merged.append(f"into {inflated} by the {radius} (gaps it cannot pass)")
        counted = plural(listed, "obstacle")
        shapes = f"{counted} merged " + " and ".join(merged) if merged else counted
        if inflated == raw:
            shapes += f", {radius}"
    return (
        f"{map_.name}: {xmax - xmin:g} x {ymax - ymin:g} bounds, {shapes}, "
        f"{plural(len(map_.landmarks), 'landmark')}, {plural(len(map_.starts), 'start')}"
    )
