"""``bearnav simulate``: the closed loop of ALGORITHMS §7, every robot advanced together.

This version simulates what ``verify`` needs: the single integrator
``x ← x + dt·v·unit(u)`` driven by the displacement output (``x̂ = x``), noise-free,
with a full field of view. Cell location, switching and the field come from
:mod:`bearnav_cli.runtime`, the code a robot runs.

All robots advance in lock step as arrays: one step is a handful of numpy
operations over the robots still running plus one batched, exact segment test
(:meth:`~bearnav_cli.geometry.FreeSpace.segments_free`) of their step segments
against the inflated obstacles and the bounds.

Extension points for the bearing mode, the field of view, noise and the unicycle:
:func:`_measure` returns the position estimate ``x̂`` and the output ``y`` each step
(where the bearing reconstruction and the hold policy go), and :func:`_integrate`
is the dynamics. :class:`Outcome` already reserves ``LOST``.
"""

from __future__ import annotations

import enum
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bearnav_cli import runtime
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.runtime import PlanArrays

VERSION = 1
log = logging.getLogger(__name__)

#: A robot must move ``2·v·dt`` net over this many steps, or it stalls (ALGORITHMS §7.2).
PROGRESS_WINDOW = 200
#: ``‖a − M x̂‖ < STALL_FIELD · u_max`` is a stall: the field has (almost) an equilibrium there.
STALL_FIELD = 1e-6
#: ``dt = min(DT_PER_DIAGONAL · D / v, DT_MAX)`` by default (ALGORITHMS §7.1).
DT_PER_DIAGONAL = 0.0025
DT_MAX = 0.2
#: How often (in steps) ``progress`` is called.
PROGRESS_EVERY = 25
#: Outcome of a robot still running (internal).
RUNNING = -1


class Outcome(enum.IntEnum):
    """How a run ended (ALGORITHMS §7.4)."""

    SUCCESS = 0  # within goal_tolerance of the goal
    COLLISION = 1  # a step segment met the inflated obstacles or left the bounds (or the start was not free)
    STALL = 2  # field below 1e-6·u_max, or no net progress over PROGRESS_WINDOW steps
    TIMEOUT = 3  # more than max_steps steps
    LOST = 4  # fewer than two usable landmarks for longer than hold_time (bearing mode; not produced yet)


@dataclass(frozen=True)
class Params:
    """Parameters of the closed loop (ALGORITHMS §7).

    Attributes
    ----------
    speed : float
        Reference speed ``v_ref`` (map units / s); the field only gives the direction.
    dt : float or None
        Euler step (s); ``None`` means ``min(0.0025·D/v, 0.2)`` with ``D`` the bounds' diagonal.
    goal_tolerance : float or None
        Success radius (map units); ``None`` takes the plan's.
    max_steps : int or None
        Step limit of every run; ``None`` means ``ceil(5·L_route/(v·dt)) + 1000`` per run, with
        ``L_route = ‖x₀ − x_n‖ + cost(n)`` and ``n`` the start's nearest tree node.
    seed : int
        Seed of ``numpy.random.default_rng`` (measurement noise, in a later version).
    record_trajectories : bool
        Keep every robot's trajectory (``verify`` turns this off).
    """

    speed: float = 0.1
    dt: float | None = None
    goal_tolerance: float | None = None
    max_steps: int | None = None
    seed: int = 0
    record_trajectories: bool = True

    def __post_init__(self) -> None:
        if not (self.speed > 0 and math.isfinite(self.speed)):
            raise InvalidParamsError(f"must be positive, got {self.speed}", field="speed")
        if self.dt is not None and not (self.dt > 0 and math.isfinite(self.dt)):
            raise InvalidParamsError(f"must be positive, got {self.dt}", field="dt")
        if self.goal_tolerance is not None and not (self.goal_tolerance > 0 and math.isfinite(self.goal_tolerance)):
            raise InvalidParamsError(f"must be positive, got {self.goal_tolerance}", field="goal_tolerance")
        if self.max_steps is not None and (
            isinstance(self.max_steps, bool) or int(self.max_steps) != self.max_steps or self.max_steps < 1
        ):
            raise InvalidParamsError(f"must be a positive integer, got {self.max_steps}", field="max_steps")


@dataclass(frozen=True)
class Settings:
    """Concrete loop constants for one plan (the ``None`` defaults of :class:`Params` filled in).

    Attributes
    ----------
    speed, dt : float
        ``v`` (map units / s) and the step (s).
    eps_sw : float
        Switching radius ``2·v·dt`` around the exit point (map units).
    goal_tolerance : float
        Success radius (map units).
    tol : float
        ``1e-9·D``, the membership slack of switching.
    """

    speed: float
    dt: float
    eps_sw: float
    goal_tolerance: float
    tol: float


