"""The look-ahead unicycle inside the certificate (ALGORITHMS §12.6, Lemma 7) and the map's ``robot:`` section.

Lemma 7 exactly; a unicycle on a plan with a look-ahead λ, from starts in D, reaches the goal with no
collision of its body; ``verify --dynamics unicycle`` proves the look-ahead checks and counts no
breach; the ``robot:`` section is parsed, overridden by ``--lookahead`` and leaves a map without it
as it was (the same content hash).
"""

from __future__ import annotations

import copy
import functools
import json
import math

import numpy as np
import pytest
import shapely

from bearnav_cli import pipeline, verify, verify_checks
from bearnav_cli.datatypes import Outcome, replace
from bearnav_cli.geometry import inflate, to_shapely
from bearnav_cli.runtime import Controller, PlanArrays, robot, step
from bearnav_cli.stages import simulate
from bearnav_cli.world.motion import body_space
from bearnav_cli.world.starts import domain_starts

from .conftest import build_map
from .funnel_maps import ITERATIONS, random_spec
from .handmade import write_plan
from .test_cli_errors import assert_one_line_error

#: The look-ahead of the test plans (map units; the random maps' robot radii are 0.08–0.15).
LAMBDA = 0.1


@functools.cache
def lookahead_plan(seed: int = 2, lookahead: float = LAMBDA, reverse: bool = True):
    """The plan of ``random_spec(seed)`` with ``robot: {lookahead, reverse}`` (in memory, once per process)."""
    spec = random_spec(seed, ITERATIONS)
    spec["robot"] = {"lookahead": lookahead, **({} if reverse else {"reverse": False})}
    return pipeline.compute(build_map(spec))["plan"]


# --------------------------------------------------------------------------- Lemma 7


def test_lemma_7_the_look_ahead_point_is_a_single_integrator():
    """(v, ω) = (w·h, w·h^⊥/λ) gives ṗ = v h + λ ω h^⊥ = w exactly, with |v| ≤ ‖w‖ and |ω| ≤ ‖w‖/λ."""
    rng = np.random.default_rng(7)
    theta = rng.uniform(-4 * math.pi, 4 * math.pi, 5000)
    w = rng.normal(size=(5000, 2)) * rng.uniform(0.0, 3.0, (5000, 1))
    for lam in (0.01, 0.2, 3.0):
        v, omega, clamped = robot.lookahead_command(w, theta, lam)
        h = np.column_stack([np.cos(theta), np.sin(theta)])
        h_perp = np.column_stack([-np.sin(theta), np.cos(theta)])
        p_dot = v[:, None] * h + lam * omega[:, None] * h_perp  # d/dt (x + λh(θ)) with ẋ = v h, θ̇ = ω
        np.testing.assert_allclose(p_dot, w, rtol=0, atol=1e-12)
        speed = np.hypot(*w.T)
        assert np.all(np.abs(v) <= speed + 1e-12) and np.all(np.abs(omega) <= speed / lam + 1e-12)
        assert not clamped.any()
    # the point itself, and λ = 0 gives the axle back
    x = rng.normal(size=(10, 2))
    np.testing.assert_allclose(robot.lookahead_point(x, theta[:10], 0.5) - x, 0.5 * h[:10], atol=1e-15)
    np.testing.assert_array_equal(robot.lookahead_point(x, theta[:10], 0.0), x)
    with pytest.raises(ValueError):
        robot.lookahead_command(w, theta, 0.0)


