"""Necks (ALGORITHMS §11.5 step 2, §12.4): rows that narrow a cell's exit face into its eroded parent, and the
exit inset of each cell that maximises its usable tolerance."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bearnav_cli.funnel.region import Region, exit_row_index
from bearnav_cli.funnel.tolerance import exit_face, exit_sink, exit_sinks
from bearnav_cli.geometry import clip, polygon_rows

__all__ = [
    "best_neck",
    "depth",
    "exit_interval",
    "INSET_LIMIT",
    "INSET_SAMPLES",
    "NECK_ANGLE",
    "neck_choice",
    "neck_rows",
    "NeckChoice",
    "necked",
]


#: ψ of the neck rows: the angle their lines make with the exit direction ``z`` (radians).
NECK_ANGLE = math.radians(45.0)


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


def neck_choice(
    region: Region, x_i: np.ndarray, x_j: np.ndarray, parent: Region, inset: float, tol: float
) -> NeckChoice:
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


def best_neck(
    region: Region, x_i: np.ndarray, x_j: np.ndarray, parent: Region, tol: float, samples: int = INSET_SAMPLES
) -> NeckChoice:
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
