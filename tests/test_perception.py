"""Perception coverage (issue 11 part 2): the rule, checked against an independent evaluation.

On small random maps (tests/funnel_maps.py) and a rooms map of tests/mapgen.py: the camera heading is
the direction of the runtime's field (computed here through ``cell_policy.field``, the gain applied
to the displacements, not the affine form the module uses), visibility is the segment test of
``FreeSpace.visible`` with an own field-of-view test, the fix is usable exactly when two or more
tags are seen with ``λ_min(Σ P_k) ≥ 1 − cos 2°`` (numpy's ``eigvalsh``), and the predicted error
is ``3σ/sqrt(λ_min(Σ P_k/d_k²))``. Then monotonicity in the camera, the error target, the noise
scaling, bad parameters and the figure.
"""

from __future__ import annotations

import functools
import logging
import math

import matplotlib.pyplot as plt
import numpy as np
import pytest

from bearnav_cli import perception, plot
from bearnav_cli.datatypes import percent
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.runtime import cell_policy
from bearnav_cli.runtime.plan_arrays import PlanArrays
from tests.conftest import build_map, made_plan, random_plan
from tests.funnel_maps import ITERATIONS, random_spec

#: Coarser than the default D/100, to keep the file fast; the rule does not depend on it.
CELLS = 60


@pytest.fixture(autouse=True)
def _quiet(caplog):
    caplog.set_level(logging.ERROR)  # random maps have blind spots: the map stage warns


def plans():
    return [
        ("random 0", lambda: random_plan(0)),
        ("random 3", lambda: random_plan(3)),
        ("rooms 2", lambda: made_plan(2, "rooms")),
    ]


def spacing_of(plan) -> float:
    return plan.map.diagonal / CELLS


def _wrap(a):
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi


# --------------------------------------------------------------------------- the rule, independently


@pytest.mark.parametrize("name,make", plans(), ids=[p[0] for p in plans()])
def test_rule_matches_an_independent_evaluation(name, make):
    plan = make()
    fov, noise = 60.0, 1.0
    cov = perception.perception_coverage(plan, fov, noise, spacing=spacing_of(plan))
    assert cov.in_domain.any() and cov.in_free.any()
    # D ⊂ F (ALGORITHMS §11.1 (C1)): every point of D is free
    assert np.all(cov.in_free[cov.in_domain])
    rng = np.random.default_rng(0)
    pick = np.sort(rng.choice(len(cov.points), size=min(250, len(cov.points)), replace=False))
    x = cov.points[pick]
    arrays = PlanArrays.from_plan(plan)
    # heading: the field (gain @ displacement) of the least-rank cell, or the straight approach
    cell = cell_policy.least_rank_cell(arrays, x)
    direction = np.zeros_like(x)
    inside = cell >= 0
    direction[inside] = cell_policy.field(arrays, cell[inside], x[inside])
    target = cell_policy.approach_target(arrays, x[~inside])
    direction[~inside] = np.where(target[:, None] >= 0, arrays.nodes[target] - x[~inside], 0.0)
    heading = np.where(np.any(direction != 0, axis=1), np.arctan2(direction[:, 1], direction[:, 0]), np.nan)
    # no heading only where no node can be approached in a straight line (never in D)
    assert np.array_equal(np.isnan(cov.heading[pick]), np.isnan(heading))
    assert not np.isnan(heading[inside]).any()
    known = ~np.isnan(heading)
    assert np.all(np.abs(_wrap(cov.heading[pick][known] - heading[known])) < 1e-9)
    # visibility: own field-of-view test and the exact segment test through the raw obstacles
    lm = plan.map.landmarks
    d = lm[None] - x[:, None]
    off = _wrap(np.arctan2(d[..., 1], d[..., 0]) - heading[:, None])
    space = FreeSpace.from_map(plan.map)
    sight = space.visible(np.repeat(x, len(lm), axis=0), np.tile(lm, (len(x), 1))).reshape(len(x), len(lm))
    visible = (np.abs(off) <= math.radians(fov) / 2) & sight
    assert np.array_equal(cov.visible[pick], visible)
    assert np.array_equal(cov.visible_count[pick], visible.sum(axis=1))
    # the fix: two or more tags spread by θ_min = 2°, and its 3σ error bound
    beta = d / np.linalg.norm(d, axis=2)[..., None]
    proj = np.eye(2)[None, None] - beta[..., :, None] * beta[..., None, :]
    dist2 = np.sum(d * d, axis=2)
    for q in range(len(x)):
        v = visible[q]
        lam = np.linalg.eigvalsh(proj[q, v].sum(axis=0))[0] if v.sum() >= 2 else 0.0
        usable = v.sum() >= 2 and lam >= 1 - math.cos(math.radians(2.0))
        assert cov.usable[pick[q]] == usable, (name, q)
        if usable:
            info = np.linalg.eigvalsh((proj[q, v] / dist2[q, v][:, None, None]).sum(axis=0))[0]
            expected = 3 * math.radians(noise) / math.sqrt(info)
            assert cov.predicted_error[pick[q]] == pytest.approx(expected, rel=1e-9)
        else:
            assert cov.predicted_error[pick[q]] == math.inf
    assert np.array_equal(cov.holds, cov.usable)  # no error target: the fix alone
    assert cov.fraction_domain == pytest.approx(np.mean(cov.holds[cov.in_domain]))
    assert cov.fraction_free == pytest.approx(np.mean(cov.holds[cov.in_free]))
    assert cov.plan_tolerance == plan.plan_tolerance
    within = np.mean((cov.usable & (cov.predicted_error <= plan.plan_tolerance))[cov.in_domain])
    assert cov.fraction_within_tolerance == pytest.approx(within)
    assert len(cov.failing_domain) == np.sum(cov.in_domain & ~cov.holds)
    assert str(len(lm)) in cov.summary() and "of the certified area" in cov.summary()


