"""Bearings, the field of view and the reconstruction of the scaled output (ALGORITHMS §6, "Tests that pin §6")."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.runtime import bearing
from bearnav_cli.runtime.bearing import METHODS, in_field_of_view, in_range, noisy_bearings, reconstruct

from .conftest import REPO

BOX = 10.0  # landmarks and robots live in [0, BOX]²
TOL = 1e-9 * math.hypot(BOX, BOX)
SPREAD = math.radians(2.0)


def truth(x: np.ndarray, landmarks: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """``(l_k − x)/‖l_f − x‖`` raveled, shape (R, 2L): what every reconstruction targets."""
    d = landmarks[None, :, :] - x[:, None, :]
    s = np.linalg.norm(d[np.arange(len(x)), fixed], axis=1)
    return (d / s[:, None, None]).reshape(len(x), -1)


def sin_angle(u: np.ndarray, v: np.ndarray) -> float:
    return abs(u[0] * v[1] - u[1] * v[0]) / (np.linalg.norm(u) * np.linalg.norm(v))


def well_spread(x: np.ndarray, landmarks: np.ndarray, seen: np.ndarray, degrees: float) -> bool:
    """Some ordered visible pair has sines of the angles at the robot and at ``l_b`` ≥ sin(degrees)."""
    bound = math.sin(math.radians(degrees))
    idx = np.flatnonzero(seen)
    for a in idx:
        for b in idx:
            if a != b:
                la, lb = landmarks[a], landmarks[b]
                if min(sin_angle(la - x, lb - x), sin_angle(lb - x, lb - la)) >= bound:
                    return True
    return False


def run(method, x, landmarks, fixed, visible=None, sigma=0.0, rng=None, bearings=None):
    x = np.atleast_2d(np.asarray(x, float))
    landmarks = np.asarray(landmarks, float)
    fixed = np.broadcast_to(np.asarray(fixed), (len(x),))
    if visible is None:
        visible = in_field_of_view(x, 0.0, landmarks, 2 * math.pi, tol=TOL)
    if bearings is None:
        bearings = noisy_bearings(x, landmarks, sigma, rng)
    return reconstruct(bearings, np.asarray(visible, bool), landmarks, fixed, method=method, tol=TOL)


def rotate(v: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def test_imports_numpy_only():
    code = (
        "import bearnav_cli.runtime.bearing, sys; "
        "bad = [m for m in sys.modules if m.split('.')[0] in ('scipy', 'shapely', 'matplotlib', 'yaml', 'typer')]; "
        "sys.exit(1 if bad else 0)"
    )
    assert subprocess.run([sys.executable, "-c", code], cwd=REPO).returncode == 0


# --------------------------------------------------------------------------- noise-free: all methods exact


def test_noise_free_all_methods_exact_at_random_points():
    """§6.4 Equivalence: noise-free, lsq, pair and rescale all return (l_k − x)/‖l_f − x‖ (random FOVs)."""
    rng = np.random.default_rng(6)
    checked = hidden = 0
    for _ in range(20):
        n_lm = int(rng.integers(3, 9))
        landmarks = rng.uniform(0, BOX, (n_lm, 2))
        x = rng.uniform(0, BOX, (200, 2))
        far = np.linalg.norm(landmarks[None] - x[:, None], axis=2).min(axis=1) >= 0.5
        x = x[far]
        fov = np.where(rng.random() < 0.3, 2 * math.pi, rng.uniform(math.radians(60), math.radians(300)))
        seen = in_field_of_view(x, rng.uniform(-math.pi, math.pi, len(x)), landmarks, float(fov), tol=TOL)
        good = np.array([well_spread(p, landmarks, s, 5.0) for p, s in zip(x, seen, strict=True)])
        x, seen = x[good], seen[good]
        fixed = rng.integers(0, n_lm, len(x))  # visible or not
        beta = noisy_bearings(x, landmarks, 0.0, None)
        want = truth(x, landmarks, fixed)
        for method in METHODS:
            rec = reconstruct(beta, seen, landmarks, fixed, method=method, tol=TOL)
            assert rec.usable.all(), method
            np.testing.assert_allclose(rec.y, want, rtol=0, atol=1e-9, err_msg=method)
            np.testing.assert_allclose(rec.x_hat, x, rtol=0, atol=1e-9, err_msg=method)
        checked += len(x)
        hidden += int((~seen).sum())
    assert checked > 1000 and hidden > 1000  # not vacuous: many robots, many invisible landmarks


def test_pair_equals_lsq_with_two_visible_under_noise():
    """§6.4: with exactly two visible landmarks, pair and lsq agree even with noise (σ = 2°)."""
    rng = np.random.default_rng(7)
    landmarks = rng.uniform(0, BOX, (4, 2))
    x = rng.uniform(0, BOX, (4000, 2))
    pick = np.argsort(rng.random((len(x), 4)), axis=1)[:, :2]
    visible = np.zeros((len(x), 4), bool)
    visible[np.arange(len(x))[:, None], pick] = True
    keep = []
    for r, (a, b) in enumerate(pick):
        la, lb, p = landmarks[a], landmarks[b], x[r]
        sines = (sin_angle(la - p, lb - p), sin_angle(p - la, lb - la), sin_angle(p - lb, la - lb))
        keep.append(min(sines) >= math.sin(math.radians(10)) and min(np.linalg.norm(landmarks - p, axis=1)) > 0.5)
    keep = np.array(keep)
    x, visible = x[keep], visible[keep]
    fixed = rng.integers(0, 4, len(x))
    beta = noisy_bearings(x, landmarks, math.radians(2.0), rng)
    lsq = reconstruct(beta, visible, landmarks, fixed, method="lsq", tol=TOL)
    pair = reconstruct(beta, visible, landmarks, fixed, method="pair", tol=TOL)
    both = lsq.usable & pair.usable
    assert len(x) > 300 and both.mean() > 0.95
    np.testing.assert_allclose(pair.y[both], lsq.y[both], rtol=0, atol=1e-9)
    np.testing.assert_allclose(pair.x_hat[both], lsq.x_hat[both], rtol=0, atol=1e-9)
    assert np.abs(lsq.x_hat[both] - x[both]).max() > 1e-3  # the noise is really there


# --------------------------------------------------------------------------- field of view, range, noise


@pytest.mark.parametrize("seed", range(5))
def test_landmark_exactly_at_half_fov_is_visible_and_just_beyond_is_not(seed):
    rng = np.random.default_rng(seed)
    n = 50
    x = rng.uniform(0, BOX, (n, 2))
    heading = rng.uniform(-4 * math.pi, 4 * math.pi, n)  # any angle, wrap-around included
    fov = rng.uniform(0.05, 2 * math.pi - 0.05, n)
    dist = rng.uniform(0.1, BOX, n)
    side = rng.choice([-1.0, 1.0], n)
    for extra, expected in ((0.0, True), (1e-9, False)):
        angle = heading + side * (fov / 2 + extra)
        lm = x + dist[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
        for r in range(n):  # one landmark per robot, each with its own fov
            got = in_field_of_view(x[r : r + 1], heading[r], lm[r : r + 1], float(fov[r]), tol=TOL)
            assert got[0, 0] == expected, (r, extra)


def test_full_fov_sees_all_but_landmarks_within_tol():
    landmarks = np.array([[1.0, 1.0], [5.0, 5.0], [9.0, 2.0]])
    x = np.array([[3.0, 3.0], [1.0 + 0.5 * TOL, 1.0], [1.0 + 2 * TOL, 1.0]])
    got = in_field_of_view(x, np.zeros(3), landmarks, 2 * math.pi, tol=TOL)
    assert got.tolist() == [[True, True, True], [False, True, True], [True, True, True]]
    assert in_field_of_view(x, 0.0, landmarks, math.inf, tol=TOL).tolist() == got.tolist()


def test_range_is_inclusive():
    landmarks = np.array([[3.0, 4.0], [6.0, 8.0]])
    assert in_range(np.zeros((1, 2)), landmarks, 5.0).tolist() == [[True, False]]
    assert in_range(np.zeros((1, 2)), landmarks, math.inf).all()


def test_noise_model():
    """β = R(ε)·unit(l − x) with ε ~ N(0, σ²) drawn over (R, L); σ = 0 is exact and draws nothing."""
    rng = np.random.default_rng(3)
    landmarks = rng.uniform(0, BOX, (5, 2))
    x = rng.uniform(0, BOX, (400, 2))
    exact = bearing.directions(x, landmarks)[0]
    state = rng.bit_generator.state
    np.testing.assert_array_equal(noisy_bearings(x, landmarks, 0.0, rng), exact)
    assert rng.bit_generator.state == state
    sigma = math.radians(2.0)
    noisy = noisy_bearings(x, landmarks, sigma, np.random.default_rng(11))
    eps = np.random.default_rng(11).normal(0.0, sigma, (400, 5))
    cross = exact[..., 0] * noisy[..., 1] - exact[..., 1] * noisy[..., 0]
    turned = np.arctan2(cross, np.einsum("rki,rki->rk", exact, noisy))
    np.testing.assert_allclose(turned, eps, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(noisy, axis=2), 1.0, atol=1e-12)


# --------------------------------------------------------------------------- the degenerate cases of §6.5


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("n_visible", [0, 1])
def test_fewer_than_two_visible_is_unusable(method, n_visible):
    landmarks = np.array([[0.0, 0.0], [4.0, 0.0], [2.0, 5.0]])
    visible = np.zeros((1, 3), bool)
    visible[0, :n_visible] = True
    rec = run(method, [1.0, 1.0], landmarks, 0, visible)
    assert not rec.usable[0]
    assert not rec.y.any() and not rec.x_hat.any()


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("robot", [[7.0, 0.0], [1.0, 0.0], [-3.0, 0.0], [7.0, 0.02], [-3.0, -0.02]])
def test_robot_on_the_line_through_all_visible_landmarks_is_unusable(method, robot):
    """On the line (or so near that every bearing pair spans < θ_min = 2°): λ_min and κ below threshold."""
    landmarks = np.array([[0.0, 0.0], [2.0, 0.0], [4.5, 0.0]])
    beta = bearing.directions(np.array([robot]), landmarks)[0][0]
    assert max(sin_angle(u, v) for u in beta for v in beta) < math.sin(SPREAD)
    assert not run(method, robot, landmarks, 0).usable[0]
    assert run(method, [robot[0], 1.0], landmarks, 0).usable[0]  # off the line it works


def test_pair_needs_the_angle_at_l_b_too():
    """Robot just off the segment l_a l_b: 177° at the robot (lsq usable) but 1.5° at each landmark (κ too small)."""
    landmarks = np.array([[0.0, 0.0], [2.0, 0.0]])
    x = np.array([[1.0, math.tan(math.radians(1.5))]])
    assert run("lsq", x, landmarks, 0).usable[0]
    assert not run("pair", x, landmarks, 0).usable[0]
    assert not run("rescale", x, landmarks, 0).usable[0]  # |det| = sin 1.5° < sin θ_min, then pair


def test_rescale_uses_the_measured_bearings_of_consistent_landmarks():
    """§6.3 under noise: ỹ_f = β_f and, for a consistent visible k, ỹ_k = b_k β_k with b_k > 0."""
    rng = np.random.default_rng(5)
    landmarks = np.array([[0.0, 0.0], [9.0, 1.0], [1.0, 9.0]])  # no line through l_f and l_k meets [4, 6]²
    x = rng.uniform(4, 6, (200, 2))
    beta = noisy_bearings(x, landmarks, math.radians(1.0), rng)
    rec = run("rescale", x, landmarks, 0, bearings=beta)
    assert rec.usable.all()
    assert np.abs(rec.y - truth(x, landmarks, np.zeros(200, np.int64))).max() > 1e-4  # the noise is really there
    y = rec.y.reshape(200, 3, 2)
    np.testing.assert_allclose(y[:, 0], beta[:, 0], atol=1e-12)
    np.testing.assert_allclose(y / np.linalg.norm(y, axis=2, keepdims=True), beta, atol=1e-12)


@pytest.mark.parametrize("method", METHODS)
def test_collinear_landmarks_robot_off_their_line(method):
    landmarks = np.array([[0.0, 0.0], [2.0, 0.0], [5.0, 0.0], [9.0, 0.0]])
    x = np.array([[1.0, 3.0], [7.0, -2.0], [4.0, 8.0]])
    fixed = np.array([0, 2, 3])
    rec = run(method, x, landmarks, fixed)
    assert rec.usable.all()
    np.testing.assert_allclose(rec.y, truth(x, landmarks, fixed), atol=1e-9)


def crossed_bearings() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two landmarks 1 apart seen from 10 below; each bearing turned 5° the other way, so the lines cross above them."""
    landmarks = np.array([[0.0, 0.0], [1.0, 0.0]])
    x = np.array([0.5, -10.0])
    beta = bearing.directions(x, landmarks)[0][0]
    crossed = np.array([rotate(beta[0], -math.radians(5)), rotate(beta[1], math.radians(5))])
    return landmarks, x, crossed[None]


