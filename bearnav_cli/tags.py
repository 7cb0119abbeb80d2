"""Where to glue more tags: a greedy set cover of the perception rule and the bound it certifies (issue 11, part 1).

:func:`propose_tags` places new tags on obstacle and wall boundaries so that the perception rule of
:mod:`bearnav_cli.perception` (the camera looks along the field; two or more tags in view, in range
and in line of sight, spread enough for a usable ``lsq`` fix, optionally with predicted error at
most a target) holds at every grid point of the certified domain ``D`` where any placement can make
it hold (docs/algorithms.md, "Perception coverage and tag placement"):

1. **Candidates** (:func:`candidates`): points on every boundary edge of the raw obstacles and on
   the four walls of the bounds ``B``, ``tag_width`` apart along each edge (one at the middle of an
   edge shorter than that, e.g. the facets of a disc), kept where the free side is real free space
   (the point nudged off the edge along its normal by :data:`NUDGE`·D is in ``B`` and outside every
   raw obstacle) and some evaluation point sees it, at least ``tag_width`` from every existing tag
   and from each other. Positions lie exactly on the boundary, which the map stage accepts.
2. **Greedy** (the baseline): repeatedly add the candidate that makes the rule hold at the most
   additional points of ``D`` (ties, including the first tag of a region that sees none, go to the
   largest progress ``ψ``: a quarter per tag up to two, a quarter for the spread and error reached,
   all of it once the rule holds; then the lowest index), until it holds at every point that can
   be covered or ``max_tags`` are placed. Every (point, candidate) pair is evaluated at once: each
   point keeps its running sums ``Σ_k P_k`` and ``Σ_k P_k/d_k²`` (``P_k = I − β_kβ_kᵀ``), so adding
   a candidate is a closed-form 2×2 ``λ_min`` for every pair. A pruning pass then drops, the last
   chosen first, every tag whose removal keeps the rule wherever it holds (``Params.prune``).
3. **Lower bound**: the LP relaxation of the necessary condition "every coverable point of ``D``
   sees at least two tags", ``min Σ x_c`` subject to ``Σ_{c seen from p} x_c ≥ 2 − (existing tags
   seen from p)``, ``0 ≤ x ≤ 1`` (:class:`bearnav_cli.lp.LpSolver`); no placement among the
   candidates that reaches the target uses fewer than ``ceil(LP optimum)`` new tags.

:func:`map_spec_with_tags` appends the proposal to a map description (DESIGN §4) and
:func:`map_text_with_tags` to the YAML text the user wrote (comments and circles kept); writing it
is the caller's business. ``plot.plot_tags`` draws a proposal.
"""

from __future__ import annotations

import copy
import heapq
import json
import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely

from bearnav_cli import perception
from bearnav_cli.datatypes import percent, plural
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace, box_polygon
from bearnav_cli.lp import INF, LpSolver, LpStatus
from bearnav_cli.perception import EvaluationGrid, PerceptionCoverage
from bearnav_cli.runtime import bearing, bounded, estimate, step
from bearnav_cli.runtime.invariants import is_number

__all__ = [
    "LIVE_RESCORE",
    "NUDGE",
    "TAG_WIDTH_FRACTION",
    "TARGETS",
    "Candidates",
    "Params",
    "TagProposal",
    "candidates",
    "map_spec_with_tags",
    "map_text_with_tags",
    "new_tag_ids",
    "propose",
    "propose_live_tags",
    "propose_tags",
    "tagged_name",
]

#: Default tag width as a fraction of the bounds' diagonal D: 0.19 m on the kitchen (D = 12.8 m), the
#: size of a printed AprilTag; in map units, so it scales with maps drawn in other units.
TAG_WIDTH_FRACTION = 0.015
#: A candidate's free side is tested this far off its edge (fraction of D).
NUDGE = 1e-6
#: The LP optimum is rounded up after removing this much (solver tolerance).
LP_SLACK = 1e-6
#: What the tags are for: a usable fix where the robot looks (``fix``), or every cell live (``live``).
TARGETS = ("fix", "live")
#: Candidates the live greedy re-scores together when the best one's score is stale.
LIVE_RESCORE = 32


