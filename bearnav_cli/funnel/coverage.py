"""What the cells are to cover (ALGORITHMS §11.1): ``F_m``, and its parts the cells reach and those they cannot."""

from __future__ import annotations

import numpy as np
import shapely

__all__ = ["coverage_domain", "reached_parts"]


def coverage_domain(
    free_region: shapely.Geometry, free_bounds: np.ndarray, obstacles: shapely.Geometry, margin: float
) -> shapely.Geometry:
    """``F_m``: the free points at distance at least ``m`` from ``O`` and from the walls of ``B_r`` (§11.1).

    Parameters
    ----------
    free_region : shapely geometry
        The part of ``B_r \\ O`` to cover (the goal's component of the free space).
    free_bounds : ndarray, shape (4,)
        ``B_r`` as ``(xmin, ymin, xmax, ymax)`` (map units).
    obstacles : shapely geometry
        The inflated obstacles ``O`` (may be empty).
    margin : float
        ``m`` (map units).

    Returns
    -------
    shapely geometry
        ``F_m``, possibly several polygons.
    """
    inner = shapely.buffer(shapely.box(*free_bounds), -margin, join_style="mitre")
    grown = shapely.buffer(obstacles, margin) if not obstacles.is_empty else obstacles
    domain = shapely.intersection(free_region, inner)
    return shapely.difference(domain, grown) if not grown.is_empty else domain


def reached_parts(domain: shapely.Geometry, covered: shapely.Geometry) -> tuple[shapely.Geometry, shapely.Geometry]:
    """Split ``F_m`` into the connected parts that the cells ``D`` meet and those they do not.

    A part of ``F_m`` that no cell meets is cut off from every cell, the goal's included, by
    passages narrower than ``2m``: a robot keeping the margin cannot get there from the goal's side,
    and densification, whose leaves join the tree by segments with clearance, does not reach it.
    The coverage target of §11.5 is of the reached parts; the rest is reported apart.

    Parameters
    ----------
    domain : shapely geometry
        ``F_m`` (:func:`coverage_domain`).
    covered : shapely geometry
        The union of the cells.

    Returns
    -------
    reached, unreached : shapely geometries
    """
    parts = shapely.get_parts(domain)
    parts = parts[shapely.area(parts) > 0] if len(parts) else parts
    if not len(parts):
        return shapely.Polygon(), shapely.Polygon()
    met = shapely.intersects(parts, covered)
    return shapely.union_all(parts[met]), shapely.union_all(parts[~met])