@pytest.mark.parametrize("method", METHODS)
def test_inconsistent_estimate_under_noise_is_unusable(method):
    landmarks, x, crossed = crossed_bearings()
    exact = bearing.directions(x, landmarks)[0]
    assert run(method, x, landmarks, 0, bearings=exact).usable[0]
    # The crossed lines are 5.7° − 10° apart, well conditioned, but the intersection lies behind both cameras.
    assert math.degrees(math.asin(sin_angle(crossed[0, 0], crossed[0, 1]))) > 4
    rec = run(method, x, landmarks, 0, bearings=crossed)
    assert not rec.usable[0] and not rec.y.any()


@pytest.mark.parametrize("robot", [[7.0, 0.0], [2.0, 0.0], [-1.5, 0.0], [6.0, 0.01]])
def test_rescale_robot_on_the_line_through_lf_and_lk_takes_the_closed_form(robot):
    """l_1 lies on the line through l_f and the robot: its 2×2 solve is singular, the closed form from l_2 serves."""
    landmarks = np.array([[0.0, 0.0], [4.0, 0.0], [2.0, 5.0]])
    x = np.array([robot])
    beta = bearing.directions(x, landmarks)[0]
    assert sin_angle(beta[0, 1], landmarks[1] - landmarks[0]) < math.sin(SPREAD)  # the singular solve
    rec = run("rescale", x, landmarks, 0)
    assert rec.usable[0]
    np.testing.assert_allclose(rec.y, truth(x, landmarks, np.array([0])), atol=1e-9)
    np.testing.assert_allclose(rec.x_hat, x, atol=1e-9)


