"""contrib/ros2: the ROS 2 node's logic on messages built with rosbags' type system (no ROS 2 here).

The node (``bearnav_node.py``) is rclpy glue around ``bearnav_ros.py``; these tests feed
``bearnav_ros`` real ``apriltag_msgs``, ``sensor_msgs`` and ``geometry_msgs`` messages (CDR round
trips) and check that the Twist it publishes is what ``runtime.camera.observe`` and
``Controller.command`` give for the same detections. The glue itself runs against stand-in rclpy
modules at the end.
"""

from __future__ import annotations

import importlib.util
import math
import sys
import types as pytypes

import numpy as np
import pytest

# rosbags comes with the test extra (bearnav[ros]): a broken install fails here rather than skipping
from rosbags import typesys

from bearnav_cli.runtime import Controller, camera, camera_model

from .conftest import REPO, planned_small_map

CONTRIB = REPO / "contrib" / "ros2"

#: christianrauch/apriltag_msgs (2.x), the messages apriltag_ros publishes.
APRILTAG_MSGS = {
    "apriltag_msgs/msg/Point": "float64 x\nfloat64 y\n",
    "apriltag_msgs/msg/AprilTagDetection": (
        "string family\nint32 id\nint32 hamming\nfloat32 goodness\nfloat32 decision_margin\n"
        "Point centre\nPoint[4] corners\nfloat64[9] homography\n"
    ),
    "apriltag_msgs/msg/AprilTagDetectionArray": "std_msgs/Header header\nAprilTagDetection[] detections\n",
}
WIDTH, HEIGHT, F = 640, 480, 320.0
MOUNT = camera_model.Mount.forward(height=0.3)
TAG_SIZE, TAG_HEIGHT = 0.16, 0.3


def load(name: str):
    spec = importlib.util.spec_from_file_location(name, CONTRIB / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up; the node imports bearnav_ros by name
    spec.loader.exec_module(module)
    return module


ros = load("bearnav_ros")


@pytest.fixture(scope="module")
def store():
    store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    for name, text in APRILTAG_MSGS.items():
        store.register(typesys.get_types_from_msg(text, name))
    return store


@pytest.fixture(scope="module")
def plan_path(tmp_path_factory):
    return str(planned_small_map(tmp_path_factory))


def wire(store, message):
    """The message after a CDR round trip, as a subscriber receives it."""
    kind = message.__msgtype__
    return store.deserialize_cdr(store.serialize_cdr(message, kind), kind)


def header(t, frame="camera_optical"):
    return t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id=frame)


def camera_info(store, p_scale=1.0):
    t = store.types
    k = np.array([F, 0, 319.5, 0, F, 239.5, 0, 0, 1.0])
    p = np.array([F * p_scale, 0, 319.5, 0, 0, F * p_scale, 239.5, 0, 0, 0, 1.0, 0])
    roi = t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    msg = t["sensor_msgs/msg/CameraInfo"](
        header=header(t),
        height=HEIGHT,
        width=WIDTH,
        distortion_model="plumb_bob",
        d=np.array([0.1, -0.05, 0.0, 0.0, 0.0]),
        k=k,
        r=np.eye(3).ravel(),
        p=p,
        binning_x=0,
        binning_y=0,
        roi=roi,
    )
    return wire(store, msg)


def quaternion(t, yaw):
    return t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def imu(store, yaw):
    t = store.types
    zero = t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    msg = t["sensor_msgs/msg/Imu"](
        header=header(t, "imu"),
        orientation=quaternion(t, yaw),
        orientation_covariance=np.zeros(9),
        angular_velocity=zero,
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=zero,
        linear_acceleration_covariance=np.zeros(9),
    )
    return wire(store, msg)


