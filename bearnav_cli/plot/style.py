"""The figures' shared vocabulary: colours by role, polygons as patches, legend labels shared by artists.

Every colour is the palette's (:mod:`bearnav_cli.palette`, one source for figures and bags); the
names here are the roles the layers and the figure scripts of ``repro/`` draw with.
"""

from __future__ import annotations

from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import shapely
from matplotlib.patches import PathPatch
from matplotlib.path import Path as MplPath
from shapely.geometry.polygon import orient

from bearnav_cli.datatypes import Polygon
from bearnav_cli.palette import ROLE_COLORS

__all__ = [
    "add_geometry",
    "ADDED_COLOR",
    "AXIS_UNITS",
    "axis_labels",
    "EXIT_COLOR",
    "GOAL_COLOR",
    "INFLATED_COLOR",
    "LANDMARK_COLOR",
    "OUTLINE_COLOR",
    "polygon_patch",
    "RAW_COLOR",
    "shared_label",
    "TREE_COLOR",
    "UNCERTIFIED_COLOR",
    "UNCOVERED_COLOR",
    "UNREACHED_COLOR",
    "use_file_backend",
]


def use_file_backend() -> None:
    """Switch matplotlib to its file backend (Agg), as the command line does before drawing.

    Importing this module leaves the backend alone, so a notebook that imports it keeps its own.
    """
    matplotlib.use("Agg")


RAW_COLOR = ROLE_COLORS["raw obstacle"]
INFLATED_COLOR = ROLE_COLORS["inflated obstacle"]
OUTLINE_COLOR = ROLE_COLORS["cell outline"]
EXIT_COLOR = ROLE_COLORS["exit face"]
UNCERTIFIED_COLOR = ROLE_COLORS["uncertified"]
UNCOVERED_COLOR = ROLE_COLORS["uncovered"]
ADDED_COLOR = ROLE_COLORS["added node"]
LANDMARK_COLOR = ROLE_COLORS["landmark"]
GOAL_COLOR = ROLE_COLORS["goal"]
TREE_COLOR = ROLE_COLORS["tree"]
#: Parts of ``F_m`` that no cell reaches (cut off by passages narrower than ``2m``).
UNREACHED_COLOR = ROLE_COLORS["unreached"]
AXIS_UNITS = "map units"


def polygon_patch(polygon: Polygon, **style: Any) -> PathPatch:
    """A map polygon (exterior and holes) as one matplotlib patch with ``style``."""
    rings = [polygon.exterior, *polygon.holes]
    vertices = np.concatenate([np.vstack([r, r[:1]]) for r in rings])
    codes = np.concatenate([[MplPath.MOVETO] + [MplPath.LINETO] * (len(r) - 1) + [MplPath.CLOSEPOLY] for r in rings])
    return PathPatch(MplPath(vertices, codes), **style)


def _geometry_path(geom: shapely.Geometry) -> MplPath | None:
    """The polygons of a shapely geometry as one matplotlib path (holes cut out), or None if empty."""
    vertices, codes = [], []
    for part in shapely.get_parts(geom):
        if not isinstance(part, shapely.Polygon) or part.is_empty:
            continue
        part = orient(part, 1.0)
        for ring in (part.exterior, *part.interiors):
            xy = np.asarray(ring.coords)
            vertices.append(xy)
            codes.append([MplPath.MOVETO] + [MplPath.LINETO] * (len(xy) - 2) + [MplPath.CLOSEPOLY])
    return MplPath(np.concatenate(vertices), np.concatenate(codes)) if vertices else None


def add_geometry(ax: plt.Axes, geom: shapely.Geometry, **style: Any) -> PathPatch | None:
    """Add the polygons of a shapely geometry to ``ax`` as one patch with ``style``; None (nothing added) if empty."""
    path = _geometry_path(geom)
    return None if path is None else ax.add_patch(PathPatch(path, **style))


def shared_label(label: str, seen: set) -> str:
    """``label`` for the first artist of a legend entry, ``_label`` for the others that share it.

    matplotlib leaves labels starting with ``_`` out of a legend, so the entry appears once; the
    underscore form still names the entry the artist belongs to (what the tests read).
    """
    if label in seen:
        return "_" + label
    seen.add(label)
    return label


def axis_labels(ax: plt.Axes) -> None:
    """Name both axes in map units."""
    ax.set_xlabel(f"x ({AXIS_UNITS})")
    ax.set_ylabel(f"y ({AXIS_UNITS})")
