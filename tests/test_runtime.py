"""The robot-side runtime (cell location, switching, field) and the closed loop built on it (ALGORITHMS §7)."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from bearnav_cli import runtime
from bearnav_cli.datatypes import Cells, Outcome, Plan, Simulation
from bearnav_cli.errors import ArtifactError
from bearnav_cli.runtime import PlanArrays
from bearnav_cli.stages import simulate

from .conftest import REPO
from .handmade import (
    CHAIN_NODES,
    CHAIN_PARENT,
    cell_polygons,
    first_plan_cells,
    hand_map,
    hand_plan,
    write_plan,
)
from .test_hostile_common import rewrite_npz

#: The exact motion of ALGORITHMS §7.1 (no wheel slip), for tests of exact paths.
EXACT = simulate.Params(odometry_noise=0.0)
#: A field that pushes +x everywhere (it breaks the CLF of a cell whose exit lies at −x).
RIGHT = (np.zeros((2, 2)), np.array([1.0, 0.0]))
LEFT = (np.zeros((2, 2)), np.array([-1.0, 0.0]))


@pytest.fixture(scope="module")
def chain() -> Plan:
    """Root (1, 1) ← node 1 (5, 1) ← node 2 (9, 1); cells x ≤ 3, 1 ≤ x ≤ 7, x ≥ 5 on [0,10]×[0,8]."""
    return hand_plan(hand_map())


@pytest.fixture(scope="module")
def arrays(chain) -> PlanArrays:
    return PlanArrays.from_plan(chain)


def test_runtime_imports_with_numpy_only():
    code = (
        "import bearnav_cli.runtime, sys; "
        "bad = [m for m in sys.modules if m.split('.')[0] in ('scipy', 'shapely', 'matplotlib', 'yaml', 'typer')]; "
        "assert not bad, bad; "
        "assert not [m for m in sys.modules if m.startswith('bearnav_cli.') and m != 'bearnav_cli.errors' "
        "and m.split('.')[1] != 'runtime']"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)


def test_chain_cells_are_as_designed(chain):
    cells = chain.cells
    spans = [(cells.vertices(c)[:, 0].min(), cells.vertices(c)[:, 0].max()) for c in range(3)]
    assert spans == [(0.0, 3.0), (1.0, 7.0), (5.0, 10.0)]
    assert chain.status.tolist() == [4, 0, 0]


def test_from_npz_equals_from_plan(chain, arrays, tmp_path):
    path = write_plan(tmp_path / "plan.npz", chain)
    loaded = PlanArrays.from_npz(path)
    for name in runtime.RUNTIME_KEYS + ("bounds", "goal", "node_cell", "parent_cell", "field_a", "field_M"):
        ours, theirs = np.asarray(getattr(loaded, name)), np.asarray(getattr(arrays, name))
        assert np.array_equal(ours, theirs, equal_nan=ours.dtype.kind == "f"), name
    assert loaded.tol == arrays.tol and loaded.goal_cell == 0


def test_from_npz_names_a_missing_entry(chain, tmp_path):
    good = write_plan(tmp_path / "good.npz", chain)
    path = rewrite_npz(good, tmp_path / "plan.npz", lambda manifest, entries: entries.__delitem__("gain"))
    with pytest.raises(ArtifactError, match="gain: missing entry"):
        PlanArrays.from_npz(path)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ArtifactError, match="not an npz archive"):
        PlanArrays.from_npz(tmp_path / "junk.npz")


def test_every_node_needs_a_cell(chain):
    with pytest.raises(ArtifactError, match="exactly one cell"):
        PlanArrays.from_plan(first_plan_cells(chain, 2))


def test_field_is_the_gain_applied_to_displacements(chain, arrays):
    rng = np.random.default_rng(1)
    x = rng.uniform((0, 0), (10, 8), (50, 2))
    cell = rng.integers(0, 3, 50)
    u = runtime.field(arrays, cell, x)
    for r in range(50):
        assert np.allclose(u[r], chain.gain[cell[r]] @ (chain.landmarks - x[r]).ravel(), atol=1e-12)
    assert np.allclose(runtime.affine_field(arrays, cell, x), u, atol=1e-12)
    # the default chain fields point at each cell's exit point
    assert np.allclose(runtime.field(arrays, [2], [[9.0, 4.0]]), [[-4 / 7, -3 / 7]], atol=1e-12)


def test_voronoi_owner_contains_the_point_on_random_trees():
    """Lemma 2: the nearest node's cell contains the point, on random trees and points."""
    rng = np.random.default_rng(7)
    for _ in range(5):
        nodes = rng.uniform((0.5, 0.5), (9.5, 7.5), (12, 2))
        parent = np.array([-1] + [int(rng.integers(0, i)) for i in range(1, 12)])
        map_ = hand_map(goal=nodes[0])
        plan = hand_plan(map_, nodes, parent, polygons=cell_polygons(nodes, parent, map_.bounds))
        arr = PlanArrays.from_plan(plan)
        x = rng.uniform((0, 0), (10, 8), (2000, 2))
        owner = runtime.voronoi_owner(arr, x)
        assert np.all(owner == np.argmin(((x[:, None] - nodes[None]) ** 2).sum(-1), axis=1))
        assert runtime.contains(arr, owner, x).all()
        # every node lies in its own cell and in its child's cells
        assert runtime.contains(arr, np.arange(12), nodes).all()
        assert runtime.contains(arr, np.arange(1, 12), nodes[parent[1:]]).all()


