"""Bounded-error estimation: convex sets that always hold the robot (ALGORITHMS §12.1, §12.2, Lemma 5).

Numpy only. A batch of ``R`` convex polygons is a padded vertex array ``vertices`` (R, W, 2),
counter-clockwise, with ``count`` (R,) vertices each (rows past ``count`` are padding and never
read); ``count == 0`` is the empty set. Every operation takes and returns that pair, for all the
robots at once:

- :func:`box` — the bounds ``B_r`` every set starts from;
- :func:`cone_rows` — the bearing set ``W(l, φ̃)``: two half-planes through the landmark;
- :func:`clip` — intersection with one half-plane per polygon (Sutherland–Hodgman);
- :func:`grow` — every row moved outward by a radius, corners bevelled where sharp: a polygon that
  contains the Minkowski sum with the disc (the odometry bound of the prediction);
- :func:`intersect_cones` — clip by the cones of every visible bearing;
- :func:`centre` — the estimate ``x̂`` (a point of the set) and its exact error radius
  ``e = max_v ‖v − x̂‖``;
- :func:`diameter` — the largest distance between two points of a set (the static bound ``ε(x, S)``
  of §12.2 built on these operations is :mod:`~bearnav_cli.runtime.look_bound`'s);
- :func:`contains` — whether points lie in their sets (the simulator's containment count).

Every clip keeps a slack of ``tol`` (``1e-9·D``) on the outside, so round-off never empties a set
that holds the truth: the sets are outer approximations, as Lemma 5 needs.
"""

from __future__ import annotations

import math

import numpy as np

from bearnav_cli.runtime.sight import crossing_parity

__all__ = [
    "CENTRE_STEPS",
    "MAX_VERTICES",
    "RADIUS_PER_WIDTH",
    "box",
    "clip_pairs",
    "centre",
    "common_rotation",
    "clip",
    "cone_rows",
    "contains",
    "diameter",
    "grow",
    "inside_rows",
    "intersect_cones",
    "translate",
    "valid_vertices",
]

#: :func:`common_rotation` cuts the interval of the heading error into this many parts per level, and narrows it
#: this many levels: the interval it keeps is at most ``2/ROTATION_PARTS**ROTATION_LEVELS`` of the compass's wider
#: than the rotations that fit the bearings.
ROTATION_PARTS = 4
ROTATION_LEVELS = 3
#: Widest vertex array kept: a set with more vertices is merged down (outward) to this many. A set
#: rarely has more than 12 (the kitchen's 28 tags all around: at most 10 in 1,000 runs).
MAX_VERTICES = 24
#: ``x̂`` is refined by this many Bădoiu–Clarkson steps toward the centre of the smallest circle
#: around the vertices (the error radius is exact for whatever point results).
CENTRE_STEPS = 12
#: ``e ≤ RADIUS_PER_WIDTH · diam X`` for the ``x̂`` :func:`centre` returns: Jung's ``R ≤ diam/√3`` and
#: Bădoiu–Clarkson's ``e ≤ (1 + 1/√(CENTRE_STEPS + 1)) R`` (:func:`~bearnav_cli.runtime.look_bound.one_look_bound`).
RADIUS_PER_WIDTH = min(1.0, (1.0 + 1.0 / math.sqrt(CENTRE_STEPS + 1)) / math.sqrt(3.0))


def box(bounds: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray]:
    """``r`` copies of the rectangle ``bounds = [xmin, ymin, xmax, ymax]`` (map units), counter-clockwise."""
    x0, y0, x1, y1 = (float(v) for v in np.asarray(bounds, float).reshape(4))
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    return np.broadcast_to(corners, (r, 4, 2)).copy(), np.full(r, 4, np.int64)


