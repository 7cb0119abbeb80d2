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
pairs the last RC found blocked by a node (:func:`_split_crossings` keeps them, the same
pairs a fresh scan finds); only when the pass bound stops the passes are both counted by
a fresh scan of all edges (:func:`count_crossings`).

Indices: deleted leaves are dropped by an order-preserving compaction and RC
appends its new node after all others, so every "ascending index" rule sees the
same order as with stable indices, and the final renumbering (root → 0, then
ascending old index) is already in place.

Speed: PPR is vectorised per BFS level (exactly the sequential result, see
:func:`_shortcut`), CtL is pure numpy. RC's first pass scans all edge pairs whose
boxes meet (a ``shapely.STRtree``) and keeps, per edge, the edges that may meet it
(:class:`_Neighbours`), against which it re-tests only the split edges; each later pass
scans only the edges PPR changed since and the pairs the previous pass found blocked by a
node (:func:`_split_crossings`), and the result is the one a scan of all pairs gives. The
number of crossings RC removes still grows faster than the number of nodes (PPR's long
edges cross more often in a denser tree), so RC does too, at a fraction of a millisecond
per insertion.
"""

from __future__ import annotations

import heapq
import logging
import math
from typing import Callable

import numpy as np
import shapely

from bearnav_cli import verdicts
from bearnav_cli.datatypes import Tree
from bearnav_cli.errors import ArtifactError
from bearnav_cli.geometry import FreeSpace, barrier_margin
from bearnav_cli.params.simplify import Params

__all__ = [
    "bfs_levels",
    "count_crossings",
    "MAX_FINISH_PASSES",
    "MEET_SLACK",
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
        part = np.argpartition(d, k - 1, axis=1)[:, :k] if k < d.shape[1] else np.tile(np.arange(d.shape[1]),
                                                                                        (len(d), 1))  # fmt: skip
        part.sort(axis=1)
        near = np.take_along_axis(d, part, axis=1)
        order = np.take_along_axis(part, np.argsort(near, axis=1, kind="stable"), axis=1)
        index[s : s + step] = order
        dist[s : s + step] = np.take_along_axis(d, order, axis=1)
    return dist, index


class _NearNodes:
    """Is any node within ``tol`` of a point? Every node filed under its grid cell (side ``tol``).

    A node within ``tol`` of a point lies in the point's cell or one of the eight around it, so a
    query looks up nine cells and measures only the nodes it finds there (almost always none).
    Positions are kept as Python floats: RC's loop asks about one point at a time.
    """

    def __init__(self, nodes: np.ndarray, tol: float):
        self.tol = tol
        self.cells: dict[tuple[int, int], list[tuple[float, float]]] = {}
        for x, y in np.asarray(nodes, float).reshape(-1, 2).tolist():
            self.add(x, y)

    def add(self, x: float, y: float) -> None:
        """File the node at ``(x, y)``."""
        self.cells.setdefault((math.floor(x / self.tol), math.floor(y / self.tol)), []).append((x, y))

    def clear(self, x: float, y: float) -> bool:
        """Whether every node lies farther than ``tol`` from ``(x, y)``."""
        tol, cells = self.tol, self.cells
        bx, by = math.floor(x / tol), math.floor(y / tol)
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                near = cells.get((bx + dx, by + dy))
                if near and any(math.dist(q, (x, y)) <= tol for q in near):
                    return False
        return True

    def clear_of(self, pts: np.ndarray) -> np.ndarray:
        """Whether every node lies farther than ``tol`` from each point; shape (n,) bool."""
        pts = np.asarray(pts, float).reshape(-1, 2)
        return np.fromiter((self.clear(x, y) for x, y in pts.tolist()), bool, len(pts))


def _crossing(nodes, parent, e, f, near: _NearNodes | None, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Proper crossings of edges ``(e, parent[e])`` and ``(f, parent[f])``, pairwise.

    A pair crosses properly when the edges share no endpoint, are not parallel
    (``|cross(r, s)| > tol·max(|r|, |s|)``: the shorter edge turns by more than
    ``tol`` over its length), meet at ``k`` inside both, and ``k`` lies farther than
    ``tol`` from the four endpoints and from every node (``near``; ``None`` leaves
    out this last test).

    Returns
    -------
    ok : ndarray of bool, shape (m,)
    k : ndarray, shape (m, 2)
        Crossing points (meaningful where ``ok``).
    """
    e, f = np.minimum(e, f), np.maximum(e, f)  # k is computed on the lower edge, whichever side asks
    pe, pf = parent[e], parent[f]
    a, b, c, d = nodes[e], nodes[pe], nodes[f], nodes[pf]
    r, s = b - a, d - c
    den = r[:, 0] * s[:, 1] - r[:, 1] * s[:, 0]
    ok = (e != f) & (e != pf) & (pe != f) & (pe != pf)
    ok &= np.abs(den) > tol * np.maximum(np.hypot(r[:, 0], r[:, 1]), np.hypot(s[:, 0], s[:, 1]))
    # each further test only for the pairs still in play (few: most candidate pairs miss), where den ≠ 0
    idx = np.flatnonzero(ok)
    w = c[idx] - a[idx]
    t = (w[:, 0] * s[idx, 1] - w[:, 1] * s[idx, 0]) / den[idx]
    u = (w[:, 0] * r[idx, 1] - w[:, 1] * r[idx, 0]) / den[idx]
    inside = (t > 0) & (t < 1) & (u > 0) & (u < 1)
    idx, t = idx[inside], t[inside]
    k_in = a[idx] + t[:, None] * r[idx]
    clear = np.ones(len(idx), bool)
    for end in (a, b, c, d):
        clear &= np.hypot(k_in[:, 0] - end[idx, 0], k_in[:, 1] - end[idx, 1]) > tol
    ok[:] = False
    ok[idx] = clear
    k = np.full((len(e), 2), np.nan)
    k[idx] = k_in
    if near is not None and ok.any():
        ok[ok] = near.clear_of(k[ok])
    return ok, k


