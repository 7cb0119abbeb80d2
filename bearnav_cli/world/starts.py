"""Where the simulated robots start: the ``--starts`` forms ``map``, ``random:N``, ``domain:N`` and ``x,y;x,y;...``."""

from __future__ import annotations

import math
import re

import numpy as np

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.routes import sample_starts
from bearnav_cli.runtime.invariants import cell_areas

__all__ = ["InDomain", "domain_starts", "parse_starts", "resolve_starts"]

_RANDOM = re.compile(r"^(random|domain):(\d+)$")


class InDomain(int):
    """The count ``N`` of ``domain:N``: starts drawn uniformly in the certified domain ``D`` (:func:`domain_starts`)."""


def parse_starts(spec: str) -> str | int | np.ndarray:
    """``"map"``, the count of ``random:N`` (an :class:`InDomain` for ``domain:N``), or the explicit starts (n, 2).

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
        count = int(match.group(2))
        if count < 1:
            raise InvalidParamsError(f"{match.group(1)}:N needs N >= 1", field="starts")
        return InDomain(count) if match.group(1) == "domain" else count
    try:
        points = [[float(v) for v in item.split(",")] for item in text.split(";") if item.strip()]
    except ValueError:
        points = []
    if not points or any(len(p) != 2 or not all(math.isfinite(v) for v in p) for p in points):
        raise InvalidParamsError(f"expected map, random:N, domain:N or x,y;x,y;..., got {spec!r}", field="starts")
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
    inside = space.in_bounds(starts)  # B_r: the bounds shrunk by the planning radius
    blocked = space.in_obstacle(starts)  # O: the obstacles grown by it
    lo, hi = np.asarray(map_.bounds[:2], float), np.asarray(map_.bounds[2:], float)
    for k, (x, y) in enumerate(starts):
        where = f"start {k} ({x:g}, {y:g})"
        if not inside[k]:
            if not (lo <= (x, y)).all() or not ((x, y) <= hi).all():
                raise InvalidParamsError(f"{where} is outside the bounds {_box(map_.bounds)}", field="starts")
            raise InvalidParamsError(
                f"{where} is within the {map_.inflation_text} of a wall (the robot's centre "
                f"stays in {_box(map_.free_bounds)})",
                field="starts",
            )
        if blocked[k]:
            raise InvalidParamsError(
                f"{where} is inside an obstacle grown by the {map_.inflation_text} (the robot would touch it)",
                field="starts",
            )
    return starts


def _box(bounds) -> str:
    x0, y0, x1, y1 = (float(v) for v in bounds)
    return f"[{x0:g}, {x1:g}] × [{y0:g}, {y1:g}]"


def domain_starts(arrays, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` starts drawn uniformly in the certified domain ``D`` (the union of a funnel plan's cells), (count, 2).

    A cell is picked with probability proportional to its area, a point uniformly in it (rejection in
    its bounding box), and the point is kept with probability ``1/k``, ``k`` the number of cells that
    hold it: so the starts are uniform over the union, overlaps counted once. Deterministic for a
    given generator state.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's cells (``row_A``, ``row_b``, ``cell_vertices``); a funnel plan.
    count : int
        Number of starts (map units).
    rng : numpy.random.Generator
        The source of the draws; advanced by the call.

    Raises
    ------
    InvalidParamsError
        The plan is not a funnel plan (its cells certify nothing beyond themselves).
    """
    if not arrays.funnel:
        raise InvalidParamsError("domain:N needs a funnel plan (its cells are the certified domain D)", field="starts")
    vo = arrays.cell_vertex_offsets
    lo = np.minimum.reduceat(arrays.cell_vertices, vo[:-1], axis=0)
    hi = np.maximum.reduceat(arrays.cell_vertices, vo[:-1], axis=0)
    area = np.abs(cell_areas(arrays))
    found: list[np.ndarray] = []
    need = int(count)
    while need > 0:
        batch = max(64, 4 * need)
        cell = rng.choice(arrays.n_cells, size=batch, p=area / area.sum())
        p = rng.uniform(lo[cell], hi[cell])
        slack = arrays.tol
        inside = np.all(np.einsum("rpk,rk->rp", arrays.row_A[cell], p) <= arrays.row_b[cell] + slack, axis=1)
        p = p[inside]
        holders = np.zeros(len(p), np.int64)
        for k in range(0, len(p), 128):  # (points, cells, rows) in chunks
            q = p[k : k + 128]
            holders[k : k + 128] = np.all(
                np.einsum("cpk,rk->rcp", arrays.row_A, q) <= arrays.row_b[None] + slack, axis=2
            ).sum(axis=1)
        keep = rng.uniform(size=len(p)) * np.maximum(holders, 1) < 1.0
        found.append(p[keep][:need])
        need -= len(found[-1])
    return np.concatenate(found) if found else np.zeros((0, 2))
