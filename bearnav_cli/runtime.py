"""The controller a robot runs: bearings of one camera frame in, a velocity command out (DESIGN §6, ALGORITHMS §7).

This module needs numpy only (with :mod:`bearnav_cli.bearing`, :mod:`bearnav_cli.cell_policy`
and :mod:`bearnav_cli.plan_arrays`, which need nothing else), so it can be copied onto a
robot next to ``plan.npz``. ``bearnav simulate`` advances its robots with :func:`control`,
the same step :class:`Controller` takes, so what is simulated is what runs on the robot.

:func:`control` is one step for ``R`` robots: the ``lsq`` fix from the bearings (§6.2), its
fusion with odometry, the cell policy of :mod:`bearnav_cli.cell_policy`, the gain, speed
normalisation, the hold and look-around behaviour and the unicycle mapping.
The cell policy's functions are re-exported here (``runtime.locate``, ``runtime.switch``, ...).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from bearnav_cli import bearing
from bearnav_cli.cell_policy import (
    affine_field,
    apply_gain,
    approach_target,
    barrier_values,
    contains,
    displacement,
    field,
    funnel_update,
    in_safe_set,
    least_rank_cell,
    locate,
    lyapunov,
    nearest_node,
    segments_clear,
    switch,
    update,
    voronoi_owner,
)
from bearnav_cli.plan_arrays import RUNTIME_KEYS, PlanArrays, ring_edges, tree_costs

__all__ = [  # re-exported: a robot's one import
    "RUNTIME_KEYS", "PlanArrays", "ring_edges", "tree_costs",
    "contains",
    "nearest_node",
    "voronoi_owner",
    "lyapunov",
    "barrier_values",
    "locate",
    "least_rank_cell",
    "funnel_update",
    "switch",
    "in_safe_set",
    "segments_clear",
    "approach_target",
    "update",
    "displacement",
    "apply_gain",
    "field",
    "affine_field",
]  # fmt: skip

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- the control step

DYNAMICS = ("single", "unicycle")
MEASUREMENTS = ("bearing", "displacement")


@dataclass(frozen=True)
class ControlSettings:
    """Constants of the control step shared by :class:`Controller` and ``bearnav simulate`` (ALGORITHMS §7).

    Attributes
    ----------
    speed : float
        ``v_ref`` of the single integrator (map units / s).
    dt : float
        Control period (s): the hold timer advances by it on every step without a fix.
    eps_sw : float
        Switching and arrival radius (map units).
    tol : float
        Membership slack (map units), ``1e-9·D``.
    dynamics : {"single", "unicycle"}
    alpha, beta : float
        Unicycle gains: ``v = α cos e`` (map units / s), ``ω = β sin e`` (rad / s).
    clamp_reverse : bool
        Unicycle: clamp ``v`` at 0 (never reverse).
    turn_first : bool
        Unicycle: ``v = α cos³ e`` (slow down to turn) instead of §7.1's ``α cos e``.
    measurement : {"bearing", "displacement"}
        ``bearing``: reconstruct ``ỹ`` and ``x̂`` from bearings (§6); ``displacement``: the
        true displacements, ``x̂ = x`` (paper B).
    reconstruction : {"lsq", "pair", "rescale"}
    min_spread : float
        ``θ_min`` of §6.2 (radians).
    hold_time : float
        Seconds without a usable reconstruction before the robot stops to look around; it
        is ``lost`` after one more revolution, ``2π/β`` (§7.5).
    odometry : bool
        Between fixes, carry ``x̂`` forward with the commanded motion and keep following the
        fields (for at most ``hold_time``); off: the hold policy of §7.5 as written.
    odometry_drift : float
        Standard deviation of the odometry's position error per unit travelled: the filter's
        process noise (:func:`control`).
    blind_error : float
        Without a fix, the robot keeps following the fields on odometry beyond ``hold_time``
        while its estimate's 3σ stays below this (map units; the barrier margin in
        ``bearnav simulate``); 0: ``hold_time`` only.
    """

    speed: float
    dt: float
    eps_sw: float
    tol: float
    dynamics: str = "single"
    alpha: float = 0.1
    beta: float = 0.5
    clamp_reverse: bool = False
    turn_first: bool = True
    measurement: str = "bearing"
    reconstruction: str = "lsq"
    min_spread: float = bearing.DEFAULT_MIN_SPREAD
    hold_time: float = 2.0
    odometry: bool = True
    odometry_drift: float = 0.05
    blind_error: float = 0.0
    bearing_sigma: float = 0.0
    max_fix_error: float = math.inf


@dataclass(frozen=True)
class ControlState:
    """What a controller remembers between steps, for ``R`` robots.

    Attributes
    ----------
    cell, target : ndarray of int64, shape (R,)
        Active cell (``-1`` before the first fix) and approached node (``-1`` for none).
    last_dir : ndarray, shape (R, 2)
        Unit direction of the last command (the initial heading before the first).
    hold : ndarray, shape (R,)
        Seconds since the last usable reconstruction.
    x_hat : ndarray, shape (R, 2)
        The last position estimate, carried forward by odometry between fixes (map units).
    motion : ndarray, shape (R, 2)
        World-frame velocity of the last command (map units / s): what odometry integrates.
    known : ndarray of bool, shape (R,)
        Whether the robot has had a fix yet.
    var : ndarray, shape (R,)
        Variance of the estimate (map units²), isotropic; ``inf`` before the first fix.
    scanning : ndarray of bool, shape (R,)
        Looking around at the last step.
    spin : ndarray, shape (R,)
        ``±1``: the direction of the current look-around.
    """

    cell: np.ndarray
    target: np.ndarray
    last_dir: np.ndarray
    hold: np.ndarray
    x_hat: np.ndarray
    motion: np.ndarray
    known: np.ndarray
    var: np.ndarray
    scanning: np.ndarray
    spin: np.ndarray

    @classmethod
    def initial(cls, heading: np.ndarray) -> ControlState:
        """Robots that have not had a fix yet, facing ``heading`` (rad, shape (R,))."""
        h = np.asarray(heading, float).reshape(-1)
        r = len(h)
        return cls(np.full(r, -1, np.int64), np.full(r, -1, np.int64), np.column_stack([np.cos(h), np.sin(h)]),
                   np.zeros(r), np.zeros((r, 2)), np.zeros((r, 2)), np.zeros(r, bool), np.full(r, np.inf),
                   np.zeros(r, bool), np.ones(r))  # fmt: skip

    def take(self, idx: np.ndarray) -> ControlState:
        """The state of the robots ``idx``."""
        return ControlState(*(getattr(self, f.name)[idx] for f in dataclasses.fields(self)))

    def put(self, idx: np.ndarray, other: ControlState) -> None:
        """Write ``other`` (the robots ``idx``) back into this state's arrays."""
        for f in dataclasses.fields(self):
            getattr(self, f.name)[idx] = getattr(other, f.name)


