"""Barrier rows of a cell (ALGORITHMS §4.5–4.6 and the corridor rows of docs/choices.md).

Each function returns rows ``h(x) = n·x + q`` with unit normals ``n``, safe where every
``h >= 0``: the wedge through collision samples of §4.5 (:func:`cbf_rows`), the goal cell's
rows of §4.6 (:func:`goal_cbf_rows`), and the corridor rows that separate a tree edge from
every obstacle piece near its cell (:func:`corridor_rows`, the default) with the walls'
(:func:`wall_rows`).
"""

from __future__ import annotations

import logging
import math

import numpy as np
import shapely

from bearnav_cli.geometry import clip, convex_pieces, polygon_rows

__all__ = [
    "cbf_rows",
    "corridor_rows",
    "goal_cbf_rows",
    "wall_rows",
]

log = logging.getLogger(__name__)


def cbf_rows(
    child: np.ndarray,
    parent: np.ndarray,
    samples: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    tol: float,
    *,
    apex: str = "child",
    sample_filter: str = "both",
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Barrier rows of an edge cell: the wedge of ALGORITHMS §4.5.

    Parameters
    ----------
    child, parent : ndarray, shape (2,)
        ``x_i`` and ``x_j``.
    samples : ndarray, shape (S, 2)
        Collision samples (map units).
    A, b : ndarray, shapes (p, 2), (p,)
        The cell's half-planes ``A x <= b`` (for the in-cell filter).
    tol : float
        Map tolerance (map units) of the in-cell filter and of the on-edge-line test.
    apex : {"child", "parent"}
        Where the wedge's lines pass through.
    sample_filter : {"both", "projection", "cell"}
        Which samples may bound the wedge: those projecting onto the edge ``[x_i, x_j]``,
        those inside the cell, or both.

    Returns
    -------
    normals : ndarray, shape (h, 2)
        Unit normals ``n``; ``h(x) = n·(x − apex)``, ``h <= 2`` rows.
    offsets : ndarray, shape (h,)
        ``−n·apex``.
    on_edge : bool
        Whether a sample on the edge line was skipped.
    """
    origin, target = (child, parent) if apex == "child" else (parent, child)
    e = target - origin
    e2 = e @ e
    rel = samples - origin
    keep = np.ones(len(samples), bool)
    if sample_filter in ("both", "projection"):
        # the projection filter is stated on the edge from x_i whichever apex is used
        t = (samples - child) @ (parent - child) / e2
        keep &= (t >= 0.0) & (t <= 1.0)
    if sample_filter in ("both", "cell"):
        keep &= np.all(samples @ A.T <= b + tol, axis=1)
    cross = e[0] * rel[:, 1] - e[1] * rel[:, 0]
    dot = rel @ e
    length = math.sqrt(e2)
    on_edge = bool(np.any(keep & (np.abs(cross) <= tol * length)))
    normals, offsets = [], []
    for side in (1.0, -1.0):
        candidates = np.flatnonzero(keep & (side * cross > tol * length))
        if candidates.size == 0:
            continue
        theta = np.arctan2(np.abs(cross[candidates]), dot[candidates])
        best = candidates[np.lexsort((candidates, theta))[0]]
        d = rel[best]
        n = np.array([-d[1], d[0]]) / np.hypot(*d)
        if n @ e < 0:
            n = -n
        normals.append(n)
        offsets.append(-(n @ origin))
    return np.array(normals, float).reshape(-1, 2), np.array(offsets, float), on_edge


def goal_cbf_rows(
    goal: np.ndarray, samples: np.ndarray, polygon: np.ndarray, bounds: np.ndarray, tol: float
) -> tuple[np.ndarray, np.ndarray]:
    """Barrier rows of the goal cell (ALGORITHMS §4.6): one per supporting sample.

    Each sample ``o`` in the cell and off the border gives ``h_o(x) = n_o·(x − o)`` with
    ``n_o = unit(g − o)``; only rows that support an edge of the safe polygon are kept.

    Parameters
    ----------
    goal : ndarray, shape (2,)
        The goal ``g`` (map units); every row's normal points from its sample toward it.
    samples : ndarray, shape (S, 2)
        Collision samples of the tree (map units), border pseudo-samples included.
    polygon : ndarray, shape (p, 2)
        The goal cell (CCW, map units); only samples inside it (within ``tol``) give rows, and
        the safe polygon the kept rows must support is this cell clipped by every row.
    bounds : ndarray, shape (4,)
        ``(xmin, ymin, xmax, ymax)`` of the map (map units); samples within ``tol`` of a border
        line are border pseudo-samples and give no row.
    tol : float
        Map tolerance (map units) of the in-cell, on-border and supporting-edge tests.

    Returns
    -------
    normals : ndarray, shape (h, 2)
        Unit normals ``n_o`` of the supporting rows.
    offsets : ndarray, shape (h,)
        ``−n_o·o``, so that ``h(x) = normals @ x + offsets``.
    """
    A, b = polygon_rows(polygon)
    inside = np.all(samples @ A.T <= b + tol, axis=1)
    xmin, ymin, xmax, ymax = bounds
    border = (
        (np.abs(samples[:, 0] - xmin) <= tol)
        | (np.abs(samples[:, 0] - xmax) <= tol)
        | (np.abs(samples[:, 1] - ymin) <= tol)
        | (np.abs(samples[:, 1] - ymax) <= tol)
    )
    chosen = samples[inside & ~border]
    if len(chosen) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    normals = goal - chosen
    normals /= np.hypot(normals[:, 0], normals[:, 1])[:, None]
    offsets = -np.einsum("ij,ij->i", normals, chosen)
    # clip by the nearest rows first: far ones are then usually redundant at once
    order = np.argsort(normals @ goal + offsets, kind="stable")
    safe = polygon
    for k in order:
        safe = clip(safe, -normals[k], offsets[k], tol)  # h >= 0  <=>  −n·x <= q
    values = safe @ normals.T + offsets  # h_k at every vertex of the safe polygon
    on_line = np.abs(values) <= tol
    supports = (on_line & np.roll(on_line, -1, axis=0)).any(axis=0)
    return normals[supports], offsets[supports]


def _nearest_separators(pieces, segment: shapely.Geometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each piece, the nearest point ``p`` on it, the unit normal toward the segment and the gap."""
    pair = shapely.get_coordinates(shapely.shortest_line(np.asarray(pieces, dtype=object), segment)).reshape(-1, 2, 2)
    gap = pair[:, 1] - pair[:, 0]
    dist = np.hypot(gap[:, 0], gap[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        n = gap / dist[:, None]
    return pair[:, 0], n, dist


def wall_rows(polygon: np.ndarray, bounds: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """One row ``h(x) = n·x + q`` (inward unit normal, ``h`` the distance to the wall) per wall of ``B``
    within ``reach`` of the cell.

    Parameters
    ----------
    polygon : ndarray, shape (p, 2)
        The cell's vertices (map units); a wall gets a row when some vertex lies within
        ``reach`` of its line.
    bounds : ndarray, shape (4,)
        ``(xmin, ymin, xmax, ymax)`` of the walls ``B`` (map units).
    reach : float
        Distance from a wall (map units) below which the wall gets a row.

    Returns
    -------
    normals : ndarray, shape (w, 2)
        Inward unit normals, in the order left, right, bottom, top wall (``w <= 4``).
    offsets : ndarray, shape (w,)
        ``q``, so that ``h(x) = normals @ x + offsets`` is the distance to each wall.
    """
    xmin, ymin, xmax, ymax = bounds
    normals, offsets = [], []
    for axis, value, sign in ((0, xmin, 1.0), (0, xmax, -1.0), (1, ymin, 1.0), (1, ymax, -1.0)):
        if np.any(np.abs(polygon[:, axis] - value) <= reach):
            n = np.zeros(2)
            n[axis] = sign
            normals.append(n)
            offsets.append(-sign * value)
    return np.array(normals, float).reshape(-1, 2), np.array(offsets, float)


def corridor_rows(
    keep_clear: np.ndarray,
    polygon: np.ndarray,
    obstacles: shapely.Geometry,
    margin: float,
    walls: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Barrier rows that separate a segment from every obstacle piece near a cell.

    For each convex piece ``T`` of ``O ∩ buffer(X, margin)`` with nearest points ``p ∈ T``
    and ``s ∈ S`` (``S = [x_i, x_j]``, or the goal), the row is
    ``h(x) = n·(x − p) − m`` with ``n = unit(s − p)`` and ``m = min(margin, ‖s − p‖/2)``.
    By the optimality of the nearest pair, ``h ≥ ‖s − p‖ − m > 0`` on all of ``S`` and
    ``h ≤ −m`` on all of ``T``; the safe set ``{h ≥ 0}`` is therefore free of obstacles
    by at least ``m``, and contains the segment. Wall rows are moved the same way, by
    ``min(margin, d/2)`` with ``d`` the segment's distance from the wall.

    Parameters
    ----------
    keep_clear : ndarray, shape (2, 2) or (1, 2)
        The segment ``[x_i, x_j]`` or the single point ``g``.
    polygon : ndarray, shape (p, 2)
        The cell (CCW).
    obstacles : shapely geometry
        The inflated obstacles ``O``.
    margin : float
        Map units.
    walls : tuple of ndarray, optional
        Rows of the walls within ``margin`` of the cell (:func:`wall_rows`).

    Returns
    -------
    normals : ndarray, shape (h, 2)
        Unit normals.
    offsets : ndarray, shape (h,)
        ``h(x) = normals @ x + offsets``.
    levels : ndarray, shape (h,)
        ``−m`` of each row: its obstacle piece (or wall) lies where ``h <= level``.
    """
    ends = np.asarray(keep_clear, float).reshape(-1, 2)
    segment = shapely.LineString(ends) if len(ends) == 2 else shapely.Point(ends[0])
    region = shapely.Polygon(polygon)
    if margin > 0:
        region = shapely.buffer(region, margin, join_style="mitre")
    near = shapely.intersection(obstacles, region)
    normals, offsets, levels = [np.zeros((0, 2))], [np.zeros(0)], [np.zeros(0)]
    parts, edges = convex_pieces(near, segment) if not near.is_empty else ([], np.zeros((0, 2, 2)))
    anchor, n, dist = np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    if parts:
        anchor, n, dist = _nearest_separators(parts, segment)
    if len(edges):
        # An edge's own line separates it best when the segment lies on its free side (a wall
        # stays a wall); otherwise the nearest-point separator, as for the convex parts.
        d = edges[:, 1] - edges[:, 0]
        own = np.column_stack([d[:, 1], -d[:, 0]]) / np.hypot(d[:, 0], d[:, 1])[:, None]  # right: free side
        clear = np.min(np.einsum("ek,sk->es", own, ends) - np.einsum("ek,ek->e", own, edges[:, 0])[:, None], axis=1)
        use_own = clear > 0
        e_anchor, e_n, e_dist = edges[:, 0].copy(), own, clear
        if not use_own.all():
            rest = shapely.linestrings(edges[~use_own])
            e_anchor[~use_own], e_n[~use_own], e_dist[~use_own] = _nearest_separators(rest, segment)
        anchor, n, dist = np.concatenate([anchor, e_anchor]), np.concatenate([n, e_n]), np.concatenate([dist, e_dist])
    apart = dist > 0  # a piece that touches the segment (an edge that is not free) cannot be separated
    if not apart.all():
        log.warning("an obstacle touches the tree edge %s: it gets no barrier row", ends.round(6).tolist())
        anchor, n, dist = anchor[apart], n[apart], dist[apart]
    if len(dist):
        shift = np.minimum(margin, 0.5 * dist)
        rows = np.unique(np.column_stack([n, -np.einsum("ij,ij->i", n, anchor) - shift, -shift]).round(12), axis=0)
        normals.append(rows[:, :2] / np.hypot(rows[:, 0], rows[:, 1])[:, None])
        offsets.append(rows[:, 2])
        levels.append(rows[:, 3])
    if walls is not None:
        dist = np.min(ends @ walls[0].T + walls[1], axis=0)  # the segment's distance from each wall
        shift = np.minimum(margin, 0.5 * dist)
        normals.append(walls[0])
        offsets.append(walls[1] - shift)
        levels.append(-shift)
    # Every row is kept, also those redundant for the safe polygon: a robot that starts or
    # lands outside the safe set is kept off piece k by row k alone (h_k never decreases
    # while negative, and the piece lies at h_k <= level_k).
    return np.concatenate(normals), np.concatenate(offsets), np.concatenate(levels)
