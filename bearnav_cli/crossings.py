"""RC, remove-crossings (ALGORITHMS §3): the edge pairs of a tree that cross, found and split at their crossing points.

:func:`split_crossings` is the RC of ``bearnav simplify`` (:mod:`bearnav_cli.stages.simplify` runs it in
every round and in the finishing passes); :func:`count_crossings` counts what is left by a fresh scan of
all pairs. Speed: the first pass scans every edge pair whose boxes meet (a ``shapely.STRtree``) and keeps,
per edge, the edges that may meet it (:class:`Neighbours`), against which it re-tests only the split
edges; a later pass scans only the edges changed since and the pairs the previous pass found blocked by a
node, and its result is the one a scan of all pairs gives. Per split, the re-test (:func:`crossing`) decides
most pairs from two numerators before any division, and no cost is written into the moved subtrees (their
sizes grow with the tree): a cost is summed along the way to the root when asked (:func:`_route_cost`),
bit for bit the sum the writing made.
"""

from __future__ import annotations

import heapq
import math

import numpy as np
import shapely

__all__ = [
    "carry",
    "count_crossings",
    "crossing",
    "edge_ends",
    "may_meet",
    "MEET_SLACK",
    "NearNodes",
    "Neighbours",
    "split_crossings",
]


class NearNodes:
    """Is any node within ``tol`` of a point? Every node filed under its grid cell (side ``tol``).

    A node within ``tol`` of a point lies in the point's cell or one of the eight around it, so a
    query looks up nine cells and measures only the nodes it finds there (almost always none).
    Positions are kept as Python floats: RC's loop asks about one point at a time.
    """

    def __init__(self, nodes: np.ndarray, tol: float):
        self.tol = tol
        self.cells: dict[tuple[int, int], list[tuple[float, float]]] = {}
        pts = np.asarray(nodes, float).reshape(-1, 2)
        # the cells by numpy (floor of the same quotient as add's), filed in one loop without calls
        keys = np.floor(pts / tol).astype(np.int64).tolist()
        setdefault = self.cells.setdefault
        for (bx, by), (x, y) in zip(keys, pts.tolist(), strict=True):
            setdefault((bx, by), []).append((x, y))

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
        """Whether every node lies farther than ``tol`` from each point; shape (n,) bool.

        Only the points with a filed cell among their nine are measured (:meth:`clear`); the others
        are clear, found by one sorted lookup of all their cells.
        """
        pts = np.asarray(pts, float).reshape(-1, 2)
        out = np.ones(len(pts), bool)
        if not len(pts) or not self.cells:
            return out
        filed = np.array(list(self.cells), np.int64)
        cell = np.floor(pts / self.tol).astype(np.int64)
        # cells as one int64 each: both coordinates offset to be non-negative and below 2**31 (cells are
        # tol wide, and a map spans about 1e9 tol; points beyond the filed cells ± 1 meet none of them)
        low = filed.min(axis=0) - 1
        span = filed.max(axis=0) + 2 - low
        if np.any(span >= 1 << 31):  # not a map's range of cells: ask each point
            return np.fromiter((self.clear(x, y) for x, y in pts.tolist()), bool, len(pts))
        code = np.sort((filed[:, 0] - low[0]) * (1 << 31) + (filed[:, 1] - low[1]))
        near = np.zeros(len(pts), bool)
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                q = cell + (dx, dy) - low
                inside = np.all((q >= 0) & (q < span), axis=1)
                key = q[:, 0] * (1 << 31) + q[:, 1]
                at = np.minimum(np.searchsorted(code, key), len(code) - 1)
                near |= inside & (code[at] == key)
        ask = np.flatnonzero(near)
        out[ask] = [self.clear(x, y) for x, y in pts[ask].tolist()]
        return out


