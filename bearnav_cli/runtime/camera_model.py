"""The camera itself: its intrinsics (pinhole with Brown–Conrady distortion) and its mount on the robot.

Numpy only (and :mod:`bearnav_cli.errors`). :class:`Intrinsics` maps pixels to rays and back
(``sensor_msgs/CameraInfo``'s ``K`` and ``D``), :class:`Mount` places the camera on the robot
(``base_link → camera optical frame``). :mod:`bearnav_cli.runtime.camera` turns detections into
bearings with them; ``docs/camera.md`` states the frames and conventions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.runtime.invariants import is_number

__all__ = ["DISTORTION_MODELS", "Intrinsics", "Mount", "finite", "rotation_z"]

#: Distortion models of ``sensor_msgs/CameraInfo`` understood (both are the Brown–Conrady model).
DISTORTION_MODELS = ("plumb_bob", "rational_polynomial")


def finite(value: Any, name: str) -> float:
    """``value`` as a finite float; :class:`InvalidParamsError` naming ``name`` otherwise."""
    if not is_number(value):
        raise InvalidParamsError(f"expected a number, got {value!r}", field=name)
    if not math.isfinite(float(value)):
        raise InvalidParamsError(f"must be finite, got {value}", field=name)
    return float(value)


# --------------------------------------------------------------------------- intrinsics


@dataclass(frozen=True)
class Intrinsics:
    """A pinhole camera with Brown–Conrady distortion, as in ``sensor_msgs/CameraInfo``.

    Attributes
    ----------
    fx, fy : float
        Focal lengths (px), positive.
    cx, cy : float
        Principal point (px; pixel centres at integer coordinates, as in OpenCV and ROS).
    width, height : int
        Image size (px).
    distortion : tuple of float
        ``CameraInfo.d``: ``plumb_bob`` ``(k1, k2, t1, t2[, k3])``, or the 8 coefficients of
        ``rational_polynomial`` ``(k1, k2, t1, t2, k3, k4, k5, k6)``; empty (or zeros) for none.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    distortion: tuple = ()

    def __post_init__(self) -> None:
        for name in ("fx", "fy"):
            value = finite(getattr(self, name), name)
            if value <= 0:
                raise InvalidParamsError(f"the focal length must be positive (px), got {value}", field=name)
            object.__setattr__(self, name, value)
        for name in ("cx", "cy"):
            object.__setattr__(self, name, finite(getattr(self, name), name))
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
                raise InvalidParamsError(f"must be a positive number of pixels, got {value!r}", field=name)
            object.__setattr__(self, name, int(value))
        d = tuple(finite(v, "distortion") for v in self.distortion)
        if len(d) not in (0, 4, 5, 8):
            raise InvalidParamsError(
                f"expected 0, 4, 5 (plumb_bob) or 8 (rational_polynomial) coefficients, got {len(d)}",
                field="distortion",
            )
        object.__setattr__(self, "distortion", d)

    @classmethod
    def from_camera_info(
        cls, k: Any, d: Any, width: int, height: int, distortion_model: str = "plumb_bob"
    ) -> Intrinsics:
        """From the fields of a ``sensor_msgs/CameraInfo``.

        Parameters
        ----------
        k : sequence of 9 float
            ``CameraInfo.k`` (``K``), row-major ``[fx, 0, cx, 0, fy, cy, 0, 0, 1]``.
        d : sequence of float
            ``CameraInfo.d``.
        width, height : int
        distortion_model : {"plumb_bob", "rational_polynomial"}
            An all-zero ``d`` is accepted with any model name.
        """
        k = np.asarray(k, float).reshape(-1)
        if k.shape != (9,):
            raise InvalidParamsError(f"expected the 9 numbers of CameraInfo.k, got {k.size}", field="k")
        d = tuple(float(v) for v in np.asarray(d, float).reshape(-1))
        if distortion_model not in DISTORTION_MODELS and any(d):
            raise InvalidParamsError(
                f"unsupported distortion model {distortion_model!r} (expected one of: {', '.join(DISTORTION_MODELS)})",
                field="distortion_model",
            )
        for name, value in (("fx", k[0]), ("fy", k[4])):
            if not (math.isfinite(value) and value > 0):
                raise InvalidParamsError(
                    f"the focal length must be positive (px), got {value:g} (an uncalibrated "
                    "camera publishes K = 0: calibrate it)",
                    field=name,
                )
        if not np.all(np.isfinite(k)):
            raise InvalidParamsError("CameraInfo.k contains NaN or infinity", field="k")
        if abs(k[1]) > 1e-9 * max(abs(k[0]), 1.0) or abs(k[3]) > 0 or np.any(k[6:] != (0.0, 0.0, 1.0)):
            raise InvalidParamsError("expected [fx, 0, cx, 0, fy, cy, 0, 0, 1] (no skew)", field="k")
        if distortion_model == "rational_polynomial" and len(d) not in (0, 8):
            raise InvalidParamsError(f"rational_polynomial needs 8 coefficients, got {len(d)}", field="distortion")
        return cls(fx=k[0], fy=k[4], cx=k[2], cy=k[5], width=width, height=height, distortion=d if any(d) else ())

    @classmethod
    def from_fov(cls, width: int, height: int, hfov: float) -> Intrinsics:
        """An ideal camera: square pixels, centred principal point, no distortion.

        Parameters
        ----------
        width, height : int
            Image size (px).
        hfov : float
            Horizontal field of view (rad, in (0, π)), edge to edge of the image.
        """
        hfov = finite(hfov, "hfov")
        if not 0 < hfov < math.pi:
            raise InvalidParamsError(
                f"a pinhole camera's field of view lies in (0°, 180°), got {math.degrees(hfov):g}°", field="hfov"
            )
        f = 0.5 * width / math.tan(0.5 * hfov)
        return cls(fx=f, fy=f, cx=0.5 * (width - 1), cy=0.5 * (height - 1), width=width, height=height)

    @property
    def hfov(self) -> float:
        """Horizontal field of view (rad) of the undistorted pinhole, edge to edge."""
        return math.atan((self.cx + 0.5) / self.fx) + math.atan((self.width - 0.5 - self.cx) / self.fx)

    def _coefficients(self) -> tuple[float, ...]:
        d = self.distortion + (0.0,) * (8 - len(self.distortion))
        return d  # k1, k2, t1, t2, k3, k4, k5, k6

    def distort(self, xy: Any) -> np.ndarray:
        """Normalised image coordinates ``(x/z, y/z)`` after distortion; shape (n, 2) in, (n, 2) out."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        if not self.distortion:
            return xy.copy()
        k1, k2, t1, t2, k3, k4, k5, k6 = self._coefficients()
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * t1 * x * y + t2 * (r2 + 2 * x * x)
        yd = y * radial + t1 * (r2 + 2 * y * y) + 2 * t2 * x * y
        return np.column_stack([xd, yd])

    def undistort(self, pixels: Any) -> np.ndarray:
        """Normalised undistorted coordinates ``(x/z, y/z)`` of pixels; shape (n, 2) in and out.

        The inverse of :meth:`distort` by fixed-point iteration (as OpenCV's ``undistortPoints``),
        run until it moves less than 1e-15 or 100 times.
        """
        uv = np.asarray(pixels, float).reshape(-1, 2)
        xd = np.column_stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy])
        if not self.distortion:
            return xd
        k1, k2, t1, t2, k3, k4, k5, k6 = self._coefficients()
        xy = xd.copy()
        for _ in range(100):
            x, y = xy[:, 0], xy[:, 1]
            r2 = x * x + y * y
            radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
            dx = 2 * t1 * x * y + t2 * (r2 + 2 * x * x)
            dy = t1 * (r2 + 2 * y * y) + 2 * t2 * x * y
            new = np.column_stack([(xd[:, 0] - dx) / radial, (xd[:, 1] - dy) / radial])
            done = np.max(np.abs(new - xy), initial=0.0) < 1e-15
            xy = new
            if done:
                break
        return xy

    def rays(self, pixels: Any) -> np.ndarray:
        """Unit rays in the optical frame through pixels (undistorted); shape (n, 2) in, (n, 3) out."""
        xy = self.undistort(pixels)
        ray = np.column_stack([xy, np.ones(len(xy))])
        return ray / np.linalg.norm(ray, axis=1, keepdims=True)

    def project(self, points: Any) -> np.ndarray:
        """Pixels of points given in the optical frame (``z > 0``); shape (n, 3) in, (n, 2) out."""
        p = np.asarray(points, float).reshape(-1, 3)
        xy = self.distort(p[:, :2] / p[:, 2:3])
        return np.column_stack([self.fx * xy[:, 0] + self.cx, self.fy * xy[:, 1] + self.cy])


# --------------------------------------------------------------------------- mount


#: ``robot_R_camera`` of a camera looking along the robot's ``x`` axis: optical ``x`` (right) is the
#: robot's ``−y``, optical ``y`` (down) the robot's ``−z``, optical ``z`` (forward) the robot's ``x``.
_FORWARD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def rotation_z(angle: float) -> np.ndarray:
    """The rotation by ``angle`` (rad) about ``z``, shape (3, 3)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True, eq=False)
