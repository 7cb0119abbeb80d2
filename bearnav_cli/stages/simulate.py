"""``bearnav simulate``: the closed loop of ALGORITHMS §7, every robot advanced together.

Each step asks the simulated camera (:mod:`bearnav_cli.world.camera`, or ``camera="render"``) what
the robots see, hands it to :func:`bearnav_cli.runtime.control` (the very function a robot runs)
and moves the simulated bases (:mod:`bearnav_cli.world.motion`: single integrator or unicycle,
wheel slip, the exact collision test, clearance). The measurement ``displacement`` feeds the true
displacements instead (``x̂ = x``, paper B). All robots advance in lock step as arrays, in the
loop of :mod:`bearnav_cli.world.loop` (outcomes, the no-progress window, the recorded trajectories).
This module resolves the parameters, builds that loop (camera, bases, step limits), runs it into a
:class:`~bearnav_cli.datatypes.Simulation` and computes the metrics.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from bearnav_cli import runtime
from bearnav_cli.datatypes import Outcome, Simulation, replace
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.params import simulate as declared
from bearnav_cli.runtime import ControlSettings, PlanArrays
from bearnav_cli.runtime import controller as runtime_controller
from bearnav_cli.runtime import robot as runtime_robot
from bearnav_cli.runtime.defaults import BEARING_SIGMA
from bearnav_cli.world import starts as world_starts
from bearnav_cli.world.camera import Camera, IdealCamera
from bearnav_cli.world.loop import EstimateTrace, Loop, trace_estimates
from bearnav_cli.world.motion import Base, Contact, body_space, initial_headings
from bearnav_cli.world.starts import parse_starts

__all__ = [
    "PROGRESS_EVERY",
    "PROGRESS_WINDOW",
    "Params",
    "Settings",
    "VERSION",
    "check_resources",
    "estimate_trace",
    "in_domain",
    "make_camera",
    "metrics",
    "resolve_starts",
    "rollout",
    "run",
    "settings",
    "start_loop",
    "step_limit",
    "step_limits",
    "summary",
    "tree_routes",
]

VERSION = 3
log = logging.getLogger(__name__)

#: A robot must move ``2·v·dt`` net over this many steps with a fix, or it stalls (ALGORITHMS §7.2).
PROGRESS_WINDOW = 200
#: How often (in steps) ``progress`` is called.
PROGRESS_EVERY = 25


def _radians(degrees: float | None) -> float | None:
    return None if degrees is None else math.radians(degrees)


class Params(declared.Params):
    # the declaration's docstring (numpydoc, every field): this class only checks ``starts``' syntax too
    __doc__ = declared.Params.__doc__

    def __post_init__(self) -> None:
        super().__post_init__()
        parse_starts(self.starts)  # syntax only; positions are checked against the map in run()


@dataclass(frozen=True)
class Settings:
    """Concrete loop constants for one plan (the ``None`` defaults of :class:`Params` filled in).

    Attributes
    ----------
    goal_tolerance : float
        Success radius (map units).
    control : ControlSettings
        What :func:`bearnav_cli.runtime.control` is called with; ``speed``, ``dt`` and ``eps_sw``
        are read from it.
    speed : float
        The speed ``dt`` and ``eps_sw`` are scaled by: ``v_ref``, or ``α`` for the unicycle.
    dt : float
        Step (s).
    eps_sw : float
        Switching radius ``2·v·dt`` around the exit point (map units).
    """

    goal_tolerance: float
    control: ControlSettings

    @property
    def speed(self) -> float:
        return self.control.top_speed

    @property
    def dt(self) -> float:
        return self.control.dt

    @property
    def eps_sw(self) -> float:
        return self.control.eps_sw


def settings(plan, params: Params) -> Settings:
    """Resolve :class:`Params` against a plan (``dt`` from the map's diagonal, the plan's tolerance).

    The control settings come from :meth:`ControlSettings.for_plan`, the builder the robot's
    :class:`~bearnav_cli.runtime.Controller` uses; the filter assumes the bearing noise this
    simulation draws (``noise_deg``; the exact default camera's fixes are exact), and with
    ``camera="render"`` at least the Controller's default :data:`~bearnav_cli.runtime.settings.BEARING_SIGMA`.
    """
    goal_tolerance = params.goal_tolerance if params.goal_tolerance is not None else float(plan.goal_tolerance)
    sigma = math.radians(params.noise_deg)
    if params.camera == "render":
        # a detector's bearings are never exact: the filter assumes what the robot's Controller
        # does (a filter sure of its fixes rejects the slightly-off ones and gets lost: kitchen, 2 of 4)
        sigma = max(sigma, BEARING_SIGMA)
    control = ControlSettings.for_plan(
        plan.map.diagonal,
        plan.map.tol,
        dynamics=params.dynamics,
        speed=params.speed,
        alpha=params.alpha,
        dt=params.dt,
        bearing_sigma=sigma,
        beta=params.beta,
        clamp_reverse=params.clamp_reverse or not plan.map.robot["reverse"],
        turn_first=params.turn_first,
        certified_heading=params.certified_heading,
        measurement=params.measurement,
        reconstruction=params.reconstruction,
        min_spread=math.radians(params.min_spread_deg),
        hold_time=params.hold_time,
        odometry=params.odometry,
        odometry_drift=params.odometry_drift,
        max_fix_error=math.inf if params.max_fix_error is None else params.max_fix_error,
        fov=math.radians(params.fov),
        max_range=math.inf if params.range is None else float(params.range),
        look_on_purpose=params.look_on_purpose,
        keep_clear=params.keep_clear,
        **error_model(plan.map, params),
    )
    return Settings(goal_tolerance, control)


def error_model(map_, params: Params) -> dict:
    """The bounds the set estimator assumes (ALGORITHMS §12.1), as :class:`ControlSettings` fields.

    Each comes from ``params`` where given, else from the map's ``robot:`` section: ``η = η_cam + ψ``
    (``bearing_error_deg`` plus ``compass_error_deg``; a simulation with ``noise_bound_deg`` and no
    ``bearing_error_deg`` of its own assumes that bound, which is what its world draws), ``ψ``, ``κ``
    (``slip``) and ``ν`` (``slip_floor``; default ``1e-4·D``).
    """
    robot = dict(map_.robot)
    for key in ("bearing_error_deg", "compass_error_deg", "slip", "slip_floor"):
        if getattr(params, key) is not None:
            robot[key] = getattr(params, key)
    if params.noise_bound_deg is not None and params.bearing_error_deg is None:
        # the world's bound is the world-frame one, camera and heading together
        robot["bearing_error_deg"] = params.noise_bound_deg
        robot["compass_error_deg"] = params.compass_error_deg
    return {"estimator": params.estimator, **runtime_controller.error_model(robot)}


def step_limits(
    arrays: PlanArrays, starts: np.ndarray, s: Settings, params: Params, routes: np.ndarray | None = None
) -> np.ndarray:
    """``max_steps`` of each run (ALGORITHMS §7.2), shape (R,).

    ``params.max_steps`` for every run if given, else ``ceil(5·L_route/(v·dt)) + 1000``.

    Parameters
    ----------
    arrays : PlanArrays
        The plan's tree nodes and their route costs, for :func:`tree_routes`.
    starts : ndarray, shape (R, 2)
        Start positions (map units).
    s : Settings
        The loop's speed ``v`` (map units / s) and step ``dt`` (s).
    params : Params
        Its ``max_steps`` overrides the rule when given.
    routes : ndarray, shape (R,), optional
        ``L_route`` of each start (map units) when already computed by :func:`tree_routes`.
    """
    if params.max_steps is not None:
        return np.full(len(starts), int(params.max_steps), np.int64)
    routes = tree_routes(arrays, starts) if routes is None else routes
    return step_limit(routes, s).astype(np.int64)


def step_limit(route_length: Any, s: Settings) -> np.ndarray:
    """The step limit ``ceil(5·L_route/(v·dt)) + 1000`` of ALGORITHMS §7.2 (float, the shape of ``route_length``).

    Parameters
    ----------
    route_length : array_like
        Tree route lengths ``L_route`` (map units).
    s : Settings
        The loop's speed ``v`` (map units / s) and step ``dt`` (s).
    """
    return np.ceil(5.0 * np.asarray(route_length, float) / (s.speed * s.dt)) + 1000.0


def tree_routes(arrays: PlanArrays, starts: np.ndarray) -> np.ndarray:
    """``L_route = ‖x₀ − x_n‖ + cost(n)`` with ``n`` the start's nearest node (map units), shape (R,)."""
    if not len(starts):
        return np.zeros(0)
    near = runtime.nearest_node(arrays, starts)
    return np.hypot(*(starts - arrays.nodes[near]).T) + arrays.node_cost[near]


def make_camera(
    plan,
    world,
    space: FreeSpace,
    params: Params,
    bound: float | None = None,
    toward: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Camera | None:
    """The camera of :attr:`Params.camera` for robots in ``world`` (whose free space is ``space``),
    drawing from the stream ``[seed, 2]``; ``None`` for ``measurement="displacement"``.

    Parameters
    ----------
    plan : Plan
        The plan: its map's tolerance, and the map the rendered camera draws.
    world : Map
        The world the robots drive in (the plan's map, or a deformed one): the ideal camera sees
        its landmarks.
    space : FreeSpace
        The free space of ``world``: its raw obstacles hide landmarks when ``params.occlusion``.
    params : Params
        ``measurement``, ``camera``, ``fov`` and ``noise_deg`` or ``noise_bound_deg`` (degrees),
        ``noise_worst``, ``range`` (map units), ``occlusion`` and ``seed``.
    bound : float, optional
        The world's bound on every bearing error (rad): errors uniform within it, or at it with
        ``toward`` (:func:`world_bound`); ``None``: ``noise_deg``'s Gaussian.
    toward : callable, optional
        :func:`nearest_obstacle` of the plan, for ``noise_worst``.

    Raises
    ------
    InvalidParamsError
        ``camera="render"`` in a world other than the plan's map (it draws the plan's).
    """
    if params.measurement == "displacement":
        return None
    rng = np.random.default_rng([params.seed, 2])
    if params.camera == "render":
        if world is not plan.map:
            raise InvalidParamsError(
                "the rendered camera draws the plan's own map; use camera ideal for another world", field="camera"
            )
        from bearnav_cli.world.render import RenderedCamera  # OpenCV, only when asked for

        return RenderedCamera.for_plan(plan, fov=math.radians(params.fov), rng=rng, space=space)
    return IdealCamera(
        space,
        world.landmarks,
        fov=math.radians(params.fov),
        noise=math.radians(params.noise_deg),
        max_range=math.inf if params.range is None else float(params.range),
        occlusion=params.occlusion,
        tol=plan.map.tol,
        rng=rng,
        bound=bound,
        toward=toward if params.noise_worst else None,
    )


def world_bound(params: Params, s: Settings) -> float | None:
    """The bound on the simulated camera's bearing errors (rad): ``noise_bound_deg``; with ``noise_worst``
    alone the camera's share of the bound the robot assumes (``η − ψ``: the compass errs too,
    :func:`compass_errors`); ``None``: Gaussian ``noise_deg``."""
    if params.noise_bound_deg is not None:
        return math.radians(params.noise_bound_deg)
    return s.control.bearing_bound - s.control.heading_bound if params.noise_worst else None


def compass_errors(params: Params, s: Settings, runs: int) -> np.ndarray | None:
    """Each run's compass error (rad, shape (R,)) under bounded noise, or ``None`` (a true heading).

    The robot's bound ``ψ`` (``compass_error_deg``) where it has one: a bias drawn once per run, uniform in
    ``[−ψ, ψ]`` (a magnetometer indoors errs by a slowly varying bias), or ``±ψ`` in turn under ``noise_worst``.
    Gaussian noise (``noise_deg``) keeps the true heading: it stresses the bearings alone.
    """
    psi = s.control.heading_bound
    if psi <= 0.0 or world_bound(params, s) is None:
        return None
    if params.noise_worst:
        return np.where(np.arange(runs) % 2, -psi, psi)
    return np.random.default_rng([params.seed, 4]).uniform(-psi, psi, runs)


def nearest_obstacle(arrays: PlanArrays) -> Callable[[np.ndarray], np.ndarray]:
    """``toward(x)``: the unit direction from each point (R, 2) toward its nearest inflated obstacle or wall
    (``runtime.sight.obstacle_clearance``), what the worst-case errors push toward."""

    def toward(x: np.ndarray) -> np.ndarray:
        return -runtime.sight.obstacle_clearance(arrays, x)[1]

    return toward


def start_loop(
    plan,
    starts: np.ndarray,
    params: Params = Params(),
    world=None,
    *,
    arrays: PlanArrays | None = None,
    space: FreeSpace | None = None,
) -> tuple[Loop, np.ndarray, dict]:
    """The loop of :func:`rollout` before its first step: the loop, the runs to step and what it was built from.

    Starts that are not free are already finished as collisions. The dict holds the ``arrays``,
    ``settings`` and ``routes`` (:func:`tree_routes`) of the runs.

    Parameters
    ----------
    plan : Plan
        The synthesised plan.
    starts : ndarray, shape (R, 2)
        Start positions (map units).
    params : Params
        The loop's parameters (its ``starts`` field is ignored here).
    world : Map, optional
        The world the robots drive in, as for :func:`rollout`; default the plan's map.
    arrays : PlanArrays, optional
        The plan's run-time view when the caller has built it (built here otherwise).
    space : FreeSpace, optional
        The free space of ``world`` when the caller has built it (built here otherwise).

    Raises
    ------
    InvalidParamsError
        ``world`` has not as many landmarks as the plan, or the camera cannot be made
        (:func:`make_camera`).
    """
    arrays = PlanArrays.from_plan(plan) if arrays is None else arrays
    world = plan.map if world is None else world
    if len(world.landmarks) != len(arrays.landmarks):
        raise InvalidParamsError("the world must have the plan's landmarks (moved, not added)", field="world")
    space = FreeSpace.from_map(world) if space is None else space
    s = settings(plan, params)
    x0 = np.array(starts, float).reshape(-1, 2)
    routes = tree_routes(arrays, x0)
    limits = step_limits(arrays, x0, s, params, routes)
    blocked = ~space.points_free(x0)
    heading = np.zeros(len(x0))
    if (~blocked).any():
        heading[~blocked] = initial_headings(arrays, x0[~blocked], _radians(params.initial_heading))
    toward = nearest_obstacle(arrays) if params.noise_worst else None
    bound = world_bound(params, s)
    camera = make_camera(plan, world, space, params, bound, toward)
    # bounded noise: the odometry errs within the bound the robot assumes, κ‖d̂‖ + ν (ALGORITHMS §12.8)
    slip_bound = None if bound is None else (s.control.slip, s.control.slip_floor)
    base = Base(
        params.dynamics,
        s.dt,
        params.odometry_noise,
        len(x0),
        np.random.default_rng([params.seed, 3]),
        slip_bound,
        toward,
    )
    # a unicycle on a look-ahead plan: the starts are the look-ahead point's, and the body (radius ρ
    # around the axle) is what hits things (ALGORITHMS §12.6)
    lookahead = arrays.lookahead if params.dynamics == "unicycle" else 0.0
    axle = runtime_robot.lookahead_point(x0, heading, -lookahead)
    contact = Contact(body_space(world, space), axle) if lookahead > 0 else Contact(space, x0)
    loop = Loop(
        arrays,
        camera,
        base,
        contact,
        x0,
        heading,
        s,
        params,
        limits,
        world.landmarks,
        lookahead,
        window=PROGRESS_WINDOW,
        compass=compass_errors(params, s, len(x0)),
    )
    if blocked.any():
        log.warning("%d starts are not free: counted as collisions", int(np.count_nonzero(blocked)))
        loop.finish(np.flatnonzero(blocked), Outcome.COLLISION)
    return loop, np.flatnonzero(~blocked), {"arrays": arrays, "settings": s, "routes": routes}


def rollout(
    plan,
    starts: np.ndarray,
    params: Params = Params(),
    progress: Callable[[int, int], None] | None = None,
    world=None,
    on_step: Callable[[np.ndarray, np.ndarray, np.ndarray], None] | None = None,
    *,
    arrays: PlanArrays | None = None,
    space: FreeSpace | None = None,
) -> Simulation:
    """Run the closed loop from every start at once.

    Parameters
    ----------
    plan : Plan
        The synthesised plan (any object with the :class:`~bearnav_cli.datatypes.Plan` attributes).
    starts : ndarray, shape (R, 2)
        Start positions (map units; a look-ahead unicycle's are its look-ahead point's, the axle
        begins ``λ`` behind). A start that is not free ends at once as a collision.
    params : Params
        Its ``starts`` field is ignored here (see :func:`run`).
    progress : callable, optional
        ``progress(finished_runs, R)`` every few steps.
    world : Map, optional
        The world the robots drive in, when it differs from the one the plan was made for
        (paper B's deformation test): its obstacles stop them and hide landmarks, its
        landmark positions are what the camera sees. The controllers, cells and goal stay
        the plan's. Default: the plan's map.
    on_step : callable, optional
        ``on_step(runs, x, certified)`` after every step: the runs (int, (K,)) that moved (a command that
        translates them: not a robot standing or turning in place to look), their true
        positions after the step (K, 2; a look-ahead unicycle's look-ahead point ``x + λh``, the point
        the plan is about) and whether that step was certified (bool, (K,)), e.g. for ``verify`` to
        check every true position against the certified domain.
    arrays, space : PlanArrays, FreeSpace, optional
        The plan's run-time view and the world's free space, when the caller has built them.

    Returns
    -------
    Simulation
        Outcome, figures and trajectory of every run, the loop constants, the plan's tree and
        cells; ``stats`` holds only the camera's ``report()`` (under ``camera``) if it has one.
    """
    loop, active, built = start_loop(plan, starts, params, world, arrays=arrays, space=space)
    s, x0 = built["settings"], loop.position
    iteration = 0
    while active.size:
        if on_step is None:
            active = loop.step(active)
        else:
            translated, certified = loop.moved.copy(), loop.certified.copy()
            active = loop.step(active)
            moved = np.flatnonzero(loop.moved > translated)
            on_step(moved, loop.reference(loop.x[moved], loop.phi[moved]), loop.certified[moved] > certified[moved])
        iteration += 1
        if progress is not None and iteration % PROGRESS_EVERY == 0:
            progress(len(x0) - len(active), len(x0))
    if progress is not None:
        progress(len(x0), len(x0))
    coords, cells, headings, offsets = loop.trajectories()
    report = getattr(loop.camera, "report", None)
    return Simulation(
        map=plan.map,
        starts=x0,
        outcome=loop.outcome,
        steps=loop.steps,
        time=loop.steps * s.dt,
        path_length=loop.length,
        route_length=built["routes"],
        left_cell=loop.left,
        approach_steps=loop.approach,
        hold_steps=loop.held,
        certified_steps=loop.certified,
        start_in_domain=in_domain(built["arrays"], x0),
        min_clearance=loop.contact.clearance,
        final_position=loop.position,
        final_cell=loop.state.cell,
        max_steps=loop.limits,
        trajectory_coords=coords,
        trajectory_cells=cells,
        trajectory_heading=headings,
        trajectory_offsets=offsets,
        nodes=plan.cells.nodes,
        parent=plan.cells.parent,
        cell_vertices=plan.cells.cell_vertices,
        cell_vertex_offsets=plan.cells.cell_vertex_offsets,
        cell_status=plan.status,
        speed=s.speed,
        dt=s.dt,
        eps_sw=s.eps_sw,
        goal_tolerance=s.goal_tolerance,
        stats={
            "estimator_counts": {"name": s.control.estimator, **loop.estimate_counts()},
            **({"camera": report()} if callable(report) else {}),
        },
    )


def estimate_trace(plan, start: np.ndarray, params: Params, every: int = 10) -> EstimateTrace:
    """Run one robot from ``start`` with ``params`` (``estimator="set"``) and record its sets every ``every`` steps.

    Parameters
    ----------
    plan : Plan
        The plan.
    start : ndarray, shape (2,)
        The start (map units).
    params : Params
        The loop's parameters; its ``estimator`` must be ``"set"``.
    every : int
        Record one step in this many (and the last).

    Raises
    ------
    InvalidParamsError
        ``params.estimator`` is not ``"set"``.
    """
    if params.estimator != "set":
        raise InvalidParamsError("a trace of estimate sets needs estimator set", field="estimator")
    loop, active, _ = start_loop(plan, np.asarray(start, float).reshape(1, 2), params)
    return trace_estimates(loop, active, every)


def in_domain(arrays: PlanArrays, starts: np.ndarray) -> np.ndarray:
    """Whether each start lies in the certified domain ``D`` (some funnel cell holds it), shape (R,).

    Always False for ``paper`` plans, whose cells certify nothing beyond themselves.
    """
    if not arrays.funnel or not len(starts):
        return np.zeros(len(starts), bool)
    return runtime.least_rank_cell(arrays, starts) >= 0


def resolve_starts(plan, params: Params) -> np.ndarray:
    """The starts of :attr:`Params.starts` for this plan, shape (R, 2) (``random:N`` and ``domain:N`` from the
    stream ``[seed, 1]``); see :func:`bearnav_cli.world.starts.resolve_starts` and
    :func:`~bearnav_cli.world.starts.domain_starts` (``domain:N``, uniform in the plan's cells)."""
    rng = np.random.default_rng([params.seed, 1])
    spec = parse_starts(params.starts)
    if isinstance(spec, world_starts.InDomain):
        return world_starts.domain_starts(PlanArrays.from_plan(plan), int(spec), rng)
    return world_starts.resolve_starts(plan.map, params.starts, rng)


def metrics(sim: Simulation) -> dict:
    """The figures ``bearnav simulate`` prints and writes to ``sim.json`` (from the runs alone)."""
    done = sim.outcome == Outcome.SUCCESS
    n = len(sim)

    def mean(values: np.ndarray) -> float | None:
        return float(np.mean(values)) if len(values) else None

    counts = sim.stats.get("estimator_counts", {})
    finish = np.hypot(*(sim.final_position - sim.map.goal).T)  # the last straight bit into the goal ball
    ratio = (sim.path_length + finish)[done] / np.maximum(sim.route_length[done], 1e-300)
    return {
        "runs": n,
        "success_rate": _finite_or_none(sim.success_rate),
        "outcomes": sim.counts(),
        "time_mean_s": mean(sim.time[done]),
        "time_max_s": float(np.max(sim.time[done])) if done.any() else None,
        "path_length_mean": mean(sim.path_length[done]),
        "path_over_tree_route_mean": mean(ratio),
        "min_clearance": float(np.min(sim.min_clearance)) if n else None,
        "left_cell_events": int(sim.left_cell.sum()),
        "runs_with_left_cell": int(np.count_nonzero(sim.left_cell > 0)),
        "runs_with_approach": int(np.count_nonzero(sim.approach_steps > 0)),
        "hold_time_total_s": float(sim.hold_steps.sum() * sim.dt),
        "certified_step_fraction": _moving_fraction(sim),
        "estimator": counts.get("name"),
        "containment_violations": counts.get("containment_violations"),
        "inconsistencies": counts.get("inconsistencies"),
        "looks_per_run": counts["looks"] / n if n and "looks" in counts else None,
        "look_time_mean_s": (counts["look_steps"] * sim.dt / counts["looks"]) if counts.get("looks") else None,
        "look_time_total_s": counts.get("look_steps", 0) * sim.dt,
        "error_bound_mean": counts.get("error_bound_mean"),
        "true_error_mean": counts.get("true_error_mean"),
        "error_used_max": counts.get("error_used_max"),
        "runs_from_certified_domain": int(np.count_nonzero(sim.start_in_domain)),
        "success_rate_in_domain": _finite_or_none(sim.success_rate_of(sim.start_in_domain)),
        "success_rate_outside_domain": _finite_or_none(sim.success_rate_of(~sim.start_in_domain)),
        "dt": sim.dt,
    }


def _moving_fraction(sim: Simulation) -> float:
    """Certified steps over the steps that translated (ALGORITHMS §12.3: a look is not a step taken);
    over every step where the run did not count its moves."""
    moved = sim.stats.get("estimator_counts", {}).get("moved_steps")
    if moved is None:
        return sim.certified_fraction
    return float(sim.certified_steps.sum() / max(1, moved))


def _finite_or_none(value: float) -> float | None:
    return value if math.isfinite(value) else None


def run(
    plan,
    params: Params = Params(),
    progress: Callable[[int, int], None] | None = None,
    on_step: Callable[[np.ndarray, np.ndarray, np.ndarray], None] | None = None,
) -> Simulation:
    """``bearnav simulate``: the starts of ``params.starts`` run through :func:`rollout`.

    Parameters
    ----------
    plan : Plan
        The synthesised plan (any object with the :class:`~bearnav_cli.datatypes.Plan` attributes).
    params : Params
        The loop's parameters; ``params.starts`` names the starts (:func:`resolve_starts`).
    progress : callable, optional
        ``progress(finished_runs, R)`` every few steps.
    on_step : callable, optional
        As :func:`rollout`'s.

    Returns
    -------
    Simulation
        What :func:`rollout` returns, with the :func:`metrics` (and the camera's report, if any)
        as its ``stats``.
    """
    sim = rollout(plan, resolve_starts(plan, params), params, progress, on_step=on_step)
    return replace(sim, stats={**metrics(sim), **sim.stats})


def summary(result: Simulation) -> str:
    """One line: success rate and the other outcomes."""
    counts = result.counts()
    others = ", ".join(f"{n} {name}" for name, n in counts.items() if name != "success" and n)
    text = f"{counts['success']}/{len(result)} runs reached the goal"
    return text + (f" ({others})" if others else "")


def check_resources(plan, params: Params, given: frozenset[str] = frozenset()) -> None:
    """Refuse closed-loop requests that cannot finish: too many steps per run, too many runs, or too much memory.

    Each run may take ``max_steps`` steps, ``ceil(5·L/(v·dt)) + 1000`` by default with ``L`` at most
    ``D`` plus the largest cost-to-go in the plan; memory is about ``limits.RUN_BYTES`` per run plus,
    when trajectories are recorded, ``limits.TRAJECTORY_POINT_BYTES`` per step of a typical run.

    Parameters
    ----------
    plan : Plan
        The plan to run: its map's diagonal and its cells' ``cell_rank`` (cost-to-go, map units)
        bound the route length ``L``; its map's starts count for ``starts: map``.
    params : Params
        The loop's parameters: ``starts`` (how many runs), ``speed``/``alpha`` and ``dt`` (through
        :func:`settings`), ``max_steps`` and ``record_trajectories``.
    given : frozenset of str
        The parameters set by the map's ``params:`` or an option: an explicit ``dt`` is named by a
        too-many-steps error instead of the speed.

    Raises
    ------
    ResourceLimitError
        A run may take more than ``limits.MAX_STEPS_PER_RUN`` steps (field ``dt``, ``alpha`` or
        ``speed``), or the runs need more memory than the budget (field ``starts``).
    InvalidParamsError
        More than ``limits.MAX_RUNS`` runs (field ``starts``).
    """
    from bearnav_cli import limits
    from bearnav_cli.errors import ResourceLimitError

    spec = parse_starts(params.starts)
    runs = spec if isinstance(spec, int) else (len(plan.map.starts) if isinstance(spec, str) else len(spec))
    speed = "alpha" if params.dynamics == "unicycle" else "speed"
    loop = settings(plan, params)
    diagonal = plan.map.diagonal
    longest = float(max(plan.cells.cell_rank.max(initial=0.0), 0.0)) + diagonal
    per_step = loop.speed * loop.dt
    if params.max_steps is not None:
        steps = int(params.max_steps)  # its range is that of MAX_STEPS_PER_RUN
    else:
        steps = int(step_limit(longest, loop))  # the rule each run gets, for the longest route
        if steps > limits.MAX_STEPS_PER_RUN:
            raise ResourceLimitError(
                f"at speed {loop.speed:g} with dt = {loop.dt:.3g} s one run may take up to {steps:.3g} steps "
                f"(limit {limits.MAX_STEPS_PER_RUN:.0e}); raise the speed or dt",
                field="dt" if "dt" in given else speed,
            )
    if runs > limits.MAX_RUNS:
        raise InvalidParamsError(f"at most {limits.MAX_RUNS:,} runs, got {runs:,}", field="starts")
    typical = min(steps, math.ceil((longest - 0.75 * diagonal) / per_step) + 1) if per_step > 0 else steps
    record = params.record_trajectories
    per_run = limits.RUN_BYTES + (limits.TRAJECTORY_POINT_BYTES * typical if record else 0)
    note = " (without recorded trajectories: params.simulate.record_trajectories false)" if record else ""
    limits.check_memory(runs, "runs", per_run, "starts", note=note)