def settings(plan, params: Params) -> Settings:
    """Resolve :class:`Params` against a plan (``dt`` from the map's diagonal, the plan's tolerance)."""
    diagonal = plan.map.diagonal
    dt = params.dt if params.dt is not None else min(DT_PER_DIAGONAL * diagonal / params.speed, DT_MAX)
    goal_tolerance = params.goal_tolerance if params.goal_tolerance is not None else float(plan.goal_tolerance)
    return Settings(params.speed, dt, 2.0 * params.speed * dt, goal_tolerance, plan.map.tol)


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
    final_position : ndarray, shape (R, 2)
    final_cell : ndarray of int64, shape (R,)
        Active cell at the end (``-1`` if the start was not free).
    max_steps : ndarray of int64, shape (R,)
        Step limit of each run.
    trajectory_coords, trajectory_cells, trajectory_offsets : ndarray, shapes (P, 2), (P,), (R + 1,)
        Run ``r`` visits ``trajectory_coords[o[r]:o[r + 1]]`` (start first, ``steps + 1`` points);
        ``trajectory_cells`` is the cell whose field moved the robot on from each point (the
        active cell at the end for the last point). Empty when trajectories are not recorded.
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
    final_position: np.ndarray
    final_cell: np.ndarray
    max_steps: np.ndarray
    trajectory_coords: np.ndarray
    trajectory_cells: np.ndarray
    trajectory_offsets: np.ndarray
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


def step_limits(arrays: PlanArrays, starts: np.ndarray, s: Settings, params: Params) -> np.ndarray:
    """``max_steps`` of each run (ALGORITHMS §7.2), shape (R,)."""
    if params.max_steps is not None:
        return np.full(len(starts), int(params.max_steps), np.int64)
    cost = runtime.tree_costs(arrays.nodes, arrays.parent)
    near = runtime.nearest_node(arrays, starts)
    route = np.hypot(*(starts - arrays.nodes[near]).T) + cost[near]
    return np.ceil(5.0 * route / (s.speed * s.dt)).astype(np.int64) + 1000