def test_the_step_error_bounds_the_look_ahead_point_off_its_straight_step():
    """Over one step at the pace ``p`` the look-ahead point leaves the straight step ``pℓd`` by at most
    ``p²·curvature`` (``StepError.of``: ``ℓ²|d·h^⊥|/2λ``), whether the base is integrated at the step's start
    (the simulated one) or turns continuously along its arc (a real one)."""
    from bearnav_cli.runtime.safety import StepError

    rng = np.random.default_rng(3)
    n, dt, alpha = 4000, 0.2, 1.0
    theta = rng.uniform(-math.pi, math.pi, n)
    angle = rng.uniform(-math.pi, math.pi, n)
    d = np.column_stack([np.cos(angle), np.sin(angle)])
    pace = rng.uniform(0.0, 1.0, n)
    for lam in (0.05, 0.5, 2.0):
        motion = StepError.of(alpha * dt, 0.0, 0.0, d, theta, lam)
        v, omega, _ = robot.lookahead_command(alpha * pace[:, None] * d, theta, lam)
        straight = dt * alpha * pace[:, None] * d
        turned = theta + omega * dt
        p0 = robot.lookahead_point(np.zeros((n, 2)), theta, lam)
        euler = dt * v[:, None] * np.column_stack([np.cos(theta), np.sin(theta)])
        arc = np.where(
            np.abs(omega)[:, None] > 1e-12,
            (v / np.where(omega == 0, 1.0, omega))[:, None]
            * np.column_stack([np.sin(turned) - np.sin(theta), np.cos(theta) - np.cos(turned)]),
            euler,
        )
        for axle in (euler, arc):
            moved = robot.lookahead_point(axle, turned, lam) - p0
            off = np.hypot(*(moved - straight).T)
            assert np.all(off <= pace**2 * motion.curvature * (1.0 + 1e-9) + 1e-12)
        # the bound is attained (up to the arc's second order) where the step crosses the heading
        assert np.max(off / np.maximum(pace**2 * motion.curvature, 1e-300)) > 0.9


def test_the_reverse_clamp_never_reverses_and_turns_toward_the_wanted_velocity():
    rng = np.random.default_rng(8)
    theta, w = rng.uniform(-math.pi, math.pi, 2000), rng.normal(size=(2000, 2))
    v, omega, clamped = robot.lookahead_command(w, theta, 0.3, clamp_reverse=True)
    behind = w[:, 0] * np.cos(theta) + w[:, 1] * np.sin(theta) < 0
    assert np.all(v >= 0.0) and np.array_equal(clamped, behind) and behind.any()
    # behind: a turn in place at the law's largest rate, toward w (the sign of w·h^⊥)
    across = -w[:, 0] * np.sin(theta) + w[:, 1] * np.cos(theta)
    np.testing.assert_allclose(np.abs(omega[behind]), np.hypot(*w[behind].T) / 0.3)
    assert np.all(np.sign(omega[behind]) == np.where(across[behind] < 0, -1.0, 1.0))
    v_free, omega_free, _ = robot.lookahead_command(w, theta, 0.3)
    np.testing.assert_array_equal(v[~behind], v_free[~behind])
    np.testing.assert_array_equal(omega[~behind], omega_free[~behind])


# --------------------------------------------------------------------------- the runtime law


def test_the_control_step_drives_the_look_ahead_point_along_the_field():
    """On a λ > 0 plan a unicycle's command moves p̂ = x̂ + λh by α·u(p̂)/‖u(p̂)‖, u the field of the cell holding p̂."""
    plan = lookahead_plan()
    arrays = PlanArrays.from_plan(plan)
    assert arrays.lookahead == pytest.approx(LAMBDA)
    rng = np.random.default_rng(3)
    p = domain_starts(arrays, 50, rng)
    theta = rng.uniform(-math.pi, math.pi, len(p))
    x = robot.lookahead_point(p, theta, -LAMBDA)
    s = step.ControlSettings.for_plan(
        plan.map.diagonal, plan.map.tol, dynamics="unicycle", measurement="displacement", bearing_sigma=0.0
    )
    n = len(arrays.landmarks)
    out = step.control(
        arrays,
        s,
        step.ControlState.initial(theta),
        np.zeros((len(p), n, 2)),
        np.ones((len(p), n), bool),
        theta,
        x_true=x,
    )
    cell = out.state.cell
    assert np.all(cell >= 0) and np.all(out.certified)
    u = arrays.field_a[cell] - np.einsum("rij,rj->ri", arrays.field_M[cell], p)
    wanted = s.alpha * u / np.hypot(*u.T)[:, None]
    h = np.column_stack([np.cos(theta), np.sin(theta)])
    h_perp = np.column_stack([-np.sin(theta), np.cos(theta)])
    np.testing.assert_allclose(out.forward[:, None] * h + LAMBDA * out.turn[:, None] * h_perp, wanted, atol=1e-12)
    np.testing.assert_allclose(out.state.x_hat, x, atol=1e-12)  # the filter keeps the axle's estimate


