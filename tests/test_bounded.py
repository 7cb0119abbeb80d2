"""Bounded-error estimation (ALGORITHMS §12.2, Lemma 5) and the certified policy of §12.3.

The convex-set operations of :mod:`bearnav_cli.runtime.bounded` are checked against shapely on
random polygons; Lemma 5 (the set always holds the truth) and the static bound on random bearing
geometries with errors drawn within their bounds; and the closed loop of ``estimator = set`` on the
project's random maps, with uniform and worst-case bounded noise: no collision, the truth never
outside its set, and every certified step ending inside the certified domain.
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
import shapely

from bearnav_cli.datatypes import cell_polygons
from bearnav_cli.runtime import PlanArrays, bounded, least_rank_cell, look_bound
from bearnav_cli.runtime.cell_policy import cell_slack
from bearnav_cli.runtime.safety import StepError, certified_pace
from bearnav_cli.stages import simulate
from tests.conftest import random_plan


def random_polygons(seed: int, r: int = 60, points: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """``r`` random convex polygons (hulls of Gaussian points), counter-clockwise and padded."""
    rng = np.random.default_rng(seed)
    vertices, count = np.zeros((r, points, 2)), np.zeros(r, np.int64)
    for i in range(r):
        hull = shapely.convex_hull(shapely.multipoints(rng.normal(size=(points, 2)) * rng.uniform(0.1, 3.0)))
        ring = np.asarray(shapely.orient_polygons(hull).exterior.coords)[:-1]
        vertices[i, : len(ring)], count[i] = ring, len(ring)
    return vertices, count


def polygon(vertices: np.ndarray, count: np.ndarray, i: int) -> shapely.Polygon:
    return shapely.Polygon(vertices[i, : count[i]]) if count[i] >= 3 else shapely.Polygon()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_clip_is_the_intersection_with_the_half_plane(seed):
    vertices, count = random_polygons(seed)
    rng = np.random.default_rng(seed + 10)
    a = rng.normal(size=(len(count), 2))
    b = rng.normal(size=len(count))
    out, n = bounded.clip(vertices, count, a, b)
    for i in range(len(count)):
        unit = a[i] / np.linalg.norm(a[i])
        origin, along, big = unit * b[i] / np.linalg.norm(a[i]), np.array([-unit[1], unit[0]]), 1e3
        half = shapely.Polygon(
            [
                origin + along * big,
                origin - along * big,
                origin - along * big - unit * big,
                origin + along * big - unit * big,
            ]
        )
        expected = polygon(vertices, count, i).intersection(half)
        assert abs(polygon(out, n, i).area - expected.area) <= 1e-9 * max(1.0, expected.area)
        if n[i] >= 3:
            assert shapely.Polygon(out[i, : n[i]]).exterior.is_ccw


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_grow_contains_the_minkowski_sum_and_stays_close(seed):
    vertices, count = random_polygons(seed)
    radius = np.random.default_rng(seed + 20).uniform(0.0, 0.5, len(count))
    out, n = bounded.grow(vertices, count, radius, 1e-12)
    for i in range(len(count)):
        grown = polygon(out, n, i)
        exact = polygon(vertices, count, i).buffer(radius[i], quad_segs=64)
        assert grown.buffer(1e-9).contains(exact)
        # a mitre of a right angle is the farthest an offset vertex lies: r(√2 − 1) beyond the disc
        assert shapely.hausdorff_distance(grown, exact) <= (math.sqrt(2.0) - 1.0 + 1e-6) * radius[i] + 1e-9
        assert grown.exterior.is_ccw


@pytest.mark.parametrize("seed", [0, 1])
def test_centre_lies_in_the_set_and_its_radius_is_exact(seed):
    vertices, count = random_polygons(seed)
    x_hat, error = bounded.centre(vertices, count)
    for i in range(len(count)):
        poly = polygon(vertices, count, i)
        assert poly.buffer(1e-9).contains(shapely.Point(x_hat[i]))
        far = np.max(np.hypot(*(vertices[i, : count[i]] - x_hat[i]).T))
        assert error[i] == pytest.approx(far, rel=1e-12)
        assert error[i] <= 1.1 * shapely.minimum_bounding_radius(poly)


def test_the_bearing_cone_is_the_set_of_points_within_eta():
    rng = np.random.default_rng(5)
    landmark, angle, eta = np.array([1.0, 2.0]), 0.7, math.radians(3.0)
    a, b = bounded.cone_rows(landmark, np.array(angle), eta)
    y = landmark + rng.uniform(-5, 5, size=(4000, 2))
    inside = np.all(y @ a.T <= b + 1e-12, axis=1)
    d = landmark - y
    error = np.abs(np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - angle))))
    assert np.array_equal(inside, error <= eta)


@pytest.mark.parametrize("seed", range(4))
def test_lemma_5_and_the_static_bound(seed):
    """Bearings within η of the truth give a set that holds the truth, no wider than ε(x, S)."""
    rng = np.random.default_rng(seed)
    r, n_lm, eta = 200, 6, math.radians(rng.choice([0.1, 0.25, 1.0]))
    landmarks = rng.uniform(0, 10, size=(n_lm, 2))
    x = rng.uniform(0.5, 9.5, size=(r, 2))
    visible = rng.random((r, n_lm)) < 0.6
    d = landmarks[None] - x[:, None]
    truth = np.arctan2(d[..., 1], d[..., 0])
    measured = truth + rng.uniform(-eta, eta, size=truth.shape)
    bounds = np.array([0.0, 0.0, 10.0, 10.0])
    vertices, count = bounded.box(bounds, r)
    vertices, count = bounded.intersect_cones(vertices, count, landmarks, measured, visible, eta, 1e-9)
    assert np.all(count > 0)
    assert bounded.contains(vertices, count, x, 1e-9).all()
    static = look_bound.one_look_bound(x, landmarks, visible, eta, bounds, 1e-9)
    _, error = bounded.centre(vertices, count)
    assert np.all(error <= static * (1 + 1e-7) + 1e-7)  # both clipped with slack
    # the prediction: moved by the measured displacement and grown by its bound, it holds the truth again
    move = rng.normal(size=(r, 2)) * 0.1
    kappa, floor = 0.03, 1e-3
    size = kappa * np.hypot(*move.T) + floor
    slip = rng.normal(size=(r, 2))
    slip *= (size * rng.uniform(0, 1, r) / np.hypot(*slip.T))[:, None]
    predicted, n = bounded.grow(bounded.translate(vertices, move), count, size, 1e-12)
    assert bounded.contains(predicted, n, x + move + slip, 1e-9).all()


@pytest.mark.parametrize("seed", range(4))
def test_the_heading_from_the_bearings_holds_the_compass_error_and_narrows_it(seed):
    """``common_rotation`` (ALGORITHMS §12.1): every bearing of a view turned by the same compass error ``r``
    (``|r| ≤ ψ``) plus its own camera error (``≤ η``, at the bound or drawn within it): the interval it returns holds
    ``r`` and is never wider than the compass's, the set clipped by its cones holds the truth, and with three or
    more landmarks around the robot it bounds the heading far more tightly than the compass alone."""
    rng = np.random.default_rng(seed)
    r, n_lm = 300, 6
    eta, psi = math.radians(0.2), math.radians(rng.choice([1.0, 3.0, 10.0]))
    landmarks = rng.uniform(0, 10, size=(n_lm, 2))
    x = rng.uniform(0.5, 9.5, size=(r, 2))
    visible = rng.random((r, n_lm)) < 0.7
    d = landmarks[None] - x[:, None]
    truth = np.arctan2(d[..., 1], d[..., 0])
    compass = rng.uniform(-psi, psi, r)
    compass[: r // 3] = rng.choice([-psi, psi], r // 3)  # a third at the compass's bound
    camera = rng.uniform(-eta, eta, truth.shape)
    camera[r // 2 :] = rng.choice([-eta, eta], camera[r // 2 :].shape)  # half at the camera's bound
    measured = truth + compass[:, None] + camera
    bounds = np.array([0.0, 0.0, 10.0, 10.0])
    start_v, start_n = bounded.box(bounds, r)
    # a prior set, as the prediction gives one: a square around each truth
    prior_v, prior_n = bounded.intersect_cones(start_v, start_n, landmarks, truth, np.ones_like(visible), 0.05)
    middle, half = bounded.common_rotation(
        prior_v, prior_n, landmarks, measured, visible, np.full(r, eta), np.full(r, psi), 1e-9
    )
    assert np.all(half <= psi + 1e-15)
    assert np.all(np.abs(compass - middle) <= half * (1 + 1e-9) + 1e-12)
    vertices, count = bounded.intersect_cones(
        prior_v, prior_n, landmarks, measured - middle[:, None], visible, eta + half, 1e-9
    )
    assert bounded.contains(vertices, count, x, 1e-9).all()
    seeing = np.count_nonzero(visible, axis=1)
    assert np.all(half[seeing < 2] == psi)  # one bearing says nothing about the heading
    # three or more in view: the interval is set by the bearings (a few camera bounds wide), not by the compass
    many = seeing >= 3
    assert np.median(half[many]) < 0.5 * psi
    # and the set is no wider than the compass's cones give
    wide_v, wide_n = bounded.intersect_cones(prior_v, prior_n, landmarks, measured, visible, eta + psi, 1e-9)
    assert np.all(bounded.diameter(vertices, count) <= bounded.diameter(wide_v, wide_n) + 1e-9)


def test_a_heading_error_turns_the_step_and_the_prediction_holds_it():
    """``bounded_update`` with a heading error bound ψ: a step commanded through a heading that errs by ψ is turned
    by ψ, and with its slip it ends within ``(κ + 2 sin(ψ/2))‖d̂‖ + ν`` of the measured one (``ErrorBounds.drift``):
    the predicted set holds every such truth, and the slip alone would not."""
    from bearnav_cli.runtime import ControlState
    from bearnav_cli.runtime.estimate import axle_bounds, bounded_update

    plan = random_plan(1)
    arrays = PlanArrays.from_plan(plan)
    psi, kappa = math.radians(3.0), 0.03
    s = simulate.settings(plan, simulate.Params(estimator="set")).control
    s = dataclasses.replace(s, heading_bound=psi, slip=kappa)
    assert s.drift == pytest.approx(kappa + 2.0 * math.sin(0.5 * psi))
    rng = np.random.default_rng(3)
    r = 200
    x = arrays.nodes[rng.choice(len(arrays.nodes), r)]
    state = ControlState.initial(np.zeros(r))
    # a small square set around each truth, known
    half = 0.01 * float(np.hypot(*(arrays.bounds[2:] - arrays.bounds[:2])))
    square = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]) * half
    vertices = np.zeros((r, bounded.MAX_VERTICES, 2))
    vertices[:, :4] = x[:, None, :] + square
    state.set_vertices, state.set_count, state.known = vertices, np.full(r, 4), np.ones(r, bool)
    state.motion = rng.normal(size=(r, 2)) * s.speed
    d_hat = s.dt * state.motion
    turn = rng.choice([-psi, psi], r)
    c, si = np.cos(turn), np.sin(turn)
    d = np.column_stack([c * d_hat[:, 0] - si * d_hat[:, 1], si * d_hat[:, 0] + c * d_hat[:, 1]]) * (1.0 + kappa)
    corner = x + square[rng.integers(0, 4, r)]  # the truth at a corner of its set, where a step leaves it first
    moved = corner + d
    nothing = np.zeros((r, len(arrays.landmarks)), bool)
    bearings = np.zeros((r, len(arrays.landmarks), 2))
    x0, y0, x1, y1 = axle_bounds(arrays)  # a truth stays in B_r, where the prediction is cut
    real = (moved[:, 0] > x0) & (moved[:, 0] < x1) & (moved[:, 1] > y0) & (moved[:, 1] < y1)
    assert real.sum() > 0.8 * r
    after = bounded_update(arrays, s, state, bearings, nothing, None)
    assert bounded.contains(after.vertices, after.count, moved, 1e-9)[real].all()
    slip_only = bounded_update(arrays, dataclasses.replace(s, heading_bound=0.0), state, bearings, nothing, None)
    assert not bounded.contains(slip_only.vertices, slip_only.count, moved, 1e-9)[real].all()


def smallest_circle_radius(points: np.ndarray) -> float:
    """The radius of the smallest circle around ``points`` (N, 2), by brute force over pairs and triples."""
    best = math.inf
    n = len(points)
    for i in range(n):
        for j in range(i + 1, n):
            candidates = [0.5 * (points[i] + points[j])]
            for k in range(j + 1, n):
                a, b, c = points[i], points[j], points[k]
                d = 2.0 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
                if abs(d) > 1e-12:
                    ux = (a @ a * (b[1] - c[1]) + b @ b * (c[1] - a[1]) + c @ c * (a[1] - b[1])) / d
                    uy = (a @ a * (c[0] - b[0]) + b @ b * (a[0] - c[0]) + c @ c * (b[0] - a[0])) / d
                    candidates.append(np.array([ux, uy]))
            for centre in candidates:
                radius = float(np.max(np.hypot(*(points - centre).T)))
                best = min(best, radius)
    return best


@pytest.mark.parametrize("seed", range(3))
def test_the_centre_is_within_badoiu_clarkson_of_the_smallest_circle(seed):
    """``centre``'s error radius is at most (1 + 1/√(CENTRE_STEPS + 1)) times the smallest circle's
    radius (the Bădoiu–Clarkson step bound the static bound relies on), and never below it."""
    vertices, count = random_polygons(seed, r=40, points=8)
    _, error = bounded.centre(vertices, count)
    factor = 1.0 + 1.0 / math.sqrt(bounded.CENTRE_STEPS + 1)
    for i in range(len(count)):
        radius = smallest_circle_radius(vertices[i, : count[i]])
        assert radius * (1 - 1e-9) <= error[i] <= factor * radius * (1 + 1e-9)
    assert bounded.RADIUS_PER_WIDTH == pytest.approx(factor / math.sqrt(3.0))


@pytest.mark.parametrize(("seed", "eta_deg"), [(0, 0.05), (1, 0.25), (2, 1.0), (3, 3.0)])
def test_the_static_bound_holds_at_the_worst_errors_and_is_tighter_than_diam_k(seed, eta_deg):
    """Every bearing error at ±η (the corners of the error box, where the set is widest): the look's
    error radius stays within ε(x, S); and ε is well below §12.2's diam K where two bearings cross."""
    rng = np.random.default_rng(100 + seed)
    r, n_lm = 400, int(rng.integers(2, 9))
    eta = math.radians(eta_deg)
    landmarks = rng.uniform(0, 10, size=(n_lm, 2))
    x = rng.uniform(0.5, 9.5, size=(r, 2))
    visible = rng.random((r, n_lm)) < 0.7
    d = landmarks[None] - x[:, None]
    truth = np.arctan2(d[..., 1], d[..., 0])
    bounds = np.array([0.0, 0.0, 10.0, 10.0])
    static = look_bound.one_look_bound(x, landmarks, visible, eta, bounds, 1e-9)
    for _ in range(4):
        measured = truth + rng.choice([-1.0, 1.0], size=truth.shape) * eta
        vertices, count = bounded.intersect_cones(*bounded.box(bounds, r), landmarks, measured, visible, eta, 1e-9)
        _, error = bounded.centre(vertices, count)
        assert np.all(error <= static * (1 + 1e-7) + 1e-7)
    wide, n = bounded.intersect_cones(*bounded.box(bounds, r), landmarks, truth, visible, 2 * eta, 1e-9)
    diam_k = bounded.diameter(wide, n)
    assert np.all(static <= bounded.RADIUS_PER_WIDTH * diam_k * (1 + 1e-9))
    crossing = visible.sum(axis=1) >= 2
    # about 1/2.7 where bearings fix the robot and η is a camera's; the sets' curvature costs more at degrees
    assert np.median(static[crossing] / diam_k[crossing]) < (0.4 if eta_deg <= 0.25 else 0.6)


