"""Tags for a usable fix (``target = fix``): the greedy set cover of the perception rule in closed form, and its bound.

Steps 2 and 3 of :mod:`bearnav_cli.tags`: every (point, candidate) pair is evaluated at once on running
sums, the greedy adds the candidate that makes the rule hold at the most points, pruning drops the
tags it can do without, and an LP relaxation bounds the number of tags any placement needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from bearnav_cli import perception
from bearnav_cli.lp import INF, LpSolver, LpStatus
from bearnav_cli.perception import EvaluationGrid
from bearnav_cli.runtime import bearing
from bearnav_cli.tags.candidates import Candidates, candidates
from bearnav_cli.tags.proposal import Params, TagProposal, coverage_with, new_tag_ids

__all__ = ["LP_SLACK", "propose_tags"]


#: The LP optimum is rounded up after removing this much (solver tolerance).
LP_SLACK = 1e-6


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
    result = LpSolver().solve(
        np.ones(n_c),
        indptr,
        indices,
        np.ones(len(indices)),
        r.astype(float),
        np.full(len(r), INF),
        np.zeros(n_c),
        np.ones(n_c),
    )
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


def _greedy(pairs: _Pairs, sums: _Sums, coverable: np.ndarray, rule: _Rule, n_cand: int, limit: float) -> list[int]:
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
        covered[seen_from], psi[seen_from] = rule.holds_and_progress(
            sums.n[seen_from], sums.s[seen_from], sums.w[seen_from]
        )
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
    before = coverage_with(grid, map_, params, existing_sight)

    cand = candidates(map_, width, grid.space)
    sight = grid.space.visibility_regions(cand.positions)
    seen_all = perception.visible_landmarks(
        grid.points, grid.heading, cand.positions, params.fov_deg, params.max_range, sight, grid.tol
    )
    useful = np.flatnonzero(seen_all.any(axis=0))  # seen from some evaluation point
    cand = Candidates(cand.positions[useful], cand.normals[useful], cand.on_wall[useful])
    sight = [sight[k] for k in useful]
    dom = np.flatnonzero(grid.in_domain)
    xd = grid.points[dom]
    pairs = _Pairs.build(seen_all[np.ix_(dom, useful)], xd, cand.positions, grid.tol)

    rule = _Rule(
        1.0 - math.cos(math.radians(params.min_spread_deg)), math.radians(params.noise_deg), params.error_target
    )
    # running sums of the existing tags at every point of D
    v0 = before.visible[dom].astype(float)
    proj0, wproj0 = _projectors(xd, map_.landmarks, grid.tol)
    start = _Sums(
        v0.sum(axis=1).astype(np.int64), np.einsum("pl,plk->pk", v0, proj0), np.einsum("pl,plk->pk", v0, wproj0)
    )
    # coverable: the rule holds with every candidate added
    n_d = len(dom)
    full = _Sums(
        start.n + np.bincount(pairs.point, minlength=n_d),
        start.s + _per_point(pairs.point, pairs.proj, n_d),
        start.w + _per_point(pairs.point, pairs.wproj, n_d),
    )
    coverable = (
        rule.holds_and_progress(full.n, full.s, full.w)[0] | rule.holds_and_progress(start.n, start.s, start.w)[0]
    )
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
    after = coverage_with(grid, map_, params, existing_sight, positions, ids, [sight[k] for k in idx])
    return TagProposal(
        ids=ids,
        positions=positions,
        normals=cand.normals[idx].reshape(-1, 2),
        gains=gains,
        before=before,
        after=after,
        lower_bound=lower_bound,
        lp_objective=lp_objective,
        uncoverable=xd[~coverable],
        coverable_fraction=float(coverable.mean()) if n_d else math.nan,
        target_reached=bool(np.all(after.holds[dom][coverable])),
        candidates=cand,
        params=params,
        tag_width=width,
        stats={
            "candidates": len(cand.positions),
            "domain_points": n_d,
            "pairs": len(pairs.point),
            "greedy": greedy_count,
        },
    )
