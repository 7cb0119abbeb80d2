"""Funnel cells: obstacle-free convex cells whose exits land in their parents (ALGORITHMS §11.1, §11.5).

A funnel cell of the tree edge ``[x_i, x_j]`` is the largest convex region around the edge that
the corridor rows allow: one row per convex obstacle piece (a convex part of ``O``, or a boundary
edge of a non-convex part) that a spatial index says can reach it, one per wall of ``B_r``, and
the exit row ``z·(x − x_j) ≥ 0``. When its exit face is not inside the parent cell eroded by the
exit inset ``δ_e``, two neck rows through the ends of ``(P_j ⊖ δ_e) ∩ {V = 0}`` narrow it (§11.5
step 2). Where the cells leave part of ``F_m`` uncovered, :func:`densify` adds leaf nodes there.

Everything here is geometry on numpy arrays and shapely 2; :mod:`bearnav_cli.stages.decompose`
assembles the cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import shapely

from bearnav_cli.geometry import box_polygon, clip, convex_pieces, drop_collinear, polygon_rows

__all__ = [
    "INSET_LIMIT", "INSET_SAMPLES", "NECK_ANGLE", "PIECE_BATCH", "ROW_SHARE", "NeckChoice", "ObstaclePieces",
    "Region", "best_neck", "cell_tolerance", "coverage_domain", "depth", "exit_face", "exit_interval", "exit_sink",
    "exit_sinks", "exit_row_index", "funnel_region", "inset_walls", "neck_choice", "neck_rows", "necked",
    "plan_tolerance_of", "reached_parts", "usable_tolerances",
]  # fmt: skip

#: A cell's row keeps ``min(m, ROW_SHARE·d)`` from an obstacle piece or wall at distance ``d`` from its
#: edge (ALGORITHMS §11.5 says ``d/2``). The nodes' depth in their cells, ``d − min(m, s·d)``, bounds
#: every exit inset and so every τ_c (§12.4), and a band leaf ``q`` from a wall leaves a sliver
#: ``s·q`` of ``F`` along it uncovered (§12.7). A twentieth (docs/algorithms.md, "Rows keep a
#: twentieth"): on 60 random plans the least τ_c rose by a median 28% over a quarter's, the median
#: τ_c by 38%, the cells fell by 28%, and every plan covers 99% of ``F`` (55 of 60 with a quarter).
#: The rows still hold the edge with slack ``0.95·d`` and keep ``d/20`` from the piece (C1).
ROW_SHARE = 0.05

#: ψ of the neck rows: the angle their lines make with the exit direction ``z`` (radians).
NECK_ANGLE = math.radians(45.0)


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

    def separating_rows(self, ends: np.ndarray, which: np.ndarray, margin: float,
                        apart: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
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


def _keep_off_pieces(pieces: ObstaclePieces, polygon: np.ndarray, ends: np.ndarray, margin: float,
                     tol: float) -> np.ndarray:  # fmt: skip
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


def necked(region: Region, x_i: np.ndarray, x_j: np.ndarray, parent: Region, inset: float, tol: float) -> Region:
    """``region`` with neck rows when its exit face is not inside ``parent ⊖ inset`` (§11.5 step 2).

    Parameters
    ----------
    region : Region
        The cell of the edge ``[x_i, x_j]`` (:func:`funnel_region`).
    x_i, x_j : ndarray, shape (2,)
        The edge's child and parent node (map units); ``z = unit(x_i − x_j)``.
    parent : Region
        The parent node's cell, whose erosion by ``inset`` must hold the exit face.
    inset : float
        The exit inset ``δ_e`` (map units).
    tol : float
        Map tolerance (map units) of the clips; the neck ends are moved ``100·tol`` inside the
        eroded parent so that rounding cannot put the face's ends outside it.

    Returns
    -------
    Region
        ``region`` itself when its exit face already lies in ``parent ⊖ inset``; else the region
        clipped by the two :func:`neck_rows`, ``necked`` True.

    Raises
    ------
    ValueError
        ``x_j`` lies within ``inset`` of the parent's boundary (the caller caps the inset below
        every node's depth, so this is a bug).
    """
    z = (x_i - x_j) / math.hypot(*(x_i - x_j))
    w = np.array([-z[1], z[0]])
    t_a, t_b = exit_interval(parent.A, parent.b, x_j, w, inset)
    if not t_a < 0.0 < t_b:
        raise ValueError(f"the exit point {x_j.round(6).tolist()} lies within the exit inset of its parent cell")
    k, p = region.exit_row, len(region.polygon)
    ends = sorted(((region.polygon[k] - x_j) @ w, (region.polygon[(k + 1) % p] - x_j) @ w))
    if t_a <= ends[0] and ends[1] <= t_b:
        return region
    # a hair inside [a, b], so that rounding cannot put the face's ends outside the eroded parent
    pad = 100.0 * tol
    A_n, b_n = neck_rows(x_j, z, t_a + pad, t_b - pad)
    polygon = clip(clip(region.polygon, A_n[0], b_n[0], tol), A_n[1], b_n[1], tol)
    A, b = polygon_rows(polygon)
    return Region(polygon, A, b, exit_row_index(A, b, z, x_j, tol), True)


#: Per-cell exit insets (ALGORITHMS §12.4): insets scored per pass, and the largest tried as a fraction of
#: the exit point's depth in its parent (the face holds ``x_j``, so no inset can exceed that depth).
INSET_SAMPLES = 12
INSET_LIMIT = 0.98


@dataclass(frozen=True)
class NeckChoice:
    """The necked cell of one edge for its chosen exit inset (ALGORITHMS §12.4).

    Attributes
    ----------
    region : Region
        The cell, necked when its exit face had to be narrowed.
    inset : float
        ``δ_e,c``: the least slack of the exit face's ends in the parent's rows (map units), at
        least the inset the neck was built for.
    sink_depth : float
        ``h*``: the largest side depth of a point of the exit face (:func:`exit_sink`, map units),
        twice what Lemma 6's field tolerates.
    """

    region: Region
    inset: float
    sink_depth: float

    @property
    def usable(self) -> float:
        """``min(h*/2, δ_e,c/2)``: the ``τ_c`` Lemma 6's field gives this cell (map units)."""
        return 0.5 * min(self.sink_depth, self.inset)