def test_contains_uses_the_tolerance(arrays):
    x = np.array([[7.0 + 0.5e-9, 4.0], [7.0 + 1e-6, 4.0]])
    assert runtime.contains(arrays, [1, 1], x).tolist() == [True, False]
    assert runtime.contains(arrays, [1, 1], x, tol=1e-5).tolist() == [True, True]


def test_switch_hands_over_at_the_exit_face(arrays):
    x = np.array([[5.01, 4.0], [4.99, 4.0], [5.0, 4.0], [5.03, 1.0], [5.05, 1.0]])
    cell, moved = runtime.switch(arrays, np.full(5, 2), x, eps_sw=0.04)
    # V > 0 far from x_j stays; V < 0 and V = 0 hand over; within eps_sw of x_j hands over
    assert cell.tolist() == [2, 1, 1, 1, 2]
    assert not moved.any()
    # the goal cell never switches; one switch per call, although (1.005, 1) is also within
    # eps_sw of cell 1's exit point
    cell, moved = runtime.switch(arrays, [0, 2], [[0.5, 0.5], [1.005, 1.0]], eps_sw=0.04)
    assert cell.tolist() == [0, 1] and not moved.any()


def test_switch_relocates_a_robot_outside_its_cell(arrays):
    # cell 1 is 1 <= x <= 7: (8, 4) has V > 0 and is far from x_j, but outside the cell
    cell, moved = runtime.switch(arrays, [1, 1], [[8.0, 4.0], [6.0, 4.0]], eps_sw=0.04)
    assert cell.tolist() == [2, 1]
    assert moved.tolist() == [True, False]
    # after a hand-over the new cell is tested too: cell 2 → 1 at x = 0.5 < 1 is outside cell 1
    cell, moved = runtime.switch(arrays, [2], [[0.5, 6.0]], eps_sw=0.04)
    assert cell.tolist() == [0] and moved.tolist() == [True]


def test_locate_prefers_a_cell_whose_safe_set_holds_the_point():
    """Safety first, then the shortest route; otherwise the least violated cell; always a cell holding x."""
    from bearnav_cli.geometry import FreeSpace
    from bearnav_cli.routes import sample_starts
    from bearnav_cli.stages import decompose, rrtstar, simplify, synthesize

    from .conftest import SMALL_MAP, build_map

    small = build_map(dict(SMALL_MAP))
    tree = simplify.run(rrtstar.run(small, rrtstar.Params(iterations=600, step=1.0, seed=2)))
    plan = synthesize.run(decompose.run(tree, decompose.Params(cells="paper")))  # safe sets are a paper notion
    arr = PlanArrays.from_plan(plan)
    x = sample_starts(FreeSpace.from_map(small), small.goal, 400, np.random.default_rng(3))
    cell = runtime.locate(arr, x)
    assert runtime.contains(arr, cell, x).all()
    h = runtime.barrier_values(arr, x)  # (R, C)
    inside = np.all(np.einsum("cpk,rk->rcp", arr.row_A, x) <= arr.row_b[None] + arr.tol, axis=2)
    rows = np.arange(len(x))
    some_safe = (inside & (h >= 0)).any(axis=1)
    assert some_safe.mean() > 0.5
    assert np.all(h[rows, cell][some_safe] >= 0)  # a safe cell whenever one exists
    # otherwise the chosen cell violates its rows least among the cells holding x
    worst = np.where(inside, h, -np.inf).max(axis=1)
    assert np.all(h[rows, cell][~some_safe] >= worst[~some_safe] - 1e-12)


