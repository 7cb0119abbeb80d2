"""The map stage: shapes, inflation, free area and the validation rules of ALGORITHMS §1."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from bearnav_cli.errors import InvalidMapError
from bearnav_cli.geometry import FreeSpace, circle_polygon, to_shapely

from .conftest import build_map


def test_every_shape_kind_is_parsed(small_spec):
    m = build_map(small_spec)
    assert len(m.landmarks) == 5 and m.landmark_ids[1] == "tag12" and m.landmark_ids[0] == "0"
    raw = shapely.union_all([to_shapely(p) for p in m.raw_obstacles])
    # the triangle, the rectangle and the 64-gon are all there, disjoint
    assert len(m.raw_obstacles) == 3
    expected = 0.5 * 2 * 1 + 2 * 1 + shapely.Polygon(circle_polygon((8, 2), 0.5)).area
    assert raw.area == pytest.approx(expected, rel=1e-12)


def test_circle_polygon_contains_the_disc():
    r = 3.0
    poly = shapely.Polygon(circle_polygon((1.0, -2.0), r))
    angles = np.linspace(0, 2 * np.pi, 1000, endpoint=False)
    pts = np.column_stack([1.0 + r * (1 - 1e-12) * np.cos(angles), -2.0 + r * (1 - 1e-12) * np.sin(angles)])
    assert shapely.contains_xy(poly, pts[:, 0], pts[:, 1]).all()


def test_inflation_contains_every_point_within_the_radius(small_spec):
    rho = small_spec["robot_radius"]
    m = build_map(small_spec)
    raw = shapely.union_all([to_shapely(p) for p in m.raw_obstacles])
    grown = shapely.union_all([to_shapely(p) for p in m.obstacles])
    rng = np.random.default_rng(1)
    boundary = raw.boundary
    # points at distance exactly rho (minus a hair) from random boundary points, in random directions
    t = rng.uniform(0, boundary.length, 2000)
    base = np.array([boundary.interpolate(s).coords[0] for s in t])
    ang = rng.uniform(0, 2 * np.pi, len(base))
    pts = base + rho * (1 - 1e-9) * np.column_stack([np.cos(ang), np.sin(ang)])
    assert shapely.intersects_xy(grown, pts[:, 0], pts[:, 1]).all()
    # area grows as a Minkowski sum with the disc: at least area + perimeter*rho + pi*rho^2 per convex part
    for part in m.raw_obstacles:
        p = to_shapely(part)
        lower = p.area + p.length * rho + math.pi * rho**2
        inflated = shapely.buffer(p, rho / math.cos(math.pi / 64), quad_segs=16)
        assert lower <= inflated.area <= lower * 1.01
    assert grown.area >= sum(to_shapely(p).area for p in m.raw_obstacles)


def test_free_area_of_a_box_with_one_circle():
    spec = {
        "bounds": [0, 0, 10, 10],
        "goal": [1, 1],
        "landmarks": [[0, 0], [10, 10]],
        "obstacles": [{"circle": {"center": [5, 5], "radius": 2}}],
    }
    space = FreeSpace.from_map(build_map(spec))
    assert space.free_area == pytest.approx(100 - shapely.Polygon(circle_polygon((5, 5), 2)).area, abs=1e-9)


def test_map_json_round_trips(small_spec):
    m = build_map(small_spec)
    again = type(m).from_json(m.to_json())
    assert again.to_json_text() == m.to_json_text()


BAD_MAPS = [
    (lambda s: s.update(goal=[0, 4]), "goal"),  # on the boundary of B
    (lambda s: s.update(goal=[4.5, 4.5]), "goal"),  # inside an obstacle
    (lambda s: s["starts"].append([11, 3]), "starts[2]"),  # outside the bounds
    (lambda s: s["starts"].append([5, 4.1]), "starts[2]"),  # inside an inflated obstacle
    (lambda s: s.update(landmarks=[[0, 8]]), "landmarks"),  # fewer than two
    (lambda s: s["landmarks"].append([0, 8]), "landmarks[5]"),  # duplicate position
    (lambda s: s["landmarks"].append([5, 4.5]), "landmarks[5]"),  # inside a raw obstacle
    (lambda s: s["landmarks"].append([12, 4]), "landmarks[5]"),  # outside the bounds
    (lambda s: s.update(colour="red"), "colour"),  # unknown key
    (lambda s: s.update(robot_radius="big"), "robot_radius"),  # wrong type
    (lambda s: s["obstacles"].append({"polygon": [[0, 0], [2, 2], [2, 0], [0, 2]]}), "obstacles[3].polygon"),
    (lambda s: s["obstacles"].append({"circle": {"center": [1, 1], "radius": -1}}), "obstacles[3].circle.radius"),
    (lambda s: s["obstacles"].append({"rectangle": [3, 3, 1, 1]}), "obstacles[3].rectangle"),
    (lambda s: s["obstacles"].append({"hexagon": [1]}), "obstacles[3].hexagon"),
    (lambda s: s.update(bounds=[0, 0, -1, 5]), "bounds"),
    (lambda s: s["obstacles"].append({"rectangle": [-1, -1, 11, 9]}), "obstacles"),  # empty free space
    (lambda s: s["obstacles"].append({"rectangle": [6.5, 0, 7, 8]}), "starts[0]"),  # cut off from the goal
    # the robot section (DESIGN §3.4)
    (lambda s: s.update(robot={"lookahead": -0.1}), "robot.lookahead"),  # negative
    (lambda s: s.update(robot={"lookahead": float("inf")}), "robot.lookahead"),  # not finite
    (lambda s: s.update(robot={"lookahead": "far"}), "robot.lookahead"),  # wrong type
    (lambda s: s.update(robot={"lookahead": 0.3}), "robot.lookahead"),  # the goal (0.5, 0.5) is no longer free
    (lambda s: s.update(robot={"lookahead": 4.0}), "robot.lookahead"),  # nothing is free
    (lambda s: (s["starts"].append([5, 5.4]), s.update(robot={"lookahead": 0.25})), "robot.lookahead"),  # a start
    (lambda s: s.update(robot={"radius": 0.3}), "robot.radius"),  # differs from robot_radius
    (lambda s: s.update(robot={"radius": -1}), "robot.radius"),
    (lambda s: s.update(robot={"bearing_error_deg": 90}), "robot.bearing_error_deg"),  # a cone is convex below 90°
    (lambda s: s.update(robot={"compass_error_deg": -1}), "robot.compass_error_deg"),
    (lambda s: s.update(robot={"slip": float("nan")}), "robot.slip"),
    (lambda s: s.update(robot={"max_turn_rate": -0.5}), "robot.max_turn_rate"),
    (lambda s: s.update(robot={"reverse": "no"}), "robot.reverse"),
    (lambda s: s.update(robot={"wheelbase": 0.3}), "robot.wheelbase"),  # unknown key
    (lambda s: s.update(robot=[0.2]), "robot"),
]


@pytest.mark.parametrize("edit, field", BAD_MAPS)
def test_bad_maps_name_the_field(small_spec, edit, field):
    edit(small_spec)
    with pytest.raises(InvalidMapError) as info:
        build_map(small_spec)
    assert info.value.field == field, str(info.value)


def test_start_cut_off_from_the_goal(small_spec):
    # a wall across the map separates the start (9, 7) from the goal
    small_spec["obstacles"].append({"rectangle": [6.5, 0, 7, 8]})
    with pytest.raises(InvalidMapError) as info:
        build_map(small_spec)
    assert info.value.field == "starts[0]" and "goal" in str(info.value)


def test_landmark_on_a_wall_is_allowed(small_spec):
    small_spec["landmarks"].append([6, 4.5])  # on the rectangle's right side
    m = build_map(small_spec)
    space = FreeSpace.from_map(m)
    assert space.visible(np.array([8.0, 4.5]), m.landmarks[-1])[0]
    assert not space.visible(np.array([3.0, 4.5]), m.landmarks[-1])[0]  # behind the rectangle


def test_coverage_warning_says_where(small_spec, caplog):
    # two landmarks only, hidden from the right part of the map by a tall wall
    small_spec["landmarks"] = [[0, 8], [0, 0.2]]
    small_spec["obstacles"].append({"rectangle": [6.6, 0.0, 6.8, 7.0]})
    small_spec["starts"] = []
    with caplog.at_level("WARNING"):
        build_map(small_spec)
    message = " ".join(r.getMessage() for r in caplog.records)
    assert "fewer than 2 landmarks" in message and "x in [" in message


@pytest.mark.parametrize("name", ["kitchen.yaml", "storeroom.yaml"])
def test_spec_of_gives_back_the_same_free_space(name):
    """map_.spec_of writes a map as polygons (for `bearnav tags -o` elsewhere, or a vanished source):
    the map stage turns it back into the same raw obstacles, landmarks, goal and bounds."""
    from pathlib import Path

    from bearnav_cli.cli import read_map_source
    from bearnav_cli.stages import map_

    original = map_.run(read_map_source(Path(__file__).parent.parent / "maps" / name))
    again = map_.run(map_.MapSource(spec=map_.spec_of(original), file="again.yaml", sha256="0"))
    raw = [to_shapely(p) for p in original.raw_obstacles]
    back = [to_shapely(p) for p in again.raw_obstacles]
    assert shapely.symmetric_difference(shapely.union_all(raw), shapely.union_all(back)).area < 1e-9
    np.testing.assert_array_equal(again.landmarks, original.landmarks)
    assert again.landmark_ids == original.landmark_ids
    np.testing.assert_array_equal(again.bounds, original.bounds)
    np.testing.assert_array_equal(again.goal, original.goal)