class _Loop:
    """Mutable state of every robot during :func:`rollout` (arrays indexed by run)."""

    def __init__(self, arrays: PlanArrays, space: FreeSpace, starts: np.ndarray, s: Settings, limits: np.ndarray,
                 record: bool):  # fmt: skip
        r = len(starts)
        self.arrays, self.space, self.s, self.limits, self.record = arrays, space, s, limits, record
        self.x = starts.copy()
        self.outcome = np.full(r, RUNNING, np.int8)
        self.steps = np.zeros(r, np.int64)
        self.length = np.zeros(r)
        self.left = np.zeros(r, np.int64)
        self.cell = np.full(r, -1, np.int64)  # -1: located on the first step
        self.target = np.full(r, -1, np.int64)  # node approached in a straight line, -1 for none
        self.approach_steps = np.zeros(r, np.int64)
        self.history = np.empty((PROGRESS_WINDOW + 1, r, 2))  # ring buffer of positions, by step count
        self.history[0] = starts
        self.trace_runs: list[np.ndarray] = []
        self.trace_points: list[np.ndarray] = []
        self.trace_cells: list[np.ndarray] = []

    def finish(self, runs: np.ndarray, outcome: Outcome) -> None:
        self.outcome[runs] = outcome

    def step(self, active: np.ndarray) -> np.ndarray:
        """Advance the robots ``active`` by one step (ALGORITHMS §7.2); return those still running."""
        s, arrays = self.s, self.arrays
        p = self.x[active]
        arrived = np.hypot(*(p - arrays.goal).T) <= s.goal_tolerance
        if arrived.any():
            self.finish(active[arrived], Outcome.SUCCESS)
            active, p = active[~arrived], p[~arrived]
            if not active.size:
                return active
        x_hat, y = _measure(arrays, p)
        cell, target, moved_out = runtime.update(arrays, self.cell[active], self.target[active], x_hat, s.eps_sw, s.tol)
        self.cell[active] = cell
        self.target[active] = target
        self.left[active] += moved_out
        self.approach_steps[active] += target >= 0
        u = runtime.apply_gain(arrays, cell, y)
        idle = np.hypot(*runtime.affine_field(arrays, cell, x_hat).T) < STALL_FIELD * arrays.u_max[cell]
        going = target >= 0
        if going.any():
            u[going] = arrays.nodes[target[going]] - x_hat[going]  # straight to the node (docs/choices.md)
            idle[going] = False
        idle |= ~(np.hypot(u[:, 0], u[:, 1]) > 0)  # no direction to normalise (rounding, NaN)
        if idle.any():
            self.finish(active[idle], Outcome.STALL)
            active, p, u, cell = active[~idle], p[~idle], u[~idle], cell[~idle]
            if not active.size:
                return active
        q = _integrate(p, u, s)
        free = self.space.segments_free(p, q)
        if self.record:
            self.trace_runs.append(active)
            self.trace_points.append(p)
            self.trace_cells.append(cell)
        self.x[active] = q
        self.steps[active] += 1
        self.length[active] += np.hypot(*(q - p).T)
        if not free.all():
            self.finish(active[~free], Outcome.COLLISION)
            active, q = active[free], q[free]
        k = self.steps[active]
        self.history[k % (PROGRESS_WINDOW + 1), active] = q
        old = self.history[(k - PROGRESS_WINDOW) % (PROGRESS_WINDOW + 1), active]
        stuck = (k >= PROGRESS_WINDOW) & (np.hypot(*(q - old).T) < 2.0 * s.speed * s.dt)
        if stuck.any():
            self.finish(active[stuck], Outcome.STALL)
            active, k = active[~stuck], k[~stuck]
        late = k > self.limits[active]
        if late.any():
            self.finish(active[late], Outcome.TIMEOUT)
            active = active[~late]
        return active

    def trajectories(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Coords, cells and offsets of every run's trajectory (departure points, then the final point)."""
        r = len(self.x)
        if not self.record:
            return np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(r + 1, np.int64)
        runs = np.concatenate([*self.trace_runs, np.arange(r)])
        points = np.concatenate([*self.trace_points, self.x]) if r else np.zeros((0, 2))
        cells = np.concatenate([*self.trace_cells, self.cell])
        order = np.argsort(runs, kind="stable")  # steps were appended in time order
        offsets = np.concatenate([[0], np.cumsum(np.bincount(runs, minlength=r))]).astype(np.int64)
        return points[order], cells[order], offsets


def _measure(arrays: PlanArrays, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position estimate ``x̂`` and output ``y`` of each robot: displacement mode, ``x̂ = x``.

    Returns
    -------
    x_hat : ndarray, shape (R, 2)
    y : ndarray, shape (R, 2L)
        ``(landmarks − x̂).ravel()``.
    """
    return x, runtime.displacement(arrays, x)


def _integrate(x: np.ndarray, u: np.ndarray, s: Settings) -> np.ndarray:
    """Single integrator at constant speed: ``x + dt·v·unit(u)`` (ALGORITHMS §7.1), shape (R, 2)."""
    norm = np.hypot(u[:, 0], u[:, 1])
    return x + (s.dt * s.speed / norm)[:, None] * u


def rollout(
    plan,
    starts: np.ndarray,
    params: Params = Params(),
    progress: Callable[[int, int], None] | None = None,
) -> Rollouts:
    """Run the closed loop from every start at once.

    Parameters
    ----------
    plan : Plan
        The synthesised plan (any object with the :class:`~bearnav_cli.datatypes.Plan` attributes).
    starts : ndarray, shape (R, 2)
        Start positions (map units). A start that is not free ends at once as a collision.
    params : Params
    progress : callable, optional
        ``progress(finished_runs, R)`` every few steps.

    Returns
    -------
    Rollouts
        Outcome, steps, time, path length, relocations and trajectory of every run.
    """
    arrays = PlanArrays.from_plan(plan)
    space = FreeSpace.from_map(plan.map)
    s = settings(plan, params)
    x0 = np.array(starts, float).reshape(-1, 2)
    limits = step_limits(arrays, x0, s, params)
    loop = _Loop(arrays, space, x0, s, limits, params.record_trajectories)
    blocked = ~space.points_free(x0)
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
    coords, cells, offsets = loop.trajectories()
    return Rollouts(
        starts=x0,
        outcome=loop.outcome,
        steps=loop.steps,
        time=loop.steps * s.dt,
        path_length=loop.length,
        left_cell=loop.left,
        approach_steps=loop.approach_steps,
        final_position=loop.x,
        final_cell=loop.cell,
        max_steps=limits,
        trajectory_coords=coords,
        trajectory_cells=cells,
        trajectory_offsets=offsets,
        speed=s.speed,
        dt=s.dt,
        eps_sw=s.eps_sw,
        goal_tolerance=s.goal_tolerance,
    )


def summary(rollouts: Rollouts) -> str:
    """One line: success rate and the other outcomes."""
    counts = rollouts.counts()
    others = ", ".join(f"{n} {name}" for name, n in counts.items() if name != "success" and n)
    text = f"{counts['success']}/{len(rollouts)} runs reached the goal"
    return text + (f" ({others})" if others else "")
