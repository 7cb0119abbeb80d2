"""Stage ``simplify``: PPR, cut-the-leaves and remove-crossings to a fixed point (ALGORITHMS §3).

Each round runs PPR (shortcut to the grandparent, breadth-first), CtL (keep one
leaf per parent), RC (split properly crossing edges at their crossing point)
and CtL again; rounds repeat until nothing changes or ``max_rounds`` is reached.
Collision samples are passed through untouched.

Fixed point of RC. A round ends with CtL, and CtL can *expose* crossings: RC skips a
crossing whose point lies within ``tol`` of a node (ALGORITHMS §3, edge cases), and
that node is an earlier RC node (in every case we traced) whose children have left
it, hopped over by PPR along the very edges that cross there or re-hung by a later
RC split; once it is a leaf, CtL deletes it and the crossing becomes proper. RC
removes it in the next round, where the same can happen to the next edge through
that point, one round at a time. When
``max_rounds`` stops the loop during such a cascade, the rounds are followed by
*finishing passes* of RC | CtL only (:func:`_finish`), which never lengthen a route
and never add an edge that is not a piece of an existing one, until RC finds nothing
and CtL cuts nothing. ``stats["crossings_remaining"]`` is then 0, and
``stats["crossings_at_nodes"]``, the crossings RC leaves by definition, is the number of
pairs the last RC found blocked by a node (:func:`~bearnav_cli.crossings.split_crossings` keeps them, the same
pairs a fresh scan finds); only when the pass bound stops the passes are both counted by
a fresh scan of all edges (:func:`~bearnav_cli.crossings.count_crossings`).

Indices: deleted leaves are dropped by an order-preserving compaction and RC
appends its new node after all others, so every "ascending index" rule sees the
same order as with stable indices, and the final renumbering (root → 0, then
ascending old index) is already in place.

Speed: PPR is vectorised per BFS level (exactly the sequential result, see
:func:`_shortcut`), CtL is pure numpy. RC's first pass scans all edge pairs whose
boxes meet (a ``shapely.STRtree``) and keeps, per edge, the edges that may meet it
(:class:`~bearnav_cli.crossings.Neighbours`), against which it re-tests only the split edges; each later pass
scans only the edges PPR changed since and the pairs the previous pass found blocked by a
node (:func:`~bearnav_cli.crossings.split_crossings`), and the result is the one a scan of all pairs gives. The
number of crossings RC removes still grows faster than the number of nodes (PPR's long
edges cross more often in a denser tree), so RC does too, at a fraction of a millisecond
per insertion.
"""

from __future__ import annotations

import logging
from typing import Callable

import numpy as np

from bearnav_cli import verdicts
from bearnav_cli.crossings import carry, count_crossings, split_crossings
from bearnav_cli.datatypes import Tree
from bearnav_cli.errors import ArtifactError
from bearnav_cli.geometry import FreeSpace, barrier_margin
from bearnav_cli.params.simplify import Params

__all__ = [
    "bfs_levels",
    "MAX_FINISH_PASSES",
    "problems",
    "RECONNECT_NEIGHBOURS",
    "run",
    "summary",
    "tree_costs",
    "VERSION",
]

VERSION = 2  # 2: finishing RC | CtL passes when max_rounds stops the loop; crossings_remaining
#: Output nodes tried per discarded node for the ``discarded_reconnectable`` statistic.
RECONNECT_NEIGHBOURS = 8
#: Bound on the finishing RC | CtL passes (each strictly shortens the total edge length, so they end;
#: a cascade ends in a handful of passes in practice, see :func:`_finish`).
MAX_FINISH_PASSES = 100
log = logging.getLogger(__name__)


def bfs_levels(parent: np.ndarray) -> list[np.ndarray]:
    """Breadth-first levels from the root; within a level, in BFS queue order.

    Parameters
    ----------
    parent : ndarray of int, shape (N,)
        ``-1`` at node 0 only.

    Returns
    -------
    list of ndarray of int
        ``levels[d]`` holds the nodes at depth ``d``; concatenated they are the
        BFS order with children visited in ascending index.
    """
    n = len(parent)
    child = np.argsort(parent[1:], kind="stable") + 1  # grouped by parent, ascending index inside
    counts = np.bincount(parent[1:], minlength=n)
    start = np.concatenate([[0], np.cumsum(counts)])
    levels = [np.zeros(1, np.int64)]
    seen = 1
    while True:
        front = levels[-1]
        c = counts[front]
        total = int(c.sum())
        if total == 0:
            break
        offsets = np.repeat(start[front] - (np.cumsum(c) - c), c) + np.arange(total)
        levels.append(child[offsets])
        seen += total
    if seen != n:  # a node that never hangs below the root sits on a cycle
        raise ArtifactError(f"{n - seen} nodes do not reach the root (cycle)", field="parent")
    return levels


