"""The tree of ``tree.npz`` and ``simplified.npz``: :class:`Tree`, its data keys and its invariants."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bearnav_cli.datatypes.frozen import ArraysOnMap, data_keys, freeze, freeze_fields
from bearnav_cli.datatypes.map_ import Map
from bearnav_cli.errors import ArtifactError
from bearnav_cli.runtime.invariants import TREE_SHAPE as _TREE_SHAPE
from bearnav_cli.runtime.invariants import Invariant
from bearnav_cli.runtime.invariants import finite_problem as _finite_problem
from bearnav_cli.runtime.invariants import first as _first

__all__ = ["Tree", "TREE_INVARIANTS", "TREE_KEYS"]


@dataclass(frozen=True, eq=False)  # arrays inside: identity equality, a hash that works
class Tree(ArraysOnMap):
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
        freeze_fields(self, "tree", ("nodes",), {})
        n = len(self.nodes)
        freeze_fields(self, "tree", ("parent", "cost", "collision_samples"), {"N": n})
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
TREE_KEYS = data_keys("tree")


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
