"""Liveness (ALGORITHMS §12.5, §12.8): ``liveness.measure``, ``verify --live-fov``, ``plot --color-by live``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely

from bearnav_cli import liveness, verify
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.runtime import PlanArrays, bounded, estimate, least_rank_cell, look_bound, looking
from bearnav_cli.runtime.cell_policy import least_rank_cell_holding

from .conftest import random_plan
from .handmade import hand_map, hand_plan
from .test_hostile_common import small_plan

SEED = 1
#: A coarse grid (fraction of D) keeps the tests fast: the properties hold on any grid.
COARSE = 0.02


@pytest.fixture(scope="module")
def plan():
    return random_plan(SEED)


def measure(plan, eta_deg, fov_deg, **kwargs):
    return liveness.measure(plan, eta_deg, fov_deg, resolution=COARSE * plan.map.diagonal, **kwargs)


@pytest.fixture(scope="module")
def wide(plan):
    return measure(plan, 0.25, 360.0)


@pytest.fixture(scope="module")
def narrow(plan):
    return measure(plan, 0.25, 60.0)


def test_the_bound_of_a_row_is_one_look_bound(plan):
    arrays = PlanArrays.from_plan(plan)
    rng = np.random.default_rng(0)
    x0, y0, x1, y1 = arrays.bounds
    x = rng.uniform([x0, y0], [x1, y1], (60, 2))
    visible = looking.views(arrays, x, math.radians(90.0), math.inf, 4).reshape(-1, len(arrays.landmarks))
    x = np.repeat(x, 4, axis=0)
    eta = rng.uniform(1e-4, 0.02, len(x))
    mine = liveness.live_grid.bounds_of(arrays, x, visible, eta)
    box = estimate.axle_bounds(arrays)
    theirs = [
        look_bound.one_look_bound(x[i : i + 1], arrays.landmarks, visible[i : i + 1], eta[i], box, arrays.tol)[0]
        for i in range(len(x))
    ]
    np.testing.assert_allclose(mine, theirs, rtol=1e-9, atol=1e-9)


def test_shapes_and_json(plan, narrow):
    c = plan.cells.n_cells
    for name in ("eps_look", "eps_view", "margin", "live", "view_live", "cell_eta_star", "tolerance", "points"):
        assert getattr(narrow, name).shape == (c,), name
    assert np.all(narrow.points > 0)  # every cell has points, the small ones too
    assert narrow.grid.headings == liveness.HEADINGS and narrow.grid.step > 0 and narrow.grid.nu > 0
    data = json.loads(json.dumps(narrow.to_json(), allow_nan=False))
    assert len(data["per_cell"]["eps_look"]) == c and "not a proof" in data["measured"]
    assert "not a proof" in narrow.summary() and f"{narrow.grid.resolution:.3g}-map-unit grid" in narrow.summary()


def test_eps_look_decreases_with_eta(plan, narrow):
    smaller = measure(plan, 0.1, 60.0)
    assert np.all(smaller.eps_look <= narrow.eps_look + 1e-9)
    assert np.all(smaller.live >= narrow.live)  # the margin does not depend on η
    assert smaller.live_fraction >= narrow.live_fraction - 1e-12


def test_a_wider_camera_does_no_worse_in_one_view(narrow, wide):
    assert wide.grid.headings == 1
    assert np.all(wide.eps_view <= narrow.eps_view + 1e-9)
    assert np.all(wide.view_live >= narrow.view_live)
    np.testing.assert_array_equal(wide.eps_view, wide.eps_look)  # all around in one view


def test_a_look_ends_all_around_whatever_the_camera(narrow, wide):
    """The look of §12.5 ends with a turn all around: its bound is the 360° view's at any field of view,
    and no larger than the best single view's."""
    np.testing.assert_allclose(narrow.eps_look, wide.eps_look, rtol=1e-12)
    assert np.all(narrow.eps_look <= narrow.eps_view + 1e-12)
    assert np.all(narrow.live >= narrow.view_live) and narrow.live_fraction >= narrow.view_fraction
    assert narrow.view_fraction < narrow.live_fraction  # at 60° one view is not always enough


