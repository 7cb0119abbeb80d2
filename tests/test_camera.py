"""runtime.camera: AprilTag detections to world bearings and heading; the tags' facing in the map format."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bearnav_cli.datatypes import Map
from bearnav_cli.errors import InvalidMapError, InvalidParamsError
from bearnav_cli.runtime import camera
from bearnav_cli.runtime.camera import Detection, TagMap, heading_from_tag, observe
from bearnav_cli.runtime.camera_model import Intrinsics, Mount

from .conftest import build_map

#: Tags around a robot at (2, 1.5): on walls facing it, and one free-standing (NaN).
POSITIONS = np.array([[6.0, 1.0], [5.0, 3.0], [6.0, 3.5], [5.0, 0.0], [5.5, 0.5]])
FACING = np.radians([180.0, 250.0, 200.0, 110.0, math.nan])
NUMBERS = np.array([3, 12, 7, 0, 21])
ROBOT, HEADING = np.array([2.0, 1.5]), 0.3
DISTORTION = (-0.12, 0.05, 0.001, -0.0015, -0.01)


def _tags(facing=FACING, turn=0.0) -> TagMap:
    """The tags, turned by ``turn`` (rad) about the robot with their facings."""
    positions = ROBOT + (POSITIONS - ROBOT) @ _rz(turn)[:2, :2].T
    return TagMap(NUMBERS, positions, np.asarray(facing) + turn, tuple(f"tag{n}" for n in NUMBERS))


def _rz(a: float) -> np.ndarray:
    return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1.0]])


def _synthetic(intrinsics, mount, *, with_pose=False, heading=HEADING, robot=ROBOT, tags=None, order=None):
    """Detections made by projecting each tag's corners through the camera (AprilTag corner order)."""
    tags = tags or _tags()
    out = []
    world_r_cam = _rz(heading) @ mount.rotation
    cam_origin = np.array([*robot, 0.0]) + _rz(heading) @ mount.translation
    for k, (p, f) in enumerate(zip(tags.positions, tags.facing, strict=True)):
        facing = f if math.isfinite(f) else math.atan2(*(robot - p)[::-1])
        corners = camera.tag_corners_world(p, facing, 0.16, 0.4)
        pix, depth = camera.project_world(intrinsics, mount, robot, heading, corners)
        assert (depth > 0).all()
        pose = None
        if with_pose:
            r = world_r_cam.T @ camera.tag_rotation_world(facing)
            pose = (r, world_r_cam.T @ (np.array([*p, 0.4]) - cam_origin))
        out.append(Detection(int(tags.numbers[k]), pix if order is None else pix[order], pose))
    return out


def _truth(robot=ROBOT, positions=None) -> np.ndarray:
    positions = _tags().positions if positions is None else positions
    d = positions - robot
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize("distortion", [(), DISTORTION])
def test_bearings_equal_the_true_world_bearings(distortion):
    intr = Intrinsics(fx=420.0, fy=415.0, cx=640.2, cy=481.7, width=1280, height=960, distortion=distortion)
    mount = Mount.forward(height=0.35, yaw=0.15)
    dets = _synthetic(intr, mount)
    obs = observe(dets, intr, mount, _tags(), heading=HEADING)
    assert obs.visible.all() and obs.rejected == 0 and obs.heading == HEADING
    np.testing.assert_allclose(obs.bearings, _truth(), atol=1e-9)
    # OpenCV's corner order (clockwise from the top left) has the same diagonals
    opencv = observe(_synthetic(intr, mount, order=[3, 2, 1, 0]), intr, mount, _tags(), heading=HEADING)
    np.testing.assert_allclose(opencv.bearings, _truth(), atol=1e-9)


