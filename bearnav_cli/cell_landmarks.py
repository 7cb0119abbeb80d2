"""The landmarks each cell's controller uses, and its fixed landmark (ALGORITHMS §5.4–§5.5).

:func:`witness_points` are the points a cell's landmarks must be seen from, :func:`seen_from` and
:func:`segments_seen` which landmarks each of them sees (visibility regions, or the exact segment
test), :func:`cell_landmarks` the nearest landmarks seen from all of them, and :func:`fixed_landmark`
the landmark that rescales bearings with its exact ``s_min``, ``s_max``.
:mod:`bearnav_cli.stages.decompose` calls them for every cell.
"""

from __future__ import annotations

import numpy as np
import shapely

from bearnav_cli.datatypes import CellFlag
from bearnav_cli.geometry import FreeSpace, polygon_edges, polygon_rows

__all__ = ["cell_landmarks", "fixed_landmark", "seen_from", "segments_seen", "witness_points"]


def witness_points(space: FreeSpace, polygon: np.ndarray, anchors: np.ndarray) -> np.ndarray:
    """The points a cell's landmarks must be seen from: the anchors and the vertices of the cell's
    free part (ALGORITHMS §5.4), shape (w, 2), unique rows.

    Parameters
    ----------
    space : FreeSpace
        The map's free space.
    polygon : ndarray, shape (p, 2)
        The cell, CCW (map units).
    anchors : ndarray, shape (a, 2)
        ``x_i, x_j`` of an edge cell, or ``g`` for the goal cell.
    """
    cell = shapely.Polygon(polygon)
    witnesses = [anchors]
    if not shapely.intersects(cell, space.obstacles):  # a funnel cell (C1): its free part is itself
        witnesses.append(polygon)
    else:
        for part in shapely.get_parts(shapely.difference(cell, space.obstacles)):
            if isinstance(part, shapely.Polygon) and not part.is_empty:
                witnesses.append(np.asarray(part.exterior.coords)[:-1])
                witnesses.extend(np.asarray(h.coords)[:-1] for h in part.interiors)
    return np.unique(np.concatenate(witnesses), axis=0)


def seen_from(sight: list, points: np.ndarray) -> np.ndarray:
    """``seen[q, k]``: landmark ``k`` is in line of sight from ``points[q]``, shape (w, L).

    ``sight`` are the landmarks' visibility regions (:meth:`FreeSpace.visibility_regions`): one
    prepared point query per landmark for all points, the segment test's answers away from shadow
    boundaries. A point on a region's boundary counts as seeing (a vertex on a wall sees what the
    wall does not hide).
    """
    seen = np.zeros((len(points), len(sight)), bool)
    for k, region in enumerate(sight):
        seen[:, k] = shapely.intersects_xy(region, points[:, 0], points[:, 1])
    return seen


def segments_seen(space: FreeSpace, points: np.ndarray, landmarks: np.ndarray, from_boundary: bool = False):
    """``seen[q, k]`` by the exact segment test (:meth:`FreeSpace.visible`), shape (w, L).

    Parameters
    ----------
    space : FreeSpace
        The map's free space.
    points : ndarray, shape (w, 2)
        Where the landmarks are looked at from (map units).
    landmarks : ndarray, shape (L, 2)
        The landmarks (map units).
    from_boundary : bool
        The points may lie on an obstacle's boundary (a cell's vertex on a wall).
    """
    n_lm = len(landmarks)
    pairs_p, pairs_l = np.repeat(points, n_lm, axis=0), np.tile(landmarks, (len(points), 1))
    return space.visible(pairs_p, pairs_l, from_boundary=from_boundary).reshape(len(points), n_lm)


