"""``bearnav verify`` (ALGORITHMS §8): recomputed certificates, geometry, Monte Carlo, shortest routes."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from bearnav_cli import routes, verify, verify_checks
from bearnav_cli.datatypes import CellFlag, CellStatus, Outcome, Plan, replace
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.stages import simulate

from .conftest import EXAMPLE_MAPS, REPO, example_plan
from .handmade import cell_polygons, first_plan_cells, hand_map, hand_plan

FAST = verify.Params(n_starts=40, seed=3)


@pytest.fixture(scope="module")
def chain() -> Plan:
    return hand_plan(hand_map())


def random_tree_plan(seed: int, n: int = 10) -> Plan:
    rng = np.random.default_rng(seed)
    nodes = rng.uniform((0.5, 0.5), (9.5, 7.5), (n, 2))
    parent = np.array([-1] + [int(rng.integers(0, i)) for i in range(1, n)])
    map_ = hand_map(goal=nodes[0])
    return hand_plan(map_, nodes, parent, polygons=cell_polygons(nodes, parent, map_.bounds))


def corrupt(plan: Plan, cell: int, factor: float = 3.0) -> Plan:
    gain = plan.gain.copy()
    gain[cell] *= factor
    return replace(plan, gain=gain)


def test_a_sound_plan_passes(chain):
    report = verify.run(chain, FAST)
    assert not report.failed, report.reasons
    assert report.certificates.violation.max() <= 1e-12
    assert report.geometry.ok and report.geometry.uncovered_area <= 1e-12
    assert report.success_rate == 1.0 and report.outcome_counts["collision"] == 0
    assert report.left_cell_total == 0 and report.left_cell_fraction == 0.0
    # straight lines from the goal's own region score 1; runs through node 1 score more
    assert 1.0 <= report.ratio_straight < 1.5 and report.ratio_route == pytest.approx(report.ratio_straight)
    text = json.dumps(report.to_json(), allow_nan=False)
    assert '"failed": false' in text
    assert report.summary() == "3/3 cells certified, coverage ok, 40/40 runs reached the goal"


def test_a_corrupted_gain_violates_in_that_cell_only():
    plan = random_tree_plan(11)
    base = verify_checks.certificates(plan)
    assert base.violation.max() <= 1e-12 and base.margin_error.max() <= 1e-12
    for cell in range(plan.cells.n_cells):
        cert = verify_checks.certificates(corrupt(plan, cell))
        assert cert.violation[cell] > 1e-3, cell
        others = np.delete(cert.violation, cell)
        assert others.max() <= 1e-12, cell
    report = verify.run(corrupt(plan, 4), verify.Params(n_starts=0))
    assert report.failed and list(report.false_certificates) == [4]
    assert any("fail the recomputation: 4 (violation" in r for r in report.reasons)


def test_the_recomputed_values_match_the_definitions(chain):
    cert = verify_checks.certificates(chain)
    # cell 2 = [5,10]×[0,8], u = (1/7)((5,1) − x), z = (1,0), c_v = 1/14: the CLF value is
    # max (c_v − 1/7)·V = 0 (on the exit face); the input value max ‖u‖∞ − 1 = 0 at (10, 8)
    assert cert.value_v[2] == pytest.approx(0.0, abs=1e-12)
    assert cert.value_u[2] == pytest.approx(0.0, abs=1e-12)
    assert math.isnan(cert.value_h[2]) and math.isnan(cert.value_v[0])
    assert cert.goal_error[0] <= 1e-12
    # a barrier row h(x) = y − 0.5 in cell 2 (safe above y = 0.5): −(n·u + c_h h) at each vertex
    rows = {2: (np.array([[0.0, 1.0]]), np.array([-0.5]))}
    plan = hand_plan(hand_map(), barriers=rows)
    verts = plan.cells.vertices(2)
    u = (np.array([5.0, 1.0]) - verts) / 7.0
    expected = np.max(-(u[:, 1] + plan.c_h[2] * (verts[:, 1] - 0.5)))
    assert verify_checks.certificates(plan).value_h[2] == pytest.approx(expected, abs=1e-12)
    assert plan.margin_h[2] == pytest.approx(expected)  # the builder's margin, computed the same way
    assert expected > 0 and verify.run(plan, verify.Params(n_starts=0)).uncertified == [2]


def test_false_margins_uncertified_cells_and_goal_fields_fail(chain):
    wrong_margin = replace(chain, margin_v=np.array([np.nan, -0.5, 0.0]))
    report = verify.run(wrong_margin, verify.Params(n_starts=0))
    assert report.failed and "stored margins off by 0.5" in report.false_certificates[1]

    status = chain.status.copy()
    status[2] = 2
    report = verify.run(replace(chain, status=status), verify.Params(n_starts=0))
    assert report.failed and report.uncertified == [2] and not report.false_certificates

    # the goal cell with a certified-looking but wrong field: u = 0.1·(g − x) + (0.01, 0)
    gain = chain.gain.copy()
    from .handmade import gain_for

    gain[0] = gain_for(chain.landmarks, chain.c_v[0] * np.eye(2), chain.c_v[0] * chain.map.goal + [0.01, 0.0])
    report = verify.run(replace(chain, gain=gain), verify.Params(n_starts=0))
    assert report.failed and "field is not c·(g − x)" in report.false_certificates[0]


def test_removing_a_cell_makes_coverage_fail(chain):
    plan = first_plan_cells(chain, 2)
    report = verify.run(plan, FAST)
    assert report.failed and not report.geometry.coverage_ok
    assert report.geometry.uncovered_area == pytest.approx(3.0 * 8.0)  # cell 2 alone held 7 ≤ x ≤ 10
    assert any("uncovered" in r for r in report.reasons)
    assert report.rollouts is None and report.skipped.startswith("malformed plan")


def test_geometry_failures_are_reported():
    # a wall across the edge 1 → 0 (y = 1 between x = 2 and 3) blocks it
    map_ = hand_map(obstacles=[[[2.4, 0.5], [2.6, 0.5], [2.6, 1.5], [2.4, 1.5]]])
    rows = {2: (np.array([[-2.0, 0.0]]), np.array([20.0]))}  # h = 20 − 2x holds, but is not unit-norm
    plan = hand_plan(map_, barriers=rows)
    report = verify.run(plan, verify.Params(n_starts=0), tree_samples=np.array([[2.5, 1.0]]))
    g = report.geometry
    assert g.blocked_edges == (1,) and g.bad_barriers == (2,) and g.samples_unchanged is False
    assert g.coverage_ok and not g.cells_outside_bounds and not g.edges_outside_cell
    assert report.failed and len(report.reasons) == 3
    same = verify.run(plan, verify.Params(n_starts=0), tree_samples=np.zeros((0, 2)))
    assert same.geometry.samples_unchanged is True
    # the same rows in a cell that claims no certificate: reported as not certified, nothing refuted
    status = plan.status.copy()
    status[2] = CellStatus.NOT_CERTIFIED
    claimless = verify.run(replace(plan, status=status), verify.Params(n_starts=0))
    assert claimless.geometry.bad_barriers == () and claimless.uncertified == [2] and claimless.failed


def test_flagged_cells_and_bearing_constants(chain):
    flags = chain.cells.cell_flags.copy()
    flags[1] = CellFlag.FEW_LANDMARKS | CellFlag.BLIND_SPOT
    cells = replace(chain.cells, cell_flags=flags, s_min=np.array([0.0, 2.0, 4.0]))
    plan = replace(chain, cells=cells)
    report = verify.run(plan, verify.Params(n_starts=0))
    assert report.flagged["few_landmarks"] == [1] and report.flagged["blind_spot"] == [1]
    assert report.flagged["degenerate_risk"] == []
    # the unhashed manifest stats say nothing: only the hashed bits count
    for stats in ({"degenerate_risk": [2]}, {"flagged": {"degenerate_risk": [0]}}):
        assert verify_checks.flagged_cells(replace(plan, stats=stats)) == verify_checks.flagged_cells(plan)
    # c̃_v = c_v/s_max, c̃_h = c_h/s_min (∞ at s_min = 0, NaN without barrier rows)
    assert np.allclose(report.c_v_tilde, chain.c_v / 20.0)
    assert np.isnan(report.c_h_tilde).all() and np.isnan(report.c_h_over_s_max).all()
    with_rows = hand_plan(
        hand_map(),
        barriers={0: (np.array([[1.0, 0.0]]), np.array([1.0])), 1: (np.array([[0.0, 1.0]]), np.array([0.0]))},
    )
    with_rows = replace(with_rows, cells=replace(with_rows.cells, s_min=np.array([0.0, 2.0, 4.0])))
    report = verify.run(with_rows, verify.Params(n_starts=0))
    assert report.c_h_tilde[0] == math.inf and report.c_h_tilde[1] == pytest.approx(with_rows.c_h[1] / 2.0)
    assert report.c_h_over_s_max[1] == pytest.approx(with_rows.c_h[1] / 20.0)
    assert json.loads(json.dumps(report.to_json(), allow_nan=False))["cells"]["per_cell"]["c_h_tilde"][0] is None


def test_min_success_decides_on_the_monte_carlo():
    # cell 1 pushes +x: robots bounce between cells 1 and 2 and never arrive
    plan = hand_plan(hand_map(), fields={1: (np.zeros((2, 2)), np.array([1.0, 0.0]))})
    status = plan.status.copy()
    status[1] = 0  # claims a certificate it does not have
    report = verify.run(replace(plan, status=status), verify.Params(n_starts=30, min_success=0.9))
    assert report.success_rate < 0.9 and report.left_cell_total > 0
    assert any("below --min-success" in r for r in report.reasons)
    assert 1 in report.false_certificates


def test_starts_are_seeded_strictly_free_and_in_the_goal_component():
    walls = [[[4.0, 0.0], [4.5, 0.0], [4.5, 8.0], [4.0, 8.0]], [[6, 3], [7, 3], [7, 4], [6, 4]]]
    space = FreeSpace.from_map(hand_map(obstacles=walls))
    a = routes.sample_starts(space, np.array([1.0, 1.0]), 300, np.random.default_rng(5))
    b = routes.sample_starts(space, np.array([1.0, 1.0]), 300, np.random.default_rng(5))
    assert a.shape == (300, 2) and np.array_equal(a, b)
    assert space.points_strictly_free(a).all() and np.all(a[:, 0] < 4.0)  # the wall cuts x > 4.5 off
    assert routes.sample_starts(space, np.array([1.0, 1.0]), 0, np.random.default_rng(5)).shape == (0, 2)


def test_route_around_one_square_matches_the_hand_value():
    space = FreeSpace.from_map(hand_map(obstacles=[[[4, 3], [6, 3], [6, 5], [4, 5]]]))
    goal = np.array([8.0, 4.0])
    starts = np.array([[2.0, 4.0], [2.0, 6.0], [5.0, 1.0], [5.0, 4.0], [2.0, 3.0]])
    lengths = routes.route_lengths(space, goal, starts)
    # around a corner each: (2,4) → (4,5) → (6,5) → (8,4); (2,6) sees the goal past (6,5)
    assert lengths[0] == pytest.approx(2 * math.sqrt(5) + 2, abs=1e-12)
    assert lengths[1] == pytest.approx(math.hypot(4, 1) + math.hypot(2, 1), abs=1e-12)
    assert lengths[2] == pytest.approx(math.hypot(3, 3), abs=1e-12)  # in sight: straight
    assert lengths[3] == math.inf  # inside the obstacle
    # along the bottom edge y = 3 (touching O is allowed for the route): 2 + 2 + hypot(2, 1)
    assert lengths[4] == pytest.approx(2 + 2 + math.hypot(2, 1), abs=1e-12)


def test_routes_beyond_the_corner_limit_are_nan_and_noted(monkeypatch):
    # issue 27 item 6: 2,000 discs have 200,000+ corners; the all-pairs graph asked for 44 GiB
    from bearnav_cli import routes

    space = FreeSpace.from_map(hand_map(obstacles=[[[4, 3], [6, 3], [6, 5], [4, 5]]]))
    goal, starts = np.array([8.0, 4.0]), np.array([[2.0, 4.0], [2.0, 6.0]])
    assert np.isfinite(routes.route_lengths(space, goal, starts)).all()
    monkeypatch.setattr(routes, "MAX_ROUTE_VERTICES", 4)  # the box and the square have 8 corners
    assert np.isnan(routes.route_lengths(space, goal, starts)).all()


def test_route_through_two_staggered_walls():
    """Over the first wall's top end, under the second's bottom end: four bends, by hand."""
    walls = [[[3, 0], [3.5, 0], [3.5, 6], [3, 6]], [[6, 2], [6.5, 2], [6.5, 8], [6, 8]]]
    space = FreeSpace.from_map(hand_map(obstacles=walls))
    start, goal = np.array([1.0, 1.0]), np.array([9.0, 7.0])
    expected = math.hypot(2, 5) + 0.5 + math.hypot(2.5, 4) + 0.5 + math.hypot(2.5, 5)
    assert routes.route_lengths(space, goal, start[None])[0] == pytest.approx(expected, abs=1e-12)


def test_params_are_checked():
    for kwargs, name in (
        ({"n_starts": -1}, "n_starts"),
        ({"min_success": 1.5}, "min_success"),
        ({"speed": 0.0}, "speed"),
    ):
        with pytest.raises(InvalidParamsError) as err:
            verify.Params(**kwargs)
        assert err.value.field == name


# --------------------------------------------------------------------------- end to end


def kitchen_stages():
    from bearnav_cli.stages import decompose, map_, rrtstar, simplify, synthesize

    spec = yaml.safe_load(Path(REPO / "maps" / "kitchen.yaml").read_text())
    source = map_.MapSource(spec=spec, file="kitchen.yaml", sha256="0")
    map_obj = map_.run(source)
    tree = rrtstar.run(map_obj, rrtstar.Params(**spec["params"]["rrtstar"]))
    plan = synthesize.run(decompose.run(simplify.run(tree)))
    return tree, plan


@pytest.fixture(scope="module")
def kitchen():
    tree, plan = kitchen_stages()
    return tree, plan, verify.run(plan, verify.Params(n_starts=200), tree_samples=tree.collision_samples)


def test_kitchen_plan_is_certified_and_covers_the_map(kitchen):
    tree, plan, report = kitchen
    assert not report.uncertified
    assert not report.false_certificates
    certified = np.isin(plan.status, (0, 1, 4))
    assert certified.all()
    assert report.certificates.violation.max() <= 1e-7
    assert report.geometry.ok, report.geometry
    for name, cells in report.flagged.items():
        bits = np.flatnonzero(plan.cells.cell_flags & CellFlag[name.upper()]).tolist()
        assert cells == bits, name
    assert json.dumps(report.to_json(), allow_nan=False)
    # the Monte-Carlo figures are consistent
    assert sum(report.outcome_counts.values()) == 200
    routes, straight = report.route, report.straight
    assert np.all(routes >= straight - 1e-9)
    done = report.rollouts.outcome == Outcome.SUCCESS
    finish = np.hypot(*(report.rollouts.final_position[done] - plan.map.goal).T)
    assert np.all(report.rollouts.path_length[done] + finish >= routes[done] - 1e-9)  # routes are shortest


@pytest.fixture(scope="module", params=EXAMPLE_MAPS)
def example(request, tmp_path_factory):
    """Every example map planned by the pipeline (as `bearnav plan` does) and verified from 200 random starts."""
    from bearnav_cli import artifacts, pipeline

    path = example_plan(request.param, tmp_path_factory)
    plan = artifacts.load(path).artifact
    tree = artifacts.load(path.with_name("tree.npz")).artifact
    # at the map's own speed, as `bearnav verify` drives it (the paper maps' units are not metres)
    speed = pipeline.resolve_params("simulate", plan.map.params).speed
    return plan, verify.run(plan, verify.Params(n_starts=200, speed=speed), tree_samples=tree.collision_samples)


def test_every_example_map_is_certified_and_reaches_the_goal_from_random_starts(example):
    """ALGORITHMS §8 on every example map: every cell certified, full coverage, no false certificate,
    at least 99% of 200 uniform random starts reach the goal and none collides."""
    plan, report = example
    assert np.isin(plan.status[1:], (0, 1)).all() and plan.status[0] == 4
    assert not report.false_certificates and report.geometry.ok
    assert report.outcome_counts["collision"] == 0, report.summary()
    assert report.success_rate >= 0.99, report.summary()


def test_every_example_map_reaches_the_goal_from_its_own_starts(example):
    """DESIGN §8 end to end: every default start of every example map reaches the goal."""
    from bearnav_cli import pipeline

    plan, _ = example
    params = pipeline.resolve_params("simulate", plan.map.params, {"record_trajectories": False})
    runs = simulate.rollout(plan, plan.map.starts, params)
    assert (runs.outcome == Outcome.SUCCESS).all(), runs.counts()


# --------------------------------------------------------------------------- verify --dynamics unicycle


def _small_funnel_plan() -> Plan:
    from bearnav_cli import pipeline
    from tests.conftest import build_map
    from tests.funnel_maps import ITERATIONS, random_spec

    return pipeline.compute(build_map(random_spec(2, ITERATIONS, 0)))["plan"]


def test_the_unicycle_closed_loop_from_the_certified_domain_has_no_collision_and_no_breach():
    """``dynamics="unicycle"`` on a plan with a look-ahead (displacements, exact motion, ALGORITHMS §12.6):
    every run from D reaches the goal, every one of its steps is certified and every true position of
    its look-ahead point lies in some cell of D."""
    from tests.test_lookahead import lookahead_plan

    plan = lookahead_plan()
    report = verify.run(plan, verify.Params(n_starts=300, dynamics="unicycle"))
    assert report.rollouts is not None and report.in_domain.sum() > 200
    assert report.breaches is not None and not report.breaches.any()
    from_d = report.rollouts.outcome[report.in_domain]
    assert np.all(from_d == Outcome.SUCCESS) and report.success_in_domain == 1.0
    # starts outside D are uncertified: with cells up to the walls (§12.7) they lie within a hair of
    # an obstacle, so they are few; their runs are measured, not asserted
    assert (~report.in_domain).sum() <= 0.05 * len(report.in_domain)
    assert not report.failed, report.reasons
    assert report.to_json()["monte_carlo"]["breaches"] == 0 and "0 left the certified area" in report.summary()
    with pytest.raises(InvalidParamsError) as err:
        verify.Params(dynamics="car")
    assert err.value.field == "dynamics"


def test_a_breach_from_the_certified_domain_fails_verify(monkeypatch):
    """A run from D with a true position outside every cell is a breach, and a breach fails verify (here
    the domain test is made to say "outside" for every step)."""
    plan = _small_funnel_plan()
    import types

    outside = lambda arrays, x: np.full(len(x), -1)  # noqa: E731
    fake = types.SimpleNamespace(DYNAMICS=verify.runtime.DYNAMICS, least_rank_cell=outside)
    monkeypatch.setattr(verify, "runtime", fake)  # verify's own domain test only (simulate keeps the real one)
    report = verify.run(plan, verify.Params(n_starts=20, dynamics="unicycle"))
    assert report.breaches.sum() == report.in_domain.sum() > 0
    assert report.failed and any("breached" in why for why in report.reasons)


@pytest.mark.parametrize("from_domain", [True, False])
def test_a_collision_fails_verify_from_the_certified_domain_and_is_a_note_from_outside(monkeypatch, from_domain):
    """The theorem covers the starts in D: a collision from there fails verify; one from outside D, where
    the runtime's rules are not certified, is measured and reported as a note."""
    from bearnav_cli.stages import simulate

    plan = _small_funnel_plan()
    real = simulate.rollout

    def one_collision(*args, **kwargs):
        runs = real(*args, **kwargs)
        pick = np.flatnonzero(runs.start_in_domain == from_domain)
        if not len(pick):
            pytest.skip("no start on that side of D")
        outcome = np.array(runs.outcome)
        outcome[pick[0]] = Outcome.COLLISION
        return replace(runs, outcome=outcome)

    monkeypatch.setattr(simulate, "rollout", one_collision)
    report = verify.run(plan, verify.Params(n_starts=200))
    assert report.failed == from_domain
    said = [why for why in (report.reasons if from_domain else report.notes) if "collided" in why]
    assert len(said) == 1 and ("outside the certified domain" in said[0]) != from_domain