def tree_costs(nodes: np.ndarray, parent: np.ndarray, levels: list[np.ndarray]) -> np.ndarray:
    """Path length to the root of every node, computed level by level.

    Parameters
    ----------
    nodes : ndarray, shape (N, 2)
        Node positions (map units); node 0 is the root (the goal).
    parent : ndarray of int, shape (N,)
        Parent of each node, ``-1`` at the root.
    levels : list of ndarray of int
        The tree's breadth-first levels (:func:`bfs_levels` of ``parent``); a node's parent lies
        on the level before it, so its cost is final when the node is reached.

    Returns
    -------
    ndarray, shape (N,)
        Sum of the edge lengths from each node to the root (map units); 0 at the root.
    """
    cost = np.zeros(len(nodes))
    for level in levels[1:]:
        d = nodes[level] - nodes[parent[level]]
        cost[level] = cost[parent[level]] + np.hypot(d[:, 0], d[:, 1])
    return cost


def _shortcut(nodes: np.ndarray, parent: np.ndarray, space: FreeSpace, levels: list[np.ndarray]) -> int:
    """PPR in place: hop each node to its grandparent while that edge is free.

    Vectorised per BFS level, which gives exactly the sequential result: a node only
    ever moves to one of its ancestors, all of which sit on lower levels and were
    processed (hence final) before it, and two nodes of one level never read each
    other's parent. Returns the number of accepted hops.
    """
    hops = 0
    for level in levels[2:]:  # level 1 already hangs on the root
        active = level
        while active.size:
            q = parent[parent[active]]
            free = space.segments_free(nodes[active], nodes[q])
            active, q = active[free], q[free]
            parent[active] = q
            hops += active.size
            active = active[q != 0]
    return hops


def _cut_leaves(nodes: np.ndarray, parent: np.ndarray, mode: str) -> np.ndarray:
    """CtL: the mask of nodes to keep, shape (N,) bool.

    Leaf sets are taken once at the start, so the per-parent loop of the
    specification has no order dependence and becomes a grouped numpy sort.
    """
    n = len(parent)
    keep = np.ones(n, bool)
    has_child = np.zeros(n, bool)
    has_child[parent[1:]] = True
    leaves = np.flatnonzero(~has_child)
    leaves = leaves[leaves != 0]
    owner = parent[leaves]
    size = np.bincount(owner, minlength=n)
    crowded = size[owner] >= 2
    leaves, owner = leaves[crowded], owner[crowded]
    if leaves.size == 0:
        return keep
    grand = parent[owner]
    ref = np.where((grand >= 0)[:, None], nodes[owner] - nodes[np.maximum(grand, 0)], [1.0, 0.0])
    v = nodes[leaves] - nodes[owner]
    ang = np.arctan2(ref[:, 0] * v[:, 1] - ref[:, 1] * v[:, 0], ref[:, 0] * v[:, 0] + ref[:, 1] * v[:, 1])
    ang[ang == -np.pi] = np.pi  # atan2(-0, x<0) = -π; the specification's range is (−π, π]
    order = np.lexsort((leaves, ang, owner))
    leaves, owner = leaves[order], owner[order]
    pos = np.arange(leaves.size)
    first = np.maximum.accumulate(np.where(np.r_[True, owner[1:] != owner[:-1]], pos, 0))
    rank, count = pos - first, size[owner]
    kept = rank == count // 2 if mode == "middle" else (rank == 0) | (rank == count - 1)
    keep[leaves[~kept]] = False
    return keep


def _compact(keep: np.ndarray, *arrays: np.ndarray, parent: np.ndarray) -> tuple[np.ndarray, ...]:
    """Drop deleted nodes, preserving order; returns the kept ``arrays`` and the remapped parent."""
    new_index = np.cumsum(keep) - 1
    kept_parent = parent[keep]
    remapped = np.where(kept_parent >= 0, new_index[np.maximum(kept_parent, 0)], -1)
    return (*(a[keep] for a in arrays), remapped)


