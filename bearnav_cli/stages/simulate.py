"""``bearnav simulate``: the closed loop of ALGORITHMS §7, every robot advanced together.

Each step measures what a robot's camera would see (world-frame bearings with Gaussian
angle noise, the field of view around the camera heading, occlusion by the raw
obstacles, an optional range), hands it to :func:`bearnav_cli.runtime.control` (the
very function a robot runs: reconstruction, cell policy, gain, speed normalisation,
hold policy) and integrates the single integrator or the unicycle. The measurement
``displacement`` feeds the true displacements instead (``x̂ = x``, paper B).

All robots advance in lock step as arrays: a step is a handful of numpy operations
over the robots still running, one batched line-of-sight test of their landmark
sight lines and one batched, exact segment test
(:meth:`~bearnav_cli.geometry.FreeSpace.segments_free`) of their step segments against
the inflated obstacles and the bounds.
"""

from __future__ import annotations

import enum
import logging
import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import shapely

from bearnav_cli import runtime
from bearnav_cli.datatypes import Simulation
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.routes import sample_starts
from bearnav_cli.runtime import ControlSettings, ControlState, PlanArrays, bearing

VERSION = 1
log = logging.getLogger(__name__)

#: A robot must move ``2·v·dt`` net over this many steps with a fix, or it stalls (ALGORITHMS §7.2).
PROGRESS_WINDOW = 200
#: How often (in steps) ``progress`` is called.
PROGRESS_EVERY = 25
#: Outcome of a robot still running (internal).
RUNNING = -1
#: ``--starts`` forms: ``map``, ``random:N`` or ``x,y;x,y;...``.
_RANDOM = re.compile(r"^random:(\d+)$")


class Outcome(enum.IntEnum):
    """How a run ended (ALGORITHMS §7.4)."""

    SUCCESS = 0  # within goal_tolerance of the goal
    COLLISION = 1  # a step segment met the inflated obstacles or left the bounds (or the start was not free)
    STALL = 2  # field below 1e-6·u_max, or no net progress over PROGRESS_WINDOW steps with a fix
    TIMEOUT = 3  # more than max_steps steps
    LOST = 4  # fewer than two usable landmarks for longer than hold_time


def _positive(value: float | None, name: str, *, allow_none: bool = True) -> None:
    if value is None and allow_none:
        return
    if value is None or isinstance(value, bool) or not (value > 0 and math.isfinite(value)):
        raise InvalidParamsError(f"must be positive, got {value}", field=name)