def test_rescale_closed_form_also_covers_an_inconsistent_visible_landmark():
    """With noise, a visible k whose 2×2 solve fails the checks gets the closed form from the best consistent k."""
    landmarks = np.array([[0.0, 0.0], [6.0, 0.0], [0.0, 6.0]])
    x = np.array([[3.0, 3.0]])
    beta = bearing.directions(x, landmarks)[0].copy()
    beta[0, 2] = -beta[0, 2]  # a reflection-like outlier: b_2 < 0
    rec = run("rescale", x, landmarks, 0, bearings=beta)
    assert rec.usable[0]
    np.testing.assert_allclose(rec.y, truth(x, landmarks, np.array([0])), atol=1e-9)


def test_fixed_landmark_not_visible():
    """lsq and pair need nothing; rescale falls back to pair (identical, also with noise)."""
    rng = np.random.default_rng(4)
    landmarks = np.array([[0.0, 0.0], [8.0, 1.0], [3.0, 9.0], [9.0, 8.0]])
    x = rng.uniform(2, 7, (300, 2))
    visible = np.ones((300, 4), bool)
    visible[:, 0] = False
    fixed = np.zeros(300, np.int64)
    want = truth(x, landmarks, fixed)
    for method in METHODS:
        rec = run(method, x, landmarks, fixed, visible)
        assert rec.usable.all(), method
        np.testing.assert_allclose(rec.y, want, atol=1e-9, err_msg=method)
    beta = noisy_bearings(x, landmarks, math.radians(1.0), rng)
    pair = run("pair", x, landmarks, fixed, visible, bearings=beta)
    resc = run("rescale", x, landmarks, fixed, visible, bearings=beta)
    np.testing.assert_array_equal(resc.usable, pair.usable)
    np.testing.assert_array_equal(resc.y, pair.y)
    np.testing.assert_array_equal(resc.x_hat, pair.x_hat)
    assert np.abs(resc.y - want).max() > 1e-4  # the noise is really there


