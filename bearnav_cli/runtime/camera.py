"""From AprilTag detections in one image to the world-frame bearings and heading the Controller needs.

Numpy only (and :mod:`bearnav_cli.errors`): this runs on the robot, next to the detector's driver.
``docs/camera.md`` states the conventions, the formulas and what is rejected.

Frames (ROS REP 103 / REP 105):

- **world** (the map): ``x``, ``y`` on the floor, ``z`` up; headings are counter-clockwise from ``+x``;
- **robot** ``J``: ``x`` forward, ``y`` left, ``z`` up, at the robot's map position on the floor;
- **camera optical** ``C``: ``z`` forward, ``x`` right, ``y`` down (``sensor_msgs/CameraInfo``);
- **tag** ``AT``: the AprilTag library's (``apriltag_pose.c``, also what ``apriltag_ros`` publishes):
  origin at the tag centre, ``x`` to the right and ``y`` down as the printed tag is seen from the
  front, ``z = x × y`` into the tag (away from a camera that sees it). Its corner ``p[0]`` is at
  ``(−s, +s)`` (bottom left), then ``(+s, +s)``, ``(+s, −s)``, ``(−s, −s)``. OpenCV's ``solvePnP``
  marker frame has ``y`` up and ``z`` out of the tag: :func:`tag_pose_from_opencv` converts.

The bearing of a tag is the direction of the ray through the tag centre (the intersection of the
undistorted corner diagonals, exact under perspective), in the robot frame through the mount, then
turned by the robot's heading and projected onto the floor. The heading is the compass's when given,
else the one the tag poses give by the paper's ``W_R_J = W_R_AT · (J_R_AT)⁻¹``.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.runtime.bearing import wrap
from bearnav_cli.runtime.camera_model import Intrinsics, Mount, finite, rotation_z

__all__ = [
    "BEHIND_MARGIN",
    "CORNER_SLACK",
    "ROTATION_TOL",
    "Detection",
    "Observation",
    "TagMap",
    "heading_from_tag",
    "observe",
    "project_world",
    "tag_corners_world",
    "tag_number",
    "tag_pose_from_opencv",
    "tag_rotation_world",
]

#: A detection is rejected as seen from behind when its world bearing points past the tag's plane,
#: along the tag's facing, by more than this (rad): ``bearing · facing > sin(BEHIND_MARGIN)``. A
#: detector decodes a tag up to about 75–80° off its normal, so a real view stays ≥ 10° in front of
#: the plane; the 10° here absorb a compass error of the same size on top.
BEHIND_MARGIN = math.radians(10.0)
#: How far (px) a corner may lie outside the image (``[−0.5, size − 0.5]`` with pixel centres at
#: integers) before the detection is rejected: half a pixel, sub-pixel refinement's reach.
CORNER_SLACK = 0.5
#: Per-tag headings that agree within this (rad) are averaged; one that disagrees is left out.
HEADING_AGREEMENT = math.radians(10.0)
#: How far a pose's ``camera_R_tag`` may be from a rotation (``‖RᵀR − I‖_max`` and ``|det R − 1|``): a
#: detector's rotation is orthonormal to float precision; a matrix further off is not a rotation, and
#: the heading taken from it would mean nothing.
ROTATION_TOL = 1e-6


# --------------------------------------------------------------------------- tags


def tag_number(tag_id: str) -> int:
    """The detector's id in a map's landmark id: ``"tag12"``, ``"tag_12"``, ``"12"`` → 12; -1 when none."""
    match = re.fullmatch(r"[A-Za-z_\-]*?(\d+)", str(tag_id).strip())
    return int(match.group(1)) if match else -1


@dataclass(frozen=True, eq=False)
class TagMap:
    """The plan's landmarks as a camera sees them.

    Attributes
    ----------
    numbers : ndarray of int64, shape (L,)
        Detector id of each landmark (-1: the map's id has no number; never matched).
    positions : ndarray, shape (L, 2)
        Tag centres on the map (map units).
    facing : ndarray, shape (L,)
        Direction the printed face looks toward (rad); NaN for a free-standing tag (seen from every
        side, no orientation).
    ids : tuple of str
        The map's ids, for messages.
    """

    numbers: np.ndarray
    positions: np.ndarray
    facing: np.ndarray
    ids: tuple = ()

    def __post_init__(self) -> None:
        numbers = np.array(self.numbers, np.int64).reshape(-1)
        positions = np.array(self.positions, float).reshape(-1, 2)
        facing = np.array(self.facing, float).reshape(-1)
        n = len(numbers)
        if len(positions) != n or len(facing) != n:
            raise InvalidParamsError(
                f"{n} numbers, {len(positions)} positions and {len(facing)} facings", field="landmarks"
            )
        ids = tuple(str(i) for i in self.ids) if self.ids else tuple(str(v) for v in numbers)
        used = numbers[numbers >= 0]
        values, counts = np.unique(used, return_counts=True)
        if (counts > 1).any():
            twice = int(values[counts > 1][0])
            names = [ids[k] for k in np.flatnonzero(numbers == twice)]
            raise InvalidParamsError(
                f"landmarks {', '.join(names)} have the same detector id {twice}", field="landmarks"
            )
        for a in (numbers, positions, facing):
            a.flags.writeable = False
        object.__setattr__(self, "numbers", numbers)
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "facing", facing)
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "_index", {int(v): k for k, v in enumerate(numbers) if v >= 0})

    @classmethod
    def from_map_json(cls, map_json: dict) -> TagMap:
        """From the map JSON embedded in ``plan.npz`` (``json.loads(str(np.load(path)["map"]))``).

        A landmark without ``"facing"`` (maps written before tags had one) is free-standing (NaN).
        """
        try:
            landmarks = map_json["landmarks"]
            ids = tuple(str(lm["id"]) for lm in landmarks)
            positions = np.array([lm["position"] for lm in landmarks], float).reshape(-1, 2)
            facing = np.radians([math.nan if lm.get("facing") is None else float(lm["facing"]) for lm in landmarks])
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise InvalidParamsError(f"not a bearnav map JSON ({type(exc).__name__}: {exc})", field="map") from exc
        return cls(np.array([tag_number(i) for i in ids], np.int64), positions, facing, ids)

    @classmethod
    def from_plan(cls, path: str) -> TagMap:
        """From ``plan.npz`` (the map embedded in it)."""
        with np.load(path, allow_pickle=False) as z:
            return cls.from_map_json(json.loads(str(z["map"])))

    def index(self, number: int) -> int:
        """Row of the landmark with detector id ``number`` (-1 when the plan has none)."""
        return self._index.get(int(number), -1)  # type: ignore[attr-defined]


def tag_rotation_world(facing: float) -> np.ndarray:
    """``W_R_AT`` of an upright tag on a vertical wall whose printed face looks toward ``facing`` (rad).

    Tag ``x`` is to the right of a viewer facing the tag, ``y`` down, ``z`` into the wall
    (AprilTag convention, see the module docstring).
    """
    n = np.array([math.cos(facing), math.sin(facing), 0.0])
    return np.column_stack([[-n[1], n[0], 0.0], [0.0, 0.0, -1.0], -n])


def tag_corners_world(position: Any, facing: float, size: float, height: float) -> np.ndarray:
    """The four corners (3-D world points, AprilTag order) of an upright tag.

    Parameters
    ----------
    position : array_like, shape (2,)
        The tag's centre on the map (map units).
    facing : float
        Direction its printed face looks toward (rad, world frame); see :func:`tag_rotation_world`.
    size : float
        Edge of the black square (map units).
    height : float
        Height of the tag's centre above the floor (map units).

    Returns
    -------
    ndarray, shape (4, 3)
        World points ``(x, y, z)`` (map units) in AprilTag order: bottom left, bottom right, top
        right, top left as a viewer facing the tag sees them (tag frame ``(−s, +s)``, ``(+s, +s)``,
        ``(+s, −s)``, ``(−s, −s)`` with ``s = size/2``, ``y`` down).
    """
    centre = np.array([*np.asarray(position, float).reshape(2), height])
    s = 0.5 * size
    local = np.array([[-s, s, 0.0], [s, s, 0.0], [s, -s, 0.0], [-s, -s, 0.0]])
    return centre + local @ tag_rotation_world(facing).T


def project_world(intrinsics: Intrinsics, mount: Mount, x: Any, heading: float, points: Any) -> tuple:
    """Pixels and optical depth of world points seen by a robot at ``x`` (map units) with yaw ``heading``.

    For tests and simulations (a robot never knows its true pose).

    Parameters
    ----------
    intrinsics : Intrinsics
        The camera's pinhole model with lens distortion, which maps optical-frame points to pixels.
    mount : Mount
        Where the camera sits on the robot.
    x : array_like, shape (2,)
        The robot's position on the floor (map units).
    heading : float
        The robot's yaw (rad, world frame, counter-clockwise from ``+x``).
    points : array_like, shape (n, 3)
        World points ``(x, y, z)`` (map units), e.g. from :func:`tag_corners_world`.

    Returns
    -------
    pixels : ndarray, shape (n, 2)
        Image coordinates (pixels); meaningless for points behind the camera.
    depth : ndarray, shape (n,)
        Optical depth ``z`` in the camera frame (map units); ``<= 0`` behind the camera.
    """
    p = np.asarray(points, float).reshape(-1, 3)
    origin = np.array([*np.asarray(x, float).reshape(2), 0.0])
    world_r_cam = rotation_z(heading) @ mount.rotation
    cam = (p - origin - rotation_z(heading) @ mount.translation) @ world_r_cam
    return intrinsics.project(np.where(cam[:, 2:3] > 0, cam, 1.0)), cam[:, 2]


def tag_pose_from_opencv(rotation: Any, translation: Any) -> tuple[np.ndarray, np.ndarray]:
    """An OpenCV marker pose (``solvePnP``: ``y`` up, ``z`` out of the tag) in the AprilTag convention.

    ``rotation`` is a rotation vector (3,) or matrix (3, 3); returns ``(camera_R_tag, camera_t_tag)``.
    """
    r = np.asarray(rotation, float)
    if r.shape in ((3,), (3, 1), (1, 3)):
        v = r.reshape(3)
        angle = float(np.linalg.norm(v))
        if angle < 1e-15:
            r = np.eye(3)
        else:
            k = v / angle
            kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
            r = np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx
    return r.reshape(3, 3) @ np.diag([1.0, -1.0, -1.0]), np.asarray(translation, float).reshape(3).copy()


def heading_from_tag(camera_R_tag: Any, tag_facing: float, mount: Mount) -> float:  # noqa: N803 (the paper's name)
    """The robot's heading from one tag's pose: the paper's ``W_R_J = W_R_AT · (J_R_AT)⁻¹``.

    Parameters
    ----------
    camera_R_tag : array_like, shape (3, 3)
        The detector's tag orientation in the optical frame (AprilTag convention: tag ``x`` right,
        ``y`` down, ``z`` into the tag; :func:`tag_pose_from_opencv` converts OpenCV's).
    tag_facing : float
        The tag's facing on the map (rad): it is upright on a vertical wall, so
        ``W_R_AT`` = :func:`tag_rotation_world`.
    mount : Mount
        ``J_R_AT = robot_R_camera · camera_R_tag``.

    Returns
    -------
    float
        The yaw of ``W_R_J`` (rad, in ``(−π, π]``): the angle of the robot's ``x`` axis projected on
        the floor (a pose that is not exactly level still gives the nearest yaw).
    """
    r = np.asarray(camera_R_tag, float)
    if r.shape != (3, 3) or not np.all(np.isfinite(r)):
        raise InvalidParamsError("expected a finite 3 × 3 rotation", field="camera_R_tag")
    if not math.isfinite(tag_facing):
        raise InvalidParamsError(
            "a free-standing tag (facing NaN) has no known orientation to take a heading from", field="tag_facing"
        )
    w_r_j = tag_rotation_world(tag_facing) @ (mount.rotation @ r).T
    return math.atan2(w_r_j[1, 0], w_r_j[0, 0])


# --------------------------------------------------------------------------- observe


@dataclass(frozen=True, eq=False)
class Detection:
    """One AprilTag found in an image.

    Attributes
    ----------
    tag_id : int
        The detector's id (tag36h11: 0–586).
    corners : ndarray, shape (4, 2)
        Corner pixels in the detector's order (AprilTag's counter-clockwise or OpenCV's clockwise:
        the centre is the intersection of the diagonals 0–2 and 1–3 either way).
    pose : tuple of ndarray, optional
        ``(camera_R_tag (3, 3), camera_t_tag (3,))`` in the AprilTag tag convention (metres).
    """

    tag_id: int
    corners: np.ndarray
    pose: tuple | None = None

    def __post_init__(self) -> None:
        corners = _numbers(self.corners, "corners")
        if corners.shape != (4, 2):
            raise InvalidParamsError(f"expected 4 corners (4, 2), got shape {corners.shape}", field="corners")
        corners.flags.writeable = False
        object.__setattr__(self, "corners", corners)
        tag_id = self.tag_id
        if (
            isinstance(tag_id, (bool, np.bool_))
            or not isinstance(tag_id, (int, np.integer, float, np.floating))
            or not (math.isfinite(tag_id) and float(tag_id).is_integer() and tag_id >= 0)
        ):
            raise InvalidParamsError(f"expected a whole number 0 or more, got {tag_id!r}", field="tag_id")
        object.__setattr__(self, "tag_id", int(tag_id))
        if self.pose is not None:
            if not isinstance(self.pose, (tuple, list)) or len(self.pose) != 2:
                raise InvalidParamsError("expected (camera_R_tag (3, 3), camera_t_tag (3,))", field="pose")
            r, t = (_numbers(v, "pose") for v in self.pose)
            if r.shape != (3, 3) or t.reshape(-1).shape != (3,):
                raise InvalidParamsError("expected (camera_R_tag (3, 3), camera_t_tag (3,))", field="pose")
            t = t.reshape(3)
            with np.errstate(over="ignore", invalid="ignore"):
                off = max(float(np.max(np.abs(r.T @ r - np.eye(3)))), abs(float(np.linalg.det(r)) - 1.0))
                rng = math.hypot(*t)  # scaled: no overflow for a far but finite tag
            if not off <= ROTATION_TOL:
                raise InvalidParamsError(f"camera_R_tag is not a rotation (off by {off:.3g})", field="pose")
            if not math.isfinite(rng):
                raise InvalidParamsError("camera_t_tag must be finite, with a finite length (m)", field="pose")
            object.__setattr__(self, "pose", (r, t))


def _numbers(value: Any, name: str) -> np.ndarray:
    """``value`` as a float array, or the project's one-line error naming ``name`` (text, ragged lists)."""
    try:
        return np.array(value, float)
    except (TypeError, ValueError):
        raise InvalidParamsError(f"expected numbers, got {value!r:.60}", field=name) from None