@dataclass(frozen=True)
class Params:
    """Parameters of the closed loop (ALGORITHMS §6–§7).

    Attributes
    ----------
    dynamics : {"single", "unicycle"}
        Single integrator ``ẋ = v_ref·unit(ũ)`` or unicycle ``v = α cos e``, ``ω = β sin e``.
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
        Bearing reconstruction (§6); ``x̂`` for switching always comes from ``lsq``.
    min_spread_deg : float
        ``θ_min`` of §6.2 (degrees).
    speed : float
        Reference speed ``v_ref`` of the single integrator (map units / s).
    alpha, beta : float
        Unicycle forward gain (map units / s) and turn gain (rad / s).
    clamp_reverse : bool
        Unicycle never drives backwards (``v >= 0``).
    turn_first : bool
        Unicycle forward speed ``α cos³ e`` instead of ALGORITHMS §7.1's ``α cos e``: far off its
        field it slows down to turn rather than sweep a wide arc past an obstacle corner.
    certified_heading : bool
        Unicycle on a funnel plan: forward only within the heading allowance that keeps the
        velocity inside the cell's certified conditions (``runtime.step.heading_allowance``).
    look_on_purpose : bool
        Without a fix, first turn toward the nearest heading where the map promises a usable pair of
        tags (``runtime.step.best_view_heading``), then look all around; off (default): the
        revolution at once.
    initial_heading : float or None
        Initial heading (degrees); ``None``: toward the active cell's exit point (the goal
        in the goal cell).
    hold_time : float
        Seconds without a usable reconstruction before the robot stops to look around (a
        revolution at ``beta``); then the run is ``lost`` (§7.5).
    odometry : bool
        Between fixes, carry ``x̂`` forward with the commanded motion (exact here: the
        simulation has no wheel slip) for at most ``hold_time``; off: §7.5's hold as written.
    odometry_noise : float
        Wheel slip: each step's true displacement is the commanded one scaled by ``1 + ε`` and
        turned by ``ε'`` (rad), ``ε, ε' ~ N(0, odometry_noise²)``; 0 is the exact dynamics of §7.1.
    max_fix_error : float or None
        Use a noisy fix only if its predicted 3σ position error (from ``noise_deg`` and the
        bearing geometry, :func:`bearnav_cli.runtime.bearing.fix_variance`) is at most this (map units);
        ``None``: every usable fix.
    starts : str
        ``map`` (the map's starts), ``random:N`` (N uniform free starts in the goal's
        component, seeded) or ``x,y;x,y;...``.
    dt : float or None
        Euler step (s); ``None`` means ``min(0.0025·D/v, 0.2)``, ``v = speed`` or ``alpha``.
    goal_tolerance : float or None
        Success radius (map units); ``None`` takes the plan's.
    max_steps : int or None
        Step limit of every run; ``None`` means ``ceil(5·L_route/(v·dt)) + 1000`` per run, with
        ``L_route = ‖x₀ − x_n‖ + cost(n)`` and ``n`` the start's nearest tree node.
    seed : int
        Seeds the bearing noise and the random starts (separate streams).
    record_trajectories : bool
        Keep every robot's trajectory (``verify`` turns this off).
    """

    dynamics: str = "single"
    measurement: str = "bearing"
    fov: float = 360.0
    noise_deg: float = 0.0
    range: float | None = None
    occlusion: bool = True
    reconstruction: str = "lsq"
    min_spread_deg: float = 2.0
    speed: float = 0.1
    alpha: float = 0.1
    beta: float = 0.5
    clamp_reverse: bool = False
    turn_first: bool = True
    certified_heading: bool = True
    look_on_purpose: bool = False
    initial_heading: float | None = None
    hold_time: float = 2.0
    odometry: bool = True
    max_fix_error: float | None = None
    odometry_noise: float = 0.0
    starts: str = "map"
    dt: float | None = None
    goal_tolerance: float | None = None
    max_steps: int | None = None
    seed: int = 0
    record_trajectories: bool = True

    def __post_init__(self) -> None:
        for name, allowed in (("dynamics", runtime.DYNAMICS), ("measurement", runtime.MEASUREMENTS),
                              ("reconstruction", bearing.METHODS)):  # fmt: skip
            if getattr(self, name) not in allowed:
                raise InvalidParamsError(f"must be one of {', '.join(allowed)}, got {getattr(self, name)!r}",
                                         field=name)  # fmt: skip
        bearing.check_camera(self.fov, self.noise_deg, self.min_spread_deg)
        for name in ("speed", "alpha", "beta", "hold_time"):
            _positive(getattr(self, name), name, allow_none=False)
        for name in ("range", "dt", "goal_tolerance"):
            _positive(getattr(self, name), name)
        if not (self.odometry_noise >= 0 and math.isfinite(self.odometry_noise)):
            raise InvalidParamsError(f"must be zero or positive, got {self.odometry_noise}", field="odometry_noise")
        if self.initial_heading is not None and not math.isfinite(self.initial_heading):
            raise InvalidParamsError(f"must be finite, got {self.initial_heading}", field="initial_heading")
        if self.max_steps is not None and (
            isinstance(self.max_steps, bool) or int(self.max_steps) != self.max_steps or self.max_steps < 1
        ):
            raise InvalidParamsError(f"must be a positive integer, got {self.max_steps}", field="max_steps")
        parse_starts(self.starts)  # syntax only; positions are checked against the map in run()


def parse_starts(spec: str) -> str | int | np.ndarray:
    """``"map"``, the count of ``random:N``, or the explicit starts as an array (n, 2).

    Raises
    ------
    InvalidParamsError
        Anything else.
    """
    text = str(spec).strip()
    if text == "map":
        return "map"
    match = _RANDOM.match(text)
    if match:
        count = int(match.group(1))
        if count < 1:
            raise InvalidParamsError("random:N needs N >= 1", field="starts")
        return count
    try:
        points = [[float(v) for v in item.split(",")] for item in text.split(";") if item.strip()]
    except ValueError:
        points = []
    if not points or any(len(p) != 2 or not all(math.isfinite(v) for v in p) for p in points):
        raise InvalidParamsError(f"expected map, random:N or x,y;x,y;..., got {spec!r}", field="starts")
    return np.array(points, float)