def neck_choice(region: Region, x_i: np.ndarray, x_j: np.ndarray, parent: Region, inset: float,
                tol: float) -> NeckChoice:  # fmt: skip
    """``region`` necked for ``inset`` (:func:`necked`), with its actual inset and sink depth.

    Parameters
    ----------
    region : Region
        The un-necked cell of the edge ``[x_i, x_j]``.
    x_i, x_j : ndarray, shape (2,)
        Child and parent node (map units).
    parent : Region
        The parent node's final cell.
    inset : float
        The inset the neck is built for (map units), below the depth of ``x_j`` in ``parent``.
    tol : float
        Map tolerance (map units).

    Returns
    -------
    NeckChoice
    """
    cell = necked(region, x_i, x_j, parent, inset, tol)
    return _scored(cell, exit_face(cell.polygon, (x_i - x_j) / math.hypot(*(x_i - x_j)), x_j), parent)


def _scored(cell: Region, face: np.ndarray, parent: Region) -> NeckChoice:
    """``cell`` with its exit face's slack in ``parent`` and its sink depth ``h*``; ``face`` is its
    :func:`exit_face`, shape (2, 2)."""
    keep = np.arange(len(cell.b)) != cell.exit_row
    return NeckChoice(cell, depth(parent.A, parent.b, face), exit_sink(face, -cell.A[keep], cell.b[keep])[1])