def test_without_a_look_ahead_the_unicycle_keeps_its_law_and_is_never_certified():
    plan = pipeline.compute(build_map(random_spec(2, ITERATIONS)))["plan"]
    assert plan.map.lookahead == 0.0 and "robot" not in plan.map.to_json()
    arrays = PlanArrays.from_plan(plan)
    starts = domain_starts(arrays, 40, np.random.default_rng(4))
    params = simulate.Params(
        dynamics="unicycle", measurement="displacement", odometry_noise=0.0, record_trajectories=False
    )
    runs = simulate.rollout(plan, starts, params)
    assert np.all(runs.outcome == Outcome.SUCCESS), runs.counts()
    assert runs.certified_steps.sum() == 0 and runs.steps.sum() > 0
    single = simulate.rollout(
        plan, starts, simulate.Params(measurement="displacement", odometry_noise=0.0, record_trajectories=False)
    )
    assert single.certified_fraction == 1.0


# --------------------------------------------------------------------------- the closed loop


def test_a_look_ahead_unicycle_from_d_reaches_the_goal_and_its_body_never_touches_an_obstacle():
    """Starts in D (``domain:N``), exact motion: every run succeeds, every step is certified, and the body
    (radius ρ around the axle x = p − λh, recomputed from the recorded p and heading) stays clear."""
    plan = lookahead_plan()
    starts = simulate.resolve_starts(plan, simulate.Params(starts="domain:150", seed=1))
    params = simulate.Params(dynamics="unicycle", measurement="displacement", odometry_noise=0.0)
    runs = simulate.rollout(plan, starts, params)
    assert runs.start_in_domain.all()
    assert np.all(runs.outcome == Outcome.SUCCESS), runs.counts()
    assert runs.certified_fraction == 1.0
    assert np.all(runs.min_clearance >= 0.0)
    # the record is of p (it ends within the goal tolerance), the body is p − λh
    assert np.all(np.hypot(*(runs.final_position - plan.map.goal).T) <= runs.goal_tolerance)
    axle = robot.lookahead_point(runs.trajectory_coords, runs.trajectory_heading, -LAMBDA)
    body = body_space(plan.map)
    assert np.all(body.clearance(axle) >= 0.0)
    assert body.clearance(axle).min() == pytest.approx(runs.min_clearance.min(), abs=0.03 * LAMBDA)
    raw = shapely.union_all([to_shapely(p) for p in plan.map.raw_obstacles])
    gap = shapely.distance(raw, shapely.points(axle))
    assert np.all(gap >= plan.map.robot_radius - 1e-9)  # the disc of radius ρ around x touches nothing
    # and with wheel slip and noise-free bearings (simulate's defaults), still no collision
    noisy = simulate.rollout(plan, starts[:60], simulate.Params(dynamics="unicycle", record_trajectories=False))
    assert noisy.counts()["collision"] == 0 and np.all(noisy.min_clearance >= 0.0)


def test_verify_proves_the_look_ahead_and_counts_no_breach():
    plan = lookahead_plan()
    report = verify.run(plan, verify.Params(n_starts=150, dynamics="unicycle"))
    assert report.breaches is not None and not report.breaches.any() and report.in_domain.sum() > 100
    assert report.outcome_counts["collision"] == 0 and report.success_in_domain == 1.0
    d = report.in_domain
    assert report.rollouts.certified_steps[d].sum() == report.rollouts.steps[d].sum()  # every step from D certified
    assert not report.failed, report.reasons
    assert report.lookahead_problems == () and report.uncovered_dynamics is None
    # a λ = 0 plan: the unicycle is outside the certificate, and the report says so without failing
    plain = pipeline.compute(build_map(random_spec(2, ITERATIONS)))["plan"]
    uncovered = verify.run(plain, verify.Params(n_starts=20, dynamics="unicycle"))
    assert not uncovered.failed and "outside the certificate" in uncovered.notes[0]