def test_the_rule_grows_with_the_camera_and_shrinks_with_an_error_target():
    plan = random_plan(3)
    s = spacing_of(plan)
    narrow = perception.perception_coverage(plan, 60, 1.0, spacing=s)
    short = perception.perception_coverage(plan, 60, 1.0, max_range=0.3 * plan.map.diagonal, spacing=s)
    wide = perception.perception_coverage(plan, 360, 1.0, spacing=s)
    # a superset of visible tags: never fewer, never worse spread, never a larger error
    assert np.all(narrow.visible <= wide.visible) and np.all(short.visible <= narrow.visible)
    assert np.all(wide.holds[narrow.holds]) and np.all(narrow.holds[short.holds])
    both = narrow.usable & wide.usable
    assert np.all(wide.predicted_error[both] <= narrow.predicted_error[both] * (1 + 1e-12))
    assert wide.fraction_domain >= narrow.fraction_domain >= short.fraction_domain
    # with an error target: exactly the usable fixes within it
    target = float(np.median(wide.predicted_error[wide.usable]))
    strict = perception.perception_coverage(plan, 360, 1.0, error_target=target, spacing=s)
    assert np.array_equal(strict.holds, wide.usable & (wide.predicted_error <= target))
    assert 0 < strict.fraction_domain < wide.fraction_domain
    assert f"error ≤ {target:g}" in strict.summary()


def test_noise_scales_the_predicted_error_and_not_the_rule():
    plan = random_plan(0)
    s = spacing_of(plan)
    one = perception.perception_coverage(plan, 90, 1.0, spacing=s)
    two = perception.perception_coverage(plan, 90, 2.0, spacing=s)
    exact = perception.perception_coverage(plan, 90, 0.0, spacing=s)
    assert np.array_equal(one.holds, two.holds) and np.array_equal(one.holds, exact.holds)
    u = one.usable
    assert np.allclose(two.predicted_error[u], 2 * one.predicted_error[u], rtol=1e-12)
    assert np.all(exact.predicted_error[u] == 0)
    # noise-free, every usable fix is within δ*
    assert exact.fraction_within_tolerance == pytest.approx(exact.fraction_domain)


