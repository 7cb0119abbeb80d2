"""The filter's error bound under wheel slip, and what the control step does when it outgrows blind travel."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from bearnav_cli import runtime
from bearnav_cli.runtime.estimate import Estimate, Fix, fuse
from bearnav_cli.runtime.looking import look_around
from bearnav_cli.runtime.settings import ControlState


def _settings(**kw):
    base = dict(speed=0.1, dt=0.2, eps_sw=0.04, tol=1e-9, odometry_drift=0.05, hold_time=2.0, beta=0.5)
    return runtime.ControlSettings(**{**base, **kw})


def test_the_error_bound_grows_linearly_with_the_distance_driven_blind():
    """Slip is systematic per run, so σ = σ_fix + drift·d (not √(σ_fix² + n·(drift·ℓ)²))."""
    s = _settings()
    state = ControlState.initial(np.zeros(1))
    state.known[:], state.var[:], state.motion[:] = True, 0.01**2, [0.1, 0.0]
    none = Fix(np.zeros((1, 2)), np.zeros(1, bool), np.zeros(1))
    for _ in range(40):
        est = fuse(s, state, none)
        state.x_hat[:], state.var[:] = est.x_hat, est.var
    d = 40 * s.dt * 0.1
    np.testing.assert_allclose(np.sqrt(est.var), 0.01 + s.odometry_drift * d)
    np.testing.assert_allclose(est.x_hat, [[d, 0.0]])


def test_a_look_around_after_a_long_blind_stretch_gets_its_whole_revolution():
    """A robot carried blind far beyond hold_time starts looking around when its bound outgrows blind_error,
    and the revolution is timed from then, not from the last fix (it used to end lost at once)."""
    s = _settings()
    state = ControlState.initial(np.zeros(1))
    state.known[:] = True
    no, yes = np.zeros(1, bool), np.ones(1, bool)

    def estimate(hold):
        return Estimate(np.zeros((1, 2)), np.ones(1), no, no, yes, np.full(1, hold), np.full(1, 3.0))

    last_dir = np.array([[1.0, 0.0]])
    scanning, lost, *_ = look_around(s, state, estimate(20.0), last_dir, np.zeros(1))
    assert scanning.all() and not lost.any()
    started = dataclasses.replace(state, scanning=yes.copy(), scan_from=np.full(1, 20.0 - s.dt))
    for extra, expected in ((2 * math.pi / s.beta - s.dt, False), (2 * math.pi / s.beta + 2 * s.dt, True)):
        scanning, lost, *_ = look_around(s, started, estimate(20.0 + extra), last_dir, np.zeros(1))
        assert scanning.all() and lost.tolist() == [expected]


def test_a_rejected_fix_widens_the_estimate_and_the_next_one_pulls_it_back():
    """A standing robot sure of a wrong estimate: the first far fix is rejected but widens the variance
    to the gap, the next consistent one passes the gate (without the widening every fix was rejected)."""
    s = _settings()
    state = ControlState.initial(np.zeros(1))
    state.known[:], state.var[:] = True, 0.01**2  # 3σ = 3 cm, but the robot is 1 m away
    truth = np.array([[1.0, 0.0]])
    fix = Fix(truth.copy(), np.ones(1, bool), np.full(1, 0.05**2))
    first = fuse(s, state, fix)
    assert not first.fix.any() and first.x_hat.tolist() == [[0.0, 0.0]]
    assert first.error_bound[0] == np.float64(1.0)  # 3σ is now the gap
    state.x_hat[:], state.var[:] = first.x_hat, first.var
    second = fuse(s, state, fix)
    assert second.fix.all()
    assert np.hypot(*(second.x_hat - truth).T)[0] < 0.05  # pulled to within one σ of the fix
    assert second.error_bound[0] <= 3 * 0.05 + 1e-12  # and as sure as one fix, no surer than the two agree
    # a fix within the gate is fused as before: no widening
    close = Fix(np.array([[0.02, 0.0]]), np.ones(1, bool), np.full(1, 0.05**2))
    state.x_hat[:], state.var[:] = 0.0, 0.01**2
    fused = fuse(s, state, close)
    assert fused.fix.all() and fused.var[0] < 0.01**2


def test_a_noisy_fix_is_weighted_and_its_variance_taken_at_the_prediction():
    """With a prediction, the distance-weighted fix's weights and variance use the predicted position, so
    a fix's own error does not decide how much it is trusted; without one, the refined fix's own."""
    from types import SimpleNamespace

    from bearnav_cli.runtime import bearing
    from bearnav_cli.runtime.estimate import measure

    lm = np.array([[0.0, 3.0], [4.0, 0.0], [9.0, 9.0], [-6.0, -2.0]])
    arrays = SimpleNamespace(landmarks=lm, tol=1e-9)  # what measure reads of a plan
    s = _settings(bearing_sigma=math.radians(1.0))
    x = np.array([[1.0, 1.0], [2.0, -0.5]])
    rng = np.random.default_rng(0)
    angle = np.arctan2(*(lm[None] - x[:, None]).transpose(2, 0, 1)[::-1]) + rng.normal(0, 0.02, (2, 4))
    beta = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    seen = np.ones((2, 4), bool)
    prior = np.array([[1.2, 0.9], [np.nan, np.nan]])
    fix = measure(arrays, s, beta, seen, prior=prior)
    assert fix.usable.all()
    expected = bearing.fix_variance(beta, seen, lm, np.array([prior[0], fix.position[1]]), s.bearing_sigma, 1e-9)
    np.testing.assert_allclose(fix.variance, expected)
    plain = bearing.reconstruct(beta, seen, lm, 0, method="lsq", min_spread=s.min_spread, tol=s.tol).x_hat
    np.testing.assert_allclose(fix.position[0], bearing.refine_fix(beta[:1], seen[:1], lm, prior[:1], s.tol, 1)[0])
    np.testing.assert_allclose(fix.position[1], bearing.refine_fix(beta[1:], seen[1:], lm, plain[1:], s.tol, 2)[0])
    assert np.all(np.hypot(*(fix.position - plain).T) > 0)  # refined, not the plain lsq fix