@pytest.mark.parametrize("seed", [1, 2])
def test_rows_widened_behind_the_polygon_fail_verify_in_that_cell(seed):
    # the hostile edit of issue 27: a cell's rows pushed out by 0.2, its vertices (where the
    # certificate is checked) and every margin kept; the runtime would take points outside the
    # certified polygon as inside the cell
    from bearnav_cli.runtime import PlanArrays, cell_policy

    from .conftest import random_plan

    plan = random_plan(seed)
    cells = plan.cells
    assert verify_checks.rows_not_polygon(cells, plan.map.tol) == ()  # what the planner writes passes
    c = int(np.flatnonzero(cells.parent[cells.cell_node] >= 0)[len(cells.cell_node) // 2])
    r0, r1 = cells.cell_row_offsets[c], cells.cell_row_offsets[c + 1]
    widened = cells.cell_b.copy()
    widened[r0:r1] += 0.2
    edited = replace(plan, cells=replace(cells, cell_b=widened))
    assert verify_checks.rows_not_polygon(edited.cells, plan.map.tol) == (c,)
    report = verify.run(edited, verify.Params(n_starts=0))
    assert report.failed and report.geometry.rows_not_polygon == (c,)
    assert any("rows that are not their polygon" in r and str(c) in r for r in report.reasons)
    # the point the runtime would misplace: beyond an edge of the polygon, inside the widened rows
    verts = cells.vertices(c)
    A, b = cells.rows(c)
    outside = 0.5 * (verts[0] + verts[1]) + 0.1 * A[0]
    arrays = PlanArrays.from_plan(edited)
    assert cell_policy.contains(arrays, np.array([c]), outside[None, :]).all()


def test_rows_of_a_non_convex_polygon_fail_even_when_each_lies_on_its_edge():
    # a dart: every row is the unit-normal line of its own edge, but the reflex vertex breaks a row
    from bearnav_cli.geometry import polygon_rows

    dart = np.array([[0.0, 0.0], [4.0, 0.0], [2.0, 1.0], [4.0, 4.0], [0.0, 4.0]])
    A, b = polygon_rows(dart)

    class Dart:
        cell_A, cell_b, cell_vertices = A, b, dart
        cell_vertex_offsets = cell_row_offsets = np.array([0, 5])

    assert verify_checks.rows_not_polygon(Dart, 1e-9) == (0,)
    square = dart[[0, 1, 3, 4]]
    Dart.cell_A, Dart.cell_b = polygon_rows(square)
    Dart.cell_vertices, Dart.cell_vertex_offsets = square, np.array([0, 4])
    assert verify_checks.rows_not_polygon(Dart, 1e-9) == ()


def test_verify_reads_flags_from_the_hashed_bits_not_the_manifest_stats():
    # the manifest's stats are outside the content hash: an edit there (issue 27: "invalid literal
    # for int()" was exit 70) must change nothing verify says
    from .conftest import random_plan

    plan = random_plan(1)
    honest = verify_checks.flagged_cells(plan)
    edited = replace(plan, stats={**plan.stats, "flagged": {"blind_spot": ["x", "y"]}, "few_landmarks": "z"})
    assert verify_checks.flagged_cells(edited) == honest
    assert honest["blind_spot"] == plan.cells.flagged(CellFlag.BLIND_SPOT)
