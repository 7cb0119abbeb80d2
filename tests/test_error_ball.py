"""The error-ball rule of the control step (issue 11): beyond the certified tolerance ``δ*`` a robot
drives only as fast as keeps every position its estimate allows off the obstacles.

Properties, on small random maps (tests/funnel_maps.py) and a rooms map of tests/mapgen.py:

- ``obstacle_clearance`` is the exact distance to the inflated obstacles and the walls (checked
  against shapely), and ``away`` points from the nearest boundary point;
- ``error_ball_pace`` never allows a step whose ball ``e + p·ℓ`` reaches an obstacle, is 1 where
  the certificate covers the step, and never grows with the error bound;
- ``steer_clear`` leaves a full-pace command alone and turns a stopped one away from the obstacle;
- in the closed loop, no robot whose true position lies within its estimate's error bound collides.
"""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np
import pytest
import shapely

from bearnav_cli.geometry import FreeSpace
from bearnav_cli.runtime.cell_policy import least_rank_cell
from bearnav_cli.runtime.plan_arrays import PlanArrays
from bearnav_cli.runtime.safety import error_ball_pace, steer_clear
from bearnav_cli.runtime.settings import ControlSettings
from bearnav_cli.runtime.sight import obstacle_clearance
from bearnav_cli.stages import simulate
from tests.conftest import made_plan, random_plan


@pytest.fixture(autouse=True)
def _quiet(caplog):
    caplog.set_level(logging.ERROR)  # random maps have blind spots: the map stage warns


PLANS = {
    "random 1": lambda: random_plan(1),
    "random 4": lambda: random_plan(4),
    "rooms 2": lambda: made_plan(2, "rooms"),
}


def _points_in_bounds(plan, n: int, seed: int) -> np.ndarray:
    lo, hi = np.asarray(plan.map.bounds[:2], float), np.asarray(plan.map.bounds[2:], float)
    return np.random.default_rng(seed).uniform(lo, hi, (n, 2))


def _settings(plan, **fields) -> ControlSettings:
    return ControlSettings.for_plan(plan.map.diagonal, plan.map.tol, dynamics="unicycle", **fields)


@pytest.mark.parametrize("name", PLANS)
def test_clearance_is_the_exact_distance_and_away_points_from_the_nearest_boundary_point(name):
    plan = PLANS[name]()
    arrays, space = PlanArrays.from_plan(plan), FreeSpace.from_map(plan.map)
    x = _points_in_bounds(plan, 400, 0)
    x = x[space.points_free(x)]
    clearance, away = obstacle_clearance(arrays, x)
    np.testing.assert_allclose(clearance, space.clearance(x), atol=1e-9 * plan.map.diagonal)
    np.testing.assert_allclose(np.hypot(*away.T), 1.0, atol=1e-9)
    # x − k·away is a point of the boundary (an obstacle's or a wall's): at distance 0 from it
    foot = x - clearance[:, None] * away
    boundary = shapely.union(space.obstacles.boundary, space.box.exterior)
    gaps = shapely.distance(boundary, shapely.points(foot))
    assert np.all(gaps <= 1e-7 * plan.map.diagonal)


@pytest.mark.parametrize("name", PLANS)
def test_pace_never_lets_the_error_ball_reach_an_obstacle(name):
    plan = PLANS[name]()
    arrays, space = PlanArrays.from_plan(plan), FreeSpace.from_map(plan.map)
    s = _settings(plan)
    rng = np.random.default_rng(1)
    x = _points_in_bounds(plan, 600, 1)
    x = x[space.points_free(x)]
    cell = least_rank_cell(arrays, x)
    e = rng.uniform(0.0, 0.05 * plan.map.diagonal, len(x))
    e[::7] = 0.5 * arrays.plan_tolerance  # certified steps
    pace, away = error_ball_pace(arrays, s, cell, x, e)
    assert np.all((pace >= 0.0) & (pace <= 1.0))
    assert np.all(pace[::7] == 1.0)  # the certificate covers them: full speed
    step = s.alpha * s.dt * (1.0 + s.odometry_drift)
    uncertified = e > arrays.tolerance_in(cell) + s.tol  # each cell's own τ_c (ALGORITHMS §12.3)
    moving = uncertified & (pace > 0)
    assert moving.any() and (uncertified & (pace == 0)).any() and (uncertified & (pace < 1) & (pace > 0)).any()
    # the ball of every position the robot can reach this step is free
    assert np.all(space.clearance(x[moving]) >= e[moving] + pace[moving] * step - 1e-9 * plan.map.diagonal)
    # slowed robots know which way is away, the others get no push
    slowed = pace < 1
    assert np.allclose(np.hypot(*away[slowed & uncertified].T), 1.0)
    assert np.all(away[pace == 1] == 0.0)
    # a larger error bound never allows a faster step
    more, _ = error_ball_pace(arrays, s, cell, x, 1.5 * e + 1e-3)
    assert np.all(more <= pace + 1e-12)
    # an estimate never fixed (inf) does not move
    none, _ = error_ball_pace(arrays, s, cell[:3], x[:3], np.full(3, math.inf))
    assert np.all(none == 0.0)