@dataclass(frozen=True)
class Settings:
    """Concrete loop constants for one plan (the ``None`` defaults of :class:`Params` filled in).

    Attributes
    ----------
    speed : float
        The speed ``dt`` and ``eps_sw`` are scaled by: ``v_ref``, or ``α`` for the unicycle.
    dt : float
        Step (s).
    eps_sw : float
        Switching radius ``2·v·dt`` around the exit point (map units).
    goal_tolerance : float
        Success radius (map units).
    tol : float
        ``1e-9·D``, the membership slack of switching.
    control : ControlSettings
        What :func:`bearnav_cli.runtime.control` is called with.
    """

    speed: float
    dt: float
    eps_sw: float
    goal_tolerance: float
    tol: float
    control: ControlSettings


def settings(plan, params: Params) -> Settings:
    """Resolve :class:`Params` against a plan (``dt`` from the map's diagonal, the plan's tolerance)."""
    v = params.alpha if params.dynamics == "unicycle" else params.speed
    dt, eps_sw, blind_error = runtime.timing(plan.map.diagonal, v, params.dt)
    goal_tolerance = params.goal_tolerance if params.goal_tolerance is not None else float(plan.goal_tolerance)
    control = ControlSettings(
        speed=params.speed, dt=dt, eps_sw=eps_sw, tol=plan.map.tol, dynamics=params.dynamics, alpha=params.alpha,
        beta=params.beta, clamp_reverse=params.clamp_reverse, turn_first=params.turn_first,
        certified_heading=params.certified_heading, measurement=params.measurement,
        reconstruction=params.reconstruction, min_spread=math.radians(params.min_spread_deg),
        hold_time=params.hold_time, odometry=params.odometry,
        blind_error=blind_error,
        bearing_sigma=math.radians(params.noise_deg),
        max_fix_error=math.inf if params.max_fix_error is None else params.max_fix_error,
        fov=math.radians(params.fov), max_range=math.inf if params.range is None else float(params.range),
        look_on_purpose=params.look_on_purpose,
    )  # fmt: skip
    return Settings(v, dt, eps_sw, goal_tolerance, plan.map.tol, control)