@pytest.mark.parametrize("worst", [False, True])
def test_a_turn_all_around_gives_a_set_within_the_look_bound(plan, worst):
    """A look simulated view by view (a 60° camera at 36 headings, every bearing within η, the set never
    grown while the robot turns in place) errs by no more than ``ε(x, S_all)``, the bound liveness uses."""
    arrays = PlanArrays.from_plan(plan)
    rng = np.random.default_rng(7)
    box = estimate.axle_bounds(arrays)
    x = rng.uniform(box[:2], box[2:], (200, 2))  # B_r: where an axle can be
    eta = math.radians(0.25)
    d = arrays.landmarks[None] - x[:, None]
    truth = np.arctan2(d[..., 1], d[..., 0])
    per_heading = looking.views(arrays, x, math.radians(60.0), math.inf, 36)  # (R, H, L)
    vertices, count = bounded.box(box, len(x))
    # at the worst, each bearing errs by ±η in every view (opposite signs in two views leave only a line)
    signs = rng.choice([-1.0, 1.0], truth.shape)
    for h in range(per_heading.shape[1]):
        error = signs * eta if worst else rng.uniform(-eta, eta, truth.shape)
        vertices, count = bounded.intersect_cones(
            vertices, count, arrays.landmarks, truth + error, per_heading[:, h], eta, arrays.tol
        )
    _, error = bounded.centre(vertices, count)
    all_around = looking.views(arrays, x, 2.0 * math.pi, math.inf, 1)[:, 0]
    np.testing.assert_array_equal(all_around, per_heading.any(axis=1))
    bound = liveness.live_grid.bounds_of(arrays, x, all_around, np.full(len(x), eta))
    seen = all_around.sum(axis=1) >= 2
    assert seen.sum() > 100
    assert np.all(error[seen] <= bound[seen] * (1 + 1e-7) + 1e-9)


@pytest.mark.parametrize(("lookahead", "worst"), [(0.0, False), (0.0, True), (0.1, True)])
def test_a_sure_start_finds_a_cell_that_holds_its_set_after_a_look(plan, narrow, lookahead, worst):
    """Where the grid calls a start sure (``LiveGrid.sure_start``), a look all around with every bearing within
    η (uniform, or at ±η) leaves a set that a cell holds whole, for a look-ahead robot at one of the headings it
    may turn to: §12.3 step 4 starts it. At the edge of D no start is sure (a robot without a look-ahead); most
    of D is."""
    if lookahead:
        plan = random_plan(4, lookahead)
        narrow = measure(plan, 0.25, 60.0)
    g, arrays = narrow.grid, PlanArrays.from_plan(plan)
    rng = np.random.default_rng(11)
    square = g.points[: g.grid_points]
    inside = square[least_rank_cell(arrays, square) >= 0]
    x = inside[rng.choice(len(inside), min(300, len(inside)), replace=False)]
    visible, eps = g.look(arrays.landmarks, x)
    sure = g.sure_start(x, eps)
    assert 0.5 < sure.mean() < 1.0 and 0.5 < narrow.start_fraction <= 1.0
    eta = g.eta
    d = arrays.landmarks[None] - x[:, None]
    error = (rng.choice([-1.0, 1.0], visible.shape) if worst else rng.uniform(-1.0, 1.0, visible.shape)) * eta
    vertices, count = bounded.intersect_cones(
        *bounded.box(estimate.axle_bounds(arrays), len(x)),
        arrays.landmarks,
        np.arctan2(d[..., 1], d[..., 0]) + error,
        visible,
        eta,
        arrays.tol,
    )
    x_hat, _ = bounded.centre(vertices, count)
    held = np.zeros(len(x), bool)
    for theta in np.linspace(0.0, 2.0 * math.pi, liveness.HEADINGS, endpoint=False) if lookahead else [0.0]:
        ahead = lookahead * np.array([math.cos(theta), math.sin(theta)])
        held |= least_rank_cell_holding(arrays, x_hat + ahead, vertices + ahead, count) >= 0
    assert np.all(held[sure]), int(np.count_nonzero(~held[sure]))
    if lookahead:  # a look-ahead robot turns its point away from the edge: its camera there may be sure
        return
    # the corners of the cells on the edge of D (pulled 0.1% inside) are never sure starts
    corners = g.points[g.grid_points :]
    edge = shapely.distance(shapely.union_all(g.polygons).boundary, shapely.points(corners)) < 1e-3 * plan.map.diagonal
    assert edge.sum() > 10
    assert not g.sure_start(corners[edge], g.look(arrays.landmarks, corners[edge])[1]).any()