def test_landmarks_override_and_default_grid():
    plan = random_plan(0)
    own = perception.perception_coverage(plan, 60, 1.0)
    same = perception.perception_coverage(
        plan, 60, 1.0, landmarks=plan.map.landmarks, landmark_ids=plan.map.landmark_ids
    )
    assert own.landmark_ids == plan.map.landmark_ids and same.landmark_ids == own.landmark_ids
    assert np.array_equal(own.holds, same.holds) and own.fraction_domain == same.fraction_domain
    assert own.spacing == pytest.approx(plan.map.diagonal / perception.GRID_CELLS)
    two = perception.perception_coverage(plan, 60, 1.0, landmarks=plan.map.landmarks[:2])
    assert two.landmark_ids == ("0", "1") and two.visible.shape == (len(two.points), 2)
    assert np.all(two.holds <= own.holds)  # a subset of the tags
    # the headings do not depend on the landmarks (ALGORITHMS Lemma 3)
    assert np.array_equal(two.heading, own.heading, equal_nan=True)
    # every point of D has a heading (the field vanishes only at the goal)
    assert not np.isnan(own.heading[own.in_domain]).any()


@pytest.mark.parametrize(
    "kwargs,field",
    [({"fov_deg": 0}, "fov"), ({"fov_deg": 361}, "fov"), ({"fov_deg": -60}, "fov"), ({"fov_deg": math.nan}, "fov"),
     ({"noise_deg": -1}, "noise_deg"), ({"noise_deg": math.inf}, "noise_deg"), ({"max_range": -1}, "range"),
     ({"max_range": 0}, "range"), ({"error_target": 0}, "error_target"), ({"error_target": -0.1}, "error_target"),
     ({"spacing": 0}, "spacing"), ({"spacing": -1.0}, "spacing")],
)  # fmt: skip
def test_bad_parameters_name_their_field(kwargs, field):
    plan = random_plan(0)
    args = {"fov_deg": 60.0, "noise_deg": 1.0, **kwargs}
    with pytest.raises(InvalidParamsError) as info:
        perception.perception_coverage(plan, **args)
    assert info.value.field == field
    assert "\n" not in str(info.value) and field in str(info.value)


def test_figure_marks_where_the_rule_fails():
    plan = random_plan(3)
    cov = perception.perception_coverage(plan, 60, 1.0, spacing=spacing_of(plan))
    fig, ax = plt.subplots()
    plot.plot_map(ax, plan.map, landmarks=False, labels=False)
    plot.plot_perception(ax, cov)
    by_gid = {c.get_gid(): c for c in ax.collections if c.get_gid()}
    assert len(by_gid["perception-fail-domain"].get_offsets()) == np.sum(cov.in_domain & ~cov.holds)
    assert len(by_gid["perception-fail-free"].get_offsets()) == np.sum(cov.in_free & ~cov.in_domain & ~cov.holds)
    assert len(by_gid["perception-tags"].get_offsets()) == len(cov.landmarks)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(f"{1 - cov.fraction_domain:.1%} of D" in t for t in labels)
    assert any(t == f"tags ({len(cov.landmarks)})" for t in labels)
    assert "map units" in ax.get_xlabel() and "map units" in ax.get_ylabel()
    plt.close(fig)


# --------------------------------------------------------------------------- before a plan: any heading (map --fov)


@functools.cache
def random_map(seed: int):
    return build_map(random_spec(seed, ITERATIONS))


def _spec_with_landmarks(seed: int, keep) -> dict:
    spec = random_spec(seed, ITERATIONS)
    spec["landmarks"] = [spec["landmarks"][k] for k in keep]
    return spec


def _brute_force(space: FreeSpace, x, lm, fov_deg: float, max_range: float, headings) -> np.ndarray:
    """Usable noise-free fix at each heading, from scratch: segment sight test, own field of view, eigvalsh."""
    d = lm - x
    dist = np.hypot(d[:, 0], d[:, 1])
    reach = space.visible(np.repeat(x[None], len(lm), axis=0), lm) & (dist <= max_range)
    theta = np.arctan2(d[:, 1], d[:, 0])
    beta = d / dist[:, None]
    proj = np.eye(2)[None] - beta[:, :, None] * beta[:, None, :]
    out = []
    for phi in headings:
        seen = reach & ((np.abs(_wrap(theta - phi)) <= math.radians(fov_deg) / 2 + 1e-12) | (fov_deg >= 360))
        lam = np.linalg.eigvalsh(proj[seen].sum(axis=0))[0] if seen.sum() >= 2 else 0.0
        out.append(seen.sum() >= 2 and lam >= 1 - math.cos(math.radians(2.0)))
    return np.array(out)


