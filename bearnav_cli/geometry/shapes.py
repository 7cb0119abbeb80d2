"""Map polygons and shapely both ways, polygonised circles, inflation by the robot radius (ALGORITHMS §1)."""

from __future__ import annotations

import math

import numpy as np
import shapely

from bearnav_cli.datatypes import Polygon
from bearnav_cli.params.map_ import CIRCLE_SEGMENTS

__all__ = ["BUFFER_QUAD_SEGS", "circle_polygon", "from_shapely", "inflate", "to_shapely"]


#: Segments per quarter circle of the round joins used for inflation.
BUFFER_QUAD_SEGS = 16


def to_shapely(polygon: Polygon) -> shapely.Polygon:
    """Convert a :class:`Polygon` to a shapely polygon."""
    return shapely.Polygon(polygon.exterior, [h for h in polygon.holes])


def from_shapely(geometry: shapely.Geometry) -> tuple[Polygon, ...]:
    """Split a (multi)polygon into :class:`Polygon` parts, normalised and in a fixed order.

    Rings are oriented as shapely's ``normalize`` leaves them and written without the
    closing repeat, so equal geometries give identical coordinates.
    """
    parts = [g for g in shapely.get_parts(shapely.normalize(geometry)) if not g.is_empty]
    parts = [p for p in parts if isinstance(p, shapely.Polygon) and p.area > 0]
    parts.sort(key=lambda p: (p.bounds[0], p.bounds[1], p.bounds[2], p.bounds[3]))
    return tuple(
        Polygon(
            np.asarray(p.exterior.coords)[:-1],
            tuple(np.asarray(h.coords)[:-1] for h in p.interiors),
        )
        for p in parts
    )


def circle_polygon(center: tuple[float, float], radius: float, segments: int = CIRCLE_SEGMENTS) -> np.ndarray:
    """Regular ``segments``-gon that contains the disc (vertices at ``r / cos(π/segments)``).

    Parameters
    ----------
    center : tuple of float
        ``(x, y)`` of the disc's centre (map units).
    radius : float
        The disc's radius ``r`` (map units); the polygon's edges touch the circle.
    segments : int
        Number of vertices, :data:`CIRCLE_SEGMENTS` by default; the first lies at angle 0.

    Returns
    -------
    ndarray, shape (segments, 2)
        Counter-clockwise vertices.
    """
    outer = radius / math.cos(math.pi / segments)
    angles = 2.0 * math.pi * np.arange(segments) / segments
    return np.column_stack([center[0] + outer * np.cos(angles), center[1] + outer * np.sin(angles)])


def inflate(raw: shapely.Geometry, radius: float) -> shapely.Geometry:
    """Configuration-space obstacles: ``buffer(raw, ρ')`` with ``ρ' = ρ / cos(π/(4q))``.

    The rounded-up radius makes the polygonal buffer contain the exact Minkowski sum
    with the disc of radius ``ρ`` (ALGORITHMS §1).
    """
    if radius <= 0:
        return raw
    grown = radius / math.cos(math.pi / (4 * BUFFER_QUAD_SEGS))
    return shapely.buffer(raw, grown, quad_segs=BUFFER_QUAD_SEGS, join_style="round")
