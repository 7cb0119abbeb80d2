"""Start sampling and exact shortest routes in the goal's free component (ALGORITHMS §8).

Used by ``bearnav verify``'s Monte Carlo check (:mod:`bearnav_cli.verify`):

* :func:`sample_starts` draws starts uniformly from the strictly free points of the
  goal's component ``B \\ O`` (rejection sampling, deterministic per generator state);
* :func:`route_lengths` gives the exact length of the shortest collision-free route from
  each start to the goal: Dijkstra on the tangent visibility graph of the component's
  vertices, then the best visible vertex per start.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from bearnav_cli.geometry import FreeSpace

__all__ = [
    "MAX_ROUTE_VERTICES",
    "route_lengths",
    "sample_starts",
]

#: Candidate vertices tested per start and round when searching the shortest route.
_ROUTE_BATCH = 8


def sample_starts(space: FreeSpace, goal: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` starts drawn uniformly from the strictly free points of the goal's component.

    Rejection sampling in the component's bounding box, in batches; deterministic for a
    given generator state.

    Parameters
    ----------
    space : FreeSpace
        The map's free space; a start is kept when it is strictly free
        (:meth:`FreeSpace.points_strictly_free`) and in the goal's component.
    goal : ndarray, shape (2,)
        The goal (map units), which picks the component (:meth:`FreeSpace.component_of`).
    count : int
        Number of starts wanted; 0 (or an empty component) returns none.
    rng : numpy.random.Generator
        The source of the uniform draws; advanced by the call.

    Returns
    -------
    ndarray, shape (count, 2)
        Starts in map units, in the order drawn.
    """
    region = space.component_of(goal)
    if count == 0 or region.is_empty:
        return np.zeros((0, 2))
    shapely.prepare(region)
    xmin, ymin, xmax, ymax = region.bounds
    box_area = (xmax - xmin) * (ymax - ymin)
    batch = max(64, math.ceil(1.25 * count * box_area / max(region.area, 1e-300)))
    found: list[np.ndarray] = []
    total = 0
    while total < count:
        p = rng.uniform((xmin, ymin), (xmax, ymax), size=(batch, 2))
        keep = space.points_strictly_free(p)
        keep[keep] = shapely.contains_xy(region, p[keep, 0], p[keep, 1])
        found.append(p[keep])
        total += int(keep.sum())
    return np.concatenate(found)[:count]


#: Most corners of the goal's free component the visibility graph is built on. The graph tests every
#: pair (``n²/2``): 5,000 corners are 12.5 M pairs, about a second and a few hundred MB; a map of
#: 2,000 small discs has over 200,000 corners (tens of GB). Beyond it the routes are not computed.
MAX_ROUTE_VERTICES = 5000


def _ring_vertices(region: shapely.Polygon) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices of every ring of a polygon with their ring neighbours, each shape (V, 2)."""
    verts, prev, nxt = [], [], []
    for ring in (region.exterior, *region.interiors):
        coords = np.asarray(ring.coords)[:-1]
        if len(coords) < 3:
            continue
        verts.append(coords)
        prev.append(np.roll(coords, 1, axis=0))
        nxt.append(np.roll(coords, -1, axis=0))
    if not verts:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2))
    return np.concatenate(verts), np.concatenate(prev), np.concatenate(nxt)


def _tangent(v: np.ndarray, prev: np.ndarray, nxt: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Whether the line through vertex ``v`` and point ``w`` leaves both ring neighbours of ``v``
    on one (closed) side; broadcasts. A shortest route only bends at vertices where both of
    its segments are tangent in this sense (a separating line would let it cut the corner)."""
    d = w - v
    s1 = d[..., 0] * (prev[..., 1] - v[..., 1]) - d[..., 1] * (prev[..., 0] - v[..., 0])
    s2 = d[..., 0] * (nxt[..., 1] - v[..., 1]) - d[..., 1] * (nxt[..., 0] - v[..., 0])
    return s1 * s2 >= 0.0