def test_heading_from_tag_poses_and_parallax():
    intr = Intrinsics.from_camera_info([500, 0, 640, 0, 500, 480, 0, 0, 1], DISTORTION, 1280, 960)
    # a camera ahead of and to the left of the robot's centre, turned right a little and pitched down
    pitch = np.array([[1, 0, 0], [0, math.cos(0.1), -math.sin(0.1)], [0, math.sin(0.1), math.cos(0.1)]])
    rot = Mount.forward(yaw=-0.2).rotation @ pitch
    mount = Mount(rot, np.array([0.25, 0.1, 0.4]))
    for heading in (0.3, -2.9, 3.1):
        tags = _tags(turn=heading - HEADING)
        dets = _synthetic(intr, mount, with_pose=True, heading=heading, tags=tags)
        obs = observe(dets, intr, mount, tags, heading=None)
        assert obs.heading == pytest.approx(heading, abs=1e-9) and obs.pose_heading == obs.heading
        # the pose's range puts each tag on its ray: bearings from the robot's centre, not the camera's
        np.testing.assert_allclose(obs.bearings, _truth(positions=tags.positions), atol=1e-9)
        for det, f in zip(dets, tags.facing, strict=True):
            if math.isfinite(f):
                assert heading_from_tag(det.pose[0], f, mount) == pytest.approx(
                    math.remainder(heading, 2 * math.pi), abs=1e-9
                )


def test_opencv_pose_convention():
    """OpenCV's marker frame (y up, z out of the tag) turned into the AprilTag one (y down, z into it)."""
    r_april = camera.tag_rotation_world(1.0)
    r_cv = r_april @ np.diag([1.0, -1.0, -1.0])
    back, _ = camera.tag_pose_from_opencv(r_cv, np.zeros(3))
    np.testing.assert_allclose(back, r_april, atol=1e-12)


def test_rejected_detections_are_counted():
    intr = Intrinsics.from_fov(1280, 960, math.radians(120))
    mount = Mount.forward(height=0.3)
    dets = _synthetic(intr, mount)
    stranger = Detection(99, dets[0].corners)  # an id the plan does not have
    off_image = Detection(int(NUMBERS[1]), dets[1].corners + np.array([2000.0, 0.0]))
    twice = Detection(int(NUMBERS[2]), dets[2].corners)
    obs = observe([stranger, off_image, *dets[2:], twice], intr, mount, _tags(), heading=HEADING)
    assert (obs.unknown, obs.outside_image, obs.duplicates, obs.from_behind) == (1, 1, 1, 0)
    assert obs.visible.tolist() == [False, False, True, True, True]
    np.testing.assert_allclose(obs.bearings[2:], _truth()[2:], atol=1e-9)
    # half a pixel past the edge is still in the image; more is not
    edge = dets[2].corners.copy()
    edge[0, 0] = -1.0
    assert observe([Detection(7, edge)], intr, mount, _tags(), heading=HEADING).outside_image == 0
    edge[0, 0] = -1.01
    assert observe([Detection(7, edge)], intr, mount, _tags(), heading=HEADING).outside_image == 1


def test_a_tag_seen_from_behind_is_rejected():
    intr = Intrinsics.from_fov(1280, 960, math.radians(120))
    mount = Mount.forward(height=0.3)
    dets = _synthetic(intr, mount)
    flipped = FACING.copy()
    flipped[0] += math.pi  # the map says tag 3 faces away from the robot: what it saw is not that tag
    obs = observe(dets, intr, mount, _tags(flipped), heading=HEADING)
    assert obs.from_behind == 1 and not obs.visible[0] and obs.visible[1:].all()
    # a grazing view within the margin is kept: the facing turned 95° from the view direction
    grazing = FACING.copy()
    grazing[0] = math.atan2(*(ROBOT - POSITIONS[0])[::-1]) + math.radians(95)
    assert observe(dets, intr, mount, _tags(grazing), heading=HEADING).from_behind == 0


