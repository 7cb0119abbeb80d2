"""Where the simulated robots start: the ``--starts`` forms ``map``, ``random:N`` and ``x,y;x,y;...``."""

from __future__ import annotations

import math
import re

import numpy as np

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.routes import sample_starts

__all__ = ["parse_starts", "resolve_starts"]

_RANDOM = re.compile(r"^random:(\d+)$")


def parse_starts(spec: str) -> str | int | np.ndarray:
    """``"map"``, the count of ``random:N``, or the explicit starts as an array (n, 2).

    Raises
    ------
    InvalidParamsError
        Anything else.
    """
    text = str(spec).strip()
    if text == "map":
        return "map"
    match = _RANDOM.match(text)
    if match:
        count = int(match.group(1))
        if count < 1:
            raise InvalidParamsError("random:N needs N >= 1", field="starts")
        return count
    try:
        points = [[float(v) for v in item.split(",")] for item in text.split(";") if item.strip()]
    except ValueError:
        points = []
    if not points or any(len(p) != 2 or not all(math.isfinite(v) for v in p) for p in points):
        raise InvalidParamsError(f"expected map, random:N or x,y;x,y;..., got {spec!r}", field="starts")
    return np.array(points, float)


def resolve_starts(map_, spec: str, rng: np.random.Generator) -> np.ndarray:
    """The starts ``spec`` names in ``map_``, shape (R, 2); ``random:N`` draws them from ``rng``
    (uniform over the free space of the goal's component).

    Parameters
    ----------
    map_ : Map
        The map: its ``starts`` (for ``map``), bounds, obstacles and goal.
    spec : str
        ``map`` (the map's own starts), ``random:N`` or ``x,y;x,y;...`` (map units), as
        :func:`parse_starts` reads it.
    rng : numpy.random.Generator
        Source of the ``random:N`` starts (not used by the other forms).

    Raises
    ------
    InvalidParamsError
        A start outside the bounds or inside an obstacle, named by its index and position.
    """
    parsed = parse_starts(spec)
    space = FreeSpace.from_map(map_)
    if isinstance(parsed, int):
        return sample_starts(space, map_.goal, parsed, rng)
    starts = np.asarray(map_.starts, float).reshape(-1, 2) if isinstance(parsed, str) else parsed
    inside = space.in_bounds(starts)
    blocked = space.in_obstacle(starts)
    for k, (x, y) in enumerate(starts):
        if not inside[k]:
            raise InvalidParamsError(f"start {k} ({x:g}, {y:g}) is outside the bounds", field="starts")
        if blocked[k]:
            raise InvalidParamsError(f"start {k} ({x:g}, {y:g}) is inside an obstacle", field="starts")
    return starts