def view(tags, x, yaw, intrinsics):
    """``[(tag id, corners (4, 2))]`` of the plan's tags a robot at ``x`` with ``yaw`` sees, and their poses."""
    seen, poses = [], {}
    world_r_cam = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
    world_r_cam = world_r_cam @ MOUNT.rotation
    origin = np.array([*x, 0.0]) + MOUNT.translation
    for number, position, facing in zip(tags.numbers, tags.positions, tags.facing, strict=True):
        corners = camera.tag_corners_world(position, facing, TAG_SIZE, TAG_HEIGHT)
        pixels, depth = camera.project_world(intrinsics, MOUNT, x, yaw, corners)
        to_robot = np.asarray(x) - position
        if (
            (depth > 0).all()
            and (pixels >= 0).all()
            and (pixels[:, 0] < WIDTH - 1).all()
            and (pixels[:, 1] < HEIGHT - 1).all()
            and to_robot @ [math.cos(facing), math.sin(facing)] > 0
        ):
            seen.append((int(number), pixels))
            w_r_at = camera.tag_rotation_world(facing)
            centre = np.array([*position, TAG_HEIGHT])
            poses[int(number)] = (world_r_cam.T @ w_r_at, world_r_cam.T @ (centre - origin))
    return seen, poses


def detections_msg(store, seen, extra=()):
    t = store.types
    point = t["apriltag_msgs/msg/Point"]
    items = []
    for tag_id, corners in [*seen, *extra]:
        c = corners.mean(axis=0)
        items.append(
            t["apriltag_msgs/msg/AprilTagDetection"](
                family="tag36h11",
                id=tag_id,
                hamming=0,
                goodness=0.0,
                decision_margin=80.0,
                centre=point(x=float(c[0]), y=float(c[1])),
                corners=[point(x=float(u), y=float(v)) for u, v in corners],
                homography=np.zeros(9),
            )
        )
    msg = t["apriltag_msgs/msg/AprilTagDetectionArray"](header=header(t), detections=items)
    return wire(store, msg)


@pytest.fixture(scope="module")
def scene(plan_path):
    """A robot at (3, 6) turned toward the most tags: (yaw, seen, poses, ideal intrinsics)."""
    tags = camera.TagMap.from_plan(plan_path)
    ideal = camera_model.Intrinsics(F, F, 319.5, 239.5, WIDTH, HEIGHT)
    best = max(
        (view(tags, (3.0, 6.0), math.radians(a), ideal) + (math.radians(a),) for a in range(0, 360, 5)),
        key=lambda v: len(v[0]),
    )
    seen, poses, yaw = best
    assert len(seen) >= 2
    return yaw, seen, poses, ideal


def test_messages_become_runtime_types(store):
    t = store.types
    info = camera_info(store, p_scale=1.1)
    rect = ros.intrinsics_from_camera_info(info)  # the rectified image: P, no distortion
    assert (rect.fx, rect.fy, rect.cx, rect.cy, rect.distortion) == (F * 1.1, F * 1.1, 319.5, 239.5, ())
    raw = ros.intrinsics_from_camera_info(info, rectified=False)
    assert raw == camera_model.Intrinsics.from_camera_info(info.k, info.d, WIDTH, HEIGHT, "plumb_bob")
    assert raw.distortion == (0.1, -0.05, 0.0, 0.0, 0.0)
    for yaw in (0.0, 1.0, -2.5, math.pi - 1e-9):
        assert ros.yaw_from_quaternion(imu(store, yaw).orientation) == pytest.approx(yaw, abs=1e-12)
    q = quaternion(t, 0.7)
    assert np.allclose(
        ros.rotation_from_quaternion(q),
        [[math.cos(0.7), -math.sin(0.7), 0], [math.sin(0.7), math.cos(0.7), 0], [0, 0, 1]],
    )
    transform = t["geometry_msgs/msg/Transform"](
        translation=t["geometry_msgs/msg/Vector3"](x=1.0, y=2.0, z=3.0), rotation=q
    )
    r, p = ros.pose_from_transform(wire(store, transform))
    assert np.array_equal(p, [1, 2, 3]) and np.allclose(r @ r.T, np.eye(3))
    corners = np.array([[10.0, 20.0], [30.0, 20.0], [30.0, 40.0], [10.0, 40.0]])
    msg = detections_msg(store, [(3, corners), (12, corners + 100)])
    msg.detections[1].family = "tag25h9"
    got = ros.detections_from_msg(msg)
    assert [d.tag_id for d in got] == [3, 12] and np.array_equal(got[0].corners, corners)
    assert [d.tag_id for d in ros.detections_from_msg(msg, family="36h11")] == [3]
    # older apriltag_msgs: centre float64[2], corners float64[8]
    old = pytypes.SimpleNamespace(
        detections=[pytypes.SimpleNamespace(family="tag36h11", id=3, corners=corners.ravel().tolist())]
    )
    assert np.array_equal(ros.detections_from_msg(old)[0].corners, corners)
    assert ros.tag_frame("tag36h11", 3) == "tag36h11:3"