def best_neck(region: Region, x_i: np.ndarray, x_j: np.ndarray, parent: Region, tol: float,
              samples: int = INSET_SAMPLES) -> NeckChoice:  # fmt: skip
    """The exit inset of one edge cell that maximises ``τ_c = min(h*/2, δ_e,c/2)`` (ALGORITHMS §12.4).

    A larger inset narrows the exit face (its neck) and so lowers ``h*``, while the face's slack
    in the parent, ``δ_e,c``, grows with it. ``samples`` insets evenly spaced in
    ``(0, INSET_LIMIT·depth(x_j, parent)]`` are scored at once, then as many again around the
    best, and the best is built (:func:`neck_choice`; ties: the smaller inset). Scoring needs no
    clipping: the neck rows pass through the ends ``a, b`` of the eroded parent's chord, so the
    necked face is the face clipped to ``[a, b]``; along it every row is affine in the position
    ``t``, so ``h*`` is the largest, over the face's ends and every crossing of two rows, of the
    least row (a row that the clip makes redundant is never nearer than the boundary). The
    synthesis never tolerates less than Lemma 6's field, so this ``τ_c`` bounds the plan's
    from below.

    Parameters
    ----------
    region : Region
        The un-necked cell of the edge ``[x_i, x_j]``.
    x_i, x_j : ndarray, shape (2,)
        Child and parent node (map units).
    parent : Region
        The parent node's final cell.
    tol : float
        Map tolerance (map units).
    samples : int
        Insets scored per pass (two passes).

    Returns
    -------
    NeckChoice
    """
    # a face already deeper in the parent than its own side depth: any neck would only lower h*
    z = (x_i - x_j) / math.hypot(*(x_i - x_j))
    face = exit_face(region.polygon, z, x_j)
    bare = _scored(region, face, parent)
    if bare.inset >= bare.sink_depth:
        return bare
    w = np.array([-z[1], z[0]])
    f0, f1 = np.sort((face - x_j) @ w)
    keep = np.arange(len(region.b)) != region.exit_row
    slope, room0 = parent.A @ w, parent.b - parent.A @ x_j
    up, down = slope > 1e-15, slope < -1e-15
    pad = 100.0 * tol  # as necked() pads the neck ends
    A_n, _ = neck_rows(x_j, z, 0.0, 0.0)  # the neck rows' normals; only their offsets depend on the inset
    normals = np.vstack([-region.A[keep], -A_n])
    offsets = np.concatenate([region.b[keep], [np.inf, np.inf]])
    # what does not depend on the inset, once: the divisors of the eroded parent's rows along the exit
    # line, and the neck rows' offsets at t = 0 and their rates along it
    over_up, over_down = np.where(up, slope, 1.0), np.where(down, slope, 1.0)
    (at_a, at_b), (rate_a, rate_b) = (A_n[0] @ x_j, A_n[1] @ x_j), (A_n[0] @ w, A_n[1] @ w)

    def usable(insets: np.ndarray) -> np.ndarray:
        # the parent's rows along the first axis: minima over an outer axis are the fast ones
        room = room0[:, None] - insets[None, :]  # (p, K): the eroded parent's rows along the exit line
        t_b = np.min(np.where(up[:, None], room / over_up[:, None], np.inf), axis=0) - pad
        t_a = np.max(np.where(down[:, None], room / over_down[:, None], -np.inf), axis=0) + pad
        necked_ = ~((t_a - pad <= f0) & (f1 <= t_b + pad))
        lo, hi = np.where(necked_, np.maximum(f0, t_a), f0), np.where(necked_, np.minimum(f1, t_b), f1)
        ends = np.stack([lo, hi])  # (2, K): the necked faces' ends along w
        q = np.broadcast_to(offsets, (len(insets), len(offsets))).copy()
        # where necked, the neck rows through a = x_j + t_a·w and b = x_j + t_b·w (neck_rows)
        q[:, -2] = np.where(necked_, at_a + t_a * rate_a, np.inf)
        q[:, -1] = np.where(necked_, at_b + t_b * rate_b, np.inf)
        faces = x_j + ends.T[:, :, None] * w  # (K, 2, 2)
        h_star = exit_sinks(faces, np.broadcast_to(normals, (len(insets), *normals.shape)), q)[1]
        slack = np.min(room0[:, None, None] - ends[None] * slope[:, None, None], axis=(0, 1))
        return np.where(lo < hi, 0.5 * np.minimum(h_star, slack), -np.inf)

    limit = INSET_LIMIT * depth(parent.A, parent.b, x_j)
    grid = limit * np.arange(1, samples + 1) / samples
    scores = usable(grid)
    k = int(np.argmax(scores))
    fine = grid[k] + (limit / samples) * np.linspace(-1.0, 1.0, samples + 2)[1:-1]
    fine = fine[(fine > 0) & (fine <= limit)]
    both = np.concatenate([grid, fine])
    # an inset's score is its own row's: the grid's scores stand, only the fine insets are new
    scores = np.concatenate([scores, usable(fine)]) if len(fine) else scores
    best = both[np.lexsort((both, -scores))[0]]
    return neck_choice(region, x_i, x_j, parent, float(best), tol)