@dataclass(frozen=True, eq=False)
class Observation:
    """What one image says, in the form :meth:`Controller.command` takes.

    Attributes
    ----------
    bearings : ndarray, shape (L, 2)
        World-frame unit bearing of each landmark (zero rows where not visible).
    visible : ndarray of bool, shape (L,)
        Landmarks with an accepted detection in this image.
    heading : float or None
        The robot heading used (rad): the compass's if given, else from the tag poses (the circular
        mean of the per-tag headings that agree, :data:`HEADING_AGREEMENT`); None without either.
    unknown, from_behind, outside_image, duplicates : int
        Rejected detections: ids not in the plan; seen from behind (:data:`BEHIND_MARGIN`); a corner
        outside the image by more than :data:`CORNER_SLACK`; a second detection of the same tag.
    pose_heading : float or None
        The heading the tag poses gave (also when a compass heading was used: compare them).
    """

    bearings: np.ndarray
    visible: np.ndarray
    heading: float | None
    unknown: int = 0
    from_behind: int = 0
    outside_image: int = 0
    duplicates: int = 0
    pose_heading: float | None = None

    @property
    def rejected(self) -> int:
        """All rejected detections."""
        return self.unknown + self.from_behind + self.outside_image + self.duplicates


def _mean_heading(headings: list[float]) -> float | None:
    """Circular mean of the largest group of headings that agree within :data:`HEADING_AGREEMENT`."""
    if not headings:
        return None
    h = np.array(headings)
    diff = np.abs(wrap(h[:, None] - h[None, :]))
    best = int(np.argmax((diff <= HEADING_AGREEMENT).sum(axis=1)))
    group = h[diff[best] <= HEADING_AGREEMENT]
    return float(np.angle(np.exp(1j * group).mean()))


