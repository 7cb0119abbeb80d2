#!/usr/bin/env python3
"""bearnav on a ROS 2 robot: AprilTag detections in, ``geometry_msgs/Twist`` out (README.md next to this file).

Thin rclpy glue around ``bearnav_ros.BearnavLogic`` (the same folder; no ROS 2 needed to import or
test it): parameters, subscriptions, TF look-ups, publishing. Run it with::

    python3 bearnav_node.py --ros-args -p plan:=/path/to/plan.npz -p heading_source:=imu

Subscribes ``detections`` (``apriltag_msgs/AprilTagDetectionArray``, christianrauch/apriltag_ros),
``camera_info`` (``sensor_msgs/CameraInfo``) and, with ``heading_source:=imu``, ``imu``
(``sensor_msgs/Imu`` with an absolute yaw); publishes ``cmd_vel`` (``geometry_msgs/Twist``). The
topic names are parameters, and remapping works as usual.
"""

from __future__ import annotations

import sys
from pathlib import Path

import rclpy
import rclpy.executors
import tf2_ros
from apriltag_msgs.msg import AprilTagDetectionArray
from geometry_msgs.msg import Twist
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.time import Time
from sensor_msgs.msg import CameraInfo, Imu

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bearnav_ros.py sits next to this file
from bearnav_ros import BearnavLogic, Settings, fill_twist, mount_from_transform, pose_from_transform  # noqa: E402

#: Parameter -> default (types follow the defaults; angles in radians, lengths in metres = map units): the
#: ``Settings`` fields' defaults (the loop's from ``runtime.defaults``), then the node's frames and topics.
PARAMETERS = {
    "plan": "",
    **{name: field.default for name, field in Settings.__dataclass_fields__.items() if name != "plan"},
    "base_frame": "base_link",
    "tag_frame_format": "{family}:{id}",
    "detections_topic": "detections",
    "camera_info_topic": "camera_info",
    "imu_topic": "imu",
    "cmd_vel_topic": "cmd_vel",
}
#: ``Settings`` fields among the parameters.
SETTINGS = tuple(name for name in PARAMETERS if name in Settings.__dataclass_fields__)


class BearnavNode(Node):
    """The node: parameters (``PARAMETERS``), three subscriptions, one publisher, a watchdog."""

    def __init__(self) -> None:
        super().__init__("bearnav")
        for name, default in PARAMETERS.items():
            self.declare_parameter(name, default)
        self.param = {name: self.get_parameter(name).value for name in PARAMETERS}
        if not self.param["plan"]:
            raise SystemExit("bearnav: set the plan: --ros-args -p plan:=/path/to/plan.npz")
        settings = Settings(**{name: self.param[name] for name in SETTINGS})
        self.logic = BearnavLogic(settings)
        self.mount_known = False
        self.status = ""
        self.last_frame = self.get_clock().now()
        self.tf = tf2_ros.Buffer()
        self.listener = tf2_ros.TransformListener(self.tf, self)
        self.pub = self.create_publisher(Twist, self.param["cmd_vel_topic"], 10)
        self.create_subscription(
            CameraInfo, self.param["camera_info_topic"], self.on_camera_info, qos_profile_sensor_data
        )
        if settings.heading_source == "imu":
            self.create_subscription(Imu, self.param["imu_topic"], self.logic.on_imu, qos_profile_sensor_data)
        self.create_subscription(
            AprilTagDetectionArray, self.param["detections_topic"], self.on_detections, qos_profile_sensor_data
        )  # best effort: matches any publisher
        self.create_timer(settings.period, self.watchdog)
        lookahead = self.logic.controller.arrays.lookahead
        self.get_logger().info(
            f"bearnav: {len(self.logic.tags.numbers)} tags, {settings.dynamics}, "
            f"heading from {settings.heading_source}" + (f", look-ahead {lookahead:g} m" if lookahead > 0 else "")
        )

    def publish(self, values: tuple) -> None:
        self.pub.publish(fill_twist(Twist(), values))

    def report(self, status: str) -> None:
        if status != self.status:  # log changes only, not every frame
            log = self.get_logger()
            (log.info if status in ("ok", "arrived") else log.warning)(f"bearnav: {status}")
            self.status = status

    def on_camera_info(self, msg: CameraInfo) -> None:
        try:
            self.logic.on_camera_info(msg)
        except ValueError as exc:
            self.report(f"camera_info refused: {exc}")

    def lookup(self, target: str, source: str, stamp: Time | None = None):
        try:
            return self.tf.lookup_transform(target, source, stamp or Time(), timeout=Duration(seconds=0.02)).transform
        except tf2_ros.TransformException:
            return None

    def on_detections(self, msg: AprilTagDetectionArray) -> None:
        self.last_frame = self.get_clock().now()
        camera_frame = msg.header.frame_id
        if not self.mount_known and camera_frame:  # base_link -> camera optical frame, once
            transform = self.lookup(self.param["base_frame"], camera_frame)
            if transform is not None:
                self.logic.set_mount(mount_from_transform(transform))
                self.mount_known = True
        poses = None
        if self.logic.settings.heading_source == "tags":
            stamp = Time.from_msg(msg.header.stamp)
            poses = {}
            for tag_id, frame in self.logic.tag_frames(msg, self.param["tag_frame_format"]).items():
                transform = self.lookup(camera_frame, frame, stamp)
                if transform is not None:
                    poses[tag_id] = pose_from_transform(transform)
        try:
            step = self.logic.on_detections(msg, poses)
        except ValueError as exc:  # a detection the runtime refuses: stop, say why
            self.publish((0.0, 0.0, 0.0))
            self.report(f"frame refused: {exc}")
            return
        self.publish(step.twist)
        self.report(step.status)

    def watchdog(self) -> None:
        """No detection message for five periods (a camera or detector that died): stop."""
        silent = self.get_clock().now() - self.last_frame > Duration(seconds=5 * self.logic.settings.period)
        if silent and self.status != "no detections: stopped":  # one zero twist, then quiet
            self.publish((0.0, 0.0, 0.0))
            self.report("no detections: stopped")


def main(args: list[str] | None = None) -> None:
    rclpy.init(args=args)
    node = BearnavNode()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        try:
            node.publish((0.0, 0.0, 0.0))  # stop the robot on the way out
        except Exception:  # noqa: BLE001 - the context may be gone already
            pass
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
