"""Camera-in-the-loop simulation: grey images of the map drawn from the robot's pose, with real detection.

:class:`RenderedCamera` is a :class:`~bearnav_cli.world.camera.Camera` for ``bearnav simulate
--camera render``: for each robot and step it draws one frame (a pinhole camera, the raw obstacles
and the bounds as vertical walls that occlude, a uniform floor and background, each landmark as its
tag36h11 pattern on its wall facing the map's ``landmark_facing``), runs OpenCV's AprilTag detector
on it (:mod:`bearnav_cli.world.detect`) and turns the detections into world-frame bearings through
:func:`bearnav_cli.runtime.camera.observe`, with the true heading as the compass. It checks the
perception path, not the statistics: a frame costs milliseconds (``docs/camera.md`` has numbers).

Drawing is vectorised numpy and exact for vertical walls: one ray per image column meets its
nearest wall (a depth per column), rows above and below the wall show background and floor; a
tag is painted by inverse mapping of the sub-pixels of its quad (``supersample``² per pixel,
averaged: anti-aliased edges for the sub-pixel corner refinement), where its depth is not behind
the column's wall.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace, box_polygon
from bearnav_cli.runtime import bearing
from bearnav_cli.runtime.camera import TagMap, observe, project_world, tag_corners_world, tag_number
from bearnav_cli.runtime.camera_model import Intrinsics, Mount
from bearnav_cli.runtime.plan_arrays import ring_edges
from bearnav_cli.world import detect

__all__ = ["D455_HFOV", "D455_VFOV", "RenderSettings", "RenderedCamera", "MAX_FOV"]

#: The Intel RealSense D455's colour camera: 90° × 65° (the paper's robot).
D455_HFOV, D455_VFOV = math.radians(90.0), math.radians(65.0)
#: Largest horizontal field of view of the rendered pinhole camera (rad).
MAX_FOV = math.radians(175.0)
#: Cells across a drawn tag: tag36h11's 8 (6 data + the black border) and a white quiet zone of one.
_CELLS = 10


def _default_height(width: int = 640) -> int:
    return round(width * math.tan(D455_VFOV / 2) / math.tan(D455_HFOV / 2))


@dataclass(frozen=True)
class RenderSettings:
    """How frames are drawn.

    Attributes
    ----------
    width, height : int
        Image size (px); the default height gives the D455's 65° vertically at 90° horizontally.
    hfov : float
        Horizontal field of view (rad, below 175°); square pixels, no distortion.
    tag_size : float
        Edge of a tag's black square, border included (map units: metres). A white quiet zone one
        cell wide (``tag_size / 8``) is drawn around it.
    tag_height, camera_height : float
        Heights of the tag centres and of the camera above the floor (equal: tags on the horizon).
    wall_height : float
        Height of every wall (the raw obstacles and the bounds).
    noise : float
        Standard deviation of the Gaussian pixel noise (grey levels, >= 0).
    supersample : int
        Sub-pixels per pixel and axis where tags are drawn (1: aliased edges).
    floor, background, wall, black, white : float
        Grey levels of the floor, of what is above the walls, of the walls (varied by ±25 with each
        wall's direction, so that adjacent walls differ), and of a tag's black and white cells.
    heading : {"compass", "tags"}
        Where :func:`~bearnav_cli.runtime.camera.observe` gets the robot's heading: the true one (a
        perfect compass), or the detected tags' poses (``cv2.solvePnP``, the paper's formula). The
        poses' heading error is reported either way.
    """

    width: int = 640
    height: int = _default_height()
    hfov: float = D455_HFOV
    tag_size: float = 0.16
    tag_height: float = 0.3
    camera_height: float = 0.3
    wall_height: float = 1.0
    noise: float = 2.0
    supersample: int = 3
    floor: float = 95.0
    background: float = 200.0
    wall: float = 150.0
    black: float = 30.0
    white: float = 225.0
    heading: str = "compass"

    def __post_init__(self) -> None:
        if self.heading not in ("compass", "tags"):
            raise InvalidParamsError(f"expected 'compass' or 'tags', got {self.heading!r}", field="heading")
        for name in ("width", "height", "supersample"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < (1 if name == "supersample" else 16):
                raise InvalidParamsError(
                    f"must be an integer of at least {1 if name == 'supersample' else 16}, got {value!r}", field=name
                )
        if not (0 < self.hfov < MAX_FOV):
            raise InvalidParamsError(
                f"a pinhole camera's field of view lies below 175°, got {math.degrees(self.hfov):g}°", field="hfov"
            )
        for name in ("tag_size", "wall_height"):
            if not (getattr(self, name) > 0 and math.isfinite(getattr(self, name))):
                raise InvalidParamsError(f"must be positive, got {getattr(self, name)}", field=name)
        for name in ("tag_height", "camera_height", "noise"):
            if not (getattr(self, name) >= 0 and math.isfinite(getattr(self, name))):
                raise InvalidParamsError(f"must be zero or positive, got {getattr(self, name)}", field=name)

    @property
    def intrinsics(self) -> Intrinsics:
        """The ideal pinhole of these settings."""
        return Intrinsics.from_fov(self.width, self.height, self.hfov)


class RenderedCamera:
    """A camera that draws each frame and detects the tags in it (the :class:`Camera` protocol).

    Parameters
    ----------
    map_ : Map
        Obstacles, bounds, landmarks and their facing.
    rng : numpy.random.Generator
        Source of the pixel noise.
    settings : RenderSettings, optional
        How frames are drawn (image size, field of view, tag size, heights, noise, grey levels, the
        heading's source); default :class:`RenderSettings`'s defaults.
    space : FreeSpace, optional
        The free space of ``map_`` when the caller has it (its raw obstacles hide tags); built otherwise.
    """

    def __init__(
        self,
        map_: Any,
        *,
        rng: np.random.Generator,
        settings: RenderSettings | None = None,
        space: FreeSpace | None = None,
    ) -> None:
        self.settings = s = settings or RenderSettings()
        self.map = map_
        self.rng = rng
        self.intrinsics = s.intrinsics
        self.mount = Mount.forward(height=s.camera_height)
        self.tags = TagMap(
            np.array([tag_number(i) for i in map_.landmark_ids], np.int64),
            map_.landmarks,
            map_.landmark_facing,
            map_.landmark_ids,
        )
        self.drawable = self.tags.numbers >= 0
        unknown = [i for i, n in zip(map_.landmark_ids, self.tags.numbers, strict=True) if n >= detect.TAG36H11_IDS]
        if unknown:
            raise InvalidParamsError(
                f"landmark {unknown[0]!r} has no tag36h11 pattern (ids 0 to {detect.TAG36H11_IDS - 1})",
                field="landmarks",
            )
        levels = np.array([s.black, s.white])
        textures = np.full((len(self.tags.numbers), _CELLS, _CELLS), s.white)
        for k in np.flatnonzero(self.drawable):
            textures[k, 1:-1, 1:-1] = levels[detect.tag36h11_cells(int(self.tags.numbers[k]))]
        self.textures = textures
        # the walls: the bounds and every raw obstacle ring
        edges = ring_edges([(box_polygon(map_.bounds),), *((p.exterior, *p.holes) for p in map_.raw_obstacles)])
        self.seg_a, self.seg_e = edges[:, 0], edges[:, 1] - edges[:, 0]
        keep = np.hypot(*self.seg_e.T) > 0
        self.seg_a, self.seg_e = self.seg_a[keep], self.seg_e[keep]
        self.seg_shade = s.wall + 25.0 * np.cos(2.0 * np.arctan2(self.seg_e[:, 1], self.seg_e[:, 0]) + 0.6)
        space = FreeSpace.from_map(map_) if space is None else space
        self.sight = space.visibility_regions(np.asarray(map_.landmarks, float))
        self.tol = map_.tol
        self._detector = detect.detector()
        u = np.arange(s.width, dtype=float)
        v = np.arange(s.height, dtype=float)
        self._a = (u - self.intrinsics.cx) / self.intrinsics.fx  # column ray: forward + a·right
        self._b = (v - self.intrinsics.cy) / self.intrinsics.fy  # row: height drops by b per unit forward
        self._noise = (
            rng.standard_normal(2 * s.width * s.height + s.width).astype(np.float32) * s.noise if s.noise > 0 else None
        )
        self.stats: dict[str, Any] = {
            key: 0
            for key in (
                "frames",
                "detections",
                "matched",
                "unknown",
                "from_behind",
                "outside_image",
                "duplicates",
                "expected",
                "missed",
                "missed_small",
            )
        }
        self.errors: list[float] = []
        self.heading_errors: list[float] = []

    @classmethod
    def for_plan(
        cls,
        plan: Any,
        *,
        fov: float,
        rng: np.random.Generator,
        settings: RenderSettings | None = None,
        space: FreeSpace | None = None,
    ) -> RenderedCamera:
        """The rendered camera for ``bearnav simulate --camera render``: ``fov`` (rad) is ``--fov``."""
        if not (isinstance(fov, (int, float)) and math.isfinite(fov) and 0 < fov < MAX_FOV):
            given = f"{math.degrees(fov):g}" if isinstance(fov, (int, float)) else repr(fov)
            raise InvalidParamsError(
                f"--camera render is a pinhole camera: give --fov below 175 (the D455's colour "
                f"camera: 90), got {given}",
                field="fov",
            )
        settings = dataclasses.replace(settings or RenderSettings(), hfov=float(fov))
        return cls(plan.map, rng=rng, settings=settings, space=space)

    # ------------------------------------------------------------------ drawing

    def _cast(self, p: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest wall along rays ``p + t·d`` (d: (n, 2), forward component 1): ``t`` (n,), segment (n,)."""
        ap = self.seg_a - p  # (S, 2)
        den = d[:, None, 0] * self.seg_e[None, :, 1] - d[:, None, 1] * self.seg_e[None, :, 0]  # d × e, (n, S)
        safe = np.where(np.abs(den) > 1e-15, den, np.inf)
        t = (ap[:, 0] * self.seg_e[:, 1] - ap[:, 1] * self.seg_e[:, 0])[None, :] / safe
        w = (ap[None, :, 0] * d[:, None, 1] - ap[None, :, 1] * d[:, None, 0]) / safe
        t = np.where((t > 1e-9) & (w >= -1e-12) & (w <= 1 + 1e-12), t, np.inf)
        k = np.argmin(t, axis=1)
        return np.minimum(t[np.arange(len(d)), k], 1e6), k

    def _directions(self, heading: float, a: np.ndarray) -> np.ndarray:
        f = np.array([math.cos(heading), math.sin(heading)])
        r = np.array([math.sin(heading), -math.cos(heading)])
        return f[None, :] + a[:, None] * r[None, :]

    def render(self, x: Any, heading: float) -> np.ndarray:
        """One grey frame (uint8, shape (height, width)) from the robot at ``x`` with yaw ``heading`` (rad)."""
        s = self.settings
        p = np.asarray(x, float).reshape(2)
        t_wall, seg = self._cast(p, self._directions(heading, self._a))
        z = s.camera_height - self._b[:, None] * t_wall[None, :]
        img = np.where(
            z < 0,
            np.float32(s.floor),
            np.where(z > s.wall_height, np.float32(s.background), self.seg_shade[seg].astype(np.float32)),
        )
        for k in range(len(self.tags.numbers)):
            if self.drawable[k]:
                self._paint_tag(img, k, p, heading)
        if self._noise is not None:
            start = int(self.rng.integers(0, len(self._noise) - img.size))
            img += self._noise[start : start + img.size].reshape(img.shape)
        return np.clip(img + 0.5, 0, 255).astype(np.uint8)

    def _paint_tag(self, img: np.ndarray, k: int, p: np.ndarray, heading: float) -> None:
        s, intr = self.settings, self.intrinsics
        lm = self.tags.positions[k]
        facing = self.tags.facing[k]
        if math.isfinite(facing):
            n = np.array([math.cos(facing), math.sin(facing)])
        else:  # free-standing: seen from every side, drawn turned toward the camera
            n = p - lm
            n = n / max(math.hypot(*n), 1e-300)
        if (lm - p) @ n >= 0:
            return  # its back: a printed tag shows nothing there
        half = 0.5 * s.tag_size * _CELLS / 8
        tangent = np.array([-n[1], n[0]])  # to the right as seen from the front
        ends = np.array([lm - half * tangent, lm + half * tangent])
        f = np.array([math.cos(heading), math.sin(heading)])
        r = np.array([math.sin(heading), -math.cos(heading)])
        fwd = (ends - p) @ f
        if (fwd <= 0).all():
            return
        if (fwd > 1e-9).all():
            u = intr.cx + intr.fx * ((ends - p) @ r) / fwd
            u0, u1 = max(int(math.floor(u.min())), 0), min(int(math.ceil(u.max())), s.width - 1)
        else:
            u0, u1 = 0, s.width - 1
        if u1 < u0:
            return
        ss = s.supersample
        us = u0 - 0.5 + (np.arange((u1 - u0 + 1) * ss) + 0.5) / ss
        d = self._directions(heading, (us - intr.cx) / intr.fx)
        e = ends[1] - ends[0]
        ap = ends[0] - p
        den = d[:, 0] * e[1] - d[:, 1] * e[0]
        safe = np.where(np.abs(den) > 1e-15, den, np.inf)
        t = (ap[0] * e[1] - ap[1] * e[0]) / safe
        w = (ap[0] * d[:, 1] - ap[1] * d[:, 0]) / safe
        t_wall, _ = self._cast(p, d)
        ok = (t > 1e-9) & (w >= 0) & (w < 1) & (t <= t_wall * (1 + 1e-7) + 1e-7)
        if not ok.any():
            return
        top, bottom = s.tag_height + half, s.tag_height - half
        t_ok = t[ok]
        span = np.array([t_ok.min(), t_ok.max()])
        rows = intr.cy + intr.fy * (s.camera_height - np.array([top, bottom]))[:, None] / span
        v0, v1 = max(int(math.floor(rows.min())), 0), min(int(math.ceil(rows.max())), s.height - 1)
        if v1 < v0:
            return
        vs = v0 - 0.5 + (np.arange((v1 - v0 + 1) * ss) + 0.5) / ss
        height = s.camera_height - ((vs - intr.cy) / intr.fy)[:, None] * t[None, :]
        y = (top - height) / (2 * half)
        inside = ok[None, :] & (y >= 0) & (y < 1)
        ix = np.clip((w * _CELLS).astype(np.int64), 0, _CELLS - 1)
        iy = np.clip((y * _CELLS).astype(np.int64), 0, _CELLS - 1)
        texture = self.textures[k][iy, ix[None, :]]
        block = img[v0 : v1 + 1, u0 : u1 + 1]
        under = np.repeat(np.repeat(block, ss, axis=0), ss, axis=1)
        sample = np.where(inside, texture, under)
        img[v0 : v1 + 1, u0 : u1 + 1] = sample.reshape(v1 - v0 + 1, ss, u1 - u0 + 1, ss).mean(axis=(1, 3))

    # ------------------------------------------------------------------ measuring

    def frame(self, x: Any, heading: float) -> tuple[np.ndarray, list]:
        """One frame and the detector's detections in it."""
        img = self.render(x, heading)
        return img, detect.detect(img, self._detector)

    def expected(self, x: Any, heading: float) -> tuple[np.ndarray, np.ndarray]:
        """Which tags the frame should show whole (in view, in line of sight, front side) and their edge (px)."""
        p = np.asarray(x, float).reshape(2)
        s, intr = self.settings, self.intrinsics
        out = np.zeros(len(self.tags.numbers), bool)
        edge = np.zeros(len(self.tags.numbers))
        for k in np.flatnonzero(self.drawable):
            lm, facing = self.tags.positions[k], self.tags.facing[k]
            if math.isfinite(facing) and (lm - p) @ np.array([math.cos(facing), math.sin(facing)]) >= 0:
                continue
            if not math.isfinite(facing):
                away = p - lm
                facing = math.atan2(away[1], away[0])
            corners = tag_corners_world(lm, facing, s.tag_size, s.tag_height)
            pix, depth = project_world(intr, self.mount, p, heading, corners)
            if (
                (depth <= 0).any()
                or (pix < -0.5).any()
                or (pix[:, 0] > s.width - 0.5).any()
                or (pix[:, 1] > s.height - 0.5).any()
            ):
                continue
            if not shapely.intersects_xy(self.sight[k], p[0], p[1]):
                continue
            out[k] = True
            edge[k] = float(np.min(np.hypot(*(pix - np.roll(pix, 1, axis=0)).T)))
        return out, edge

    def measure(self, runs: np.ndarray, x: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """See :meth:`bearnav_cli.world.camera.Camera.measure`: one frame per robot, detected, observed."""
        x = np.asarray(x, float).reshape(-1, 2)
        heading = np.asarray(heading, float).reshape(-1)
        n_lm = len(self.tags.numbers)
        bearings, seen = np.zeros((len(x), n_lm, 2)), np.zeros((len(x), n_lm), bool)
        compass = self.settings.heading == "compass"
        for r in range(len(x)):
            _, found = self.frame(x[r], heading[r])
            found = [detect.estimate_pose(d, self.intrinsics, self.settings.tag_size) for d in found]
            try:
                obs = observe(
                    found, self.intrinsics, self.mount, self.tags, heading=float(heading[r]) if compass else None
                )
            except InvalidParamsError:  # only free-standing tags in sight: no heading without a compass
                obs = observe([], self.intrinsics, self.mount, self.tags, heading=float(heading[r]))
            bearings[r], seen[r] = obs.bearings, obs.visible
            self._count(x[r], heading[r], found, obs)
        return bearings, seen

    def _count(self, p: np.ndarray, heading: float, found: list, obs: Any) -> None:
        st = self.stats
        st["frames"] += 1
        st["detections"] += len(found)
        st["matched"] += int(obs.visible.sum())
        for key in ("unknown", "from_behind", "outside_image", "duplicates"):
            st[key] += int(getattr(obs, key))
        expected, edge = self.expected(p, heading)
        missed = expected & ~obs.visible
        st["expected"] += int(expected.sum())
        st["missed"] += int(missed.sum())
        st["missed_small"] += int((missed & (edge < 12.0)).sum())
        if obs.pose_heading is not None:
            self.heading_errors.append(abs(math.degrees(math.remainder(obs.pose_heading - heading, 2 * math.pi))))
        if obs.visible.any():
            true, _ = bearing.directions(p[None], self.tags.positions)
            b = obs.bearings[obs.visible]
            t = true[0][obs.visible]
            err = np.degrees(np.abs(np.arctan2(t[:, 0] * b[:, 1] - t[:, 1] * b[:, 0], (t * b).sum(axis=1))))
            self.errors.extend(err.tolist())

    def report(self) -> dict:
        """Counts over every frame so far and the bearing error of the matched detections (degrees).

        ``missed``: tags whose whole quad was in view, in line of sight and front side on but not
        detected (``missed_small``: of those, the ones under 12 px across, too small to decode).
        ``heading_error_deg``: the tag poses' heading (:attr:`Observation.pose_heading`) against
        the true one, over the frames with one. Statistics are None when nothing was matched.
        """
        out: dict[str, Any] = dict(self.stats)
        for key, values in (("bearing_error_deg", self.errors), ("heading_error_deg", self.heading_errors)):
            err = np.asarray(values)
            # None (JSON null) when nothing matched: sim.json is strict JSON, without NaN
            out[key] = {
                "median": float(np.median(err)) if err.size else None,
                "p95": float(np.percentile(err, 95)) if err.size else None,
                "max": float(err.max()) if err.size else None,
            }
        return out