def observe(
    detections: Any,
    intrinsics: Intrinsics,
    mount: Mount,
    tags: TagMap,
    heading: float | None = None,
    *,
    behind_margin: float = BEHIND_MARGIN,
) -> Observation:
    """World-frame bearings (and the heading) from the AprilTag detections in one image.

    Parameters
    ----------
    detections : iterable of Detection
        What the AprilTag detector found in the image (corner pixels, optionally a pose).
    intrinsics : Intrinsics
        The camera that took the image: its pinhole model (with lens distortion) turns corner
        pixels into rays, and its image size bounds the corners (:data:`CORNER_SLACK`).
    mount : Mount
        Where the camera sits on the robot: turns camera rays into robot-frame bearings.
    tags : TagMap
        The plan's landmarks (:meth:`TagMap.from_plan`), in the order of the Controller's rows.
    heading : float, optional
        The compass yaw (rad). Without it the tag poses give the heading; a frame with accepted
        detections but neither raises.
    behind_margin : float
        See :data:`BEHIND_MARGIN` (rad).

    Returns
    -------
    Observation

    Raises
    ------
    InvalidParamsError
        No heading: neither the compass nor a detection with a pose of a tag with a known facing.

    Notes
    -----
    Rejected, and counted in the result: ids not among the plan's (``unknown``), detections with a
    corner outside the image by more than :data:`CORNER_SLACK` (``outside_image``; a real detector
    never returns one), a tag seen from behind (``from_behind``: its bearing points along its facing
    past the tag's plane by more than ``behind_margin``: a printed tag cannot be seen from behind, so
    it is a misidentification or a reflection) and a second detection of a tag (``duplicates``).
    When a detection carries a pose, its range ``‖camera_t_tag‖`` places the tag along the ray, so
    the bearing is taken from the robot's origin (no parallax from a camera off the robot's centre);
    without one it is the ray's direction from the camera centre.
    """
    n_lm = len(tags.numbers)
    bearings, visible = np.zeros((n_lm, 2)), np.zeros(n_lm, bool)
    unknown = outside = duplicates = behind = 0
    lo = -0.5 - CORNER_SLACK
    hi_u, hi_v = intrinsics.width - 0.5 + CORNER_SLACK, intrinsics.height - 0.5 + CORNER_SLACK
    accepted: list[tuple[int, Detection]] = []
    seen: set[int] = set()
    for det in detections:
        k = tags.index(det.tag_id)
        if k < 0:
            unknown += 1
            continue
        c = det.corners
        if not np.all(np.isfinite(c)) or (c < lo).any() or (c[:, 0] > hi_u).any() or (c[:, 1] > hi_v).any():
            outside += 1
            continue
        if k in seen:
            duplicates += 1
            continue
        seen.add(k)
        accepted.append((k, det))
    pose_headings = [
        heading_from_tag(det.pose[0], float(tags.facing[k]), mount)
        for k, det in accepted
        if det.pose is not None and math.isfinite(tags.facing[k])
    ]
    pose_heading = _mean_heading(pose_headings)
    if heading is not None:
        heading = finite(heading, "heading")
    elif accepted:
        if pose_heading is None:
            raise InvalidParamsError(
                "no heading: pass the compass yaw, or detections with tag poses (of tags with a known facing)",
                field="heading",
            )
        heading = pose_heading
    if accepted:
        corners = np.stack([det.corners for _, det in accepted])  # (m, 4, 2)
        xy = intrinsics.undistort(corners.reshape(-1, 2)).reshape(-1, 4, 2)
        centre = _diagonals(xy)
        ray = np.column_stack([centre, np.ones(len(centre))])
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        world_r_robot = rotation_z(heading)
        sin_margin = math.sin(behind_margin)
        for (k, det), r in zip(accepted, ray, strict=True):
            v = mount.rotation @ r
            if det.pose is not None and np.all(np.isfinite(det.pose[1])):
                v = mount.translation + v * math.hypot(*det.pose[1])
            w = (world_r_robot @ v)[:2]
            norm = math.hypot(w[0], w[1])
            if not 1e-12 <= norm < math.inf:  # straight up or down: no direction on the floor
                continue
            b = w / norm
            f = tags.facing[k]
            if math.isfinite(f) and b[0] * math.cos(f) + b[1] * math.sin(f) > sin_margin:
                behind += 1
                continue
            bearings[k], visible[k] = b, True
    return Observation(
        bearings,
        visible,
        heading,
        unknown=unknown,
        from_behind=behind,
        outside_image=outside,
        duplicates=duplicates,
        pose_heading=pose_heading,
    )


def _diagonals(xy: np.ndarray) -> np.ndarray:
    """Intersection of the diagonals 0–2 and 1–3 of quads (m, 4, 2) → (m, 2); the mean of the corners
    when they are parallel (a degenerate quad)."""
    p, r = xy[:, 0], xy[:, 2] - xy[:, 0]
    q, s = xy[:, 1], xy[:, 3] - xy[:, 1]
    den = r[:, 0] * s[:, 1] - r[:, 1] * s[:, 0]
    qp = q - p
    t = (qp[:, 0] * s[:, 1] - qp[:, 1] * s[:, 0]) / np.where(den != 0, den, 1.0)
    out = p + t[:, None] * r
    return np.where((np.abs(den) > 1e-300)[:, None], out, xy.mean(axis=1))
