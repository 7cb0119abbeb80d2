"""`bearnav tags --for live` (issue 22 item 5): tags until every cell is live (ALGORITHMS §12.5)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely
import yaml

from bearnav_cli import liveness, tags
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace

from .conftest import random_plan
from .handmade import hand_map, hand_plan
from .test_cli_errors import assert_one_line_error
from .test_cli_tags import _plan

#: A coarse liveness grid (fraction of D): the properties hold on any grid.
COARSE = 0.05
SEEDS = (1,)


def live_params(plan, **kwargs):
    return tags.Params(target="live", bearing_error_deg=0.5, resolution=COARSE * plan.map.diagonal, **kwargs)


@pytest.fixture(scope="module", params=SEEDS)
def proposal(request):
    plan = random_plan(request.param)
    return plan, tags.propose_live_tags(plan, live_params(plan))


def test_the_tags_make_cells_live_and_nothing_less_live(proposal):
    plan, p = proposal
    before, after = p.live_before, p.live_after
    assert after.live_fraction >= before.live_fraction and np.all(after.live >= before.live)
    assert np.all(after.eps_look <= before.eps_look + 1e-12)  # more tags, smaller looks
    assert p.count > 0 and before.n_live < len(before.live)  # at 0.5° these maps need tags
    assert after.n_live > before.n_live
    assert len(p.gains) == p.count and np.all(p.gains >= 0) and p.gains.sum() > 0
    assert p.target_reached == bool(np.all(after.live))


def test_live_after_is_the_liveness_of_the_map_with_the_tags(proposal):
    plan, p = proposal
    again = liveness.measure(
        plan, 0.5, 60.0, resolution=COARSE * plan.map.diagonal, landmarks=np.vstack([plan.map.landmarks, p.positions])
    )
    np.testing.assert_array_equal(again.live, p.live_after.live)
    np.testing.assert_allclose(again.eps_look, p.live_after.eps_look)


def test_the_tags_lie_on_boundaries_facing_free_space_a_tag_apart(proposal):
    plan, p = proposal
    space = FreeSpace.from_map(plan.map)
    boundary = shapely.union_all([shapely.box(*plan.map.bounds).exterior, space.raw_obstacles.boundary])
    assert np.all(shapely.distance(boundary, shapely.points(p.positions)) <= 1e-9 * plan.map.diagonal)
    ahead = p.positions + 1e-4 * plan.map.diagonal * p.normals
    assert not np.any(shapely.intersects_xy(space.raw_obstacles, ahead[:, 0], ahead[:, 1]))
    every = np.vstack([plan.map.landmarks, p.positions])
    gaps = np.hypot(*(every[:, None] - every[None]).transpose(2, 0, 1)) + np.eye(len(every)) * 1e9
    assert gaps[len(plan.map.landmarks) :].min() >= p.tag_width * (1 - 1e-9)


def test_where_no_tag_helps_is_reported_not_claimed(proposal):
    plan, p = proposal
    stuck = np.asarray(p.uncoverable).reshape(-1, 2)
    if len(stuck):
        assert not p.target_reached
    assert 0.0 <= p.coverable_fraction <= 1.0


def test_a_budget_is_kept():
    plan = random_plan(SEEDS[0])
    coarse = tags.Params(target="live", bearing_error_deg=0.5, resolution=0.1 * plan.map.diagonal, max_tags=1)
    p = tags.propose_live_tags(plan, coarse)
    assert p.count <= 1 and not p.target_reached


def test_a_paper_plan_has_no_liveness():
    with pytest.raises(InvalidParamsError) as info:
        tags.propose_live_tags(hand_plan(hand_map()), tags.Params(target="live"))
    assert info.value.field == "plan"


def test_an_unknown_target_is_refused():
    with pytest.raises(InvalidParamsError) as info:
        tags.Params(target="both")
    assert info.value.field == "target"


def test_cli_tags_for_live(cli, write_map, small_spec, tmp_path):
    plan = _plan(cli, write_map, small_spec, tmp_path)
    out = tmp_path / "live.yaml"
    result = cli(
        "tags", plan, "--for", "live", "--bearing-error-deg", "0.3", "--live-resolution", "0.3", "-o", out, "--json"
    )
    assert result.exit_code in (0, 1), result.output
    data = json.loads(result.output) if result.exit_code == 0 else None
    assert out.exists() and out.with_suffix(".png").exists()
    spec = yaml.safe_load(out.read_text())
    assert len(spec["landmarks"]) >= 2
    if data is not None:
        assert data["for"] == "live" and data["live_after"] >= data["live_before"]
        assert math.isclose(data["eta_deg"], 0.3)
    assert_one_line_error(cli("tags", plan, "--bearing-error-deg", "0.3", "-o", tmp_path / "x.yaml"), "--for live")
    assert_one_line_error(cli("tags", plan, "--for", "both", "-o", tmp_path / "x.yaml"), "--for")
    assert_one_line_error(
        cli("tags", plan, "--for", "live", "--bearing-error-deg", "50", "-o", tmp_path / "x.yaml"),
        "--bearing-error-deg",
    )
    assert not (tmp_path / "x.yaml").exists()