def _own_critical_headings(space, x, lm, fov_deg, max_range):
    """Per point, in plain loops: each reachable tag at the arc's clockwise edge, and between-event midpoints."""
    d = lm - x
    dist = np.hypot(d[:, 0], d[:, 1])
    reach = space.visible(np.repeat(x[None], len(lm), axis=0), lm) & (dist <= max_range)
    half = math.radians(fov_deg) / 2
    theta = [math.atan2(d[k, 1], d[k, 0]) for k in range(len(lm)) if reach[k]]
    edges = [t + half for t in theta]
    events = sorted(((t + s * half) % (2 * math.pi)) for t in theta for s in (-1, 1))
    mids = [(a + b) / 2 for a, b in zip(events, events[1:] + [events[0] + 2 * math.pi] if events else [], strict=False)]
    return edges, mids


@pytest.mark.parametrize(
    "seed,fov,max_range", [(0, 60.0, math.inf), (1, 200.0, math.inf), (5, 270.0, math.inf), (3, 300.0, 3.0)]
)
def test_heading_coverage_matches_a_brute_force_over_headings(seed, fov, max_range):
    map_ = random_map(seed)
    cov = perception.heading_coverage(map_, fov, max_range, spacing=map_.diagonal / CELLS)
    space = FreeSpace.from_map(map_)
    lm = map_.landmarks
    assert np.all(space.points_free(cov.points)) and len(cov.points)
    assert cov.some.any() and not cov.some.all() and (cov.every.any() or fov < 180)
    rng = np.random.default_rng(seed)
    # points of each kind: no heading works, some but not every, every
    kinds = (~cov.some, cov.some & ~cov.every, cov.every)
    pick = np.concatenate([rng.permutation(np.flatnonzero(kind))[:12] for kind in kinds])
    fine = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    for q in pick:
        x = cov.points[q]
        d = lm - x
        reach = space.visible(np.repeat(x[None], len(lm), axis=0), lm) & (np.hypot(d[:, 0], d[:, 1]) <= max_range)
        assert cov.reachable_count[q] == reach.sum()
        on_fine = _brute_force(space, x, lm, fov, max_range, fine)
        # a sample of headings: at most what some heading gives, at least what every heading gives
        assert cov.some[q] >= on_fine.any() and cov.every[q] <= on_fine.all(), q
        edges, mids = _own_critical_headings(space, x, lm, fov, max_range)
        assert cov.some[q] == _brute_force(space, x, lm, fov, max_range, edges + list(fine)).any(), q
        if cov.some[q]:
            assert cov.every[q] == _brute_force(space, x, lm, fov, max_range, mids + list(fine)).all(), q
    assert np.all(cov.every <= cov.some)  # every heading ⊆ some heading
    assert cov.fraction_some == pytest.approx(np.mean(cov.some))
    assert cov.fraction_every == pytest.approx(np.mean(cov.every))
    assert len(cov.blind) == np.sum(~cov.some) and len(cov.heading_dependent) == np.sum(cov.some & ~cov.every)
    assert f"{percent(cov.fraction_some)} of the free space with some heading" in cov.summary()


