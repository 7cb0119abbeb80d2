"""The controller a robot runs: one camera frame's bearings in, a velocity command out (DESIGN §6).

Numpy only. :class:`Controller` holds one robot's :class:`~bearnav_cli.runtime.settings.ControlState`
and calls :func:`~bearnav_cli.runtime.step.control`, the same step ``bearnav simulate`` advances its
robots with, so what is simulated is what runs on the robot.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bearnav_cli.runtime.plan_arrays import PlanArrays
from bearnav_cli.runtime.plan_file import load_plan
from bearnav_cli.runtime.robot import lookahead_point, robot_parameters
from bearnav_cli.runtime.settings import SPEED, ControlOutput, ControlSettings, ControlState
from bearnav_cli.runtime.step import control

__all__ = ["Controller"]


class Controller:
    """The controller a robot runs: load ``plan.npz``, feed bearings at camera rate, get a command.

    Numpy only. One robot; the step is :func:`control`, the same function ``bearnav
    simulate`` advances its robots with.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's run-time arrays (:meth:`PlanArrays.from_npz`): cells, gains, barrier rows
        and the tree the step follows.
    settings : ControlSettings
        Constants of the step (period ``dt`` in s, switching radius ``eps_sw`` in map units,
        dynamics, reconstruction, noise), as :meth:`ControlSettings.for_plan` builds them.
    heading : float
        Initial heading (rad) standing in for the last command until the first fix.
    """

    def __init__(self, arrays: PlanArrays, settings: ControlSettings, heading: float = 0.0) -> None:
        self.arrays = arrays
        self.settings = settings
        self.state = ControlState.initial(np.array([heading]))
        self.last: ControlOutput | None = None
        self.heading = float(heading)  # the last heading given (rad): where the look-ahead point is

    @classmethod
    def from_plan(
        cls,
        path: str,
        *,
        speed: float = SPEED,
        dt: float | None = None,
        dynamics: str = "single",
        heading: float = 0.0,
        **options: Any,
    ) -> Controller:
        """Load ``plan.npz``; ``options`` are further :class:`ControlSettings` fields.

        The settings come from :meth:`ControlSettings.for_plan`, the builder ``bearnav simulate``
        uses, with the same defaults: ``dt`` is the camera period (s), by default the
        simulation's, ``min(0.0025·D/v, 0.2)`` with ``v`` = ``speed`` (``alpha`` for the
        unicycle), and ``eps_sw`` defaults to ``2·v·dt``. Pass ``bearing_sigma``, the camera's
        angular noise (radians; default :data:`~bearnav_cli.runtime.defaults.BEARING_SIGMA`, 1°).
        A plan whose map says ``robot: {reverse: false}`` clamps ``v ≥ 0`` whatever
        ``clamp_reverse`` says (the option can only add the clamp). The bounds of the set estimator
        (``estimator="set"``: ``bearing_bound``, ``heading_bound``, ``slip``, ``slip_floor``) default to
        the map's robot section (:func:`error_model`). On a plan with a look-ahead
        ``λ > 0`` (``arrays.lookahead``) the unicycle drives the point ``λ`` ahead of its axle
        (ALGORITHMS §12.6, docs/runtime.md).

        Raises
        ------
        ArtifactError
            The plan fails a check of :func:`~bearnav_cli.runtime.plan_file.load_plan` (a damaged or
            edited file, a manifest, entry or invariant), naming the file and the field.
        """
        loaded = load_plan(path)  # every check of the CLI's loader numpy can make: ArtifactError, nothing raw
        arrays = PlanArrays.from_loaded(loaded)
        robot = _robot(loaded.map.document)
        if not robot["reverse"]:
            options["clamp_reverse"] = True
        # the set estimator's bounds are the robot's (the map's robot section) unless given
        options = {**error_model(robot), **options}
        diagonal = math.hypot(*(arrays.bounds[2:] - arrays.bounds[:2]))
        settings = ControlSettings.for_plan(diagonal, arrays.tol, dynamics=dynamics, speed=speed, dt=dt, **options)
        return cls(arrays, settings, heading)

    def command(self, bearings: np.ndarray, visible: np.ndarray, heading: float | None = None) -> np.ndarray:
        """The command for one camera frame.

        Parameters
        ----------
        bearings : array_like, shape (L, 2)
            World-frame unit bearing of each landmark (rows of invisible ones are ignored).
        visible : array_like of bool, shape (L,)
        heading : float, optional
            The robot's yaw (rad) from the compass: required by the unicycle; for the single
            integrator, the camera's heading (default 0).

        Returns
        -------
        ndarray
            Single integrator: the velocity ``(vx, vy)`` (map units / s); while looking around
            it is zero and ``self.last.turn`` is the rate to turn the camera. Unicycle:
            ``(v, ω)``. Zero once the robot is lost (``self.lost``).

        Raises
        ------
        ValueError
            A unicycle without ``heading``.
        """
        if heading is None and self.settings.dynamics == "unicycle":
            raise ValueError("the unicycle needs its heading (rad) on every frame")
        out = control(
            self.arrays,
            self.settings,
            self.state,
            np.asarray(bearings, float)[None],
            np.asarray(visible, bool)[None],
            np.array([0.0 if heading is None else heading]),
        )
        self.state, self.last = out.state, out
        self.heading = 0.0 if heading is None else float(heading)
        if out.lost[0]:
            return np.zeros(2)
        if self.settings.dynamics == "unicycle":
            return np.array([out.forward[0], out.turn[0]])
        return out.velocity[0].copy()

    @property
    def lost(self) -> bool:
        """No position estimate after looking around for a whole revolution (``2π/β`` s past the
        odometry's ``hold_time``); a later fix clears it."""
        return bool(self.last is not None and self.last.lost[0])

    @property
    def arrived(self) -> bool:
        """The current estimate lies within the plan's goal tolerance of the goal: stop."""
        # the state's estimate, which odometry keeps current; the step's output is zero while the
        # robot looks around, and (0, 0) may well lie within the tolerance of a goal near the origin
        if not self.state.known[0]:
            return False
        return bool(np.hypot(*(self.position - self.arrays.goal)) <= self.arrays.goal_tolerance)

    @property
    def position(self) -> np.ndarray:
        """The estimate of the point the plan is about, shape (2,) (map units; NaN before the first fix):
        the axle's ``x̂``, or for a unicycle on a look-ahead plan ``p̂ = x̂ + λ(cos θ, sin θ)`` at the
        last heading given (ALGORITHMS §12.6)."""
        if not self.state.known[0]:
            return np.full(2, np.nan)
        lam = self.arrays.lookahead if self.settings.dynamics == "unicycle" else 0.0
        return lookahead_point(self.state.x_hat, np.array([self.heading]), lam)[0]

    @property
    def cell(self) -> int:
        """The active cell (``-1`` before the first fix)."""
        return int(self.state.cell[0])


def _robot(document: dict) -> dict:
    """The robot parameters of the map embedded in ``plan.npz`` (``runtime.robot.robot_parameters``; defaults
    where the map says nothing)."""
    section = document.get("robot")
    return robot_parameters(section if isinstance(section, dict) else None)


def error_model(robot: dict) -> dict:
    """The set estimator's bounds (ALGORITHMS §12.1) from robot parameters, as :class:`ControlSettings` fields:
    ``bearing_bound = η_cam + ψ`` and ``heading_bound = ψ`` (rad), ``slip`` κ, and ``slip_floor`` ν where given."""
    compass = robot.get("compass_error_deg") or 0.0
    fields = {
        "bearing_bound": math.radians(robot["bearing_error_deg"] + compass),
        "heading_bound": math.radians(compass),
        "slip": robot["slip"],
    }
    if robot.get("slip_floor") is not None:
        fields["slip_floor"] = robot["slip_floor"]
    return fields
