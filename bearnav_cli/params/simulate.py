"""The parameters of the closed loop (ALGORITHMS §6–§7): :class:`Params`, whose :mod:`bearnav_cli.stages.simulate`
subclass adds the check of ``starts`` and is the stage's ``Params``."""

from __future__ import annotations

from dataclasses import dataclass

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.params.declare import MAX_STEPS_PER_RUN, SEED, Range, check, param
from bearnav_cli.runtime.defaults import (
    DYNAMICS,
    ESTIMATORS,
    LOOP_DEFAULTS,
    MEASUREMENTS,
    METHODS,
    MIN_SPREAD_DEG,
)

__all__ = ["CAMERAS", "Params"]

#: The simulated cameras (:data:`bearnav_cli.world.camera.CAMERAS`).
CAMERAS = ("ideal", "render")
#: A speed or a gain: up to 1000 diagonals per second.
_SPEED = Range(0, 1e3, low_open=True, per_diagonal=True)


@dataclass(frozen=True)
class Params:
    """Parameters of the closed loop (ALGORITHMS §6–§7).

    Attributes
    ----------
    dynamics : {"single", "unicycle"}
        Single integrator ``ẋ = v_ref·unit(ũ)`` or unicycle ``v = α cos e``, ``ω = β sin e``; on a
        plan with a look-ahead λ, the unicycle's point λ ahead driven as a single integrator
        (ALGORITHMS §12.6, docs/runtime.md).
    measurement : {"bearing", "displacement"}
        What the controller is fed: bearings (reconstructed, §6) or true displacements.
    fov : float
        Camera field of view (degrees, in (0, 360]); centred on the camera heading (the
        unicycle's yaw, or the single integrator's last command direction).
    noise_deg : float
        Standard deviation of the Gaussian bearing-angle noise (degrees, >= 0).
    range : float or None
        Largest distance at which a landmark is seen (map units); ``None`` for unlimited.
    occlusion : bool
        Landmarks hidden by the raw obstacles are not seen (line of sight, ALGORITHMS §1).
    reconstruction : {"lsq", "pair", "rescale"}
        Bearing reconstruction (§6); the position estimate that picks the cell always comes from ``lsq``.
    min_spread_deg : float
        ``θ_min`` of §6.2 (degrees).
    speed : float
        Reference speed ``v_ref`` of the single integrator (map units / s).
    alpha : float
        Unicycle forward gain ``α`` (map units / s): it drives at ``v = α cos e``, ``e`` its heading
        error (ALGORITHMS §7.1).
    beta : float
        Unicycle turn gain ``β`` (rad / s): it turns at ``ω = β sin e``; also the rate at which a
        robot turns to look around (``hold_time``).
    clamp_reverse : bool
        Unicycle never drives backwards (``v >= 0``); also set by the map's ``robot: {reverse: false}``.
        On a look-ahead plan the clamped steps are not certified.
    turn_first : bool
        Unicycle forward speed ``α cos³ e`` instead of ALGORITHMS §7.1's ``α cos e``: far off its
        field it slows down to turn rather than sweep a wide arc past an obstacle corner.
    certified_heading : bool
        Unicycle on a funnel plan without a look-ahead: forward only within the heading allowance
        that keeps the velocity inside the cell's certified conditions
        (``runtime.step.heading_allowance``); the look-ahead law replaces it.
    look_on_purpose : bool
        Without a fix, first turn toward the nearest heading where the map promises a usable pair of
        tags (``runtime.step.best_view_heading``), then look all around; off (default): the
        revolution at once.
    keep_clear : bool
        On a funnel plan, a step beyond the position error the cell tolerates is slowed so that the
        estimate's error ball (3σ), grown by the step, never reaches an obstacle, and bent away
        from the nearest one as it slows; a robot that cannot
        move waits for fixes. Off: full speed on any estimate.
    initial_heading : float or None
        Initial heading (degrees); ``None``: toward the active cell's exit point (the goal
        in the goal cell).
    hold_time : float
        Seconds without a usable reconstruction before the robot stops to look around (a
        revolution at ``beta``); then the run is ``lost`` (§7.5).
    odometry : bool
        Between fixes, carry the position estimate forward with the commanded motion (wheel odometry: it errs by
        the wheel slip, ``odometry_noise``) for ``hold_time``, and on while the filter's 3σ stays
        within the barrier margin; off: the paper's hold policy as written (§7.5).
    odometry_noise : float
        Wheel slip ``σ`` of the simulated base (default 0.02): odometry alone errs by ``≈ σ·d``
        (standard deviation, along and across the path) over a straight run of length ``d`` (per run
        a scale error and a heading bias, both ``N(0, σ²)``, plus per-step jitter of the same size).
        0 is the exact motion that the certificates assume (§7.1,
        :class:`bearnav_cli.world.motion.Base`); ``verify`` runs with it.
    odometry_drift : float
        Odometry error (1σ) per unit travelled that the controller's filter assumes, its process
        noise (default 0.05 = 5% of the distance travelled). The default is
        :class:`~bearnav_cli.runtime.ControlSettings`'s. More than the slip (2σ = 4% rms per step,
        ``σ·d`` over a run), and added up linearly, as the per-run slip adds up:
        :func:`bearnav_cli.runtime.estimate.fuse` grows the
        estimate's σ by ``drift·ℓ`` per step of length ``ℓ`` (``σ ← σ + drift·ℓ``, so ``drift·d``
        after ``d`` blind), and its 3σ covers the default slip over a hold (``docs/choices.md``).
    max_fix_error : float or None
        Use a noisy fix only if its predicted 3σ position error (from ``noise_deg`` and the
        bearing geometry, :func:`bearnav_cli.runtime.bearing.fix_variance`) is at most this (map units);
        ``None``: every usable fix.
    starts : str
        ``map`` (the map's starts), ``random:N`` (N uniform free starts in the goal's
        component, seeded), ``domain:N`` (N uniform starts in the certified domain ``D``, the union
        of a funnel plan's cells, seeded) or ``x,y;x,y;...``. With a look-ahead unicycle
        (ALGORITHMS §12.6) a start is the look-ahead point's; the axle begins ``λ`` behind it.
    dt : float or None
        Euler step (s); ``None`` means ``min(0.0025·D/v, 0.2)``, ``v = speed`` or ``alpha``.
    goal_tolerance : float or None
        Success radius (map units); ``None`` takes the plan's.
    max_steps : int or None
        Step limit of every run; ``None`` means ``ceil(5·L_route/(v·dt)) + 1000`` per run, with
        ``L_route = ‖x₀ − x_n‖ + cost(n)`` and ``n`` the start's nearest tree node.
    camera : {"ideal", "render"}
        ``ideal``: exact bearings to the tags in view, with the ``fov``, ``noise_deg``, ``range`` and
        ``occlusion`` above (ALGORITHMS §6.1, :class:`bearnav_cli.world.camera.IdealCamera`);
        ``render``: camera frames drawn and the AprilTags detected in them (needs
        ``bearnav[camera]``; its figures go to the metrics under ``camera``,
        ``bearnav_cli.world.render.RenderedCamera``).
    seed : int
        Seeds the bearing noise, the wheel slip and the random starts (separate streams).
    record_trajectories : bool
        Keep every robot's trajectory (``verify`` turns this off).
    estimator : {"set", "kalman"}
        How the robot knows where it is: ``set``, a bound on its position error that holds while
        the errors stay within the robot section's bounds (ALGORITHMS §12.2–12.3): it drives only
        while the bound is within the error the cell
        tolerates, and stops to look otherwise; ``kalman``, a scalar filter of the position and its standard
        deviation, with the pace rule of ``keep_clear``.
    noise_bound_deg : float or None
        Bounded noise instead of ``noise_deg`` (degrees, in [0, 45)): every bearing error uniform
        in ``[−η, η]`` and every odometry error within ``κ‖d̂‖ + ν`` (ALGORITHMS §12.8); the set
        estimator assumes this ``η`` unless ``bearing_error_deg`` is given.
    noise_worst : bool
        Every error at its bound (``noise_bound_deg``, else the bound the robot assumes), turned
        so that the truth lies nearer to the nearest obstacle than the estimate says (bearings, and
        odometry pushed toward it).
    bearing_error_deg : float or None
        The bound on every bearing error the set estimator assumes (degrees, ``η_cam``); ``None``: the
        map's ``robot.bearing_error_deg`` (default 0.2), or ``noise_bound_deg`` when that is given.
    compass_error_deg : float or None
        The compass (heading) error bound, added to the bearing bound (degrees; ``η = η_cam + ψ``);
        ``None``: the map's.
    slip : float or None
        The odometry error bound as a fraction of each step (``κ``); ``None``: the map's ``robot.slip``
        (0.03).
    slip_floor : float or None
        The odometry error bound's floor, added on every step that translates (map units; ``ν``);
        ``None``: the map's, else ``1e-4·D``.
    """

    dynamics: str = param(LOOP_DEFAULTS["dynamics"], choices=DYNAMICS)
    measurement: str = param(LOOP_DEFAULTS["measurement"], choices=MEASUREMENTS)
    fov: float = param(360.0, range=Range(0, 360, low_open=True), unit="degrees", capped=True)
    noise_deg: float = param(0.0, range=Range(0, 180), unit="degrees")
    range: float | None = param(
        None, range=Range(0, 1e6, low_open=True, per_diagonal=True), unit="map units", option="--range"
    )
    occlusion: bool = True
    reconstruction: str = param(LOOP_DEFAULTS["reconstruction"], choices=METHODS)
    min_spread_deg: float = param(
        MIN_SPREAD_DEG, range=Range(0, 90, low_open=True), unit="degrees", option=None, capped=True
    )
    speed: float = param(LOOP_DEFAULTS["speed"], range=_SPEED, unit="map units/s")
    alpha: float = param(LOOP_DEFAULTS["alpha"], range=_SPEED, unit="map units/s")
    beta: float = param(LOOP_DEFAULTS["beta"], range=Range(0, 1e3, low_open=True), unit="rad/s")
    clamp_reverse: bool = param(LOOP_DEFAULTS["clamp_reverse"], off="--allow-reverse")
    turn_first: bool = param(LOOP_DEFAULTS["turn_first"], option=None)
    certified_heading: bool = param(LOOP_DEFAULTS["certified_heading"], option=None)
    look_on_purpose: bool = param(LOOP_DEFAULTS["look_on_purpose"], option=None)
    keep_clear: bool = LOOP_DEFAULTS["keep_clear"]
    initial_heading: float | None = param(None, range=Range(-360, 360), unit="degrees", option=None)
    hold_time: float = param(LOOP_DEFAULTS["hold_time"], range=Range(0, 1e6, low_open=True), unit="s")
    odometry: bool = LOOP_DEFAULTS["odometry"]
    max_fix_error: float | None = param(
        None, range=Range(0, 1e3, low_open=True, per_diagonal=True), unit="map units", option=None
    )
    odometry_noise: float = param(0.02, range=Range(0, 1))
    odometry_drift: float = param(LOOP_DEFAULTS["odometry_drift"], range=Range(0, 1))
    starts: str = "map"
    dt: float | None = param(None, range=Range(0, 1e3, low_open=True), unit="s")
    goal_tolerance: float | None = param(
        None, range=Range(0, 1, low_open=True, per_diagonal=True), unit="map units", option=None
    )
    max_steps: int | None = param(None, range=Range(1, MAX_STEPS_PER_RUN, integer=True), option=None)
    camera: str = param("ideal", choices=CAMERAS)
    seed: int = param(0, range=SEED)
    record_trajectories: bool = param(True, option=None)
    estimator: str = param(LOOP_DEFAULTS["estimator"], choices=ESTIMATORS)
    noise_bound_deg: float | None = param(None, range=Range(0, 45, high_open=True), unit="degrees", capped=True)
    noise_worst: bool = False
    bearing_error_deg: float | None = param(None, range=Range(0, 45, high_open=True), unit="degrees", capped=True)
    compass_error_deg: float | None = param(None, range=Range(0, 45, high_open=True), unit="degrees", capped=True)
    slip: float | None = param(None, range=Range(0))
    slip_floor: float | None = param(None, range=Range(0), unit="map units")

    def __post_init__(self) -> None:
        check(self)
        if self.noise_bound_deg is not None and self.noise_deg:
            raise InvalidParamsError(
                "give either a bound (noise_bound_deg) or a Gaussian noise_deg, not both", field="noise_bound_deg"
            )
        if self.noise_worst and self.noise_deg:
            raise InvalidParamsError(
                "the worst case is of bounded errors, not of a Gaussian noise_deg", field="noise_worst"
            )
        if (self.bearing_error_deg or 0.0) + (self.compass_error_deg or 0.0) >= 45.0:
            raise InvalidParamsError(
                "the bearing error bound (camera plus compass) must be below 45 degrees", field="bearing_error_deg"
            )
