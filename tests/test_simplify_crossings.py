"""Simplify reaches RC's fixed point on maps nobody tuned (ALGORITHMS §3: no proper crossing after the last round).

The maps come from the project's generator (tests/mapgen.py: clutter, rooms and ragged grids).
Each round ends with CtL, which can delete a node that hid a crossing (RC skips crossings within
``tol`` of a node); ``max_rounds`` used to stop such a cascade with crossings left. The cases
below with fewer rounds than the default are ones where the finishing passes remove crossings
that the last CtL exposed (1 or 2 pairs; ``clutter`` 36 with 4 rounds also leaves one at a pass
bound of 1); the default-round ones check the fixed point where no finishing pass is needed.
Every check here is independent of the stage: a brute-force pair scan, the exact segment test,
costs walked edge by edge.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bearnav_cli import pipeline
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.stages import rrtstar, simplify

from . import mapgen
from .conftest import build_made

#: (kind, seed, max_rounds); None is the default (10)
CASES = [
    ("grid", 0, None),
    ("clutter", 0, None),
    ("rooms", 0, None),
    ("clutter", 36, 4),
    ("grid", 0, 3),
    ("rooms", 58, 4),
    ("grid", 37, 4),
    ("rooms", 58, 3),
]


def crossing_pairs(nodes: np.ndarray, parent: np.ndarray, tol: float, at_nodes: bool = False) -> list[tuple[int, int]]:
    """Every pair of edges that crosses properly, by brute force over all pairs, in plain floats.

    Edges ``(e, parent[e])`` and ``(f, parent[f])`` sharing no endpoint, not parallel
    (``|cross(r, s)| > tol·max(|r|, |s|)``), meeting at ``k`` strictly inside both, with ``k``
    farther than ``tol`` from the four endpoints and from every node. ``at_nodes``: the pairs
    that pass every test but the last one instead (a third node within ``tol`` of ``k``).
    """
    out = []
    kids = range(1, len(nodes))
    seg = {e: (nodes[e].tolist(), nodes[parent[e]].tolist()) for e in kids}
    for e in kids:
        (ax, ay), (bx, by) = seg[e]
        rx, ry = bx - ax, by - ay
        for f in range(e + 1, len(nodes)):
            if len({e, int(parent[e]), f, int(parent[f])}) < 4:
                continue
            (cx, cy), (dx, dy) = seg[f]
            if max(cx, dx) < min(ax, bx) or min(cx, dx) > max(ax, bx):
                continue
            if max(cy, dy) < min(ay, by) or min(cy, dy) > max(ay, by):
                continue
            sx, sy = dx - cx, dy - cy
            den = rx * sy - ry * sx
            if abs(den) <= tol * max(math.hypot(rx, ry), math.hypot(sx, sy)):
                continue
            t = ((cx - ax) * sy - (cy - ay) * sx) / den
            u = ((cx - ax) * ry - (cy - ay) * rx) / den
            if not (0 < t < 1 and 0 < u < 1):
                continue
            k = (ax + t * rx, ay + t * ry)
            if min(math.dist(k, p) for p in (seg[e][0], seg[e][1], seg[f][0], seg[f][1])) <= tol:
                continue
            out.append((e, f, k))
    if not out:
        return []
    near = np.array([np.hypot(*(nodes - k).T).min() for _, _, k in out])
    return [(e, f) for (e, f, _), d in zip(out, near, strict=True) if (d <= tol) == at_nodes]


@pytest.fixture(scope="module")
def runs():
    """(map, tree, simplified) per case; RRT* with each map's defaults (one tree per map)."""
    out, trees = {}, {}
    for kind, seed, rounds in CASES:
        if (kind, seed) not in trees:
            m = build_made(mapgen.generate(seed, kind))
            trees[kind, seed] = m, rrtstar.run(m, pipeline.resolve_params("rrtstar", m.params))
        m, tree = trees[kind, seed]
        params = simplify.Params() if rounds is None else simplify.Params(max_rounds=rounds)
        out[kind, seed, rounds] = (m, tree, simplify.run(tree, params))
    return out


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}{c[1]}-r{c[2] or 10}")
def test_no_proper_crossing_remains_and_stats_count_them(runs, case):
    m, _, out = runs[case]
    left = crossing_pairs(out.nodes, out.parent, m.tol)
    assert left == []
    assert out.stats["crossings_remaining"] == len(left)
    assert "remain" not in simplify.summary(out)
    # what RC leaves by definition is counted too, and named in the summary
    at_nodes = crossing_pairs(out.nodes, out.parent, m.tol, at_nodes=True)
    assert out.stats["crossings_at_nodes"] == len(at_nodes)
    assert (f"; {len(at_nodes)} edge pair" in simplify.summary(out)) == bool(at_nodes)


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}{c[1]}-r{c[2] or 10}")
def test_edges_free_routes_not_longer_samples_untouched(runs, case):
    m, tree, out = runs[case]
    assert FreeSpace.from_map(m).segments_free(out.nodes[1:], out.nodes[out.parent[1:]]).all()
    # costs: walked edge by edge, consistent with the stored ones, never above the input's
    walked = np.zeros(len(out.nodes))
    for i in range(1, len(out.nodes)):
        v, steps = i, 0
        while v != 0:
            walked[i] += math.dist(out.nodes[v], out.nodes[out.parent[v]])
            v, steps = out.parent[v], steps + 1
            assert steps <= len(out.nodes), "cycle"
    assert np.allclose(walked, out.cost, rtol=0, atol=m.tol)
    before = {tuple(p): c for p, c in zip(tree.nodes.tolist(), tree.cost, strict=True)}
    matched = [(before[tuple(p)], c) for p, c in zip(out.nodes.tolist(), out.cost, strict=True) if tuple(p) in before]
    old, new = np.array(matched).T
    assert np.all(new <= old + m.tol)
    assert out.collision_samples.tobytes() == tree.collision_samples.tobytes()
    # CtL's fixed point holds too: one leaf per parent at most (middle), positions distinct
    has_child = np.zeros(len(out.nodes), bool)
    has_child[out.parent[1:]] = True
    leaves = np.flatnonzero(~has_child)
    assert np.bincount(out.parent[leaves], minlength=len(out.nodes)).max() <= 1
    assert len(np.unique(out.nodes, axis=0)) == len(out.nodes)
    s = out.stats
    assert s["nodes_before"] - s["leaves_cut"] + s["crossings_removed"] == len(out.nodes)