@dataclass(frozen=True, eq=False)
class Rollouts:
    """The runs of one :func:`rollout` call, ``R`` robots.

    Attributes
    ----------
    starts : ndarray, shape (R, 2)
    outcome : ndarray of int8, shape (R,)
        :class:`Outcome` values.
    steps : ndarray of int64, shape (R,)
        Euler steps taken.
    time : ndarray, shape (R,)
        ``steps · dt`` (s).
    path_length : ndarray, shape (R,)
        Length of the trajectory polyline (map units).
    left_cell : ndarray of int64, shape (R,)
        Relocations after leaving the cell through a side face (ALGORITHMS §7.3).
    approach_steps : ndarray of int64, shape (R,)
        Steps driven straight to a tree node from outside every safe set (docs/choices.md).
    hold_steps : ndarray of int64, shape (R,)
        Steps without a usable reconstruction (hold policy, §7.5).
    certified_steps : ndarray of int64, shape (R,)
        Steps covered by the composed certificate (ALGORITHMS §11.4; 0 for ``paper`` plans).
    start_in_domain : ndarray of bool, shape (R,)
        The start lies in the certified domain ``D`` (a funnel plan's cells, ALGORITHMS §11.3).
    min_clearance : ndarray, shape (R,)
        Smallest distance from the inflated obstacles and the walls of ``B_r`` along the run (map units).
    final_position : ndarray, shape (R, 2)
    final_cell : ndarray of int64, shape (R,)
        Active cell at the end (``-1`` if the start was not free or never had a fix).
    max_steps : ndarray of int64, shape (R,)
        Step limit of each run.
    trajectory_coords, trajectory_cells, trajectory_offsets : ndarray, shapes (P, 2), (P,), (R + 1,)
        Run ``r`` visits ``trajectory_coords[o[r]:o[r + 1]]`` (start first, ``steps + 1`` points);
        ``trajectory_cells`` is the cell whose field moved the robot on from each point (the
        active cell at the end for the last point). Empty when trajectories are not recorded.
    trajectory_heading : ndarray, shape (P,)
        Camera heading at each trajectory point (rad).
    speed, dt, eps_sw, goal_tolerance : float
        The loop constants used.
    """

    starts: np.ndarray
    outcome: np.ndarray
    steps: np.ndarray
    time: np.ndarray
    path_length: np.ndarray
    left_cell: np.ndarray
    approach_steps: np.ndarray
    hold_steps: np.ndarray
    certified_steps: np.ndarray
    start_in_domain: np.ndarray
    min_clearance: np.ndarray
    final_position: np.ndarray
    final_cell: np.ndarray
    max_steps: np.ndarray
    trajectory_coords: np.ndarray
    trajectory_cells: np.ndarray
    trajectory_offsets: np.ndarray
    trajectory_heading: np.ndarray
    speed: float
    dt: float
    eps_sw: float
    goal_tolerance: float

    def __len__(self) -> int:
        return len(self.outcome)

    def trajectory(self, r: int) -> np.ndarray:
        """Positions of run ``r``, shape (steps + 1, 2) (empty if not recorded)."""
        o = self.trajectory_offsets
        return self.trajectory_coords[o[r] : o[r + 1]]

    def cells_along(self, r: int) -> np.ndarray:
        """Cells along run ``r``, aligned with :meth:`trajectory`."""
        o = self.trajectory_offsets
        return self.trajectory_cells[o[r] : o[r + 1]]

    def counts(self) -> dict[str, int]:
        """Number of runs per outcome name (every outcome listed)."""
        return {o.name.lower(): int(np.count_nonzero(self.outcome == o)) for o in Outcome}

    @property
    def success_rate(self) -> float:
        """Fraction of successful runs (NaN without runs)."""
        return float(np.mean(self.outcome == Outcome.SUCCESS)) if len(self) else math.nan

    def success_rate_of(self, runs: np.ndarray) -> float:
        """Fraction of successful runs among ``runs`` (bool mask, shape (R,)); NaN when it selects none."""
        done = self.outcome[runs] == Outcome.SUCCESS
        return float(np.mean(done)) if len(done) else math.nan

    @property
    def certified_fraction(self) -> float:
        """Steps covered by the composed certificate over all steps (ALGORITHMS §11.4; 0 without steps)."""
        return float(self.certified_steps.sum() / max(1, self.steps.sum()))


def step_limits(arrays: PlanArrays, starts: np.ndarray, s: Settings, params: Params) -> np.ndarray:
    """``max_steps`` of each run (ALGORITHMS §7.2), shape (R,)."""
    if params.max_steps is not None:
        return np.full(len(starts), int(params.max_steps), np.int64)
    return np.ceil(5.0 * tree_routes(arrays, starts) / (s.speed * s.dt)).astype(np.int64) + 1000


def tree_routes(arrays: PlanArrays, starts: np.ndarray) -> np.ndarray:
    """``L_route = ‖x₀ − x_n‖ + cost(n)`` with ``n`` the start's nearest node (map units), shape (R,)."""
    near = runtime.nearest_node(arrays, starts)
    return np.hypot(*(starts - arrays.nodes[near]).T) + arrays.node_cost[near]


