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
is the caller's business. ``plot.plot_tags`` draws a proposal. Every name is re-exported here; the
modules, each with one job:

- :mod:`~bearnav_cli.tags.candidates` — step 1, the candidate positions;
- :mod:`~bearnav_cli.tags.proposal` — :class:`Params`, :class:`TagProposal`, new ids, the rule with added tags;
- :mod:`~bearnav_cli.tags.cover` — steps 2 and 3 for ``target = fix`` (:func:`propose_tags`);
- :mod:`~bearnav_cli.tags.live` — ``target = live``, every cell live (:func:`propose_live_tags`);
- :mod:`~bearnav_cli.tags.map_text` — the map with the tags, as a description or as YAML text.
"""

from __future__ import annotations

from typing import Any

from bearnav_cli.tags.candidates import NUDGE, Candidates, candidates
from bearnav_cli.tags.cover import propose_tags
from bearnav_cli.tags.live import LIVE_RESCORE, propose_live_tags
from bearnav_cli.tags.map_text import map_spec_with_tags, map_text_with_tags, tagged_name
from bearnav_cli.tags.proposal import TAG_WIDTH_FRACTION, TARGETS, Params, TagProposal, new_tag_ids

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


def propose(plan: Any, params: Params = Params()) -> TagProposal:
    """:func:`propose_tags` or :func:`propose_live_tags`, as ``params.target`` says."""
    return propose_live_tags(plan, params) if params.target == "live" else propose_tags(plan, params)