def test_segments_clear_is_exact_and_counts_touching():
    square = [[4.0, 3.0], [6.0, 3.0], [6.0, 5.0], [4.0, 5.0]]
    plan = hand_plan(hand_map(obstacles=[square]))
    arr = PlanArrays.from_plan(plan)
    a = np.array([[1.0, 4.0], [1.0, 4.0], [1.0, 5.0], [1.0, 6.0], [1.0, 2.0], [4.0, 1.0], [9.0, 4.0]])
    b = np.array([[9.0, 4.0], [3.9, 4.0], [9.0, 5.0], [9.0, 6.0], [9.0, 3.6], [4.0, 2.9], [11.0, 4.0]])
    # through it | short of it | along its top edge (touching) | above it | through the corner (6, 3)
    # | ending just below | leaving the bounds
    assert runtime.segments_clear(arr, a, b).tolist() == [False, True, False, True, False, True, False]
    # the same answers as the exact shapely test of the planning stages
    from bearnav_cli.geometry import FreeSpace

    rng = np.random.default_rng(4)
    p, q = rng.uniform(0, 10, (400, 2)), rng.uniform(0, 8, (400, 2))
    space = FreeSpace.from_map(plan.map)
    free = space.points_free(p) & space.points_free(q)
    assert np.array_equal(runtime.segments_clear(arr, p[free], q[free]), space.segments_free(p[free], q[free]))


def test_a_robot_outside_every_safe_set_drives_straight_to_a_visible_node():
    """The approach rule: outside every safe set, the target is a node with a clear segment on the
    shortest route; arriving there (or entering a safe set) hands back to the certified fields."""
    from bearnav_cli.geometry import FreeSpace
    from bearnav_cli.routes import sample_starts
    from bearnav_cli.stages import decompose, rrtstar, simplify, synthesize

    from .conftest import SMALL_MAP, build_map

    small = build_map(dict(SMALL_MAP))
    plan = synthesize.run(decompose.run(simplify.run(rrtstar.run(small, rrtstar.Params(iterations=600, seed=2)))))
    arr = PlanArrays.from_plan(plan)
    space = FreeSpace.from_map(small)
    x = sample_starts(space, small.goal, 300, np.random.default_rng(5))
    cell, target, moved = runtime.update(arr, np.full(len(x), -1), np.full(len(x), -1), x, eps_sw=0.05)
    assert not moved.any()
    safe = runtime.in_safe_set(arr, cell, x)
    going = target >= 0
    assert not (safe & going).any()  # a certified robot never approaches
    assert going.any() and safe.any()
    assert space.segments_free(x[going], arr.nodes[target[going]]).all()  # exact shapely check
    # a robot at its target node is handed to a cell whose safe set holds it
    at = arr.nodes[target[going]]
    cell2, target2, _ = runtime.update(arr, cell[going], target[going], at, eps_sw=0.05)
    assert (target2 == -1).all() and runtime.in_safe_set(arr, cell2, at).all()


# --------------------------------------------------------------------------- the closed loop


