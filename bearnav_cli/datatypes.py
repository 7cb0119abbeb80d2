"""Typed, immutable containers for every artifact (DESIGN §3).

Each artifact is a frozen dataclass of numpy arrays plus a few scalars. The
constructors check shapes and dtypes and make the arrays read-only, so an
artifact cannot be changed after it is built. The keys, dtypes and shapes come from the one
schema declaration, :data:`bearnav_cli.runtime.schema.ENTRIES` (shared with the loader, the
robot's run-time view and the docs test). Serialisation lives in ``artifacts.py``; this module
knows nothing about files.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bearnav_cli.errors import ArtifactError
from bearnav_cli.runtime.invariants import (
    CELLS_INVARIANTS,
    PLAN_INVARIANTS,
    Invariant,
    cell_areas,
    check_cells_form,
    check_plan_form,
    ragged_problem,
    validate,
)
from bearnav_cli.runtime.invariants import TREE_SHAPE as _TREE_SHAPE
from bearnav_cli.runtime.invariants import at_least as _at_least
from bearnav_cli.runtime.invariants import finite_problem as _finite_problem
from bearnav_cli.runtime.invariants import first as _first
from bearnav_cli.runtime.invariants import in_range as _in_range
from bearnav_cli.runtime.invariants import nodes_problem as _nodes_problem
from bearnav_cli.runtime.invariants import offsets_problem as _offsets_problem
from bearnav_cli.runtime.invariants import tree_problem as _tree_problem
from bearnav_cli.runtime.robot import ROBOT_DEFAULTS, ROBOT_KEYS, robot_parameters, robot_problem
from bearnav_cli.runtime.schema import ENTRIES

__all__ = [
    "AREA_QUANTILES",
    "tolerance_by_area",
    "FrozenDict",
    "freeze",
    "thaw",
    "CELL_KEYS",
    "cell_list",
    "CellFlag",
    "Cells",
    "CellStatus",
    "frozen_array",
    "INVARIANTS",
    "Map",
    "MAP_INVARIANTS",
    "NEGLIGIBLE_SHARE",
    "Outcome",
    "percent",
    "Plan",
    "PLAN_KEYS",
    "plural",
    "Polygon",
    "ragged",
    "replace",
    "Simulation",
    "SIMULATION_INVARIANTS",
    "SIMULATION_KEYS",
    "Tree",
    "TREE_INVARIANTS",
    "TREE_KEYS",
    "validate_artifact",
]


class FrozenDict(dict):
    """A ``dict`` that cannot change (issue 14.5): the ``stats`` and ``params`` of a frozen artifact.

    It is a ``dict`` for every reader (``json.dumps``, ``==``, ``isinstance``); every mutating
    method raises ``TypeError``. :func:`copy.copy` and :func:`copy.deepcopy` give plain, mutable
    ``dict`` copies (:func:`thaw`), so a caller that wants to edit one edits its own copy.
    """

    __slots__ = ()

    def _read_only(self, *args: Any, **kwargs: Any) -> None:
        raise TypeError("an artifact's stats and params are read-only: copy them (dict(x)) to change them")

    __setitem__ = __delitem__ = __ior__ = clear = pop = popitem = setdefault = update = _read_only  # type: ignore[assignment]

    def __copy__(self) -> dict:
        return dict(self)

    def __deepcopy__(self, memo: dict) -> Any:
        return thaw(self)

    def __reduce__(self) -> tuple:
        return (FrozenDict, (dict(self),))


def freeze(value: Any) -> Any:
    """``value`` with every dict in it (nested too) made a :class:`FrozenDict`; other values as they are.

    Parameters
    ----------
    value : Any
        A JSON-like value (dicts, lists, numbers, strings).

    Returns
    -------
    Any
        The same value, its dicts read-only (lists stay lists: they compare equal to JSON arrays).
    """
    if isinstance(value, dict):
        return value if type(value) is FrozenDict and all(not isinstance(v, dict) or type(v) is FrozenDict
                                                          for v in value.values()) else \
            FrozenDict({k: freeze(v) for k, v in value.items()})  # fmt: skip
    if isinstance(value, list):
        return [freeze(v) for v in value]
    return value


def thaw(value: Any) -> Any:
    """A plain, mutable deep copy of ``value`` (every :class:`FrozenDict` in it a ``dict``).

    Parameters
    ----------
    value : Any
        A JSON-like value, possibly frozen by :func:`freeze`.

    Returns
    -------
    Any
        The copy (YAML's safe dumper, for one, writes only plain dicts).
    """
    if isinstance(value, dict):
        return {k: thaw(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [thaw(v) for v in value]
    return value


def frozen_array(value: Any, dtype: Any, shape: tuple[int | None, ...], name: str) -> np.ndarray:
    """Return a read-only copy of ``value`` as ``dtype`` after checking its shape.

    Parameters
    ----------
    value : array_like
        The data.
    dtype : numpy dtype
        Target dtype (float64 for positions, int64 for indices).
    shape : tuple of int or None
        Expected shape; ``None`` matches any length along that axis.
    name : str
        Field name used in the error message.
    """
    array = np.array(value, dtype=dtype, copy=True)
    if array.size == 0 and len(shape) > 1 and array.ndim == 1:
        array = array.reshape((0,) + tuple(s or 0 for s in shape[1:]))
    if array.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(array.shape, shape, strict=False)
    ):
        raise ArtifactError(f"expected shape {_shape_text(shape)}, got {array.shape}", field=name)
    array.setflags(write=False)
    return array


def _shape_text(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"


def _freeze(obj: Any, kind: str, names: tuple[str, ...], dims: dict[str, int]) -> None:
    """Replace each field of ``names`` on ``obj`` by a read-only array of the dtype and shape that
    ``ENTRIES[kind]`` declares, the dimensions in ``dims`` filled in (the others match any length)."""
    for name in names:
        entry = ENTRIES[kind][name]
        object.__setattr__(obj, name, frozen_array(getattr(obj, name), entry.numpy_dtype, entry.resolve(dims), name))


def _data_keys(kind: str) -> tuple[str, ...]:
    """The data entries of ``kind`` that its container holds as fields (all but the embedded ``map``)."""
    return tuple(name for name in ENTRIES[kind] if name != "map")


# --------------------------------------------------------------------------- meaning (checked on load)
#
# A content hash proves that a file is intact, not that it makes sense. Each artifact's schema
# below is followed by its INVARIANTS: what the next stage relies on. artifacts.load runs them on
# every file it reads (whatever its hash says), pipeline runs them on every stage's output before
# it is saved, and docs/artifacts.md lists them ("Checked on load"; a test compares the lists).


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
            raise ArtifactError(f"unknown key {unknown[0]!r} (expected one of: {', '.join(ROBOT_KEYS)})",
                                field="robot")  # fmt: skip
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
    inside = np.all((points > lo) & (points < hi), axis=1) if strict else np.all((points >= lo) & (points <= hi),
                                                                                   axis=1)  # fmt: skip
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


@dataclass(frozen=True, eq=False)  # arrays inside: identity equality, a hash that works
class Tree:
    """A tree rooted at the goal, with the RRT* collision samples (ALGORITHMS §2–3).

    Used for both ``tree.npz`` (schema ``bearnav.tree/1``) and ``simplified.npz``
    (schema ``bearnav.simplified/1``).

    Attributes
    ----------
    map : Map
        The map the tree was planned on.
    nodes : ndarray, shape (N, 2)
        Node positions; node 0 is the root, at the goal.
    parent : ndarray of int64, shape (N,)
        Parent index of each node, ``-1`` exactly at the root.
    cost : ndarray, shape (N,)
        Length of the tree path from each node to the root (map units).
    collision_samples : ndarray, shape (S, 2)
        Random samples that fell in obstacles, then the border pseudo-samples.
    stats : dict
        Stage statistics copied into the manifest (counts per round, sample counts ...).
    """

    map: Map
    nodes: np.ndarray
    parent: np.ndarray
    cost: np.ndarray
    collision_samples: np.ndarray
    stats: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stats", freeze(dict(self.stats)))
        _freeze(self, "tree", ("nodes",), {})
        n = len(self.nodes)
        _freeze(self, "tree", ("parent", "cost", "collision_samples"), {"N": n})
        if n == 0 or self.parent[0] != -1 or np.count_nonzero(self.parent == -1) != 1:
            raise ArtifactError("parent must be -1 exactly at node 0", field="parent")
        if np.any((self.parent < -1) | (self.parent >= n)):
            raise ArtifactError("parent index out of range", field="parent")
        for name in ("nodes", "cost", "collision_samples"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ArtifactError("contains NaN or infinity", field=name)

    @property
    def edges(self) -> np.ndarray:
        """Edge segments child → parent, shape (N−1, 2, 2), in node order 1…N−1."""
        return np.stack([self.nodes[1:], self.nodes[self.parent[1:]]], axis=1)

    def arrays(self) -> dict[str, np.ndarray]:
        """The data entries of the artifact file (without ``manifest`` and ``map``)."""
        return {name: getattr(self, name) for name in TREE_KEYS}


#: Data keys of ``tree.npz`` and ``simplified.npz`` besides ``map`` (DESIGN §3.2).
TREE_KEYS = _data_keys("tree")


def _tree_cost_problem(tree: Tree) -> str | None:
    cost, parent, nodes = tree.cost, tree.parent, tree.nodes
    if len(cost) and cost[0] != 0:
        return f"must be 0 at the root, got {cost[0]:g}"
    child = np.arange(1, len(nodes))
    expected = cost[parent[child]] + np.hypot(*(nodes[child] - nodes[parent[child]]).T)
    k = _first(np.abs(cost[child] - expected) > 1e-6 * max(tree.map.diagonal, 1.0))
    if k is None:
        return None
    return f"node {k + 1}: {cost[k + 1]:g} is not its parent's cost plus the edge length ({expected[k]:g})"


#: What ``tree.npz`` and ``simplified.npz`` must satisfy (besides their map's invariants).
TREE_INVARIANTS: tuple[Invariant, ...] = (
    *_TREE_SHAPE,
    Invariant("cost", "0 at the root, the parent's cost plus the edge length at every other node", _tree_cost_problem),
    Invariant("collision_samples", "finite", lambda t: _finite_problem(t.collision_samples)),
)  # fmt: skip


class CellStatus(enum.IntEnum):
    """Outcome of a cell's synthesis (``plan.npz`` ``status``, ALGORITHMS §5.3)."""

    CERTIFIED = 0
    RELAXED = 1  # certified after halving the constants
    NOT_CERTIFIED = 2  # least-violation solution stored
    SOLVER_FAILURE = 3
    GOAL = 4


class CellFlag(enum.IntFlag):
    """Warnings attached to a cell by decomposition (ALGORITHMS §4.5, §5.4, §5.5)."""

    NONE = 0
    FEW_LANDMARKS = 1  # fewer than 2 landmarks visible from the whole cell (topped up)
    DEGENERATE_RISK = 2  # every landmark line through the fixed landmark crosses the cell
    LANDMARK_INSIDE = 4  # every candidate fixed landmark lies in the cell (s_min = 0)
    SAMPLE_ON_EDGE = 8  # a collision sample on the edge line was skipped
    BLIND_SPOT = 16  # a free point of the coverage grid (spacing D/100) in the cell sees < 2 landmarks


def plural(count: int, word: str, many: str | None = None) -> str:
    """``"1 obstacle"``, ``"3 obstacles"``: a count and its noun, for every message that counts things.

    Parameters
    ----------
    count : int
        How many.
    word : str
        The noun in the singular.
    many : str, optional
        Its plural, when it is not ``word + "s"``.

    Returns
    -------
    str
    """
    return f"{count} {word if count == 1 else many or word + 's'}"


#: A share of an area below which a warning is not worth giving: it would read ``0.0%``, a few points of a
#: grid at a corner rather than a place a robot could be stuck in (the checks that fail a plan do not use it).
NEGLIGIBLE_SHARE = 0.0005


def percent(share: float) -> str:
    """A share as a percentage to 0.1%, never ``0.0%`` or ``100.0%`` unless it is exactly 0 or 1.

    A message that reports a sliver as ``0.0%`` says nothing (or something false): it reads
    ``< 0.1%`` instead, and ``> 99.9%`` for a share just short of all.
    """
    if 0.0 < share < NEGLIGIBLE_SHARE:
        return "< 0.1%"
    if 1.0 - NEGLIGIBLE_SHARE <= share < 1.0:
        return "> 99.9%"
    return f"{share:.1%}"


def cell_list(cells: Any, limit: int = 12) -> str:
    """``"3, 7, 12"`` for messages, cut after ``limit`` cells with the total count."""
    items = [str(int(c)) if isinstance(c, (int, np.integer)) else str(c) for c in cells]
    text = ", ".join(items[:limit])
    return text + (f" … ({len(items)} in all)" if len(items) > limit else "")


def ragged(coords: Any, offsets: Any, width: int | None, name: str, count: int, dtype: Any = float):
    """Check a coords + offsets pair (DESIGN §3.1) and return both, read-only.

    Item ``c`` is ``coords[offsets[c]:offsets[c + 1]]``; ``offsets`` has ``count + 1``
    non-decreasing entries from 0 to ``len(coords)``.

    Parameters
    ----------
    coords : array_like, shape (M,) or (M, width)
        The rows of every item, concatenated (``cell_A`` rows, ``cell_vertices`` in map
        units, ...); converted to ``dtype``.
    offsets : array_like of int, shape (count + 1,)
        Where each item's rows begin in ``coords``; converted to int64.
    width : int or None
        Columns of each row (2 for points and normals); None for a 1-d ``coords``.
    name : str
        The entry's name (``"cell_A"``), as the error names it (``"cell_A offsets"`` for
        the offsets).
    count : int
        Number of items (C, the cells).
    dtype : numpy dtype, default float
        dtype of ``coords`` (float64 for coordinates, ``bool`` for flags).

    Returns
    -------
    coords, offsets : ndarray
        Read-only copies, ``coords`` of ``dtype`` and ``offsets`` of int64.

    Raises
    ------
    ArtifactError
        A wrong shape (of ``coords``, or ``offsets`` not of ``count + 1`` entries), or offsets
        that do not rise from 0 to ``len(coords)``.
    """
    shape = (None,) if width is None else (None, width)
    coords = frozen_array(coords, dtype, shape, name)
    offsets = frozen_array(offsets, np.int64, (count + 1,), f"{name} offsets")
    problem = ragged_problem(coords, offsets)
    if problem is not None:
        raise ArtifactError(problem, field=f"{name} offsets")
    return coords, offsets


@dataclass(frozen=True, eq=False)  # arrays inside: identity equality, a hash that works
class Cells:
    """Convex cells with their CLF and CBF rows, one per tree node (``cells.npz``, ALGORITHMS §4).

    C cells, R half-plane rows, V vertices, H barrier rows, L landmarks. Cell ``c``
    is ``{x : cell_A[r] @ x <= cell_b[r]}`` for ``r`` in its row range; rows are the
    outward unit normals of the CCW polygon edges, row ``q`` for edge ``v_q → v_{q+1}``.

    Attributes
    ----------
    map : Map
        The map.
    nodes, parent, collision_samples : ndarray, shapes (N, 2), (N,), (S, 2)
        The simplified tree the cells were cut along.
    cell_node : ndarray of int64, shape (C,)
        Node owning each cell (``cell_node[c] == c``; node 0's cell is the goal cell).
    cell_A, cell_b, cell_row_offsets : ndarray, shapes (R, 2), (R,), (C + 1,)
        Half-planes of each cell.
    cell_vertices, cell_vertex_offsets : ndarray, shapes (V, 2), (C + 1,)
        The same cells as CCW polygons (aligned with the rows).
    exit_point, exit_dir : ndarray, shape (C, 2)
        ``x_j`` and unit ``z`` into the cell: ``V(x) = z·(x − x_j)``; zeros for the goal cell.
    cbf_A, cbf_b, cbf_offsets : ndarray, shapes (H, 2), (H,), (C + 1,)
        Barrier rows ``h(x) = cbf_A @ x + cbf_b``, safe where ``h >= 0``.
    cell_landmarks : ndarray of bool, shape (C, L)
        Landmarks each cell's controller uses.
    fixed_landmark : ndarray of int64, shape (C,)
        Landmark ``f`` that rescales bearings in each cell (ALGORITHMS §5.5).
    s_min, s_max : ndarray, shape (C,)
        Exact smallest and largest distance from ``l_f`` to the cell (map units).
    cell_flags : ndarray of int64, shape (C,)
        :class:`CellFlag` bits.
    certificate : {"funnel", "paper"}
        ``funnel``: every cell is obstacle-free and its exit face lies in its parent cell, so the
        certificates compose (ALGORITHMS §11); ``paper``: the §4 cells, per-cell certificates only.
    cell_exit_row : ndarray of int64, shape (C,)
        Index of the exit row among each cell's own rows (local, 0-based); ``-1`` for the goal cell.
    cell_rank : ndarray, shape (C,)
        Rank of the switching policy: the cost-to-go of the cell's node (0 for the goal cell).
    exit_inset : ndarray, shape (C,)
        ``δ_e,c``: cell c's exit face lies in its parent cell eroded by this (map units,
        ALGORITHMS §12.3; 0 for ``paper``); NaN for the goal cell.
    node_added : ndarray of bool, shape (N,)
        Nodes added by densification (ALGORITHMS §11.5), not by the tree stages.
    free_coverage : float
        ``area(D) / area(F)`` of the reached part of ``F`` as built (ALGORITHMS §12.7; NaN for
        ``paper``: its cells are not a certified domain).
    lookahead : float
        ``λ`` the cells were built for (map units, ALGORITHMS §12.6): the map's obstacles and
        walls are inflated by ``ρ + λ``; 0 for a robot that is its own reference point.
    stats : dict
        Statistics for the manifest.
    """

    map: Map
    nodes: np.ndarray
    parent: np.ndarray
    collision_samples: np.ndarray
    cell_node: np.ndarray
    cell_A: np.ndarray
    cell_b: np.ndarray
    cell_row_offsets: np.ndarray
    cell_vertices: np.ndarray
    cell_vertex_offsets: np.ndarray
    exit_point: np.ndarray
    exit_dir: np.ndarray
    cbf_A: np.ndarray
    cbf_b: np.ndarray
    cbf_offsets: np.ndarray
    cell_landmarks: np.ndarray
    fixed_landmark: np.ndarray
    s_min: np.ndarray
    s_max: np.ndarray
    cell_flags: np.ndarray
    certificate: str
    cell_exit_row: np.ndarray
    cell_rank: np.ndarray
    exit_inset: np.ndarray
    node_added: np.ndarray
    free_coverage: float
    lookahead: float = 0.0
    stats: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stats", freeze(dict(self.stats)))
        _check_cell_arrays(self)
        dims = {"C": len(self.cell_node), "N": len(self.nodes)}
        put = object.__setattr__
        _freeze(self, "cells", ("cell_flags",), dims)
        put(self, "certificate", str(self.certificate))
        _freeze(self, "cells", ("cell_exit_row", "cell_rank", "node_added", "exit_inset"), dims)
        put(self, "free_coverage", float(self.free_coverage))
        put(self, "lookahead", float(self.lookahead))
        check_cells_form(self)  # the robot's loader runs the same checks (runtime.invariants)

    @property
    def is_funnel(self) -> bool:
        """Whether the cells compose (ALGORITHMS §11)."""
        return self.certificate == "funnel"

    @property
    def n_cells(self) -> int:
        return len(self.cell_node)

    def flagged(self, flag: CellFlag) -> list[int]:
        """Indices of the cells carrying ``flag``."""
        return np.flatnonzero(self.cell_flags & flag).tolist()

    def vertices(self, c: int) -> np.ndarray:
        """CCW vertices of cell ``c``, shape (p, 2)."""
        return self.cell_vertices[self.cell_vertex_offsets[c] : self.cell_vertex_offsets[c + 1]]

    def rows(self, c: int) -> tuple[np.ndarray, np.ndarray]:
        """``(A, b)`` of cell ``c``, shapes (p, 2) and (p,)."""
        r0, r1 = self.cell_row_offsets[c], self.cell_row_offsets[c + 1]
        return self.cell_A[r0:r1], self.cell_b[r0:r1]

    def barrier(self, c: int) -> tuple[np.ndarray, np.ndarray]:
        """Barrier rows ``(n, q)`` of cell ``c`` (``h = n @ x + q``), shapes (h, 2) and (h,)."""
        r0, r1 = self.cbf_offsets[c], self.cbf_offsets[c + 1]
        return self.cbf_A[r0:r1], self.cbf_b[r0:r1]

    def arrays(self) -> dict[str, np.ndarray]:
        """The data entries of ``cells.npz`` (without ``manifest`` and ``map``)."""
        return {name: _entry(getattr(self, name)) for name in CELL_KEYS}


#: The quantiles of :func:`tolerance_by_area`, by name.
AREA_QUANTILES = {"p10": 0.1, "median": 0.5, "p90": 0.9}


def tolerance_by_area(cells: Cells, usable: np.ndarray) -> dict[str, float]:
    """The distribution of ``τ_c`` over ``D`` by area (ALGORITHMS §12.4): its minimum and quantiles, map units.

    Each cell weighs by its own area (a point of several cells counts in each: the policy may
    use any of them once the robot is in it). Cells without a finite ``τ_c`` are left out.

    Parameters
    ----------
    cells : Cells
        The cells (their polygons give the areas).
    usable : ndarray, shape (C,)
        ``τ_c`` of each cell (map units).

    Returns
    -------
    dict
        ``{"min", "p10", "median", "p90"}``; NaN values when no cell has a finite ``τ_c``.
    """
    tau = np.asarray(usable, float)
    keep = np.isfinite(tau)
    if not keep.any():
        return {"min": math.nan, **{k: math.nan for k in AREA_QUANTILES}}
    order = np.argsort(tau[keep], kind="stable")
    values, weight = tau[keep][order], np.cumsum(np.abs(cell_areas(cells))[keep][order])
    out = {"min": float(values[0])}
    for name, q in AREA_QUANTILES.items():
        out[name] = float(values[min(int(np.searchsorted(weight, q * weight[-1])), len(values) - 1)])
    return out


def _entry(value: Any) -> Any:
    """A data entry as artifacts store it: texts stay ``str`` (a 0-d text entry), the rest arrays."""
    return value if isinstance(value, str) else np.asarray(value)


#: Data keys common to ``cells.npz`` and ``plan.npz`` besides ``map`` (DESIGN §3.2–3.3).
CELL_KEYS = _data_keys("cells")


def _check_cell_arrays(obj: Any) -> None:
    """The cell arrays of ``obj`` (a :class:`Cells`) as read-only arrays of their declared dtypes and shapes;
    what they must then satisfy is :func:`~bearnav_cli.runtime.invariants.check_cells_form`'s."""
    _freeze(obj, "cells", ("nodes",), {})
    n = len(obj.nodes)
    c = len(np.asarray(obj.cell_node))
    dims = {"N": n, "C": c, "L": len(obj.map.landmarks)}
    _freeze(obj, "cells", ("parent", "collision_samples", "cell_node", "exit_point", "exit_dir", "fixed_landmark",
                           "s_min", "s_max"), dims)  # fmt: skip
    for coords, values, offsets in (
        ("cell_A", "cell_b", "cell_row_offsets"),
        ("cbf_A", "cbf_b", "cbf_offsets"),
        ("cell_vertices", None, "cell_vertex_offsets"),
    ):
        entry = ENTRIES["cells"][coords]
        a, off = ragged(getattr(obj, coords), getattr(obj, offsets), entry.shape[1], coords, c, entry.numpy_dtype)
        object.__setattr__(obj, coords, a)
        object.__setattr__(obj, offsets, off)
        if values is not None:
            _freeze(obj, "cells", (values,), {entry.shape[0]: len(a)})
    _freeze(obj, "cells", ("cell_landmarks",), dims)


#: Data keys that ``plan.npz`` adds to the cell keys (DESIGN §3.2–3.3).
PLAN_KEYS = tuple(name for name in ENTRIES["plan"] if name not in ENTRIES["cells"])


@dataclass(frozen=True, eq=False)  # arrays inside: identity equality, a hash that works
class Plan:
    """Cells with a synthesised, certified controller each (``plan.npz``, DESIGN §3.2, ALGORITHMS §5).

    Attributes
    ----------
    cells : Cells
        The decomposition the controllers were synthesised for.
    gain : ndarray, shape (C, 2, 2L)
        ``u(x) = gain[c] @ (landmarks − x).ravel()``; unused landmarks' columns are zero.
    c_h, c_v, u_max : ndarray, shape (C,)
        Constants the certificate is stated with; ``c_h`` is NaN in a cell without barrier rows.
    margin_h, margin_v : ndarray, shape (C,)
        Worst-case CBF and CLF slack over the cell (≤ 0 holds; NaN where no row).
    status : ndarray of int8, shape (C,)
        :class:`CellStatus` of each cell.
    goal_tolerance : float
        Success radius around the goal (map units).
    tolerance : ndarray, shape (C,)
        ``δ_c``, the position error each cell's certificate tolerates (ALGORITHMS §11.4, map
        units); ``+inf`` where the field is constant (``M = 0``: its margins do not depend on
        the position); NaN where none (``paper`` cells).
    usable_tolerance : ndarray, shape (C,)
        ``τ_c = min(δ_c, δ_e,c / 2)`` (``δ_c`` in the goal cell), finite in every funnel cell:
        the error radius under which the runtime may move in cell c (ALGORITHMS §12.3, map
        units); NaN for ``paper``.
    plan_tolerance : float
        ``min_c τ_c`` (NaN for ``paper``).
    stats : dict
        Statistics for the manifest.
    """

    cells: Cells
    gain: np.ndarray
    c_h: np.ndarray
    c_v: np.ndarray
    u_max: np.ndarray
    margin_h: np.ndarray
    margin_v: np.ndarray
    status: np.ndarray
    goal_tolerance: float
    tolerance: np.ndarray
    usable_tolerance: np.ndarray
    plan_tolerance: float
    stats: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stats", freeze(dict(self.stats)))
        dims = {"C": self.cells.n_cells, "L": len(self.cells.map.landmarks)}
        _freeze(self, "plan", ("gain", "c_h", "c_v", "u_max", "margin_h", "margin_v", "status"), dims)
        object.__setattr__(self, "goal_tolerance", float(self.goal_tolerance))
        _freeze(self, "plan", ("tolerance", "usable_tolerance"), dims)
        object.__setattr__(self, "plan_tolerance", float(self.plan_tolerance))
        check_plan_form(self)  # the robot's loader runs the same checks (runtime.invariants)

    @property
    def map(self) -> Map:
        return self.cells.map

    @property
    def landmarks(self) -> np.ndarray:
        return self.cells.map.landmarks

    def arrays(self) -> dict[str, np.ndarray]:
        """The data entries of ``plan.npz`` (without ``manifest`` and ``map``): exactly DESIGN §3.2."""
        out = self.cells.arrays()
        out.update({name: np.asarray(getattr(self, name)) for name in PLAN_KEYS})  # landmarks: the map's
        return out


class Outcome(enum.IntEnum):
    """How a run of ``bearnav simulate`` ended (``sim.npz`` ``outcome``, ALGORITHMS §7.4)."""

    SUCCESS = 0  # within goal_tolerance of the goal
    COLLISION = 1  # a step segment met the inflated obstacles or left the bounds (or the start was not free)
    STALL = 2  # field below 1e-6·u_max, or no net progress over the progress window with a fix
    TIMEOUT = 3  # more than max_steps steps
    LOST = 4  # fewer than two usable landmarks for longer than hold_time


#: Data keys of ``sim.npz`` besides ``map`` and ``manifest`` (DESIGN §3; ``ENTRIES["simulation"]``).
SIMULATION_KEYS = _data_keys("simulation")


@dataclass(frozen=True, eq=False)  # arrays inside: identity equality, a hash that works
class Simulation:
    """The closed-loop runs of ``bearnav simulate`` (``sim.npz``; metrics in ``sim.json``), R runs.

    What :func:`bearnav_cli.stages.simulate.rollout` returns (``stats`` empty) and what
    :func:`~bearnav_cli.stages.simulate.run` saves (``stats`` the metrics).

    Attributes
    ----------
    map : Map
        The plan's map (the world the robots drove in may differ: ``rollout(world=...)``).
    starts, final_position : ndarray, shape (R, 2)
        Where each run began and ended (map units).
    outcome : ndarray of int8, shape (R,)
        :class:`Outcome` values: 0 success, 1 collision, 2 stall, 3 timeout, 4 lost (ALGORITHMS §7.4).
    steps, left_cell, approach_steps, hold_steps, certified_steps : ndarray of int64, shape (R,)
        Euler steps; relocations through a side face (§7.3); steps driven straight to a tree node from
        outside every safe set; steps without a usable reconstruction (§7.5); steps covered by the
        composed certificate (§11.4; 0 for ``paper`` plans).
    start_in_domain : ndarray of bool, shape (R,)
        The start lies in the certified domain ``D`` (a funnel plan's cells, ALGORITHMS §11.3).
    final_cell, max_steps : ndarray of int64, shape (R,)
        Active cell at the end (``-1`` if the start was not free or never had a fix); step limit of the run.
    time, path_length, route_length, min_clearance : ndarray, shape (R,)
        Seconds (``steps · dt``); path length; the tree route from the start (``‖x₀ − x_n‖ +
        cost(n)``); the smallest distance from the inflated obstacles and the walls (map units).
    trajectory_coords, trajectory_cells, trajectory_heading, trajectory_offsets : ndarray
        Shapes (P, 2), (P,), (P,), (R + 1,): run ``r`` is ``coords[o[r]:o[r + 1]]`` (start first,
        ``steps + 1`` points) with the cell whose field moved the robot on from each point (the active
        cell at the end for the last point) and the camera heading (rad); empty when not recorded.
    nodes, parent : ndarray, shapes (N, 2), (N,)
        The simplified tree the plan was built on.
    cell_vertices, cell_vertex_offsets, cell_status : ndarray, shapes (V, 2), (C + 1,), (C,)
        The plan's cells and their synthesis status (for plots).
    speed, dt, eps_sw, goal_tolerance : float
        The loop constants used: the speed ``dt`` and ``eps_sw`` are scaled by (map units / s), the
        Euler step (s), the switching radius and the success radius (map units).
    stats : dict
        The metrics of ``sim.json`` (empty from ``rollout``).
    """

    map: Map
    starts: np.ndarray
    outcome: np.ndarray
    steps: np.ndarray
    time: np.ndarray
    path_length: np.ndarray
    route_length: np.ndarray
    left_cell: np.ndarray
    approach_steps: np.ndarray
    hold_steps: np.ndarray
    certified_steps: np.ndarray
    start_in_domain: np.ndarray
    min_clearance: np.ndarray
    final_position: np.ndarray
    final_cell: np.ndarray
    max_steps: np.ndarray
    trajectory_coords: np.ndarray
    trajectory_cells: np.ndarray
    trajectory_heading: np.ndarray
    trajectory_offsets: np.ndarray
    nodes: np.ndarray
    parent: np.ndarray
    cell_vertices: np.ndarray
    cell_vertex_offsets: np.ndarray
    cell_status: np.ndarray
    speed: float
    dt: float
    eps_sw: float
    goal_tolerance: float
    stats: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stats", freeze(dict(self.stats)))
        arrays = tuple(name for name in SIMULATION_KEYS if ENTRIES["simulation"][name].ndim)
        for name in SIMULATION_KEYS:
            if name not in arrays:
                object.__setattr__(self, name, float(getattr(self, name)))
        _freeze(self, "simulation", arrays, {"R": len(np.asarray(self.outcome))})
        points = len(self.trajectory_coords)
        if len(self.trajectory_cells) != points or len(self.trajectory_heading) != points:
            raise ArtifactError("trajectory arrays differ in length", field="trajectory_cells")
        if points and (self.trajectory_offsets[0] != 0 or self.trajectory_offsets[-1] != points):
            raise ArtifactError("offsets do not span the trajectory points", field="trajectory_offsets")

    def __len__(self) -> int:
        return len(self.outcome)

    def trajectory(self, r: int) -> np.ndarray:
        """Positions of run ``r``, shape (steps + 1, 2) (empty when not recorded)."""
        o = self.trajectory_offsets
        return self.trajectory_coords[o[r] : o[r + 1]]

    def cells_along(self, r: int) -> np.ndarray:
        """Cells along run ``r``, aligned with :meth:`trajectory`."""
        o = self.trajectory_offsets
        return self.trajectory_cells[o[r] : o[r + 1]]

    def counts(self) -> dict[str, int]:
        """Number of runs per outcome name (every outcome listed)."""
        return {o.name.lower(): int(np.count_nonzero(self.outcome == o)) for o in Outcome}

    @property
    def success_rate(self) -> float:
        """Fraction of successful runs (NaN without runs)."""
        return float(np.mean(self.outcome == Outcome.SUCCESS)) if len(self) else math.nan

    def success_rate_of(self, runs: np.ndarray) -> float:
        """Fraction of successful runs among ``runs`` (bool mask, shape (R,)); NaN when it selects none."""
        done = self.outcome[runs] == Outcome.SUCCESS
        return float(np.mean(done)) if len(done) else math.nan

    @property
    def certified_fraction(self) -> float:
        """Steps covered by the composed certificate over all steps (ALGORITHMS §11.4; 0 without steps)."""
        return float(self.certified_steps.sum() / max(1, self.steps.sum()))

    def arrays(self) -> dict[str, np.ndarray]:
        """The data entries of ``sim.npz`` (without ``manifest`` and ``map``)."""
        return {name: np.asarray(getattr(self, name)) for name in SIMULATION_KEYS}


def _sim_cells_problem(sim: Simulation) -> str | None:
    return _offsets_problem(sim.cell_vertex_offsets, len(sim.cell_vertices), len(sim.cell_status)) or (
        _finite_problem(sim.cell_vertices)
    )


def _sim_trajectory_problem(sim: Simulation) -> str | None:
    return _offsets_problem(sim.trajectory_offsets, len(sim.trajectory_coords), len(sim.outcome))


#: What ``sim.npz`` must satisfy (besides its map's invariants).
SIMULATION_INVARIANTS: tuple[Invariant, ...] = (
    Invariant("parent", "-1 exactly at node 0, indices in range, every chain ends at node 0 (no cycle)",
              lambda s: _tree_problem(s.nodes, s.parent)),
    Invariant("nodes", "finite; node 0 is the goal", lambda s: _nodes_problem(s)),
    Invariant("outcome", "0 to 4", lambda s: _in_range(s.outcome, 0, 4)),
    Invariant("steps", "zero or positive", lambda s: _in_range(s.steps, 0, np.iinfo(np.int64).max)),
    Invariant("starts", "finite", lambda s: _finite_problem(s.starts)),
    Invariant("final_position", "finite", lambda s: _finite_problem(s.final_position)),
    Invariant("time", "finite, zero or positive", lambda s: _at_least(s.time, 0.0, "zero or positive")),
    Invariant("path_length", "finite, zero or positive", lambda s: _at_least(s.path_length, 0.0, "zero or positive")),
    Invariant("min_clearance", "not NaN", lambda s: None if not np.isnan(s.min_clearance).any() else "contains NaN"),
    Invariant("trajectory_offsets", "R + 1 offsets from 0, never decreasing, to the number of points",
              _sim_trajectory_problem),
    Invariant("trajectory_coords", "finite", lambda s: _finite_problem(s.trajectory_coords)),
    Invariant("trajectory_heading", "finite", lambda s: _finite_problem(s.trajectory_heading)),
    Invariant("trajectory_cells", "-1 (no cell) or a cell index",
              lambda s: _in_range(s.trajectory_cells, -1, len(s.cell_status) - 1)),
    Invariant("cell_status", "0 to 4", lambda s: _in_range(s.cell_status, 0, 4)),
    Invariant("cell_vertex_offsets", "C + 1 offsets from 0, never decreasing, to the number of vertices; finite "
              "vertices", _sim_cells_problem),
    Invariant("certified_steps", "zero or positive, at most steps",
              lambda s: _in_range(s.certified_steps, 0, np.iinfo(np.int64).max)
              or (None if (s.certified_steps <= s.steps).all() else "more than steps")),
    Invariant("final_cell", "-1 (no cell) or a cell index",
              lambda s: _in_range(s.final_cell, -1, len(s.cell_status) - 1)),
    Invariant("dt", "finite and positive", lambda s: _positive_scalar(s.dt)),
    Invariant("speed", "finite and positive", lambda s: _positive_scalar(s.speed)),
    Invariant("eps_sw", "finite and positive", lambda s: _positive_scalar(s.eps_sw)),
    Invariant("goal_tolerance", "finite and positive", lambda s: _positive_scalar(s.goal_tolerance)),
)  # fmt: skip


def _positive_scalar(value: float) -> str | None:
    return None if math.isfinite(value) and value > 0 else f"got {value:g}"


#: The invariants of each artifact kind (``artifacts.KINDS`` names); every kind but ``map`` also checks
#: its embedded map against :data:`MAP_INVARIANTS` (fields ``map.NAME``).
INVARIANTS: dict[str, tuple[Invariant, ...]] = {
    "map": MAP_INVARIANTS,
    "tree": TREE_INVARIANTS,
    "simplified": TREE_INVARIANTS,
    "cells": CELLS_INVARIANTS,
    "plan": CELLS_INVARIANTS + PLAN_INVARIANTS,
    "simulation": SIMULATION_INVARIANTS,
}


def validate_artifact(kind: str, artifact: Any, check_map: bool = True) -> None:
    """Check what ``artifact`` (of ``kind``) means: its map's invariants, then its own.

    Parameters
    ----------
    kind : {"map", "tree", "simplified", "cells", "plan", "simulation"}
        The artifact's kind, a key of :data:`INVARIANTS`.
    artifact : Map, Tree, Cells, Plan or Simulation
        The artifact to check; a plan is checked as its ``cells``, then as a plan.
    check_map : bool, default True
        Also run :data:`MAP_INVARIANTS` on the map (its fields named ``map.…``); False when
        the map was checked already (a loader that read it once).

    Raises
    ------
    ArtifactError
        Naming the field (``map.goal``, ``parent`` ...) and what is wrong.
    """
    if kind == "map":
        if check_map:
            validate(MAP_INVARIANTS, artifact)
        return
    if check_map:
        validate(MAP_INVARIANTS, artifact.map, prefix="map.")
    if kind == "plan":
        validate(CELLS_INVARIANTS, artifact.cells)
        validate(PLAN_INVARIANTS, artifact)
        return
    validate(INVARIANTS[kind], artifact)


def replace(artifact: Any, **changes: Any) -> Any:
    """:func:`dataclasses.replace` for artifacts (they are immutable); ``map=`` works on every one.

    Parameters
    ----------
    artifact : Map, Tree, Cells, Plan or Simulation
        The artifact to copy.
    **changes
        Fields to change; a :class:`Plan`'s ``map`` is its cells' (``map=`` replaces that).

    Returns
    -------
    Any
        The new artifact, checked by its type.
    """
    if isinstance(artifact, Plan) and "map" in changes:
        changes["cells"] = dataclasses.replace(changes.get("cells", artifact.cells), map=changes.pop("map"))
    return dataclasses.replace(artifact, **changes)
