"""Tag placement (issue 11 part 1): properties of the greedy proposal on random maps.

After proposing, the rule re-evaluated independently (``perception_coverage`` with the new
landmarks, and on a plan re-made from the map the map stage builds with them) holds on at least the
fraction the proposal reports; every proposed tag lies on a raw obstacle's boundary or a wall, faces
free space and keeps a tag's width from every other tag; the greedy never beats the LP lower bound
it certifies; the proposal is deterministic; a map stripped to two tags gets tags; a budget too
small is reported; re-planning with the new tags keeps the cells (ALGORITHMS Lemma 3).
"""

from __future__ import annotations

import copy
import functools
import logging
import math

import matplotlib.pyplot as plt
import numpy as np
import pytest
import shapely

from bearnav_cli import perception, pipeline, plot, tags
from bearnav_cli.datatypes import replace
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.stages import decompose, synthesize
from tests import mapgen
from tests.conftest import build_map
from tests.funnel_maps import ITERATIONS, random_spec

#: Evaluation grid D/CELLS: coarser than the default D/100 to keep the file fast.
CELLS = 60


@pytest.fixture(autouse=True)
def _quiet(caplog):
    caplog.set_level(logging.ERROR)  # random maps have blind spots: the map stage and decompose warn


@functools.cache
def spec_of(source: str, seed: int) -> dict:
    if source == "random":
        return random_spec(seed, ITERATIONS)
    return mapgen.generate(seed, source, params={"rrtstar": {"iterations": ITERATIONS, "seed": 0}}).spec


@functools.cache
def plan_of(source: str, seed: int, keep: int | None = None):
    spec = copy.deepcopy(spec_of(source, seed))
    if keep is not None:
        spec["landmarks"] = spec["landmarks"][:keep]
    return pipeline.compute(build_map(spec))["plan"]


def params_for(plan, **changes) -> tags.Params:
    return tags.Params(spacing=plan.map.diagonal / CELLS, **changes)


@functools.cache
def proposal_of(source: str, seed: int, keep: int | None = None, **changes):
    plan = plan_of(source, seed, keep)
    return tags.propose_tags(plan, params_for(plan, **changes))


MAPS = [("random", 0), ("random", 2), ("random", 5), ("rooms", 2)]


def on_boundary(map_, points: np.ndarray) -> np.ndarray:
    """On a wall of B, or on the boundary of the raw obstacles (own shapely test, to 10·tol)."""
    tol = 10 * map_.tol
    xmin, ymin, xmax, ymax = map_.bounds
    x, y = points[:, 0], points[:, 1]
    in_box = (x >= xmin) & (x <= xmax) & (y >= ymin) & (y <= ymax)
    wall = in_box & (
        (np.abs(x - xmin) <= tol) | (np.abs(x - xmax) <= tol) | (np.abs(y - ymin) <= tol) | (np.abs(y - ymax) <= tol)
    )
    raw = shapely.union_all([shapely.Polygon(p.exterior, p.holes) for p in map_.raw_obstacles])
    edge = shapely.distance(raw.boundary, shapely.points(points)) <= tol if not raw.is_empty else wall & False
    return in_box & (wall | edge)


# --------------------------------------------------------------------------- properties


@pytest.mark.parametrize("source,seed", MAPS, ids=[f"{s}-{k}" for s, k in MAPS])
def test_proposal_properties(source, seed):
    plan = plan_of(source, seed)
    prop = proposal_of(source, seed)
    map_ = plan.map
    n_d = int(prop.before.in_domain.sum())
    # the target: the rule holds at every coverable point of D
    assert prop.target_reached and "target reached" in prop.summary()
    assert prop.after.fraction_domain >= prop.coverable_fraction - 1e-12
    assert prop.after.fraction_domain >= prop.before.fraction_domain
    assert len(prop.uncoverable) == round((1 - prop.coverable_fraction) * n_d)
    # re-evaluated independently with the new landmarks: at least what the proposal reports
    again = perception.perception_coverage(
        plan, prop.params.fov_deg, prop.params.noise_deg, spacing=prop.params.spacing, landmarks=prop.landmarks
    )
    assert again.fraction_domain >= prop.after.fraction_domain
    assert again.fraction_free >= prop.after.fraction_free
    # where the tags go: on a raw obstacle's boundary or a wall, facing free space
    assert prop.count > 0 and prop.positions.shape == (prop.count, 2) and len(prop.gains) == prop.count
    assert np.all(on_boundary(map_, prop.positions))
    assert np.allclose(np.linalg.norm(prop.normals, axis=1), 1.0)
    front = prop.positions + 1e-4 * map_.diagonal * prop.normals
    raw = shapely.union_all([shapely.Polygon(p.exterior, p.holes) for p in map_.raw_obstacles])
    assert not shapely.intersects_xy(raw, front[:, 0], front[:, 1]).any()
    # a tag's width from every other tag, old or new
    everything = np.vstack([map_.landmarks, prop.positions])
    gap = np.linalg.norm(everything[:, None] - prop.positions[None], axis=2)
    gap[len(map_.landmarks) + np.arange(prop.count), np.arange(prop.count)] = np.inf
    assert gap.min() >= prop.tag_width * (1 - 1e-12)
    assert prop.tag_width == pytest.approx(tags.TAG_WIDTH_FRACTION * map_.diagonal)
    # the greedy against the bound it certifies
    assert 0 <= prop.lower_bound <= prop.count
    assert prop.lp_objective <= prop.count + 1e-9 and prop.lower_bound == math.ceil(prop.lp_objective - 1e-6)
    assert prop.count <= prop.stats["greedy"]  # pruning only removes
    # ids: new, distinct, continuing the map's numbering
    assert len(set(prop.ids)) == prop.count and not set(prop.ids) & set(map_.landmark_ids)
    # the map stage accepts the new map; existing tags untouched
    spec = spec_of(source, seed)
    with_tags = tags.map_spec_with_tags(spec, prop)
    assert with_tags["landmarks"][: len(spec["landmarks"])] == spec["landmarks"]
    new_map = build_map(with_tags)
    assert new_map.landmark_ids == prop.landmark_ids
    assert np.array_equal(new_map.landmarks, prop.landmarks)


