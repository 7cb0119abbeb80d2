"""The corridor region of one tree edge (ALGORITHMS §11.5 step 1): the largest convex cell the rows allow.

One row per convex obstacle piece (a convex part of ``O``, or a boundary edge of a non-convex
part) that a spatial index says can reach the edge, one per wall of ``B_r``, and the exit row
``z·(x − x_j) ≥ 0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import shapely

from bearnav_cli.geometry import box_polygon, clip, convex_pieces, drop_collinear, polygon_rows

__all__ = ["exit_row_index", "funnel_region", "inset_walls", "ObstaclePieces", "PIECE_BATCH", "Region", "ROW_SHARE"]


#: A cell's row keeps ``min(m, ROW_SHARE·d)`` from an obstacle piece or wall at distance ``d`` from its
#: edge (ALGORITHMS §11.5 says ``d/2``). The nodes' depth in their cells, ``d − min(m, s·d)``, bounds
#: every exit inset and so every τ_c (§12.4), and a band leaf ``q`` from a wall leaves a sliver
#: ``s·q`` of ``F`` along it uncovered (§12.7). A twentieth (docs/algorithms.md, "Rows keep a
#: twentieth"): on 60 random plans the least τ_c rose by a median 28% over a quarter's, the median
#: τ_c by 38%, the cells fell by 28%, and every plan covers 99% of ``F`` (55 of 60 with a quarter).
#: The rows still hold the edge with slack ``0.95·d`` and keep ``d/20`` from the piece (C1).
ROW_SHARE = 0.05


@dataclass(frozen=True, eq=False)
class ObstaclePieces:
    """The convex pieces of ``O`` a cell must keep off, with a spatial index (ALGORITHMS §11.5 step 1).

    A convex part of ``O`` is one piece; every boundary edge of a non-convex part is one piece (a
    convex set that holds a free point and meets no boundary edge of a polygon misses its interior).

    Attributes
    ----------
    geoms : ndarray of shapely geometries, shape (P,)
        Convex polygons, then edges as line strings.
    edges : ndarray, shape (P, 2, 2)
        For an edge piece its endpoints ``(a, b)``, oriented with the obstacle on the left; NaN
        for a convex part.
    tree : shapely.STRtree
        Over ``geoms``.
    """

    geoms: np.ndarray
    edges: np.ndarray
    tree: shapely.STRtree

    @classmethod
    def from_obstacles(cls, obstacles: shapely.Geometry) -> ObstaclePieces:
        """Split the (inflated) obstacles into convex pieces."""
        parts, edge_array = convex_pieces(obstacles)
        geoms = np.concatenate([np.array(parts, dtype=object), shapely.linestrings(edge_array)])
        all_edges = np.concatenate([np.full((len(parts), 2, 2), np.nan), edge_array])
        return cls(geoms, all_edges, shapely.STRtree(geoms))

    def __len__(self) -> int:
        return len(self.geoms)

    @cached_property
    def own_lines(self) -> tuple[np.ndarray, np.ndarray]:
        """Each edge piece's own line as ``n·x = c``, ``n`` its unit normal to the free side (the right).

        Returns
        -------
        n : ndarray, shape (P, 2)
            NaN for a convex part.
        c : ndarray, shape (P,)
            Map units; NaN for a convex part.
        """
        d = self.edges[:, 1] - self.edges[:, 0]
        own = np.column_stack([d[:, 1], -d[:, 0]]) / np.hypot(d[:, 0], d[:, 1])[:, None]
        return own, np.einsum("ek,ek->e", own, self.edges[:, 0])

    def separating_rows(
        self, ends: np.ndarray, which: np.ndarray, margin: float, apart: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """One row ``A x ≤ b`` (unit ``A``) per piece in ``which`` that keeps the segment ``ends`` off it.

        For a piece with nearest points ``p`` (on the piece) and ``s`` (on the segment),
        ``n = unit(s − p)`` and ``d = ‖s − p‖``; an edge whose own line leaves the whole segment
        on its free side uses that line instead (a wall stays a wall). The row
        ``n·x ≥ n·p + min(margin, s·d)`` (``s`` = :data:`ROW_SHARE`) holds on the whole segment with
        slack at least ``d − min(margin, s·d) > 0`` and fails on the whole piece by at least
        ``min(margin, s·d)``.

        Parameters
        ----------
        ends : ndarray, shape (2, 2) or (1, 2)
            ``[x_i, x_j]``, or the goal alone.
        which : ndarray of int, shape (k,)
        margin : float
            Map units.
        apart : ndarray, shape (k,), optional
            ``shapely.distance`` of each piece in ``which`` from the segment (map units), when the
            caller has it already.

        Returns
        -------
        A, b : ndarray, shapes (k', 2), (k',)
            Rows of the pieces at positive distance (a piece touching the segment has none).
        """
        ends = np.asarray(ends, float).reshape(-1, 2)
        which = np.asarray(which, np.int64)
        if not len(which):
            return np.zeros((0, 2)), np.zeros(0)
        segment = shapely.LineString(ends) if len(ends) == 2 else shapely.Point(ends[0])
        anchor = np.zeros((len(which), 2))
        normal = np.zeros((len(which), 2))
        dist = np.zeros(len(which))
        edges = self.edges[which]
        is_edge = ~np.isnan(edges[:, 0, 0])
        use_own = np.zeros(len(which), bool)
        if is_edge.any():
            e = edges[is_edge]
            own, own_at = (lines[which[is_edge]] for lines in self.own_lines)
            clear = np.min(own @ ends.T - own_at[:, None], axis=1)
            # The own line only when it leaves the segment about as much room as the edge itself
            # does: a line through a far edge can pass right by the segment and squeeze the cell.
            far = shapely.distance(self.geoms[which[is_edge]], segment) if apart is None else apart[is_edge]
            good = (clear > 0) & (clear >= np.minimum(2.0 * margin, 0.5 * far))
            idx = np.flatnonzero(is_edge)[good]
            use_own[idx] = True
            anchor[idx], normal[idx], dist[idx] = e[good, 0], own[good], clear[good]
        rest = np.flatnonzero(~use_own)
        if len(rest):
            pair = shapely.get_coordinates(shapely.shortest_line(self.geoms[which[rest]], segment)).reshape(-1, 2, 2)
            gap = pair[:, 1] - pair[:, 0]
            length = np.hypot(gap[:, 0], gap[:, 1])
            with np.errstate(invalid="ignore", divide="ignore"):
                normal[rest] = gap / length[:, None]
            anchor[rest], dist[rest] = pair[:, 0], length
        apart = dist > 0
        shift = np.minimum(margin, ROW_SHARE * dist[apart])
        n = normal[apart]
        return -n, -np.einsum("ij,ij->i", n, anchor[apart]) - shift


def inset_walls(free_bounds: np.ndarray, ends: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """The four walls of ``B_r`` as rows ``A x ≤ b``, each moved ``min(margin, s·d)`` inward (``d`` the
    segment's distance from that wall).

    Parameters
    ----------
    free_bounds : ndarray, shape (4,)
        ``B_r`` as ``(xmin, ymin, xmax, ymax)`` (map units).
    ends : ndarray, shape (2, 2) or (1, 2)
        The segment ``[x_i, x_j]`` the cell holds, or the goal ``[g]`` (map units).
    margin : float
        The barrier margin ``m`` (map units): the most a wall moves inward.

    Returns
    -------
    A : ndarray, shape (4, 2)
        Outward unit normals of the left, right, bottom and top wall.
    b : ndarray, shape (4,)
        The moved walls' offsets, so that the segment stays strictly inside when it is inside ``B_r``.
    """
    xmin, ymin, xmax, ymax = free_bounds
    ends = np.asarray(ends, float).reshape(-1, 2)
    A = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])
    limit = np.array([-xmin, xmax, -ymin, ymax])
    dist = np.min(limit[None, :] - ends @ A.T, axis=0)
    return A, limit - np.minimum(margin, ROW_SHARE * dist)


def _clip_rows(polygon: np.ndarray, A: np.ndarray, b: np.ndarray, inside: np.ndarray, tol: float) -> np.ndarray:
    """Clip a convex polygon by every row ``A x ≤ b`` that cuts it, the tightest at ``inside`` first.

    Rows that never cut the shrinking polygon fall away without a clip.
    """
    slack = b - A @ inside
    order = np.argsort(slack, kind="stable")
    A, b = A[order], b[order]
    limit = b + tol
    while len(b):
        cuts = (polygon @ A.T).max(axis=0) > limit
        if not cuts.any():
            break
        k = int(cuts.argmax())  # the tightest row that still cuts
        polygon = clip(polygon, A[k], b[k], tol)
        cuts[k] = False  # the rows left to test: those that cut the polygon before this clip
        A, b, limit = A[cuts], b[cuts], limit[cuts]
    return polygon


#: Pieces whose rows are built and applied at a time, nearest the edge first (see :func:`_keep_off_pieces`).
PIECE_BATCH = 24


def _keep_off_pieces(
    pieces: ObstaclePieces, polygon: np.ndarray, ends: np.ndarray, margin: float, tol: float
) -> np.ndarray:
    """Clip ``polygon`` by the separating rows of the pieces that meet it, nearest the segment first.

    A piece gets its row only while it still meets the shrinking polygon: one hidden behind a
    nearer piece's row needs none. Every piece that meets the result had its row applied, so the
    result meets no piece (C1); it is the same or larger than the polygon cut by the rows of every
    piece that met the starting one, with fewer rows to build.
    """
    if not len(pieces):
        return polygon
    remaining = pieces.tree.query(shapely.Polygon(polygon), predicate="intersects")
    if not len(remaining):
        return polygon
    segment = shapely.LineString(ends) if len(ends) == 2 else shapely.Point(ends[0])
    apart = shapely.distance(pieces.geoms[remaining], segment)
    order = np.lexsort((remaining, apart))
    remaining, apart = remaining[order], apart[order]
    inside = ends.mean(axis=0)
    while len(remaining):
        A_o, b_o = pieces.separating_rows(ends, remaining[:PIECE_BATCH], margin, apart[:PIECE_BATCH])
        remaining, apart = remaining[PIECE_BATCH:], apart[PIECE_BATCH:]
        polygon = _clip_rows(polygon, A_o, b_o, inside, tol)
        if len(remaining) and len(polygon) >= 3:
            meet = shapely.intersects(pieces.geoms[remaining], shapely.Polygon(polygon))
            remaining, apart = remaining[meet], apart[meet]
    return polygon


@dataclass(frozen=True)
class Region:
    """A funnel cell as a CCW polygon and its rows.

    Attributes
    ----------
    polygon : ndarray, shape (p, 2)
        The cell's CCW vertices (map units).
    A, b : ndarray, shapes (p, 2), (p,)
        ``A[q]`` is the outward unit normal of the edge ``v_q → v_{q+1}``.
    exit_row : int
        Index of the exit row among them, ``-1`` for the goal cell.
    necked : bool
        Whether neck rows were added.
    """

    polygon: np.ndarray
    A: np.ndarray
    b: np.ndarray
    exit_row: int
    necked: bool = False


def exit_row_index(A: np.ndarray, b: np.ndarray, z: np.ndarray, x_j: np.ndarray, tol: float) -> int:
    """Index of the exit row ``−z·x ≤ −z·x_j`` among a cell's rows: normal ``−z``, through ``x_j``.

    Parameters
    ----------
    A, b : ndarray, shapes (p, 2), (p,)
        The cell's rows ``A x ≤ b`` with unit normals.
    z : ndarray, shape (2,)
        Unit exit direction ``unit(x_i − x_j)``.
    x_j : ndarray, shape (2,)
        The exit point, the parent node (map units).
    tol : float
        Map tolerance (map units); a row passes through ``x_j`` when ``|A_k·x_j − b_k| ≤ 1000·tol``.

    Returns
    -------
    int
        Among the rows through ``x_j`` with ``A_k·(−z) > 1 − 1e-9``, the one best aligned with ``−z``.

    Raises
    ------
    ValueError
        If no such row is left (the exit face was cut away).
    """
    score = A @ -z
    on_line = np.abs(A @ x_j - b) <= 1e3 * tol
    candidates = np.flatnonzero(on_line & (score > 1.0 - 1e-9))
    if not len(candidates):
        raise ValueError("the exit row was cut away (the edge's exit face is empty)")
    return int(candidates[np.argmax(score[candidates])])


def funnel_region(
    pieces: ObstaclePieces,
    free_bounds: np.ndarray,
    ends: np.ndarray,
    margin: float,
    tol: float,
    start: np.ndarray | None = None,
) -> Region:
    """The corridor region of an edge (or of the goal): ALGORITHMS §11.5 step 1.

    Parameters
    ----------
    pieces : ObstaclePieces
        The convex pieces of ``O`` the cell must keep off, with their spatial index.
    free_bounds : ndarray, shape (4,)
        ``B_r`` as ``(xmin, ymin, xmax, ymax)`` (map units).
    ends : ndarray, shape (2, 2) or (1, 2)
        ``[x_i, x_j]`` (child, parent) for an edge cell; ``[g]`` for the goal cell.
    margin : float
        The barrier margin ``m`` (map units).
    tol : float
        Map tolerance (map units) of the clips.
    start : ndarray, shape (p, 2), optional
        A convex polygon to start from instead of ``B_r`` (``funnel-local``: the §4.1 cell).

    Returns
    -------
    Region
    """
    ends = np.asarray(ends, float).reshape(-1, 2)
    A_w, b_w = inset_walls(free_bounds, ends, margin)
    if start is None:  # the wall rows are the sides of a box: B_r moved inward, no clipping needed
        polygon = box_polygon(np.array([-b_w[0], -b_w[2], b_w[1], b_w[3]]))
    else:
        polygon = _clip_rows(np.asarray(start, float), A_w, b_w, ends.mean(axis=0), tol)
    z = x_j = None
    if len(ends) == 2:
        x_i, x_j = ends
        z = (x_i - x_j) / math.hypot(*(x_i - x_j))
        polygon = clip(polygon, -z, -(z @ x_j), tol)
    polygon = _keep_off_pieces(pieces, polygon, ends, margin, tol)
    if len(polygon) < 3:
        raise ValueError(f"the cell of {ends.round(6).tolist()} degenerated (an obstacle touches the edge)")
    polygon = drop_collinear(polygon, tol)
    A, b = polygon_rows(polygon)
    exit_row = -1 if z is None else exit_row_index(A, b, z, x_j, tol)
    return Region(polygon, A, b, exit_row)