def reference(plan_path, scene, dynamics, frames=6):
    """What runtime.camera + Controller give for the scene, frame by frame: [(command, observation)]."""
    yaw, seen, _, ideal = scene
    ctl = Controller.from_plan(
        plan_path,
        speed=0.1,
        dt=0.1,
        dynamics=dynamics,
        alpha=0.1,
        beta=0.5,
        clamp_reverse=False,
        hold_time=2.0,
        bearing_sigma=math.radians(1.0),
    )
    tags = camera.TagMap.from_plan(plan_path)
    dets = [camera.Detection(tag_id, corners) for tag_id, corners in seen]
    out = []
    for _ in range(frames):
        obs = camera.observe(dets, ideal, MOUNT, tags, yaw)
        out.append((ctl.command(obs.bearings, obs.visible, heading=yaw), obs, ctl.last.turn[0]))
    return out


def logic_for(plan_path, **changes):
    settings = ros.Settings(plan=plan_path, mount_height=0.3, **changes)
    return ros.BearnavLogic(settings)


def test_the_twist_is_the_controllers_command_and_unknown_ids_are_ignored(store, plan_path, scene):
    yaw, seen, _, _ = scene
    logic = logic_for(plan_path, dynamics="unicycle")
    logic.on_camera_info(camera_info(store))  # rectified: P = K, no distortion
    logic.on_imu(imu(store, yaw))
    stray = (99, seen[0][1] + 5.0)  # a tag the plan does not have
    for command, obs, _ in reference(plan_path, scene, "unicycle"):
        step = logic.on_detections(detections_msg(store, seen, extra=[stray]))
        assert step.status == "ok" and step.observation.unknown == 1
        assert np.array_equal(step.observation.visible, obs.visible)
        assert np.allclose(step.observation.bearings, obs.bearings, atol=1e-12)
        assert np.allclose(step.twist, (command[0], 0.0, command[1]), atol=1e-12)
    assert np.hypot(step.twist[0], step.twist[2]) > 0  # it does drive
    twist = ros.fill_twist(wire(store, zero_twist(store)), step.twist)
    back = wire(store, twist)
    assert (back.linear.x, back.linear.y, back.angular.z) == pytest.approx(step.twist, abs=1e-15)


def zero_twist(store):
    t = store.types
    v = t["geometry_msgs/msg/Vector3"]
    return t["geometry_msgs/msg/Twist"](linear=v(x=0.0, y=0.0, z=0.0), angular=v(x=0.0, y=0.0, z=0.0))


def test_a_holonomic_base_gets_its_velocity_in_the_body_frame(store, plan_path, scene):
    yaw, seen, _, _ = scene
    logic = logic_for(plan_path, dynamics="single")
    logic.on_camera_info(camera_info(store))
    logic.on_imu(imu(store, yaw))
    for command, _, turn in reference(plan_path, scene, "single", frames=3):
        step = logic.on_detections(detections_msg(store, seen))
        body = (
            math.cos(yaw) * command[0] + math.sin(yaw) * command[1],
            -math.sin(yaw) * command[0] + math.cos(yaw) * command[1],
            turn,
        )
        assert np.allclose(step.twist, body, atol=1e-12)
    assert math.hypot(step.twist[0], step.twist[1]) == pytest.approx(0.1)  # the single integrator's speed


