"""Collision and visibility queries behind one door (DESIGN §1.6, ALGORITHMS §1).

:class:`FreeSpace` is built once from a :class:`~bearnav_cli.datatypes.Map` and
answers every geometric question the stages ask, vectorised over numpy arrays
with shapely 2. Edge tests are exact (segment against polygon); touching an
obstacle counts as a collision.

Every name is re-exported here; the modules, each with one job:

- :mod:`~bearnav_cli.geometry.shapes` — map polygons and shapely, circles, inflation;
- :mod:`~bearnav_cli.geometry.free_space` — :class:`FreeSpace`, the barrier margin, landmark coverage;
- :mod:`~bearnav_cli.geometry.convex` — convex polygons as arrays: pieces, clipping, rows.
"""

from bearnav_cli.geometry.convex import box_polygon, clip, convex_pieces, drop_collinear, polygon_edges, polygon_rows
from bearnav_cli.geometry.free_space import (
    DEFAULT_CLEARANCE,
    GOAL_OPENING,
    FreeSpace,
    barrier_margin,
    landmark_coverage,
)
from bearnav_cli.geometry.shapes import (
    BUFFER_QUAD_SEGS,
    CIRCLE_SEGMENTS,
    circle_polygon,
    from_shapely,
    inflate,
    to_shapely,
)

__all__ = [
    "barrier_margin",
    "box_polygon",
    "BUFFER_QUAD_SEGS",
    "circle_polygon",
    "CIRCLE_SEGMENTS",
    "clip",
    "convex_pieces",
    "DEFAULT_CLEARANCE",
    "drop_collinear",
    "FreeSpace",
    "GOAL_OPENING",
    "from_shapely",
    "inflate",
    "landmark_coverage",
    "polygon_edges",
    "polygon_rows",
    "to_shapely",
]
