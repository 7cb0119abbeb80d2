"""The simulated camera: which landmarks a robot sees from where, and the bearings it measures.

A camera is anything with :meth:`Camera.measure`: ``bearnav simulate`` calls it once per step for
the robots still running. :class:`IdealCamera` is the model of ALGORITHMS §6.1 (exact directions
with Gaussian angle noise, a field of view around the camera heading, an optional range, occlusion
by the raw obstacles); :class:`bearnav_cli.world.render.RenderedCamera` draws images and runs a
real AprilTag detector on them (``--camera render``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

import numpy as np
import shapely

from bearnav_cli.geometry import FreeSpace
from bearnav_cli.runtime import bearing

__all__ = ["Camera", "IdealCamera"]


class Camera(Protocol):
    """What the simulator asks a camera (one method, for every robot still running)."""

    def measure(self, runs: np.ndarray, x: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The bearings the robots ``runs`` measure this step.

        Parameters
        ----------
        runs : ndarray of int64, shape (R,)
            Indices of the robots among all runs (a camera may keep state per run).
        x : ndarray, shape (R, 2)
            True positions (map units).
        heading : ndarray, shape (R,)
            Camera headings (rad, counter-clockwise from the map's x axis).

        Returns
        -------
        bearings : ndarray, shape (R, L, 2)
            World-frame unit bearings of the landmarks (rows of unseen landmarks are ignored).
        seen : ndarray of bool, shape (R, L)
            Which landmarks the camera sees.
        """
        ...


class IdealCamera:
    """Bearings of ALGORITHMS §6.1: exact directions turned by ``N(0, σ²)`` angle noise.

    Parameters
    ----------
    space : FreeSpace
        The world's free space (its raw obstacles hide landmarks when ``occlusion``).
    landmarks : ndarray, shape (L, 2)
        Where the landmarks are in the world (map units).
    fov : float
        Field of view (rad, in (0, 2π]) centred on the camera heading.
    noise : float
        Standard deviation of the angle noise (rad, >= 0).
    max_range : float
        Largest distance at which a landmark is seen (map units; ``inf`` for unlimited).
    occlusion : bool
        Landmarks out of line of sight are not seen.
    tol : float
        Slack of the field-of-view test (map units).
    rng : numpy.random.Generator
        Source of the noise (one angle per robot and landmark each step, seen or not).
    bound : float, optional
        ``η`` (rad): bounded errors instead of ``noise`` — each uniform in ``[−η, η]`` (ALGORITHMS §12.8).
    toward : callable, optional
        With ``bound``, the worst case: ``toward(x)`` (R, 2) is the unit direction from each robot
        toward its nearest obstacle, and every error is ``±η``, the sign that moves the bearing's
        line (and so the estimate) away from it.
    """

    def __init__(
        self,
        space: FreeSpace,
        landmarks: np.ndarray,
        *,
        fov: float,
        noise: float,
        max_range: float,
        occlusion: bool,
        tol: float,
        rng: np.random.Generator,
        bound: float | None = None,
        toward: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        self.landmarks = np.asarray(landmarks, float).reshape(-1, 2)
        self.fov, self.noise, self.max_range, self.tol, self.rng = fov, noise, max_range, tol, rng
        self.bound, self.toward = bound, toward
        # one prepared region per landmark: a point query instead of a segment test per sight line
        self.sight = space.visibility_regions(self.landmarks) if occlusion else None

    def measure(self, runs: np.ndarray, x: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """See :meth:`Camera.measure`."""
        seen = bearing.in_field_of_view(x, heading, self.landmarks, self.fov, tol=self.tol)
        if math.isfinite(self.max_range):
            seen &= bearing.in_range(x, self.landmarks, self.max_range)
        if self.sight is not None and seen.any():
            for k in np.flatnonzero(seen.any(axis=0)):
                rows = np.flatnonzero(seen[:, k])
                seen[rows, k] = shapely.intersects_xy(self.sight[k], x[rows, 0], x[rows, 1])
        if self.bound is None:
            return bearing.noisy_bearings(x, self.landmarks, self.noise, self.rng), seen
        unit = bearing.directions(x, self.landmarks)[0]
        if self.toward is None:  # every error uniform within the bound (ALGORITHMS §12.8)
            eps = self.rng.uniform(-self.bound, self.bound, size=unit.shape[:2])
        else:
            # the worst case: every error at the bound, turned so that the bearing's line moves away
            # from the nearest obstacle, so the estimate lies on the far side and the truth nearer to it
            # than the robot believes (turning by +η moves the apparent point along (sin φ, −cos φ))
            push = self.toward(x)  # (R, 2) unit, toward the nearest obstacle
            shift = unit[..., 1] * push[:, None, 0] - unit[..., 0] * push[:, None, 1]
            eps = np.where(shift > 0.0, -self.bound, self.bound)
        return bearing.rotated(unit, eps), seen