def _in_subtree(v: int, parent: list[int], roots: tuple[int, int]) -> bool:
    """Whether ``v`` lies in the subtree of either root: walk up from ``v`` (O(depth))."""
    while v >= 0:
        if v in roots:
            return True
        v = parent[v]
    return False


def _box_pairs(nodes, parent, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Ordered pairs ``(e, f)``, ``e != f``, of edges (named by their child) whose boxes, grown by ``tol``, meet."""
    kids = np.arange(1, len(nodes))
    a, b = nodes[kids], nodes[parent[kids]]
    lo, hi = np.minimum(a, b) - tol, np.maximum(a, b) + tol
    boxes = shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])
    qa, qb = shapely.STRtree(boxes).query(boxes)
    return kids[qa[qa != qb]], kids[qb[qa != qb]]


#: Slack of :func:`_may_meet`, in units of ``tol`` (``1e-9·D``): far above the rounding of a split
#: point carried along its edge (at most about ``5e-8·D``, for a piece of length ``2·tol`` on an edge
#: of length ``D``), far below any edge's length.
MEET_SLACK = 1e4


def _may_meet(a, b, c, d, common: np.ndarray, slack: float) -> np.ndarray:
    """Whether segments ``[a, b]`` and ``[c, d]`` can hold pieces that cross properly, pairwise.

    False where the two endpoints of one segment lie on the same side of the other's line, both
    farther than ``slack`` from it (the segments, and every piece of them up to rounding far below
    ``slack``, are disjoint), and where the segments have a ``common`` end and meet at more than
    1e-3 rad (pieces of two rays from one point cannot cross). Nearly parallel and collinear
    segments are kept, conservatively.

    Parameters
    ----------
    a, b, c, d : ndarray, shape (m, 2)
        The segments' endpoints (map units).
    common : ndarray of bool, shape (m,)
        The segments share an endpoint (the same node).
    slack : float
        Map units.

    Returns
    -------
    ndarray of bool, shape (m,)
    """
    r, s = b - a, d - c
    len_r, len_s = np.hypot(r[:, 0], r[:, 1]), np.hypot(s[:, 0], s[:, 1])
    gap_r, gap_s = slack * len_r, slack * len_s  # cross products are signed distances × the length
    side_c = r[:, 0] * (c[:, 1] - a[:, 1]) - r[:, 1] * (c[:, 0] - a[:, 0])
    side_d = r[:, 0] * (d[:, 1] - a[:, 1]) - r[:, 1] * (d[:, 0] - a[:, 0])
    side_a = s[:, 0] * (a[:, 1] - c[:, 1]) - s[:, 1] * (a[:, 0] - c[:, 0])
    side_b = s[:, 0] * (b[:, 1] - c[:, 1]) - s[:, 1] * (b[:, 0] - c[:, 0])
    apart = ((side_c > gap_r) & (side_d > gap_r)) | ((side_c < -gap_r) & (side_d < -gap_r))
    apart |= ((side_a > gap_s) & (side_b > gap_s)) | ((side_a < -gap_s) & (side_b < -gap_s))
    # within 1e-3 rad the rounding of a split point is no longer negligible against the angle
    den = r[:, 0] * s[:, 1] - r[:, 1] * s[:, 0]
    apart |= common & (np.abs(den) > 1e-3 * len_r * len_s)
    return ~apart


class _Neighbours:
    """For each edge of a tree (named by its child), the edges that may meet it (:func:`_may_meet`).

    The tree's edges are RC's *origins*: every later edge is a piece of one of them, so two pieces
    can only cross properly if their origins may meet. Candidates come from an STRtree of the
    edges' boxes grown by ``tol``; :func:`_may_meet` then drops the pairs that lie apart, which a
    box overlap keeps in numbers that grow with the square of the density (PPR makes long edges).
    The endpoints are copied: RC re-hangs nodes while it asks.
    """

    def __init__(self, nodes: np.ndarray, parent: np.ndarray, tol: float):
        self.a = np.array(nodes, float)
        self.up = np.maximum(parent, 0)
        self.b = self.a[self.up]
        lo, hi = np.minimum(self.a, self.b) - tol, np.maximum(self.a, self.b) + tol
        self.boxes = shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])
        self.tree = shapely.STRtree(self.boxes[1:])
        extent = float(np.max(np.ptp(self.a, axis=0))) if len(self.a) else 0.0
        self.slack = max(MEET_SLACK * tol, 1e-6 * extent)
        self.lists: dict[int, np.ndarray] = {}
        self.start: np.ndarray | None = None

    def pairs(self, edges: np.ndarray, upper: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Ordered pairs ``(e, f)``, ``e`` in ``edges``, ``f != e`` (``upper``: ``f > e``), that may meet.

        Sorted by ``e``, then ``f``.
        """
        qa, qb = self.tree.query(self.boxes[edges])
        e, f = edges[qa], qb + 1
        keep = e < f if upper else e != f
        e, f = e[keep], f[keep]
        up = self.up
        common = (e == up[f]) | (up[e] == f) | (up[e] == up[f])
        keep = _may_meet(self.a[e], self.b[e], self.a[f], self.b[f], common, self.slack)
        e, f = e[keep], f[keep]
        order = np.lexsort((f, e))
        return e[order], f[order]

    def index_all(self) -> tuple[np.ndarray, np.ndarray]:
        """Every pair ``(e, f)``, ``e < f``, that may meet; the lists of all edges are filed on the way."""
        e, f = self.pairs(np.arange(1, len(self.a)), upper=True)  # half the pairs to judge
        both_e, both_f = np.concatenate([e, f]), np.concatenate([f, e])
        order = np.lexsort((both_f, both_e))
        self.start = np.searchsorted(both_e[order], np.arange(len(self.a) + 1))
        self.all_f = both_f[order]
        return e, f

    def of(self, edge: int) -> np.ndarray:
        """The edges that may meet ``edge``, ascending."""
        if self.start is not None:
            return self.all_f[self.start[edge] : self.start[edge + 1]]
        found = self.lists.get(edge)
        if found is None:
            found = self.lists[edge] = self.pairs(np.array([edge]))[1]
        return found


def _remove_crossings(nodes, parent, cost, tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """RC: split properly crossing edges until none is left (ALGORITHMS §3).

    :func:`_split_crossings` from scratch, without what it carries to the next pass.

    Returns
    -------
    nodes (M, 2), parent (M,), cost (M,), insertions
    """
    return _split_crossings(nodes, parent, cost, tol)[:4]


def _split_crossings(
    nodes, parent, cost, tol: float, carried: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, np.ndarray]:
    """RC: split properly crossing edges until none is left (ALGORITHMS §3).

    Order: each step takes the lexicographically smallest crossing pair ``(i, j)``,
    ``i < j`` (edges named by their child), among the current edges, i.e. the scan
    "ascending i, then the smallest j > i" restarted after every insertion. A heap
    holds every crossing pair; entries of edges changed since are dropped when popped.

    Every later edge is a sub-segment of a starting edge (its *origin*), so two
    edges can only cross if their origins may meet (:class:`_Neighbours`); that
    relation bounds every re-test. ``cost`` is trusted (PPR recomputes it just before).

    The pairs that cross but for a node within ``tol`` of the crossing point (*blocked*)
    are kept, and returned for the next pass: every pair of final edges that crosses was
    tested once both had their final form (at the start, or when the later one changed),
    and was then either found blocked at the start, or pushed and, when popped, split (so
    not final) or found blocked.

    Parameters
    ----------
    nodes : ndarray, shape (N, 2)
    parent : ndarray of int, shape (N,)
    cost : ndarray, shape (N,)
    tol : float
    carried : (stale, blocked), optional
        What the previous pass returned, carried through the tree's changes since: ``stale``
        (N,) bool marks the edges changed since (a new parent), ``blocked`` (m, 2) the blocked
        pairs of that pass whose edges are both still there. Two unchanged edges outside
        ``blocked`` did not cross then and cannot now (nodes never move and only vanish, which
        can only unblock a pair), so the start scans only the stale edges and ``blocked``, and
        finds the same crossings as a scan of all pairs. ``None``: scan all pairs.

    Returns
    -------
    nodes (M, 2), parent (M,), cost (M,), insertions, blocked (b, 2) int
        ``blocked``: the blocked pairs of the result, ``(e, f)`` with ``e < f``, sorted.
    """
    n0 = len(nodes)
    if n0 < 4:  # two edges without a common endpoint need four nodes
        return nodes, parent, cost, 0, np.zeros((0, 2), np.int64)
    if carried is not None and not carried[0][1:].any() and not len(carried[1]):
        return nodes, parent, cost, 0, carried[1]  # nothing changed and nothing was blocked: nothing crosses
    neighbours = _Neighbours(nodes, parent, tol)
    if carried is None or carried[0][1:].all():
        qa, qb = neighbours.index_all()
    else:
        stale, old_blocked = carried
        e, f = neighbours.pairs(np.flatnonzero(stale[1:]) + 1)
        once = ~stale[f] | (e < f)  # a pair of two stale edges is found from both sides
        e, f = e[once], f[once]
        kept = old_blocked[~(stale[old_blocked[:, 0]] | stale[old_blocked[:, 1]])]
        qa = np.concatenate([np.minimum(e, f), kept[:, 0]])
        qb = np.concatenate([np.maximum(e, f), kept[:, 1]])
    near = _NearNodes(nodes, tol)
    ok, k = _crossing(nodes, parent, qa, qb, None, tol)
    clear = near.clear_of(k[ok])
    blocked = [(i, j, 0, 0) for i, j in zip(qa[ok][~clear].tolist(), qb[ok][~clear].tolist(), strict=True)]
    sel = np.flatnonzero(ok)[clear]
    found = zip(qa[sel].tolist(), qb[sel].tolist(), k[sel].tolist(), strict=True)
    heap = [(i, j, 0, 0, kx, ky) for i, j, (kx, ky) in found]
    if not heap:
        return nodes, parent, cost, 0, _pairs_array([(i, j) for i, j, _, _ in blocked])
    heapq.heapify(heap)

    cap = n0 + len(heap) + 1  # each insertion removes at least one crossing pair
    nodes = np.concatenate([nodes, np.empty((cap - n0, 2))])
    parent = np.concatenate([parent, np.full(cap - n0, -1, np.int64)])
    # scalar state as Python lists: the loop reads and writes it one item at a time
    xy = nodes[:n0].tolist()
    up = parent[:n0].tolist()
    cst = cost.tolist()
    length: list[float | None] = [None] * n0  # math.dist of each edge, filled when first needed
    origin = list(range(n0))
    version = [0] * n0
    extra: dict[int, list[int]] = {}  # origin → nodes added whose edge lies on it
    has_extra = np.zeros(n0, bool)
    children: list[list[int]] = [[] for _ in range(n0)]
    for c in range(1, n0):
        children[up[c]].append(c)
    n = n0
    while heap:
        i, j, vi, vj, kx, ky = heapq.heappop(heap)
        if version[i] != vi or version[j] != vj:
            continue  # an edge changed since the pair was found; its new pieces were re-tested
        if not near.clear(kx, ky):  # a node lies within tol (added since, for the first entries): blocked
            blocked.append((i, j, vi, vj))
            continue
        if n == len(nodes):  # the bound above holds in exact arithmetic; stay safe under rounding
            nodes, parent = np.concatenate([nodes, nodes]), np.concatenate([parent, parent])
        k = [kx, ky]
        pi, pj = up[i], up[j]
        c_i = cst[pi] + math.dist(k, xy[pi])
        c_j = cst[pj] + math.dist(k, xy[pj])
        candidates = ((pi, c_i), (pj, c_j)) if c_i <= c_j else ((pj, c_j), (pi, c_i))
        # cycle guard: a parent inside subtree(i) ∪ subtree(j) would hang the new node below itself
        p, c_k = next((q, c) for q, c in candidates if not _in_subtree(q, up, (i, j)))
        new = n
        n += 1
        nodes[new], parent[new] = k, p
        xy.append(k)
        up.append(p)
        cst.append(c_k)
        length.append(None)
        version.append(0)
        o_new = origin[i] if p == pi else origin[j]
        origin.append(o_new)
        extra.setdefault(o_new, []).append(new)
        has_extra[o_new] = True
        near.add(kx, ky)
        children[pi].remove(i)
        children[pj].remove(j)
        children[p].append(new)
        children.append([i, j])
        parent[i] = parent[j] = up[i] = up[j] = new
        length[i] = length[j] = None
        stack = [i, j]  # costs change in the two moved subtrees only
        while stack:
            v = stack.pop()
            edge = length[v]
            if edge is None:
                edge = length[v] = math.dist(xy[v], xy[up[v]])
            cst[v] = cst[up[v]] + edge
            stack.extend(children[v])
        version[i] += 1
        version[j] += 1
        # re-test the three changed edges against every piece of their origins' neighbours (the
        # new edge lies on i's origin or j's, whose pieces are gathered once)
        edge_ids, cands = [], []
        pieces_of: dict[int, np.ndarray] = {}
        for e in (i, j, new):
            o = origin[e]
            cand = pieces_of.get(o)
            if cand is None:
                cand = neighbours.of(o)
                split = cand[has_extra[cand]]
                if split.size:
                    pieces = [piece for s in split.tolist() for piece in extra[s]]
                    cand = np.concatenate([cand, np.array(pieces, np.int64)])
                pieces_of[o] = cand
            edge_ids.append(np.full(cand.size, e))
            cands.append(cand)
        es, fs = np.concatenate(edge_ids), np.concatenate(cands)
        ok, k = _crossing(nodes, parent, es, fs, None, tol)
        # the node test waits for the pop, which makes it anyway (nodes are only added): most of
        # these entries go stale before that
        for e, f, (kx, ky) in zip(es[ok].tolist(), fs[ok].tolist(), k[ok].tolist(), strict=True):
            lo_, hi_ = min(e, f), max(e, f)
            heapq.heappush(heap, (lo_, hi_, version[lo_], version[hi_], kx, ky))
    final = [(e, f) for e, f, ve, vf in blocked if version[e] == ve and version[f] == vf]
    return nodes[:n], parent[:n], np.array(cst), n - n0, _pairs_array(final)


def _pairs_array(pairs: list[tuple[int, int]]) -> np.ndarray:
    """Distinct pairs as a sorted int64 array, shape (m, 2)."""
    if not pairs:
        return np.zeros((0, 2), np.int64)
    return np.unique(np.array(pairs, np.int64), axis=0)


def _carry(carried: tuple[np.ndarray, np.ndarray], keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RC's carried state (:func:`_split_crossings`) after a compaction that keeps the nodes ``keep``."""
    stale, blocked = carried
    new_index = np.cumsum(keep) - 1
    blocked = blocked[keep[blocked].all(axis=1)] if len(blocked) else blocked
    return stale[keep], new_index[blocked]


def count_crossings(nodes: np.ndarray, parent: np.ndarray, tol: float) -> tuple[int, int]:
    """Edge pairs that cross, by a fresh scan of all pairs: properly, and at a node.

    Parameters
    ----------
    nodes : ndarray, shape (N, 2)
        Node positions (map units); the edges are ``nodes[i] → nodes[parent[i]]``.
    parent : ndarray of int, shape (N,)
        ``-1`` at node 0 only.
    tol : float
        The map's tolerance (map units).

    Returns
    -------
    proper : int
        Unordered pairs ``{e, f}`` that cross properly (:func:`_crossing`), the pairs RC
        splits; 0 at RC's fixed point.
    at_nodes : int
        Pairs that would cross properly but for a node within ``tol`` of the crossing
        point (not one of their four endpoints): RC skips them by definition (ALGORITHMS
        §3, edge cases). Typically a bundle of collinear edges that PPR laid through an
        RC node, met by the edge that node was made to split.
    """
    if len(nodes) < 4:
        return 0, 0
    qa, qb = _box_pairs(nodes, parent, tol)
    upper = qa < qb
    ok, k = _crossing(nodes, parent, qa[upper], qb[upper], None, tol)
    proper = _NearNodes(nodes, tol).clear_of(k[ok]) if ok.any() else np.zeros(0, bool)
    return int(proper.sum()), int((~proper).sum())


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
        What the last RC carries to this tree (:func:`_split_crossings`).

    Returns
    -------
    nodes, parent, cost, passes, insertions, done, carried
        ``done`` is False only if the guard stopped the passes; ``carried`` is what the last RC
        carries to the result (its blocked pairs are the result's when ``done``).
    """
    passes = insertions = 0
    while passes < MAX_FINISH_PASSES:
        passes += 1
        nodes, parent, cost, added, blocked = _split_crossings(nodes, parent, cost, tol, carried)
        insertions += added
        carried = (np.zeros(len(nodes), bool), blocked)
        if added == 0:  # the tree is the previous CtL's output: CtL would cut nothing either
            return nodes, parent, cost, passes, insertions, True, carried
        size = len(nodes)
        nodes, cost, parent, keep = cut(nodes, parent, cost)
        carried = _carry(carried, keep)
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
        see :func:`count_crossings`); ``discarded_reconnectable`` (see
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
    # what each RC leaves the next (see _split_crossings): all edges are stale before the first
    carried = (np.ones(len(nodes), bool), np.zeros((0, 2), np.int64))
    for rnd in range(1, params.max_rounds + 1):
        size_before = len(nodes)
        before = parent.copy()
        hops = _shortcut(nodes, parent, space, bfs_levels(parent))
        stats["ppr_rewires"] += hops
        carried = (carried[0] | (parent != before), carried[1])  # a hop gives an edge a new parent
        cost = tree_costs(nodes, parent, bfs_levels(parent))
        nodes, cost, parent, keep = cut(nodes, parent, cost)
        carried = _carry(carried, keep)
        after_first_cut = len(nodes)
        nodes, parent, cost, added, blocked = _split_crossings(nodes, parent, cost, tol, carried)
        stats["crossings_removed"] += added
        nodes, cost, parent, keep = cut(nodes, parent, cost)
        carried = _carry((np.zeros(len(keep), bool), blocked), keep)
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