#: Largest number of point × node distances computed at once by :func:`_nearest_distances`.
_CHUNK = 1 << 20
#: Above this many point × node pairs, :func:`_nearest_distances` asks a k-d tree (a 20,000-iteration
#: tree has about 10⁴ discarded × 4·10³ kept nodes: 1 s by brute force, 0.05 s by the tree).
_KDTREE_PAIRS = 1 << 23


def _nearest_distances(points: np.ndarray, nodes: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest nodes of each point: distances and indices, shapes (n, k), ties to the lower index.

    Up to :data:`_KDTREE_PAIRS` pairs by chunked brute force, which beats building a k-d tree there
    and spares the command the import of scipy.spatial (a fifth of a second); above it, by
    ``scipy.spatial.cKDTree``, whose answers are re-ordered to the same tie rule (rows where the
    ``k``-th and the next distance tie are measured by brute force, so the answer is the same).
    """
    points = np.asarray(points, float).reshape(-1, 2)
    if len(points) * len(nodes) > _KDTREE_PAIRS and k < len(nodes):
        from scipy.spatial import cKDTree

        dist, index = cKDTree(nodes).query(points, k=k + 1)
        # (dist, index) order within each row: the tie rule of the brute force
        key = np.argsort(index, axis=1, kind="stable")
        dist, index = np.take_along_axis(dist, key, axis=1), np.take_along_axis(index, key, axis=1)
        key = np.argsort(dist, axis=1, kind="stable")
        dist, index = np.take_along_axis(dist, key, axis=1), np.take_along_axis(index, key, axis=1)
        tied = np.flatnonzero(dist[:, k - 1] == dist[:, k])
        dist, index = dist[:, :k].copy(), index[:, :k].copy()
        if tied.size:
            dist[tied], index[tied] = _brute_nearest(points[tied], nodes, k)
        return dist, index
    return _brute_nearest(points, nodes, k)


def _brute_nearest(points: np.ndarray, nodes: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_nearest_distances` by chunked brute force."""
    dist = np.empty((len(points), k))
    index = np.empty((len(points), k), np.int64)
    step = max(1, _CHUNK // max(1, len(nodes)))
    for s in range(0, len(points), step):
        d = points[s : s + step, None, :] - nodes[None, :, :]
        d = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1])
        # the k smallest by partition, then those k in order (ties: the lower index)
        part = (
            np.argpartition(d, k - 1, axis=1)[:, :k] if k < d.shape[1] else np.tile(np.arange(d.shape[1]), (len(d), 1))
        )
        part.sort(axis=1)
        near = np.take_along_axis(d, part, axis=1)
        order = np.take_along_axis(part, np.argsort(near, axis=1, kind="stable"), axis=1)
        index[s : s + step] = order
        dist[s : s + step] = np.take_along_axis(d, order, axis=1)
    return dist, index