@pytest.mark.parametrize("seed", range(3))
def test_bound_with_one_more_landmark_is_an_upper_bound_on_the_exact_one(seed):
    """``bound_with`` (the tag placement's cheap score) never promises less than ``look_bound`` computes with the
    landmark, and never more than without it."""
    rng = np.random.default_rng(200 + seed)
    r, n_lm, eta = 300, 5, math.radians(0.25)
    landmarks = rng.uniform(0, 10, size=(n_lm, 2))
    extra = rng.uniform(0, 10, size=(r, 2))
    x = rng.uniform(0.5, 9.5, size=(r, 2))
    visible = rng.random((r, n_lm)) < 0.5
    bounds = np.array([0.0, 0.0, 10.0, 10.0])
    look = look_bound.look_bound(x, landmarks, visible, eta, bounds, 1e-9)
    cheap = look_bound.bound_with(look, x, extra, 1e-9)
    exact = np.array(
        [
            look_bound.one_look_bound(
                x[i : i + 1], np.vstack([landmarks, extra[i]]), np.append(visible[i], True)[None], eta, bounds, 1e-9
            )[0]
            for i in range(r)
        ]
    )
    assert np.all(exact <= cheap * (1 + 1e-9) + 1e-12)
    assert np.all(cheap <= look.bound * (1 + 1e-12))
    assert np.mean(cheap < 0.9 * look.bound) > 0.3  # the landmark often helps (where it crosses the others)


