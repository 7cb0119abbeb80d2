"""The parameters of the map stage: :class:`Params`, re-exported by :mod:`bearnav_cli.stages.map_`."""

from __future__ import annotations

from dataclasses import dataclass

from bearnav_cli.params.declare import Range, param

__all__ = ["CIRCLE_SEGMENTS", "Params", "UNKNOWN"]

#: Vertices of a polygonised circle (ALGORITHMS §1): the 64-gon circumscribes the disc
#: (:func:`bearnav_cli.geometry.circle_polygon`).
CIRCLE_SEGMENTS = 64
#: How an occupancy grid's unknown cells may count.
UNKNOWN = ("obstacle", "free")


@dataclass(frozen=True)
class Params:
    """Parameters of the map stage.

    Attributes
    ----------
    circle_segments : int
        Vertices of the polygon that replaces a circle (it contains the disc).
    unknown : {"obstacle", "free"}
        How unknown cells of an occupancy grid count.
    coverage_cells : int
        The landmark-coverage check uses a grid of spacing ``D / coverage_cells``.
    """

    circle_segments: int = param(CIRCLE_SEGMENTS, range=Range(8, 4096, integer=True))
    unknown: str = param("obstacle", choices=UNKNOWN)
    coverage_cells: int = param(100, range=Range(1, 1000, integer=True), option=None)