@pytest.mark.parametrize("which", ["wide", "narrow"])
def test_live_means_below_the_margin_at_every_point(which, request):
    """A cell is live when every grid point's bound is below the margin there: what the certificate tolerates
    around the point (``runtime.tolerance``), never less than the cell's ``τ_c − κℓ − ν``; so every cell with
    ``eps_look < margin`` is live, and the margins at the points are larger somewhere."""
    lv = request.getfixturevalue(which)
    g = lv.grid
    np.testing.assert_allclose(lv.margin, lv.tolerance - g.drift * g.step - g.nu - g.swing)
    _, eps = g.look(g.arrays.landmarks)
    at_points = g.pair_margin(eps[g.pair_point])
    assert np.all(at_points >= lv.margin[g.pair_cell])
    assert np.any(at_points > 1.5 * lv.margin[g.pair_cell])
    short = np.bincount(g.pair_cell[eps[g.pair_point] >= at_points], minlength=len(lv.live)) > 0
    np.testing.assert_array_equal(lv.live, ~short)
    assert np.all(lv.live[lv.eps_look < lv.margin])


def test_eta_star_re_evaluated_is_live(plan, wide):
    eta = wide.cell_eta_star
    assert wide.eta_star == pytest.approx(eta.min())
    assert np.all(eta[wide.live] >= wide.grid.eta - 1e-15)  # a cell live at η has η*_c ≥ η
    assert np.all(eta[~wide.live] < wide.grid.eta)
    positive = eta[eta > 0]
    assert len(positive)
    # ε grows with η, so at the least positive η*_c every cell with η*_c > 0 is live; at the largest, its cell
    for value in (positive.min(), positive.max()):
        again = measure(plan, math.degrees(value) * (1 - 1e-9), 360.0)
        assert np.all(again.live[eta >= value])


def test_live_fraction_is_the_area_of_the_live_cells_the_policy_uses(plan, wide):
    assert 0.0 <= wide.live_fraction <= wide.cover_fraction <= 1.0
    from bearnav_cli.datatypes import active_regions, cell_polygons

    cells = plan.cells
    regions = active_regions(cell_polygons(cells), cells.cell_rank)
    domain = shapely.union_all(cell_polygons(cells)).area
    share = sum(regions[c].area for c in np.flatnonzero(wide.live)) / domain
    assert wide.live_fraction == pytest.approx(share, rel=1e-9, abs=1e-12)
    cover = shapely.union_all([cell_polygons(cells)[c] for c in np.flatnonzero(wide.live)]).area / domain
    assert wide.cover_fraction == pytest.approx(cover, rel=1e-9, abs=1e-12)


def test_a_camera_that_sees_nothing_is_never_live(plan):
    blind = measure(plan, 0.25, 360.0, max_range=1e-6)
    assert not blind.live.any() and blind.live_fraction == 0.0 and blind.eta_star == 0.0
    # K is all of B_r: the bound is the share of its diagonal a centre's error radius may reach
    x0, y0, x1, y1 = estimate.axle_bounds(PlanArrays.from_plan(plan))
    np.testing.assert_allclose(blind.eps_look, bounded.RADIUS_PER_WIDTH * math.hypot(x1 - x0, y1 - y0))


