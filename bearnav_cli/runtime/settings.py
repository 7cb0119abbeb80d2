"""The control step's constants, memory and output, for ``R`` robots (ALGORITHMS §7, §12).

Numpy only. :class:`ControlSettings` (the loop's constants, grouped by the rules that read them:
:class:`LoopSettings`, :class:`UnicycleSettings`, :class:`FixSettings`, :class:`LookSettings` and
:class:`ErrorBounds`), :class:`ControlState` (what a controller remembers between steps),
:class:`ControlOutput` (one step's result) and :func:`timing` (the default period of a map). The
step itself is :func:`bearnav_cli.runtime.step.control`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from bearnav_cli.runtime import bearing
from bearnav_cli.runtime.bounded import MAX_VERTICES
from bearnav_cli.runtime.defaults import ALPHA, BEARING_SIGMA, LOOP_DEFAULTS, ODOMETRY_DRIFT, SPEED
from bearnav_cli.runtime.robot import ROBOT_DEFAULTS

__all__ = [
    "BLIND_ERROR_PER_DIAGONAL",
    "DT_MAX",
    "DT_PER_DIAGONAL",
    "SLIP_FLOOR_PER_DIAGONAL",
    "ControlOutput",
    "ControlSettings",
    "ControlState",
    "ErrorBounds",
    "FixSettings",
    "LookSettings",
    "LoopSettings",
    "UnicycleSettings",
    "timing",
]

#: ``ν = SLIP_FLOOR_PER_DIAGONAL · D``, the odometry bound's floor per step (ALGORITHMS §12.1).
SLIP_FLOOR_PER_DIAGONAL = 1e-4
#: ``dt = min(DT_PER_DIAGONAL · D / v, DT_MAX)`` by default (ALGORITHMS §7.1).
DT_PER_DIAGONAL = 0.0025
DT_MAX = 0.2
#: Blind travel on odometry lasts while 3σ stays below this fraction of D (the default barrier margin).
BLIND_ERROR_PER_DIAGONAL = 0.01


@dataclass(frozen=True)
class LoopSettings:
    """The loop itself: its period, radii, and which model and rules the step runs.

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
        ``p = x + λh(θ)`` as a single integrator at ``α`` (ALGORITHMS §12.6,
        :func:`~bearnav_cli.runtime.step.control`).
    measurement : {"bearing", "displacement"}
        ``bearing``: reconstruct ``ỹ`` and ``x̂`` from bearings (§6); ``displacement``: the
        true displacements, ``x̂ = x`` (paper B).
    estimator : {"set", "kalman"}
        ``set``: the bounded-error sets of ALGORITHMS §12.2 and the certified policy of §12.3 — drive
        only while ``e_t + κℓ + ν`` is within what the cell tolerates at the set (at least ``τ_c``), else
        stop and look (§12.5,
        :func:`~bearnav_cli.runtime.step.bounded_control`), the default; ``kalman``: the scalar filter
        of :func:`~bearnav_cli.runtime.estimate.fuse` with the pace rule (docs/runtime.md).
    keep_clear : bool
        A step the certificate does not cover (error bound above ``δ*``) is slowed so that the
        error ball, grown by the step, stays off the obstacles
        (:func:`~bearnav_cli.runtime.safety.error_ball_pace`), and bent away from the nearest one as
        it slows (:func:`~bearnav_cli.runtime.safety.steer_clear`); a robot that cannot move at all
        waits in place for fixes that shrink the ball (turning to look when it has none). Off:
        every step at full speed. (Only the ``kalman`` estimator, and starts outside ``D``.)
    """

    speed: float
    dt: float
    eps_sw: float
    tol: float
    dynamics: str = LOOP_DEFAULTS["dynamics"]
    measurement: str = LOOP_DEFAULTS["measurement"]
    estimator: str = LOOP_DEFAULTS["estimator"]
    keep_clear: bool = LOOP_DEFAULTS["keep_clear"]


@dataclass(frozen=True)
class UnicycleSettings:
    """The unicycle's gains and heading rules (:mod:`bearnav_cli.runtime.unicycle`); ``beta`` is also the
    rate at which any robot turns to look around.

    Attributes
    ----------
    alpha, beta : float
        Unicycle gains: ``v = α cos e`` (map units / s), ``ω = β sin e`` (rad / s).
    clamp_reverse : bool
        Unicycle: clamp ``v`` at 0 (never reverse); on a look-ahead plan those steps are not certified.
    turn_first : bool
        Unicycle: ``v = α cos³ e`` (slow down to turn) instead of §7.1's ``α cos e``.
    certified_heading : bool
        Unicycle on a funnel plan without a look-ahead: drive forward only while the heading error
        keeps the velocity inside every condition the cell's field meets at ``x̂``
        (:func:`~bearnav_cli.runtime.unicycle.heading_allowance`), turn in place otherwise; off:
        §7.1's rule alone. (The look-ahead law replaces it.)
    """

    alpha: float = LOOP_DEFAULTS["alpha"]
    beta: float = LOOP_DEFAULTS["beta"]
    clamp_reverse: bool = LOOP_DEFAULTS["clamp_reverse"]
    turn_first: bool = LOOP_DEFAULTS["turn_first"]
    certified_heading: bool = LOOP_DEFAULTS["certified_heading"]


@dataclass(frozen=True)
class FixSettings:
    """The fix from bearings and the scalar filter that carries it on odometry (:mod:`bearnav_cli.runtime.estimate`).

    Attributes
    ----------
    reconstruction : {"lsq", "pair", "rescale"}
        How the field's output ``ỹ`` is rebuilt from bearings (§6.2–6.4): ``lsq`` takes it at ``x̂``,
        ``(l_k − x̂)/‖l_f − x̂‖``; ``pair`` and ``rescale`` reconstruct it from the bearings when every
        robot that steers has a fix this step (from ``x̂`` otherwise, and where theirs is not usable).
        ``x̂`` itself always comes from ``lsq``.
    min_spread : float
        ``θ_min`` of §6.2 (radians).
    bearing_sigma : float
        Bearing noise (1σ, radians) the filter assumes, :data:`BEARING_SIGMA` (1°) by default: a
        filter that assumes exact bearings (0) trusts odometry over every noisy fix.
    max_fix_error : float
        Use a fix only if its predicted 3σ error is at most this (map units).
    odometry : bool
        Between fixes, carry ``x̂`` forward with the commanded motion and keep following the
        fields (for at most ``hold_time``); off: the hold policy of §7.5 as written.
    odometry_drift : float
        Standard deviation of the odometry's position error per unit travelled: the filter's
        process noise (:func:`~bearnav_cli.runtime.estimate.fuse`).
    hold_time : float
        Seconds without a usable reconstruction before the robot stops to look around; it
        is ``lost`` after one more revolution, ``2π/β`` (§7.5).
    blind_error : float
        Without a fix, the robot keeps following the fields on odometry beyond ``hold_time``
        while its estimate's 3σ stays below this (map units; the barrier margin in
        ``bearnav simulate``); 0: ``hold_time`` only.
    """

    reconstruction: str = LOOP_DEFAULTS["reconstruction"]
    min_spread: float = bearing.DEFAULT_MIN_SPREAD
    bearing_sigma: float = BEARING_SIGMA
    max_fix_error: float = math.inf
    odometry: bool = LOOP_DEFAULTS["odometry"]
    odometry_drift: float = ODOMETRY_DRIFT
    hold_time: float = LOOP_DEFAULTS["hold_time"]
    blind_error: float = 0.0


@dataclass(frozen=True)
class LookSettings:
    """The camera a robot turns to look with (:mod:`bearnav_cli.runtime.looking`).

    Attributes
    ----------
    fov, max_range : float
        The camera's full field of view (radians) and range (map units), for looking on purpose.
    look_on_purpose : bool
        A robot that lost its fix first turns toward the nearest heading where the map says a
        usable pair of tags is in view from its estimate
        (:func:`~bearnav_cli.runtime.looking.best_view_heading`), then, if that gives no fix, looks
        all around; off (the default: it did not do better, docs/choices.md) or a camera that sees
        all around: the revolution at once. The set estimator always looks on purpose.
    """

    fov: float = 2.0 * math.pi
    max_range: float = math.inf
    look_on_purpose: bool = LOOP_DEFAULTS["look_on_purpose"]


@dataclass(frozen=True)
class ErrorBounds:
    """The bounds the set estimator assumes (ALGORITHMS §12.1; :func:`~bearnav_cli.runtime.estimate.bounded_update`).

    Attributes
    ----------
    bearing_bound : float
        ``η`` (rad): the bound on every world-frame bearing error the set estimator assumes
        (``η_cam + ψ``, ALGORITHMS §12.1).
    heading_bound : float
        ``ψ`` (rad): the bound on the heading error; a look-ahead point ``λ`` ahead errs by at most
        ``2λ sin(ψ/2)`` more than the axle.
    slip : float
        ``κ``: odometry errs by at most ``κ‖d̂‖ + ν`` over a step that translates by ``d̂``.
    slip_floor : float
        ``ν`` (map units), ``1e-4·D`` from :meth:`ControlSettings.for_plan`.
    """

    bearing_bound: float = math.radians(ROBOT_DEFAULTS["bearing_error_deg"])
    heading_bound: float = 0.0
    slip: float = ROBOT_DEFAULTS["slip"]
    slip_floor: float = 0.0

    @property
    def drift(self) -> float:
        """``κ + 2 sin(ψ/2)``: a step commanded (and its displacement measured) in the world frame through a heading
        that errs by up to ``ψ`` is turned by up to ``ψ``, which moves its end by ``2 sin(ψ/2)`` of its length on
        top of the slip; the odometry bound of a step ``d̂`` is ``drift·‖d̂‖ + ν``."""
        return self.slip + 2.0 * math.sin(0.5 * self.heading_bound)


# the fields of the groups, in this order: LoopSettings first (its four fields without defaults lead)
@dataclass(frozen=True)
class ControlSettings(ErrorBounds, LookSettings, FixSettings, UnicycleSettings, LoopSettings):
    """Constants of the control step shared by :class:`Controller` and ``bearnav simulate`` (ALGORITHMS §7).

    One flat set of fields (``settings.alpha``, ``ControlSettings(speed=..., keep_clear=False)``,
    ``Controller.from_plan(..., hold_time=...)``), grouped by the rules that read them; each group's
    docstring documents its fields.

    Attributes
    ----------
    speed, dt, eps_sw, tol, dynamics, measurement, estimator, keep_clear
        The loop: :class:`LoopSettings`.
    alpha, beta, clamp_reverse, turn_first, certified_heading
        The unicycle: :class:`UnicycleSettings`.
    reconstruction, min_spread, bearing_sigma, max_fix_error, odometry, odometry_drift, hold_time, blind_error
        The fix and the filter: :class:`FixSettings`.
    fov, max_range, look_on_purpose
        Looking: :class:`LookSettings`.
    bearing_bound, heading_bound, slip, slip_floor
        The set estimator's bounds: :class:`ErrorBounds`.
    """

    @property
    def top_speed(self) -> float:
        """The robot's full speed (map units / s): ``v_ref`` of the single integrator, or ``α`` of the unicycle."""
        return self.alpha if self.dynamics == "unicycle" else self.speed

    @classmethod
    def for_plan(
        cls,
        diagonal: float,
        tol: float,
        *,
        dynamics: str = "single",
        speed: float = SPEED,
        alpha: float = ALPHA,
        dt: float | None = None,
        bearing_sigma: float = BEARING_SIGMA,
        **fields: object,
    ) -> ControlSettings:
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
        return cls(speed=speed, dt=dt, tol=tol, dynamics=dynamics, alpha=alpha, bearing_sigma=bearing_sigma, **fields)  # type: ignore[arg-type]