def translate(vertices: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The sets moved by ``d`` (R, 2) map units (padding moves too; it is never read)."""
    return vertices + np.asarray(d, float)[:, None, :]


def valid_vertices(vertices: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Which rows of the padded vertex array (R, W, 2) are vertices: shape (R, W) bool, the first ``count`` of each."""
    return np.arange(vertices.shape[1])[None, :] < count[:, None]


def _next_index(vertices: np.ndarray, count: np.ndarray) -> np.ndarray:
    j = np.arange(vertices.shape[1])[None, :]
    return np.where(j + 1 < count[:, None], j + 1, 0)


def _rows_at(values: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``values[r, index[r, j]]`` for every row ``r`` (``values`` (R, W, ...), ``index`` (R, J)): a gather along
    axis 1 by plain fancy indexing (``np.take_along_axis`` builds its index in Python on every call)."""
    return values[np.arange(len(values))[:, None], index]


def _compact(candidates: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The kept candidates of every row moved to the front, in order, and their numbers."""
    count = keep.sum(axis=1).astype(np.int64)
    width = max(int(count.max(initial=0)), 1)
    return _rows_at(candidates, np.argsort(~keep, axis=1, kind="stable")[:, :width]), count


def clip(
    vertices: np.ndarray, count: np.ndarray, a: np.ndarray, b: np.ndarray, tol: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Each polygon intersected with its half-plane ``{y : a·y ≤ b + tol}`` (Sutherland–Hodgman).

    Parameters
    ----------
    vertices : ndarray, shape (R, W, 2)
        Counter-clockwise convex polygons, padded (map units).
    count : ndarray of int, shape (R,)
        Their vertex counts.
    a : ndarray, shape (R, 2)
        Row normals (any length; ``0`` with ``b ≥ 0`` keeps the polygon).
    b : ndarray, shape (R,)
        Row offsets (map units when ``a`` is a unit vector).
    tol : float
        Slack on the outside (map units, in the units of ``a·y``).

    Returns
    -------
    vertices : ndarray, shape (R, W', 2)
    count : ndarray of int64, shape (R,)
        At most one more vertex than before; 0 where the polygon lies wholly outside.
    """
    valid = valid_vertices(vertices, count)
    s = vertices[..., 0] * a[:, 0, None] + vertices[..., 1] * a[:, 1, None] - (np.asarray(b, float) + tol)[:, None]
    s = np.where(valid, s, 0.0)
    cut = np.flatnonzero(np.any(s > 0.0, axis=1))
    if len(cut) < len(vertices):  # most rows lie inside their half-plane: only the others are clipped
        if not len(cut):
            return vertices, count
        sub_v, sub_n = _clip_rows(vertices[cut], count[cut], s[cut], valid[cut])
        width = max(vertices.shape[1], sub_v.shape[1])
        out, out_count = fit(vertices, width).copy(), count.copy()
        out[cut], out_count[cut] = fit(sub_v, width), sub_n
        return out, out_count
    return _clip_rows(vertices, count, s, valid)


def _clip_rows(
    vertices: np.ndarray, count: np.ndarray, s: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`clip` of rows whose signed row values ``s`` (R, W) are known (positive: outside)."""
    nxt = _next_index(vertices, count)
    rows = np.arange(len(vertices))[:, None]
    following = vertices[rows, nxt]
    s_next = s[rows, nxt]
    inside = s <= 0.0
    crossing = valid & (inside != (s_next <= 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(crossing, s / (s - s_next), 0.0)
    point = vertices + t[..., None] * (following - vertices)
    candidates = np.stack([vertices, point], axis=2).reshape(len(vertices), -1, 2)
    keep = np.stack([valid & inside, crossing], axis=2).reshape(len(vertices), -1)
    return _compact(candidates, keep)


def _dedupe(vertices: np.ndarray, count: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Drop every vertex within ``tol`` of the next one (a move of at most ``tol``)."""
    if not len(vertices):
        return vertices, count
    valid = valid_vertices(vertices, count)
    nxt = _next_index(vertices, count)
    gap = vertices - _rows_at(vertices, nxt)
    close = np.hypot(gap[..., 0], gap[..., 1]) <= tol
    # the last of a run of equal vertices stays (a lone vertex is never dropped)
    keep = valid & ~(close & (count[:, None] > 1))
    keep[(keep.sum(axis=1) == 0) & (count > 0), 0] = True
    return _compact(vertices, keep)


def _normals(vertices: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Outward unit normals of the edges ``v_j → v_{j+1}`` of counter-clockwise polygons, (R, W, 2)."""
    edge = _rows_at(vertices, _next_index(vertices, count)) - vertices
    length = np.hypot(edge[..., 0], edge[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        n = np.stack([edge[..., 1], -edge[..., 0]], axis=-1) / length[..., None]
    return np.where(np.isfinite(n), n, 0.0)


def _area(vertices: np.ndarray, count: np.ndarray) -> np.ndarray:
    nxt = _rows_at(vertices, _next_index(vertices, count))
    cross = vertices[..., 0] * nxt[..., 1] - vertices[..., 1] * nxt[..., 0]
    return 0.5 * np.sum(np.where(valid_vertices(vertices, count), cross, 0.0), axis=1)


def grow(
    vertices: np.ndarray, count: np.ndarray, radius: np.ndarray, tol: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Each polygon with every row moved outward by its ``radius``: it contains ``X ⊕ B(radius)``.

    At a corner whose edge normals turn by ``φ`` the offset rows meet ``r/cos(φ/2)`` from the
    vertex; where ``φ > π/2`` (a sharp corner: thin cones meet at them) a bevel row tangent to the
    disc around the vertex cuts the corner off, so no offset vertex lies farther than ``r/cos(φ/4) ≤ 1.31r`` from
    its vertex. Polygons with fewer than three vertices, or no area, become
    their bounding box grown by ``radius``.

    Parameters
    ----------
    vertices : ndarray, shape (R, W, 2)
        Counter-clockwise convex polygons, padded (map units).
    count : ndarray of int, shape (R,)
        Their vertex counts.
    radius : ndarray, shape (R,)
        ``r ≥ 0`` (map units); 0 leaves the polygon as it is.
    tol : float
        Vertices closer than this are merged first (map units).
    """
    radius = np.asarray(radius, float).reshape(len(vertices))
    vertices, count = _dedupe(vertices, count, tol)
    valid = valid_vertices(vertices, count)
    flat = (count < 3) | (np.abs(_area(vertices, count)) <= max(tol, 1e-300) ** 2)
    n = _normals(vertices, count)
    j = np.arange(vertices.shape[1])[None, :]
    before = np.where(j == 0, np.maximum(count[:, None] - 1, 0), j - 1)
    previous = _rows_at(n, before)  # the normal of the edge into each vertex
    cos_turn = np.clip(np.einsum("rwk,rwk->rw", previous, n), -1.0, 1.0)
    sharp = cos_turn < 0.0
    r = radius[:, None, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        mitre = vertices + r * (previous + n) / (1.0 + cos_turn)[..., None]
        # the bevel: the row of normal m = unit(n_prev + n) at distance r; it meets the two offset rows
        # at r·tan(φ/4) from the offset points along the edges (φ the turn of the normals)
        quarter = np.tan(0.25 * np.arccos(cos_turn))[..., None]
        along_prev = np.stack([-previous[..., 1], previous[..., 0]], axis=-1)  # edge direction of n_prev
        along = np.stack([-n[..., 1], n[..., 0]], axis=-1)
        first = vertices + r * previous + r * quarter * along_prev
        second = vertices + r * n - r * quarter * along
    corner = np.where(sharp[..., None], first, mitre)
    candidates = np.stack([corner, second], axis=2).reshape(len(vertices), -1, 2)
    keep = np.stack([valid, valid & sharp], axis=2).reshape(len(vertices), -1)
    out, out_count = _compact(candidates, keep)
    if flat.any():
        idx = np.flatnonzero(flat & (count > 0))
        if len(idx):
            v = np.where(valid[idx, :, None], vertices[idx], np.nan)
            lo, hi = np.nanmin(v, axis=1) - radius[idx, None], np.nanmax(v, axis=1) + radius[idx, None]
            rect = np.stack(
                [lo, np.column_stack([hi[:, 0], lo[:, 1]]), hi, np.column_stack([lo[:, 0], hi[:, 1]])], axis=1
            )
            if out.shape[1] < 4:
                out = np.concatenate([out, np.repeat(out[:, :1], 4 - out.shape[1], axis=1)], axis=1)
            out[idx, :4], out_count[idx] = rect, 4
    still = radius <= 0.0  # no growth: the deduplicated polygon as it was
    if still.any():
        width = max(out.shape[1], vertices.shape[1])
        out = fit(out, width)
        out[still] = fit(vertices, width)[still]
        out_count[still] = count[still]
    return _reduce(out, out_count)


def fit(vertices: np.ndarray, width: int) -> np.ndarray:
    """The padded vertex arrays made ``width`` wide (R, width, 2): cut, or padded with each row's first vertex.

    The padding is never read (only the first ``count`` vertices are); the input itself comes back
    when it has that width already.
    """
    if vertices.shape[1] > width:
        return vertices[:, :width]
    if vertices.shape[1] == width:
        return vertices
    return np.concatenate([vertices, np.repeat(vertices[:, :1], width - vertices.shape[1], axis=1)], axis=1)


def _reduce(vertices: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sets of more than :data:`MAX_VERTICES` vertices merged down, outward: the shortest edge whose two
    neighbouring rows meet beyond it is replaced by that meeting point, until few enough remain."""
    over = np.flatnonzero(count > MAX_VERTICES)
    for i in over:  # rare: one polygon at a time
        poly = list(vertices[i, : count[i]])
        while len(poly) > MAX_VERTICES:
            p = np.array(poly)
            k = len(p)
            edge = np.roll(p, -1, axis=0) - p
            length = np.hypot(edge[:, 0], edge[:, 1])
            best = None
            for j in np.argsort(length):
                a0, a1 = p[(j - 1) % k], p[j]  # the row before edge j
                b0, b1 = p[(j + 1) % k], p[(j + 2) % k]  # the row after it
                da, db = a1 - a0, b1 - b0
                denom = da[0] * db[1] - da[1] * db[0]
                if denom <= 1e-15 * (np.hypot(*da) * np.hypot(*db)):  # the rows turn by π or more: no apex
                    continue
                t = ((b0[0] - a0[0]) * db[1] - (b0[1] - a0[1]) * db[0]) / denom
                if t < 1.0:
                    continue
                best = (j, a0 + t * da)
                break
            if best is None:
                break
            j, apex = best
            poly[j] = apex
            del poly[(j + 1) % k]
        vertices[i, : len(poly)], count[i] = poly, len(poly)
    width = max(int(count.max(initial=0)), 1)
    return vertices[:, :width], count


def cone_rows(landmarks: np.ndarray, angle: np.ndarray, eta: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two half-planes ``a·y ≤ b`` of each bearing set ``W(l, φ̃)`` (ALGORITHMS §12.2).

    ``W(l, φ̃) = {y : |wrap(angle(l − y) − φ̃)| ≤ η}`` is the cone with apex ``l`` around
    ``−(cos φ̃, sin φ̃)`` of half-angle ``η < π/2``: the intersection of
    ``(−sin(φ̃−η), cos(φ̃−η))·(y − l) ≤ 0`` and ``(sin(φ̃+η), −cos(φ̃+η))·(y − l) ≤ 0``.

    Parameters
    ----------
    landmarks : ndarray, shape (..., 2)
        Apexes ``l`` (map units).
    angle : ndarray, shape (...)
        Measured world-frame bearing angles ``φ̃`` from the robot to ``l`` (rad).
    eta : float or ndarray, shape (...)
        Half-angle ``η`` (rad, in [0, π/2)), one or one per bearing.

    Returns
    -------
    a : ndarray, shape (..., 2, 2)
        Unit normals of the two rows.
    b : ndarray, shape (..., 2)
        Their offsets ``a·l`` (map units).
    """
    lo, hi = angle - eta, angle + eta
    a = np.stack([np.stack([-np.sin(lo), np.cos(lo)], axis=-1), np.stack([np.sin(hi), -np.cos(hi)], axis=-1)], axis=-2)
    b = np.einsum("...qk,...k->...q", a, np.asarray(landmarks, float))
    return a, b


def intersect_cones(
    vertices: np.ndarray,
    count: np.ndarray,
    landmarks: np.ndarray,
    angle: np.ndarray,
    visible: np.ndarray,
    eta: float | np.ndarray,
    tol: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Every set clipped by the bearing cones of the landmarks its robot sees (§12.2's update).

    The robots are clipped together, one visible bearing of each per round (a robot with fewer
    bearings sits out the later rounds).

    Parameters
    ----------
    vertices : ndarray, shape (R, W, 2)
        Counter-clockwise convex polygons, padded (map units).
    count : ndarray of int, shape (R,)
        Their vertex counts.
    landmarks : ndarray, shape (L, 2)
        Landmark positions (map units).
    angle : ndarray, shape (R, L)
        Measured world-frame bearing angles (rad); only the visible ones are read.
    visible : ndarray of bool, shape (R, L)
        Which landmarks each robot sees.
    eta : float or ndarray, shape (R,)
        The bearing error bound (rad), one or one per robot.
    tol : float
        Outside slack of every clip (map units).
    """
    visible = np.asarray(visible, bool)
    if not visible.any():
        return vertices, count
    rob, lm = np.nonzero(visible)  # the (robot, landmark) pairs, robot by robot
    eta_pairs = np.broadcast_to(np.asarray(eta, float), (len(visible),))[rob]
    a, b = cone_rows(np.asarray(landmarks, float)[lm], np.asarray(angle, float)[rob, lm], eta_pairs)  # (P, 2, 2)
    return clip_pairs(vertices, count, rob, a, b, tol)


def common_rotation(
    vertices: np.ndarray,
    count: np.ndarray,
    landmarks: np.ndarray,
    angle: np.ndarray,
    visible: np.ndarray,
    eta: np.ndarray,
    psi: np.ndarray,
    tol: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The heading error bounded by the bearings themselves (ALGORITHMS §12.1): an interval ``[m − ψ', m + ψ']``
    that holds the compass's error ``r``, with ``ψ' ≤ ψ``.

    A world-frame bearing is the compass heading plus the camera's bearing, so every bearing of one view errs
    by the same ``r`` (``|r| ≤ ψ``) plus its own camera error (``≤ η``): the truth lies in
    ``X ∩ ∩_k W(l_k, φ̃_k − r)`` with cones of half-angle ``η``, and a rotation ``r`` for which that set is
    empty is not the error. The test is exact for a whole interval ``[c − h, c + h]`` of rotations at once:
    each cone of half-angle ``η`` around ``φ̃_k − r`` lies in the cone of half-angle ``η + h`` around
    ``φ̃_k − c``, so where the wider cones miss the set, every rotation of the interval does. The interval
    ``[−ψ, ψ]`` is cut into :data:`ROTATION_PARTS` parts, the parts so ruled out are dropped, and what is left
    is cut again, :data:`ROTATION_LEVELS` times. The set clipped by the cones of half-angle ``η + ψ'`` around
    ``φ̃_k − m`` then holds the truth (each cone around ``φ̃_k − r`` lies in it), and is never wider than
    the cones of ``η + ψ`` around ``φ̃_k`` the compass alone gives.

    Parameters
    ----------
    vertices, count : ndarray, shapes (R, W, 2), (R,)
        The sets before this view's bearings (the prediction ``X_t⁻``, map units).
    landmarks : ndarray, shape (L, 2)
        Landmark positions (map units).
    angle : ndarray, shape (R, L)
        Measured world-frame bearing angles ``φ̃`` (rad): compass heading plus camera bearing.
    visible : ndarray of bool, shape (R, L)
        Which landmarks each robot sees.
    eta, psi : ndarray, shape (R,)
        The camera's bound ``η`` and the compass's ``ψ`` (rad; ``η + ψ < π/2``).
    tol : float
        Outside slack of every clip (map units).

    Returns
    -------
    middle, half : ndarray, shape (R,)
        ``m`` and ``ψ'`` (rad): ``m = 0``, ``ψ' = ψ`` where the bearings rule nothing out (fewer than two in
        view, or every rotation ruled out: then a bound was broken, and the update says so).
    """
    psi = np.asarray(psi, float)
    lo, hi = -psi.copy(), psi.copy()
    todo = np.flatnonzero((np.count_nonzero(visible, axis=1) >= 2) & (psi > 0.0) & (count > 0))
    parts = np.arange(ROTATION_PARTS)
    for _ in range(ROTATION_LEVELS):
        if not len(todo):
            break
        h = (hi[todo] - lo[todo]) / (2 * ROTATION_PARTS)
        centres = lo[todo][:, None] + h[:, None] * (2 * parts + 1)  # (T, P)
        rep = np.repeat(todo, ROTATION_PARTS)
        _, n = intersect_cones(
            vertices[rep],
            count[rep],
            landmarks,
            angle[rep] - centres.reshape(-1, 1),
            visible[rep],
            eta[rep] + np.repeat(h, ROTATION_PARTS),
            tol,
        )
        fits = (n > 0).reshape(-1, ROTATION_PARTS)
        some = fits.any(axis=1)
        rows = np.arange(len(todo))
        first = np.argmax(fits, axis=1)
        last = ROTATION_PARTS - 1 - np.argmax(fits[:, ::-1], axis=1)
        # nothing fits: a bound was broken, or round-off at a narrow level; the interval before stays (it held
        # every rotation that fits)
        lo[todo] = np.where(some, centres[rows, first] - h, lo[todo])
        hi[todo] = np.where(some, centres[rows, last] + h, hi[todo])
        todo = todo[some]
    return 0.5 * (lo + hi), 0.5 * (hi - lo)


def clip_pairs(
    vertices: np.ndarray, count: np.ndarray, rob: np.ndarray, a: np.ndarray, b: np.ndarray, tol: float
) -> tuple[np.ndarray, np.ndarray]:
    """Each set clipped by the rows of its pairs: pair ``p`` clips set ``rob[p]`` by ``a[p, q]·y ≤ b[p, q]``.

    The sets are clipped together, one pair of each per round (a set with fewer pairs sits out the
    later rounds). The caller's arrays stay as they were.

    Parameters
    ----------
    vertices, count : ndarray, shapes (R, W, 2), (R,)
        The padded sets (map units).
    rob : ndarray of int, shape (P,)
        The set each pair clips, sorted.
    a, b : ndarray, shapes (P, Q, 2), (P, Q)
        Each pair's ``Q`` rows ``a·y ≤ b`` (map units).
    tol : float
        The slack every clip keeps outside (map units).

    Returns
    -------
    vertices, count : ndarray, shapes (R, W', 2), (R,)
    """
    vertices, count = vertices[:, : max(int(count.max(initial=0)), 1)].copy(), count.copy()
    # a pair whose rows hold every vertex now hold the set after every other clip too (clips only
    # shrink it): only the pairs that cut it are applied
    s = np.einsum("pqk,pwk->pqw", a, vertices[rob]) - (b + tol)[..., None]
    cuts = np.any((s > 0.0) & valid_vertices(vertices, count)[rob][:, None, :], axis=(1, 2))
    rob, a, b = rob[cuts], a[cuts], b[cuts]
    if not len(rob):
        return _reduce(*_dedupe(vertices, count, tol))
    first = np.searchsorted(rob, rob)  # pairs are sorted by robot: a pair's round is its place among its robot's
    rounds = np.arange(len(rob)) - first
    for k in range(int(rounds.max()) + 1):
        sel = np.flatnonzero(rounds == k)
        who = rob[sel]
        sub_v, sub_n = vertices[who], count[who]
        for q in range(a.shape[1]):
            sub_v, sub_n = clip(sub_v, sub_n, a[sel, q], b[sel, q], tol)
        width = max(vertices.shape[1], sub_v.shape[1])
        vertices = fit(vertices, width)
        vertices[who] = fit(sub_v, width)
        count[who] = sub_n
    return _reduce(*_dedupe(vertices, count, tol))


def centre(vertices: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The estimate ``x̂`` in each set and its exact error radius ``e = max_v ‖v − x̂‖`` (§12.2).

    ``x̂`` approaches the centre of the smallest circle around the vertices (Bădoiu–Clarkson steps
    from their mean; the better of that and the midpoint of the farthest pair is kept). Every step
    moves toward a vertex, so ``x̂`` stays in the convex set; ``e`` is exact for the ``x̂`` returned,
    which is all Lemma 5's ``‖x − x̂‖ ≤ e`` needs.

    Returns
    -------
    x_hat : ndarray, shape (R, 2)
        Map units; NaN for empty sets.
    error : ndarray, shape (R,)
        Map units; ``inf`` for empty sets.
    """
    vertices = vertices[:, : max(int(count.max(initial=0)), 1)]  # the padding past the widest set
    r = len(vertices)
    rows = np.arange(r)
    valid = valid_vertices(vertices, count)
    empty = count <= 0
    weight = valid / np.maximum(count, 1)[:, None]
    c = np.einsum("rw,rwk->rk", weight, vertices)
    vx, vy = vertices[..., 0], vertices[..., 1]

    def farthest(point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dist2 = np.where(valid, (vx - point[:, 0, None]) ** 2 + (vy - point[:, 1, None]) ** 2, -1.0)
        j = np.argmax(dist2, axis=1)
        return np.sqrt(np.maximum(dist2[rows, j], 0.0)), j  # empty sets: e is set to inf below

    for k in range(CENTRE_STEPS):
        _, j = farthest(c)
        c = c + (vertices[rows, j] - c) / (k + 2.0)
    e, j = farthest(c)
    # a far pair's midpoint (the farthest vertex from x̂, then the farthest from it): the optimum when
    # the smallest circle rests on two vertices
    _, i = farthest(vertices[rows, j])
    mid = 0.5 * (vertices[rows, i] + vertices[rows, j])
    e_mid, _ = farthest(mid)
    better = e_mid < e
    c[better], e[better] = mid[better], e_mid[better]
    c[empty], e[empty] = np.nan, np.inf
    return c, e


def diameter(vertices: np.ndarray, count: np.ndarray) -> np.ndarray:
    """The largest distance between two vertices of each set (R,) map units; ``inf`` for empty sets."""
    valid = valid_vertices(vertices, count)
    d = vertices[:, :, None] - vertices[:, None]
    dist2 = np.where(valid[:, :, None] & valid[:, None, :], np.einsum("rwvk,rwvk->rwv", d, d), 0.0)
    out = np.sqrt(np.max(dist2.reshape(len(vertices), -1), axis=1, initial=0.0))
    return np.where(count > 0, out, np.inf)


def inside_rows(
    vertices: np.ndarray, count: np.ndarray, A: np.ndarray, b: np.ndarray, margin: np.ndarray | float = 0.0
) -> np.ndarray:
    """Whether each set lies in its polygon ``{y : A y ≤ b}`` with ``margin`` to spare, shape (R,).

    A convex set lies in a convex polygon exactly when its vertices do, so the test is exact: every
    vertex ``v`` of set ``r`` satisfies ``A[r, k]·v ≤ b[r, k] − margin[r]·‖A[r, k]‖`` for every row ``k``
    (padding rows ``0·y ≤ 0`` always hold). Empty sets are in nothing.

    Parameters
    ----------
    vertices, count : ndarray, shapes (R, W, 2), (R,)
        The padded sets (map units).
    A, b : ndarray, shapes (R, P, 2), (R, P)
        Each set's polygon as half-plane rows (map units).
    margin : float or ndarray, shape (R,)
        Room every vertex must keep inside each row (map units).
    """
    norm = np.hypot(A[..., 0], A[..., 1])
    room = b - np.broadcast_to(np.asarray(margin, float), (len(A),))[:, None] * norm
    lhs = np.einsum("rpk,rwk->rwp", A, vertices) - room[:, None, :]
    ok = np.all(lhs <= 0.0, axis=2) | ~valid_vertices(vertices, count)
    return np.all(ok, axis=1) & (count > 0)


def contains(vertices: np.ndarray, count: np.ndarray, x: np.ndarray, tol: float = 0.0) -> np.ndarray:
    """Whether each point lies in its set, or within ``tol`` of its boundary, shape (R,).

    The even-odd crossing test, not the half-planes of the edges: repeated growth and clipping leave
    chains of very short edges whose directions round-off may turn a little backward, and one such
    edge's half-plane would exclude points of the set.

    Parameters
    ----------
    vertices : ndarray, shape (R, W, 2)
        Convex polygons, padded (map units).
    count : ndarray of int, shape (R,)
        Their vertex counts (1 or 2: a point or a segment, within ``tol``; 0: contains nothing).
    x : ndarray, shape (R, 2)
        One point per set (map units).
    tol : float
        Slack (map units).
    """
    p = np.asarray(x, float).reshape(-1, 2)
    valid = valid_vertices(vertices, count)
    a = vertices
    b = vertices[np.arange(len(vertices))[:, None], _next_index(vertices, count)]
    inside = crossing_parity(a, b, p, valid)
    edge = b - a
    length2 = np.einsum("rwk,rwk->rw", edge, edge)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip(np.einsum("rwk,rwk->rw", p[:, None, :] - a, edge) / length2, 0.0, 1.0)
    t = np.where(length2 > 0, t, 0.0)
    gap = p[:, None, :] - (a + t[..., None] * edge)
    near = np.any(valid & (np.hypot(gap[..., 0], gap[..., 1]) <= tol), axis=1)
    return (inside | near) & (count > 0)