def test_bad_intrinsics_and_missing_heading_are_clear_errors():
    with pytest.raises(InvalidParamsError, match="fx"):
        Intrinsics(fx=0.0, fy=500.0, cx=320, cy=240, width=640, height=480)
    with pytest.raises(InvalidParamsError, match="fy"):
        Intrinsics.from_camera_info([500, 0, 320, 0, math.nan, 240, 0, 0, 1], [], 640, 480)
    with pytest.raises(InvalidParamsError, match="fx"):
        Intrinsics.from_camera_info([0] * 9 + [], [], 640, 480)
    with pytest.raises(InvalidParamsError, match="distortion_model"):
        Intrinsics.from_camera_info([500, 0, 320, 0, 500, 240, 0, 0, 1], [0.1, 0, 0, 0], 640, 480, "equidistant")
    with pytest.raises(InvalidParamsError, match="hfov"):
        Intrinsics.from_fov(640, 480, math.pi)
    intr, mount = Intrinsics.from_fov(1280, 960, math.radians(120)), Mount.forward()
    with pytest.raises(InvalidParamsError, match="heading"):
        observe(_synthetic(intr, mount), intr, mount, _tags())
    # nothing seen and no compass: nothing to say, no error
    assert observe([], intr, mount, _tags()).heading is None


def test_undistort_inverts_distort():
    intr = Intrinsics.from_camera_info([600, 0, 640, 0, 600, 400, 0, 0, 1], DISTORTION, 1280, 800)
    xy = np.random.default_rng(0).uniform(-0.9, 0.9, (200, 2))
    uv = intr.project(np.column_stack([xy, np.ones(len(xy))]))
    np.testing.assert_allclose(intr.undistort(uv), xy, atol=1e-12)
    assert intr.hfov == pytest.approx(2 * math.atan(640 / 600))


def test_tag_map_from_plan_json_and_tag_numbers():
    assert [camera.tag_number(i) for i in ("tag12", "12", "tag_3", "door", "tag36h11")] == [12, 12, 3, -1, -1]
    old = {"landmarks": [{"id": "tag4", "position": [1, 2]}, {"id": "5", "position": [3, 4]}]}
    tags = TagMap.from_map_json(old)
    assert tags.numbers.tolist() == [4, 5] and np.isnan(tags.facing).all() and tags.index(5) == 1
    new = {
        "landmarks": [
            {"id": "tag4", "position": [1, 2], "facing": 90.0},
            {"id": "x", "position": [3, 4], "facing": None},
        ]
    }
    tags = TagMap.from_map_json(new)
    assert tags.facing[0] == pytest.approx(math.pi / 2) and math.isnan(tags.facing[1]) and tags.index(-1) == -1
    with pytest.raises(InvalidParamsError, match="same detector id"):
        TagMap.from_map_json({"landmarks": [{"id": "tag4", "position": [1, 2]}, {"id": "4", "position": [3, 4]}]})


# --------------------------------------------------------------------------- facing in the map format


def _facing_spec() -> dict:
    return {
        "bounds": [0, 0, 10, 8],
        "goal": [1, 1],
        "obstacles": [{"rectangle": [4, 4, 6, 5]}],
        "landmarks": [
            [0, 4],  # left wall: faces +x
            {"id": "tag1", "position": [5, 4]},  # bottom face of the block: faces -y
            {"id": "tag2", "position": [4, 5]},  # its top-left corner (convex): the bisector
            {"id": "tag3", "position": [0, 8]},  # the room's top-left corner (concave)
            {"id": "tag4", "position": [5, 2]},  # free-standing
            {"id": "tag5", "position": [10, 3], "facing": 100},  # explicit: kept
            {"id": "tag6", "position": [6, 4.5], "facing": None},  # explicit: free-standing
        ],
    }


def test_facing_is_inferred_on_walls_and_kept_when_given():
    m = build_map(_facing_spec())
    deg = np.degrees(m.landmark_facing)
    np.testing.assert_allclose(deg[[0, 1, 2, 3, 5]], [0.0, 270.0, 135.0, 315.0, 100.0], atol=1e-9)
    assert np.isnan(deg[[4, 6]]).all()
    # the inferred facing points into free space
    from bearnav_cli.geometry import FreeSpace

    space = FreeSpace.from_map(m)
    for k in (0, 1, 2, 3):
        probe = m.landmarks[k] + 0.05 * np.array([math.cos(m.landmark_facing[k]), math.sin(m.landmark_facing[k])])
        assert space.points_free(probe[None])[0]


