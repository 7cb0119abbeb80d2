"""The control step: one camera frame in, one command out, for ``R`` robots (ALGORITHMS §7, §11.3–11.4).

Numpy only. :func:`control` composes small steps that can be tested alone: the fix and its
fusion with odometry (:mod:`bearnav_cli.runtime.estimate`), the cell policy and the field
(:func:`follow_fields`), looking around without an estimate (:func:`look_around`) and the
unicycle mapping (:func:`unicycle_command`). ``bearnav simulate`` advances its robots with
:func:`control`, and :class:`~bearnav_cli.runtime.controller.Controller` takes the same step on a
robot, so what is simulated is what runs on the robot.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass

import numpy as np

from bearnav_cli.runtime import bearing
from bearnav_cli.runtime.bounded import MAX_VERTICES, one_look_bound
from bearnav_cli.runtime.cell_policy import (
    affine_field,
    apply_gain,
    cell_slack,
    displacement,
    in_sight,
    least_rank_cell,
    obstacle_clearance,
    update,
)
from bearnav_cli.runtime.estimate import Estimate, axle_bounds, bounded_update, fuse, measure
from bearnav_cli.runtime.plan_arrays import PlanArrays
from bearnav_cli.runtime.robot import ROBOT_DEFAULTS, lookahead_command, lookahead_point

__all__ = [
    "ALPHA", "APPROACH_ALIGNMENT", "BEARING_SIGMA", "DYNAMICS", "MEASUREMENTS", "ODOMETRY_DRIFT", "SPEED",
    "STALL_FIELD", "ControlOutput", "ControlSettings", "ControlState",
    "ESTIMATORS", "LOOK_HEADINGS", "best_bound_heading", "best_view_heading", "bounded_control",
    "bend_inward", "carry_inside", "certified_pace", "control", "error_ball_pace", "follow_fields",
    "heading_allowance", "look_around", "steer_clear", "timing", "unicycle_command", "views",
]  # fmt: skip

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- the control step

DYNAMICS = ("single", "unicycle")
MEASUREMENTS = ("bearing", "displacement")
#: Reference speed ``v_ref`` of the single integrator (map units / s): the one default of
#: ``bearnav simulate``, ``bearnav verify`` and :class:`~bearnav_cli.runtime.Controller`.
SPEED = 0.1
#: Forward gain ``α`` of the unicycle (map units / s), likewise.
ALPHA = 0.1
#: Bearing noise (1σ, radians) the filter assumes when the caller does not know its camera's: 1°.
#: Not 0: a filter that assumes exact bearings gives every fix zero variance, so after one fix the
#: odometry's prediction (variance ``(odometry_drift·d)²``) rejects every later fix that errs by more
#: than its 3σ: it trusts odometry over every noisy fix.
BEARING_SIGMA = math.radians(1.0)
#: Odometry error (1σ) per unit travelled that the filter assumes (its process noise): 5%.
ODOMETRY_DRIFT = 0.05
#: The estimators of the control step: bounded-error sets (ALGORITHMS §12.2) or the scalar filter.
ESTIMATORS = ("kalman", "set")
#: ``ν = SLIP_FLOOR_PER_DIAGONAL · D``, the odometry bound's floor per step (ALGORITHMS §12.1).
SLIP_FLOOR_PER_DIAGONAL = 1e-4
#: Headings tried when a look chooses where to turn (ALGORITHMS §12.5).
LOOK_HEADINGS = 36


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
        The robot's model (§7.1): the single integrator ``ẋ = v_ref·unit(ũ)``, or the unicycle
        driven by ``v = α cos e``, ``ω = β sin e`` toward the command's direction; on a plan with a
        look-ahead ``λ > 0`` (``arrays.lookahead``) the unicycle instead drives its point
        ``p = x + λh(θ)`` as a single integrator at ``α`` (ALGORITHMS §12.6, :func:`control`).
    alpha, beta : float
        Unicycle gains: ``v = α cos e`` (map units / s), ``ω = β sin e`` (rad / s).
    clamp_reverse : bool
        Unicycle: clamp ``v`` at 0 (never reverse); on a look-ahead plan those steps are not certified.
    turn_first : bool
        Unicycle: ``v = α cos³ e`` (slow down to turn) instead of §7.1's ``α cos e``.
    measurement : {"bearing", "displacement"}
        ``bearing``: reconstruct ``ỹ`` and ``x̂`` from bearings (§6); ``displacement``: the
        true displacements, ``x̂ = x`` (paper B).
    reconstruction : {"lsq", "pair", "rescale"}
        How the field's output ``ỹ`` is rebuilt from bearings (§6.2–6.4): ``lsq`` takes it at ``x̂``,
        ``(l_k − x̂)/‖l_f − x̂‖``; ``pair`` and ``rescale`` reconstruct it from the bearings when every
        robot that steers has a fix this step (from ``x̂`` otherwise, and where theirs is not usable).
        ``x̂`` itself always comes from ``lsq``.
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
    bearing_sigma : float
        Bearing noise (1σ, radians) the filter assumes, :data:`BEARING_SIGMA` (1°) by default: a
        filter that assumes exact bearings (0) trusts odometry over every noisy fix.
    max_fix_error : float
        Use a fix only if its predicted 3σ error is at most this (map units).
    certified_heading : bool
        Unicycle on a funnel plan without a look-ahead: drive forward only while the heading error
        keeps the velocity inside every condition the cell's field meets at ``x̂``
        (:func:`heading_allowance`), turn in place otherwise; off: §7.1's rule alone. (The
        look-ahead law replaces it.)
    fov, max_range : float
        The camera's full field of view (radians) and range (map units), for looking on purpose.
    look_on_purpose : bool
        A robot that lost its fix first turns toward the nearest heading where the map says a
        usable pair of tags is in view from its estimate (:func:`best_view_heading`), then, if that
        gives no fix, looks all around; off (the default: it did not do better, docs/choices.md) or
        a camera that sees all around: the revolution at once.
    keep_clear : bool
        A step the certificate does not cover (error bound above ``δ*``) is slowed so that the
        error ball, grown by the step, stays off the obstacles (:func:`error_ball_pace`), and bent
        away from the nearest one as it slows (:func:`steer_clear`); a robot that cannot move at
        all waits in place for fixes that shrink the ball (turning to look when it has none). Off:
        every step at full speed. (Only the ``kalman`` estimator, and starts outside ``D``.)
    estimator : {"kalman", "set"}
        ``set``: the bounded-error sets of ALGORITHMS §12.2 and the certified policy of §12.3 — drive
        only while ``e_t + κℓ + ν ≤ τ_c``, else stop and look (§12.5, :func:`bounded_control`);
        ``kalman`` (the default until plans are made live, docs/runtime.md): the scalar filter of
        :func:`~bearnav_cli.runtime.estimate.fuse` with the pace rule.
    bearing_bound : float
        ``η`` (rad): the bound on every world-frame bearing error the set estimator assumes
        (``η_cam + ψ``, ALGORITHMS §12.1).
    heading_bound : float
        ``ψ`` (rad): the bound on the heading error; a look-ahead point ``λ`` ahead errs by at most
        ``2λ sin(ψ/2)`` more than the axle.
    slip : float
        ``κ``: odometry errs by at most ``κ‖d̂‖ + ν`` over a step that translates by ``d̂``.
    slip_floor : float
        ``ν`` (map units), ``1e-4·D`` from :meth:`for_plan`.
    """

    speed: float
    dt: float
    eps_sw: float
    tol: float
    dynamics: str = "single"
    alpha: float = ALPHA
    beta: float = 0.5
    clamp_reverse: bool = False
    turn_first: bool = True
    measurement: str = "bearing"
    reconstruction: str = "lsq"
    min_spread: float = bearing.DEFAULT_MIN_SPREAD
    hold_time: float = 2.0
    odometry: bool = True
    odometry_drift: float = ODOMETRY_DRIFT
    blind_error: float = 0.0
    bearing_sigma: float = BEARING_SIGMA
    max_fix_error: float = math.inf
    certified_heading: bool = True
    fov: float = 2.0 * math.pi
    max_range: float = math.inf
    look_on_purpose: bool = False
    keep_clear: bool = True
    estimator: str = "kalman"
    bearing_bound: float = math.radians(ROBOT_DEFAULTS["bearing_error_deg"])
    heading_bound: float = 0.0
    slip: float = ROBOT_DEFAULTS["slip"]
    slip_floor: float = 0.0

    @property
    def top_speed(self) -> float:
        """The robot's full speed (map units / s): ``v_ref`` of the single integrator, or ``α`` of the unicycle."""
        return self.alpha if self.dynamics == "unicycle" else self.speed

    @classmethod
    def for_plan(cls, diagonal: float, tol: float, *, dynamics: str = "single", speed: float = SPEED,
                 alpha: float = ALPHA, dt: float | None = None, bearing_sigma: float = BEARING_SIGMA,
                 **fields: object) -> ControlSettings:  # fmt: skip
        """The settings of a plan's loop: the one builder of ``bearnav simulate`` and :class:`Controller`.

        ``dt`` defaults to ``min(0.0025·D/v, 0.2)``, ``eps_sw`` to ``2·v·dt`` and ``blind_error``
        to ``0.01·D`` (:func:`timing`), with ``v`` = ``speed``, or ``alpha`` for the unicycle.
        ``bearing_sigma`` (radians) is the noise the filter assumes, :data:`BEARING_SIGMA` (1°)
        unless the caller knows its camera's: a robot passes its camera's angular noise, and
        ``bearnav simulate`` the noise it draws (``noise_deg``; 0 for its exact default camera,
        whose fixes are exact). ``fields`` are further fields of :class:`ControlSettings`.

        Parameters
        ----------
        diagonal : float
            ``D``, the diagonal of the map's bounds (map units).
        tol : float
            The plan's membership slack (``1e-9·D``).
        """
        v = alpha if dynamics == "unicycle" else speed
        dt, eps_sw, blind_error = timing(diagonal, v, dt)
        fields.setdefault("eps_sw", eps_sw)
        fields.setdefault("blind_error", blind_error)
        fields.setdefault("slip_floor", SLIP_FLOOR_PER_DIAGONAL * diagonal)
        return cls(speed=speed, dt=dt, tol=tol, dynamics=dynamics, alpha=alpha, bearing_sigma=bearing_sigma,
                   **fields)  # type: ignore[arg-type]  # fmt: skip


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
    look : ndarray, shape (R,)
        The heading a look on purpose turns to (rad), NaN when none (:func:`look_around`).
    scan_from : ndarray, shape (R,)
        ``hold`` when the current look-around began (s): its clock, which starts when the scan does
        (odometry may have carried the robot blind for much longer than ``hold_time`` before).
    set_vertices : ndarray, shape (R, W, 2)
        The set estimator's ``X_t`` (ALGORITHMS §12.2), padded convex polygons (map units).
    set_count : ndarray of int64, shape (R,)
        Their vertex counts.
    resume : ndarray, shape (R,)
        The heading a look-ahead unicycle turns back to after a look (rad; NaN: none).
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
    look: np.ndarray
    scan_from: np.ndarray
    set_vertices: np.ndarray
    set_count: np.ndarray
    resume: np.ndarray

    @classmethod
    def initial(cls, heading: np.ndarray) -> ControlState:
        """Robots that have not had a fix yet, facing ``heading`` (rad, shape (R,))."""
        h = np.asarray(heading, float).reshape(-1)
        r = len(h)
        return cls(np.full(r, -1, np.int64), np.full(r, -1, np.int64), np.column_stack([np.cos(h), np.sin(h)]),
                   np.zeros(r), np.zeros((r, 2)), np.zeros((r, 2)), np.zeros(r, bool), np.full(r, np.inf),
                   np.zeros(r, bool), np.ones(r), np.full(r, np.nan), np.zeros(r),
                   np.zeros((r, MAX_VERTICES, 2)), np.zeros(r, np.int64), np.full(r, np.nan))  # fmt: skip

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
        The position estimate (measured or carried by odometry; zeros before the first fix): the
        axle's; a look-ahead unicycle's policy ran at ``x̂ + λh(θ)``.
    certified : ndarray of bool, shape (R,)
        The step is covered by the composed certificate (ALGORITHMS §11.4): a funnel plan, a cell's
        field (not a straight approach), and an estimate whose error bound (3σ) is at most the
        active cell's usable tolerance ``τ_c`` (§12.3);
        for a unicycle only as the look-ahead point of §12.6 (``λ > 0``) on a step the reverse
        clamp left alone (never with ``λ = 0``).
    waiting : ndarray of bool, shape (R,)
        Held in place because the error ball grown by any step would reach an obstacle
        (:func:`error_ball_pace` is 0): the robot does not translate and waits for better fixes.
    looking : ndarray of bool, shape (R,)
        Stopped to look (ALGORITHMS §12.5): the robot does not translate this step (looking around,
        waiting, or a look-ahead unicycle turning back to its heading before the look).
    error_bound : ndarray, shape (R,)
        The bound on the error of the point the policy ran at (map units): ``e_t`` of the set (plus
        ``2λ sin(ψ/2)`` for a look-ahead point), or the filter's 3σ.
    inconsistent : ndarray of bool, shape (R,)
        The set estimator found its set empty this step (a bound was broken, §12.2).
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
    waiting: np.ndarray
    looking: np.ndarray
    error_bound: np.ndarray
    inconsistent: np.ndarray


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

    A unicycle on a plan with a look-ahead ``λ > 0`` (ALGORITHMS §12.6): the estimate is of the
    axle ``x``; the policy (cells, switching, field, the error ball's pace) runs at
    ``p̂ = x̂ + λh(θ)``, and the wanted velocity of ``p``, ``w = α·pace·unit(u)``, becomes
    ``(v, ω) = (w·h, w·h^⊥/λ)`` (:func:`~bearnav_cli.runtime.robot.lookahead_command`, Lemma 7),
    in place of §7.1's rule and the heading allowance. Without an estimate it turns in place as
    before.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's run-time arrays: landmarks, cells, gains and barrier rows.
    settings : ControlSettings
        The loop's constants (:meth:`ControlSettings.for_plan`).
    state : ControlState
        What the robots remember from the previous step (:meth:`ControlState.initial` at the start).
    bearings : ndarray, shape (R, L, 2)
        World-frame unit bearings (ignored in displacement mode).
    visible : ndarray of bool, shape (R, L)
        Which landmarks each robot's camera sees this frame (only those enter the fix).
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
    if s.estimator == "set":
        return bounded_control(arrays, s, state, bearings, visible, heading, x_true)
    prior = np.where((state.known & s.odometry)[:, None], state.x_hat + s.dt * state.motion, np.nan)
    fix = measure(arrays, s, bearings, visible, x_true, displacements, prior)
    axle = fuse(s, state, fix)  # the estimate of the axle x (where the camera is)
    lam = arrays.lookahead if s.dynamics == "unicycle" else 0.0
    ahead = lam > 0.0  # ALGORITHMS §12.6: the policy runs at the look-ahead point p̂ = x̂ + λh(θ̂)
    policy, reference = s, axle
    if ahead:
        phi = np.asarray(heading, float).reshape(len(state.cell))
        unit_heading = np.column_stack([np.cos(phi), np.sin(phi)])
        reference = dataclasses.replace(axle, x_hat=lookahead_point(axle.x_hat, phi, lam))
        if displacements is not None:  # l_k − p = (l_k − x) − λh
            displacements = displacements - lam * unit_heading[:, None, :]
        if s.reconstruction != "lsq":  # the bearings are taken at x, not at p: the output comes from p̂
            policy = dataclasses.replace(s, reconstruction="lsq")
    est = carry_inside(arrays, s, state, reference)
    cell, target, last_dir, u, stalled, relocated = follow_fields(arrays, policy, state, est, bearings, visible,
                                                                  displacements)  # fmt: skip
    if s.keep_clear:
        pace, away = error_ball_pace(arrays, s, cell, est.x_hat, est.error_bound)
        u = steer_clear(u, pace, away)
    else:
        pace = np.ones(len(cell))
    waiting = est.steer & (pace <= 0.0)
    if waiting.any():
        # waiting with no fix this step: look for one (turning in place keeps the ball where it is)
        est = dataclasses.replace(est, steer=est.steer & ~(waiting & ~est.fix))
    holding = ~est.steer  # no position estimate this step
    # a look on purpose looks from the camera, on the axle
    seen_from = dataclasses.replace(est, x_hat=axle.x_hat) if ahead else est
    scanning, lost, spin, turn, look = look_around(s, state, seen_from, last_dir, heading, arrays)
    direction = np.where(holding[:, None], last_dir, u)
    slow = np.where(est.steer, pace, 1.0)  # the error ball's pace, for robots that steer by an estimate
    within = est.error_bound <= arrays.tolerance_in(cell) + s.tol  # the estimate is good to τ_c (§12.3)
    velocity = (s.speed * slow)[:, None] * direction
    velocity[scanning] = 0.0
    forward, motion = np.zeros(len(cell)), velocity.copy()
    clamped = np.zeros(len(cell), bool)
    if ahead:
        # Lemma 7: p is a single integrator; w = α·pace·u moves it exactly (holding and looking
        # around turn in place as below: the axle stays where it is)
        forward, turn, motion = unicycle_command(s, direction, heading, holding, scanning, target, turn)
        drive = np.flatnonzero(est.steer & ~scanning)
        w = (s.alpha * slow[drive])[:, None] * direction[drive]
        forward[drive], turn[drive], clamped[drive] = lookahead_command(w, phi[drive], lam, s.clamp_reverse)
        motion = forward[:, None] * unit_heading
    elif s.dynamics == "unicycle":
        allowed = None
        if s.certified_heading:
            # the allowance keeps a certified step certified; a step beyond δ* has no certificate to
            # keep (error_ball_pace keeps it clear whichever way it drives), and there the noise in
            # x̂ turns the field's direction faster than a tight allowance lets the robot follow
            allowed = heading_allowance(arrays, cell, est.x_hat, target)
            if s.keep_clear:
                allowed = np.where(within, allowed, math.pi)
        forward, turn, motion = unicycle_command(s, direction, heading, holding, scanning, target, turn, allowed)
        forward, motion = forward * slow, motion * slow[:, None]
    # the estimate always moves on with the robot's own motion, steering with it or not; it is the axle's
    x_hat = axle.x_hat if ahead else est.x_hat
    new = ControlState(cell, target, last_dir, est.hold, np.where(est.known[:, None], x_hat, state.x_hat), motion,
                       est.known, est.var, scanning, spin, look,
                       np.where(scanning & ~state.scanning, est.hold - s.dt, state.scan_from),
                       state.set_vertices, state.set_count, state.resume)  # fmt: skip
    # certified (§11.4): a funnel plan, driven by a certified cell's field (not a straight approach),
    # on an estimate whose error bound is within the cell's τ_c; a unicycle only as the
    # look-ahead point of §12.6 (λ > 0), and not on a step the reverse clamp changed
    certified = arrays.funnel & est.steer & (target < 0) & (cell >= 0) & within & ~clamped
    if s.dynamics == "unicycle" and not ahead:
        certified = np.zeros(len(cell), bool)  # λ = 0: the heading rules keep it safe in practice, unproven
    return ControlOutput(velocity, forward, turn, scanning, new, est.fix, lost, stalled, relocated,
                         np.where(est.steer[:, None], x_hat, 0.0), certified, waiting, scanning | waiting,
                         est.error_bound, np.zeros(len(cell), bool))  # fmt: skip


def bounded_control(arrays: PlanArrays, s: ControlSettings, state: ControlState, bearings: np.ndarray,
                    visible: np.ndarray, heading: np.ndarray,
                    x_true: np.ndarray | None = None) -> ControlOutput:  # fmt: skip
    """One step of the certified policy of ALGORITHMS §12.3 on the estimate sets of §12.2, for ``R`` robots.

    The set ``X_t`` and its estimate ``x̂`` with error ``e`` come from
    :func:`~bearnav_cli.runtime.estimate.bounded_update`; a look-ahead unicycle's policy runs at
    ``p̂ = x̂ + λh(θ)`` with the error ``e + 2λ sin(ψ/2)``. Then, for each robot:

    - **in a cell** (the least-rank cell ``k`` with ``p̂ ∈ P_k ⊖ e``, switched to only at lower rank,
      :func:`~bearnav_cli.runtime.cell_policy.update` with erosion ``e``): it **moves** with the cell's
      field only while ``e + κℓ + ν ≤ τ_c`` (``ℓ = v·dt``); every such step is certified;
    - **maybe in one** (some cell holds ``p̂`` but none eroded by ``e``), or in a cell with too large
      an ``e``: it **stops and looks** (§12.5) — it turns toward the heading from which the plan's
      landmarks promise the smallest one-look bound (:func:`best_bound_heading`), then, if that was
      not enough, once all around; after that it is ``lost`` (stuck looking). A look-ahead unicycle
      remembers its heading when a look begins and turns back to it before it moves again (``p``
      swings around the axle while it looks), unless it may move where it is;
    - **outside every cell** (a start in ``F \\ D``): the uncertified rules of the ``kalman``
      estimator — a straight approach to a node at the error ball's pace (:func:`error_ball_pace`,
      :func:`steer_clear`), waiting and looking where that pace is 0.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's run-time arrays.
    s : ControlSettings
        The loop's constants, with ``estimator == "set"`` and the error model (``bearing_bound``,
        ``heading_bound``, ``slip``, ``slip_floor``).
    state : ControlState
        What the robots remember, their sets ``set_vertices``/``set_count`` among it.
    bearings : ndarray, shape (R, L, 2)
        World-frame unit bearings.
    visible : ndarray of bool, shape (R, L)
        Which landmarks each robot sees.
    heading : ndarray, shape (R,)
        Yaw (rad) from the compass.
    x_true : ndarray, shape (R, 2), optional
        True positions, in displacement mode (``X_t = {x}``).

    Returns
    -------
    ControlOutput
    """
    r = len(state.cell)
    sets = bounded_update(arrays, s, state, bearings, visible, x_true)
    phi = np.asarray(heading, float).reshape(r)
    lam = arrays.lookahead if s.dynamics == "unicycle" else 0.0
    ahead = lam > 0.0
    swing = 2.0 * lam * math.sin(0.5 * s.heading_bound) if ahead else 0.0
    reference = lookahead_point(sets.x_hat, phi, lam) if ahead else sets.x_hat
    known = state.known | sets.seen  # a set narrower than B_r
    error = np.where(known, sets.error + swing, np.inf)
    # κℓ + ν of one step; a measured displacement knows the position itself at every step (paper B, and
    # verify's loop with the exact motion of §7.1): no odometry enters the estimate
    step_len = s.top_speed * s.dt  # ℓ
    margin = 0.0 if s.measurement == "displacement" else s.slip * step_len + s.slip_floor
    est = Estimate(reference, error**2 / 9.0, sets.seen, known & np.isfinite(error), known,
                   np.where(known, state.hold, 0.0), error)  # fmt: skip
    # the truth is in the active cell (Theorem 2), so its estimate may lie up to e outside it; not after a
    # look-ahead unicycle's look swung p around the axle: then p̂ must lie in a cell eroded by e
    swung = np.isfinite(state.resume) if ahead else np.zeros(r, bool)
    keep = np.where(swung, -error, error)
    cell, target, last_dir, u, stalled, relocated = follow_fields(arrays, s, state, est, bearings, visible,
                                                                  keep=keep)  # fmt: skip
    in_cell = (cell >= 0) & (target < 0) & known
    tau = arrays.tolerance_in(cell)
    move = in_cell & (error + margin <= tau + s.tol)
    if arrays.funnel:
        # a cell grown by e holds p̂ (the robot may be in it) but none eroded by e does: look while a
        # look may tell which (e too large for that cell); with e that small the robot sits at the edge
        # of a cell, and drives on that cell's field, uncertified, until the switch applies
        holder = np.full(r, -1, np.int64)
        open_ = np.flatnonzero(known & ~in_cell)
        holder[open_] = least_rank_cell(arrays, reference[open_], -error[open_])
        undecided = (holder >= 0) & (error + margin > arrays.tolerance_in(holder) + s.tol)
    else:
        undecided = np.zeros(r, bool)
        move = in_cell
    # undecided robots have not chosen a cell: they look before any approach
    cell, target = np.where(undecided, -1, cell), np.where(undecided, -1, target)
    outside = known & ~in_cell & ~undecided
    pace = np.where(move, 1.0, 0.0)
    if arrays.funnel and move.any():
        idx = np.flatnonzero(move)
        # the motion's own error, and a look-ahead point's Euler error λ(ωdt)²/2 ≤ ℓ²/2λ (|ω| ≤ α/λ)
        wobble = margin + (step_len**2 / (2.0 * lam) if ahead else 0.0)
        pace[idx] = certified_pace(arrays, cell[idx], reference[idx], error[idx], u[idx], step_len, wobble)
        slow = idx[pace[idx] < 1.0]
        if len(slow):  # near a face the field may slide along it: bend it inward just enough, if that helps
            bent = bend_inward(arrays, cell[slow], reference[slow], error[slow], u[slow], step_len, wobble)
            better = certified_pace(arrays, cell[slow], reference[slow], error[slow], bent, step_len, wobble)
            take = better > pace[slow]
            u[slow[take]], pace[slow[take]] = bent[take], better[take]
        move[idx] = pace[idx] > 0.0
    if arrays.funnel:
        # at the edge of D (a cell holds p̂, e is small, no cell eroded by e does): that cell's field,
        # uncertified, at the error ball's pace; it leads deeper into the cell, where the switch applies
        edge = np.flatnonzero(outside & (holder >= 0))
        if len(edge):
            field = affine_field(arrays, holder[edge], reference[edge])
            norm = np.hypot(field[:, 0], field[:, 1])
            ok = norm > 0
            u[edge] = np.where(ok[:, None], field / np.where(ok, norm, 1.0)[:, None], 0.0)
            cell[edge], target[edge] = holder[edge], -1
            last_dir[edge[ok]] = u[edge[ok]]
            # follow_fields found no cell eroded by e nor a node in sight and called it a stall; the field of
            # the cell holding p̂ applies now (a run ended at its first step there, under worst-case bearings)
            stalled[edge] = ~ok
    if outside.any():
        idx = np.flatnonzero(outside)
        pace_out, away = error_ball_pace(arrays, s, cell[idx], reference[idx], error[idx])
        u[idx] = steer_clear(u[idx], pace_out, away)
        pace[idx] = pace_out
    resume = state.resume.copy()
    # after a look a look-ahead unicycle's p has swung around the axle: only a certified step goes
    # from there; anything else waits until it has turned back
    pending = np.isfinite(resume) if ahead else np.zeros(r, bool)
    if pending.any() and arrays.funnel:
        # a swung p is progress only in a cell of lower rank than the one it left; in that cell (or a worse one)
        # the look's swing may have undone the field's progress, and driving from there repeats it look after look
        # (a loop seen under worst-case bearings): turn back first, as ALGORITHMS §12.6 says
        had = state.cell >= 0
        worse = pending & had & (cell >= 0) & (arrays.cell_rank[np.maximum(cell, 0)] >=
                                               arrays.cell_rank[np.maximum(state.cell, 0)])  # fmt: skip
        move &= ~worse
    drive = (move | (outside & (pace > 0.0) & ~pending)) & np.any(u != 0.0, axis=1)
    back = np.zeros(r, bool)
    if ahead:
        resume[drive] = np.nan
        returning = ~drive & known & pending
        if returning.any():  # the look is over when e would let it move where it was (or it was outside D)
            idx = np.flatnonzero(returning)
            there = lookahead_point(sets.x_hat[idx], resume[idx], lam)
            if arrays.funnel:
                # in the cell it will drive in there: the one it keeps, unless a cell of lower rank
                # holds p̂ eroded by e (the switch); the least-rank cell merely holding p̂ may have a
                # larger τ_c, and a look ended on it turned back into a cell that made it look again
                had = state.cell[idx]
                k = least_rank_cell(
                    arrays, there, error[idx], below=np.where(had >= 0, arrays.cell_rank[np.maximum(had, 0)], np.inf)
                )
                k = np.where(k >= 0, k, had)
                # without a cell, the one a robot there would wait in (a cell grown by e holds p̂)
                k = np.where(k >= 0, k, least_rank_cell(arrays, there, -error[idx]))
            else:
                k = np.full(len(idx), -1)
            over = error[idx] + margin <= arrays.tolerance_in(k) + s.tol
            out = np.flatnonzero(k < 0)
            if len(out):
                # outside D there: the uncertified rules move it only at a positive error-ball pace; a
                # look ended at pace 0 turned back to wait, and waiting began the look again
                over[out] = error_ball_pace(arrays, s, k[out], there[out], error[idx[out]])[0] > 0.0
            back[idx[over]] = True
        # the swung p says nothing about the cell the robot will drive in: it keeps the one it had
        cell[returning], target[returning], relocated[returning] = state.cell[returning], state.target[returning], False
    hold = np.where(drive, 0.0, np.where(known, state.hold + s.dt, 0.0))
    looker = Estimate(sets.x_hat, est.var, est.fix, drive | back, known, hold, error)
    scanning, lost, spin, turn, look = look_around(s, state, looker, last_dir, heading, arrays)
    if ahead:
        starting = scanning & ~state.scanning & ~np.isfinite(resume)
        resume[starting] = phi[starting]
        if back.any():
            gap = bearing.wrap(resume[back] - phi[back])
            turn[back] = np.clip(gap / s.dt, -s.beta, s.beta)
            arrived = np.abs(gap) <= s.beta * s.dt * 1e-6 + 1e-12
            resume[np.flatnonzero(back)[arrived]] = np.nan
    holding = ~drive
    direction = np.where(drive[:, None], u, last_dir)
    velocity = (s.speed * np.where(drive, pace, 0.0))[:, None] * direction
    forward, motion = np.zeros(r), velocity.copy()
    clamped = np.zeros(r, bool)
    if ahead:
        # a look-ahead unicycle that does not drive turns only to look or to turn back: any other turn
        # would swing p unrecorded (a look records the heading it turns back to)
        turn = np.where(scanning | back, turn, 0.0)
        idx = np.flatnonzero(drive)
        w = (s.alpha * pace[idx])[:, None] * direction[idx]
        forward[idx], turn[idx], clamped[idx] = lookahead_command(w, phi[idx], lam, s.clamp_reverse)
        motion = forward[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    elif s.dynamics == "unicycle":
        allowed = heading_allowance(arrays, cell, reference, target) if s.certified_heading else None
        forward, turn_cmd, motion = unicycle_command(s, direction, heading, holding, scanning, target, turn, allowed)
        # a robot that may not move only turns (to look, or toward its field)
        forward, motion = forward * pace, motion * pace[:, None]
        turn = np.where(scanning, turn, turn_cmd)
    new = ControlState(cell, target, last_dir, hold, np.where(known[:, None], sets.x_hat, state.x_hat), motion,
                       known, est.var, scanning, spin, look,
                       np.where(scanning & ~state.scanning, hold - s.dt, state.scan_from),
                       sets.vertices, sets.count, resume)  # fmt: skip
    certified = arrays.funnel & move & drive & ~clamped
    if s.dynamics == "unicycle" and not ahead:
        certified = np.zeros(r, bool)  # λ = 0: the unicycle is not the single integrator of the certificate
    looking = known & ~drive
    return ControlOutput(velocity, forward, turn, scanning, new, sets.seen, lost & ~drive, stalled & drive,
                         relocated, np.where(known[:, None], reference, 0.0), certified, looking & ~scanning & ~back,
                         looking | ~known, error, sets.inconsistent)  # fmt: skip


def certified_pace(arrays: PlanArrays, cell: np.ndarray, x_hat: np.ndarray, error: np.ndarray,
                   direction: np.ndarray, step: float, disturbance: float) -> np.ndarray:  # fmt: skip
    """The largest fraction of a step that keeps the truth in its cell's barrier set, shape (R,) in [0, 1].

    The discrete-time part of Theorem 2 (ALGORITHMS §12.3), done exactly: the true position ``x``
    lies within ``e`` of ``x̂`` and, by induction, in the cell (every barrier row ``h_k = A_k·x + b_k
    ≥ 0``); a step at the fraction ``p`` moves it by ``pℓ·d`` plus an error of at most ``w``
    (``κpℓ + ν``, and for a look-ahead point the Euler error ``ℓ²/2λ``). Row ``k`` stays satisfied if

    - the step moves inward fast enough: ``pℓ (A_k·d) ≥ w`` (then ``h_k`` does not decrease), or
    - the row is far enough whichever way: ``h_k(x̂) − e ≥ pℓ + w``.

    The first holds for every ``p`` once ``A_k·d ≥ w/ℓ`` (with ``w`` at ``p = 1``, an upper bound); the
    second bounds ``p``. The pace is the least bound over the rows that need it (0: no step is safe).
    The exit row is not a barrier: crossing it is the progress the cell is for.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's barrier rows ``bar_A``, ``bar_b`` (padding rows are ``0·x + inf``).
    cell : ndarray of int, shape (R,)
        Active cells (all ``>= 0``).
    x_hat : ndarray, shape (R, 2)
        Estimates of the point the plan is about (map units).
    error : ndarray, shape (R,)
        Their error bounds ``e`` (map units).
    direction : ndarray, shape (R, 2)
        Unit step directions.
    step : float
        ``ℓ``, a full step's length (map units).
    disturbance : float
        ``w``: the bound on a step's motion error at full length (map units).
    """
    c = np.asarray(cell, np.int64)
    A, b = arrays.bar_A[c], arrays.bar_b[c]
    with np.errstate(invalid="ignore"):
        h = np.einsum("rqi,ri->rq", A, x_hat) + b
    inward = np.einsum("rqi,ri->rq", A, direction)
    free = ~np.isfinite(b) | (step * inward >= disturbance)
    with np.errstate(invalid="ignore"):
        room = (h - error[:, None] - disturbance) / step
    bound = np.where(free, 1.0, np.clip(room, 0.0, 1.0))
    return np.min(bound, axis=1, initial=1.0)


def bend_inward(arrays: PlanArrays, cell: np.ndarray, x_hat: np.ndarray, error: np.ndarray, direction: np.ndarray,
                step: float, disturbance: float) -> np.ndarray:  # fmt: skip
    """The unit step directions turned toward the inside of the faces that :func:`certified_pace` finds near, (R, 2).

    For every barrier row ``k`` within reach (``h_k(x̂) − e < ℓ + w``) that the step does not leave
    fast enough (``A_k·d < w/ℓ``), the direction gains ``(w/ℓ − A_k·d + 0.01)·A_k``; the sum is
    normalised. The exit direction is kept: a bend that would stop the progress (``z·d' ≥ 0`` in a cell
    with an exit) gives the field's direction back. Safety does not rest on the bend: the step it
    gives is taken only at :func:`certified_pace`'s pace, which checks every row exactly.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's barrier rows and exit directions.
    cell : ndarray of int, shape (R,)
        Active cells.
    x_hat : ndarray, shape (R, 2)
        Estimates (map units).
    error : ndarray, shape (R,)
        Their error bounds (map units).
    direction : ndarray, shape (R, 2)
        The field's unit directions.
    step, disturbance : float
        ``ℓ`` and ``w`` as in :func:`certified_pace` (map units).
    """
    c = np.asarray(cell, np.int64)
    A, b = arrays.bar_A[c], arrays.bar_b[c]
    with np.errstate(invalid="ignore"):
        h = np.einsum("rqi,ri->rq", A, x_hat) + b
    inward = np.einsum("rqi,ri->rq", A, direction)
    need = np.isfinite(b) & (h - error[:, None] < step + disturbance) & (inward < disturbance / step)
    gain = np.where(need, disturbance / step - inward + 0.01, 0.0)
    bent = direction + np.einsum("rq,rqi->ri", gain, np.where(np.isfinite(b)[..., None], A, 0.0))
    norm = np.hypot(bent[:, 0], bent[:, 1])
    out = np.where(norm[:, None] > 0, bent / np.where(norm > 0, norm, 1.0)[:, None], direction)
    exit_ = arrays.parent_cell[c] >= 0
    stops = exit_ & (np.einsum("ri,ri->r", arrays.exit_dir[c], out) >= 0.0)
    out[stops] = direction[stops]
    return out


def best_bound_heading(arrays: PlanArrays, s: ControlSettings, x: np.ndarray, phi: np.ndarray,
                       headings: int = LOOK_HEADINGS) -> np.ndarray:  # fmt: skip
    """The camera heading at ``x`` whose view promises the smallest one-look bound ``ε``, shape (R,) rad.

    Among ``headings`` evenly spaced headings, the landmarks in the field of view, in range and in
    line of sight from ``x`` (``cell_policy.in_sight``) give
    :func:`~bearnav_cli.runtime.bounded.one_look_bound` at ``η = s.bearing_bound``; the least ``ε``
    wins, ties to the smallest turn from ``phi`` (ALGORITHMS §12.5). NaN where no heading sees a
    landmark.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's landmarks, sight edges and bounds.
    s : ControlSettings
        ``fov`` (rad), ``max_range`` (map units) and ``bearing_bound`` (rad).
    x : ndarray, shape (R, 2)
        Where each robot looks from (its estimate, map units).
    phi : ndarray, shape (R,)
        Its heading now (rad).
    headings : int
        Candidate headings over ``[−π, π)``.
    """
    p = np.asarray(x, float).reshape(-1, 2)
    phi = np.asarray(phi, float).reshape(len(p))
    visible = views(arrays, p, s.fov, s.max_range, headings)  # (R, H, L)
    r, h, n_lm = visible.shape
    # more cones give a smaller set: only the views no other heading's view contains (the first of
    # equal ones) need their bound; a heading whose view lies in another's is never better
    within = np.all(visible[:, :, None, :] <= visible[:, None, :, :], axis=3)  # (R, H, H): view h ⊆ view h'
    earlier = np.arange(h)[None, :] < np.arange(h)[:, None]  # h' < h
    dominated = np.any(within & (~np.swapaxes(within, 1, 2) | earlier[None]) & ~np.eye(h, dtype=bool)[None], axis=2)
    todo = ~dominated & visible.any(axis=2)
    rr, hh = np.nonzero(todo)
    eps = np.full((r, h), np.inf)
    if len(rr):
        eps[rr, hh] = one_look_bound(p[rr], arrays.landmarks, visible[rr, hh], s.bearing_bound, axle_bounds(arrays),
                                     arrays.tol)  # fmt: skip
    theta = np.linspace(-math.pi, math.pi, h, endpoint=False)
    turn = np.abs(bearing.wrap(theta[None, :] - phi[:, None]))
    best = np.lexsort((turn, eps), axis=1)[:, 0] if eps.size else np.zeros(len(p), np.int64)
    out = theta[best]
    out[~np.isfinite(eps).any(axis=1)] = np.nan
    return out


def views(arrays: PlanArrays, x: np.ndarray, fov: float, max_range: float, headings: int,
          landmarks: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """Which landmarks a camera at ``x`` sees at each of ``headings`` evenly spaced headings, (R, H, L).

    In the field of view ``fov`` (rad) around the heading, within ``max_range`` (map units; ``inf``:
    any) and in line of sight (``cell_policy.in_sight``); heading ``k`` is ``−π + 2πk/H``.
    ``landmarks`` (L, 2): other positions than the plan's (tags proposed for it).

    Parameters
    ----------
    arrays : PlanArrays
        The plan's landmarks and the raw obstacle edges that hide them.
    x : ndarray, shape (R, 2)
        Camera positions (map units).
    fov : float
        Full field of view (rad).
    max_range : float
        Range (map units).
    headings : int
        ``H``.
    landmarks : ndarray, shape (L, 2), optional
        The landmarks (map units); default the plan's.
    """
    p = np.asarray(x, float).reshape(-1, 2)
    lm = arrays.landmarks if landmarks is None else np.asarray(landmarks, float).reshape(-1, 2)
    d = lm[None] - p[:, None, :]
    seen = in_sight(arrays, p, lm)
    if math.isfinite(max_range):
        seen &= np.einsum("rlk,rlk->rl", d, d) <= max_range**2
    theta = np.linspace(-math.pi, math.pi, headings, endpoint=False)
    angle = np.arctan2(d[..., 1], d[..., 0])
    in_view = np.abs(bearing.wrap(angle[:, None, :] - theta[None, :, None])) <= 0.5 * fov + 1e-12
    return in_view & seen[:, None, :]


def error_ball_pace(arrays: PlanArrays, s: ControlSettings, cell: np.ndarray, x_hat: np.ndarray,
                    error_bound: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """How fast each robot may drive without its error ball reaching an obstacle, and which way is away.

    The true position lies within ``e`` (the estimate's error bound, 3σ) of ``x̂``, and a step at
    the fraction ``p`` of full speed moves it by at most ``p·ℓ`` with ``ℓ = v·dt·(1 + odometry_drift)``
    (``v`` = ``v_ref``, or ``α`` for the unicycle). So with ``k`` the clearance of ``x̂`` from the
    inflated obstacles and the walls, every position the robot can be in during a step at
    ``p = clip((k − e)/ℓ, 0, 1)`` is free, whichever way it drives. ``p = 0``: the robot waits for
    fixes that shrink ``e`` (standing still adds no odometry error); a slower robot also drifts
    less, so its filter settles to a smaller ``e``. A step the certificate covers (``e ≤ δ*`` on a
    funnel plan, ALGORITHMS §11.4) is taken at full speed as it is, and so is every step on a
    paper plan (which runs as the papers ran it). The cheap bound first: the slack of ``x̂`` in its
    own funnel cell (cells are free, C1); the exact distance
    (:func:`~bearnav_cli.runtime.cell_policy.obstacle_clearance`) only where that bound slows it.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: cells, ``usable_tolerance`` (τ_c), obstacle edges and ``B_r``.
    s : ControlSettings
        ``top_speed`` (map units / s), ``dt`` (s) and ``odometry_drift``.
    cell : ndarray of int, shape (R,)
        Each robot's active cell (``-1`` for none).
    x_hat : ndarray, shape (R, 2)
        Position estimates (map units).
    error_bound : ndarray, shape (R,)
        Their error bounds ``e`` (map units; ``inf`` before the first fix: pace 0).

    Returns
    -------
    pace : ndarray, shape (R,)
        The fraction of full speed allowed, in ``[0, 1]``.
    away : ndarray, shape (R, 2)
        Where the pace is below 1: the unit direction away from the nearest obstacle piece
        (:func:`~bearnav_cli.runtime.cell_policy.obstacle_clearance`); zero elsewhere.
    """
    e = np.asarray(error_bound, float).reshape(-1)
    away = np.zeros((len(e), 2))
    if not arrays.funnel:  # paper plans run as the papers ran them
        return np.ones(len(e)), away
    pace = np.where(e <= arrays.tolerance_in(cell) + s.tol, 1.0, 0.0)
    step = s.top_speed * s.dt * (1.0 + s.odometry_drift)
    todo = (pace < 1.0) & np.isfinite(e)
    cell = np.asarray(cell, np.int64).reshape(-1)
    quick = todo & (cell >= 0)
    if quick.any():
        idx = np.flatnonzero(quick)
        pace[idx] = np.clip((cell_slack(arrays, cell[idx], x_hat[idx]) - e[idx]) / step, 0.0, 1.0)
        todo[idx[pace[idx] >= 1.0]] = False
    if todo.any():
        idx = np.flatnonzero(todo)
        clearance, away[idx] = obstacle_clearance(arrays, x_hat[idx])
        pace[idx] = np.maximum(pace[idx], np.clip((clearance - e[idx]) / step, 0.0, 1.0))
        away[idx[pace[idx] >= 1.0]] = 0.0
    return pace, away


def steer_clear(u: np.ndarray, pace: np.ndarray, away: np.ndarray) -> np.ndarray:
    """The unit command bent away from the nearest obstacle as the pace drops, shape (R, 2).

    ``u − (1 − p)·min(u·a, 0)·a + (1 − p)·a``, normalised: at full pace (``p = 1``) the command
    is ``u``; below, its component toward the obstacle fades and a push along ``away`` grows, so a
    robot slowed by its error ball (:func:`error_ball_pace`) also gains clearance, and its pace
    recovers, instead of creeping along the obstacle. At ``p = 0`` the push dominates. Rows with
    no command (``u = 0``) or no ``away`` stay as they are.

    Parameters
    ----------
    u : ndarray, shape (R, 2)
        Unit commands (zero rows: none).
    pace : ndarray, shape (R,)
        Allowed fraction of full speed, in ``[0, 1]``.
    away : ndarray, shape (R, 2)
        Unit directions away from the nearest obstacle piece (zero rows: no push).
    """
    w = (1.0 - np.asarray(pace, float))[:, None]
    toward = np.minimum(np.einsum("rk,rk->r", u, away), 0.0)[:, None]
    bent = u - w * toward * away + w * away
    norm = np.hypot(bent[:, 0], bent[:, 1])
    ok = (w[:, 0] > 0) & (norm > 0) & np.any(u != 0.0, axis=1) & np.any(away != 0.0, axis=1)
    out = u.copy()
    out[ok] = bent[ok] / norm[ok, None]
    return out


def carry_inside(arrays: PlanArrays, s: ControlSettings, state: ControlState, est: Estimate) -> Estimate:
    """Odometry also carries a robot that lost its fix while its whole error ball lies in one funnel cell.

    :func:`~bearnav_cli.runtime.estimate.fuse` stops blind travel once the estimate's 3σ exceeds
    ``blind_error`` (after ``hold_time``). A robot in the middle of a large cell may still drive on:
    where some cell eroded by the error bound holds ``x̂`` (``least_rank_cell`` with that erosion),
    the true position lies (within 3σ) in that cell, which is free (C1). Robots approaching a node
    and plans that are not funnels are left to ``fuse``'s rule.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: only a funnel plan's cells (``arrays.funnel``) let a robot drive on this way.
    s : ControlSettings
        Only with ``s.odometry`` on (without it there is no estimate between fixes).
    state : ControlState
        The previous step's state: the robot must be following a cell (``cell >= 0``), not
        approaching a node (``target == -1``).
    est : Estimate
        This step's estimate from :func:`~bearnav_cli.runtime.estimate.fuse`, with a finite
        ``error_bound`` (map units).

    Returns
    -------
    Estimate
        ``est`` with ``steer`` also set for the robots whose eroded cell holds ``x̂``.
    """
    wait = ~est.steer & est.known & s.odometry & (state.cell >= 0) & (state.target < 0) & np.isfinite(est.error_bound)
    if not arrays.funnel or not wait.any():
        return est
    idx = np.flatnonzero(wait)
    inside = least_rank_cell(arrays, est.x_hat[idx], est.error_bound[idx]) >= 0
    if not inside.any():
        return est
    steer = est.steer.copy()
    steer[idx[inside]] = True
    return dataclasses.replace(est, steer=steer)


def follow_fields(arrays: PlanArrays, s: ControlSettings, state: ControlState, est: Estimate, bearings: np.ndarray,
                  visible: np.ndarray, displacements: np.ndarray | None = None,
                  keep: np.ndarray | None = None) -> tuple[np.ndarray, ...]:  # fmt: skip
    """The cell policy and the unit command of every robot that has an estimate (ALGORITHMS §7.2, §11.3).

    The policy is :func:`~bearnav_cli.runtime.cell_policy.update` (funnel cells eroded by the
    estimate's error bound, capped at δ*); the output ``ỹ`` is rebuilt for the cell's fixed
    landmark and ``ũ = gain[c] @ ỹ``, or ``x_n − x̂`` while approaching node ``n``.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's run-time arrays: cells, gains, fixed landmarks and tree nodes.
    s : ControlSettings
        ``eps_sw`` and ``tol`` (map units) of the cell policy, ``measurement`` and
        ``reconstruction`` (how ``ỹ`` is built), ``min_spread`` (rad) and ``bearing_sigma``.
    state : ControlState
        The previous step's ``cell``, ``target`` and ``last_dir``.
    est : Estimate
        This step's estimate: only the robots with ``steer`` get a command, at ``x_hat``; its
        ``error_bound`` (capped at the plan's δ*) erodes a funnel plan's cells.
    bearings : ndarray, shape (R, L, 2)
        World-frame unit bearings, for the ``pair`` and ``rescale`` reconstructions of ``ỹ``.
    visible : ndarray of bool, shape (R, L)
        Which landmarks each robot sees.
    displacements : ndarray, shape (R, L, 2), optional
        Displacement mode in a world that differs from the plan's: the measured ``l_k − x``
        (map units), used as the output as they are; default ``l_k − x̂``.
    keep : ndarray, shape (R,), optional
        A robot keeps its cell while ``x̂`` lies in it grown by this (map units; negative: eroded);
        default the set estimator's error bound (``cell_policy.update``), or ``tol``.

    Returns
    -------
    cell, target : ndarray of int64, shape (R,)
    last_dir, u : ndarray, shape (R, 2)
        The last command's direction (updated where a command was made) and this step's unit
        command (zero for robots without an estimate).
    stalled, relocated : ndarray of bool, shape (R,)
    """
    r = len(state.cell)
    x_hat, fix = est.x_hat, est.fix
    cell, target, last_dir = state.cell.copy(), state.target.copy(), state.last_dir.copy()
    relocated = np.zeros(r, bool)
    stalled = np.zeros(r, bool)
    u = np.zeros((r, 2))
    if not est.steer.any():
        return cell, target, last_dir, u, stalled, relocated
    idx = np.flatnonzero(est.steer)
    # the filter's 3σ is capped at δ* (beyond it nothing is certified anyway); a set's e_t is a bound
    erosion = None
    if arrays.funnel:
        erosion = est.error_bound[idx] if s.estimator == "set" else np.minimum(est.error_bound[idx],
                                                                                arrays.plan_tolerance)  # fmt: skip
    # a bounded estimate of a robot its cell's certificate keeps inside may stray up to e outside it
    if keep is not None:
        keep = np.asarray(keep, float)[idx]
    elif arrays.funnel and s.estimator == "set":
        keep = est.error_bound[idx]
    c, t, moved = update(arrays, cell[idx], target[idx], x_hat[idx], s.eps_sw, s.tol, erosion, keep)
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
    # outside every cell with no node in straight sight: no field applies (index -1 would pick the
    # last cell's), so no command: the robot waits for an estimate that lands in a cell
    nowhere = (c < 0) & (t < 0)
    ui[nowhere] = 0.0
    going = t >= 0
    ui[going] = arrays.nodes[t[going]] - x_hat[idx[going]]
    stalled[idx[going]] = False
    norm = np.hypot(ui[:, 0], ui[:, 1])
    stalled[idx[~(norm > 0)]] = True
    if s.measurement != "displacement" and s.bearing_sigma > 0:
        stalled[idx[nowhere]] = False  # a noisy estimate off every cell may land in one at the next fix
    ok = norm > 0
    u[idx[ok]] = ui[ok] / norm[ok, None]
    last_dir[idx[ok]] = u[idx[ok]]
    return cell, target, last_dir, u, stalled, relocated


def look_around(s: ControlSettings, state: ControlState, est: Estimate, last_dir: np.ndarray,
                heading: np.ndarray, arrays: PlanArrays | None = None) -> tuple[np.ndarray, ...]:  # fmt: skip
    """Who looks around in place, who is lost, and how they turn (ALGORITHMS §7.5 with docs/choices.md).

    With odometry, a robot without an estimate never moves blind: it looks around at once, for
    one revolution at ``β``, then it is lost; without odometry §7.5's hold comes first. A
    look-around starts toward the last command and keeps its direction. Looking on purpose
    (``s.look_on_purpose``, a camera narrower than 2π and ``arrays`` given), it first turns by the
    shorter way to :func:`best_view_heading` at its estimate and stops there; if no fix comes, the
    revolution follows from there (lost after ``3π/β`` in all: half a turn, then a whole one).

    Parameters
    ----------
    s : ControlSettings
        ``odometry``, ``hold_time`` (s), ``beta`` (rad / s), ``dt`` (s), ``look_on_purpose`` and
        ``fov`` (rad).
    state : ControlState
        The previous step's ``known``, ``scanning``, ``scan_from``, ``spin`` and ``look``.
    est : Estimate
        This step's estimate: the robots without ``steer`` look around; ``hold`` (s) is their clock.
    last_dir : ndarray, shape (R, 2)
        Unit direction of the last command (after :func:`follow_fields`): a look-around starts
        turning toward it.
    heading : ndarray, shape (R,)
        The camera's heading ``φ`` (rad).
    arrays : PlanArrays, optional
        The plan, to look on purpose (:func:`best_view_heading`); ``None``: the revolution at once.

    Returns
    -------
    scanning, lost : ndarray of bool, shape (R,)
    spin : ndarray, shape (R,)
        ``±1``, the direction of each look-around.
    turn : ndarray, shape (R,)
        The turn rate of the robots looking around (rad / s; 0 for the others).
    look : ndarray, shape (R,)
        The heading each look on purpose turns to (rad; NaN for none).
    """
    holding = ~est.steer
    if s.odometry:
        scanning = holding
        # a look-around's clock starts with it: odometry may have carried the robot blind for longer
        # than hold_time (while its error bound stayed within blind_error)
        begun = np.where(state.scanning, state.scan_from, est.hold - s.dt)
        scan_time = est.hold - np.where(state.known, begun, 0.0)
    else:
        scanning = holding & (est.hold > s.hold_time)
        scan_time = est.hold - s.hold_time
    # the set estimator always looks on purpose: toward the least one-look bound (ALGORITHMS §12.5)
    bounded = s.estimator == "set"
    purposeful = (s.look_on_purpose or bounded) and arrays is not None and s.fov < 2.0 * math.pi
    budget = (3.0 if purposeful else 2.0) * math.pi / s.beta
    lost = scanning & (scan_time > budget)
    phi = np.asarray(heading, float).reshape(len(holding))
    # a scan that always turned one way undid the unicycle's turn toward its field
    toward = bearing.wrap(np.arctan2(last_dir[:, 1], last_dir[:, 0]) - phi)
    starting = scanning & ~state.scanning  # a scan keeps the direction it started with
    spin = np.where(starting, np.where(toward < 0, -1.0, 1.0), state.spin)
    look = np.where(scanning & ~starting, state.look, np.nan)
    if purposeful and starting.any() and np.all(np.isfinite(est.x_hat[starting])):
        idx = np.flatnonzero(starting)
        want = np.arctan2(last_dir[idx, 1], last_dir[idx, 0])  # where the robot was driving
        aim = best_bound_heading if bounded else best_view_heading
        look[idx] = aim(arrays, s, est.x_hat[idx], phi[idx] if bounded else want)
    turn = np.where(scanning, spin * s.beta, 0.0)
    aiming = scanning & np.isfinite(look)
    if aiming.any():
        error = bearing.wrap(look[aiming] - phi[aiming])
        # turn the shorter way and stop on the heading (no overshoot within one step)
        turn[aiming] = np.clip(error / s.dt, -s.beta, s.beta)
        spin[aiming] = np.where(error < 0, -1.0, 1.0)
        arrived = np.abs(error) <= s.beta * s.dt * 1e-6 + 1e-12
        done = np.flatnonzero(aiming)[arrived]
        look[done] = np.nan  # reached without a fix: the revolution follows, in the same direction
    return scanning, lost, spin, turn, look


def best_view_heading(arrays: PlanArrays, s: ControlSettings, x: np.ndarray, phi: np.ndarray,
                      headings: int = 72) -> np.ndarray:  # fmt: skip
    """The camera heading at ``x`` from which the map promises the best fix, shape (R,) rad; NaN if none.

    Among ``headings`` evenly spaced headings, those where at least two landmarks are in the field
    of view, in range and in line of sight (``cell_policy.in_sight``) and spread enough for the
    ``lsq`` fix (``λ_min(Σ P_k) ≥ 1 − cos θ_min``, as :func:`bearing.reconstruct` requires); of
    those, the one nearest to ``phi`` (the direction the robot was driving: a fix there lasts when
    it drives on), ties to the largest ``λ_min(Σ P_k / d_k²)`` (the smallest predicted fix
    variance, :func:`bearing.fix_variance`).

    Parameters
    ----------
    arrays : PlanArrays
        The plan's landmarks (L, 2) and the raw obstacle edges that hide them.
    s : ControlSettings
        The camera's ``fov`` (rad) and ``max_range`` (map units), and ``min_spread`` (rad).
    x : ndarray, shape (R, 2)
        Where each robot looks from: its position estimate (map units).
    phi : ndarray, shape (R,)
        The direction each robot was driving (rad): the heading preferred among the usable ones.
    headings : int
        How many evenly spaced candidate headings over ``[−π, π)`` are tried.
    """
    p = np.asarray(x, float).reshape(-1, 2)
    phi = np.asarray(phi, float).reshape(len(p))
    lm = arrays.landmarks
    d = lm[None] - p[:, None, :]  # (R, L, 2)
    dist2 = np.maximum(np.einsum("rlk,rlk->rl", d, d), arrays.tol**2)
    beta = d / np.sqrt(dist2)[..., None]
    seen = in_sight(arrays, p)
    if math.isfinite(s.max_range):
        seen &= dist2 <= s.max_range**2
    theta = np.linspace(-math.pi, math.pi, headings, endpoint=False)
    angle = np.arctan2(d[..., 1], d[..., 0])  # (R, L)
    in_view = np.abs(bearing.wrap(angle[:, None, :] - theta[None, :, None])) <= 0.5 * s.fov  # (R, H, L)
    vis = in_view & seen[:, None, :]
    bx, by = beta[..., 0][:, None, :], beta[..., 1][:, None, :]

    def lam(weight: np.ndarray) -> np.ndarray:
        a11 = np.sum(weight * (1.0 - bx * bx), axis=2)
        a22 = np.sum(weight * (1.0 - by * by), axis=2)
        a12 = -np.sum(weight * bx * by, axis=2)
        return 0.5 * (a11 + a22) - np.hypot(0.5 * (a11 - a22), a12)

    usable = (vis.sum(axis=2) >= 2) & (lam(vis.astype(float)) >= 1.0 - math.cos(s.min_spread))
    score = np.where(usable, lam(np.where(vis, 1.0 / dist2[:, None, :], 0.0)), -np.inf)
    turn = np.abs(bearing.wrap(theta[None, :] - phi[:, None]))
    turn = np.where(usable, turn, np.inf)
    best = np.lexsort((-score, turn), axis=1)[:, 0] if score.size else np.zeros(len(p), np.int64)
    out = theta[best]
    out[~usable.any(axis=1)] = np.nan
    return out


def unicycle_command(s: ControlSettings, direction: np.ndarray, heading: np.ndarray, holding: np.ndarray,
                     scanning: np.ndarray, target: np.ndarray, turn: np.ndarray,
                     allowed: np.ndarray | None = None) -> tuple[np.ndarray, ...]:  # fmt: skip
    """``(v, ω)`` of the unicycle toward the unit command ``direction`` (ALGORITHMS §7.1).

    §7.1's ``v = α cos e``; ``turn_first`` uses ``α cos³ e``: a unicycle far off its field slows
    down to turn instead of sweeping a wide arc past an obstacle corner. Holding or looking
    around, it turns in place; a straight approach drives only when aligned within
    ``APPROACH_ALIGNMENT``. ``allowed`` (R,), from :func:`heading_allowance`: where it is below
    π the robot drives forward (never back) only while ``|e| < allowed``, else turns in place.

    Parameters
    ----------
    s : ControlSettings
        The gains ``alpha`` (map units / s) and ``beta`` (rad / s), ``turn_first`` and
        ``clamp_reverse``.
    direction : ndarray, shape (R, 2)
        The unit command (``u``, or ``last_dir`` while holding); a zero row is no command.
    heading : ndarray, shape (R,)
        The unicycle's yaw ``φ`` (rad); ``e`` is the angle from it to ``direction``.
    holding : ndarray of bool, shape (R,)
        No position estimate this step: no forward motion, only the turn toward ``direction``.
    scanning : ndarray of bool, shape (R,)
        Looking around in place: no forward motion, and ``turn`` as given.
    target : ndarray of int, shape (R,)
        Approached node (``-1`` for none): a straight approach drives only within
        ``APPROACH_ALIGNMENT`` of ``direction``.
    turn : ndarray, shape (R,)
        The look-around turn rate of :func:`look_around` (rad / s), used where ``scanning``.
    allowed : ndarray, shape (R,), optional
        The heading allowance (rad) of :func:`heading_allowance`; ``None``: §7.1's rule alone.

    Returns
    -------
    forward, turn : ndarray, shape (R,)
        ``v`` (map units / s) and ``ω`` (rad / s).
    motion : ndarray, shape (R, 2)
        The world-frame velocity odometry integrates.
    """
    phi = np.asarray(heading, float).reshape(len(direction))
    e = bearing.wrap(np.arctan2(direction[:, 1], direction[:, 0]) - phi)
    e[~np.any(direction != 0.0, axis=1)] = 0.0  # no command: neither turn nor drive for it
    gain = np.cos(e) ** 3 if s.turn_first else np.cos(e)
    idle = ~np.any(direction != 0.0, axis=1) & ~holding & ~scanning
    forward = np.where(holding | scanning | idle, 0.0, s.alpha * gain)
    forward[(target >= 0) & (np.abs(e) > APPROACH_ALIGNMENT)] = 0.0
    if s.clamp_reverse:
        forward = np.maximum(forward, 0.0)
    if allowed is not None:
        bound = allowed < math.pi
        forward[bound] = np.where(np.abs(e[bound]) < allowed[bound], np.maximum(forward[bound], 0.0), 0.0)
    turn = np.where(scanning, turn, s.beta * np.sin(e))
    return forward, turn, forward[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])


def heading_allowance(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The largest heading error at which a unicycle may drive forward and stay certified, shape (R,), rad.

    The cell's field ``u`` meets at ``x`` its barrier conditions ``n_k·u + c_h h_k ≥ μ_k`` and its
    progress condition ``−(z·u + c_v V) ≥ μ_v`` with pointwise margins ``μ`` (positive on a
    certified cell, ALGORITHMS §11.2). Driving at any speed ``v > 0`` along a heading ``e`` instead
    of ``d = u/‖u‖`` changes each left side, scaled by ``λ = v/‖u‖``, by at most ``v‖e − d‖``
    (unit normals); so while ``‖e − d‖ = 2 sin(|Δ|/2) < min μ / ‖u‖`` the velocity still meets
    ``ḣ_k ≥ −λ c_h h_k`` and ``V̇ ≤ −λ(c_v V + ε)`` with ``ε > 0``: the robot stays in the cell's safe
    set and keeps progressing to its exit, as the single integrator does (a positive time scaling
    of the certified field). Turning in place (``v = 0``) keeps every ``h`` and ``V``.

    Returns ``π`` (no bound) for robots outside a funnel plan's cells, approaching a node, or where
    a margin is not positive at ``x`` (an estimate off its cell: the certificate says nothing there).

    Parameters
    ----------
    arrays : PlanArrays
        The plan: each cell's affine field, barrier rows, ``c_h``, ``c_v`` and exit (funnel plans).
    cell : ndarray of int, shape (R,)
        Active cell of each robot (``-1`` for none).
    x : ndarray, shape (R, 2)
        The position estimate ``x̂`` the field is evaluated at (map units).
    target : ndarray of int, shape (R,)
        Approached node (``-1`` for none): an approaching robot has no bound.
    """
    p = np.asarray(x, float).reshape(-1, 2)
    cell = np.asarray(cell, np.int64)
    out = np.full(len(p), math.pi)
    on = (cell >= 0) & (np.asarray(target) < 0)
    if not arrays.funnel or not on.any():
        return out
    idx = np.flatnonzero(on)
    c, q = cell[idx], p[idx]
    u = affine_field(arrays, c, q)
    speed = np.hypot(u[:, 0], u[:, 1])
    A, b = arrays.bar_A[c], arrays.bar_b[c]  # padding rows: 0·x + inf
    h = np.einsum("rqi,ri->rq", A, q) + b
    with np.errstate(invalid="ignore"):
        margins = np.einsum("rqi,ri->rq", A, u) + arrays.c_h[c][:, None] * h
    margin = np.min(np.where(np.isfinite(b), margins, math.inf), axis=1, initial=math.inf)
    z, x_j = arrays.exit_dir[c], arrays.exit_point[c]
    edge = arrays.parent_cell[c] >= 0  # the goal cell has no progress condition
    progress = -(np.einsum("ri,ri->r", z, u) + arrays.c_v[c] * np.einsum("ri,ri->r", z, q - x_j))
    margin = np.where(edge, np.minimum(margin, progress), margin)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(speed > 0, margin / speed, -1.0)
    bounded = (ratio > 0) & (ratio < 2.0)  # ‖e − d‖ ≤ 2 always: ratio ≥ 2 allows any heading
    out[idx[bounded]] = 2.0 * np.arcsin(0.5 * ratio[bounded])
    return out


#: ``dt = min(DT_PER_DIAGONAL · D / v, DT_MAX)`` by default (ALGORITHMS §7.1).
DT_PER_DIAGONAL = 0.0025
DT_MAX = 0.2
#: Blind travel on odometry lasts while 3σ stays below this fraction of D (the default barrier margin).
BLIND_ERROR_PER_DIAGONAL = 0.01


def timing(diagonal: float, speed: float, dt: float | None = None) -> tuple[float, float, float]:
    """The loop constants of a map of diagonal ``D`` driven at ``speed`` (``α`` for the unicycle).

    Parameters
    ----------
    diagonal : float
        ``D``, the diagonal of the map's bounds (map units).
    speed : float
        ``v``: ``v_ref`` of the single integrator, or ``α`` of the unicycle (map units / s).
    dt : float, optional
        The control period (s) when the caller fixes it; ``None``: ``min(0.0025·D/speed, 0.2)``.

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