def test_the_heading_from_tag_poses_replaces_the_compass(store, plan_path, scene):
    yaw, seen, poses, _ = scene
    t = store.types
    logic = logic_for(plan_path, dynamics="unicycle", heading_source="tags")
    logic.on_camera_info(camera_info(store))
    msg = detections_msg(store, seen)
    assert logic.on_detections(msg).status == "waiting for a tag pose"  # no pose, no compass
    frames = logic.tag_frames(msg)
    assert set(frames) == {tag_id for tag_id, _ in seen} and frames[seen[0][0]] == f"tag36h11:{seen[0][0]}"
    # the TF transforms apriltag_ros would publish (camera -> tag), through geometry_msgs/Transform
    from_tf = {}
    for tag_id, (r, p) in poses.items():
        w, x, y, z = _quaternion_of(r)
        transform = t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=p[0], y=p[1], z=p[2]),
            rotation=t["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
        )
        from_tf[tag_id] = ros.pose_from_transform(wire(store, transform))
    (command, _, _), *_ = reference(plan_path, scene, "unicycle", frames=1)
    step = logic.on_detections(msg, from_tf)
    assert step.status == "ok" and step.observation.heading == pytest.approx(yaw, abs=1e-9)
    assert np.allclose(step.twist, (command[0], 0.0, command[1]), atol=1e-6)
    # a frame without poses: the last heading, carried on by the commanded turn
    again = logic.on_detections(detections_msg(store, []))
    assert again.observation.heading == pytest.approx(yaw + 0.1 * step.twist[2], abs=1e-9)