def crossing(
    nodes, parent, e, f, near: NearNodes | None, tol: float, ends: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Proper crossings of edges ``(e, parent[e])`` and ``(f, parent[f])``, pairwise.

    A pair crosses properly when the edges share no endpoint, are not parallel
    (``|cross(r, s)| > tol·max(|r|, |s|)``: the shorter edge turns by more than
    ``tol`` over its length), meet at ``k`` inside both, and ``k`` lies farther than
    ``tol`` from the four endpoints and from every node (``near``; ``None`` leaves
    out this last test).

    Most pairs miss: the crossing parameters ``t = t_n/den`` and ``u = u_n/den`` of a pair can
    lie in (0, 1) only where ``t_n`` and ``u_n`` have the sign of ``den`` and at most its size
    (a correctly rounded quotient of a larger numerator is at least 1), so every further test,
    the division included, runs only for the pairs that pass this, on the same numbers.

    Parameters
    ----------
    nodes : ndarray, shape (N, 2)
        Node positions (map units); the edges are ``nodes[i] → nodes[parent[i]]``.
    parent : ndarray of int, shape (N,)
        Each node's parent, ``-1`` at node 0 only.
    e, f : ndarray of int, shape (m,)
        The pairs' edges, named by their child node.
    near : NearNodes or None
        The nodes a crossing point must keep ``tol`` from; None: only the four endpoints.
    tol : float
        The map's tolerance (map units).
    ends : ndarray, shape (4, N), optional
        Each edge's endpoints as rows ``x_i, y_i, x_parent, y_parent`` (map units), the numbers
        ``nodes`` and ``parent`` give (RC keeps it beside them, :func:`edge_ends`); by default
        gathered from them for the pairs' edges.

    Returns
    -------
    ok : ndarray of bool, shape (m,)
    k : ndarray, shape (m, 2)
        Crossing points (meaningful where ``ok``).
    """
    e, f = np.minimum(e, f), np.maximum(e, f)  # k is computed on the lower edge, whichever side asks
    if ends is None:  # only the pairs' edges: the others' parents need not even be nodes
        ax, ay, bx, by = np.concatenate([nodes[e], nodes[parent[e]]], axis=1).T
        cx, cy, dx, dy = np.concatenate([nodes[f], nodes[parent[f]]], axis=1).T
    else:
        ax, ay, bx, by = ends[:, e]
        cx, cy, dx, dy = ends[:, f]
    rx, ry, sx, sy = bx - ax, by - ay, dx - cx, dy - cy
    den = rx * sy - ry * sx
    wx, wy = cx - ax, cy - ay
    t_n, u_n = wx * sy - wy * sx, wx * ry - wy * rx
    sign, size = np.sign(den), np.abs(den)  # times ±1 or 0: exact
    t_s, u_s = t_n * sign, u_n * sign
    idx = np.flatnonzero((t_s > 0) & (t_s <= size) & (u_s > 0) & (u_s <= size))
    ok = np.zeros(len(e), bool)
    k = np.full((len(e), 2), np.nan)
    if not idx.size:
        return ok, k
    ei, fi = e[idx], f[idx]
    pe, pf = parent[ei], parent[fi]
    rx, ry, sx, sy, den = rx[idx], ry[idx], sx[idx], sy[idx], den[idx]
    keep = (ei != fi) & (ei != pf) & (pe != fi) & (pe != pf)
    keep &= np.abs(den) > tol * np.maximum(np.hypot(rx, ry), np.hypot(sx, sy))
    t, u = t_n[idx] / den, u_n[idx] / den
    keep &= (t > 0) & (t < 1) & (u > 0) & (u < 1)
    idx, t, rx, ry = idx[keep], t[keep], rx[keep], ry[keep]
    if idx.size:
        kx, ky = ax[idx] + t * rx, ay[idx] + t * ry
        # k against the four endpoints at once: (4, m) distances, each as np.hypot of one difference
        gx = kx - np.stack([ax[idx], bx[idx], cx[idx], dx[idx]])
        gy = ky - np.stack([ay[idx], by[idx], cy[idx], dy[idx]])
        ok[idx] = np.all(np.hypot(gx, gy) > tol, axis=0)
        k[idx, 0], k[idx, 1] = kx, ky
    if near is not None and ok.any():
        ok[ok] = near.clear_of(k[ok])
    return ok, k


def edge_ends(nodes: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """Each edge's endpoints as rows ``x_i, y_i, x_parent, y_parent``, shape (4, N) (the root's: itself twice).

    Parameters
    ----------
    nodes : ndarray, shape (N, 2)
        Node positions (map units).
    parent : ndarray of int, shape (N,)
        ``-1`` at node 0 only.
    """
    nodes = np.asarray(nodes, float)
    return np.ascontiguousarray(np.concatenate([nodes, nodes[np.maximum(parent, 0)]], axis=1).T)


def _route_cost(
    q: int, up: list[int], moved: list[bool], base: list[float], length: list[float | None], xy: list, roots
) -> tuple[float, bool]:
    """Route length from node ``q`` to the root during RC, and whether ``q`` lies in the subtree of a root.

    RC moves whole subtrees (a split re-hangs ``i`` and ``j`` below the new node), so instead of
    writing the new costs into every moved subtree (whose sizes grow with the tree), a cost is worked
    out when asked, by the very sums the writing did: a node with no moved node on its way to the
    root keeps its input cost ``base``; from the highest moved node down, each cost is its parent's
    plus the edge's ``math.dist``. The walk up also answers the cycle guard (O(depth) either way).

    Parameters
    ----------
    q : int
        The node.
    up, moved, base, length, xy : list
        RC's parents, moved flags (re-hung or added), input costs (map units), cached edge lengths
        (None: not yet measured) and positions, by node.
    roots : (int, int)
        The two nodes whose subtrees the guard asks about.

    Returns
    -------
    cost : float
        Map units, the value the eager propagation gives bit for bit.
    inside : bool
        ``q`` is one of ``roots`` or lies below one.
    """
    chain = []
    v, inside = q, False
    while v >= 0:
        inside = inside or v in roots
        chain.append(v)
        v = up[v]
    cost = None
    for v in reversed(chain):  # root first
        if cost is None and not moved[v]:
            continue
        edge = length[v]
        if edge is None:
            edge = length[v] = math.dist(xy[v], xy[up[v]])
        cost = (base[up[v]] if cost is None else cost) + edge
    return (base[q] if cost is None else cost), inside


def _route_costs(up: list[int], moved: list[bool], base: list[float], length: list[float | None], xy: list) -> list:
    """:func:`_route_cost` of every node, each worked out once (its parent's first), by node."""
    n = len(up)
    cost: list[float | None] = [None] * n
    touched = [False] * n  # a moved node on the way to the root, itself included
    cost[0] = base[0]
    for v in range(1, n):
        chain = []
        while cost[v] is None:
            chain.append(v)
            v = up[v]
        for w in reversed(chain):
            pw = up[w]
            if moved[w] or touched[pw]:
                touched[w] = True
                edge = length[w]
                if edge is None:
                    edge = length[w] = math.dist(xy[w], xy[pw])
                cost[w] = cost[pw] + edge
            else:
                cost[w] = base[w]
    return cost


def _box_pairs(nodes, parent, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Ordered pairs ``(e, f)``, ``e != f``, of edges (named by their child) whose boxes, grown by ``tol``, meet.

    Parameters
    ----------
    nodes : ndarray, shape (N, 2)
        Node positions (map units); the edges are ``nodes[i] → nodes[parent[i]]``.
    parent : ndarray of int, shape (N,)
        Each node's parent, ``-1`` at node 0 only.
    tol : float
        The map's tolerance (map units).

    Returns
    -------
    e, f : ndarray of int, shape (m,)
    """
    kids = np.arange(1, len(nodes))
    a, b = nodes[kids], nodes[parent[kids]]
    lo, hi = np.minimum(a, b) - tol, np.maximum(a, b) + tol
    boxes = shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])
    qa, qb = shapely.STRtree(boxes).query(boxes)
    return kids[qa[qa != qb]], kids[qb[qa != qb]]


#: Slack of :func:`may_meet`, in units of ``tol`` (``1e-9·D``): far above the rounding of a split
#: point carried along its edge (at most about ``5e-8·D``, for a piece of length ``2·tol`` on an edge
#: of length ``D``), far below any edge's length.
MEET_SLACK = 1e4


def may_meet(a, b, c, d, common: np.ndarray, slack: float) -> np.ndarray:
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


class Neighbours:
    """For each edge of a tree (named by its child), the edges that may meet it (:func:`may_meet`).

    The tree's edges are RC's *origins*: every later edge is a piece of one of them, so two pieces
    can only cross properly if their origins may meet. Candidates come from an STRtree of the
    edges' boxes grown by ``tol``; :func:`may_meet` then drops the pairs that lie apart, which a
    box overlap keeps in numbers that grow with the square of the density (PPR makes long edges).
    The endpoints are copied: RC re-hangs nodes while it asks.

    Parameters
    ----------
    nodes : ndarray, shape (N, 2)
        Node positions (map units); the edges are ``nodes[i] → nodes[parent[i]]``.
    parent : ndarray of int, shape (N,)
        Each node's parent, ``-1`` at node 0 only.
    tol : float
        The map's tolerance (map units).
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
        keep = may_meet(self.a[e], self.b[e], self.a[f], self.b[f], common, self.slack)
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


def split_crossings(
    nodes, parent, cost, tol: float, carried: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, np.ndarray]:
    """RC: split properly crossing edges until none is left (ALGORITHMS §3).

    Order: each step takes the lexicographically smallest crossing pair ``(i, j)``,
    ``i < j`` (edges named by their child), among the current edges, i.e. the scan
    "ascending i, then the smallest j > i" restarted after every insertion. A heap
    holds every crossing pair; entries of edges changed since are dropped when popped.

    Every later edge is a sub-segment of a starting edge (its *origin*), so two
    edges can only cross if their origins may meet (:class:`Neighbours`); that
    relation bounds every re-test. ``cost`` is trusted (PPR recomputes it just before).

    The pairs that cross but for a node within ``tol`` of the crossing point (*blocked*)
    are kept, and returned for the next pass: every pair of final edges that crosses was
    tested once both had their final form (at the start, or when the later one changed),
    and was then either found blocked at the start, or pushed and, when popped, split (so
    not final) or found blocked.

    Parameters
    ----------
    nodes : ndarray, shape (N, 2)
        Node positions (map units); the edges are ``nodes[i] → nodes[parent[i]]``.
    parent : ndarray of int, shape (N,)
        Each node's parent, ``-1`` at node 0 only.
    cost : ndarray, shape (N,)
        Route length from each node to the root (map units), consistent with the tree.
    tol : float
        The map's tolerance (map units).
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
    neighbours = Neighbours(nodes, parent, tol)
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
    near = NearNodes(nodes, tol)
    ok, k = crossing(nodes, parent, qa, qb, None, tol)
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
    ends = edge_ends(nodes, parent)  # each edge's endpoints, for crossing
    # scalar state as Python lists: the loop reads and writes it one item at a time
    xy = nodes[:n0].tolist()
    up = parent[:n0].tolist()
    base = cost.tolist()  # costs stay consistent without writing into moved subtrees: see _route_cost
    moved = [False] * n0
    length: list[float | None] = [None] * n0  # math.dist of each edge, filled when first needed
    origin = list(range(n0))
    version = [0] * n0
    extra: dict[int, list[int]] = {}  # origin → nodes added whose edge lies on it
    has_extra = np.zeros(n0, bool)
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
            ends = np.concatenate([ends, ends], axis=1)
        k = [kx, ky]
        pi, pj = up[i], up[j]
        cost_i, below_i = _route_cost(pi, up, moved, base, length, xy, (i, j))
        cost_j, below_j = _route_cost(pj, up, moved, base, length, xy, (i, j))
        c_i = cost_i + math.dist(k, xy[pi])
        c_j = cost_j + math.dist(k, xy[pj])
        candidates = ((pi, c_i, below_i), (pj, c_j, below_j))
        # cycle guard: a parent inside subtree(i) ∪ subtree(j) would hang the new node below itself
        p = next(q for q, _, below in (candidates if c_i <= c_j else candidates[::-1]) if not below)
        new = n
        n += 1
        nodes[new], parent[new] = k, p
        ends[:, new] = (kx, ky, *xy[p])
        ends[2, i] = ends[2, j] = kx
        ends[3, i] = ends[3, j] = ky
        xy.append(k)
        up.append(p)
        moved.append(True)
        length.append(None)
        version.append(0)
        o_new = origin[i] if p == pi else origin[j]
        origin.append(o_new)
        extra.setdefault(o_new, []).append(new)
        has_extra[o_new] = True
        near.add(kx, ky)
        parent[i] = parent[j] = up[i] = up[j] = new
        moved[i] = moved[j] = True
        length[i] = length[j] = None
        version[i] += 1
        version[j] += 1
        # re-test the three changed edges against every piece of their origins' neighbours (the
        # new edge lies on i's origin or j's, whose pieces are gathered once)
        cands = []
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
            cands.append(cand)
        es = np.repeat(np.array([i, j, new]), [c.size for c in cands])
        fs = np.concatenate(cands)
        ok, k = crossing(nodes, parent, es, fs, None, tol, ends)
        # the node test waits for the pop, which makes it anyway (nodes are only added): most of
        # these entries go stale before that
        for e, f, (kx, ky) in zip(es[ok].tolist(), fs[ok].tolist(), k[ok].tolist(), strict=True):
            lo_, hi_ = min(e, f), max(e, f)
            heapq.heappush(heap, (lo_, hi_, version[lo_], version[hi_], kx, ky))
    final = [(e, f) for e, f, ve, vf in blocked if version[e] == ve and version[f] == vf]
    cst = _route_costs(up, moved, base, length, xy)
    return nodes[:n], parent[:n], np.array(cst), n - n0, _pairs_array(final)


def _pairs_array(pairs: list[tuple[int, int]]) -> np.ndarray:
    """Distinct pairs as a sorted int64 array, shape (m, 2)."""
    if not pairs:
        return np.zeros((0, 2), np.int64)
    return np.unique(np.array(pairs, np.int64), axis=0)


def carry(carried: tuple[np.ndarray, np.ndarray], keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RC's carried state (:func:`split_crossings`) after a compaction that keeps the nodes ``keep``."""
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
        Unordered pairs ``{e, f}`` that cross properly (:func:`crossing`), the pairs RC
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
    ok, k = crossing(nodes, parent, qa[upper], qb[upper], None, tol)
    proper = NearNodes(nodes, tol).clear_of(k[ok]) if ok.any() else np.zeros(0, bool)
    return int(proper.sum()), int((~proper).sum())