def test_verify_refutes_a_look_ahead_the_cells_were_not_built_for():
    plan = lookahead_plan()
    # the map now claims a larger look-ahead than the cells and obstacles were made with
    bigger = replace(plan, map=replace(plan.map, robot={**plan.map.robot, "lookahead": 2 * LAMBDA}))
    problems = verify_checks.check_lookahead(bigger)
    assert any(p.startswith("lookahead:") for p in problems) and any(p.startswith("obstacles:") for p in problems)
    # the obstacles inflated by ρ only, with the look-ahead kept: the obstacle check alone fails
    body_only = build_map(random_spec(2, ITERATIONS))
    thin = replace(plan, map=replace(plan.map, obstacles=body_only.obstacles))
    problems = verify_checks.check_lookahead(thin)
    assert len(problems) == 1 and problems[0].startswith("obstacles:")
    assert verify_checks.check_lookahead(plan) == []


def test_a_robot_that_may_not_reverse_never_drives_backwards():
    plan = lookahead_plan(reverse=False)
    assert plan.map.robot["reverse"] is False
    assert simulate.settings(plan, simulate.Params(dynamics="unicycle")).control.clamp_reverse
    starts = simulate.resolve_starts(plan, simulate.Params(starts="domain:40", seed=2))
    params = simulate.Params(dynamics="unicycle", measurement="displacement", odometry_noise=0.0, initial_heading=180.0)
    runs = simulate.rollout(plan, starts, params)
    assert runs.counts()["collision"] == 0 and np.all(runs.min_clearance >= 0.0)
    heading, coords, offsets = runs.trajectory_heading, runs.trajectory_coords, runs.trajectory_offsets
    for k in range(len(runs)):
        p, th = coords[offsets[k] : offsets[k + 1]], heading[offsets[k] : offsets[k + 1]]
        x = robot.lookahead_point(p, th, -LAMBDA)
        ahead = np.einsum("ri,ri->r", np.diff(x, axis=0), np.column_stack([np.cos(th[:-1]), np.sin(th[:-1])]))
        assert np.all(ahead >= -1e-12)  # the axle never moves backwards
    assert runs.certified_fraction < 1.0  # facing away at the start: the clamped turns are not certified


@pytest.mark.parametrize("estimator", ["set", "kalman"])
def test_the_controller_reports_arrival_of_the_look_ahead_point(tmp_path, estimator):
    plan = lookahead_plan(reverse=False)
    path = write_plan(tmp_path / "plan.npz", plan)
    assert Controller.from_plan(str(path), dynamics="unicycle").settings.clamp_reverse  # the map's reverse: false
    ctl = Controller.from_plan(str(path), dynamics="unicycle", estimator=estimator)
    arrays = ctl.arrays
    goal = arrays.goal
    x = goal - np.array([LAMBDA, 0.0])  # the axle λ behind the goal, facing it: p is at the goal
    bearings = arrays.landmarks - x
    bearings /= np.hypot(*bearings.T)[:, None]
    out = ctl.command(bearings, np.ones(len(bearings), bool), heading=0.0)
    # the filter takes an exact fix as it is; the set's estimate lies within its bound e of the truth
    bound = 1e-9 if estimator == "kalman" else ctl.last.error_bound[0]
    assert np.hypot(*(ctl.position - goal)) <= bound + 1e-12 and len(out) == 2
    assert ctl.arrived


# --------------------------------------------------------------------------- the map's robot section


def test_a_map_without_a_robot_section_keeps_its_map_json(cli, write_map, small_spec, tmp_path):
    """``robot_radius: r`` and ``robot: {radius: r}`` give the same map.json content (hash), with no robot key."""
    assert cli("map", write_map(small_spec, "a.yaml"), "-o", tmp_path / "a.json").exit_code == 0
    spec = copy.deepcopy(small_spec)
    spec["robot"] = {"radius": spec.pop("robot_radius")}
    assert cli("map", write_map(spec, "b.yaml"), "-o", tmp_path / "b.json").exit_code == 0
    a, b = (json.loads((tmp_path / name).read_text()) for name in ("a.json", "b.json"))
    assert a["manifest"]["content_sha256"] == b["manifest"]["content_sha256"]
    assert "robot" not in a and "robot" not in b and a["robot_radius"] == b["robot_radius"] == 0.2
    # both spellings at once must agree
    spec["robot_radius"] = 0.2
    assert cli("map", write_map(spec, "c.yaml"), "-o", tmp_path / "c.json").exit_code == 0


