"""The logic of the bearnav ROS 2 node, importable without ROS 2 (numpy and ``bearnav_cli.runtime`` only).

``bearnav_node.py`` is the rclpy glue: it forwards each message to :class:`BearnavLogic` and
publishes what it returns. Everything here is duck-typed on message attributes, so it works on
rclpy messages and on ``rosbags`` message dataclasses alike (the tests use the latter):

- :func:`detections_from_msg`: ``apriltag_msgs/AprilTagDetectionArray`` → ``runtime.camera.Detection``;
- :func:`intrinsics_from_camera_info`: ``sensor_msgs/CameraInfo`` → ``runtime.camera_model.Intrinsics``;
- :func:`yaw_from_quaternion`, :func:`pose_from_transform`, :func:`mount_from_transform`: ``geometry_msgs``;
- :func:`twist_from_command`, :func:`fill_twist`: a :class:`~bearnav_cli.runtime.Controller` command
  → ``geometry_msgs/Twist`` in the robot's body frame (REP 103: ``x`` forward, ``y`` left).

The bearings come from ``runtime.camera.observe`` (docs/camera.md) and the command from
``Controller.command``: the same code ``bearnav simulate`` is checked with.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.runtime import ESTIMATORS, Controller, camera, camera_model
from bearnav_cli.runtime.defaults import BEARING_SIGMA, LOOP_DEFAULTS

__all__ = [
    "BearnavLogic",
    "HEADING_SOURCES",
    "Settings",
    "Step",
    "camera_yaw",
    "detections_from_msg",
    "fill_twist",
    "intrinsics_from_camera_info",
    "mount_from_transform",
    "pose_from_transform",
    "rotation_from_quaternion",
    "tag_frame",
    "twist_from_command",
    "yaw_from_quaternion",
]

#: Where the robot's yaw comes from: a compass (``sensor_msgs/Imu`` with an absolute yaw) or the
#: tag poses (TF from ``apriltag_ros``, tags with a known facing on the map).
HEADING_SOURCES = ("imu", "tags")


def _xy(value: Any) -> np.ndarray:
    """Pixel points as (n, 2): ``apriltag_msgs/Point`` objects (``x``, ``y``) or a flat ``[x1, y1, ...]``."""
    items = list(value)
    if items and hasattr(items[0], "x"):
        return np.array([[float(p.x), float(p.y)] for p in items])
    return np.asarray(items, float).reshape(-1, 2)


def _family(name: Any) -> str:
    """``"tag36h11"`` and ``"36h11"`` alike → ``"36h11"``."""
    text = str(name).strip()
    return text[3:] if text.lower().startswith("tag") else text


def tag_frame(family: str, tag_id: int, template: str = "{family}:{id}") -> str:
    """The TF frame ``apriltag_ros`` publishes a tag's pose in (default ``tag36h11:3``)."""
    return template.format(family=family, id=int(tag_id))


def detections_from_msg(msg: Any, family: str = "", poses: Mapping[int, tuple] | None = None) -> list[camera.Detection]:
    """The detections of one ``apriltag_msgs/AprilTagDetectionArray``.

    Parameters
    ----------
    msg : AprilTagDetectionArray
        ``detections[]`` with ``family``, ``id`` and ``corners`` (4 ``Point`` of pixels, or the
        8 numbers of older ``apriltag_msgs``), in the detector's order.
    family : str
        Keep only this family (``"36h11"`` or ``"tag36h11"``); empty: every family.
    poses : mapping, optional
        ``{tag id: (camera_R_tag (3, 3), camera_t_tag (3,))}``, from TF (:func:`pose_from_transform`).

    Returns
    -------
    list of Detection
    """
    keep = _family(family) if family else None
    out = []
    for det in msg.detections:
        if keep is not None and _family(det.family) != keep:
            continue
        tag_id = int(det.id)
        pose = None if poses is None else poses.get(tag_id)
        out.append(camera.Detection(tag_id=tag_id, corners=_xy(det.corners), pose=pose))
    return out


def intrinsics_from_camera_info(msg: Any, rectified: bool = True) -> camera_model.Intrinsics:
    """The camera of one ``sensor_msgs/CameraInfo``.

    Parameters
    ----------
    msg : CameraInfo
    rectified : bool
        The detector runs on the rectified image (``image_rect``, what ``apriltag_ros`` expects):
        its pixels follow the projection ``P`` without distortion. False: the raw image, ``K``
        and ``D`` (``distortion_model``).
    """
    width, height = int(msg.width), int(msg.height)
    if rectified:
        p = np.asarray(msg.p, float).reshape(-1)
        if p.shape != (12,):
            raise InvalidParamsError(f"expected the 12 numbers of CameraInfo.p, got {p.size}", field="p")
        k = [p[0], p[1], p[2], p[4], p[5], p[6], p[8], p[9], p[10]]
        return camera_model.Intrinsics.from_camera_info(k, (), width, height)
    model = str(msg.distortion_model or "plumb_bob")
    return camera_model.Intrinsics.from_camera_info(msg.k, msg.d, width, height, model)