def depth(A: np.ndarray, b: np.ndarray, point: np.ndarray) -> float:
    """``min_k (b_k − A_k·point)``: how deep a point lies in ``{A x ≤ b}`` (map units; < 0 outside).

    Given several points (an exit face's two ends, say), the least depth of any of them.

    Parameters
    ----------
    A, b : ndarray, shapes (p, 2), (p,)
        A convex polygon's rows with unit normals (then the depth is the distance to the boundary).
    point : array_like, shape (2,)
        The point (map units).

    Returns
    -------
    float
    """
    return float(np.min(b[None, :] - np.asarray(point, float).reshape(-1, 2) @ np.asarray(A).T))


def exit_interval(A: np.ndarray, b: np.ndarray, x_j: np.ndarray, w: np.ndarray, inset: float) -> tuple[float, float]:
    """``[t_a, t_b]`` with ``(P ⊖ inset) ∩ {x_j + t·w} = {x_j + t·w : t_a ≤ t ≤ t_b}`` (empty: ``t_a > t_b``).

    Parameters
    ----------
    A, b : ndarray, shapes (p, 2), (p,)
        The rows of the (parent) polygon ``P``, unit normals, so that ``P ⊖ inset`` is
        ``{A x ≤ b − inset}``.
    x_j : ndarray, shape (2,)
        A point of the line (the exit point, map units).
    w : ndarray, shape (2,)
        The line's unit direction (the exit direction turned by +90°).
    inset : float
        The erosion ``δ_e`` (map units).

    Returns
    -------
    t_a, t_b : float
        Signed distances along ``w`` from ``x_j`` (map units); ``±inf`` where the line is
        unbounded in ``P``, ``(inf, −inf)`` when it misses ``P ⊖ inset``.
    """
    slope = A @ w
    room = b - inset - A @ x_j
    lo, hi = -math.inf, math.inf
    up, down = slope > 1e-15, slope < -1e-15
    if up.any():
        hi = float(np.min(room[up] / slope[up]))
    if down.any():
        lo = float(np.max(room[down] / slope[down]))
    if np.any(~(up | down) & (room < 0)):
        return math.inf, -math.inf
    return lo, hi


def neck_rows(
    x_j: np.ndarray, z: np.ndarray, t_a: float, t_b: float, angle: float = NECK_ANGLE
) -> tuple[np.ndarray, np.ndarray]:
    """The two neck rows through ``a = x_j + t_a·w`` and ``b = x_j + t_b·w`` (ALGORITHMS §11.5 step 2).

    ``w`` is ``z`` turned by +90°. Their lines make the angle ψ with ``z`` and open away from the
    exit, so the exit face becomes ``[a, b]``, and ``x_j`` and the whole edge stay strictly inside
    when ``t_a < 0 < t_b``.

    Parameters
    ----------
    x_j : ndarray, shape (2,)
        The exit point (map units).
    z : ndarray, shape (2,)
        Unit exit direction, into the cell.
    t_a, t_b : float
        Where the exit face is to end along ``w``, from ``x_j`` (map units); ``t_a < t_b``.
    angle : float
        ψ, the angle between each neck line and ``z`` (rad); :data:`NECK_ANGLE` by default.

    Returns
    -------
    A : ndarray, shape (2, 2)
        Outward unit normals of the rows through ``a`` and through ``b``.
    b : ndarray, shape (2,)
        Their offsets: ``A x ≤ b``.
    """
    w = np.array([-z[1], z[0]])
    c, s = math.cos(angle), math.sin(angle)
    n_b = c * w - s * z  # outward at the +w side
    n_a = -c * w - s * z
    a_pt, b_pt = x_j + t_a * w, x_j + t_b * w
    return np.stack([n_a, n_b]), np.array([n_a @ a_pt, n_b @ b_pt])