def test_no_margin_no_liveness(plan):
    slippery = measure(plan, 0.25, 360.0, nu=plan.map.diagonal)
    assert np.all(slippery.margin <= 0) and not slippery.live.any() and np.all(slippery.cell_eta_star == 0.0)


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"eta_deg": -0.1}, "eta_deg"), ({"eta_deg": 0.0}, "eta_deg"), ({"eta_deg": 45.0}, "eta_deg"),
    ({"fov_deg": 0.0}, "fov_deg"), ({"fov_deg": 400.0}, "fov_deg"), ({"kappa": 1.0}, "kappa"),
    ({"nu": -1.0}, "nu"), ({"resolution": 0.0}, "resolution"), ({"resolution": 1e-5}, "resolution"),
    ({"headings": 0}, "headings"), ({"max_range": 0.0}, "max_range"), ({"speed": 0.0}, "speed"),
])  # fmt: skip
def test_bad_input_is_refused(plan, kwargs, field):
    args = {"eta_deg": 0.25, "fov_deg": 60.0, **kwargs}
    with pytest.raises(InvalidParamsError) as info:
        liveness.measure(plan, **args)
    assert info.value.field == field


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"live_fov": 60.0, "bearing_error_deg": -1.0}, "bearing_error_deg"), ({"live_fov": 0.0}, "live_fov"),
    ({"live_fov": 60.0, "slip": 1.5}, "slip"), ({"live_fov": 60.0, "live_resolution": 0.0}, "live_resolution"),
    ({"slip": 0.1}, "slip"),  # only with live_fov
])  # fmt: skip
def test_verify_params_refuse_bad_liveness_options(kwargs, field):
    with pytest.raises(InvalidParamsError) as info:
        verify.Params(n_starts=0, **kwargs)
    assert info.value.field == field


def test_verify_reports_liveness_only_when_asked(plan):
    plain = verify.run(plan, verify.Params(n_starts=0))
    assert plain.liveness is None and "liveness" not in plain.to_json()
    report = verify.run(
        plan,
        verify.Params(n_starts=0, live_fov=360.0, bearing_error_deg=0.25, live_resolution=COARSE * plan.map.diagonal),
    )
    data = json.loads(json.dumps(report.to_json(), allow_nan=False))
    assert data["liveness"]["fov_deg"] == 360.0 and data["liveness"]["eta_deg"] == pytest.approx(0.25)
    assert any(note.startswith("liveness at a bearing error of 0.25°") for note in report.notes)
    assert report.failed == plain.failed  # a measurement never fails verify


def test_a_paper_plan_gets_a_note():
    report = verify.run(hand_plan(hand_map()), verify.Params(n_starts=0, live_fov=60.0))
    assert report.liveness is None and any("paper plan" in n for n in report.notes) and not report.failed


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    return small_plan(tmp_path_factory.mktemp("liveness"))


def test_verify_cli_json_has_liveness(cli, built):
    result = cli(
        "verify",
        built["plan"],
        "--starts",
        "0",
        "--live-fov",
        "60",
        "--bearing-error-deg",
        "0.3",
        "--live-resolution",
        "0.3",
        "--json",
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["liveness"]["fov_deg"] == 60.0 and data["liveness"]["headings"] == 36
    assert data["liveness"]["resolution"] == 0.3 and data["liveness"]["eta_deg"] == 0.3
    text = cli("verify", built["plan"], "--starts", "0", "--live-fov", "360", "--live-resolution", "0.3")
    assert text.exit_code == 0 and "a measurement, not a proof" in text.output


@pytest.mark.parametrize(("args", "words"), [
    (["--live-fov", "0"], "--live-fov"), (["--live-fov", "60", "--bearing-error-deg", "-1"], "--bearing-error-deg"),
    (["--slip", "0.1"], "--slip"), (["--live-fov", "60", "--live-resolution", "1e-9"], "--live-resolution"),
])  # fmt: skip
def test_verify_cli_refuses_bad_liveness_options(cli, built, args, words):
    result = cli("verify", built["plan"], "--starts", "0", *args)
    assert result.exit_code == 3 and words in result.output, result.output


def test_plot_color_by_live(cli, built, tmp_path):
    out = tmp_path / "live.png"
    result = cli("plot", built["plan"], "-o", out, "--color-by", "live", "--live-fov", "360")
    assert result.exit_code == 0, result.output
    assert out.stat().st_size > 0 and "of the certified area live" in result.output
    result = cli("plot", built["plan"], "-o", tmp_path / "x.png", "--live-fov", "60")
    assert result.exit_code == 3 and "--color-by live" in result.output