class _Loop:
    """Mutable state of every robot during :func:`rollout` (arrays indexed by run)."""

    def __init__(self, arrays: PlanArrays, space: FreeSpace, starts: np.ndarray, heading: np.ndarray, s: Settings,
                 params: Params, limits: np.ndarray, world_landmarks: np.ndarray | None = None):  # fmt: skip
        r = len(starts)
        self.arrays, self.space, self.s, self.params, self.limits = arrays, space, s, params, limits
        self.rng = np.random.default_rng([params.seed, 2])
        self.slip = np.random.default_rng([params.seed, 3])
        self.x = starts.copy()
        self.phi = heading.copy()  # unicycle yaw; the single integrator's camera looks along its last command
        self.state = ControlState.initial(heading)
        self.outcome = np.full(r, RUNNING, np.int8)
        self.steps = np.zeros(r, np.int64)
        self.moving_steps = np.zeros(r, np.int64)  # steps with a fix: the no-progress window counts these
        self.length = np.zeros(r)
        self.left = np.zeros(r, np.int64)
        self.approach = np.zeros(r, np.int64)
        self.held = np.zeros(r, np.int64)
        self.certified = np.zeros(r, np.int64)
        self.clearance = space.clearance(starts) if r else np.zeros(0)
        self.last_clearance = self.clearance.copy()  # at the last query, and the path length since
        self.since = np.zeros(r)
        self.history = np.zeros((PROGRESS_WINDOW + 1, r, 2))  # ring buffer of positions, by moving steps
        self.history[0] = starts
        self.trace: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self.fov = math.radians(params.fov)
        self.sigma = math.radians(params.noise_deg)
        self.max_range = math.inf if params.range is None else float(params.range)
        self.world = arrays.landmarks if world_landmarks is None else np.asarray(world_landmarks, float)
        self.sight = space.visibility_regions(self.world) if params.occlusion else []

    def finish(self, runs: np.ndarray, outcome: Outcome) -> None:
        self.outcome[runs] = outcome

    def camera_heading(self, idx: np.ndarray) -> np.ndarray:
        """The unicycle's yaw; the single integrator's camera looks along its last command (or scans)."""
        return self.phi[idx]

    def measure(self, idx: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Noisy world-frame bearings (R, L, 2) and what the camera sees (R, L), ALGORITHMS §6.1."""
        params = self.params
        n_lm = len(self.world)
        if params.measurement == "displacement":
            return np.zeros((len(idx), n_lm, 2)), np.ones((len(idx), n_lm), bool)
        seen = bearing.in_field_of_view(p, self.camera_heading(idx), self.world, self.fov, tol=self.s.tol)
        if math.isfinite(self.max_range):
            seen &= bearing.in_range(p, self.world, self.max_range)
        if params.occlusion and seen.any():
            # one prepared point query per sight line against each landmark's visibility region
            # (FreeSpace.visibility_regions: the same answers as the segment test, much cheaper)
            for k in np.flatnonzero(seen.any(axis=0)):
                rows = np.flatnonzero(seen[:, k])
                seen[rows, k] = shapely.intersects_xy(self.sight[k], p[rows, 0], p[rows, 1])
        return bearing.noisy_bearings(p, self.world, self.sigma, self.rng), seen

    def step(self, active: np.ndarray) -> np.ndarray:
        """Advance the robots ``active`` by one step (ALGORITHMS §7.2); return those still running."""
        s, arrays, params = self.s, self.arrays, self.params
        p = self.x[active]
        arrived = np.hypot(*(p - arrays.goal).T) <= s.goal_tolerance
        if arrived.any():
            self.finish(active[arrived], Outcome.SUCCESS)
            active, p = active[~arrived], p[~arrived]
            if not active.size:
                return active
        bearings, seen = self.measure(active, p)
        moved_world = self.world is not arrays.landmarks and params.measurement == "displacement"
        measured = (self.world[None] - p[:, None, :]) if moved_world else None
        out = runtime.control(arrays, s.control, self.state.take(active), bearings, seen, self.phi[active], x_true=p,
                              displacements=measured)  # fmt: skip
        heading = self.camera_heading(active)
        self.state.put(active, out.state)
        self.left[active] += out.relocated
        self.approach[active] += out.state.target >= 0
        self.held[active] += ~out.fix
        self.certified[active] += out.certified
        ended = np.zeros(len(active), bool)
        for mask, outcome in ((out.lost, Outcome.LOST), (out.stalled, Outcome.STALL)):
            hit = mask & ~ended
            if hit.any():
                self.finish(active[hit], outcome)
                ended |= hit
        if ended.any():
            keep = ~ended
            active, p, heading = active[keep], p[keep], heading[keep]
            out_v, out_f, out_t, fix = out.velocity[keep], out.forward[keep], out.turn[keep], out.fix[keep]
            out_scan = out.scanning[keep]
            if not active.size:
                return active
        else:
            out_v, out_f, out_t, fix, out_scan = out.velocity, out.forward, out.turn, out.fix, out.scanning
        phi = self.phi[active]
        if params.dynamics == "unicycle":
            q = p + s.dt * out_f[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
            self.phi[active] = bearing.wrap(phi + s.dt * out_t)
        else:
            q = p + s.dt * out_v
            # the camera looks along the last command, or turns while the robot looks around
            d = self.state.last_dir[active]
            self.phi[active] = np.where(out_scan, bearing.wrap(phi + s.dt * out_t), np.arctan2(d[:, 1], d[:, 0]))
        if params.odometry_noise > 0:
            # wheel slip: the robot moves a little farther or shorter and off its command, so the
            # controller's odometry is only an estimate
            move = q - p
            scale = 1.0 + params.odometry_noise * self.slip.standard_normal(len(p))
            turn = params.odometry_noise * self.slip.standard_normal(len(p))
            c, s_ = np.cos(turn), np.sin(turn)
            rotated = np.column_stack([c * move[:, 0] - s_ * move[:, 1], s_ * move[:, 0] + c * move[:, 1]])
            q = p + scale[:, None] * rotated
        free = self.space.segments_free(p, q)
        if params.record_trajectories:
            self.trace.append((active, p, self.state.cell[active].copy(), heading))
        self.x[active] = q
        self.steps[active] += 1
        self.length[active] += np.hypot(*(q - p).T)
        # the smallest clearance so far: a step moves at most `reach` closer to an obstacle, so a
        # robot whose last measured clearance minus the distance since is above its minimum needs no query
        self.since[active] += np.hypot(*(q - p).T)
        due = self.last_clearance[active] - self.since[active] < self.clearance[active]
        if due.any():
            idx = active[due]
            measured = self.space.clearance(q[due])
            self.clearance[idx] = np.minimum(self.clearance[idx], measured)
            self.last_clearance[idx], self.since[idx] = measured, 0.0
        if not free.all():
            self.finish(active[~free], Outcome.COLLISION)
            active, q, fix = active[free], q[free], fix[free]
        # no-progress window (§7.2), over the steps with a fix: a robot holding still to turn is not stuck
        moved = active[fix]
        self.moving_steps[moved] += 1
        k = self.moving_steps[moved]
        self.history[k % (PROGRESS_WINDOW + 1), moved] = q[fix]
        old = self.history[(k - PROGRESS_WINDOW) % (PROGRESS_WINDOW + 1), moved]
        stuck = (k >= PROGRESS_WINDOW) & (np.hypot(*(q[fix] - old).T) < 2.0 * s.speed * s.dt)
        if stuck.any():
            self.finish(moved[stuck], Outcome.STALL)
            active = active[~np.isin(active, moved[stuck])]
        late = self.steps[active] > self.limits[active]
        if late.any():
            self.finish(active[late], Outcome.TIMEOUT)
            active = active[~late]
        return active

    def trajectories(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Coords, cells, headings and offsets of every run (departure points, then the final point)."""
        r = len(self.x)
        if not self.params.record_trajectories:
            return np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0), np.zeros(r + 1, np.int64)
        runs = np.concatenate([*(t[0] for t in self.trace), np.arange(r)])
        points = np.concatenate([*(t[1] for t in self.trace), self.x]) if r else np.zeros((0, 2))
        cells = np.concatenate([*(t[2] for t in self.trace), self.state.cell])
        final_heading = self.camera_heading(np.arange(r))
        heading = np.concatenate([*(t[3] for t in self.trace), final_heading])
        order = np.argsort(runs, kind="stable")  # steps were appended in time order
        offsets = np.concatenate([[0], np.cumsum(np.bincount(runs, minlength=r))]).astype(np.int64)
        return points[order], cells[order], heading[order], offsets


