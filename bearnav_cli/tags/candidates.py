"""Where a tag can go: points along the raw obstacles' boundaries and the walls, facing real free space, apart."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from bearnav_cli.geometry import FreeSpace, box_polygon

__all__ = ["Candidates", "candidates", "NUDGE"]

#: A candidate's free side is tested this far off its edge (fraction of D).
NUDGE = 1e-6


@dataclass(frozen=True, eq=False)
class Candidates:
    """Tag positions the greedy may choose from, ``C`` of them.

    Attributes
    ----------
    positions : ndarray, shape (C, 2)
        On a raw obstacle's boundary or a wall of ``B`` (map units).
    normals : ndarray, shape (C, 2)
        Unit normal of the edge, pointing to its free side (where the tag faces).
    on_wall : ndarray of bool, shape (C,)
        On a wall of the bounds (else on an obstacle).
    """

    positions: np.ndarray
    normals: np.ndarray
    on_wall: np.ndarray


def _edge_samples(ring: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Points ``width`` apart along each edge of a closed ring (the middle of a shorter edge), and each one's edge's
    left unit normal; shapes (n, 2), (n, 2)."""
    a = np.asarray(ring, float).reshape(-1, 2)
    b = np.roll(a, -1, axis=0)
    d = b - a
    length = np.hypot(d[:, 0], d[:, 1])
    keep = length > 0
    a, d, length = a[keep], d[keep], length[keep]
    count = np.maximum(1, np.floor(length / width)).astype(np.int64)
    edge = np.repeat(np.arange(len(a)), count)
    k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    t = (k + 0.5) / count[edge]
    points = a[edge] + t[:, None] * d[edge]
    # an axis-parallel edge keeps its constant coordinate exactly (a + t·0)
    left = np.column_stack([-d[:, 1], d[:, 0]]) / length[:, None]
    return points, left[edge]


def _thin(points: np.ndarray, blockers: np.ndarray, width: float) -> np.ndarray:
    """Indices of ``points`` kept in order so that each is at least ``width`` from the blockers and the kept ones."""
    kept: list[int] = []
    taken = np.asarray(blockers, float).reshape(-1, 2)
    if len(points) and len(taken):
        d = np.hypot(*(points[:, None, :] - taken[None]).transpose(2, 0, 1))
        free = np.all(d >= width, axis=1)
    else:
        free = np.ones(len(points), bool)
    chosen = np.zeros((0, 2))
    for i in np.flatnonzero(free):
        if len(chosen) and np.min(np.hypot(*(chosen - points[i]).T)) < width:
            continue
        kept.append(int(i))
        chosen = np.vstack([chosen, points[i]])
    return np.array(kept, np.int64)


def candidates(map_: Any, width: float, space: Any = None) -> Candidates:
    """Candidate tag positions on the raw obstacles' boundaries and the walls (step 1 of :mod:`bearnav_cli.tags`).

    Only the geometric filters: on the boundary, the free side real (nudged point in ``B`` and
    outside every raw obstacle), at least ``width`` from every existing tag and from each other
    (walls first, then obstacles, in ring order). :func:`propose_tags` also drops the candidates
    no evaluation point sees.

    Parameters
    ----------
    map_ : Map
        The map: its walls, raw obstacles and existing tags.
    width : float
        Tag width (map units).
    space : FreeSpace, optional
        ``FreeSpace.from_map(map_)``, when already built.

    Returns
    -------
    Candidates
    """
    if space is None:
        space = FreeSpace.from_map(map_)
    rings = [(box_polygon(map_.bounds), True)]
    for poly in map_.raw_obstacles:
        rings += [(poly.exterior, False)] + [(h, False) for h in poly.holes]
    pts, nrm, wall = [np.zeros((0, 2))], [np.zeros((0, 2))], [np.zeros(0, bool)]
    for ring, on_wall in rings:
        p, n = _edge_samples(ring, width)
        pts.append(p)
        nrm.append(n)
        wall.append(np.full(len(p), on_wall))
    points, normals, on_wall = np.concatenate(pts), np.concatenate(nrm), np.concatenate(wall)
    eps = NUDGE * map_.diagonal
    lo, hi = np.asarray(map_.bounds[:2], float), np.asarray(map_.bounds[2:], float)

    def free_side(q: np.ndarray) -> np.ndarray:
        ok = np.all((q >= lo) & (q <= hi), axis=1)
        if ok.any() and not space.raw_obstacles.is_empty:
            ok[ok] = ~shapely.intersects_xy(space.raw_obstacles, q[ok, 0], q[ok, 1])
        return ok

    in_box = np.all((points >= lo) & (points <= hi), axis=1)
    plus, minus = free_side(points + eps * normals), free_side(points - eps * normals)
    keep = in_box & (plus != minus)  # exactly one side free: a real boundary between an obstacle and free space
    normals = np.where(plus[:, None], normals, -normals)
    points, normals, on_wall = points[keep], normals[keep], on_wall[keep]
    order = _thin(points, map_.landmarks, width)
    return Candidates(points[order], normals[order], on_wall[order])
