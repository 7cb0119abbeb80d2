"""Properties of the RRT* stage (ALGORITHMS §2)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from bearnav_cli import artifacts
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace, to_shapely
from bearnav_cli.stages import rrtstar

from .conftest import build_map


@pytest.fixture(scope="module")
def small_map():
    from .conftest import SMALL_MAP

    return build_map(dict(SMALL_MAP))


@pytest.fixture(scope="module")
def tree(small_map):
    return rrtstar.run(small_map, rrtstar.Params(iterations=800, step=1.0, seed=3))


def test_every_edge_is_exactly_free(tree, small_map):
    obstacles = shapely.union_all([to_shapely(p) for p in small_map.obstacles])
    lines = shapely.linestrings(tree.edges)
    assert not shapely.intersects(obstacles, lines).any()
    box = shapely.box(*small_map.bounds)
    assert shapely.covers(box, lines).all()


def test_costs_add_up_along_edges(tree, small_map):
    child, par = np.arange(1, len(tree.nodes)), tree.parent[1:]
    lengths = np.linalg.norm(tree.nodes[child] - tree.nodes[par], axis=1)
    assert np.allclose(tree.cost[child], tree.cost[par] + lengths, rtol=0, atol=1e-9 * small_map.diagonal)
    assert tree.cost[0] == 0


def test_parent_is_a_tree_rooted_at_the_goal(tree, small_map):
    assert tree.parent[0] == -1 and np.count_nonzero(tree.parent == -1) == 1
    assert np.array_equal(tree.nodes[0], small_map.goal)
    depth = np.zeros(len(tree.nodes), int)
    for i in range(1, len(tree.nodes)):
        v, steps = i, 0
        while v != 0:
            v = tree.parent[v]
            steps += 1
            assert steps <= len(tree.nodes), "cycle"
        depth[i] = steps
    assert depth[1:].min() >= 1


def test_collision_samples_and_border_samples(tree, small_map):
    space = FreeSpace.from_map(small_map)
    n_random = tree.stats["random_collision_samples"]
    random_hits, border = tree.collision_samples[:n_random], tree.collision_samples[n_random:]
    assert (space.in_obstacle(random_hits) | ~space.in_bounds(random_hits)).all()  # in O or in the walls B \\ B_r
    spacing = 1.0 / 10
    xmin, ymin, xmax, ymax = small_map.bounds
    sides = [xmax - xmin, ymax - ymin] * 2
    assert len(border) == sum(math.ceil(s / spacing) for s in sides)
    on_edge = np.isclose(border[:, 0], xmin) | np.isclose(border[:, 0], xmax)
    on_edge |= np.isclose(border[:, 1], ymin) | np.isclose(border[:, 1], ymax)
    assert on_edge.all() and np.all((border >= small_map.bounds[:2]) & (border <= small_map.bounds[2:]))
    gaps = np.linalg.norm(np.diff(np.vstack([border, border[:1]]), axis=0), axis=1)
    assert gaps.max() <= spacing + 1e-12
    assert n_random + (len(tree.nodes) - 1) <= 800


def test_rewiring_radius_matches_a_hand_value():
    assert rrtstar.rewiring_radius(1, 50.0, 10.0) == 0.0
    gamma = math.sqrt(6 * 50.0 / math.pi)
    assert rrtstar.rewiring_radius(100, 50.0, 10.0) == pytest.approx(gamma * (math.log(100) / 100) ** (1 / 3))
    assert rrtstar.rewiring_radius(100, 50.0, 0.5) == 0.5


def test_rewiring_shortens_routes(small_map):
    """With rewiring, no node can reach the root more cheaply through a free straight segment
    to a node within the final rewiring radius by more than a small factor (a plain RRT fails this)."""
    tree = rrtstar.run(small_map, rrtstar.Params(iterations=1500, step=1.0, seed=0))
    space = FreeSpace.from_map(small_map)
    # the straight-line lower bound: cost(i) >= |x_i - goal|; RRT* costs stay within a modest factor
    straight = np.linalg.norm(tree.nodes - small_map.goal, axis=1)
    visible = space.segments_free(tree.nodes, small_map.goal)
    ratio = tree.cost[visible][1:] / straight[visible][1:]
    assert np.median(ratio) < 1.05


def test_same_seed_same_content_other_seed_other(small_map):
    def digest(seed, policy="skip"):
        t = rrtstar.run(small_map, rrtstar.Params(iterations=300, seed=seed, collision_policy=policy))
        return artifacts.content_hash(artifacts.entries_of(t))

    assert digest(5) == digest(5)
    assert digest(5) != digest(6)
    assert digest(5) != digest(5, "extend")


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"iterations": 0}, "iterations"),
        ({"step": 0.0}, "step"),
        ({"step": -1.0}, "step"),
        ({"collision_policy": "keep"}, "collision_policy"),
        ({"border_spacing": -0.1}, "border_spacing"),
    ],
)
def test_bad_params_raise(kwargs, field):
    with pytest.raises(InvalidParamsError) as info:
        rrtstar.Params(**kwargs)
    assert info.value.field == field


@pytest.mark.parametrize("option, value", [("--iterations", "0"), ("--step", "0"), ("--step", "-2")])
def test_bad_params_on_the_command_line(cli, write_map, small_spec, tmp_path, option, value):
    result = cli("map", write_map(small_spec), "-o", tmp_path / "m" / "map.json", "--quiet")
    assert result.exit_code == 0, result.output
    result = cli("rrtstar", tmp_path / "m" / "map.json", option, value)
    assert result.exit_code == 3
    assert option.lstrip("-") in result.output and len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "m" / "tree.npz").exists()


def test_no_route_when_every_sample_hits_obstacles(cli, write_map, tmp_path):
    spec = {
        "name": "pocket",
        "bounds": [0, 0, 10, 10],
        "goal": [0.5, 0.5],
        "landmarks": [[0, 0], [1, 0]],
        "obstacles": [{"polygon": [[1, 0], [10, 0], [10, 10], [0, 10], [0, 1], [1, 1]]}],
        "params": {"rrtstar": {"iterations": 5, "seed": 1}},
    }
    result = cli("plan", write_map(spec, "pocket.yaml"), "--quiet")
    tree = artifacts.load(tmp_path / "plans" / "pocket" / "tree.npz").artifact
    assert tree.stats["random_collision_samples"] == 5  # the precondition of this test
    assert result.exit_code == 1 and "no route" in result.output


def test_bucket_grid_answers_as_a_scan_of_every_node():
    """Nearest (ties: lowest index) and radius queries of the sorted grid, tail included, match brute force."""
    rng = np.random.default_rng(5)
    bounds = np.array([0.0, 0.0, 10.0, 6.0])
    # lattice points give exact distance ties; random ones fill the buckets unevenly
    lattice = np.stack(np.meshgrid(np.arange(0.5, 10, 1.5), np.arange(0.5, 6, 1.5)), -1).reshape(-1, 2)
    nodes = np.concatenate([lattice, rng.uniform(bounds[:2], bounds[2:], (700, 2))])
    grid = rrtstar._BucketGrid(bounds, 0.4, nodes)
    for index in range(len(nodes)):
        grid.insert(index)
    assert grid.sorted < grid.size  # the newest nodes are in the tail
    queries = np.concatenate([lattice + [0.75, 0.75], rng.uniform(bounds[:2], bounds[2:], (200, 2)), [[0.0, 0.0]]])
    for x, y in queries.tolist():
        d2 = ((nodes - (x, y)) ** 2).sum(axis=1)
        assert grid.nearest(x, y) == int(np.flatnonzero(d2 == d2.min()).min())
        for radius in (0.3, 1.0, 2.5):
            assert grid.within(x, y, radius).tolist() == np.flatnonzero(d2 <= radius * radius).tolist()


def test_one_segment_test_is_the_batched_one(small_map):
    """FreeSpace.segment_free (RRT*'s single edge) answers as segments_free does."""
    space = FreeSpace.from_map(small_map)
    rng = np.random.default_rng(2)
    lo, hi = space.bounds[:2], space.bounds[2:]
    a, b = rng.uniform(lo, hi, (300, 2)), rng.uniform(lo, hi, (300, 2))
    batched = space.segments_free(a, b, known_in_box=True)
    assert 0 < batched.sum() < len(batched)
    assert [space.segment_free(*p, *q) for p, q in zip(a.tolist(), b.tolist(), strict=True)] == batched.tolist()
