"""The simulated world (``bearnav_cli.world``): wheel slip, collisions and clearance, the camera choice."""

from __future__ import annotations

import numpy as np
import pytest

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.params.simulate import CAMERAS
from bearnav_cli.runtime import ControlSettings, ControlState
from bearnav_cli.runtime.estimate import Fix, fuse
from bearnav_cli.stages import simulate
from bearnav_cli.world.camera import IdealCamera
from bearnav_cli.world.motion import Base, Contact

from .handmade import hand_map, hand_plan


def _drive_straight(dynamics: str, sigma: float, robots: int, steps: int, seed: int = 0):
    """``robots`` robots driving straight at 0.1 map units/s in random directions (dt = 0.2 s) on the
    simulated base, and the runtime's odometry of the same commands (``fuse`` without fixes).

    Returns the true positions, odometry's positions (both (R, 2), from the origin), the unit
    directions (R, 2) and the distance driven."""
    v, dt = 0.1, 0.2
    rng = np.random.default_rng(seed)
    theta = rng.uniform(-np.pi, np.pi, robots)
    unit = np.column_stack([np.cos(theta), np.sin(theta)])
    base = Base(dynamics, dt, sigma, robots, np.random.default_rng(seed + 1))
    s = ControlSettings(speed=v, dt=dt, eps_sw=2 * v * dt, tol=1e-9)
    state = ControlState.initial(theta)
    state.known[:], state.var[:], state.x_hat[:], state.motion[:] = True, 0.0, 0.0, 0.0
    none = Fix(np.zeros((robots, 2)), np.zeros(robots, bool), np.zeros(robots))
    x, runs, zeros = np.zeros((robots, 2)), np.arange(robots), np.zeros(robots)
    for _ in range(steps):
        state.x_hat[:] = fuse(s, state, none).x_hat  # the runtime carries its estimate on the last command
        state.motion[:] = v * unit
        x, _ = base.step(runs, x, theta, v * unit, np.full(robots, v), zeros, np.zeros(robots, bool), unit)
    odometry = fuse(s, state, none).x_hat
    return x, odometry, unit, steps * v * dt


@pytest.mark.parametrize("dynamics", ["single", "unicycle"])
def test_odometry_errs_by_a_few_percent_of_the_distance_travelled(dynamics):
    """The default slip (σ = 2%): after a straight run of length d, the error of odometry alone
    against the truth has a standard deviation of ≈ σ·d along and across the path (a per-run scale
    and heading error; the per-step jitter adds only σ·√(d·step))."""
    sigma = simulate.Params().odometry_noise
    assert sigma == 0.02
    for steps in (25, 250):  # d = 0.5 and 5 map units
        x, odometry, unit, d = _drive_straight(dynamics, sigma, robots=3000, steps=steps)
        error = x - odometry
        along = np.einsum("rk,rk->r", error, unit)
        across = error[:, 1] * unit[:, 0] - error[:, 0] * unit[:, 1]
        for spread in (along.std(), across.std()):
            assert 1 / 1.5 < spread / (sigma * d) < 1.5, (dynamics, d, spread / (sigma * d))
        assert abs(along.mean()) < 0.1 * sigma * d and abs(across.mean()) < 0.1 * sigma * d  # unbiased


def test_without_slip_the_base_moves_exactly_as_commanded_and_draws_nothing():
    rng = np.random.default_rng(5)
    state = rng.bit_generator.state
    base = Base("single", 0.2, 0.0, 3, rng)
    x = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 0.5]])
    u = np.array([[0.1, 0.0], [0.0, -0.1], [0.06, 0.08]])
    q, heading = base.step(np.arange(3), x, np.zeros(3), u, np.zeros(3), np.zeros(3), np.zeros(3, bool), u)
    assert np.array_equal(q, x + 0.2 * u) and np.allclose(heading, np.arctan2(u[:, 1], u[:, 0]))
    assert rng.bit_generator.state == state
    uni = Base("unicycle", 0.2, 0.0, 1, rng)
    q, heading = uni.step(
        np.arange(1), x[:1], np.array([np.pi / 2]), u[:1], np.array([0.1]), np.array([0.5]), np.zeros(1, bool), u[:1]
    )
    assert np.allclose(q, [[0.0, 0.02]]) and np.allclose(heading, [np.pi / 2 + 0.1])