@dataclass(frozen=True)
class ControlOutput:
    """One control step for ``R`` robots.

    Attributes
    ----------
    velocity : ndarray, shape (R, 2)
        Single integrator: the commanded velocity (map units / s), ``v_ref·unit(ũ)``.
    forward, turn : ndarray, shape (R,)
        Unicycle: ``v`` (map units / s) and ``ω`` (rad / s). ``turn`` is also the rate at
        which a single integrator that is looking around turns its camera.
    scanning : ndarray of bool, shape (R,)
        Looking around in place: no fix for longer than ``hold_time``.
    state : ControlState
        The state after the step.
    fix : ndarray of bool, shape (R,)
        A usable reconstruction (or displacement measurement) was available.
    lost : ndarray of bool, shape (R,)
        No fix for longer than ``hold_time`` plus one revolution of looking around.
    stalled : ndarray of bool, shape (R,)
        The certified field vanishes at ``x̂`` (``‖a − M x̂‖ < 1e-6·u_max``).
    relocated : ndarray of bool, shape (R,)
        Left the cell through a side face this step (a ``left_cell`` event).
    x_hat : ndarray, shape (R, 2)
        The position estimate used (measured or carried by odometry; zeros before the first fix).
    certified : ndarray of bool, shape (R,)
        The step is covered by the composed certificate (ALGORITHMS §11.4): a funnel plan, a cell's
        field (not a straight approach), and an estimate whose error bound (3σ) is at most ``δ*``.
    """

    velocity: np.ndarray
    forward: np.ndarray
    turn: np.ndarray
    scanning: np.ndarray
    state: ControlState
    fix: np.ndarray
    lost: np.ndarray
    stalled: np.ndarray
    relocated: np.ndarray
    x_hat: np.ndarray
    certified: np.ndarray


#: ``‖a − M x̂‖ < STALL_FIELD · u_max`` is a stall: the field has (almost) an equilibrium there.
STALL_FIELD = 1e-6
#: A unicycle approaching a node drives only when its heading is this close to the segment (rad).
APPROACH_ALIGNMENT = math.radians(10.0)