def test_cones_of_inconsistent_bearings_empty_the_set():
    landmarks = np.array([[0.0, 0.0], [10.0, 0.0]])
    vertices, count = bounded.box(np.array([-20.0, -20.0, 20.0, 20.0]), 1)
    # both landmarks seen in the same direction: no point lies in both cones
    vertices, count = bounded.intersect_cones(
        vertices, count, landmarks, np.array([[0.0, math.pi]]), np.ones((1, 2), bool), math.radians(1.0)
    )
    assert count[0] == 0
    x_hat, error = bounded.centre(vertices, count)
    assert np.isnan(x_hat).all() and np.isinf(error).all()


def pace_case(seed: int, r: int = 400):
    """``r`` robots in random cells (barrier rows of random convex polygons, some rows scaled), with random
    estimates near the faces, error bounds, step directions and step errors."""
    rng = np.random.default_rng(seed)
    vertices, count = random_polygons(seed, r, 7)
    width = vertices.shape[1]
    A, b = np.zeros((r, width, 2)), np.full((r, width), np.inf)
    for i in range(r):
        ring = vertices[i, : count[i]]
        edge = np.roll(ring, -1, axis=0) - ring
        n = np.column_stack([edge[:, 1], -edge[:, 0]]) / np.hypot(edge[:, 0], edge[:, 1])[:, None]  # outward
        scale = rng.choice([1.0, 2.5], len(ring))  # h = A·x + b ≥ 0 inside; rows need not be unit
        A[i, : len(ring)] = -n * scale[:, None]
        b[i, : len(ring)] = np.einsum("ij,ij->i", n, ring) * scale
    inside = np.array([polygon(vertices, count, i).representative_point().coords[0] for i in range(r)])
    near = vertices[np.arange(r), rng.integers(0, count)]  # toward a vertex: close to two faces
    x_hat = near + rng.uniform(0.0, 1.0, (r, 1)) ** 3 * (inside - near)
    angle = rng.uniform(-np.pi, np.pi, r)
    direction = np.column_stack([np.cos(angle), np.sin(angle)])
    error = rng.uniform(0.0, 0.2, r) * rng.uniform(0.0, 1.0, r)
    step = rng.uniform(0.05, 0.5)
    motion = StepError(step, rng.uniform(0.0, 0.1), rng.uniform(0.0, 0.02), rng.uniform(0.0, 0.3, r) * step**2)
    arrays = SimpleNamespace(bar_A=A, bar_b=b)
    return arrays, np.arange(r), x_hat, error, direction, motion


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_certified_pace_keeps_every_truth_in_its_cell_and_is_the_largest(seed):
    """§12.3's step check: whatever the truth within ``e`` of ``x̂`` in the cell, and whatever the step's error
    within ``w(p)``, a step at the pace returned ends in the cell (checked on sampled truths, pushed by the
    largest error against each face in turn); and no larger pace passes the rows (checked on a fine grid)."""
    arrays, cell, x_hat, error, direction, motion = pace_case(seed)
    pace = certified_pace(arrays, cell, x_hat, error, direction, motion)
    assert np.all((pace >= 0.0) & (pace <= 1.0))
    rng = np.random.default_rng(seed + 10)
    A, b = arrays.bar_A, arrays.bar_b
    real = np.isfinite(b)
    norm = np.hypot(A[..., 0], A[..., 1])
    w = motion.at(pace)
    moved = 0
    for i in np.flatnonzero(pace > 0.0):
        # truths: points of the disc B(x̂, e) that lie in the cell (the induction hypothesis)
        angle, radius = rng.uniform(-np.pi, np.pi, 300), error[i] * np.sqrt(rng.uniform(0.0, 1.0, 300))
        x = x_hat[i] + radius[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])
        x = np.vstack([x, x_hat[i] + error[i] * np.column_stack([np.cos(angle), np.sin(angle)])])
        h = x @ A[i][real[i]].T + b[i][real[i]]
        x = x[np.all(h >= 0.0, axis=1)]
        if not len(x):
            continue
        moved += 1
        rows = A[i][real[i]] / norm[i][real[i], None]
        for push in rows:  # the step's error, as large as allowed, straight out of each face in turn
            after = x + pace[i] * motion.step * direction[i] - w[i] * push
            h_after = after @ A[i][real[i]].T + b[i][real[i]]
            assert np.all(h_after >= -1e-9 * (1.0 + np.abs(b[i][real[i]]))), (seed, i)
    assert moved > 50
    # the largest: every grid pace above the one returned fails some row's exact test
    grid = np.linspace(0.0, 1.0, 2001)[1:]
    depth = np.where(real, np.maximum(np.einsum("rqi,ri->rq", A, x_hat) + b - error[:, None] * norm, 0.0), np.inf)
    inward = np.einsum("rqi,ri->rq", A, direction)
    for i in range(len(pace)):
        w_grid = motion.floor + motion.slip * grid * motion.step + grid**2 * motion.curvature[i]
        f = depth[i][None, :] + grid[:, None] * motion.step * inward[i][None, :] - w_grid[:, None] * norm[i][None, :]
        ok = np.all(f[:, real[i]] >= 0.0, axis=1)
        best = grid[np.flatnonzero(ok)].max(initial=0.0)
        assert best <= pace[i] + 1e-3, (seed, i, best, pace[i])