def test_the_cases_do_exercise_the_finishing_passes(runs):
    """Without the finishing passes these runs end with crossings exposed by the last CtL."""
    finishing = {case: out.stats["finish_crossings_removed"] for case, (_, _, out) in runs.items()}
    assert sum(finishing.values()) > 0, finishing
    for case, (_, _, out) in runs.items():
        s = out.stats
        if s["finish_passes"]:  # only when max_rounds stopped rounds that still changed something
            assert s["rounds"] == (case[2] or 10)
            assert f"{s['finish_passes']} finishing RC/CtL pass" in simplify.summary(out)
        else:
            assert s["finish_crossings_removed"] == 0 and s["nodes_per_round"][-1] == len(out.nodes)


def test_deterministic_with_finishing_passes(runs):
    case = ("grid", 0, 3)
    _, tree, out = runs[case]
    again = simplify.run(tree, simplify.Params(max_rounds=3))
    for name in ("nodes", "parent", "cost"):
        assert getattr(again, name).tobytes() == getattr(out, name).tobytes()
    assert again.stats == out.stats


def test_crossings_left_at_the_pass_bound_are_counted_exactly(runs, monkeypatch):
    """With the finishing passes cut to one, the stats and the summary count what is left, exactly."""
    monkeypatch.setattr(simplify, "MAX_FINISH_PASSES", 1)
    tried = []
    for (kind, seed, _), (m, tree, _) in runs.items():
        for rounds in (3, 4, 5, 6):
            out = simplify.run(tree, simplify.Params(max_rounds=rounds))
            left = crossing_pairs(out.nodes, out.parent, m.tol)
            assert out.stats["crossings_remaining"] == len(left)
            tried.append((kind, seed, rounds, len(left)))
            if left:
                assert out.stats["finish_passes"] == 1
                word = "crossings remain" if len(left) > 1 else "crossing remains"
                assert f"; {len(left)} proper {word} (finishing passes stopped at their bound of 1)" in (
                    simplify.summary(out)
                )
                return
    pytest.fail(f"no case stopped at the bound with crossings left: {tried}")