def initial_headings(arrays: PlanArrays, starts: np.ndarray, params: Params) -> np.ndarray:
    """The heading each run starts with (rad, shape (R,)): ``initial_heading``, or toward the exit
    point of the cell the start is located in (the goal in the goal cell), ALGORITHMS §7.1."""
    if params.initial_heading is not None:
        return np.full(len(starts), math.radians(params.initial_heading))
    if not len(starts):
        return np.zeros(0)
    cell = runtime.locate(arrays, starts)
    aim = np.where((arrays.parent_cell[cell] >= 0)[:, None], arrays.exit_point[cell], arrays.goal)
    d = aim - starts
    return np.arctan2(d[:, 1], d[:, 0])


def rollout(
    plan,
    starts: np.ndarray,
    params: Params = Params(),
    progress: Callable[[int, int], None] | None = None,
    world=None,
) -> Rollouts:
    """Run the closed loop from every start at once.

    Parameters
    ----------
    plan : Plan
        The synthesised plan (any object with the :class:`~bearnav_cli.datatypes.Plan` attributes).
    starts : ndarray, shape (R, 2)
        Start positions (map units). A start that is not free ends at once as a collision.
    params : Params
        Its ``starts`` field is ignored here (see :func:`run`).
    progress : callable, optional
        ``progress(finished_runs, R)`` every few steps.
    world : Map, optional
        The world the robots drive in, when it differs from the one the plan was made for
        (paper B's deformation test): its obstacles stop them and hide landmarks, its
        landmark positions are what the camera sees. The controllers, cells and goal stay
        the plan's. Default: the plan's map.

    Returns
    -------
    Rollouts
        Outcome, steps, time, path length, relocations and trajectory of every run.
    """
    arrays = PlanArrays.from_plan(plan)
    world = plan.map if world is None else world
    if len(world.landmarks) != len(arrays.landmarks):
        raise InvalidParamsError("the world must have the plan's landmarks (moved, not added)", field="world")
    space = FreeSpace.from_map(world)
    s = settings(plan, params)
    x0 = np.array(starts, float).reshape(-1, 2)
    limits = step_limits(arrays, x0, s, params)
    blocked = ~space.points_free(x0)
    heading = np.zeros(len(x0))
    if (~blocked).any():
        heading[~blocked] = initial_headings(arrays, x0[~blocked], params)
    loop = _Loop(arrays, space, x0, heading, s, params, limits, world.landmarks)
    if blocked.any():
        log.warning("%d starts are not free: counted as collisions", int(np.count_nonzero(blocked)))
        loop.finish(np.flatnonzero(blocked), Outcome.COLLISION)
    active = np.flatnonzero(~blocked)
    iteration = 0
    while active.size:
        active = loop.step(active)
        iteration += 1
        if progress is not None and iteration % PROGRESS_EVERY == 0:
            progress(len(x0) - len(active), len(x0))
    if progress is not None:
        progress(len(x0), len(x0))
    coords, cells, headings, offsets = loop.trajectories()
    return Rollouts(
        starts=x0,
        outcome=loop.outcome,
        steps=loop.steps,
        time=loop.steps * s.dt,
        path_length=loop.length,
        left_cell=loop.left,
        approach_steps=loop.approach,
        hold_steps=loop.held,
        certified_steps=loop.certified,
        start_in_domain=in_domain(arrays, x0),
        min_clearance=loop.clearance,
        final_position=loop.x,
        final_cell=loop.state.cell,
        max_steps=limits,
        trajectory_coords=coords,
        trajectory_cells=cells,
        trajectory_offsets=offsets,
        trajectory_heading=headings,
        speed=s.speed,
        dt=s.dt,
        eps_sw=s.eps_sw,
        goal_tolerance=s.goal_tolerance,
    )