@pytest.mark.parametrize("method", METHODS)
def test_robot_within_tol_of_a_landmark(method):
    """Rule (a): that landmark is invisible; the others still give every ỹ_k, including the near one's."""
    landmarks = np.array([[2.0, 2.0], [8.0, 1.0], [5.0, 9.0]])
    x = landmarks[:1] + [[0.5 * TOL, 0.0]]
    visible = in_field_of_view(x, 0.0, landmarks, 2 * math.pi, tol=TOL)
    assert visible.tolist() == [[False, True, True]]
    rec = run(method, x, landmarks, 1, visible)
    assert rec.usable[0]
    np.testing.assert_allclose(rec.y, truth(x, landmarks, np.array([1])), atol=1e-9)


@pytest.mark.parametrize("method", ["lsq", "pair"])
def test_estimate_within_tol_of_the_fixed_landmark_divides_by_tol(method):
    """‖l_f − x̂‖ < tol: ỹ_k = (l_k − x̂)/tol, finite and in the right direction (only the speed changes)."""
    landmarks = np.array([[2.0, 2.0], [8.0, 1.0], [5.0, 9.0]])
    x = landmarks[:1] + [[0.5 * TOL, 0.0]]
    visible = in_field_of_view(x, 0.0, landmarks, 2 * math.pi, tol=TOL)
    rec = run(method, x, landmarks, 0, visible)
    assert rec.usable[0] and np.isfinite(rec.y).all()
    assert np.linalg.norm(rec.x_hat[0] - landmarks[0]) < TOL
    y = rec.y.reshape(3, 2)
    np.testing.assert_allclose(y * TOL, landmarks - rec.x_hat[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(y[1:] * TOL, landmarks[1:] - x[0], atol=1e-9)


@pytest.mark.parametrize("method", METHODS)
def test_vertical_inter_landmark_line(method):
    """The authors' code uses slopes; the 2×2 solves do not care about a vertical β^f_k."""
    landmarks = np.array([[2.0, 0.0], [2.0, 5.0], [2.0, -3.0], [7.0, 1.0]])
    x = np.array([[-1.0, 1.0], [5.0, 2.0], [4.0, -6.0]])
    for f in range(3):
        fixed = np.full(3, f)
        rec = run(method, x, landmarks, fixed, np.array([[True, True, True, False]] * 3))
        assert rec.usable.all()
        np.testing.assert_allclose(rec.y, truth(x, landmarks, fixed), atol=1e-9)


def test_bad_parameters_raise():
    landmarks = np.array([[0.0, 0.0], [1.0, 0.0]])
    beta, visible = np.zeros((1, 2, 2)), np.ones((1, 2), bool)
    with pytest.raises(InvalidParamsError):
        reconstruct(beta, visible, landmarks, 0, method="slopes", tol=TOL)
    with pytest.raises(InvalidParamsError):
        reconstruct(beta, visible, landmarks, 0, min_spread=0.0, tol=TOL)
    with pytest.raises(ValueError):
        reconstruct(beta, visible, landmarks, 2, tol=TOL)
    with pytest.raises(InvalidParamsError):
        noisy_bearings(np.zeros((1, 2)), landmarks, 0.1, None)


# --------------------------------------------------------------------------- no NaN, ever

coord = st.integers(0, 3).map(float) | st.floats(-5, 5, allow_nan=False)


@st.composite
def scenes(draw):
    n_lm = draw(st.integers(1, 5))
    n_rob = draw(st.integers(1, 4))
    landmarks = np.array(draw(st.lists(st.tuples(coord, coord), min_size=n_lm, max_size=n_lm)))
    x = np.array(draw(st.lists(st.tuples(coord, coord), min_size=n_rob, max_size=n_rob)))
    visible = np.array(draw(st.lists(st.booleans(), min_size=n_rob * n_lm, max_size=n_rob * n_lm))).reshape(n_rob, n_lm)
    fixed = np.array(draw(st.lists(st.integers(0, n_lm - 1), min_size=n_rob, max_size=n_rob)))
    kind = draw(st.sampled_from(["exact", "noisy", "arbitrary"]))
    if kind == "arbitrary":  # anything a broken sensor might send, zeros included
        values = draw(st.lists(st.integers(-2, 2).map(float), min_size=2 * n_rob * n_lm, max_size=2 * n_rob * n_lm))
        beta = np.array(values).reshape(n_rob, n_lm, 2)
    else:
        sigma = 0.0 if kind == "exact" else draw(st.sampled_from([0.01, 0.5, 3.0]))
        beta = noisy_bearings(x, landmarks, sigma, np.random.default_rng(draw(st.integers(0, 99))))
    heading = np.array(draw(st.lists(st.floats(-10, 10), min_size=n_rob, max_size=n_rob)))
    fov = draw(st.sampled_from([0.0, 0.5, math.pi / 2, math.pi, 2 * math.pi]))
    return landmarks, x, visible, fixed, beta, heading, fov


@settings(max_examples=300, deadline=None)
@given(scenes(), st.sampled_from(METHODS))
def test_no_nan_anywhere(scene, method):
    landmarks, x, visible, fixed, beta, heading, fov = scene
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        seen = in_field_of_view(x, heading, landmarks, fov, tol=TOL) & in_range(x, landmarks, 4.0)
        for mask in (visible, seen, visible & seen):
            rec = reconstruct(beta, mask, landmarks, fixed, method=method, tol=TOL)
            assert rec.y.shape == (len(x), 2 * len(landmarks)) and rec.x_hat.shape == (len(x), 2)
            assert rec.usable.dtype == bool and rec.usable.shape == (len(x),)
            assert np.isfinite(rec.y).all() and np.isfinite(rec.x_hat).all()
            assert not rec.y[~rec.usable].any() and not rec.x_hat[~rec.usable].any()
    unit, dist = bearing.directions(x, landmarks)
    assert np.isfinite(unit).all() and np.isfinite(dist).all() and np.isfinite(beta).all()


@pytest.mark.parametrize("seed", range(4))
def test_the_refined_fix_has_the_variance_fix_variance_predicts(seed):
    """Monte Carlo: the spread of the distance-weighted fix under angle noise is ``fix_variance``.

    Tags at very different distances (two near, three far) are where the plain ``lsq`` fix, which
    weighs every line alike, is several times noisier than that: the runtime refines it.
    """
    rng = np.random.default_rng(seed)
    x = np.array([0.0, 0.0])
    near = rng.uniform(0.0, 2.0 * np.pi)
    angles = np.concatenate([[near, near + rng.uniform(0.4, 0.6) * np.pi], rng.uniform(0.0, 2.0 * np.pi, 3)])
    dist = np.concatenate([rng.uniform(0.5, 1.0, 2), rng.uniform(8.0, 15.0, 3)])
    lm = x + dist[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
    sigma, n = math.radians(0.5), 20000
    noisy = angles[None] + rng.normal(0.0, sigma, (n, len(lm)))
    beta = np.stack([np.cos(noisy), np.sin(noisy)], axis=-1)
    vis = np.ones((n, len(lm)), bool)
    rec = bearing.reconstruct(beta, vis, lm, 0, method="lsq", min_spread=math.radians(2.0), tol=1e-9)
    assert rec.usable.all()
    refined = bearing.refine_fix(beta, vis, lm, rec.x_hat, 1e-9)
    exact = np.column_stack([np.cos(angles), np.sin(angles)])
    predicted = bearing.fix_variance(exact[None], vis[:1], lm, x[None], sigma, 1e-9)[0]
    worst = np.linalg.eigvalsh(np.cov((refined - x).T))[-1]
    assert predicted == pytest.approx(worst, rel=0.08)
    plain = np.linalg.eigvalsh(np.cov((rec.x_hat - x).T))[-1]
    assert plain > 5.0 * predicted  # what the filter would have believed of the plain fix
    # exact bearings: the refined fix is the exact point
    np.testing.assert_allclose(bearing.refine_fix(exact[None], vis[:1], lm, x[None] + 0.3, 1e-9)[0], x, atol=1e-12)