class Mount:
    """Where the camera sits on the robot (the ``base_link → camera_color_optical_frame`` transform).

    Attributes
    ----------
    rotation : ndarray, shape (3, 3)
        ``robot_R_camera``: columns are the optical axes in robot coordinates (a rotation).
    translation : ndarray, shape (3,)
        The camera centre in the robot frame (metres, map units).
    """

    rotation: np.ndarray
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        r = np.array(self.rotation, float)
        t = np.array(self.translation, float).reshape(-1)
        if r.shape != (3, 3) or not np.all(np.isfinite(r)):
            raise InvalidParamsError("expected a finite 3 × 3 matrix", field="rotation")
        if not np.allclose(r.T @ r, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise InvalidParamsError(
                "robot_R_camera must be a rotation (orthonormal, determinant +1)", field="rotation"
            )
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise InvalidParamsError("expected 3 finite numbers (m)", field="translation")
        r.flags.writeable = t.flags.writeable = False
        object.__setattr__(self, "rotation", r)
        object.__setattr__(self, "translation", t)

    @classmethod
    def forward(cls, height: float = 0.0, yaw: float = 0.0) -> Mount:
        """A level camera at ``height`` above the robot's origin, looking along its ``x`` axis turned by
        ``yaw`` (rad, counter-clockwise)."""
        return cls(rotation_z(finite(yaw, "yaw")) @ _FORWARD, np.array([0.0, 0.0, finite(height, "height")]))
