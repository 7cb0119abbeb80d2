"""Convex polygons as numpy arrays: convex pieces of a region, clipping by a half-plane, edges and rows ``A x ≤ b``."""

from __future__ import annotations

import math

import numpy as np
import shapely

__all__ = ["box_polygon", "clip", "convex_pieces", "drop_collinear", "polygon_edges", "polygon_rows"]


def convex_pieces(region: shapely.Geometry, keep_clear: shapely.Geometry | None = None) -> tuple[list, np.ndarray]:
    """Convex pieces of ``region`` that a robot must keep off: each convex part itself, and every
    boundary edge of the other parts.

    Why edges: a convex set that holds a free point and meets a polygon's interior crosses its
    boundary, so staying off every boundary edge keeps a robot out of the polygon. A hull would
    also fence off the free pockets of a non-convex part (a storeroom's wall frame encloses the
    whole room), and triangles would add rows at arbitrary angles through free space.

    Parameters
    ----------
    region : shapely geometry
        (Multi)polygons.
    keep_clear : shapely geometry, optional
        A convex part that meets it is split into edges instead (it cannot be separated whole).

    Returns
    -------
    parts : list of shapely.Polygon
        The convex parts.
    edges : ndarray, shape (E, 2, 2)
        Boundary edges ``(a, b)`` of the other parts, oriented so that the part lies on their left.
    """
    parts: list = []
    edges = [np.zeros((0, 2, 2))]
    for part in shapely.get_parts(region):
        if not isinstance(part, shapely.Polygon) or part.area <= 0:
            continue
        hull = shapely.convex_hull(part)
        convex = hull.area - part.area <= 1e-9 * hull.area and not part.interiors
        if convex and (keep_clear is None or not shapely.intersects(hull, keep_clear)):
            parts.append(hull)
            continue
        part = shapely.orient_polygons(part)  # exterior CCW, holes CW: the part is on every ring's left
        for ring in (part.exterior, *part.interiors):
            xy = np.asarray(ring.coords)
            edges.append(np.stack([xy[:-1], xy[1:]], axis=1))
    return parts, np.concatenate(edges)


def box_polygon(bounds: np.ndarray) -> np.ndarray:
    """The bounds ``[xmin, ymin, xmax, ymax]`` as a CCW polygon, shape (4, 2)."""
    xmin, ymin, xmax, ymax = bounds
    return np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]], float)


def clip(polygon: np.ndarray, normal: np.ndarray, offset: float, tol: float) -> np.ndarray:
    """Clip a convex CCW polygon by the half-plane ``normal · x <= offset`` (exact, Sutherland–Hodgman).

    Vertices closer than ``tol`` to the previous kept vertex are dropped (ALGORITHMS §4.2).

    Parameters
    ----------
    polygon : ndarray, shape (p, 2)
        The convex polygon, CCW (map units).
    normal : ndarray, shape (2,)
        Normal of the half-plane's boundary line, pointing out of the kept side (any length).
    offset : float
        Right-hand side of ``normal · x <= offset`` (map units times ``‖normal‖``).
    tol : float
        Map tolerance (map units).

    Returns
    -------
    ndarray, shape (p', 2)
        The clipped polygon, CCW; possibly with fewer than 3 vertices when the half-plane
        misses the polygon.
    """
    side_array = polygon @ normal - offset
    if (side_array <= 0).all():
        return polygon
    # A cell has a handful of vertices: plain floats are several times faster than numpy calls here
    # (and give the same numbers: the same operations in the same order).
    side, points = side_array.tolist(), polygon.tolist()
    out = []
    # each vertex q with the next one, the last with the first
    following = zip(side[1:] + side[:1], points[1:] + points[:1], strict=True)
    for s0, (x0, y0), (s1, (x1, y1)) in zip(side, points, following, strict=True):
        if s0 <= 0:  # vertex q contributes itself when kept, then the crossing of its edge q → q+1
            out.append((x0, y0))
        if s0 < 0 < s1 or s1 < 0 < s0:
            t = s0 / (s0 - s1)
            out.append((x0 + t * (x1 - x0), y0 + t * (y1 - y0)))
    kept: list = []
    for v in out:  # drop points within tol of the previous kept one
        if not kept or math.hypot(v[0] - kept[-1][0], v[1] - kept[-1][1]) > tol:
            kept.append(v)
    if len(kept) > 1 and math.hypot(kept[0][0] - kept[-1][0], kept[0][1] - kept[-1][1]) <= tol:
        kept.pop()
    return np.array(kept, float).reshape(-1, 2)


def drop_collinear(polygon: np.ndarray, tol: float) -> np.ndarray:
    """A convex CCW polygon without the vertices that lie within ``tol`` of the line of their neighbours.

    Two edges on one line give two equal rows; a cell whose exit face is split by such a vertex
    (a §4.1 cell's bisectors meeting the exit line at ``x_j``) would hold ``x_j`` on a non-exit row.

    Parameters
    ----------
    polygon : ndarray, shape (p, 2)
        The convex polygon, CCW (map units).
    tol : float
        Map tolerance (map units).

    Returns
    -------
    ndarray, shape (p', 2)
    """
    if len(polygon) <= 3:
        return polygon
    # the neighbours by slicing (np.roll gives the same arrays, at several times the overhead)
    prev, nxt = np.concatenate((polygon[-1:], polygon[:-1])), np.concatenate((polygon[1:], polygon[:1]))
    chord = nxt - prev
    # distance of each vertex from the chord of its neighbours (the vertex is on its left, CCW)
    rel = polygon - prev
    area2 = np.abs(chord[:, 0] * rel[:, 1] - chord[:, 1] * rel[:, 0])
    offset = area2 / np.maximum(np.hypot(chord[:, 0], chord[:, 1]), tol)
    keep = offset > tol
    if keep.all():
        return polygon
    # one pass drops isolated collinear vertices; repeat for runs of them
    return drop_collinear(polygon[keep], tol) if keep.sum() >= 3 else polygon


def polygon_edges(polygon: np.ndarray) -> np.ndarray:
    """The edge vectors ``v_{q+1} − v_q`` of a polygon, the last back to the first, shape (p, 2).

    ``np.roll(polygon, -1, axis=0) − polygon`` (the same numbers), without ``np.roll``'s overhead:
    cells are built by the thousand.
    """
    return np.concatenate((polygon[1:], polygon[:1])) - polygon


def polygon_rows(polygon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals and offsets of a CCW polygon's edges, row ``q`` for ``v_q → v_{q+1}``.

    Returns
    -------
    A : ndarray, shape (p, 2)
    b : ndarray, shape (p,)
        The polygon is ``{x : A x <= b}``.
    """
    edge = polygon_edges(polygon)
    normal = np.column_stack([edge[:, 1], -edge[:, 0]])
    normal /= np.hypot(normal[:, 0], normal[:, 1])[:, None]
    return normal, np.einsum("ij,ij->i", normal, polygon)