def _quaternion_of(r):
    """(w, x, y, z) of a rotation matrix (Shepperd's method)."""
    trace = np.trace(r)
    if trace > 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        return 0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s
    i = int(np.argmax(np.diag(r)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
    q = np.zeros(4)
    q[0] = (r[k, j] - r[j, k]) / s
    q[1 + i] = 0.25 * s
    q[1 + j] = (r[j, i] + r[i, j]) / s
    q[1 + k] = (r[k, i] + r[i, k]) / s
    return tuple(q)


def test_the_node_waits_for_its_inputs_with_a_zero_twist(store, plan_path, scene):
    yaw, seen, _, _ = scene
    logic = logic_for(plan_path)
    msg = detections_msg(store, seen)
    assert logic.on_detections(msg).status == "waiting for camera_info"
    logic.on_camera_info(camera_info(store))
    step = logic.on_detections(msg)
    assert (step.status, step.twist) == ("waiting for the compass", (0.0, 0.0, 0.0))
    logic.on_imu(imu(store, yaw))
    assert logic.on_detections(msg).status == "ok"
    with pytest.raises(ValueError, match="heading_source"):
        ros.Settings(plan=plan_path, heading_source="gps")


class _Clock:
    def __init__(self):
        self.t = 0.0

    def now(self):
        return _Stamp(self.t)


class _Stamp:
    def __init__(self, t):
        self.t = t

    def __sub__(self, other):
        return self.t - other.t


def _fake_ros(store, transforms):
    """Stand-ins for rclpy, tf2_ros and the message packages: enough for bearnav_node.py to run."""
    t = store.types
    published, subscriptions, timers = [], {}, []

    class Node:
        overrides: dict = {}

        def __init__(self, name):
            self.clock = _Clock()
            self.logged = []

        def declare_parameter(self, name, default):
            value = self.overrides.get(name, default)
            assert type(value) is type(default), name  # rclpy refuses a parameter of another type
            setattr(self, f"_p_{name}", value)

        def get_parameter(self, name):
            return pytypes.SimpleNamespace(value=getattr(self, f"_p_{name}"))

        def create_publisher(self, kind, topic, depth):
            return pytypes.SimpleNamespace(publish=lambda msg: published.append((topic, msg)))

        def create_subscription(self, kind, topic, callback, qos):
            subscriptions[topic] = (kind, callback)

        def create_timer(self, period, callback):
            timers.append((period, callback))

        def get_clock(self):
            return self.clock

        def get_logger(self):
            return pytypes.SimpleNamespace(info=self.logged.append, warning=self.logged.append)

        def destroy_node(self):
            pass

    class TransformException(Exception):
        pass

    class Buffer:
        def lookup_transform(self, target, source, stamp, timeout=None):
            if (target, source) not in transforms:
                raise TransformException(f"{target} -> {source}")
            return pytypes.SimpleNamespace(transform=transforms[target, source])

    def duration(seconds):
        return seconds  # compared with a clock difference (float seconds)

    time_class = type("Time", (), {"from_msg": staticmethod(lambda stamp: stamp)})
    modules = {
        "rclpy": pytypes.SimpleNamespace(
            init=lambda args=None: None, spin=lambda node: None, try_shutdown=lambda: None
        ),
        "rclpy.executors": pytypes.SimpleNamespace(ExternalShutdownException=RuntimeError),
        "rclpy.node": pytypes.SimpleNamespace(Node=Node),
        "rclpy.duration": pytypes.SimpleNamespace(Duration=duration),
        "rclpy.time": pytypes.SimpleNamespace(Time=time_class),
        "rclpy.qos": pytypes.SimpleNamespace(qos_profile_sensor_data="sensor_data"),
        "tf2_ros": pytypes.SimpleNamespace(
            Buffer=Buffer, TransformListener=lambda buffer, node: None, TransformException=TransformException
        ),
        "apriltag_msgs": pytypes.ModuleType("apriltag_msgs"),
        "apriltag_msgs.msg": pytypes.SimpleNamespace(
            AprilTagDetectionArray=t["apriltag_msgs/msg/AprilTagDetectionArray"]
        ),
        "geometry_msgs": pytypes.ModuleType("geometry_msgs"),
        "geometry_msgs.msg": pytypes.SimpleNamespace(Twist=lambda: zero_twist(store)),
        "sensor_msgs": pytypes.ModuleType("sensor_msgs"),
        "sensor_msgs.msg": pytypes.SimpleNamespace(
            CameraInfo=t["sensor_msgs/msg/CameraInfo"], Imu=t["sensor_msgs/msg/Imu"]
        ),
    }
    modules["rclpy"].executors = modules["rclpy.executors"]
    return modules, Node, published, subscriptions, timers


def test_the_rclpy_glue_wires_topics_tf_and_the_watchdog(store, plan_path, scene, monkeypatch):
    yaw, seen, _, _ = scene
    t = store.types
    w, x, y, z = _quaternion_of(MOUNT.rotation)
    mount = t["geometry_msgs/msg/Transform"](
        translation=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.3),
        rotation=t["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
    )
    modules, node_class, published, subscriptions, timers = _fake_ros(store, {("base_link", "camera_optical"): mount})
    for name, module in modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    monkeypatch.setitem(sys.modules, "bearnav_ros", ros)
    node_module = load("bearnav_node")
    node_class.overrides = {"plan": plan_path, "dynamics": "single", "detections_topic": "/apriltag/detections"}
    node = node_module.BearnavNode()
    assert set(subscriptions) == {"/apriltag/detections", "camera_info", "imu"}
    assert node.logic.settings.dynamics == "single" and node.logic.settings.period == 0.1
    subscriptions["camera_info"][1](camera_info(store))
    subscriptions["imu"][1](imu(store, yaw))
    subscriptions["/apriltag/detections"][1](detections_msg(store, seen))
    assert node.mount_known and np.allclose(node.logic.mount.rotation, MOUNT.rotation)
    (command, _, turn), *_ = reference(plan_path, scene, "single", frames=1)
    topic, twist = published[-1]
    body = (
        math.cos(yaw) * command[0] + math.sin(yaw) * command[1],
        -math.sin(yaw) * command[0] + math.cos(yaw) * command[1],
        turn,
    )
    assert topic == "cmd_vel" and (twist.linear.x, twist.linear.y, twist.angular.z) == pytest.approx(body, abs=1e-9)
    assert node.status == "ok"
    # the camera goes quiet: the watchdog stops the robot once
    ((period, watchdog),) = timers
    node.clock.t = 1.0
    watchdog()
    watchdog()
    assert len(published) == 2 and published[-1][1].linear.x == 0.0 and "no detections" in node.status