def cell_landmarks(
    landmarks: np.ndarray,
    seen: np.ndarray,
    seen_from_anchors: np.ndarray,
    anchors: np.ndarray,
    n_landmarks: int,
) -> tuple[np.ndarray, bool]:
    """The landmarks a cell's controller uses (ALGORITHMS §5.4).

    Parameters
    ----------
    landmarks : ndarray, shape (L, 2)
        The map's landmarks (map units).
    seen : ndarray of bool, shape (w, L)
        :func:`seen_from` the cell's :func:`witness_points`.
    seen_from_anchors : ndarray of bool, shape (a, L)
        :func:`seen_from` the anchors alone.
    anchors : ndarray, shape (a, 2)
        ``x_i, x_j`` of an edge cell, or ``g`` for the goal cell; their mean is the
        point the landmarks are ranked by distance from.
    n_landmarks : int
        At most this many landmarks.

    Returns
    -------
    chosen : ndarray of int64, shape (n,)
        Landmark indices, nearest first, ``2 <= n <= n_landmarks``.
    flagged : bool
        True when fewer than 2 landmarks are visible from the whole free part (the choice
        was then topped up).
    """
    n_lm = len(landmarks)
    centre = anchors.mean(axis=0)
    dist = np.hypot(*(landmarks - centre).T)
    order = np.lexsort((np.arange(n_lm), dist))
    everywhere = seen.all(axis=0)
    chosen = [k for k in order if everywhere[k]][:n_landmarks]
    flagged = len(chosen) < 2
    if flagged:
        from_ends = seen_from_anchors.all(axis=0)
        for pool in ([k for k in order if from_ends[k]], list(order)):
            for k in pool:
                if len(chosen) >= 2:
                    break
                if k not in chosen:
                    chosen.append(k)
    return np.array(chosen, np.int64), flagged


def fixed_landmark(
    landmarks: np.ndarray, chosen: np.ndarray, polygon: np.ndarray, tol: float
) -> tuple[int, float, float, CellFlag]:
    """The fixed landmark ``f`` of a cell and the exact ``s_min``, ``s_max`` (ALGORITHMS §5.5).

    Parameters
    ----------
    landmarks : ndarray, shape (L, 2)
        The map's landmarks (map units).
    chosen : ndarray of int, shape (n,)
        The cell's landmarks (:func:`cell_landmarks`), nearest first.
    polygon : ndarray, shape (p, 2)
        The cell, CCW (map units).
    tol : float
        Map tolerance (map units).

    Returns
    -------
    f : int
        Landmark index.
    s_min, s_max : float
        ``dist(l_f, X_c)`` (0 if inside) and ``max_q ‖l_f − v_q‖``, map units.
    flag : CellFlag
        ``DEGENERATE_RISK`` or ``LANDMARK_INSIDE`` when rules 2 or 1 could not be met.
    """
    A, b = polygon_rows(polygon)
    lm = landmarks[chosen]  # (n, 2)
    # s_min: exact distance to the convex polygon (0 inside), every chosen landmark at once
    edge = polygon_edges(polygon)  # (p, 2)
    rel = lm[:, None, :] - polygon[None]  # (n, p, 2)
    t = np.clip(np.einsum("npi,pi->np", rel, edge) / np.einsum("pi,pi->p", edge, edge), 0.0, 1.0)
    gap = rel - t[..., None] * edge
    inside = np.all(lm @ A.T <= b, axis=1)
    s_min = np.where(inside, 0.0, np.sqrt(np.min(np.einsum("npi,npi->np", gap, gap), axis=1)))
    s_max = np.sqrt(np.max(np.einsum("npi,npi->np", rel, rel), axis=1))
    outside = s_min > tol
    # rule 2: the cell lies strictly on one side of the line through l_f and every other l_k
    d = lm[None, :, :] - lm[:, None, :]  # d[f, k] = l_k − l_f
    side = d[..., 0, None] * (polygon[None, None, :, 1] - lm[:, None, None, 1]) - d[..., 1, None] * (
        polygon[None, None, :, 0] - lm[:, None, None, 0]
    )  # (n, n, p)
    scale = tol * np.hypot(d[..., 0], d[..., 1])[..., None]
    one_side = np.all(side > scale, axis=2) | np.all(side < -scale, axis=2)
    np.fill_diagonal(one_side, True)
    clear = outside & one_side.all(axis=1)
    ratio = np.where(outside, s_max / np.where(outside, s_min, 1.0), np.inf)
    for pool, flag in ((clear, CellFlag.NONE), (outside, CellFlag.DEGENERATE_RISK)):
        if pool.any():
            idx = np.flatnonzero(pool)
            best = idx[np.lexsort((chosen[idx], ratio[idx]))[0]]
            return int(chosen[best]), float(s_min[best]), float(s_max[best]), flag
    best = int(np.lexsort((chosen, s_max))[0])
    return int(chosen[best]), 0.0, float(s_max[best]), CellFlag.LANDMARK_INSIDE
