"""What the plan's obstacle edges say about points and segments: exact segment tests, line of sight, clearance.

Numpy only, vectorised over ``R`` points or segments and chunked over the edges:

- :func:`edges_clear` / :func:`segments_clear` — whether segments cross or touch no edge (and, for
  :func:`segments_clear`, stay in the bounds): the straight approach to a tree node;
- :func:`in_sight` — line of sight from points to landmarks through the raw obstacles (ALGORITHMS §1);
- :func:`obstacle_clearance` — the distance to the nearest inflated obstacle edge or wall, and the
  way away from it;
- :func:`crossing_parity` — the even-odd test of points against rings of edges;
  :func:`inside_obstacles` applies it to the plan's inflated obstacles.
"""

from __future__ import annotations

import numpy as np

from bearnav_cli.runtime.plan_arrays import CHUNK, PlanArrays
from bearnav_cli.runtime.planar import points

__all__ = ["crossing_parity", "edges_clear", "in_sight", "inside_obstacles", "obstacle_clearance", "segments_clear"]


def _on_segment(orientation: np.ndarray, point: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> np.ndarray:
    """Collinear (``orientation == 0``) and inside the bounding box of ``[s0, s1]`` (broadcast arrays)."""
    inside = orientation == 0
    for k in (0, 1):
        low, high = np.minimum(s0[..., k], s1[..., k]), np.maximum(s0[..., k], s1[..., k])
        inside &= (low <= point[..., k]) & (point[..., k] <= high)
    return inside


def segments_clear(arrays: PlanArrays, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact test that each segment ``[a_r, b_r]`` stays in the bounds and touches no obstacle edge, shape (R,).

    Both endpoints are assumed free, so a segment meets the (closed) obstacles exactly when it
    crosses or touches one of their ring edges.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: the free bounds and the ring edges of the inflated obstacles (``obstacle_edges``).
    a, b : ndarray, shape (R, 2)
        The segments' endpoints (map units).
    """
    a, b = points(a), points(b)
    lo, hi = arrays.free_bounds[:2], arrays.free_bounds[2:]
    ok = np.all((a >= lo) & (a <= hi) & (b >= lo) & (b <= hi), axis=1)
    return edges_clear(arrays.obstacle_edges, a, b, ok)


def edges_clear(edges: np.ndarray, a: np.ndarray, b: np.ndarray, ok: np.ndarray | None = None) -> np.ndarray:
    """Exact test that each segment ``[a_r, b_r]`` crosses or touches none of ``edges`` (E, 2, 2), shape (R,).

    Parameters
    ----------
    edges : ndarray, shape (E, 2, 2)
        The edges ``(start, end)`` to test against (map units).
    a, b : ndarray, shape (R, 2)
        The segments' endpoints (map units).
    ok : ndarray of bool, shape (R,), optional
        Only those segments are tested (the others stay ``False``); default all.
    """
    a, b = points(a), points(b)
    ok = np.ones(len(a), bool) if ok is None else np.array(ok, bool)
    if not len(edges) or not ok.any():
        return ok
    p, q = edges[:, 0], edges[:, 1]
    step = max(1, CHUNK // len(edges))
    for s in range(0, len(a), step):
        A, Bp = a[s : s + step, None, :], b[s : s + step, None, :]
        d = Bp - A
        o1 = d[..., 0] * (p[None, :, 1] - A[..., 1]) - d[..., 1] * (p[None, :, 0] - A[..., 0])
        o2 = d[..., 0] * (q[None, :, 1] - A[..., 1]) - d[..., 1] * (q[None, :, 0] - A[..., 0])
        e = q - p
        o3 = e[None, :, 0] * (A[..., 1] - p[None, :, 1]) - e[None, :, 1] * (A[..., 0] - p[None, :, 0])
        o4 = e[None, :, 0] * (Bp[..., 1] - p[None, :, 1]) - e[None, :, 1] * (Bp[..., 0] - p[None, :, 0])
        proper = (o1 * o2 < 0) & (o3 * o4 < 0)
        # touching counts as a collision: an endpoint of one segment on the other (orientation 0
        # and inside the other's bounding box)
        touch = (
            _on_segment(o1, p[None], A, Bp)
            | _on_segment(o2, q[None], A, Bp)
            | _on_segment(o3, A, p[None], q[None])
            | _on_segment(o4, Bp, p[None], q[None])
        )
        ok[s : s + step] &= ~np.any(proper | touch, axis=1)
    return ok


def in_sight(arrays: PlanArrays, x: np.ndarray, landmarks: np.ndarray | None = None) -> np.ndarray:
    """Line of sight from each point to each landmark through the raw obstacles, shape (R, L) (ALGORITHMS §1).

    The segment from ``x`` to ``l − tol·unit(l − x)`` must touch no raw obstacle edge, so a tag on
    a wall is seen from the free side (:meth:`bearnav_cli.geometry.FreeSpace.visible`'s rule, exact
    against the embedded map's rings).

    Parameters
    ----------
    arrays : PlanArrays
        The plan's raw obstacle edges (``sight_edges``) and landmarks.
    x : ndarray, shape (R, 2)
        Where the camera is (map units).
    landmarks : ndarray, shape (L, 2), optional
        Other positions than the plan's landmarks (tags proposed for it; map units).
    """
    p = points(x)
    lm = arrays.landmarks if landmarks is None else np.asarray(landmarks, float).reshape(-1, 2)
    d = lm[None, :, :] - p[:, None, :]
    dist = np.hypot(d[..., 0], d[..., 1])
    far = dist > arrays.tol
    ends = lm[None] - arrays.tol * d / np.where(far, dist, 1.0)[..., None]
    out = edges_clear(arrays.sight_edges, np.repeat(p, len(lm), axis=0), ends.reshape(-1, 2), far.ravel())
    return out.reshape(len(p), len(lm))


def obstacle_clearance(arrays: PlanArrays, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance from each point to the nearest inflated obstacle edge or wall of ``B_r``, and the way away from it.

    Exact (point-to-segment distances over every ring edge of ``arrays.obstacle_edges``, chunked).
    A point outside ``B_r`` gets a negative clearance (minus its distance to ``B_r``); a point
    inside an obstacle gets its distance to that obstacle's boundary, so a caller that must tell
    free points apart tests membership separately. The distance to a segment or a wall's
    half-plane is convex, so ``clearance(x + δ) ≥ clearance_k(x) + away_k·δ`` for the nearest
    piece ``k``: moving along ``away`` never brings the point closer to that piece.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: ``obstacle_edges`` (E, 2, 2) and ``free_bounds`` (``B_r``).
    x : ndarray, shape (R, 2)
        Points (map units).

    Returns
    -------
    clearance : ndarray, shape (R,)
        Map units.
    away : ndarray, shape (R, 2)
        Unit direction from the nearest point of the nearest piece to ``x`` (for a wall, its
        inward normal); zero where ``x`` lies on it.
    """
    p = points(x)
    lo, hi = arrays.free_bounds[:2], arrays.free_bounds[2:]
    walls = np.concatenate([p - lo, hi - p], axis=1)  # x − xmin, y − ymin, xmax − x, ymax − y
    nearest_wall = np.argmin(walls, axis=1) if len(p) else np.zeros(0, np.int64)
    out = walls[np.arange(len(p)), nearest_wall] if len(p) else np.zeros(0)
    normals = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
    away = normals[nearest_wall] if len(p) else np.zeros((0, 2))
    edges = arrays.obstacle_edges
    if not len(edges) or not len(p):
        return out, away
    a, d = edges[:, 0], edges[:, 1] - edges[:, 0]
    length2 = np.maximum(np.einsum("ek,ek->e", d, d), arrays.tol**2)
    step = max(1, CHUNK // len(edges))
    for s in range(0, len(p), step):
        rel = p[s : s + step, None, :] - a[None]  # (r, E, 2)
        t = np.clip(np.einsum("rek,ek->re", rel, d) / length2, 0.0, 1.0)
        gap = rel - t[..., None] * d[None]  # from each edge's nearest point to x
        dist2 = np.einsum("rek,rek->re", gap, gap)
        k = np.argmin(dist2, axis=1)
        rows = np.arange(len(k))
        dist = np.sqrt(dist2[rows, k])
        closer = dist < out[s : s + step]
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = np.where(dist[:, None] > 0, gap[rows, k] / dist[:, None], 0.0)
        out[s : s + step] = np.where(closer, dist, out[s : s + step])
        away[s : s + step] = np.where(closer[:, None], unit, away[s : s + step])
    return out, away


def crossing_parity(a: np.ndarray, b: np.ndarray, p: np.ndarray, valid: np.ndarray | bool = True) -> np.ndarray:
    """Whether a ray from each point toward ``+x`` crosses the edges ``a → b`` an odd number of times, shape (R,).

    The even-odd test: odd is inside a ring the edges close (a point of two overlapping rings
    crosses both, an even number).

    Parameters
    ----------
    a, b : ndarray, shape (R, E, 2) or (E, 2)
        The edges' ends (map units): each point's own edges, or one set for every point.
    p : ndarray, shape (R, 2)
        The points (map units).
    valid : ndarray of bool, shape (R, E), or True
        The edges that count (padding rows do not).
    """
    px, py = p[:, 0, None], p[:, 1, None]
    straddles = valid & ((a[..., 1] > py) != (b[..., 1] > py))  # never true for a level edge
    with np.errstate(divide="ignore", invalid="ignore"):
        cross_x = a[..., 0] + (py - a[..., 1]) * (b[..., 0] - a[..., 0]) / (b[..., 1] - a[..., 1])
    return (np.count_nonzero(straddles & (px < cross_x), axis=1) % 2) == 1


def inside_obstacles(arrays: PlanArrays, p: np.ndarray) -> np.ndarray:
    """Whether each point lies inside an inflated obstacle ring of the plan (even-odd, chunked), shape (R,).

    Where obstacles overlap a point of both crosses an even number of edges: only a True is sure.
    """
    edges, step = arrays.obstacle_edges, max(1, CHUNK // max(len(arrays.obstacle_edges), 1))
    parts = [crossing_parity(edges[:, 0], edges[:, 1], p[s : s + step]) for s in range(0, len(p), step)]
    return np.concatenate(parts) if parts else np.zeros(0, bool)