def test_chain_runs_reach_the_goal(chain):
    starts = np.array([[9.5, 7.5], [6.0, 0.2], [2.0, 7.9], [0.1, 0.1], [1.0, 1.05]])
    # with the default wheel slip (2%) every step is a few percent off its command ...
    slipped = simulate.rollout(chain, starts)
    assert slipped.outcome.tolist() == [Outcome.SUCCESS] * 5
    per_step = slipped.path_length[:-1] / (slipped.steps[:-1] * slipped.speed * slipped.dt)
    assert np.all(np.abs(per_step - 1.0) < 0.1) and not np.allclose(per_step, 1.0)
    # ... exactly on it with the exact motion of §7.1
    out = simulate.rollout(chain, starts, EXACT)
    # the one type of a set of runs (sim.npz's); its stats are the estimator's counts alone
    assert isinstance(out, Simulation) and set(out.stats) == {"estimator_counts"}
    assert out.outcome.tolist() == [Outcome.SUCCESS] * 5
    assert out.steps[-1] == 0 and out.path_length[-1] == 0.0  # starts inside the goal tolerance
    v_dt = out.speed * out.dt
    assert out.dt == pytest.approx(0.2) and out.eps_sw == pytest.approx(2 * v_dt)
    assert np.allclose(out.path_length, out.steps * v_dt)
    assert np.allclose(out.time, out.steps * out.dt)
    for r in range(5):
        path = out.trajectory(r)
        assert len(path) == out.steps[r] + 1 and np.array_equal(path[0], starts[r])
        assert np.linalg.norm(path[-1] - chain.map.goal) <= out.goal_tolerance
    # run 0 follows the tree: cell 2, then cell 1 (whose exit point is the goal itself)
    cells = out.cells_along(0)
    assert cells[0] == 2 and cells[-1] in (0, 1) and np.all(np.diff(cells) <= 0)
    assert out.left_cell.sum() == 0
    assert simulate.summary(out) == "5/5 runs reached the goal"


def test_a_crossing_of_the_exit_face_switches_on_that_step():
    plan = hand_plan(hand_map(), fields={2: LEFT})
    out = simulate.rollout(plan, [[9.01, 4.0]])
    path, cells = out.trajectory(0), out.cells_along(0)
    first_beyond = int(np.argmax(path[:, 0] < 5.0))  # first point past the exit line x = 5
    assert path[first_beyond - 1, 0] > 5.0
    assert cells[first_beyond - 1] == 2 and cells[first_beyond] == 1
    assert out.outcome[0] == Outcome.SUCCESS and out.left_cell[0] == 0


def test_a_robot_outside_its_cell_is_relocated():
    """Cell 1 pushes +x (no certificate): the robot leaves cell 1 through x = 7 and is relocated."""
    plan = hand_plan(hand_map(), fields={1: RIGHT})
    out = simulate.rollout(plan, [[6.905, 4.0]], simulate.Params(max_steps=60))
    path, cells = out.trajectory(0), out.cells_along(0)
    assert cells[0] == 1
    out_of_cell = int(np.argmax(path[:, 0] > 7.0))
    assert cells[out_of_cell - 1] == 1 and cells[out_of_cell] == 2  # Voronoi owner: node 2
    assert out.left_cell[0] >= 1
    # the same through the runtime alone, one call
    cell, moved = runtime.switch(PlanArrays.from_plan(plan), [1], path[out_of_cell][None], out.eps_sw)
    assert cell.tolist() == [2] and moved.tolist() == [True]


def test_a_step_that_grazes_an_obstacle_corner_is_a_collision():
    """Robot on y = 4 moving −x; a diamond's bottom vertex sits at (6.0031, 4), between two step ends."""
    diamond = [[6.0031, 4.0], [7.0, 5.0], [6.0031, 6.0], [5.5, 5.0]]
    plan = hand_plan(hand_map(obstacles=[diamond]), fields={2: LEFT})
    out = simulate.rollout(plan, [[9.0, 4.0], [9.0, 4.0 - 1e-9]], EXACT)  # exactly along y = 4
    assert out.outcome.tolist() == [Outcome.COLLISION, Outcome.SUCCESS]
    path = out.trajectory(0)
    assert path[-2, 0] > 6.0031 > path[-1, 0]  # the colliding step spans the vertex
    assert path[-1, 1] == 4.0 and out.steps[0] == len(path) - 1
    # no step end is in the obstacle: only the exact segment test sees this
    from bearnav_cli.geometry import FreeSpace

    assert FreeSpace.from_map(plan.map).points_free(path).all()


def test_a_start_that_is_not_free_is_a_collision():
    plan = hand_plan(hand_map(obstacles=[[[6, 3], [7, 3], [7, 4], [6, 4]]]))
    out = simulate.rollout(plan, [[6.5, 3.5], [10.5, 3.0], [9.0, 7.0]])
    assert out.outcome.tolist()[:2] == [Outcome.COLLISION, Outcome.COLLISION]
    assert out.steps[:2].tolist() == [0, 0] and out.final_cell[:2].tolist() == [-1, -1]


