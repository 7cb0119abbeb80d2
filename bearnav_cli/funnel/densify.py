"""Densification of funnel cells (ALGORITHMS §11.5 step 3, §12.7): leaves in the pockets the cells leave.

:func:`densify` adds leaves, largest pocket first, until the uncovered area is small enough or a budget
is spent; :func:`densify_leaf` finds a leaf for a pocket of ``F_m`` (its deepest points first) and
:func:`band_candidates` the leaf points of a pocket in the band along ``O``; :func:`join_leaf` joins a
leaf point to a node it sees. :mod:`bearnav_cli.stages.decompose` builds the leaves' cells.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import shapely
import shapely.ops

from bearnav_cli.funnel.coverage import reached_parts
from bearnav_cli.geometry import FreeSpace

__all__ = [
    "BAND_CORNER_TURN",
    "BAND_NODE_TRIES",
    "DENSIFY_BATCH",
    "DENSIFY_GRID",
    "DENSIFY_NEAREST",
    "WALL_LEAF_DEPTH",
    "band_candidates",
    "cells_union",
    "densify",
    "densify_leaf",
    "join_leaf",
    "pocket_mouth",
    "reached_coverage",
]

#: Densification tries a pocket's pole, a point on it, then up to ``DENSIFY_GRID²`` grid points in it.
DENSIFY_GRID = 16
#: Band leaves (ALGORITHMS §12.7) sit this fraction of the barrier margin from ``O``: their cells reach
#: within ``ROW_SHARE`` of that of the walls.
WALL_LEAF_DEPTH = 0.1
#: A band curve's vertex turning by more than this (radians) is a corner: band leaves go there first.
BAND_CORNER_TURN = math.radians(30.0)
#: Nodes a band leaf tries, nearest first, before its cell is given up for not keeping the floor.
BAND_NODE_TRIES = 3
#: Candidate points tested against the nodes in one vectorised call.
DENSIFY_BATCH = 8
#: Nodes (by route length) each candidate tries before all of them.
DENSIFY_NEAREST = 16


def cells_union(regions: list) -> shapely.Geometry:
    """The union of the cells built so far (:class:`~bearnav_cli.funnel.Region` objects)."""
    return shapely.union_all([shapely.Polygon(r.polygon) for r in regions])


def reached_coverage(domain: shapely.Geometry, covered: shapely.Geometry) -> tuple[float, float, float]:
    """The parts of ``domain`` (``F`` or ``F_m``) the cells ``covered`` meet (:func:`reached_parts`): their area,
    the share of it the cells cover, and the area they leave (map units², 1, map units²)."""
    reached, _ = reached_parts(domain, covered)
    area = float(reached.area)
    left = float(shapely.difference(reached, covered).area)
    return area, (1.0 - left / area if area > 0 else 1.0), left


def densify(pockets: list, allowed: float, budget: int, find_leaf: Callable, add_leaf: Callable) -> list:
    """Add leaves until the pockets' area is at most ``allowed`` or ``budget`` leaves were added (§11.5 step 3).

    Parameters
    ----------
    pockets : list of [geometry, area, unreachable]
        The uncovered pockets (separate polygons); a new cell only cuts the pockets it meets.
    allowed : float
        The uncovered area to stop at (map units²).
    budget : int
        At most this many leaves.
    find_leaf : callable
        ``find_leaf(pocket) -> (point, node)`` or None when no node reaches the pocket.
    add_leaf : callable
        ``add_leaf(point, node) -> cell polygon``: adds the leaf and builds its cell.

    Returns
    -------
    list
        The pockets left, those no node reaches marked.
    """
    marks_current = True  # no node was added since the unreachable pockets were marked
    grown_count = 0
    while sum(p[1] for p in pockets) > allowed and grown_count < budget:
        grown = False
        for pocket in sorted((p for p in pockets if not p[2]), key=lambda p: -p[1]):
            leaf = find_leaf(pocket[0])
            if leaf is None:
                pocket[2] = True
                continue
            cell = add_leaf(*leaf)
            hit = shapely.intersects(np.array([q[0] for q in pockets], dtype=object), cell)
            kept = [q for q, h in zip(pockets, hit, strict=True) if not h]
            for q in (q for q, h in zip(pockets, hit, strict=True) if h):
                kept += [
                    [g, float(g.area), q[2]] for g in shapely.get_parts(shapely.difference(q[0], cell)) if g.area > 0
                ]
            pockets = kept
            grown_count += 1
            grown = True
            marks_current = False
            break
        if not grown:
            if marks_current or not any(p[2] for p in pockets):
                break
            # nodes were added since the pockets were marked: they may see them now, so retry once
            for q in pockets:
                q[2] = False
            marks_current = True
    return pockets


def _seen(points: np.ndarray, cand: np.ndarray, nodes: np.ndarray, reach: FreeSpace, tol: float) -> np.ndarray:
    """``seen[i, k]``: node ``cand[i, k]`` is reached from ``points[i]`` by a segment free with clearance."""
    width = cand.shape[1]
    free = reach.segments_free(np.repeat(points, width, axis=0), nodes[cand.ravel()]).reshape(len(points), width)
    return free & (np.hypot(*(nodes[cand] - points[:, None, :]).transpose(2, 0, 1)) > 1e3 * tol)


def densify_leaf(
    pocket: shapely.Geometry,
    nodes: np.ndarray,
    cost: np.ndarray,
    reach: FreeSpace,
    tol: float,
    domain_edge: shapely.Geometry | None = None,
) -> tuple[np.ndarray, int] | None:
    """A leaf for an uncovered pocket: its point of largest clearance (the pole of inaccessibility, then
    a point on its surface) and the node with the least ``‖p − x_n‖ + cost(n)`` over the nodes it sees
    along a segment free with clearance; ``None`` when no node is reachable.

    When no deep point of the pocket sees a node (a long pocket behind a bend), points where the
    pocket meets the cells (its boundary off ``domain_edge``, the boundary of ``F_m``) are tried
    last: a leaf there is near the tree, and its cell reaches into the pocket, so the pocket is
    covered from its mouth inward over a few leaves.

    Parameters
    ----------
    pocket : shapely geometry
        One uncovered polygon.
    nodes, cost : ndarray, shapes (n, 2), (n,)
        The tree's nodes and their route costs to the goal (map units).
    reach : FreeSpace
        The free space with the planning clearance: leaves and their segments must be free in it.
    tol : float
        Map tolerance (map units): a node closer than ``1e3·tol`` is not a separate leaf's parent.
    domain_edge : shapely geometry, optional
        The boundary of ``F_m``, a hair thick: the pocket's boundary off it is its mouth.

    Returns
    -------
    (point, node) or None
    """
    pole = shapely.ops.polylabel(pocket, tolerance=max(tol, 1e-3 * math.sqrt(pocket.area)))
    surface = shapely.point_on_surface(pocket)
    # then a grid over the pocket, farthest from its boundary first: a large pocket whose pole sees
    # no node may still be reached from elsewhere in it
    x0, y0, x1, y1 = pocket.bounds
    xs, ys = np.meshgrid(np.linspace(x0, x1, DENSIFY_GRID + 2)[1:-1], np.linspace(y0, y1, DENSIFY_GRID + 2)[1:-1])
    grid = np.column_stack([xs.ravel(), ys.ravel()])
    grid = grid[shapely.contains_xy(pocket, grid[:, 0], grid[:, 1])]
    depth_in = shapely.distance(pocket.boundary, shapely.points(grid)) if len(grid) else np.zeros(0)
    grid = grid[np.argsort(-depth_in, kind="stable")]
    candidates = np.vstack([[pole.x, pole.y], [surface.x, surface.y], grid, pocket_mouth(pocket, domain_edge)])
    return join_leaf(candidates, nodes, cost, reach, tol)


def join_leaf(
    candidates: np.ndarray,
    nodes: np.ndarray,
    cost: np.ndarray,
    reach: FreeSpace,
    tol: float,
    eligible: np.ndarray | None = None,
    nearest: bool = False,
) -> tuple[np.ndarray, int] | None:
    """The first of ``candidates`` (in order) free in ``reach`` that sees a node along a segment free in
    ``reach``, and the node with the least ``‖p − x_n‖ + cost(n)`` among those it sees; None if none does.

    ``eligible``: the indices of the nodes that may be joined (band leaves hang from the tree and
    its F_m leaves, never from another band leaf, whose exit point would sit near a wall, nor from
    a node too shallow in its own cell for the band's floor on ``τ_c``).
    ``nearest``: the nearest node it sees instead of the cheapest route (measured on the kitchen:
    band leaves cover 98.3% of F with it, 98.1% by route, 96.7% joined to the farthest node).

    Parameters
    ----------
    candidates : ndarray, shape (k, 2)
        Leaf points, in the order they are tried (map units).
    nodes, cost : ndarray, shapes (n, 2), (n,)
        The tree's nodes and their route costs to the goal (map units).
    reach : FreeSpace
        The free space with the planning clearance.
    tol : float
        Map tolerance (map units).
    eligible : ndarray of int, optional
        The nodes that may be joined (all when None).
    nearest : bool
        Join the nearest node seen instead of the cheapest route.

    Returns
    -------
    (point, node) or None
    """
    if eligible is not None:
        leaf = join_leaf(candidates, nodes[eligible], cost[eligible], reach, tol, nearest=nearest)
        return None if leaf is None else (leaf[0], int(eligible[leaf[1]]))
    candidates = candidates[reach.points_free(candidates)] if len(candidates) else candidates
    # a few candidates at a time, deepest first, each against every node: most pockets are reached
    # from their pole, and a pocket no node sees costs one pass over its grid
    for start in range(0, len(candidates), DENSIFY_BATCH):
        group = candidates[start : start + DENSIFY_BATCH]
        # each candidate against its nodes in route order: the DENSIFY_NEAREST cheapest first, and all
        # of them only for the candidates ahead of the first that sees one of those (the result is
        # the first candidate, deepest first, that sees any node, joined to its cheapest seen node)
        route = np.hypot(*(group[:, None, :] - nodes[None]).transpose(2, 0, 1))
        route = route if nearest else route + cost[None]
        order = np.argsort(route, axis=1, kind="stable")
        # the deepest candidate alone first: it mostly sees a node (kitchen, cover F: 181 of 186
        # groups), and then the others' segments need no test
        head = _seen(group[:1], order[:1, :DENSIFY_NEAREST], nodes, reach, tol)
        if head.any():
            return group[0], int(order[0, int(np.argmax(head[0]))])
        near = np.vstack([head, _seen(group[1:], order[1:, :DENSIFY_NEAREST], nodes, reach, tol)])
        first = int(np.argmax(near.any(axis=1))) if near.any() else len(group)
        if first > 0 and len(nodes) > DENSIFY_NEAREST:
            ahead = _seen(group[:first], order[:first], nodes, reach, tol)
            if ahead.any():
                k = int(np.argmax(ahead.any(axis=1)))
                return group[k], int(order[k, int(np.argmax(ahead[k]))])
        if first < len(group):
            return group[first], int(order[first, int(np.argmax(near[first]))])
    return None


def band_candidates(pocket: shapely.Geometry, offset: shapely.Geometry) -> np.ndarray:
    """Leaf candidates of a pocket in the band along ``O`` (ALGORITHMS §12.7), shape (k, 2).

    Points of ``offset`` (the curve at the band leaf depth ``q`` from ``O`` and the walls) inside the
    pocket: first the curve's corners, sharpest turn first, then its middle, then points spread
    along it. A leaf there gets a cell that keeps only ``min(m, s·d) = q/20`` (``funnel.ROW_SHARE``)
    from the piece beside it, so its cell reaches that close to the wall. At a corner, the leaf is
    ``q`` from both walls and its cell fills the corner; from the middle of one wall, the cell keeps
    the row's share of its distance from the other wall, and filling the corner took a fan of leaves.
    """
    curve = shapely.intersection(pocket, offset)
    length = float(curve.length) if not curve.is_empty else 0.0
    if not length > 0:
        return np.zeros((0, 2))
    parts = shapely.get_parts(curve)
    lengths = shapely.length(parts)
    parts = parts[lengths > 0][np.argsort(-lengths[lengths > 0], kind="stable")]  # longest first
    # every part's vertices with their neighbours at once (a pocket's curve has some twenty parts):
    # the interior vertices of an open part; every vertex of a closed one, its first preceded by the
    # last but one (the closing repeat)
    xy, owner = shapely.get_coordinates(parts, return_index=True)
    starts = np.searchsorted(owner, np.arange(len(parts)))
    ends = np.append(starts[1:], len(xy)) - 1
    closed = np.all(xy[starts] == xy[ends], axis=1)
    first = np.where(closed, starts, starts + 1)
    count = np.maximum(ends - first, 0)  # vertices with a neighbour on either side
    at = np.repeat(first - np.cumsum(count) + count, count) + np.arange(count.sum())
    before = np.where(at == np.repeat(starts, count), np.repeat(ends - 1, count), at - 1)
    u, v = xy[at] - xy[before], xy[at + 1] - xy[at]
    turn = np.abs(np.arctan2(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0], np.einsum("ij,ij->i", u, v)))
    sharp = turn > BAND_CORNER_TURN
    corners = xy[at][sharp][np.argsort(-turn[sharp], kind="stable")]
    where = np.array([0.5, 0.25, 0.75, 0.1, 0.9])
    points = shapely.get_coordinates(shapely.line_interpolate_point(parts[:4, None], where, normalized=True).ravel())
    return np.concatenate([corners, points]).reshape(-1, 2)


def pocket_mouth(pocket: shapely.Geometry, domain_edge: shapely.Geometry | None) -> np.ndarray:
    """Up to ``DENSIFY_GRID`` points spread along where ``pocket`` meets the cells, shape (k, 2)."""
    if domain_edge is None:
        return np.zeros((0, 2))
    mouth = shapely.difference(pocket.boundary, domain_edge)
    length = float(mouth.length)
    if not length > 0:
        return np.zeros((0, 2))
    points = shapely.line_interpolate_point(mouth, np.linspace(0.0, 1.0, DENSIFY_GRID), normalized=True)
    return shapely.get_coordinates(points).reshape(-1, 2)