@dataclass(eq=False)
class ControlState:
    """What a controller remembers between steps, for ``R`` robots.

    Mutable (compared by identity): :meth:`put` writes robots back into its arrays (``bearnav simulate``
    keeps one state for all its robots and writes back the ones it stepped). The step
    (:func:`~bearnav_cli.runtime.step.control`) writes into no array of the state it is given: it
    returns a new state, which may share the arrays the step left unchanged.

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
    bound_scale : ndarray, shape (R,)
        What the set estimator's bearing bound ``η`` is multiplied by: 1, until a set came out empty
        (a bound was broken) and the robot widened it (ALGORITHMS §12.2, docs/algorithms.md).
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
    bound_scale: np.ndarray

    @classmethod
    def initial(cls, heading: np.ndarray) -> ControlState:
        """Robots that have not had a fix yet, facing ``heading`` (rad, shape (R,))."""
        h = np.asarray(heading, float).reshape(-1)
        r = len(h)
        return cls(
            np.full(r, -1, np.int64),
            np.full(r, -1, np.int64),
            np.column_stack([np.cos(h), np.sin(h)]),
            np.zeros(r),
            np.zeros((r, 2)),
            np.zeros((r, 2)),
            np.zeros(r, bool),
            np.full(r, np.inf),
            np.zeros(r, bool),
            np.ones(r),
            np.full(r, np.nan),
            np.zeros(r),
            np.zeros((r, MAX_VERTICES, 2)),
            np.zeros(r, np.int64),
            np.full(r, np.nan),
            np.ones(r),
        )

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