def test_a_step_along_a_near_face_goes_at_full_pace():
    """The unit square, ``x̂`` 3 cm above its floor with ``e`` = 1 cm, a step of 10 cm along the floor: the truth
    stays at least 2 cm above it, more than the step's error ``w`` = 4 mm, so the whole step is certified. (The
    rule before asked a row nearer than ``ℓ + w`` for an inward step of ``w/ℓ`` and allowed 16% of it.) Toward
    the floor, only the part of the step that the 1.6 cm of room allows."""
    A = np.array([[[0.0, 1.0], [-1.0, 0.0], [0.0, -1.0], [1.0, 0.0]]])
    arrays = SimpleNamespace(bar_A=A, bar_b=np.array([[0.0, 1.0, 1.0, 0.0]]))
    motion = StepError(0.1, 0.03, 0.001, np.zeros(1))
    along = certified_pace(
        arrays, np.zeros(1, int), np.array([[0.5, 0.03]]), np.array([0.01]), np.array([[1.0, 0.0]]), motion
    )
    assert along[0] == 1.0
    down = certified_pace(
        arrays, np.zeros(1, int), np.array([[0.5, 0.03]]), np.array([0.01]), np.array([[0.0, -1.0]]), motion
    )
    # 0.02 − p·0.1 − (0.001 + 0.003p) ≥ 0
    assert down[0] == pytest.approx(0.019 / 0.103, rel=1e-6)