def test_heading_coverage_grows_with_tags_camera_and_range():
    seed = 2
    spec = random_spec(seed, ITERATIONS)
    n = len(spec["landmarks"])
    maps = [build_map(_spec_with_landmarks(seed, range(k))) for k in (2, n // 2, n)]
    s = maps[0].diagonal / CELLS
    for fov in (60.0, 180.0):
        covs = [perception.heading_coverage(m, fov, spacing=s) for m in maps]
        for small, big in zip(covs, covs[1:], strict=False):
            assert np.array_equal(small.points, big.points)  # the grid does not depend on the tags
            assert np.all(small.some <= big.some) and np.all(small.every <= big.every)
            assert small.fraction_some <= big.fraction_some and small.fraction_every <= big.fraction_every
    full = maps[-1]
    narrow = perception.heading_coverage(full, 60.0, spacing=s)
    wide = perception.heading_coverage(full, 150.0, spacing=s)
    short = perception.heading_coverage(full, 60.0, 0.3 * full.diagonal, spacing=s)
    # a wider camera: every view of the narrow one lies in one of its views, and each of its views holds one
    assert np.all(narrow.some <= wide.some) and np.all(narrow.every <= wide.every)
    assert np.all(short.some <= narrow.some) and np.all(short.every <= narrow.every)
    assert np.all(short.reachable_count <= narrow.reachable_count)
    assert "range" in short.summary() and "range" not in narrow.summary()


@pytest.mark.parametrize("seed", [0, 4])
def test_at_360_degrees_some_heading_is_every_heading(seed):
    map_ = random_map(seed)
    cov = perception.heading_coverage(map_, 360.0, spacing=map_.diagonal / CELLS)
    assert np.array_equal(cov.some, cov.every) and cov.fraction_some == cov.fraction_every
    narrow = perception.heading_coverage(map_, 90.0, spacing=map_.diagonal / CELLS)
    assert np.all(narrow.some <= cov.some) and np.all(narrow.every <= cov.every)


def test_two_tags_far_apart_give_a_closed_form():
    """Two tags: some heading works where both are in sight and 2° ≤ their angle ≤ min(fov, 178°); every, nowhere."""
    spec = random_spec(1, ITERATIONS)
    xmin, ymin, xmax, ymax = spec["bounds"]
    spec["landmarks"] = [[xmin, ymin], [xmax, ymax]]  # two opposite corners
    map_ = build_map(spec)
    s = map_.diagonal / CELLS
    space = FreeSpace.from_map(map_)
    for fov in (60.0, 120.0, 360.0):
        cov = perception.heading_coverage(map_, fov, spacing=s)
        x = cov.points
        d = map_.landmarks[None] - x[:, None]
        both = np.all(
            space.visible(np.repeat(x, 2, axis=0), np.tile(map_.landmarks, (len(x), 1))).reshape(-1, 2), axis=1
        )
        u = d / np.linalg.norm(d, axis=2)[..., None]
        angle = np.degrees(np.arccos(np.clip(np.sum(u[:, 0] * u[:, 1], axis=1), -1, 1)))
        expected = both & (angle >= 2.0) & (angle <= min(fov, 178.0))
        clear = (np.abs(angle - 2.0) > 1e-6) & (np.abs(angle - fov) > 1e-6) & (np.abs(angle - 178.0) > 1e-6)
        assert np.array_equal(cov.some[clear], expected[clear]), fov
        if fov < 360:
            assert not cov.every.any()  # some heading looks away from both
        else:
            assert np.array_equal(cov.every, cov.some)
        assert np.all(cov.reachable_count[both] == 2) and np.all(cov.reachable_count[~both] < 2)
        assert fov < 90 or expected.any()  # from inside the box the corners are at least 90° apart


def test_heading_coverage_bounds_the_plans_rule():
    """The plan's heading is one heading: its rule holds only where some heading works, and wherever every does."""
    plan = random_plan(3)
    s = spacing_of(plan)
    for fov in (60.0, 120.0):
        along = perception.perception_coverage(plan, fov, 1.0, spacing=s)
        free = perception.heading_coverage(plan.map, fov, spacing=s)
        assert np.array_equal(free.points, along.points[along.in_free])  # the same grid over F
        holds, heading = along.holds[along.in_free], along.heading[along.in_free]
        assert np.all(holds <= free.some)
        assert np.all(free.every[~np.isnan(heading)] <= holds[~np.isnan(heading)])
    default = perception.heading_coverage(plan.map, 60.0)
    assert default.spacing == pytest.approx(plan.map.diagonal / perception.GRID_CELLS)


@pytest.mark.parametrize(
    "kwargs,field",
    [({"fov_deg": 0}, "fov"), ({"fov_deg": 400}, "fov"), ({"max_range": -1}, "range"), ({"max_range": 0}, "range"),
     ({"spacing": 0}, "spacing"), ({"min_spread_deg": 0}, "min_spread_deg")],
)  # fmt: skip
def test_heading_coverage_names_a_bad_parameter(kwargs, field):
    args = {"fov_deg": 60.0, **kwargs}
    with pytest.raises(InvalidParamsError) as info:
        perception.heading_coverage(random_map(0), **args)
    assert info.value.field == field