def test_facing_round_trips_through_map_json():
    m = build_map(_facing_spec())
    text = m.to_json_text()
    assert json.loads(text)["landmarks"][1]["facing"] == 270.0 and json.loads(text)["landmarks"][4]["facing"] is None
    back = Map.from_json(json.loads(text))
    np.testing.assert_array_equal(back.landmark_facing, m.landmark_facing)
    assert back.to_json_text() == text
    # a map written before tags had a facing: every tag free-standing
    old = json.loads(text)
    for lm in old["landmarks"]:
        del lm["facing"]
    assert np.isnan(Map.from_json(old).landmark_facing).all()
    tags = TagMap.from_map_json(json.loads(text))
    np.testing.assert_array_equal(tags.facing, m.landmark_facing)


@pytest.mark.parametrize(
    ("value", "message"), [("north", "expected a number"), (math.inf, "finite"), (True, "expected a number")]
)
def test_a_bad_facing_is_a_map_error(value, message):
    spec = _facing_spec()
    spec["landmarks"][1]["facing"] = value
    with pytest.raises(InvalidMapError, match=message) as err:
        build_map(spec)
    assert err.value.field == "landmarks[1].facing"


def test_a_bad_facing_is_one_line_from_the_cli(cli, write_map):
    spec = _facing_spec()
    spec["landmarks"][2]["facing"] = [1, 2]
    result = cli("map", write_map(spec), "-o", "m.json")
    assert result.exit_code == 3
    assert "landmarks[2].facing" in result.output and len(result.output.strip().splitlines()) == 1


CORNERS = [[10.0, 10.0], [20.0, 10.0], [20.0, 20.0], [10.0, 20.0]]


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"tag_id": math.nan}, "tag_id"),
        ({"tag_id": "seven"}, "tag_id"),
        ({"tag_id": 3.5}, "tag_id"),
        ({"tag_id": -1}, "tag_id"),
        ({"corners": [["a", "b"]] * 4}, "corners"),
        ({"corners": [[1.0, 2.0], [3.0]]}, "corners"),
        ({"pose": (np.eye(3) * 2.0, np.ones(3))}, "pose"),  # a scaling, not a rotation
        ({"pose": (np.diag([1.0, 1.0, -1.0]), np.ones(3))}, "pose"),  # a reflection
        ({"pose": (np.eye(3), np.full(3, 1.5e308))}, "pose"),  # finite, but its length is not
        ({"pose": (np.eye(3), [1.0, math.nan, 0.0])}, "pose"),
        ({"pose": (np.eye(3), ["x", 0.0, 0.0])}, "pose"),
    ],
)
def test_a_bad_detection_is_one_clear_error_naming_the_field(kwargs, field):
    # issue 27 item 8: these gave a bare ValueError, a NaN bearing marked visible, or a heading from
    # a matrix that is not a rotation
    args = {"tag_id": 7, "corners": CORNERS, **kwargs}
    with pytest.raises(InvalidParamsError) as info:
        Detection(**args)
    assert info.value.field == field


def test_a_good_pose_and_a_whole_float_id_are_kept():
    det = Detection(7.0, CORNERS, (_rz(0.4), [0.1, 0.2, 3.0]))
    assert det.tag_id == 7 and isinstance(det.tag_id, int)
    assert np.allclose(det.pose[0], _rz(0.4))


def test_a_far_pose_gives_a_finite_bearing_or_none():
    intr, mount = Intrinsics.from_fov(640, 480, math.radians(60.0)), Mount.forward(height=0.3)
    for t in ([1e300, 0.0, 0.0], [0.0, 0.0, 1e300], np.full(3, 1e300), [1e-300, 0.0, 0.0]):
        det = Detection(
            int(NUMBERS[0]), [[300.0, 220.0], [340.0, 220.0], [340.0, 260.0], [300.0, 260.0]], (np.eye(3), t)
        )
        with np.errstate(all="raise"):  # no RuntimeWarning either
            obs = observe([det], intr, mount, _tags(), heading=HEADING)
        assert np.isfinite(obs.bearings).all()
        assert not obs.visible.any() or np.isclose(np.linalg.norm(obs.bearings[obs.visible], axis=1), 1.0).all()