@pytest.mark.parametrize("seed", [1, 4])
def test_the_cell_holding_a_set_is_the_least_rank_cell_that_contains_it(seed):
    """``least_rank_cell_holding`` against shapely on small random sets all over a random plan: the cell it names
    contains the set (grown by the margin), no cell of lower rank does, and ``-1`` only where no cell does. Sets
    across the boundary between two cells are among them: there a third cell, or none, holds the set."""
    from bearnav_cli.runtime import least_rank_cell_holding

    plan = random_plan(seed)
    arrays = PlanArrays.from_plan(plan)
    vertices, count = random_polygons(seed, r=300)
    rng = np.random.default_rng(seed)
    lo, hi = arrays.bounds[:2], arrays.bounds[2:]
    size = 0.01 * float(np.hypot(*(hi - lo)))
    centre = rng.uniform(lo, hi, size=(len(count), 2))
    vertices = centre[:, None, :] + size * vertices / 3.0
    margin = rng.choice([0.0, 0.2 * size], len(count))
    x = vertices[:, 0, :]  # a vertex of each set: the estimate may lie anywhere in it
    found = least_rank_cell_holding(arrays, x, vertices, count, margin)
    cells = [
        shapely.Polygon(arrays.cell_vertices[arrays.cell_vertex_offsets[c] : arrays.cell_vertex_offsets[c + 1]])
        for c in range(len(arrays.cell_node))
    ]
    order = np.lexsort((np.arange(len(cells)), arrays.cell_rank))
    shrink = 1e-9 * float(np.hypot(*(hi - lo)))
    for i in range(len(count)):
        grown = polygon(vertices, count, i).buffer(margin[i] - shrink, join_style="mitre")
        holding = [c for c in order if cells[c].contains(grown)]
        if found[i] >= 0:
            assert cells[found[i]].buffer(shrink).contains(polygon(vertices, count, i).buffer(margin[i] * 0.999))
            assert not holding or arrays.cell_rank[holding[0]] >= arrays.cell_rank[found[i]]
        else:
            assert not holding
    assert (found >= 0).sum() > 0.3 * len(count)
    straddling = [i for i in range(len(count)) if least_rank_cell(arrays, x[i : i + 1], margin[i] + size)[0] < 0]
    assert straddling and any(found[i] >= 0 for i in straddling)