def _covered(region: shapely.Geometry, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether each segment ``[a, b]`` lies in the closed region (boundary allowed)."""
    if len(a) == 0:
        return np.zeros(0, bool)
    return shapely.covers(region, shapely.linestrings(np.stack([a, b], axis=1)))


def route_lengths(space: FreeSpace, goal: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Length of the shortest collision-free route from each start to the goal (exact for polygons).

    Dijkstra from the goal on the (tangent) visibility graph of the vertices of the goal's
    free component ``B \\ O``, then, per start, the best visible vertex.

    **Visibility.** A route may run along the boundary of ``O``: the shortest route wraps
    around obstacle corners and is the limit of strictly free routes, while
    :meth:`FreeSpace.segments_free` calls any touch a collision. So visibility here is
    ``covers``: the segment lies in the *closed* free component. One consequence: where
    two obstacles touch at a single point, a route may pass through that point; the
    length is then a lower bound.

    Parameters
    ----------
    space : FreeSpace
        The map's free space; the graph is built on the goal's component of ``B \\ O``.
    goal : ndarray, shape (2,)
        The goal (map units), the source of the Dijkstra search.
    starts : ndarray, shape (R, 2)
        Start positions (map units).

    Returns
    -------
    ndarray, shape (R,)
        Route lengths (map units); ``inf`` for a start outside the goal's component; ``NaN``
        for every start when the component has more than :data:`MAX_ROUTE_VERTICES` corners
        (its all-pairs visibility graph would not fit a run's memory or time).
    """
    starts = np.asarray(starts, float).reshape(-1, 2)
    goal = np.asarray(goal, float)
    out = np.full(len(starts), np.inf)
    region = space.component_of(goal)
    if region.is_empty or len(starts) == 0:
        return out
    shapely.prepare(region)
    verts, prev, nxt = _ring_vertices(region)
    n = len(verts)
    if n > MAX_ROUTE_VERTICES:
        return np.full(len(starts), np.nan)
    # graph over the vertices plus the goal (index n): tangent at both ends, then visible
    ii, jj = np.triu_indices(n, k=1)
    keep = _tangent(verts[ii], prev[ii], nxt[ii], verts[jj]) & _tangent(verts[jj], prev[jj], nxt[jj], verts[ii])
    ii, jj = ii[keep], jj[keep]
    seen = _covered(region, verts[ii], verts[jj])
    ii, jj = ii[seen], jj[seen]
    to_goal = np.flatnonzero(_tangent(verts, prev, nxt, goal[None, :]))
    to_goal = to_goal[_covered(region, verts[to_goal], np.broadcast_to(goal, (len(to_goal), 2)))]
    rows = np.concatenate([ii, to_goal])
    cols = np.concatenate([jj, np.full(len(to_goal), n)])
    points = np.vstack([verts, goal])
    weights = np.hypot(*(points[rows] - points[cols]).T)
    # scipy.sparse takes a quarter second to import: only the routes need it, not every command
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    graph = coo_matrix((weights, (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    from_goal = dijkstra(graph, directed=False, indices=n)[:n]

    inside = shapely.covers(region, shapely.points(starts))
    direct = np.zeros(len(starts), bool)
    direct[inside] = _covered(region, starts[inside], np.broadcast_to(goal, (int(inside.sum()), 2)))
    out[direct] = np.hypot(*(starts[direct] - goal).T)
    todo = np.flatnonzero(inside & ~direct)
    if todo.size == 0 or n == 0:
        return out
    # candidates in order of total length; the first visible one gives the shortest route
    p = starts[todo]
    total = np.hypot(p[:, None, 0] - verts[None, :, 0], p[:, None, 1] - verts[None, :, 1]) + from_goal[None, :]
    total[~_tangent(verts[None], prev[None], nxt[None], p[:, None, :])] = np.inf
    order = np.argsort(total, axis=1, kind="stable")
    pending = np.arange(len(todo))
    for first in range(0, n, _ROUTE_BATCH):
        if pending.size == 0:
            break
        cand = order[pending, first : first + _ROUTE_BATCH]  # (P, B)
        value = np.take_along_axis(total[pending], cand, axis=1)
        test = np.isfinite(value)
        rows_p, cols_b = np.nonzero(test)
        ok = np.zeros(value.shape, bool)
        ok[rows_p, cols_b] = _covered(region, p[pending[rows_p]], verts[cand[rows_p, cols_b]])
        hit = ok.any(axis=1)
        best = np.argmax(ok, axis=1)
        out[todo[pending[hit]]] = value[hit, best[hit]]
        exhausted = ~test.all(axis=1)  # later candidates are all infinite
        pending = pending[~hit & ~exhausted]
    return out
