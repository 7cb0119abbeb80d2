"""The normalised map (``map.json``, embedded in every later artifact): :class:`Polygon`, :class:`Map`, its invariants.

A content hash proves that a file is intact, not that it makes sense. Each artifact's container is
followed by its INVARIANTS: what the next stage relies on. ``artifacts.load`` runs them on every file
it reads (whatever its hash says), ``pipeline`` runs them on every stage's output before it is saved,
and ``docs/artifacts.md`` lists them ("Checked on load"; a test compares the lists).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bearnav_cli.datatypes.frozen import freeze, frozen_array, thaw
from bearnav_cli.errors import ArtifactError
from bearnav_cli.runtime.invariants import Invariant
from bearnav_cli.runtime.invariants import at_least as _at_least
from bearnav_cli.runtime.invariants import first as _first
from bearnav_cli.runtime.robot import ROBOT_DEFAULTS, ROBOT_KEYS, robot_parameters, robot_problem

__all__ = ["Map", "MAP_INVARIANTS", "Polygon"]


def _ring_problem(polygons: tuple[Polygon, ...]) -> str | None:
    """Rings of 3 or more finite vertices, simple polygons of positive area (shapely's validity)."""
    for k, polygon in enumerate(polygons):
        for ring in (polygon.exterior, *polygon.holes):
            if len(ring) < 3:
                return f"polygon {k} has a ring of {len(ring)} points (at least 3 are needed)"
            if not np.all(np.isfinite(ring)):
                return f"polygon {k} has a NaN or infinite vertex"
    if not polygons:
        return None
    import shapely  # only when there are polygons to check (shapely is loaded by every stage anyway)

    shapes = [shapely.Polygon(p.exterior, p.holes) for p in polygons]
    valid = shapely.is_valid(shapes) & (shapely.area(shapes) > 0)
    k = _first(~valid)
    if k is None:
        return None
    return f"polygon {k} is not a simple polygon of positive area ({shapely.is_valid_reason(shapes[k])})"


@dataclass(frozen=True, eq=False)  # arrays inside: identity equality, a hash that works
class Polygon:
    """A simple polygon with optional holes, in map units.

    Attributes
    ----------
    exterior : ndarray, shape (n, 2)
        Vertices of the outer ring, without the closing repeat.
    holes : tuple of ndarray, each shape (m, 2)
        Inner rings, same convention.
    """

    exterior: np.ndarray
    holes: tuple[np.ndarray, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "exterior", frozen_array(self.exterior, float, (None, 2), "exterior"))
        object.__setattr__(self, "holes", tuple(frozen_array(h, float, (None, 2), "holes") for h in self.holes))

    def to_json(self) -> dict:
        return {"exterior": self.exterior.tolist(), "holes": [h.tolist() for h in self.holes]}

    @classmethod
    def from_json(cls, data: dict) -> Polygon:
        return cls(np.asarray(data["exterior"], float), tuple(np.asarray(h, float) for h in data["holes"]))


@dataclass(frozen=True, eq=False)  # arrays inside: identity equality, a hash that works
class Map:
    """The normalised map (schema ``bearnav.map/1``, DESIGN §3.2, ALGORITHMS §1).

    Attributes
    ----------
    name : str
        Map name (also the default plan folder).
    bounds : ndarray, shape (4,)
        ``[xmin, ymin, xmax, ymax]`` in map units.
    robot_radius : float
        The robot's radius ρ (map units); ``obstacles`` are inflated by ``ρ + λ`` (:attr:`planning_radius`).
    goal : ndarray, shape (2,)
        Goal position, the root of every tree.
    starts : ndarray, shape (S, 2)
        Default start positions for simulation.
    landmark_ids : tuple of str, length L
        Landmark identifiers (AprilTag ids, say).
    landmarks : ndarray, shape (L, 2)
        Landmark positions.
    obstacles : tuple of Polygon
        Configuration-space obstacles ``O`` the cells must avoid: the raw obstacles inflated by
        :attr:`planning_radius` (``robot_radius``, plus the ``lookahead`` when there is one).
    raw_obstacles : tuple of Polygon
        Obstacles before inflation, used for line of sight.
    params : dict
        Per-stage parameter overrides from the map file, ``{stage: {name: value}}``.
    source : dict
        ``{"file": name, "sha256": hash}`` of the input the map came from.
    landmark_facing : ndarray, shape (L,)
        Direction each tag's printed face looks toward (rad, counter-clockwise from +x, in
        ``[0, 2π)``); NaN for a free-standing tag seen from every side (the default). Stored to
        1e-9 degree, so that the map JSON (degrees) round-trips it exactly.
    robot : dict
        The map's ``robot:`` section (DESIGN §3.4) but its ``radius`` (that is ``robot_radius``):
        ``lookahead``, ``bearing_error_deg``, ``compass_error_deg``, ``slip``, ``max_turn_rate``
        and ``reverse``, every one filled in from
        :data:`~bearnav_cli.runtime.robot.ROBOT_DEFAULTS` (a frozen mapping, as ``params``).
        ``map.json`` writes only the values that differ from the defaults, and no ``robot`` key
        when none does, so a map without a robot section keeps its content hash.
    """

    name: str
    bounds: np.ndarray
    robot_radius: float
    goal: np.ndarray
    starts: np.ndarray
    landmark_ids: tuple[str, ...]
    landmarks: np.ndarray
    obstacles: tuple[Polygon, ...]
    raw_obstacles: tuple[Polygon, ...]
    params: dict = field(default_factory=dict)
    source: dict = field(default_factory=dict)
    landmark_facing: np.ndarray | None = None
    robot: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", freeze(dict(self.params)))
        object.__setattr__(self, "source", freeze(dict(self.source)))
        given = dict(self.robot or {})
        unknown = sorted(set(given) - set(ROBOT_KEYS) - {"radius"})
        if unknown:
            raise ArtifactError(f"unknown key {unknown[0]!r} (expected one of: {', '.join(ROBOT_KEYS)})", field="robot")
        object.__setattr__(self, "robot", freeze(robot_parameters(given)))
        object.__setattr__(self, "bounds", frozen_array(self.bounds, float, (4,), "bounds"))
        object.__setattr__(self, "goal", frozen_array(self.goal, float, (2,), "goal"))
        object.__setattr__(self, "starts", frozen_array(self.starts, float, (None, 2), "starts"))
        object.__setattr__(self, "landmarks", frozen_array(self.landmarks, float, (None, 2), "landmarks"))
        object.__setattr__(self, "landmark_ids", tuple(str(i) for i in self.landmark_ids))
        if len(self.landmark_ids) != len(self.landmarks):
            raise ArtifactError("one id per landmark expected", field="landmarks")
        facing = np.full(len(self.landmarks), np.nan) if self.landmark_facing is None else self.landmark_facing
        facing = np.asarray(facing, float).reshape(-1)
        if len(facing) != len(self.landmarks):
            raise ArtifactError("one facing (or NaN) per landmark expected", field="landmark_facing")
        if np.isinf(facing).any():
            raise ArtifactError("contains infinity", field="landmark_facing")
        # degrees to 1e-9 in [0, 360), as map.json writes them: the JSON round trip is exact
        degrees = [math.nan if math.isnan(f) else _facing_degrees(f) for f in facing.tolist()]
        object.__setattr__(
            self,
            "landmark_facing",
            frozen_array(np.radians(np.array(degrees, float)), float, (len(self.landmarks),), "landmark_facing"),
        )
        for name in ("bounds", "goal", "starts", "landmarks"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ArtifactError("contains NaN or infinity", field=name)

    @property
    def diagonal(self) -> float:
        """Length D of the bounds' diagonal (map units)."""
        xmin, ymin, xmax, ymax = self.bounds
        return math.hypot(xmax - xmin, ymax - ymin)

    @property
    def tol(self) -> float:
        """Geometric tolerance ``1e-9·D`` of every predicate (ALGORITHMS §0)."""
        return 1e-9 * self.diagonal

    @property
    def lookahead(self) -> float:
        """``λ`` (map units): the plan is made for the point ``λ`` ahead of a unicycle's axle (ALGORITHMS §12.6)."""
        return float(self.robot["lookahead"])

    @property
    def planning_radius(self) -> float:
        """``ρ + λ`` (map units): what ``obstacles`` and :attr:`free_bounds` are inflated and shrunk by."""
        return float(self.robot_radius) + self.lookahead

    @property
    def inflation_text(self) -> str:
        """``"robot radius 0.2"`` (``"robot radius 0.2 + look-ahead 0.1"``): what the walls and obstacles are grown
        by, in the words every message about the free space uses."""
        text = f"robot radius {self.robot_radius:g}"
        return text + (f" + look-ahead {self.lookahead:g}" if self.lookahead > 0 else "")

    @property
    def free_bounds(self) -> np.ndarray:
        """``B_r``: the bounds shrunk by the planning radius, where the planned point may go (ALGORITHMS §11.1).

        The bounds are walls: a robot of radius ρ touches ``∂B`` with its centre on ``∂B_r``; with a
        look-ahead λ the planned point is ``p`` and ``r = ρ + λ`` (:attr:`planning_radius`).
        Shape (4,), ``[xmin + r, ymin + r, xmax − r, ymax − r]``.
        """
        r = max(0.0, self.planning_radius)
        return self.bounds + np.array([r, r, -r, -r])

    def to_json(self) -> dict:
        """The ``map.json`` document without its manifest."""
        return {
            "name": self.name,
            "bounds": self.bounds.tolist(),
            "robot_radius": float(self.robot_radius),
            "goal": self.goal.tolist(),
            "starts": self.starts.tolist(),
            "landmarks": [
                {"id": i, "position": p.tolist(), "facing": _facing_degrees(f)}
                for i, p, f in zip(self.landmark_ids, self.landmarks, self.landmark_facing, strict=True)
            ],
            "obstacles": [p.to_json() for p in self.obstacles],
            "raw_obstacles": [p.to_json() for p in self.raw_obstacles],
            "params": thaw(self.params),
            "source": thaw(self.source),
            **({"robot": self.robot_json()} if self.robot_json() else {}),
        }

    def robot_json(self) -> dict:
        """The ``robot`` object of ``map.json``: the robot parameters that differ from their defaults."""
        return {key: value for key, value in thaw(self.robot).items() if value != ROBOT_DEFAULTS[key]}

    def to_json_text(self) -> str:
        """Canonical JSON text of :meth:`to_json` (sorted keys), as embedded in later artifacts."""
        return json.dumps(self.to_json(), sort_keys=True, separators=(",", ":"))

    @classmethod
    def from_json(cls, data: dict) -> Map:
        try:
            return cls(
                name=str(data["name"]),
                bounds=data["bounds"],
                robot_radius=float(data["robot_radius"]),
                goal=data["goal"],
                starts=np.asarray(data["starts"], float).reshape(-1, 2),
                landmark_ids=tuple(str(lm["id"]) for lm in data["landmarks"]),
                landmarks=np.asarray([lm["position"] for lm in data["landmarks"]], float).reshape(-1, 2),
                obstacles=tuple(Polygon.from_json(p) for p in data["obstacles"]),
                raw_obstacles=tuple(Polygon.from_json(p) for p in data["raw_obstacles"]),
                params=dict(data.get("params", {})),
                source=dict(data.get("source", {})),
                robot=dict(data.get("robot", {})),
                # maps written before tags had a facing: every tag free-standing
                landmark_facing=np.radians(
                    np.array(
                        [_facing_number(lm.get("facing")) for lm in data["landmarks"]],
                        float,
                    )
                ),
            )
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            if isinstance(exc, ArtifactError):
                raise
            raise ArtifactError(f"malformed map ({type(exc).__name__}: {exc})", field="map") from exc


def _facing_number(value: Any) -> float:
    """``map.json``'s facing (degrees, or null) as a float, NaN for null; ``true`` is not 1°."""
    if value is None:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ArtifactError(f"expected degrees or null, got {value!r}", field="map.landmarks.facing")
    return float(value)


def _facing_degrees(facing: float) -> float | None:
    """A tag's facing as ``map.json`` writes it: degrees in ``[0, 360)``, or None (free-standing)."""
    return None if math.isnan(facing) else round(math.degrees(facing) % 360.0, 9) % 360.0


def _map_params_problem(map_: Map) -> str | None:
    params = map_.params
    if not isinstance(params, dict):
        return "expected a mapping of stage name to a mapping of options"
    for stage, options in params.items():
        if not isinstance(options, dict):
            return str(stage), f"expected a mapping of options, got {type(options).__name__}"
        for name, value in options.items():
            if value is not None and not isinstance(value, (bool, int, float, str)):
                return f"{stage}.{name}", f"expected a number, a string, true/false or null, got {type(value).__name__}"
    return None


def _map_points_problem(map_: Map, points: np.ndarray, strict: bool) -> str | None:
    """The first point outside ``B_r`` (strictly inside, when ``strict``) or in an obstacle."""
    lo, hi = map_.free_bounds[:2], map_.free_bounds[2:]
    inside = (
        np.all((points > lo) & (points < hi), axis=1) if strict else np.all((points >= lo) & (points <= hi), axis=1)
    )
    k = _first(~inside)
    if k is not None:
        return f"{points[k].tolist()} is outside B_r (the bounds less the robot radius)"
    if not map_.obstacles or not len(points):
        return None
    import shapely

    for j, polygon in enumerate(map_.obstacles):
        hit = shapely.intersects_xy(shapely.Polygon(polygon.exterior, polygon.holes), points[:, 0], points[:, 1])
        k = _first(np.asarray(hit).reshape(-1))
        if k is not None:
            return f"{points[k].tolist()} lies in obstacle {j}"
    return None


def _map_landmarks_problem(map_: Map) -> str | None:
    if len(map_.landmarks) < 2:
        return f"at least 2 landmarks are needed, got {len(map_.landmarks)}"
    if len(set(map_.landmark_ids)) != len(map_.landmark_ids):
        return "landmark ids must be distinct"
    lo, hi = map_.bounds[:2], map_.bounds[2:]
    k = _first(~np.all((map_.landmarks >= lo) & (map_.landmarks <= hi), axis=1))
    if k is not None:
        return f"landmark {k} {map_.landmarks[k].tolist()} is outside the bounds"
    # two tags at one point give one bearing twice: the YAML reader refuses it, and so does map.json
    _, first, counts = np.unique(map_.landmarks, axis=0, return_index=True, return_counts=True)
    if np.any(counts > 1):
        k = int(first[np.flatnonzero(counts > 1)[0]])
        return f"two landmarks at one position, {map_.landmarks[k].tolist()} (landmark {k} and another)"
    return None


def _map_name_problem(map_: Map) -> str | None:
    name = map_.name
    if not name or any(c in name for c in "/\\:") or name.startswith("."):
        return f"must be a non-empty name without path separators, got {name!r}"
    return None


def _map_bounds_problem(map_: Map) -> str | None:
    xmin, ymin, xmax, ymax = map_.bounds
    if not (xmin < xmax and ymin < ymax):
        return "needs xmin < xmax and ymin < ymax"
    r = map_.planning_radius
    if math.isfinite(r) and not (xmax - xmin > 2 * r and ymax - ymin > 2 * r):
        return f"leave no room for a robot of radius {r:g} (B_r is empty)"
    return None


def _map_robot_problem(map_: Map) -> tuple[str, str] | None:
    """The robot section (:func:`bearnav_cli.runtime.robot.robot_problem`, the robot's own check)."""
    return robot_problem(map_.robot)


#: What every map (``map.json``, and the map embedded in every later artifact) must satisfy.
MAP_INVARIANTS: tuple[Invariant, ...] = (
    Invariant("name", "a non-empty name without path separators", _map_name_problem),
    Invariant("robot_radius", "finite, zero or positive",
              lambda m: _at_least([m.robot_radius], 0.0, "zero or positive")),
    Invariant("robot", "finite, zero or positive parameters (angles below 90°), reverse true or false",
              _map_robot_problem),
    Invariant("bounds", "xmin < xmax, ymin < ymax, wider and taller than the robot's diameter", _map_bounds_problem),
    Invariant("obstacles", "simple polygons: rings of 3 or more finite vertices, positive area",
              lambda m: _ring_problem(m.obstacles)),
    Invariant("raw_obstacles", "simple polygons: rings of 3 or more finite vertices, positive area",
              lambda m: _ring_problem(m.raw_obstacles)),
    Invariant("goal", "strictly inside B_r (the bounds less the robot radius) and in no obstacle",
              lambda m: _map_points_problem(m, m.goal[None, :], strict=True)),
    Invariant("starts", "inside B_r and in no obstacle", lambda m: _map_points_problem(m, m.starts, strict=False)),
    Invariant("landmarks", "at least 2, inside the bounds, with distinct ids and positions", _map_landmarks_problem),
    Invariant("params", "stage name -> parameter name -> a number, string, true/false or null", _map_params_problem),
)  # fmt: skip