def test_the_robot_section_and_the_lookahead_option(cli, write_map, small_spec, tmp_path):
    spec = copy.deepcopy(small_spec)
    spec["robot"] = {
        "lookahead": 0.1,
        "bearing_error_deg": 0.25,
        "slip": 0.05,
        "max_turn_rate": 1.5,
        "reverse": False,
        "compass_error_deg": None,
    }
    built = build_map(spec)
    assert built.lookahead == 0.1 and built.planning_radius == pytest.approx(0.3)
    np.testing.assert_allclose(built.free_bounds, [0.3, 0.3, 9.7, 7.7])
    assert built.robot_json() == {
        "lookahead": 0.1,
        "bearing_error_deg": 0.25,
        "slip": 0.05,
        "max_turn_rate": 1.5,
        "reverse": False,
    }
    assert type(built).from_json(built.to_json()).to_json_text() == built.to_json_text()
    # obstacles inflated by ρ + λ, raw ones unchanged
    plain = build_map(small_spec)
    grown = shapely.union_all([to_shapely(p) for p in built.obstacles])
    raw = shapely.union_all([to_shapely(p) for p in built.raw_obstacles])
    assert shapely.union_all([to_shapely(p) for p in plain.raw_obstacles]).equals(raw)
    assert shapely.covers(shapely.buffer(grown, 1e-9), inflate(raw, 0.3))
    # --lookahead overrides the map (and reruns the map stage)
    path = write_map(spec)
    assert cli("map", path, "-o", tmp_path / "m.json", "--lookahead", "0.05").exit_code == 0
    written = json.loads((tmp_path / "m.json").read_text())
    assert written["robot"]["lookahead"] == 0.05 and written["robot"]["reverse"] is False
    assert cli("map", path, "-o", tmp_path / "m.json").exit_code == 0
    assert json.loads((tmp_path / "m.json").read_text())["robot"]["lookahead"] == 0.1
    # a map.json is built already: plan refuses the option
    assert_one_line_error(cli("plan", tmp_path / "m.json", "--lookahead", "0.2"), "--lookahead")


@pytest.mark.parametrize("value", ["-0.1", "inf", "3"])
def test_a_bad_lookahead_option_exits_3_naming_the_field(cli, write_map, small_spec, tmp_path, value):
    result = cli("map", write_map(small_spec), "-o", tmp_path / "out.json", "--lookahead", value)
    assert_one_line_error(result, "small.yaml", "robot.lookahead")
    assert not (tmp_path / "out.json").exists()


def test_a_look_ahead_point_a_hair_inside_an_obstacle_is_led_out_to_a_node():
    """Slip can carry a look-ahead point just inside the obstacles inflated by ρ + λ (the cells keep only d/20
    from them) while its body is free: ``approach_target`` gives it the node of the point just outside the
    nearest edge (in clear sight of it, exactly), where it once gave none and the run stalled (paper_sim_circles,
    λ = 0.9: 23 of 1,000). Deeper than 2λ, a body in an obstacle, it gives none, as for every λ = 0 point."""
    from bearnav_cli.geometry import FreeSpace
    from bearnav_cli.runtime import cell_policy, sight

    plan = lookahead_plan()
    arrays = PlanArrays.from_plan(plan)
    space = FreeSpace.from_map(plan.map)
    for depth, expect_node in ((0.2 * LAMBDA, True), (3.0 * LAMBDA, False)):
        rings = shapely.get_parts(shapely.boundary(shapely.buffer(space.obstacles, -depth)))  # depth inside
        x = np.concatenate(
            [
                shapely.get_coordinates(
                    shapely.line_interpolate_point(ring, np.linspace(0, 1, 16)[:-1], normalized=True)
                )
                for ring in rings
            ]
        )
        inside = sight.inside_obstacles(arrays, x)
        assert inside.sum() >= 10, inside.sum()
        got = cell_policy.approach_target(arrays, x[inside])
        if not expect_node:
            assert np.all(got == -1)
            continue
        led = got >= 0
        assert led.mean() > 0.9, led.mean()
        depth_in, way = sight.obstacle_clearance(arrays, x[inside][led])
        exits = x[inside][led] - way * (depth_in + 1e3 * arrays.tol)[:, None]
        assert not sight.inside_obstacles(arrays, exits).any()
        lines = shapely.linestrings(np.stack([exits, arrays.nodes[got[led]]], axis=1))
        assert not shapely.intersects(space.obstacles, lines).any()