def test_stalls_timeouts_and_step_limits():
    # an equilibrium of cell 2's field at e = (8.005, 4): exactly there the field vanishes (stall at
    # once); from (9, 4) the robot chatters between 8.01 and 7.99 with ‖u‖ = 5e-4, making no net
    # progress (stall once the window holds only chatter)
    towards = (np.eye(2) * 0.1, np.array([0.8005, 0.4]))
    plan = hand_plan(hand_map(), fields={2: towards})
    # (the filter's robot: the set estimator's looks where its bound is too large for the cell it is in)
    out = simulate.rollout(plan, [[8.005, 4.0], [9.0, 4.0]], simulate.Params(max_steps=5000, estimator="kalman"))
    assert out.outcome.tolist() == [Outcome.STALL, Outcome.STALL]
    assert out.steps[0] == 0 and simulate.PROGRESS_WINDOW <= out.steps[1] < 2 * simulate.PROGRESS_WINDOW
    # a step limit below the route length: timeout after max_steps + 1 steps
    short = simulate.rollout(hand_plan(hand_map()), [[9.5, 7.5]], simulate.Params(max_steps=10))
    assert short.outcome.tolist() == [Outcome.TIMEOUT] and short.steps.tolist() == [11]
    # the default limit: ceil(5·L_route/(v·dt)) + 1000 with L_route through the nearest node
    default = simulate.rollout(hand_plan(hand_map()), [[9.0, 4.0]])
    assert default.max_steps[0] == int(np.ceil(5 * (3.0 + 8.0) / (0.1 * 0.2))) + 1000


def test_tree_costs_by_pointer_doubling():
    rng = np.random.default_rng(3)
    nodes = rng.uniform(0, 10, (40, 2))
    parent = np.array([-1] + [int(rng.integers(0, i)) for i in range(1, 40)])
    expected = np.zeros(40)
    for i in range(1, 40):
        expected[i] = expected[parent[i]] + np.linalg.norm(nodes[i] - nodes[parent[i]])
    assert np.allclose(runtime.tree_costs(nodes, parent), expected, atol=1e-12)
    assert np.allclose(runtime.tree_costs(CHAIN_NODES, CHAIN_PARENT), [0.0, 4.0, 8.0])


def test_params_are_checked():
    from bearnav_cli.errors import InvalidParamsError

    for kwargs, name in (
        ({"speed": 0}, "speed"),
        ({"dt": -1.0}, "dt"),
        ({"max_steps": 0}, "max_steps"),
        ({"goal_tolerance": 0.0}, "goal_tolerance"),
    ):
        with pytest.raises(InvalidParamsError) as err:
            simulate.Params(**kwargs)
        assert err.value.field == name


def test_without_trajectories_the_figures_are_the_same(chain):
    starts = np.array([[9.5, 7.5], [6.0, 0.2]])
    full = simulate.rollout(chain, starts)
    bare = simulate.rollout(chain, starts, simulate.Params(record_trajectories=False))
    for name in ("outcome", "steps", "path_length", "left_cell", "final_position", "final_cell"):
        assert np.array_equal(getattr(full, name), getattr(bare, name)), name
    assert len(bare.trajectory_coords) == 0 and bare.trajectory_offsets.tolist() == [0, 0, 0]


def test_cells_type_is_the_datatypes_one(chain):
    assert isinstance(chain.cells, Cells)


# --------------------------------------------------------------------------- the step's parts, alone


def _settings(**kw):
    base = dict(speed=0.1, dt=0.2, eps_sw=0.04, tol=1e-9, odometry_drift=0.05, hold_time=2.0, beta=0.5)
    return runtime.ControlSettings(**{**base, **kw})