def test_replanning_with_the_tags_keeps_the_cells():
    """ALGORITHMS Lemma 3: the fields do not depend on the landmarks, so only the gains change."""
    spec = spec_of("random", 1)
    map_ = build_map(spec)
    tree = pipeline.compute(map_, through="simplify")["simplified"]
    params = pipeline.resolve_params("decompose", map_.params)
    cells = decompose.run(tree, params)
    plan = synthesize.run(cells, pipeline.resolve_params("synthesize", map_.params))
    prop = tags.propose_tags(plan, params_for(plan))
    assert prop.count > 0
    new_map = build_map(tags.map_spec_with_tags(spec, prop))
    cells2 = decompose.run(replace(tree, map=new_map), params)
    for key in (
        "cell_vertices",
        "cell_vertex_offsets",
        "cell_A",
        "cell_b",
        "cell_row_offsets",
        "exit_point",
        "exit_dir",
        "cell_rank",
        "cell_node",
    ):
        assert np.array_equal(getattr(cells, key), getattr(cells2, key)), key
    plan2 = synthesize.run(cells2, pipeline.resolve_params("synthesize", new_map.params))
    # the re-made plan, with the new map's own tags, keeps what the proposal reported (to a grid point)
    again = perception.perception_coverage(
        plan2, prop.params.fov_deg, prop.params.noise_deg, spacing=prop.params.spacing
    )
    assert again.landmark_ids == prop.landmark_ids
    assert again.fraction_domain >= prop.after.fraction_domain - 1.0 / again.in_domain.sum()


def test_proposals_are_deterministic():
    plan = plan_of("random", 0)
    first = proposal_of("random", 0)
    second = tags.propose_tags(plan, params_for(plan))
    assert first.ids == second.ids and np.array_equal(first.positions, second.positions)
    assert first.lower_bound == second.lower_bound and np.array_equal(first.gains, second.gains)
    assert np.array_equal(first.after.holds, second.after.holds)


def test_a_map_stripped_to_two_tags_gets_tags():
    plan = plan_of("random", 5, keep=2)
    assert len(plan.map.landmarks) == 2
    prop = proposal_of("random", 5, keep=2)
    assert prop.count >= 2 and prop.target_reached
    assert prop.after.fraction_domain > prop.before.fraction_domain
    assert prop.ids[0] not in plan.map.landmark_ids
    # the bound: a coverable point that sees neither of the two needs two new tags
    blind = prop.before.points[prop.before.in_domain & (prop.before.visible_count == 0)]
    stuck = {tuple(p) for p in prop.uncoverable}
    if any(tuple(p) not in stuck for p in blind):
        assert prop.lower_bound >= 2


def test_too_small_a_budget_is_reported():
    full = proposal_of("random", 2)
    assert full.count >= 3
    short = proposal_of("random", 2, max_tags=1)
    assert short.count == 1 and not short.target_reached
    assert "NOT reached" in short.summary()
    assert short.before.fraction_domain <= short.after.fraction_domain < full.after.fraction_domain
    none = proposal_of("random", 2, max_tags=0)
    assert none.count == 0 and not none.target_reached and none.positions.shape == (0, 2)
    assert none.after.fraction_domain == none.before.fraction_domain
    assert none.lower_bound == full.lower_bound  # the bound does not depend on the budget


def test_error_target_needs_more_tags():
    plain = proposal_of("random", 0)
    target = float(np.median(plain.after.predicted_error[plain.after.in_domain & plain.after.usable]))
    strict = proposal_of("random", 0, error_target=target)
    assert strict.count >= plain.count
    assert np.all(strict.after.predicted_error[strict.after.holds] <= target)
    assert strict.after.fraction_domain >= strict.coverable_fraction - 1e-12 or not strict.target_reached