def coverage_domain(free_region: shapely.Geometry, free_bounds: np.ndarray, obstacles: shapely.Geometry,
                    margin: float) -> shapely.Geometry:  # fmt: skip
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


def exit_sink(face: np.ndarray, normals: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, float]:
    """The sink of Lemma 6 (ALGORITHMS §12.4): the point of the exit face of largest side depth.

    One cell of :func:`exit_sinks`.

    Parameters
    ----------
    face : ndarray, shape (2, 2)
        The two ends of the exit face ``E_c`` (map units).
    normals, offsets : ndarray, shapes (h, 2), (h,)
        The non-exit rows as barriers, ``h_k(x) = n_k·x + q_k ≥ 0`` in the cell (unit normals,
        so ``h_k`` is the distance to row k's line).

    Returns
    -------
    sink : ndarray, shape (2,)
        ``x*`` on the face (map units).
    depth : float
        ``h* = min_k h_k(x*)`` (map units); ``inf`` without rows.
    """
    face = np.asarray(face, float).reshape(1, 2, 2)
    sink, depth_ = exit_sinks(face, np.asarray(normals, float).reshape(1, -1, 2), np.asarray(offsets).reshape(1, -1))
    return sink[0], float(depth_[0])


def exit_sinks(faces: np.ndarray, normals: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lemma 6's sink of many cells at once: per cell, the point of its exit face of largest side depth.

    ``h*(x) = min_k (n_k·x + q_k)`` over a cell's non-exit rows is concave and piecewise affine
    along the face, so its maximum is at an end of the face or where two rows' values cross; every
    such point is evaluated (exact, no search).

    Parameters
    ----------
    faces : ndarray, shape (C, 2, 2)
        The two ends of each cell's exit face (map units).
    normals, offsets : ndarray, shapes (C, H, 2), (C, H)
        Each cell's non-exit rows as barriers, ``h_k(x) = n_k·x + q_k ≥ 0`` in the cell (unit
        normals); pad a cell with fewer rows with zero normals and ``+inf`` offsets.

    Returns
    -------
    sinks : ndarray, shape (C, 2)
        ``x*`` on each face (map units).
    depths : ndarray, shape (C,)
        ``h*`` (map units); ``inf`` for a cell without rows.
    """
    faces = np.asarray(faces, float).reshape(-1, 2, 2)
    n = np.asarray(normals, float).reshape(len(faces), -1, 2)
    q = np.asarray(offsets, float).reshape(len(faces), -1)
    if not q.shape[1]:  # no rows: every point of the face is as deep (inf)
        return faces.mean(axis=1), np.full(len(faces), np.inf)
    along = faces[:, 1] - faces[:, 0]
    alpha = np.einsum("chi,ci->ch", n, faces[:, 0]) + q  # h_k at t = 0
    beta = np.einsum("chi,ci->ch", n, along)  # its slope along t ∈ [0, 1]
    t = np.zeros((len(faces), 2 + q.shape[1] ** 2))  # the face's ends, then every pair's crossing
    t[:, 1] = 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = (alpha[:, None, :] - alpha[:, :, None]) / (beta[:, :, None] - beta[:, None, :])
        cross = cross.reshape(len(faces), -1)
        inner = (cross > 0.0) & (cross < 1.0)  # false for NaN and ±inf too
        t[:, 2:][inner] = cross[inner]
        # rows first: a minimum over the outer axis is one pass of elementwise minima, several times
        # faster than over a short inner one (the same exact minimum)
        values = np.min(alpha.T[:, :, None] + t[None] * beta.T[:, :, None], axis=0)
    best = np.argmax(values, axis=1)
    rows = np.arange(len(faces))
    t_best = t[rows, best]
    return faces[:, 0] + t_best[:, None] * along, values[rows, best]


def exit_face(vertices: np.ndarray, z: np.ndarray, x_j: np.ndarray) -> np.ndarray:
    """The two ends of a funnel cell's exit face ``E_c = P_c ∩ {z·(x − x_j) = 0}``, shape (2, 2).

    Parameters
    ----------
    vertices : ndarray, shape (p, 2)
        The cell's CCW vertices (map units); the exit face is one of its edges.
    z, x_j : ndarray, shape (2,)
        Unit exit direction into the cell and the exit point (map units).

    Returns
    -------
    ndarray, shape (2, 2)
        The two vertices nearest the exit line, in polygon order.
    """
    V = np.asarray(vertices, float).reshape(-1, 2)
    gap = np.abs((V - x_j) @ z)
    ends = np.sort(np.argsort(gap, kind="stable")[:2])
    return V[ends]


def cell_tolerance(M: np.ndarray, normals: np.ndarray, sigma_h: np.ndarray, z: np.ndarray | None,
                   sigma_v: float | None) -> float:  # fmt: skip
    """``δ_c = min(min_k σ_h,k / ‖Mᵀn_k‖, σ_v / ‖Mᵀz‖)`` of ALGORITHMS §11.4 (map units).

    A robot acting on ``x̂`` with ``‖x̂ − x‖ ≤ δ`` applies ``u(x) − M(x̂ − x)``, which changes
    ``n_k·u`` by at most ``‖Mᵀn_k‖δ``; the margins absorb that while ``δ ≤ δ_c``.

    Parameters
    ----------
    M : ndarray, shape (2, 2)
        The field is ``a − M x``.
    normals : ndarray, shape (h, 2)
        Unit normals of the barrier rows (either sign: only norms enter).
    sigma_h : ndarray, shape (h,)
        Margin of (L1) of each row (``−S_h,k``), map units / s.
    z : ndarray, shape (2,) or None
        Exit direction; ``None`` for the goal cell (no (L2)).
    sigma_v : float or None
        Margin of (L2) (``−S_V``), map units / s; ``None`` with ``z``.

    Returns
    -------
    float
        ``0`` when a margin is not positive; ``inf`` when ``M = 0`` and every margin is positive.
    """
    rows = np.asarray(normals, float).reshape(-1, 2)
    sigma = np.asarray(sigma_h, float)
    if z is not None:  # (L2) is one more row: direction z, margin σ_v
        rows = np.vstack([rows, np.asarray(z, float).reshape(1, 2)])
        sigma = np.append(sigma, float(sigma_v))
    if not len(sigma) or not np.all(sigma > 0):
        return 0.0
    gain = rows @ M  # ‖Mᵀn‖ of each row
    gain = np.sqrt(gain[:, 0] * gain[:, 0] + gain[:, 1] * gain[:, 1])
    with np.errstate(divide="ignore"):
        return float(np.min(np.where(gain > 0, sigma / gain, math.inf)))


def usable_tolerances(tolerance: np.ndarray, exit_inset: np.ndarray) -> np.ndarray:
    """``τ_c = min(δ_c, δ_e,c / 2)`` of every cell (ALGORITHMS §12.3), shape (C,), map units.

    Parameters
    ----------
    tolerance : ndarray, shape (C,)
        ``δ_c`` of each cell (map units; ``+inf`` for a constant field, NaN without a certificate).
    exit_inset : ndarray, shape (C,)
        ``δ_e,c`` of each cell (map units); NaN for the goal cell, which has no exit: there
        ``τ_c = δ_c``.

    Returns
    -------
    ndarray, shape (C,)
        NaN where ``δ_c`` is NaN.
    """
    tolerance, half = np.asarray(tolerance, float), 0.5 * np.asarray(exit_inset, float)
    return np.where(np.isnan(half), tolerance, np.minimum(tolerance, half))


def plan_tolerance_of(usable: np.ndarray) -> float:
    """``min_c τ_c`` over the cells with a tolerance (ALGORITHMS §12.3), map units; NaN when none has one.

    Parameters
    ----------
    usable : ndarray, shape (C,)
        ``τ_c`` of each cell (:func:`usable_tolerances`; NaN entries are ignored).

    Returns
    -------
    float
    """
    values = np.asarray(usable, float)
    values = values[~np.isnan(values)]
    return float(values.min()) if len(values) else math.nan