def _finish(
    nodes, parent, cost, tol: float, cut, carried: tuple[np.ndarray, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int, bool, tuple[np.ndarray, np.ndarray]]:
    """RC | CtL until RC finds no crossing (or CtL cuts nothing after it): the fixed point of both.

    Run after the rounds when ``max_rounds`` stopped them while something still changed:
    the closing CtL of the last round may have deleted a node that hid crossings
    (see the module docstring). CtL never turns a node with children into a leaf
    (it keeps one leaf of each parent), so once it cuts nothing after an RC, RC's
    result (no proper crossing) stands and CtL's (one leaf per parent) too. Each RC
    insertion shortens the total edge length by more than ``tol`` and each cut by a
    leaf edge, so the passes end; ``MAX_FINISH_PASSES`` is a guard.

    Parameters
    ----------
    nodes, parent, cost
        The tree after the last round (``cost`` consistent, as RC trusts it).
    tol : float
    cut : callable
        ``cut(nodes, parent, cost) -> (nodes, cost, parent, keep)``: CtL and compaction.
    carried : (stale, blocked)
        What the last RC carries to this tree (:func:`~bearnav_cli.crossings.split_crossings`).

    Returns
    -------
    nodes, parent, cost, passes, insertions, done, carried
        ``done`` is False only if the guard stopped the passes; ``carried`` is what the last RC
        carries to the result (its blocked pairs are the result's when ``done``).
    """
    passes = insertions = 0
    while passes < MAX_FINISH_PASSES:
        passes += 1
        nodes, parent, cost, added, blocked = split_crossings(nodes, parent, cost, tol, carried)
        insertions += added
        carried = (np.zeros(len(nodes), bool), blocked)
        if added == 0:  # the tree is the previous CtL's output: CtL would cut nothing either
            return nodes, parent, cost, passes, insertions, True, carried
        size = len(nodes)
        nodes, cost, parent, keep = cut(nodes, parent, cost)
        carried = carry(carried, keep)
        if len(nodes) == size:
            return nodes, parent, cost, passes, insertions, True, carried
    return nodes, parent, cost, passes, insertions, False, carried


def _reconnectable(before: np.ndarray, after: np.ndarray, space: FreeSpace) -> float:
    """Share of the input nodes missing from the output that see one of their nearest output nodes.

    Nodes match by exact position; each discarded node tries its ``RECONNECT_NEIGHBOURS``
    nearest output nodes. Two batched segment tests: the nearest for all,
    then the others only for the nodes still unresolved (the answer is the same as
    testing all at once, for a fraction of the work). ``1.0`` if none was discarded.
    """
    key_b = before[:, 0] + 1j * before[:, 1]
    key_a = after[:, 0] + 1j * after[:, 1]
    gone = before[~np.isin(key_b, key_a)]
    if len(gone) == 0:
        return 1.0
    k = min(RECONNECT_NEIGHBOURS, len(after))
    nearest = _nearest_distances(gone, after, k)[1]
    seen = space.segments_free(gone, after[nearest[:, 0]])
    rest = np.flatnonzero(~seen)
    if k > 1 and rest.size:
        free = space.segments_free(np.repeat(gone[rest], k - 1, axis=0), after[nearest[rest, 1:].ravel()])
        seen[rest] = free.reshape(-1, k - 1).any(axis=1)
    return float(seen.mean())


def run(tree: Tree, params: Params = Params(), progress: Callable[[int, int], None] | None = None) -> Tree:
    """Simplify an RRT* tree: PPR | CtL | RC | CtL to a fixed point.

    Parameters
    ----------
    tree : Tree
        Input tree (node 0 the root at the goal); its ``cost`` is not used.
    params : Params
        ``max_rounds`` and the CtL mode.
    progress : callable, optional
        ``progress(round, max_rounds)`` after each round.

    Returns
    -------
    Tree
        Same map and collision samples; nodes (M, 2), parent (M,), cost (M,).
        ``stats``: ``nodes_before``; ``nodes_per_round`` (count after each round);
        ``rounds`` run (the last one changed nothing unless ``max_rounds`` stopped
        it); ``finish_passes`` (RC | CtL passes after the rounds, see :func:`_finish`;
        0 when the last round changed nothing) and ``finish_crossings_removed`` (their
        RC insertions); ``crossings_removed`` (RC insertions, finishing passes included);
        ``ppr_rewires`` (accepted grandparent hops); ``leaves_cut``;
        ``crossings_remaining`` (properly crossing edge pairs left: 0 unless
        ``MAX_FINISH_PASSES`` was reached, then by a fresh scan); ``crossings_at_nodes`` (pairs that
        cross at a point within ``tol`` of a third node, which RC skips by definition;
        see :func:`~bearnav_cli.crossings.count_crossings`); ``discarded_reconnectable`` (see
        :func:`_reconnectable`; reported, not enforced).

    Raises
    ------
    ArtifactError
        If some node does not reach the root (a cycle in ``parent``).
    """
    nodes = np.array(tree.nodes, float)
    parent = np.array(tree.parent, np.int64)
    stats = {
        "nodes_before": len(nodes),
        "nodes_per_round": [],
        "rounds": 0,
        "finish_passes": 0,
        "finish_crossings_removed": 0,
        "crossings_removed": 0,
        "ppr_rewires": 0,
        "leaves_cut": 0,
        "crossings_remaining": 0,
        "crossings_at_nodes": 0,
        "discarded_reconnectable": 1.0,
    }
    if len(nodes) == 1:
        return Tree(tree.map, tree.nodes, tree.parent, tree.cost, tree.collision_samples, stats)
    true_space = FreeSpace.from_map(tree.map)
    stats["clearance"] = barrier_margin(params.clearance, tree.map.diagonal)
    space = true_space.planning_space(params.clearance, tree.map.goal, tree.map.diagonal)
    tol = tree.map.tol

    def cut(nodes, parent, cost):
        keep = _cut_leaves(nodes, parent, params.ctl)
        stats["leaves_cut"] += int(len(keep) - keep.sum())
        return (*_compact(keep, nodes, cost, parent=parent), keep)

    changed, done = True, True
    # what each RC leaves the next (see split_crossings): all edges are stale before the first
    carried = (np.ones(len(nodes), bool), np.zeros((0, 2), np.int64))
    for rnd in range(1, params.max_rounds + 1):
        size_before = len(nodes)
        before = parent.copy()
        hops = _shortcut(nodes, parent, space, bfs_levels(parent))
        stats["ppr_rewires"] += hops
        carried = (carried[0] | (parent != before), carried[1])  # a hop gives an edge a new parent
        cost = tree_costs(nodes, parent, bfs_levels(parent))
        nodes, cost, parent, keep = cut(nodes, parent, cost)
        carried = carry(carried, keep)
        after_first_cut = len(nodes)
        nodes, parent, cost, added, blocked = split_crossings(nodes, parent, cost, tol, carried)
        stats["crossings_removed"] += added
        nodes, cost, parent, keep = cut(nodes, parent, cost)
        carried = carry((np.zeros(len(keep), bool), blocked), keep)
        stats["rounds"] = rnd
        stats["nodes_per_round"].append(len(nodes))
        log.info("simplify round %d: %d nodes", rnd, len(nodes))
        if progress is not None:
            progress(rnd, params.max_rounds)
        changed = hops > 0 or added > 0 or len(nodes) != after_first_cut or after_first_cut != size_before
        if not changed:
            break
    if changed:  # max_rounds stopped the loop: bring RC and CtL to their fixed point
        nodes, parent, cost, passes, added, done, carried = _finish(nodes, parent, cost, tol, cut, carried)
        stats["finish_passes"] = passes
        stats["finish_crossings_removed"] = added
        stats["crossings_removed"] += added
        log.info("simplify: %d finishing RC | CtL passes, %d crossings removed: %d nodes", passes, added, len(nodes))
        if not done:
            log.warning("simplify: finishing passes stopped after %d (MAX_FINISH_PASSES)", passes)
    if changed and not done:  # the bound stopped the passes after a cut: only a fresh scan knows
        stats["crossings_remaining"], stats["crossings_at_nodes"] = count_crossings(nodes, parent, tol)
    else:  # the last RC's result stands (nothing changed after it, or CtL cut nothing)
        stats["crossings_remaining"], stats["crossings_at_nodes"] = 0, len(carried[1])

    stats["discarded_reconnectable"] = _reconnectable(tree.nodes, nodes, true_space)
    return Tree(tree.map, nodes, parent, cost, tree.collision_samples, stats)


def summary(tree: Tree) -> str:
    """One line for ``inspect`` and ``plan``."""
    s = tree.stats
    share = s.get("discarded_reconnectable")
    share_text = f"{100 * share:.0f}%" if isinstance(share, (int, float)) else "?"
    passes = s.get("finish_passes") or 0
    finish = f" and {passes} finishing RC/CtL pass{'es' if passes != 1 else ''}" if passes else ""
    left = s.get("crossings_remaining") or 0
    bound = passes >= MAX_FINISH_PASSES
    why = f"finishing passes stopped at their bound of {MAX_FINISH_PASSES}" if bound else "missed by RC"
    left_text = f"; {left} proper crossing{'s remain' if left != 1 else ' remains'} ({why})" if left else ""
    at = s.get("crossings_at_nodes") or 0
    if at:
        pairs = f"{at} edge pair{'s cross' if at != 1 else ' crosses'}"
        left_text += f"; {pairs} at a node (left: the crossing point is a node already)"
    return (
        f"{len(tree.nodes)} nodes (from {s.get('nodes_before', '?')}) after {s.get('rounds', '?')} rounds{finish}: "
        f"{s.get('ppr_rewires', '?')} shortcuts, {s.get('leaves_cut', '?')} leaves cut, "
        f"{s.get('crossings_removed', '?')} crossings removed{left_text}; "
        f"{share_text} of discarded nodes reconnectable"
    )


def problems(tree: Tree) -> list[verdicts.Problem]:
    """Why the simplified tree is not usable: no route (only its root)."""
    return verdicts.no_route(tree.nodes)