def in_domain(arrays: PlanArrays, starts: np.ndarray) -> np.ndarray:
    """Whether each start lies in the certified domain ``D`` (some funnel cell holds it), shape (R,).

    Always False for ``paper`` plans, whose cells certify nothing beyond themselves.
    """
    if not arrays.funnel or not len(starts):
        return np.zeros(len(starts), bool)
    return runtime.least_rank_cell(arrays, starts) >= 0


def resolve_starts(plan, params: Params) -> np.ndarray:
    """The starts of :attr:`Params.starts` for this plan, shape (R, 2).

    Raises
    ------
    InvalidParamsError
        A start outside the bounds or inside an obstacle, named by its index and position.
    """
    spec = parse_starts(params.starts)
    space = FreeSpace.from_map(plan.map)
    if isinstance(spec, int):
        return sample_starts(space, plan.map.goal, spec, np.random.default_rng([params.seed, 1]))
    starts = np.asarray(plan.map.starts, float).reshape(-1, 2) if isinstance(spec, str) else spec
    inside = space.in_bounds(starts)
    blocked = space.in_obstacle(starts)
    for k, (x, y) in enumerate(starts):
        if not inside[k]:
            raise InvalidParamsError(f"start {k} ({x:g}, {y:g}) is outside the bounds", field="starts")
        if blocked[k]:
            raise InvalidParamsError(f"start {k} ({x:g}, {y:g}) is inside an obstacle", field="starts")
    return starts