@pytest.mark.parametrize("seed", [1, 4])
def test_the_tolerance_at_a_set_keeps_the_certificate_at_every_truth_in_it(seed):
    """``runtime.tolerance.set_tolerance`` on small random sets in every cell of a random plan: for truths drawn in
    each set (vertices included) and estimates at that distance in every direction, the barrier rows (L1) and the
    progress row (L2, rate 0) hold at the truth with the field at the estimate; it is never below ``τ_c``; and a set
    within reach of the exit face gets no more than ``δ_e,c / 2`` beyond ``τ_c`` (the switch, Theorem 2)."""
    from bearnav_cli.runtime.tolerance import set_tolerance

    plan = random_plan(seed)
    arrays = PlanArrays.from_plan(plan)
    rng = np.random.default_rng(seed)
    cells = np.flatnonzero(np.isfinite(arrays.exit_inset))  # every edge cell (the goal cell keeps τ_c)
    k = np.repeat(cells, 6)
    size = 0.02 * float(np.hypot(*(arrays.bounds[2:] - arrays.bounds[:2])))
    vertices, count = random_polygons(seed, r=len(k), points=6)
    # each set around a random point of its cell, shrunk until every vertex lies in the cell
    starts = arrays.cell_vertex_offsets
    corners = [arrays.cell_vertices[starts[c] : starts[c + 1]] for c in k]
    centre = np.array([rng.dirichlet(np.ones(len(w))) @ w for w in corners])
    scale = np.full(len(k), size / 3.0)
    for _ in range(40):
        pts = centre[:, None, :] + scale[:, None, None] * vertices
        inside = bounded.inside_rows(pts, count, arrays.row_A[k], arrays.row_b[k])
        scale = np.where(inside, scale, 0.5 * scale)
    pts = centre[:, None, :] + scale[:, None, None] * vertices
    assert bounded.inside_rows(pts, count, arrays.row_A[k], arrays.row_b[k]).all()
    reach = rng.choice([0.0, size], len(k))
    valid = bounded.valid_vertices(pts, count)
    tau = set_tolerance(arrays, k, pts, valid, 0.0, reach)
    assert np.all(tau >= arrays.tolerance_in(k) * (1 - 1e-12))
    assert np.any(tau > 1.5 * arrays.tolerance_in(k))  # away from the faces and the exit a cell tolerates more
    depth = np.min(
        np.where(valid, np.einsum("ri,rwi->rw", arrays.exit_dir[k], pts - arrays.exit_point[k][:, None]), np.inf), 1
    )
    near = depth <= reach
    assert np.all(tau[near] <= np.maximum(0.5 * arrays.exit_inset[k[near]], arrays.tolerance_in(k[near])) * (1 + 1e-12))
    # truths: the vertices and random points of each set; estimates τ away from them, in 16 directions
    weights = rng.dirichlet(np.ones(6), size=(len(k), 4)) * valid[:, None, :]
    weights /= weights.sum(axis=2, keepdims=True)
    truths = np.concatenate([pts, np.einsum("rtw,rwi->rti", weights, pts)], axis=1)
    use = np.concatenate([valid, np.ones((len(k), 4), bool)], axis=1)
    angle = np.linspace(0.0, 2.0 * math.pi, 16, endpoint=False)
    turn = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    x = truths[:, :, None, :]
    x_hat = x + tau[:, None, None, None] * turn[None, None]
    u = arrays.field_a[k][:, None, None, :] - np.einsum("rij,rtdj->rtdi", arrays.field_M[k], x_hat)
    scale_u = np.abs(arrays.field_a[k]).max(axis=1) + 1.0
    n, q = arrays.bar_A[k], arrays.bar_b[k]
    real = np.isfinite(q)
    h = np.einsum("rqi,rti->rtq", n, truths) + np.where(real, q, 0.0)[:, None, :]
    barrier = np.einsum("rqi,rtdi->rtdq", n, u) + arrays.c_h[k][:, None, None, None] * h[:, :, None, :]
    barrier = np.where(real[:, None, None, :] & use[:, :, None, None], barrier, np.inf)
    assert barrier.min() >= -1e-9 * scale_u.max(), barrier.min()
    progress = np.einsum("ri,rtdi->rtd", arrays.exit_dir[k], u)
    progress = np.where(use[:, :, None], progress, -np.inf)
    assert progress.max() <= 1e-9 * scale_u.max(), progress.max()


LOOP_CASES = [(seed, worst, fov, None) for seed in (1, 4) for worst in (False, True) for fov in (360.0, 60.0)]
# a compass that errs by up to 2° on top of the camera's 0.25°: a bias per run, ±2° under the worst case
LOOP_CASES += [(1, False, 60.0, 2.0), (4, True, 60.0, 2.0)]


