"""Tags for liveness (``target = live``, ALGORITHMS §12.5): a lazy greedy until every cell of a funnel plan is live."""

from __future__ import annotations

import heapq
import math
from typing import Any

import numpy as np

from bearnav_cli import perception
from bearnav_cli.perception import EvaluationGrid
from bearnav_cli.runtime import bounded, estimate, look_bound, looking
from bearnav_cli.tags.candidates import Candidates, candidates
from bearnav_cli.tags.proposal import Params, TagProposal, coverage_with, new_tag_ids

__all__ = ["LIVE_RESCORE", "propose_live_tags"]


#: Candidates the live greedy re-scores together when the best one's score is stale.
LIVE_RESCORE = 32


class _LiveScores:
    """The live greedy's state: the points of the liveness grid some cell needs a smaller bound at (F of them).

    Each point keeps its look (``runtime.look_bound.LookBound``) with the tags so far; a candidate is
    scored by ``look_bound.bound_with`` (an upper bound on the point's bound with it, cheap), a chosen
    one is added exactly.
    """

    def __init__(
        self,
        g: Any,
        x: np.ndarray,
        need: np.ndarray,
        visible: np.ndarray,
        landmarks: np.ndarray,
        seen: np.ndarray,
        positions: np.ndarray,
    ) -> None:
        self.g, self.x, self.need = g, x, need
        self.visible, self.landmarks = visible, landmarks  # (F, L) and (L, 2): the tags so far
        self.seen, self.positions = seen, positions  # (F, C) and (C, 2): the candidates
        self.look = self._look(np.arange(len(x)))

    def _look(self, rows: np.ndarray) -> look_bound.LookBound:
        return look_bound.look_bound(
            self.x[rows],
            self.landmarks,
            self.visible[rows],
            self.g.eta,
            estimate.axle_bounds(self.g.arrays),
            self.g.arrays.tol,
        )

    @property
    def eps(self) -> np.ndarray:
        return self.look.bound

    @property
    def failing(self) -> np.ndarray:
        return self.eps >= self.need

    def score(self, rows: np.ndarray, cand: np.ndarray) -> np.ndarray:
        """For pairs (point ``rows[i]``, candidate ``cand[i]``): the share of the point's missing reduction the
        candidate makes (1: live there), by the cheap bound."""
        new = look_bound.bound_with(self.look.take(rows), self.x[rows], self.positions[cand], self.g.arrays.tol)
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
            self.look = look_bound.LookBound(*fields)
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
    ``runtime.look_bound.bound_with``, the chosen tag's effect computed exactly), until every point
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
    g = liveness.grid(
        plan,
        params.bearing_error_deg,
        params.fov_deg,
        kappa=params.slip,
        resolution=params.resolution,
        max_range=params.max_range,
    )
    existing = np.asarray(map_.landmarks, float).reshape(-1, 2)
    visible0, eps0 = g.look(existing)
    # the margin at each point where the look's set is as large as it is now: a tag only makes it smaller, and
    # the margin larger, so what this asks is enough
    need = g.point_margin(eps0)
    failing = np.flatnonzero((eps0 >= need) & (need > 0))
    unfixable = np.flatnonzero(need <= 0)  # no look is good enough where a cell has no margin
    pe_grid: EvaluationGrid = perception.evaluation_grid(plan, params.spacing)
    cand = candidates(map_, width, pe_grid.space)
    x = g.points[failing]
    seen = (
        looking.views(g.arrays, x, 2.0 * math.pi, params.max_range, 1, cand.positions)[:, 0]
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
    before = coverage_with(pe_grid, map_, params, existing_sight)
    new_sight = pe_grid.space.visibility_regions(positions)
    after = coverage_with(pe_grid, map_, params, existing_sight, positions, ids, new_sight)
    stuck = np.concatenate([unfixable, failing[~coverable]])
    return TagProposal(
        ids=ids,
        positions=positions,
        normals=cand.normals[idx].reshape(-1, 2),
        gains=np.array(gains, np.int64),
        before=before,
        after=after,
        lower_bound=0,
        lp_objective=math.nan,
        uncoverable=g.points[stuck],
        coverable_fraction=1.0 - len(stuck) / max(len(g.points), 1),
        target_reached=bool(np.all(live_after.live)),
        candidates=cand,
        params=params,
        tag_width=width,
        stats={
            "candidates": len(cand.positions),
            "domain_points": len(g.points),
            "pairs": pairs,
            "greedy": len(chosen),
        },
        live_before=live_before,
        live_after=live_after,
    )