def test_the_slip_of_a_run_is_systematic():
    """The per-run part is drawn once: the same run keeps its scale error and heading bias."""
    base = Base("single", 0.2, 0.02, 2, np.random.default_rng(1))
    move = np.array([[0.02, 0.0], [0.02, 0.0]])
    steps = np.array([base.slipped(np.arange(2), move) for _ in range(400)])
    mean = steps.mean(axis=0)  # the jitter averages out, the run's own error does not
    expected = 0.02 * np.column_stack([1 + base.scale_error, np.sin(base.heading_bias)])
    assert np.allclose(mean, expected, atol=0.02 * 0.02 * 4 / np.sqrt(400))


def test_contact_is_the_exact_segment_test_and_tracks_the_smallest_clearance():
    square = [[4.0, 3.0], [5.0, 3.0], [5.0, 4.0], [4.0, 4.0]]
    space = FreeSpace.from_map(hand_map(obstacles=[square]))
    starts = np.array([[1.0, 3.5], [1.0, 6.0]])
    contact = Contact(space, starts)
    x, path = starts.copy(), [starts.copy()]
    for _ in range(400):  # both robots drive +x at 0.01 per step; the first one reaches the square
        q = x + [0.01, 0.0]
        free = contact.step(np.arange(2), x, q)
        if not free[0]:
            break
        x = q
        path.append(x.copy())
    assert not free[0] and free[1] and q[0, 0] > 4.0 - 1e-9
    brute = np.min([space.clearance(p) for p in path], axis=0)
    assert contact.clearance[1] == pytest.approx(brute[1], abs=1e-12)
    assert contact.clearance[0] <= brute[0] + 1e-12


def test_the_camera_is_chosen_by_params():
    assert simulate.Params().camera == "ideal" and CAMERAS == ("ideal", "render")
    plan = hand_plan(hand_map())
    space = FreeSpace.from_map(plan.map)
    assert isinstance(simulate.make_camera(plan, plan.map, space, simulate.Params()), IdealCamera)
    assert simulate.make_camera(plan, plan.map, space, simulate.Params(measurement="displacement")) is None
    with pytest.raises(InvalidParamsError) as err:
        simulate.Params(camera="tv")
    assert err.value.field == "camera"
    moved = hand_map(obstacles=[[[6, 3], [7, 3], [7, 4], [6, 4]]])
    with pytest.raises(InvalidParamsError) as err:
        simulate.make_camera(plan, moved, FreeSpace.from_map(moved), simulate.Params(camera="render"))
    assert err.value.field == "camera"


def _filter_coverage(steps: int) -> float:
    """Fraction of robots whose odometry error after ``steps`` blind steps lies within the filter's 3σ
    (the variance ``fuse`` itself carries from an exact fix over the same steps)."""
    sigma = simulate.Params().odometry_noise
    x, odometry, unit, d = _drive_straight("single", sigma, robots=3000, steps=steps, seed=3)
    s = ControlSettings(speed=0.1, dt=0.2, eps_sw=0.04, tol=1e-9)
    state = ControlState.initial(np.zeros(1))
    state.known[:], state.var[:], state.x_hat[:], state.motion[:] = True, 0.0, 0.0, [0.1, 0.0]
    none = Fix(np.zeros((1, 2)), np.zeros(1, bool), np.zeros(1))
    for _ in range(steps):
        est = fuse(s, state, none)
        state.x_hat[:], state.var[:] = est.x_hat, est.var
    bound = float(est.error_bound[0])
    assert bound == pytest.approx(3.0 * s.odometry_drift * d)  # σ grows linearly with the distance
    return float(np.mean(np.hypot(*(x - odometry).T) <= bound))


def test_the_filter_is_more_pessimistic_than_the_slip_over_one_step():
    """odometry_drift (5% of a step) against the slip of one step (2σ = 4% rms, systematic and jitter)."""
    drift = ControlSettings(speed=0.1, dt=0.2, eps_sw=0.04, tol=1e-9).odometry_drift
    assert drift >= 2 * simulate.Params().odometry_noise
    assert _filter_coverage(1) > 0.99


@pytest.mark.parametrize("steps", [10, 50, 250])
def test_the_filter_covers_the_slip_over_a_hold(steps):
    """Wheel slip is mostly per run (its error grows like σ·d), and so does the filter's σ
    (``odometry_drift``·d, linear in the distance): after a 2 s hold (10 steps), 50 and 250 blind steps
    at least 99% of robots are within its 3σ."""
    assert _filter_coverage(steps) > 0.99