@pytest.mark.parametrize(
    "kwargs,field",
    [({"fov_deg": 0}, "fov"), ({"fov_deg": 400}, "fov"), ({"noise_deg": -1}, "noise_deg"),
     ({"max_range": -2}, "range"), ({"max_tags": -1}, "max_tags"), ({"max_tags": 1.5}, "max_tags"),
     ({"max_tags": True}, "max_tags"), ({"tag_width": 0}, "tag_width"), ({"error_target": 0}, "error_target"),
     ({"spacing": -1}, "spacing")],
)  # fmt: skip
def test_bad_parameters_name_their_field(kwargs, field):
    with pytest.raises(InvalidParamsError) as info:
        tags.Params(**kwargs)
    assert info.value.field == field
    assert "\n" not in str(info.value) and field in str(info.value)


def test_new_ids_never_clash():
    assert tags.new_tag_ids(("tag0", "tag5", "door"), 2) == ("tag6", "tag7")
    assert tags.new_tag_ids(("0", "1", "7"), 2) == ("8", "9")
    assert tags.new_tag_ids((), 1) == ("tag0",)
    assert tags.new_tag_ids(("r0", "r1", "tag1x"), 1) == ("tag0",)


def test_map_spec_with_tags_keeps_the_spec():
    prop = proposal_of("random", 0)
    spec = spec_of("random", 0)
    before = copy.deepcopy(spec)
    out = tags.map_spec_with_tags(spec, prop)
    assert spec == before  # not changed in place
    assert {k: v for k, v in out.items() if k != "landmarks"} == {k: v for k, v in spec.items() if k != "landmarks"}
    added = out["landmarks"][len(spec["landmarks"]) :]
    assert [a["id"] for a in added] == list(prop.ids)
    assert all(isinstance(v, float) for a in added for v in a["position"])
    clash = {**spec, "landmarks": [*spec["landmarks"], {"id": prop.ids[0], "position": [0.0, 0.0]}]}
    with pytest.raises(InvalidParamsError) as info:
        tags.map_spec_with_tags(clash, prop)
    assert info.value.field == "landmarks"


def test_lower_bound_of_a_known_lp():
    # two points each needing two tags; they see candidates {0, 1} and {1, 2}: x = (1, 1, 1)
    seen = np.array([[1, 1, 0], [0, 1, 1], [1, 1, 1]], bool)
    assert tags.cover._lower_bound(seen, np.array([2, 2, 0])) == (3, pytest.approx(3.0))
    # one tag each: the shared candidate suffices
    assert tags.cover._lower_bound(seen, np.array([1, 1, 1]))[0] == 1
    assert tags.cover._lower_bound(seen, np.zeros(3, np.int64)) == (0, 0.0)


def test_figure_shows_where_to_glue_the_tags():
    plan = plan_of("random", 2)
    prop = proposal_of("random", 2, max_tags=2)
    fig, ax = plt.subplots()
    plot.plot_map(ax, plan.map, landmarks=False, labels=False)
    plot.plot_tags(ax, prop)
    by_gid = {c.get_gid(): c for c in ax.collections if c.get_gid()}
    assert len(by_gid["proposed-tags"].get_offsets()) == prop.count == 2
    assert np.allclose(by_gid["proposed-tags"].get_offsets(), prop.positions)
    assert len(by_gid["existing-tags"].get_offsets()) == len(plan.map.landmarks)
    assert len(by_gid["perception-fail-domain"].get_offsets()) == len(prop.after.failing_domain)
    names = [t.get_text() for t in ax.texts if t.get_gid() == "proposed-tag-label"]
    assert names == list(prop.ids)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert plot.PROPOSED_TAGS_LABEL.format(prop.count) in labels
    assert plot.EXISTING_TAGS_LABEL.format(len(plan.map.landmarks)) in labels
    assert "map units" in ax.get_xlabel() and "map units" in ax.get_ylabel()
    plt.close(fig)


def test_the_tags_figure_reads_well():
    """issue 23 item 5: a legend entry for every mark, no colliding ids, the palette's colours, and a title
    with the camera; every proposed id is written, existing ids where they fit."""
    from tests.test_plot import assert_reads_well

    plan = plan_of("random", 2)
    prop = proposal_of("random", 2, max_tags=2)
    fig = plot.tags_figure(prop, plan.map)
    ax = fig.axes[0]
    assert_reads_well(fig)
    assert [t.get_text() for t in ax.texts if t.get_gid() == "proposed-tag-label"] == list(prop.ids)
    existing = [t.get_text() for t in ax.texts if t.get_gid() == "existing-tag-label"]
    assert existing and set(existing) <= set(plan.map.landmark_ids)
    title = ax.get_title()
    assert title.startswith(f"{plan.map.name} — tags: where to glue 2 new tags")
    assert f"{prop.before.fov_deg:g}° camera, {prop.before.noise_deg:g}° noise" in title
    plt.close(fig)