def yaw_from_quaternion(q: Any) -> float:
    """The yaw (rad, about ``+z``, in ``(−π, π]``) of a ``geometry_msgs/Quaternion``."""
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def rotation_from_quaternion(q: Any) -> np.ndarray:
    """The rotation matrix (3, 3) of a ``geometry_msgs/Quaternion`` (normalised first)."""
    v = np.array([float(q.w), float(q.x), float(q.y), float(q.z)])
    norm = np.linalg.norm(v)
    if not np.isfinite(norm) or norm < 1e-12:
        raise InvalidParamsError("not a rotation: a zero or non-finite quaternion", field="rotation")
    w, x, y, z = v / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


def pose_from_transform(transform: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(parent_R_child (3, 3), parent_t_child (3,))`` of a ``geometry_msgs/Transform``.

    For the camera → tag transform ``apriltag_ros`` publishes, that is ``(camera_R_tag, camera_t_tag)``.
    """
    t = transform.translation
    return rotation_from_quaternion(transform.rotation), np.array([float(t.x), float(t.y), float(t.z)])


def mount_from_transform(transform: Any) -> camera_model.Mount:
    """The camera mount from the ``base_link → camera optical frame`` transform (TF)."""
    rotation, translation = pose_from_transform(transform)
    return camera_model.Mount(rotation, translation)


def camera_yaw(mount: camera_model.Mount) -> float:
    """Yaw (rad) of the camera's optical axis in the robot frame."""
    axis = mount.rotation[:, 2]
    return math.atan2(axis[1], axis[0])


def twist_from_command(command: Any, dynamics: str, yaw: float, turn: float = 0.0) -> tuple[float, float, float]:
    """``(linear.x, linear.y, angular.z)`` of the ``Twist`` for one :meth:`Controller.command`.

    Parameters
    ----------
    command : array_like, shape (2,)
        Unicycle: ``(v, ω)``; single integrator: ``(vx, vy)`` in the map frame.
    dynamics : {"single", "unicycle"}
    yaw : float
        The robot's yaw (rad): a holonomic base's map-frame velocity is turned into its body frame.
    turn : float
        Single integrator: the rate (rad/s) to turn while it looks around (``ctl.last.turn``).
    """
    a, b = (float(v) for v in np.asarray(command, float).reshape(2))
    if dynamics == "unicycle":
        return a, 0.0, b
    c, s = math.cos(yaw), math.sin(yaw)
    return c * a + s * b, -s * a + c * b, float(turn)


def fill_twist(twist: Any, values: Iterable[float]) -> Any:
    """Set ``linear.x``, ``linear.y`` and ``angular.z`` of a ``geometry_msgs/Twist`` (the rest 0)."""
    lx, ly, az = (float(v) for v in values)
    twist.linear.x, twist.linear.y, twist.linear.z = lx, ly, 0.0
    twist.angular.x, twist.angular.y, twist.angular.z = 0.0, 0.0, az
    return twist


@dataclass(frozen=True)
class Settings:
    """The node's parameters (``README.md`` next to this file), SI units and radians.

    ``period`` must be the detector's frame period: the controller advances its hold timer and
    odometry by it on every frame. ``yaw_offset`` is added to the compass yaw (the map's ``x`` axis
    need not point east). ``mount_height``/``mount_yaw`` place a level forward camera when TF has
    no ``base_frame → camera`` transform.
    """

    plan: str
    dynamics: str = "unicycle"
    speed: float = LOOP_DEFAULTS["speed"]
    alpha: float = LOOP_DEFAULTS["alpha"]
    beta: float = LOOP_DEFAULTS["beta"]
    clamp_reverse: bool = LOOP_DEFAULTS["clamp_reverse"]
    hold_time: float = LOOP_DEFAULTS["hold_time"]
    period: float = 0.1
    bearing_sigma: float = BEARING_SIGMA
    estimator: str = LOOP_DEFAULTS["estimator"]
    heading_source: str = "imu"
    yaw_offset: float = 0.0
    family: str = ""
    rectified: bool = True
    mount_height: float = 0.0
    mount_yaw: float = 0.0

    def __post_init__(self) -> None:
        if self.heading_source not in HEADING_SOURCES:
            raise InvalidParamsError(
                f"expected one of {', '.join(HEADING_SOURCES)}, got {self.heading_source!r}", field="heading_source"
            )
        if self.estimator not in ESTIMATORS:
            raise InvalidParamsError(
                f"expected one of {', '.join(ESTIMATORS)}, got {self.estimator!r}", field="estimator"
            )
        if not self.period > 0:
            raise InvalidParamsError(f"the camera period must be positive (s), got {self.period}", field="period")

    def controller(self) -> Controller:
        return Controller.from_plan(
            self.plan,
            speed=self.speed,
            dt=self.period,
            dynamics=self.dynamics,
            alpha=self.alpha,
            beta=self.beta,
            clamp_reverse=self.clamp_reverse,
            hold_time=self.hold_time,
            bearing_sigma=self.bearing_sigma,
            estimator=self.estimator,
        )


@dataclass
class Step:
    """What one detection message gave.

    Attributes
    ----------
    twist : tuple of float
        ``(linear.x, linear.y, angular.z)`` to publish (zeros while waiting, lost or arrived).
    status : str
        ``ok``, ``arrived``, ``lost``, ``waiting for camera_info``, ``waiting for the compass`` or
        ``waiting for a tag pose``.
    observation : Observation or None
        The bearings, heading and rejected detections of the frame (None while waiting).
    command : ndarray or None
        What :meth:`Controller.command` returned.
    """

    twist: tuple[float, float, float]
    status: str
    observation: camera.Observation | None = None
    command: np.ndarray | None = field(default=None, repr=False)


ZERO = (0.0, 0.0, 0.0)


class BearnavLogic:
    """One robot: the plan's tags, the camera, the heading and the :class:`Controller`, fed message by message.

    Parameters
    ----------
    settings : Settings
    mount : Mount, optional
        Default: ``Mount.forward(settings.mount_height, settings.mount_yaw)``; :meth:`set_mount`
        replaces it (from TF).
    """

    def __init__(self, settings: Settings, mount: camera_model.Mount | None = None) -> None:
        self.settings = settings
        self.tags = camera.TagMap.from_plan(settings.plan)
        self.controller = settings.controller()
        self.mount = mount or camera_model.Mount.forward(settings.mount_height, settings.mount_yaw)
        self.intrinsics: camera_model.Intrinsics | None = None
        self.compass: float | None = None
        self.yaw: float | None = None  # the last heading used (tag-pose source: carried by the turn rate)

    def set_mount(self, mount: camera_model.Mount) -> None:
        self.mount = mount

    def on_camera_info(self, msg: Any) -> camera_model.Intrinsics:
        self.intrinsics = intrinsics_from_camera_info(msg, self.settings.rectified)
        return self.intrinsics

    def on_imu(self, msg: Any) -> float:
        """Store the compass yaw (plus ``yaw_offset``) of a ``sensor_msgs/Imu``; return it."""
        yaw = yaw_from_quaternion(msg.orientation) + self.settings.yaw_offset
        self.compass = math.atan2(math.sin(yaw), math.cos(yaw))
        return self.compass

    def tag_frames(self, msg: Any, template: str = "{family}:{id}") -> dict[int, str]:
        """``{tag id: TF frame}`` of the plan's tags in a detection message (to look their poses up)."""
        keep = _family(self.settings.family) if self.settings.family else None
        return {
            int(d.id): tag_frame(d.family, d.id, template)
            for d in msg.detections
            if self.tags.index(int(d.id)) >= 0 and (keep is None or _family(d.family) == keep)
        }

    def on_detections(self, msg: Any, poses: Mapping[int, tuple] | None = None) -> Step:
        """The twist for one ``AprilTagDetectionArray`` (``poses``: tag id → camera pose, from TF)."""
        if self.intrinsics is None:
            return Step(ZERO, "waiting for camera_info")
        detections = detections_from_msg(msg, self.settings.family, poses)
        if self.settings.heading_source == "imu":
            if self.compass is None:
                return Step(ZERO, "waiting for the compass")
            obs = camera.observe(detections, self.intrinsics, self.mount, self.tags, self.compass)
        else:
            try:  # the tag poses give the heading ...
                obs = camera.observe(detections, self.intrinsics, self.mount, self.tags)
            except InvalidParamsError:  # ... none here: the last one, carried by the turn rate
                obs = None
            if obs is None or obs.heading is None:
                if self.yaw is None:
                    return Step(ZERO, "waiting for a tag pose")
                obs = camera.observe(detections, self.intrinsics, self.mount, self.tags, self.yaw)
        yaw = float(obs.heading)
        single = self.settings.dynamics != "unicycle"
        command = self.controller.command(
            obs.bearings, obs.visible, heading=yaw + camera_yaw(self.mount) if single else yaw
        )
        last = self.controller.last
        turn = float(last.turn[0]) if single and last is not None else 0.0
        twist = twist_from_command(command, self.settings.dynamics, yaw, turn)
        self.yaw = yaw + self.settings.period * twist[2]
        if self.controller.arrived:
            return Step(ZERO, "arrived", obs, command)
        if self.controller.lost:
            return Step(ZERO, "lost", obs, command)
        return Step(twist, "ok", obs, command)