def test_a_paper_plan_is_never_slowed():
    plan = random_plan(1)
    arrays = dataclasses.replace(PlanArrays.from_plan(plan), certificate="paper")
    x = _points_in_bounds(plan, 50, 2)
    pace, away = error_ball_pace(arrays, _settings(plan), np.zeros(50, np.int64), x, np.full(50, 1.0))
    assert np.all(pace == 1.0) and np.all(away == 0.0)


def test_steer_clear_bends_away_as_the_pace_drops():
    rng = np.random.default_rng(3)
    angle = rng.uniform(-math.pi, math.pi, (2, 200))
    u = np.column_stack([np.cos(angle[0]), np.sin(angle[0])])
    away = np.column_stack([np.cos(angle[1]), np.sin(angle[1])])
    np.testing.assert_array_equal(steer_clear(u, np.ones(200), away), u)  # full pace: as it was
    np.testing.assert_array_equal(steer_clear(u, np.zeros(200), np.zeros((200, 2))), u)  # no push
    for p in (0.0, 0.3, 0.7):
        bent = steer_clear(u, np.full(200, p), away)
        np.testing.assert_allclose(np.hypot(*bent.T), 1.0)
        # never more toward the obstacle than the command was, and away whenever stopped
        assert np.all(np.einsum("rk,rk->r", bent, away) >= np.einsum("rk,rk->r", u, away) - 1e-12)
        if p == 0.0:
            assert np.all(np.einsum("rk,rk->r", bent, away) > 0)
    assert np.all(steer_clear(np.zeros((5, 2)), np.zeros(5), away[:5]) == 0.0)  # no command stays none


def _drive(plan, starts: np.ndarray, params: simulate.Params):
    """Step the loop by hand, recording for every step the true position and the estimate it used."""
    loop, active, built = simulate.start_loop(plan, starts, params)
    goal, tolerance = built["arrays"].goal, built["settings"].goal_tolerance
    inside_at_collision = []
    while active.size:
        steering = active[np.hypot(*(loop.x[active] - goal).T) > tolerance]
        before = loop.x[steering].copy()
        active = loop.step(active)
        hit = loop.outcome[steering] == simulate.Outcome.COLLISION
        if hit.any():
            st = loop.state
            err = np.hypot(*(st.x_hat[steering[hit]] - before[hit]).T)
            inside_at_collision += list(err <= 3.0 * np.sqrt(np.maximum(st.var[steering[hit]], 0.0)))
    return loop.outcome, inside_at_collision


@pytest.mark.parametrize("name", ["random 1", "rooms 2"])
def test_no_robot_inside_its_error_ball_collides(name):
    """2° of bearing noise, a 60° unicycle: a collision needs a true position outside the 3σ ball."""
    plan = PLANS[name]()
    arrays = PlanArrays.from_plan(plan)
    x = _points_in_bounds(plan, 600, 5)
    starts = x[least_rank_cell(arrays, x) >= 0][:24]
    # 2,000 steps: the property is about collisions, and a robot still lost then would only time out
    # later (the made rooms map has two that ran to 4,372 steps, 40% of the test's time)
    params = simulate.Params(
        dynamics="unicycle",
        fov=60.0,
        noise_deg=2.0,
        record_trajectories=False,
        seed=1,
        max_steps=2000,
        estimator="kalman",  # the 3σ ball is the filter's
    )
    outcome, inside = _drive(plan, starts, params)
    assert not any(inside), "a robot whose estimate's 3σ ball held it collided"
    assert np.mean(outcome == simulate.Outcome.SUCCESS) >= 0.8