def metrics(rollouts: Rollouts, routes: np.ndarray, goal: np.ndarray) -> dict:
    """The figures ``bearnav simulate`` prints and writes to ``sim.json``.

    Parameters
    ----------
    rollouts : Rollouts
    routes : ndarray, shape (R,)
        Tree route length ``L_route`` of each start (map units).
    goal : ndarray, shape (2,)
    """
    done = rollouts.outcome == Outcome.SUCCESS
    n = len(rollouts)

    def mean(values: np.ndarray) -> float | None:
        return float(np.mean(values)) if len(values) else None

    finish = np.hypot(*(rollouts.final_position - goal).T)  # the last straight bit into the goal ball
    ratio = (rollouts.path_length + finish)[done] / np.maximum(routes[done], 1e-300)
    return {
        "runs": n,
        "success_rate": float(np.mean(done)) if n else None,
        "outcomes": rollouts.counts(),
        "time_mean_s": mean(rollouts.time[done]),
        "time_max_s": float(np.max(rollouts.time[done])) if done.any() else None,
        "path_length_mean": mean(rollouts.path_length[done]),
        "path_over_tree_route_mean": mean(ratio),
        "min_clearance": float(np.min(rollouts.min_clearance)) if n else None,
        "left_cell_events": int(rollouts.left_cell.sum()),
        "runs_with_left_cell": int(np.count_nonzero(rollouts.left_cell > 0)),
        "runs_with_approach": int(np.count_nonzero(rollouts.approach_steps > 0)),
        "hold_time_total_s": float(rollouts.hold_steps.sum() * rollouts.dt),
        "certified_step_fraction": rollouts.certified_fraction,
        "runs_from_certified_domain": int(np.count_nonzero(rollouts.start_in_domain)),
        "success_rate_in_domain": _finite_or_none(rollouts.success_rate_of(rollouts.start_in_domain)),
        "success_rate_outside_domain": _finite_or_none(rollouts.success_rate_of(~rollouts.start_in_domain)),
        "dt": rollouts.dt,
    }


def _finite_or_none(value: float) -> float | None:
    return value if math.isfinite(value) else None


def run(plan, params: Params = Params(), progress: Callable[[int, int], None] | None = None) -> Simulation:
    """``bearnav simulate``: the starts of ``params.starts`` run through :func:`rollout`.

    Returns
    -------
    Simulation
        Every run's outcome, figures and trajectory, the metrics, and the tree and cells
        it ran on (so ``sim.npz`` alone can be drawn).
    """
    starts = resolve_starts(plan, params)
    rollouts = rollout(plan, starts, params, progress)
    routes = tree_routes(PlanArrays.from_plan(plan), starts) if len(starts) else np.zeros(0)
    cells = plan.cells
    return Simulation(
        map=plan.map,
        starts=starts,
        outcome=rollouts.outcome,
        steps=rollouts.steps,
        time=rollouts.time,
        path_length=rollouts.path_length,
        route_length=routes,
        left_cell=rollouts.left_cell,
        approach_steps=rollouts.approach_steps,
        hold_steps=rollouts.hold_steps,
        min_clearance=rollouts.min_clearance,
        final_position=rollouts.final_position,
        trajectory_coords=rollouts.trajectory_coords,
        trajectory_cells=rollouts.trajectory_cells,
        trajectory_heading=rollouts.trajectory_heading,
        trajectory_offsets=rollouts.trajectory_offsets,
        nodes=cells.nodes,
        parent=cells.parent,
        cell_vertices=cells.cell_vertices,
        cell_vertex_offsets=cells.cell_vertex_offsets,
        cell_status=plan.status,
        dt=float(rollouts.dt),
        stats=metrics(rollouts, routes, plan.map.goal),
    )


def summary(result: Simulation | Rollouts) -> str:
    """One line: success rate and the other outcomes."""
    counts = {o.name.lower(): int(np.count_nonzero(result.outcome == o)) for o in Outcome}
    others = ", ".join(f"{n} {name}" for name, n in counts.items() if name != "success" and n)
    text = f"{counts['success']}/{len(result.outcome)} runs reached the goal"
    return text + (f" ({others})" if others else "")
