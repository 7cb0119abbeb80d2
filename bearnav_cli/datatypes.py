"""Typed, immutable containers for every artifact (DESIGN §3).

Each artifact is a frozen dataclass of numpy arrays plus a few scalars. The
constructors check shapes and dtypes and make the arrays read-only, so an
artifact cannot be changed after it is built. Serialisation lives in
``artifacts.py``; this module knows nothing about files.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bearnav_cli.errors import ArtifactError


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


@dataclass(frozen=True)
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
        object.__setattr__(
            self, "holes", tuple(frozen_array(h, float, (None, 2), "holes") for h in self.holes)
        )

    def to_json(self) -> dict:
        return {"exterior": self.exterior.tolist(), "holes": [h.tolist() for h in self.holes]}

    @classmethod
    def from_json(cls, data: dict) -> Polygon:
        return cls(np.asarray(data["exterior"], float), tuple(np.asarray(h, float) for h in data["holes"]))


@dataclass(frozen=True)
class Map:
    """The normalised map (schema ``bearnav.map/1``, DESIGN §3.2, ALGORITHMS §1).

    Attributes
    ----------
    name : str
        Map name (also the default plan folder).
    bounds : ndarray, shape (4,)
        ``[xmin, ymin, xmax, ymax]`` in map units.
    robot_radius : float
        Inflation radius ρ already applied to ``obstacles``.
    goal : ndarray, shape (2,)
        Goal position, the root of every tree.
    starts : ndarray, shape (S, 2)
        Default start positions for simulation.
    landmark_ids : tuple of str, length L
        Landmark identifiers (AprilTag ids, say).
    landmarks : ndarray, shape (L, 2)
        Landmark positions.
    obstacles : tuple of Polygon
        Configuration-space obstacles ``O`` (inflated by ``robot_radius``).
    raw_obstacles : tuple of Polygon
        Obstacles before inflation, used for line of sight.
    params : dict
        Per-stage parameter overrides from the map file, ``{stage: {name: value}}``.
    source : dict
        ``{"file": name, "sha256": hash}`` of the input the map came from.
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

    def __post_init__(self) -> None:
        object.__setattr__(self, "bounds", frozen_array(self.bounds, float, (4,), "bounds"))
        object.__setattr__(self, "goal", frozen_array(self.goal, float, (2,), "goal"))
        object.__setattr__(self, "starts", frozen_array(self.starts, float, (None, 2), "starts"))
        object.__setattr__(self, "landmarks", frozen_array(self.landmarks, float, (None, 2), "landmarks"))
        object.__setattr__(self, "landmark_ids", tuple(str(i) for i in self.landmark_ids))
        if len(self.landmark_ids) != len(self.landmarks):
            raise ArtifactError("one id per landmark expected", field="landmarks")
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

    def to_json(self) -> dict:
        """The ``map.json`` document without its manifest."""
        return {
            "name": self.name,
            "bounds": self.bounds.tolist(),
            "robot_radius": float(self.robot_radius),
            "goal": self.goal.tolist(),
            "starts": self.starts.tolist(),
            "landmarks": [
                {"id": i, "position": p.tolist()} for i, p in zip(self.landmark_ids, self.landmarks, strict=True)
            ],
            "obstacles": [p.to_json() for p in self.obstacles],
            "raw_obstacles": [p.to_json() for p in self.raw_obstacles],
            "params": self.params,
            "source": self.source,
        }

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
            )
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, ArtifactError):
                raise
            raise ArtifactError(f"malformed map ({type(exc).__name__}: {exc})", field="map") from exc


@dataclass(frozen=True)
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
        nodes = frozen_array(self.nodes, float, (None, 2), "nodes")
        n = len(nodes)
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "parent", frozen_array(self.parent, np.int64, (n,), "parent"))
        object.__setattr__(self, "cost", frozen_array(self.cost, float, (n,), "cost"))
        object.__setattr__(
            self, "collision_samples", frozen_array(self.collision_samples, float, (None, 2), "collision_samples")
        )
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
        return {
            "nodes": self.nodes,
            "parent": self.parent,
            "cost": self.cost,
            "collision_samples": self.collision_samples,
        }


def replace(artifact: Any, **changes: Any) -> Any:
    """Shorthand for :func:`dataclasses.replace` (artifacts are immutable)."""
    return dataclasses.replace(artifact, **changes)