@pytest.mark.parametrize("seed,worst,fov,compass", LOOP_CASES)
def test_the_set_estimator_keeps_the_truth_and_the_certificate(seed, worst, fov, compass):
    """estimator = set under bounded noise: no collision, no step with the truth outside its set, no empty set,
    and every certified step ends in the certified domain D (Theorem 2, in discrete time); with a compass that
    errs too, the heading the bearings bound (``common_rotation``) keeps all of it."""
    plan = random_plan(seed)
    arrays = PlanArrays.from_plan(plan)
    params = simulate.Params(
        estimator="set",
        noise_bound_deg=0.25,
        noise_worst=worst,
        fov=fov,
        compass_error_deg=compass,
        starts="domain:12",
        seed=seed,
        record_trajectories=False,
    )
    outside = []

    def watch(runs, x, certified):
        left = certified & (least_rank_cell(arrays, x) < 0)
        outside.extend(runs[left].tolist())

    sim = simulate.rollout(plan, simulate.resolve_starts(plan, params), params, on_step=watch, arrays=arrays)
    counts = sim.stats["estimator_counts"]
    assert counts["containment_violations"] == 0 and counts["inconsistencies"] == 0
    assert sim.counts()["collision"] == 0
    assert not outside
    assert sim.certified_steps.sum() > 0
    assert sim.certified_steps.sum() <= counts["moved_steps"]


def test_a_broken_bound_is_counted_not_a_crash():
    """Gaussian noise far beyond the assumed bound: empty sets are counted and the runs end normally."""
    plan = random_plan(1)
    params = simulate.Params(
        estimator="set", noise_deg=3.0, bearing_error_deg=0.05, starts="domain:6", record_trajectories=False
    )
    sim = simulate.run(plan, params)
    assert sim.stats["inconsistencies"] > 0
    assert sim.stats["containment_violations"] >= 0
    assert len(sim) == 6


def test_a_broken_bound_is_widened_to_the_least_doubling_that_holds_the_bearings():
    """Bearings that err by 3η (the truth outside every cone of half-angle η): the set comes out empty, the
    robot restarts from the bearing sets alone at the least doubling of η for which they meet (4η, which
    holds the truth), and keeps that bound for the next steps."""
    from bearnav_cli.runtime import ControlState
    from bearnav_cli.runtime.estimate import bounded_update

    plan = random_plan(1)
    arrays = PlanArrays.from_plan(plan)
    s = simulate.settings(plan, simulate.Params(estimator="set", bearing_error_deg=0.2, noise_bound_deg=0.2)).control
    eta = s.bearing_bound
    rng = np.random.default_rng(5)
    x = arrays.nodes[rng.choice(len(arrays.nodes), 40)]
    r, lm = len(x), len(arrays.landmarks)
    visible = np.ones((r, lm), bool)
    true_angle = np.arctan2(arrays.landmarks[None, :, 1] - x[:, None, 1], arrays.landmarks[None, :, 0] - x[:, None, 0])

    def bearings(angle):
        return np.stack([np.cos(angle), np.sin(angle)], axis=-1)

    state = ControlState.initial(np.zeros(r))
    first = bounded_update(arrays, s, state, bearings(true_angle), visible, None)
    state.set_vertices, state.set_count, state.known = first.vertices, first.count, np.ones(r, bool)
    assert not first.inconsistent.any() and np.all(first.bound_scale == 1.0)
    # every bearing off by 3η, alternating in sign: the cones of half-angle η no longer meet
    off = 3.0 * eta * np.where(np.arange(lm) % 2 == 0, 1.0, -1.0)
    broken = bounded_update(arrays, s, state, bearings(true_angle + off), visible, None)
    assert broken.inconsistent.all()
    assert np.all(broken.bound_scale == 4.0)  # 2η is still broken, 4η holds every bearing
    assert bounded.contains(broken.vertices, broken.count, x, 1e-9).all()
    state.set_vertices, state.set_count, state.bound_scale = broken.vertices, broken.count, broken.bound_scale
    again = bounded_update(arrays, s, state, bearings(true_angle + off), visible, None)
    assert not again.inconsistent.any() and np.all(again.bound_scale == 4.0)
    assert bounded.contains(again.vertices, again.count, x, 1e-9).all()


@pytest.mark.parametrize("value", [-0.1, math.inf, 45.0, math.nan])
def test_a_bad_noise_bound_names_the_field(value):
    from bearnav_cli.errors import InvalidParamsError

    with pytest.raises(InvalidParamsError) as info:
        simulate.Params(noise_bound_deg=value)
    assert info.value.field == "noise_bound_deg"


def lookahead_plan():
    """The plan of ``funnel_maps.random_spec(4)`` for a look-ahead unicycle, ``λ = 0.1`` (once per process)."""
    return random_plan(4, 0.1)


def lookahead_params(**options) -> simulate.Params:
    """The set estimator's look-ahead unicycle with a 60° camera and bearings within 0.25°, and ``options``."""
    return simulate.Params(
        estimator="set", dynamics="unicycle", noise_bound_deg=0.25, fov=60.0, record_trajectories=False, **options
    )