def control(
    arrays: PlanArrays,
    settings: ControlSettings,
    state: ControlState,
    bearings: np.ndarray,
    visible: np.ndarray,
    heading: np.ndarray,
    x_true: np.ndarray | None = None,
    displacements: np.ndarray | None = None,
) -> ControlOutput:
    """One step of ALGORITHMS §7.2 for every robot: measurement → cell → command.

    The position estimate ``x̂`` comes from ``lsq`` whatever the reconstruction (§7.2); the
    cell policy is :func:`update`; the output ``ỹ`` is rebuilt for the (new) cell's fixed
    landmark and ``ũ = gain[c] @ ỹ``, or ``x_n − x̂`` while approaching node ``n``.

    Without a usable reconstruction (§7.5), for up to ``hold_time`` seconds the robot carries
    its last estimate forward with its own commanded motion (odometry, ``settings.odometry``)
    and keeps following the fields; without any estimate (before its first fix, or once
    odometry has expired) it stops and looks around, turning in place at ``β``, for one
    revolution, and is then lost. With ``odometry`` off it holds as §7.5 says (the single
    integrator keeps ``last_dir``, the unicycle turns toward it) for ``hold_time``, then looks
    around the same way.

    Parameters
    ----------
    arrays : PlanArrays
    settings : ControlSettings
    state : ControlState
    bearings : ndarray, shape (R, L, 2)
        World-frame unit bearings (ignored in displacement mode).
    visible : ndarray of bool, shape (R, L)
    heading : ndarray, shape (R,)
        Yaw ``φ`` (rad) from the compass: the unicycle's heading, the single integrator's camera.
    x_true : ndarray, shape (R, 2), optional
        True positions; required in displacement mode (``x̂ = x``), ignored otherwise.
    displacements : ndarray, shape (R, L, 2), optional
        Displacement mode in a world that differs from the plan's (deformation tests): the
        measured ``l_k − x``; the field uses them as they are and ``x̂`` is the position that
        fits them best against the plan's landmarks, ``mean_k(l_k − d_k)``.

    Returns
    -------
    ControlOutput
    """
    s = settings
    r = len(state.cell)
    if s.measurement == "displacement":
        if displacements is not None:
            measured = np.mean(arrays.landmarks[None] - displacements, axis=1)
        elif x_true is None:
            raise ValueError("displacement measurement needs the true positions")
        else:
            measured = np.array(x_true, float).reshape(-1, 2)
        fix = np.ones(r, bool)
    else:
        estimate = bearing.reconstruct(bearings, visible, arrays.landmarks, 0, method="lsq",
                                       min_spread=s.min_spread, tol=s.tol)  # fmt: skip
        measured, fix = estimate.x_hat, estimate.usable.copy()
    # A scalar Kalman filter fuses the fixes with odometry: the prediction moves the last
    # estimate by the last command (its variance grows with the distance, odometry_drift per
    # unit), a fix of variance σ_fix² (from σ and the bearing geometry, bearing.fix_variance) corrects it,
    # and a fix farther than 3 standard deviations from the prediction is rejected. Noise-free
    # (σ = 0) every fix is taken as it is.
    sigma_fix2 = np.zeros(r)
    if s.bearing_sigma > 0 and fix.any():
        sigma_fix2[fix] = bearing.fix_variance(bearings[fix], visible[fix], arrays.landmarks, measured[fix],
                                               s.bearing_sigma, arrays.tol)  # fmt: skip
        fix &= sigma_fix2 <= (s.max_fix_error / 3.0) ** 2
    cell, target, last_dir = state.cell.copy(), state.target.copy(), state.last_dir.copy()
    known = state.known.copy()
    predicted = state.x_hat + s.dt * state.motion
    recent = known & s.odometry  # a prediction exists; its variance says how far to trust it
    travelled = s.dt * np.hypot(state.motion[:, 0], state.motion[:, 1])
    var_pred = state.var + (s.odometry_drift * travelled) ** 2
    innovation = np.einsum("rk,rk->r", measured - predicted, measured - predicted)
    fix &= ~(recent & (innovation > 9.0 * (var_pred + sigma_fix2)))
    with np.errstate(invalid="ignore", divide="ignore"):
        gain = np.where(recent & (var_pred + sigma_fix2 > 0), var_pred / (var_pred + sigma_fix2), 1.0)
    gain = np.where(np.isfinite(gain), gain, 1.0)
    corrected = np.where(recent[:, None], predicted + gain[:, None] * (measured - predicted), measured)
    hold = np.where(fix, 0.0, state.hold + s.dt)
    # moving on odometry alone: for hold_time, and on as long as the estimate stays within the
    # barrier margin (3σ <= blind_error; turning in place adds no uncertainty)
    carried = ~fix & recent & ((hold <= s.hold_time) | (9.0 * var_pred <= s.blind_error**2))
    x_hat = np.where(fix[:, None], corrected, predicted)
    with np.errstate(invalid="ignore"):
        posterior = np.where(np.isfinite(var_pred), (1.0 - gain) * var_pred, sigma_fix2)
    var = np.where(fix, np.where(recent, posterior, sigma_fix2), var_pred)
    steer = fix | carried  # robots with a position estimate this step
    known |= fix
    relocated = np.zeros(r, bool)
    stalled = np.zeros(r, bool)
    u = np.zeros((r, 2))
    # the estimate's error bound (3σ; 0 for exact fixes); funnel cells are tested eroded by it (§11.4)
    with np.errstate(invalid="ignore"):
        error_bound = np.where(np.isfinite(var), 3.0 * np.sqrt(np.maximum(var, 0.0)), np.inf)
    if steer.any():
        idx = np.flatnonzero(steer)
        erosion = np.minimum(error_bound[idx], arrays.plan_tolerance) if arrays.funnel else None
        c, t, moved = update(arrays, cell[idx], target[idx], x_hat[idx], s.eps_sw, s.tol, erosion)
        cell[idx], target[idx], relocated[idx] = c, t, moved
        f = arrays.fixed_landmark[c]
        if s.measurement == "displacement":
            y = displacement(arrays, x_hat[idx]) if displacements is None else displacements[idx].reshape(len(idx), -1)
        elif s.reconstruction == "lsq" or not fix[idx].all():
            y = bearing.scaled_output(x_hat[idx], arrays.landmarks, f, s.tol)
        else:
            rec = bearing.reconstruct(bearings[idx], visible[idx], arrays.landmarks, f, method=s.reconstruction,
                                      min_spread=s.min_spread, tol=s.tol)  # fmt: skip
            y = np.where(rec.usable[:, None], rec.y, bearing.scaled_output(x_hat[idx], arrays.landmarks, f, s.tol))
        ui = apply_gain(arrays, c, y)
        stalled[idx] = np.hypot(*affine_field(arrays, c, x_hat[idx]).T) < STALL_FIELD * arrays.u_max[c]
        going = t >= 0
        ui[going] = arrays.nodes[t[going]] - x_hat[idx[going]]
        stalled[idx[going]] = False
        norm = np.hypot(ui[:, 0], ui[:, 1])
        stalled[idx[~(norm > 0)]] = True
        ok = norm > 0
        u[idx[ok]] = ui[ok] / norm[ok, None]
        last_dir[idx[ok]] = u[idx[ok]]
    holding = ~steer  # no position estimate this step
    if s.odometry:
        # never move blind: without an estimate look around at once, for one revolution
        scanning = holding
        scan_time = hold - np.where(state.known, s.hold_time, 0.0)
    else:
        scanning = holding & (hold > s.hold_time)  # §7.5's hold first, then look around
        scan_time = hold - s.hold_time
    lost = scanning & (scan_time > 2.0 * math.pi / s.beta)
    direction = np.where(holding[:, None], last_dir, u)
    velocity = s.speed * direction
    velocity[scanning] = 0.0
    phi = np.asarray(heading, float).reshape(r)
    forward = np.zeros(r)
    # look around starting toward the last command (a scan that always turned one way undid
    # the unicycle's turn toward its field)
    toward = bearing.wrap(np.arctan2(last_dir[:, 1], last_dir[:, 0]) - phi)
    starting = scanning & ~state.scanning  # a scan keeps the direction it started with
    spin = np.where(starting, np.where(toward < 0, -1.0, 1.0), state.spin)
    turn = np.where(scanning, spin * s.beta, 0.0)
    motion = velocity.copy()
    if s.dynamics == "unicycle":
        e = bearing.wrap(np.arctan2(direction[:, 1], direction[:, 0]) - phi)
        # §7.1's v = α cos e; turn_first uses α cos³ e: a unicycle that is far off its field slows
        # down to turn instead of sweeping a wide arc past an obstacle corner (hold: turn in place)
        gain = np.cos(e) ** 3 if s.turn_first else np.cos(e)
        forward = np.where(holding | scanning, 0.0, s.alpha * gain)
        # a straight approach is certified only along its segment: turn on the spot first
        forward[(target >= 0) & (np.abs(e) > APPROACH_ALIGNMENT)] = 0.0
        if s.clamp_reverse:
            forward = np.maximum(forward, 0.0)
        turn = np.where(scanning, turn, s.beta * np.sin(e))
        motion = forward[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    # the estimate always moves on with the robot's own motion, steering with it or not
    new = ControlState(cell, target, last_dir, hold, np.where(known[:, None], x_hat, state.x_hat), motion, known,
                       var, scanning, spin)  # fmt: skip
    # certified (§11.4): a funnel plan, driven by a certified cell's field (not a straight approach),
    # on an estimate whose error bound is within the plan's tolerance δ*
    certified = arrays.funnel & steer & (target < 0) & (cell >= 0) & (error_bound <= arrays.plan_tolerance + s.tol)
    return ControlOutput(velocity, forward, turn, scanning, new, fix, lost, stalled, relocated,
                         np.where(steer[:, None], x_hat, 0.0), certified)  # fmt: skip


#: ``dt = min(DT_PER_DIAGONAL · D / v, DT_MAX)`` by default (ALGORITHMS §7.1).
DT_PER_DIAGONAL = 0.0025
DT_MAX = 0.2
#: Blind travel on odometry lasts while 3σ stays below this fraction of D (the default barrier margin).
BLIND_ERROR_PER_DIAGONAL = 0.01


def timing(diagonal: float, speed: float, dt: float | None = None) -> tuple[float, float, float]:
    """The loop constants of a map of diagonal ``D`` driven at ``speed`` (``α`` for the unicycle).

    Returns
    -------
    dt : float
        ``dt`` if given, else ``min(0.0025·D/speed, 0.2)`` (s).
    eps_sw : float
        Switching radius ``2·speed·dt`` (map units).
    blind_error : float
        ``0.01·D`` (map units), the default barrier margin.
    """
    dt = min(DT_PER_DIAGONAL * diagonal / speed, DT_MAX) if dt is None else dt
    return dt, 2.0 * speed * dt, BLIND_ERROR_PER_DIAGONAL * diagonal


class Controller:
    """The controller a robot runs: load ``plan.npz``, feed bearings at camera rate, get a command.

    Numpy only. One robot; the step is :func:`control`, the same function ``bearnav
    simulate`` advances its robots with.

    Parameters
    ----------
    arrays : PlanArrays
    settings : ControlSettings
    heading : float
        Initial heading (rad) standing in for the last command until the first fix.
    """

    def __init__(self, arrays: PlanArrays, settings: ControlSettings, heading: float = 0.0) -> None:
        self.arrays = arrays
        self.settings = settings
        self.state = ControlState.initial(np.array([heading]))
        self.last: ControlOutput | None = None

    @classmethod
    def from_plan(cls, path: str, *, speed: float = 0.1, dt: float | None = None, dynamics: str = "single",
                  heading: float = 0.0, **options: Any) -> Controller:  # fmt: skip
        """Load ``plan.npz``; ``options`` are further :class:`ControlSettings` fields.

        ``dt`` is the camera period (s); by default the simulation's, ``min(0.0025·D/v, 0.2)``
        with ``v`` = ``speed`` (``alpha`` for the unicycle), and ``eps_sw`` defaults to
        ``2·v·dt``, as in ``bearnav simulate``.
        """
        arrays = PlanArrays.from_npz(path)
        v = options.get("alpha", 0.1) if dynamics == "unicycle" else speed
        diagonal = math.hypot(*(arrays.bounds[2:] - arrays.bounds[:2]))
        dt, eps_sw, blind_error = timing(diagonal, v, dt)
        options.setdefault("eps_sw", eps_sw)
        options.setdefault("blind_error", blind_error)
        # a real camera is never exact: with σ = 0 the filter would trust odometry over every
        # noisy fix (set it to the camera's angular noise)
        options.setdefault("bearing_sigma", math.radians(1.0))
        return cls(arrays, ControlSettings(speed=speed, dt=dt, tol=arrays.tol, dynamics=dynamics, **options), heading)

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
        out = control(self.arrays, self.settings, self.state, np.asarray(bearings, float)[None],
                      np.asarray(visible, bool)[None], np.array([0.0 if heading is None else heading]))  # fmt: skip
        self.state, self.last = out.state, out
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
        return bool(np.hypot(*(self.state.x_hat[0] - self.arrays.goal)) <= self.arrays.goal_tolerance)

    @property
    def cell(self) -> int:
        """The active cell (``-1`` before the first fix)."""
        return int(self.state.cell[0])