@dataclass(frozen=True)
class Params:
    """Parameters of :func:`propose_tags` (deterministic: no seed).

    Attributes
    ----------
    fov_deg : float
        Camera field of view (degrees), in ``(0, 360]``.
    max_range : float
        Sensing range (map units), ``> 0``; ``inf`` for unlimited.
    noise_deg : float
        Bearing noise σ (degrees, ``≥ 0``): the predicted error ``3σ`` of a fix scales with it.
    error_target : float or None
        ``E`` (map units): the rule also needs predicted error ``≤ E``; ``None``: no error target.
    max_tags : int or None
        At most this many new tags (``≥ 0``); ``None``: as many as the target needs.
    tag_width : float or None
        Spacing of the candidates and least distance between tags (map units, ``> 0``); ``None``:
        ``TAG_WIDTH_FRACTION·D``.
    spacing : float or None
        Spacing of the evaluation grid (map units, ``> 0``); ``None``: ``D/100``.
    min_spread_deg : float
        ``θ_min`` of a usable fix (degrees, ALGORITHMS §6.2), the runtime's 2° by default.
    prune : bool
        After the greedy, drop every chosen tag (the last chosen first) whose removal keeps the rule
        wherever it holds; ``False`` gives the plain greedy.
    target : str
        ``fix``: the perception rule above (:func:`propose_tags`); ``live``: every cell live
        (ALGORITHMS §12.5, :func:`propose_live_tags`).
    bearing_error_deg, slip, resolution : float or None
        For ``live``: the bearing error bound ``η`` (degrees), the slip ``κ`` and the grid spacing
        (map units) of :func:`bearnav_cli.liveness.grid`; ``None``: its defaults (the map's robot).
    """

    fov_deg: float = 60.0
    max_range: float = math.inf
    noise_deg: float = 1.0
    error_target: float | None = None
    max_tags: int | None = None
    tag_width: float | None = None
    spacing: float | None = None
    min_spread_deg: float = 2.0
    prune: bool = True
    target: str = "fix"
    bearing_error_deg: float | None = None
    slip: float | None = None
    resolution: float | None = None

    def __post_init__(self) -> None:
        perception.check_params(self.fov_deg, self.noise_deg, self.max_range, self.error_target, self.min_spread_deg,
                                self.spacing)  # fmt: skip
        if self.target not in TARGETS:
            raise InvalidParamsError(f"must be one of {', '.join(TARGETS)}, got {self.target!r}", field="target")
        m = self.max_tags
        if m is not None and (isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 0):
            raise InvalidParamsError(f"must be an integer >= 0, got {m!r}", field="max_tags")
        w = self.tag_width
        if w is not None and (not is_number(w) or not (w > 0 and math.isfinite(w))):
            raise InvalidParamsError(f"must be positive, got {w!r}", field="tag_width")

    def width(self, diagonal: float) -> float:
        """The tag width in map units for a map of diagonal ``diagonal``."""
        return TAG_WIDTH_FRACTION * diagonal if self.tag_width is None else float(self.tag_width)