def test_fuse_takes_an_exact_fix_and_carries_the_estimate_on_odometry_without_one():
    from bearnav_cli.runtime.estimate import Fix, fuse

    s = _settings()
    state = runtime.ControlState.initial(np.zeros(2))
    state.x_hat[:] = [[1.0, 1.0], [2.0, 2.0]]
    state.motion[:] = [[0.1, 0.0], [0.0, 0.1]]
    state.known[:] = True
    state.var[:] = 0.0
    fix = Fix(np.array([[1.02, 1.0], [0.0, 0.0]]), np.array([True, False]), np.zeros(2))
    est = fuse(s, state, fix)
    # robot 0: noise-free fix within the gate replaces the prediction; robot 1: odometry's prediction
    np.testing.assert_allclose(est.x_hat, [[1.02, 1.0], [2.0, 2.02]])
    assert est.fix.tolist() == [True, False] and est.steer.tolist() == [True, True]
    travelled = s.dt * 0.1
    np.testing.assert_allclose(est.var, [0.0, (s.odometry_drift * travelled) ** 2])
    np.testing.assert_allclose(est.error_bound, 3.0 * np.sqrt(est.var))
    np.testing.assert_allclose(est.hold, [0.0, s.dt])


def test_look_around_starts_at_once_without_an_estimate_and_ends_lost_after_a_revolution():
    from bearnav_cli.runtime.estimate import Estimate
    from bearnav_cli.runtime.looking import look_around

    s = _settings()
    state = runtime.ControlState.initial(np.zeros(2))
    no = np.zeros(2, bool)
    for hold, lost in ((s.dt, False), (2 * math.pi / s.beta + 2 * s.dt, True)):
        est = Estimate(
            np.zeros((2, 2)), np.full(2, np.inf), no, np.array([False, True]), no, np.full(2, hold), np.full(2, np.inf)
        )
        scanning, is_lost, spin, turn, _ = look_around(s, state, est, np.array([[0.0, 1.0], [1.0, 0.0]]), np.zeros(2))
        assert scanning.tolist() == [True, False] and is_lost.tolist() == [lost, False]
        assert spin[0] == 1.0 and turn.tolist() == [s.beta, 0.0]  # toward the last command (+90°)


def test_unicycle_turns_in_place_when_far_off_and_drives_when_aligned():
    from bearnav_cli.runtime.unicycle import unicycle_command

    s = _settings(dynamics="unicycle", alpha=0.1)
    direction = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 0.0]])
    off = np.zeros(3, bool)
    forward, turn, motion = unicycle_command(s, direction, np.zeros(3), off, off, np.array([-1, -1, 3]), np.zeros(3))
    np.testing.assert_allclose(forward, [s.alpha, 0.0, s.alpha], atol=1e-15)  # cos³ 90° = 0
    np.testing.assert_allclose(turn, [0.0, s.beta, 0.0], atol=1e-15)
    np.testing.assert_allclose(motion, [[s.alpha, 0.0], [0.0, 0.0], [s.alpha, 0.0]], atol=1e-15)


def test_best_view_heading_points_the_camera_at_a_usable_fix():
    """Looking on purpose: at the heading it picks, the camera (60°) sees at least two landmarks in
    line of sight, and the runtime's own lsq fix from those bearings is usable."""
    from bearnav_cli.geometry import FreeSpace
    from bearnav_cli.runtime.looking import best_view_heading
    from bench.common import run_stages
    from tests.conftest import build_map
    from tests.funnel_maps import random_spec

    plan = run_stages(build_map(random_spec(6, 300, 0)), ["rrtstar", "simplify", "decompose", "synthesize"])
    arrays = PlanArrays.from_plan(plan)
    s = _settings(fov=math.radians(60.0))
    space = FreeSpace.from_map(plan.map)
    rng = np.random.default_rng(4)
    x = rng.uniform(plan.map.bounds[:2], plan.map.bounds[2:], (400, 2))
    x = x[space.points_free(x)]
    heading = best_view_heading(arrays, s, x, rng.uniform(-math.pi, math.pi, len(x)))
    found = np.isfinite(heading)
    assert found.mean() > 0.5
    lm = plan.map.landmarks
    in_view = runtime.bearing.in_field_of_view(x[found], heading[found], lm, s.fov, tol=arrays.tol)
    seen = in_view & space.visible(np.repeat(x[found], len(lm), 0), np.tile(lm, (found.sum(), 1))).reshape(-1, len(lm))
    assert np.all(seen.sum(axis=1) >= 2)
    directions, _ = runtime.bearing.directions(x[found], lm)
    rec = runtime.bearing.reconstruct(directions, seen, lm, 0, method="lsq", min_spread=s.min_spread, tol=arrays.tol)
    assert rec.usable.all()
    np.testing.assert_allclose(rec.x_hat, x[found], atol=1e-6)