@pytest.mark.parametrize(("worst", "compass"), [(False, None), (True, None), (False, 2.0), (True, 2.0)])
def test_the_look_ahead_unicycle_under_the_set_estimator(worst, compass):
    """A look-ahead unicycle (ALGORITHMS §12.6) with a 60° camera: the look swings its point around the axle,
    and still no certified step ends outside D, the truth never leaves its set, nothing collides; with a compass
    that errs by up to 2°, its point's estimate and every command turn with the heading it reads."""
    plan = lookahead_plan()
    arrays = PlanArrays.from_plan(plan)
    assert arrays.lookahead == pytest.approx(0.1)
    # safety, not arrival, is asserted: 8 starts for their first 600 steps (most look around for most of a run)
    params = lookahead_params(noise_worst=worst, compass_error_deg=compass, starts="domain:8", max_steps=600)
    outside = []

    def watch(runs, x, certified):
        outside.extend(runs[certified & (least_rank_cell(arrays, x) < 0)].tolist())

    sim = simulate.rollout(plan, simulate.resolve_starts(plan, params), params, on_step=watch, arrays=arrays)
    assert sim.stats["estimator_counts"]["containment_violations"] == 0
    assert sim.counts()["collision"] == 0 and not outside
    assert sim.certified_steps.sum() > 0


def test_a_look_ahead_unicycle_at_the_edge_of_d():
    """Starts where the set estimator's rules meet the edge of D: the cells' corners on it, pulled 1% toward the
    centre; worst-case bearings, every step of the first 150.

    - Every certified step ends inside the cell it drove in (Theorem 2, (L1)): the truth is in that cell. Two
      rules gave a robot a cell without that: an approach arriving near its node, and the uncertified step at
      the edge of D, whose cell the next step took for the robot's (bugs this test caught, 3 cm outside).
    - A start in D whose set no cell holds looks until one does (ALGORITHMS §12.3 step 4); only once its look
      has turned through every heading (a 60° camera: at least 300°) since its last certified step may it take
      the uncertified steps at the edge of D (the straight approach to a node is another rule's). A look that
      ended after one step, turned back and began again never turned past its first view (a bug this test
      caught)."""
    plan = lookahead_plan()
    arrays = PlanArrays.from_plan(plan)
    cells = cell_polygons(plan.cells)
    edge = shapely.union_all(cells).boundary
    corners = np.vstack(
        [np.asarray(c.exterior.coords)[:-1] * 0.99 + 0.01 * np.asarray(c.centroid.coords) for c in cells]
    )
    starts = corners[shapely.distance(edge, shapely.points(corners)) < 0.02][:60]
    params = lookahead_params(noise_worst=True)
    loop, active, _ = simulate.start_loop(plan, starts, params)
    r = len(loop.x)
    # the headings each run has faced since its last certified step: an interval of the unwrapped heading (a run
    # that took an uncertified step at the edge of D drives on so, without looking again, until it is certified)
    low, high, unwrapped = loop.phi.copy(), loop.phi.copy(), loop.phi.copy()
    for _ in range(150):
        if not active.size:
            break
        x, phi, certified = loop.x.copy(), loop.phi.copy(), loop.certified.copy()
        active = loop.step(active)
        unwrapped = unwrapped + np.angle(np.exp(1j * (loop.phi - phi)))
        moved = np.hypot(*(loop.x - x).T) > 0.0
        sure = np.flatnonzero(moved & (loop.certified > certified))
        depth = cell_slack(arrays, loop.state.cell[sure], loop.reference(loop.x[sure], loop.phi[sure]))
        assert np.all(depth >= -arrays.tol), depth.min()
        # the uncertified steps of a robot without a cell (not those of the straight approach to a node)
        bad = np.flatnonzero(moved & (loop.certified == certified) & (loop.state.target < 0))
        span = high[bad] - low[bad]
        assert np.all(span >= math.radians(360.0 - params.fov) - 1e-9), np.degrees(span)
        low, high = np.minimum(low, unwrapped), np.maximum(high, unwrapped)
        low[sure], high[sure] = unwrapped[sure], unwrapped[sure]
    assert r >= 40 and loop.certified.sum() > 0


def test_an_estimate_trace_holds_the_truth_and_draws(tmp_path):
    """``simulate.estimate_trace`` records sets that hold the truth within their error radius; the plot draws them."""
    from bearnav_cli import plot

    plan = random_plan(1)
    params = simulate.Params(estimator="set", fov=60.0, noise_bound_deg=0.25, record_trajectories=False)
    start = simulate.resolve_starts(plan, simulate.Params(starts="domain:1", seed=3))[0]
    trace = simulate.estimate_trace(plan, start, params, every=5)
    k = len(trace.error)
    assert k > 0 and len(trace.set_offsets) == k + 1 and trace.set_offsets[-1] == len(trace.set_coords)
    for i in range(k):
        ring = trace.set_coords[trace.set_offsets[i] : trace.set_offsets[i + 1]]
        assert shapely.Polygon(ring).buffer(1e-7).contains(shapely.Point(trace.truth[i]))
        assert np.hypot(*(trace.truth[i] - trace.x_hat[i])) <= trace.error[i] + 1e-9
    plot.use_file_backend()
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    plot.plot_estimate_trace(ax, trace, scale=10.0)
    assert len(ax.patches) >= 1
    plt.close(fig)
    from bearnav_cli.errors import InvalidParamsError

    with pytest.raises(InvalidParamsError):
        simulate.estimate_trace(plan, start, simulate.Params(estimator="kalman"))