# --------------------------------------------------------------------------- candidates


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
    """Candidate tag positions on the raw obstacles' boundaries and the walls (step 1 of the module docstring).

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


# --------------------------------------------------------------------------- the closed-form rule


def _lam_min(a11: np.ndarray, a22: np.ndarray, a12: np.ndarray) -> np.ndarray:
    """Smallest eigenvalue of ``[[a11, a12], [a12, a22]]`` (the formula of ``bearing``'s ``lsq``)."""
    return 0.5 * (a11 + a22) - np.hypot(0.5 * (a11 - a22), a12)


@dataclass
class _Sums:
    """Running sums of one set of points: tag count, ``Σ P_k`` and ``Σ P_k/d_k²`` as (a11, a22, a12)."""

    n: np.ndarray
    s: np.ndarray  # (P, 3)
    w: np.ndarray  # (P, 3)


@dataclass(frozen=True)
class _Rule:
    """The perception rule in closed form on the running sums (equal to ``fix_quality`` up to rounding)."""

    spread: float  # 1 − cos θ_min
    sigma: float  # radians
    target: float | None  # map units

    def holds_and_progress(self, n: np.ndarray, s: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lam_s = _lam_min(s[..., 0], s[..., 1], s[..., 2])
        det = s[..., 0] * s[..., 1] - s[..., 2] * s[..., 2]
        q = np.minimum(1.0, np.maximum(lam_s, 0.0) / self.spread)
        ok = (n >= 2) & (lam_s >= self.spread) & (det > 0)
        if self.target is not None and self.sigma > 0:
            lam_w = _lam_min(w[..., 0], w[..., 1], w[..., 2])
            error = 3.0 * self.sigma / np.sqrt(np.maximum(lam_w, 1e-300))
            ok &= error <= self.target
            q = np.minimum(q, np.minimum(1.0, self.target / error))
        progress = np.where(ok, 1.0, 0.25 * np.minimum(n, 2) + 0.25 * (n >= 2) * np.minimum(q, 0.999))
        return ok, progress


def _projectors(points: np.ndarray, landmarks: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """``P = I − ββᵀ`` as (a11, a22, a12) and ``P/max(d², tol²)``, for every point × landmark, shapes (P, L, 3)."""
    unit, dist = bearing.directions(points, landmarks)
    bx, by = unit[..., 0], unit[..., 1]
    proj = np.stack([1.0 - bx * bx, 1.0 - by * by, -bx * by], axis=-1)
    return proj, proj / np.maximum(dist * dist, tol * tol)[..., None]


# --------------------------------------------------------------------------- the proposal


@dataclass(frozen=True, eq=False)
class TagProposal:
    """New tags for a plan's map and what they achieve; ``K`` new tags, ``C`` candidates.

    Attributes
    ----------
    ids : tuple of str, length K
        New tag ids, none equal to an existing one (``tagN`` continuing the map's numbering, or
        integers when every existing id is one).
    positions : ndarray, shape (K, 2)
        Where to glue them (map units), on a raw obstacle's boundary or a wall, in the order chosen.
    normals : ndarray, shape (K, 2)
        Unit normal of each tag's surface, toward the free side it faces.
    gains : ndarray of int64, shape (K,)
        Grid points of ``D`` where the rule comes to hold as each new tag is added in turn, in the
        order of ``ids`` (the rule in the greedy's closed form).
    before, after : PerceptionCoverage
        The rule with the map's tags, and with the new ones added (fractions of ``D`` and ``F``).
    lower_bound : int
        ``ceil`` of the LP optimum: no placement among the candidates reaching the target uses fewer
        new tags.
    lp_objective : float
        The LP optimum itself (NaN if the LP did not solve).
    uncoverable : ndarray, shape (U, 2)
        Points of ``D`` where the rule fails even with every candidate added (map units).
    coverable_fraction : float
        Share of the points of ``D`` where some placement makes the rule hold.
    target_reached : bool
        The rule holds, after, at every coverable point of ``D`` (false when ``max_tags`` stopped it).
    candidates : Candidates
        Every candidate considered.
    params : Params
        The parameters the proposal was made with.
    tag_width : float
        The tag width used (map units).
    stats : dict
        Counts of the search: ``candidates`` (candidates seen from some evaluation point),
        ``domain_points`` (grid points of ``D``), ``pairs`` (visible point × candidate pairs) and
        ``greedy`` (tags the greedy chose before pruning). Not compared by ``==``.
    live_before, live_after : Liveness or None
        For ``target = live``: the liveness with the map's tags and with the new ones added
        (:func:`bearnav_cli.liveness.evaluate`); ``lower_bound`` is then 0 and ``lp_objective`` NaN
        (no bound is computed), ``gains`` counts liveness grid points, ``uncoverable`` the grid points
        no candidate makes live, and ``coverable_fraction`` is a share of the liveness grid.
    """

    ids: tuple
    positions: np.ndarray
    normals: np.ndarray
    gains: np.ndarray
    before: PerceptionCoverage
    after: PerceptionCoverage
    lower_bound: int
    lp_objective: float
    uncoverable: np.ndarray
    coverable_fraction: float
    target_reached: bool
    candidates: Candidates
    params: Params
    tag_width: float
    stats: dict = field(default_factory=dict, compare=False)
    live_before: Any = None
    live_after: Any = None

    @property
    def count(self) -> int:
        """Number of new tags ``K``."""
        return len(self.ids)

    @property
    def landmarks(self) -> np.ndarray:
        """Existing and new tag positions, shape (L + K, 2): the landmarks of the map with the tags."""
        return self.after.landmarks

    @property
    def landmark_ids(self) -> tuple:
        """Existing and new ids, length L + K."""
        return self.after.landmark_ids

    def summary(self) -> str:
        """One line: tags added against the lower bound, and the coverage of ``D`` and ``F`` before and after."""
        reached = "target reached" if self.target_reached else "target NOT reached"
        uncovered = 1.0 - self.coverable_fraction
        if self.live_after is not None:
            b, a = self.live_before, self.live_after
            return (
                f"{plural(self.count, 'new tag')} to the {len(self.before.landmarks)} of the map, {reached}: "
                f"live on {percent(b.live_fraction)} → {percent(a.live_fraction)} of the certified area at η = "
                f"{math.degrees(a.grid.eta):.3g}° ({b.n_live} → {a.n_live} of {len(a.live)} cells); certified bearing "
                f"error η* {math.degrees(b.eta_star):.3g}° → {math.degrees(a.eta_star):.3g}°"
                + (f"; {percent(uncovered)} of the grid cannot be made live by any tag" if uncovered > 0 else "")
            )
        return (f"{plural(self.count, 'new tag')} (lower bound {self.lower_bound}) to the "
                f"{len(self.before.landmarks)} of the map, {reached}: two usable tags in view on "
                f"{percent(self.before.fraction_domain)} → {percent(self.after.fraction_domain)} of the certified area "
                f"and {percent(self.before.fraction_free)} → {percent(self.after.fraction_free)} of the free space"
                + (f"; {percent(uncovered)} of the certified area cannot be covered" if uncovered > 0
                   else ""))  # fmt: skip


def new_tag_ids(existing: Any, count: int) -> tuple[str, ...]:
    """``count`` ids that clash with none of ``existing``.

    Every existing id an integer: the next integers. Otherwise ``tagN`` with ``N`` after the largest
    existing ``tagN`` (``tag0`` without one), skipping any id already taken.
    """
    taken = {str(i) for i in existing}
    if taken and all(re.fullmatch(r"\d+", i) for i in taken):
        prefix, start = "", max(int(i) for i in taken) + 1
    else:
        numbers = [int(m.group(1)) for i in taken if (m := re.fullmatch(r"tag(\d+)", i))]
        prefix, start = "tag", max(numbers, default=-1) + 1
    out: list[str] = []
    n = start
    while len(out) < count:
        name = f"{prefix}{n}"
        if name not in taken:
            out.append(name)
        n += 1
    return tuple(out)


def _lower_bound(visible: np.ndarray, deficit: np.ndarray) -> tuple[int, float]:
    """``ceil`` of ``min Σ x`` s.t. ``visible @ x ≥ deficit``, ``0 ≤ x ≤ 1`` (over the rows with a positive
    deficit), and the optimum itself (NaN if the LP does not solve)."""
    rows = deficit > 0
    if not rows.any():
        return 0, 0.0
    v, r = visible[rows], deficit[rows]
    # identical rows are one constraint
    packed = np.concatenate([np.packbits(v, axis=1), r[:, None].astype(np.uint8)], axis=1)
    _, first = np.unique(packed, axis=0, return_index=True)
    v, r = v[np.sort(first)], r[np.sort(first)]
    n_c = v.shape[1]
    indptr = np.concatenate([[0], np.cumsum(v.sum(axis=1))]).astype(np.int32)
    indices = np.nonzero(v)[1].astype(np.int32)
    result = LpSolver().solve(np.ones(n_c), indptr, indices, np.ones(len(indices)), r.astype(float),
                              np.full(len(r), INF), np.zeros(n_c), np.ones(n_c))  # fmt: skip
    if result.status is not LpStatus.OPTIMAL:
        return 0, math.nan
    return int(math.ceil(result.objective - LP_SLACK)), float(result.objective)


@dataclass(frozen=True)
class _Pairs:
    """Every (point of D, candidate) pair where the camera sees the candidate, with the candidate's projector there."""

    point: np.ndarray  # (n,) index into the points of D
    cand: np.ndarray  # (n,) candidate index
    proj: np.ndarray  # (n, 3) P = I − ββᵀ as (a11, a22, a12)
    wproj: np.ndarray  # (n, 3) P / max(d², tol²)

    @classmethod
    def build(cls, seen: np.ndarray, points: np.ndarray, positions: np.ndarray, tol: float) -> _Pairs:
        pi, ci = np.nonzero(seen)
        d = positions[ci] - points[pi]
        dist = np.hypot(d[:, 0], d[:, 1])
        unit = d / np.where(dist > 0, dist, 1.0)[:, None]
        bx, by = unit[:, 0], unit[:, 1]
        proj = np.stack([1.0 - bx * bx, 1.0 - by * by, -bx * by], axis=1)
        return cls(pi, ci, proj, proj / np.maximum(dist * dist, tol * tol)[:, None])

    def add(self, sums: _Sums, c: int, sign: int = 1) -> np.ndarray:
        """Add (``sign = -1``: remove) candidate ``c`` to the running sums; returns the points it is seen from."""
        at = self.cand == c
        p = self.point[at]
        sums.n[p] += sign
        sums.s[p] += sign * self.proj[at]
        sums.w[p] += sign * self.wproj[at]
        return p


def _per_point(point: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Sums of the rows of ``values`` (m, 3) per point index, shape (n, 3)."""
    return np.stack([np.bincount(point, values[:, k], n) for k in range(values.shape[1])], axis=1)


def _greedy(pairs: _Pairs, sums: _Sums, coverable: np.ndarray, rule: _Rule, n_cand: int,
            limit: float) -> list[int]:  # fmt: skip
    """Step 2 of the module docstring; updates ``sums`` in place and returns the chosen candidates in order."""
    covered, psi = rule.holds_and_progress(sums.n, sums.s, sums.w)
    available = np.ones(n_cand, bool)
    order = np.arange(n_cand)
    chosen: list[int] = []
    while len(chosen) < limit:
        sel = (coverable & ~covered)[pairs.point] & available[pairs.cand]
        if not sel.any():
            break
        p, c = pairs.point[sel], pairs.cand[sel]
        ok, prog = rule.holds_and_progress(sums.n[p] + 1, sums.s[p] + pairs.proj[sel], sums.w[p] + pairs.wproj[sel])
        primary = np.bincount(c, ok.astype(np.int64), n_cand)
        progress = np.bincount(c, prog - psi[p], n_cand)
        primary[~available] = -1
        best = int(np.lexsort((order, -progress, -primary))[0])
        if primary[best] <= 0 and not progress[best] > 0:
            break  # nothing left helps (only possible with an error target)
        seen_from = pairs.add(sums, best)
        covered[seen_from], psi[seen_from] = rule.holds_and_progress(sums.n[seen_from], sums.s[seen_from],
                                                                     sums.w[seen_from])  # fmt: skip
        available[best] = False
        chosen.append(best)
    return chosen


def _prune(chosen: list[int], pairs: _Pairs, sums: _Sums, rule: _Rule) -> list[int]:
    """Drop chosen tags, the last chosen first, whose removal keeps the rule wherever it holds (``sums`` in place)."""
    covered = rule.holds_and_progress(sums.n, sums.s, sums.w)[0]
    keep = list(chosen)
    for c in reversed(chosen):
        p = pairs.add(sums, c, -1)
        if np.all(rule.holds_and_progress(sums.n[p], sums.s[p], sums.w[p])[0] | ~covered[p]):
            keep.remove(c)
        else:
            pairs.add(sums, c)
    return keep


def _gains(chosen: list[int], pairs: _Pairs, sums: _Sums, rule: _Rule) -> np.ndarray:
    """Points where the rule comes to hold as each chosen tag is added in turn (``sums`` in place)."""
    covered = rule.holds_and_progress(sums.n, sums.s, sums.w)[0]
    out = []
    for c in chosen:
        p = pairs.add(sums, c)
        ok = rule.holds_and_progress(sums.n[p], sums.s[p], sums.w[p])[0]
        out.append(int(np.sum(ok & ~covered[p])))
        covered[p] |= ok
    return np.array(out, np.int64)


def _rule(
    grid: EvaluationGrid,
    map_: Any,
    params: Params,
    sight: list,
    positions: np.ndarray | None = None,
    ids: tuple = (),
    new_sight: list | None = None,
) -> PerceptionCoverage:
    """The perception rule at ``params``' camera with the map's tags (their ``sight``) and new ones at ``positions``."""
    camera = dict(fov_deg=params.fov_deg, noise_deg=params.noise_deg, max_range=params.max_range,
                  error_target=params.error_target, min_spread_deg=params.min_spread_deg)  # fmt: skip
    if positions is None or not len(positions):
        landmarks, landmark_ids, seen = map_.landmarks, map_.landmark_ids, sight
    else:
        landmarks = np.vstack([map_.landmarks, positions])
        landmark_ids, seen = (*map_.landmark_ids, *ids), sight + list(new_sight)
    return perception.evaluate(grid, landmarks, landmark_ids, sight=seen, **camera)


def propose_tags(plan: Any, params: Params = Params()) -> TagProposal:
    """New tags so that the perception rule holds wherever it can in the certified domain (issue 11, part 1).

    See the module docstring for the candidates, the greedy and the bound. The fields do not depend
    on the landmarks (ALGORITHMS Lemma 3), so the plan's headings hold for the new tags and
    re-planning with them keeps the cells; only the gains change.

    Parameters
    ----------
    plan : Plan
        A ``bearnav.plan/2`` plan.
    params : Params
        The camera (field of view, range, noise, ``θ_min``), the error target, the tag width,
        the evaluation grid's spacing, the tag budget and pruning.

    Returns
    -------
    TagProposal
        ``after`` is the rule re-evaluated by :func:`bearnav_cli.perception.evaluate` (the runtime's
        own reconstruction) with the map's tags and the new ones; ``stats`` holds ``candidates``,
        ``domain_points``, ``pairs`` (visible point × candidate pairs) and ``greedy`` (tags the
        greedy chose before pruning).
    """
    map_ = plan.map
    width = params.width(map_.diagonal)
    grid: EvaluationGrid = perception.evaluation_grid(plan, params.spacing)
    existing_sight = grid.space.visibility_regions(map_.landmarks)
    before = _rule(grid, map_, params, existing_sight)

    cand = candidates(map_, width, grid.space)
    sight = grid.space.visibility_regions(cand.positions)
    seen_all = perception.visible_landmarks(grid.points, grid.heading, cand.positions, params.fov_deg,
                                            params.max_range, sight, grid.tol)  # fmt: skip
    useful = np.flatnonzero(seen_all.any(axis=0))  # seen from some evaluation point
    cand = Candidates(cand.positions[useful], cand.normals[useful], cand.on_wall[useful])
    sight = [sight[k] for k in useful]
    dom = np.flatnonzero(grid.in_domain)
    xd = grid.points[dom]
    pairs = _Pairs.build(seen_all[np.ix_(dom, useful)], xd, cand.positions, grid.tol)

    rule = _Rule(1.0 - math.cos(math.radians(params.min_spread_deg)), math.radians(params.noise_deg),
                 params.error_target)  # fmt: skip
    # running sums of the existing tags at every point of D
    v0 = before.visible[dom].astype(float)
    proj0, wproj0 = _projectors(xd, map_.landmarks, grid.tol)
    start = _Sums(v0.sum(axis=1).astype(np.int64), np.einsum("pl,plk->pk", v0, proj0),
                  np.einsum("pl,plk->pk", v0, wproj0))  # fmt: skip
    # coverable: the rule holds with every candidate added
    n_d = len(dom)
    full = _Sums(start.n + np.bincount(pairs.point, minlength=n_d), start.s + _per_point(pairs.point, pairs.proj, n_d),
                 start.w + _per_point(pairs.point, pairs.wproj, n_d))  # fmt: skip
    coverable = rule.holds_and_progress(full.n, full.s, full.w)[0] | rule.holds_and_progress(start.n, start.s,
                                                                                             start.w)[0]  # fmt: skip
    deficit = np.where(coverable, np.maximum(0, 2 - start.n), 0)
    seen_d = np.zeros((n_d, len(cand.positions)), bool)
    seen_d[pairs.point, pairs.cand] = True
    lower_bound, lp_objective = _lower_bound(seen_d, deficit)

    limit = math.inf if params.max_tags is None else int(params.max_tags)
    sums = _Sums(start.n.copy(), start.s.copy(), start.w.copy())
    chosen = _greedy(pairs, sums, coverable, rule, len(cand.positions), limit)
    greedy_count = len(chosen)
    if params.prune:
        chosen = _prune(chosen, pairs, sums, rule)
    gains = _gains(chosen, pairs, _Sums(start.n.copy(), start.s.copy(), start.w.copy()), rule)

    idx = np.array(chosen, np.int64)
    ids = new_tag_ids(map_.landmark_ids, len(idx))
    positions = cand.positions[idx].reshape(-1, 2)
    after = _rule(grid, map_, params, existing_sight, positions, ids, [sight[k] for k in idx])
    return TagProposal(
        ids=ids, positions=positions, normals=cand.normals[idx].reshape(-1, 2), gains=gains, before=before,
        after=after, lower_bound=lower_bound, lp_objective=lp_objective, uncoverable=xd[~coverable],
        coverable_fraction=float(coverable.mean()) if n_d else math.nan,
        target_reached=bool(np.all(after.holds[dom][coverable])), candidates=cand, params=params, tag_width=width,
        stats={"candidates": len(cand.positions), "domain_points": n_d, "pairs": len(pairs.point),
               "greedy": greedy_count},
    )  # fmt: skip


def propose(plan: Any, params: Params = Params()) -> TagProposal:
    """:func:`propose_tags` or :func:`propose_live_tags`, as ``params.target`` says."""
    return propose_live_tags(plan, params) if params.target == "live" else propose_tags(plan, params)


class _LiveScores:
    """The live greedy's state: the points of the liveness grid some cell needs a smaller bound at (F of them).

    Each point keeps its look (``runtime.bounded.LookBound``) with the tags so far; a candidate is
    scored by ``bounded.bound_with`` (an upper bound on the point's bound with it, cheap), a chosen
    one is added exactly.
    """

    def __init__(self, g: Any, x: np.ndarray, need: np.ndarray, visible: np.ndarray, landmarks: np.ndarray,
                 seen: np.ndarray, positions: np.ndarray) -> None:  # fmt: skip
        self.g, self.x, self.need = g, x, need
        self.visible, self.landmarks = visible, landmarks  # (F, L) and (L, 2): the tags so far
        self.seen, self.positions = seen, positions  # (F, C) and (C, 2): the candidates
        self.look = self._look(np.arange(len(x)))

    def _look(self, rows: np.ndarray) -> bounded.LookBound:
        return bounded.look_bound(self.x[rows], self.landmarks, self.visible[rows], self.g.eta,
                                  estimate.axle_bounds(self.g.arrays), self.g.arrays.tol)  # fmt: skip

    @property
    def eps(self) -> np.ndarray:
        return self.look.bound

    @property
    def failing(self) -> np.ndarray:
        return self.eps >= self.need

    def score(self, rows: np.ndarray, cand: np.ndarray) -> np.ndarray:
        """For pairs (point ``rows[i]``, candidate ``cand[i]``): the share of the point's missing reduction the
        candidate makes (1: live there), by the cheap bound."""
        new = bounded.bound_with(self.look.take(rows), self.x[rows], self.positions[cand], self.g.arrays.tol)
        eps = self.eps[rows]
        gap = eps - self.need[rows]
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.clip((eps - new) / np.where(gap > 0, gap, np.inf), 0.0, 1.0)
        return np.where(new < self.need[rows], 1.0, share)

    def add(self, c: int) -> int:
        """Candidate ``c`` becomes a tag: the looks of the points that see it, exactly. Points made live."""
        rows = np.flatnonzero(self.seen[:, c])
        before = self.failing[rows]
        self.landmarks = np.vstack([self.landmarks, self.positions[c]])
        self.visible = np.column_stack([self.visible, self.seen[:, c]])
        if len(rows):
            new = self._look(rows)
            width = max(self.look.diff_vertices.shape[1], new.diff_vertices.shape[1])
            old = self.look._replace(diff_vertices=bounded.fit(self.look.diff_vertices, width))
            fields = [np.array(f, copy=True) for f in old]
            for f, value in zip(fields, new._replace(diff_vertices=bounded.fit(new.diff_vertices, width)), strict=True):
                f[rows] = value
            self.look = bounded.LookBound(*fields)
        return int(np.count_nonzero(before & ~self.failing[rows]))


def _live_greedy(scores: _LiveScores, coverable: np.ndarray, limit: float) -> tuple[list[int], list[int], int]:
    """Lazy greedy of :func:`propose_live_tags`: the chosen candidates, the points each made live, pairs scored first.

    The scores only fall as tags are added (a point's bound shrinks with every tag), so a candidate
    whose score was taken this round and still leads the others' older scores is the best; older
    ones are re-scored :data:`LIVE_RESCORE` at a time, in one batch.
    """
    n_cand = scores.seen.shape[1]
    rows, cand = np.nonzero(scores.seen & (coverable & scores.failing)[:, None])
    n_pairs = len(cand)
    estimate = np.bincount(cand, scores.score(rows, cand), n_cand)
    heap = [(-float(v), int(c)) for c, v in enumerate(estimate) if v > 0]
    heapq.heapify(heap)
    scored_in = np.full(n_cand, -1)  # the round a candidate's score in the heap was taken in
    chosen: list[int] = []
    gains: list[int] = []
    while heap and len(chosen) < limit:
        wanted = coverable & scores.failing
        if not wanted.any():
            break
        value, c = heap[0]
        if scored_in[c] == len(chosen):  # fresh and still the best: take it
            heapq.heappop(heap)
            if -value <= 1e-9:
                break
            gains.append(scores.add(c))
            chosen.append(c)
            continue
        popped = [heapq.heappop(heap) for _ in range(min(LIVE_RESCORE, len(heap)))]
        for entry in popped:  # those scored this round keep their place
            if scored_in[entry[1]] == len(chosen):
                heapq.heappush(heap, entry)
        batch = [c for _, c in popped if scored_in[c] != len(chosen)]
        rows, which = np.nonzero(wanted[:, None] & scores.seen[:, batch])
        share = scores.score(rows, np.asarray(batch)[which]) if len(rows) else np.zeros(0)
        values = np.bincount(which, share, len(batch))
        for b, v in zip(batch, values, strict=True):
            scored_in[b] = len(chosen)
            if v > 1e-9:
                heapq.heappush(heap, (-float(v), b))
    return chosen, gains, n_pairs


def propose_live_tags(plan: Any, params: Params = Params(target="live")) -> TagProposal:
    """New tags so that every cell of a funnel plan is live (ALGORITHMS §12.5; ``bearnav tags --for live``).

    On the grid of :func:`bearnav_cli.liveness.grid` (the user's ``η``, slip and range; the look
    goes all around, so the field of view does not enter), a point needs the bound of a look
    ``ε(x, S_all(x))`` below the least margin of the cells holding it. Candidates are those of
    :func:`candidates`; a lazy greedy adds the candidate whose tag brings the failing points the
    most of their missing reduction (a point made live counts 1; scored by the cheap upper bound
    ``runtime.bounded.bound_with``, the chosen tag's effect computed exactly), until every point
    some placement can make live is live, or ``max_tags`` are placed. A point no candidate makes live
    (with all of them added) is ``uncoverable``: a cell whose margin is too small for any look.

    Parameters
    ----------
    plan : Plan
        A funnel plan (``bearnav.plan/3``).
    params : Params
        ``bearing_error_deg``, ``slip``, ``resolution``, ``max_range``, ``max_tags``, the tag width;
        the camera's ``fov_deg`` and ``noise_deg`` only for the perception coverage the figure draws.

    Returns
    -------
    TagProposal
        With ``live_before`` and ``live_after``.

    Raises
    ------
    InvalidParamsError
        As :func:`bearnav_cli.liveness.grid` (a paper plan: field ``plan``).
    """
    from bearnav_cli import liveness

    map_ = plan.map
    width = params.width(map_.diagonal)
    g = liveness.grid(plan, params.bearing_error_deg, params.fov_deg, kappa=params.slip,
                      resolution=params.resolution, max_range=params.max_range)  # fmt: skip
    existing = np.asarray(map_.landmarks, float).reshape(-1, 2)
    need = g.point_margin()
    visible0, eps0 = g.look(existing)
    failing = np.flatnonzero((eps0 >= need) & (need > 0))
    unfixable = np.flatnonzero(need <= 0)  # no look is good enough where a cell has no margin
    pe_grid: EvaluationGrid = perception.evaluation_grid(plan, params.spacing)
    cand = candidates(map_, width, pe_grid.space)
    x = g.points[failing]
    seen = (
        step.views(g.arrays, x, 2.0 * math.pi, params.max_range, 1, cand.positions)[:, 0]
        if len(x)
        else np.zeros((0, len(cand.positions)), bool)
    )
    useful = np.flatnonzero(seen.any(axis=0))
    cand = Candidates(cand.positions[useful], cand.normals[useful], cand.on_wall[useful])
    seen = seen[:, useful]
    # what no placement can do: the bound with every candidate added
    full = g.bounds(x, np.column_stack([visible0[failing], seen]), np.vstack([existing, cand.positions]))
    coverable = full < need[failing]
    scores = _LiveScores(g, x, need[failing], visible0[failing], existing, seen, cand.positions)
    limit = math.inf if params.max_tags is None else int(params.max_tags)
    chosen, gains, pairs = _live_greedy(scores, coverable, limit)

    idx = np.array(chosen, np.int64)
    ids = new_tag_ids(map_.landmark_ids, len(idx))
    positions = cand.positions[idx].reshape(-1, 2)
    live_before = liveness.evaluate(g, existing, look=(visible0, eps0))
    live_after = liveness.evaluate(g, np.vstack([existing, positions]))
    existing_sight = pe_grid.space.visibility_regions(map_.landmarks)
    before = _rule(pe_grid, map_, params, existing_sight)
    after = _rule(pe_grid, map_, params, existing_sight, positions, ids, pe_grid.space.visibility_regions(positions))
    stuck = np.concatenate([unfixable, failing[~coverable]])
    return TagProposal(
        ids=ids, positions=positions, normals=cand.normals[idx].reshape(-1, 2), gains=np.array(gains, np.int64),
        before=before, after=after, lower_bound=0, lp_objective=math.nan, uncoverable=g.points[stuck],
        coverable_fraction=1.0 - len(stuck) / max(len(g.points), 1),
        target_reached=bool(np.all(live_after.live)), candidates=cand, params=params, tag_width=width,
        stats={"candidates": len(cand.positions), "domain_points": len(g.points), "pairs": pairs,
               "greedy": len(chosen)},
        live_before=live_before, live_after=live_after,
    )  # fmt: skip


def map_spec_with_tags(spec: dict, proposal: TagProposal) -> dict:
    """A map description (DESIGN §4, as ``yaml.safe_load`` returns it) with the proposed tags appended.

    The existing landmarks and every other key are kept as they are (a deep copy: ``spec`` itself is
    not changed); each new tag is appended as ``{id, position: [x, y]}``.

    Parameters
    ----------
    spec : dict
        The map description the plan was made from.
    proposal : TagProposal
        The tags to add (:func:`propose_tags`): their ``ids`` and ``positions``.

    Returns
    -------
    dict

    Raises
    ------
    InvalidParamsError
        ``spec`` has no landmark list, or one of its ids is a proposed id (the proposal belongs to
        another map).
    """
    if not isinstance(spec, dict) or not isinstance(spec.get("landmarks"), list):
        raise InvalidParamsError("the map description has no list of landmarks", field="landmarks")
    out = copy.deepcopy(spec)
    ids = set()
    for k, item in enumerate(out["landmarks"]):
        ids.add(str(item.get("id", k)) if isinstance(item, dict) else str(k))
    clash = sorted(ids & set(proposal.ids))
    if clash:
        raise InvalidParamsError(f"proposed id {clash[0]!r} is already a landmark of this map description "
                                 "(was the plan made from it?)", field="landmarks")  # fmt: skip
    for name, p in zip(proposal.ids, proposal.positions, strict=True):
        out["landmarks"].append({"id": name, "position": [float(p[0]), float(p[1])]})
    return out


def tagged_name(name: str) -> str:
    """The ``name:`` of a map with proposed tags: ``NAME_tags``, so that its plan folder is not the original's."""
    return name if name.endswith("_tags") else f"{name}_tags"


_TOP_KEY = re.compile(r"^(?P<key>[A-Za-z_][\w-]*)\s*:(?P<rest>.*)$")


def _top_key(line: str, key: str) -> re.Match | None:
    match = _TOP_KEY.match(line.rstrip("\r\n"))
    return match if match and match.group("key") == key else None


def _flow_item(name: str, p: Any) -> str:
    # JSON strings are YAML double-quoted scalars; repr of a float reads back as the same float
    return f"{{id: {json.dumps(name)}, position: [{float(p[0])!r}, {float(p[1])!r}]}}"


def map_text_with_tags(text: str, proposal: TagProposal, name: str, header: str) -> str | None:
    """The YAML text of a map description with the proposed tags appended and ``name:`` set, the rest as it was.

    Comments, key order, circles and every other key keep their text: only the ``name:`` line is
    replaced (or added after the header) and one line per new tag is added at the end of the
    top-level ``landmarks:`` list (a block list, or a flow list on one line). A first line that
    starts like ``header`` (an earlier run's) is replaced by ``header``.

    Parameters
    ----------
    text : str
        The map YAML as the user wrote it.
    proposal : TagProposal
        The tags to add: their ``ids`` and ``positions``.
    name : str
        The new map's ``name:`` (:func:`tagged_name`).
    header : str
        A comment line (starting with ``#``, no newline) put first.

    Returns
    -------
    str or None
        The new text, or None for a layout this edit does not handle (no top-level ``landmarks:``,
        a flow list over several lines); the caller checks that the text reads back as the map it
        means (``map_spec_with_tags`` and the new name) and writes the map afresh otherwise.
    """
    lines = text.splitlines(keepends=True)
    if lines and not lines[-1].endswith("\n"):
        lines[-1] += "\n"
    if lines and lines[0].startswith(header.split(":")[0] + ":"):
        lines = lines[1:]
    items = [_flow_item(ident, p) for ident, p in zip(proposal.ids, proposal.positions, strict=True)]
    at = next((i for i, line in enumerate(lines) if _top_key(line, "landmarks")), None)
    if at is None:
        return None
    rest = _top_key(lines[at], "landmarks").group("rest")
    value = rest.split(" #")[0].strip()
    if value.startswith("["):
        if not value.endswith("]"):
            return None  # a flow list over several lines
        head, _, tail = lines[at].rpartition("]")
        inner = value[1:-1].strip()
        lines[at] = head + (", " if inner else "") + ", ".join(items) + "]" + tail
    elif value:
        return None  # an alias or some other scalar: not a list this edit understands
    elif items:
        end, indent = at + 1, None
        for i in range(at + 1, len(lines)):
            stripped = lines[i].strip()
            if stripped and not lines[i][0].isspace() and not stripped.startswith(("-", "#")):
                break  # the next top-level key
            if stripped and not stripped.startswith("#"):
                end = i + 1
                if indent is None and stripped.startswith("-"):
                    indent = lines[i][: len(lines[i]) - len(lines[i].lstrip())]
        if indent is None:
            return None  # `landmarks:` with nothing under it (null)
        lines[end:end] = [f"{indent}- {item}\n" for item in items]
    named = next((i for i, line in enumerate(lines) if _top_key(line, "name")), None)
    if named is not None:
        lines[named] = f"name: {json.dumps(name)}\n"
    else:
        lines.insert(0, f"name: {json.dumps(name)}\n")
    return header + "\n" + "".join(lines)
