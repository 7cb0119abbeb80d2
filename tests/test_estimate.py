"""The filter's error bound under wheel slip, and what the control step does when it outgrows blind travel."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from bearnav_cli import runtime
from bearnav_cli.runtime.estimate import Estimate, Fix, fuse
from bearnav_cli.runtime.step import ControlState, look_around


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
