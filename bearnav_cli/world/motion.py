"""The simulated base: how a step's command moves the robot (with wheel slip), and what it hits.

:class:`Base` integrates the command :func:`bearnav_cli.runtime.control` returns for one step
(the single integrator ``x ← x + dt·u`` or the unicycle ``x ← x + dt·v·(cos φ, sin φ)``,
``φ ← φ + dt·ω``, ALGORITHMS §7.1) and perturbs the displacement the way real wheels do: a
per-run scale (wheel radius) error and heading bias, plus a little per-step jitter
(:class:`Base` says how much). :class:`Contact` is the exact collision test of each step segment
(:meth:`~bearnav_cli.geometry.FreeSpace.segments_free`) and the bookkeeping of every run's
smallest clearance.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import shapely

from bearnav_cli import runtime
from bearnav_cli.geometry import FreeSpace, inflate
from bearnav_cli.runtime import PlanArrays, bearing

__all__ = ["Base", "Contact", "body_space", "initial_headings"]


def body_space(world, space: FreeSpace | None = None) -> FreeSpace:
    """The free space of the robot's body: the raw obstacles inflated by the robot radius ρ alone, ``B`` shrunk by ρ.

    A unicycle on a look-ahead plan (ALGORITHMS §12.6) is planned for ``p = x + λh``, against the
    obstacles inflated by ``ρ + λ`` (the map's ``obstacles``); what it must not hit is its body, the
    disc of radius ρ around the axle ``x``. This is the space :class:`Contact` tests the axle's steps
    against and measures its clearance in (the same inflation as the map stage's, with λ = 0).

    Parameters
    ----------
    world : Map
        The world: its raw obstacles, bounds, robot radius and tolerance.
    space : FreeSpace, optional
        ``FreeSpace.from_map(world)``, whose union of the raw obstacles is reused (built when None).
    """
    raw = (FreeSpace.from_map(world) if space is None else space).raw_obstacles
    rho = max(0.0, float(world.robot_radius))
    obstacles = inflate(raw, rho)
    shapely.prepare(obstacles)
    bounds = np.asarray(world.bounds, float)
    return FreeSpace(bounds + np.array([rho, rho, -rho, -rho]), world.tol, obstacles, raw, bounds)


def initial_headings(arrays: PlanArrays, starts: np.ndarray, heading: float | None = None) -> np.ndarray:
    """The heading each run starts with (rad, shape (R,)): ``heading`` (rad) for all, or (``None``)
    toward the exit point of the cell the start is located in (the goal in the goal cell), §7.1.

    Parameters
    ----------
    arrays : PlanArrays
        The plan: its cells (:func:`bearnav_cli.runtime.locate`), exit points and goal.
    starts : ndarray, shape (R, 2)
        Start positions (map units).
    heading : float, optional
        One initial heading for every run (rad); ``None``: toward each start's cell exit.
    """
    if heading is not None:
        return np.full(len(starts), float(heading))
    if not len(starts):
        return np.zeros(0)
    cell = runtime.locate(arrays, starts)
    aim = np.where((arrays.parent_cell[cell] >= 0)[:, None], arrays.exit_point[cell], arrays.goal)
    d = aim - starts
    return np.arctan2(d[:, 1], d[:, 0])


class Base:
    """The bases of ``R`` robots: commanded motion made true motion, with wheel slip.

    Wheel slip of size ``σ = slip`` is what odometry gets wrong about a robot's displacement,
    modelled as real odometry errs:

    * per run, drawn once: a scale error ``ε_s ~ N(0, σ²)`` (wheel radius: every step is
      ``1 + ε_s`` times as long as commanded) and a heading bias ``ε_h ~ N(0, σ²)`` (rad: every
      step is turned by ``ε_h`` from the commanded direction);
    * per step: jitter of the same size on both, ``N(0, σ²)``, drawn anew each step.

    Over a straight run of length ``d`` in steps of length ``ℓ`` the systematic part displaces the
    robot by ``ε_s·d`` along and ``≈ ε_h·d`` across its path, the jitter by only ``σ·√(d·ℓ)``: the
    error odometry accumulates has a standard deviation of ``σ·d·√(1 + ℓ/d) ≈ σ·d`` in each
    direction (``tests/test_world.py`` measures it). ``σ = 0`` is the exact motion of §7.1 (no
    random numbers drawn).

    Parameters
    ----------
    dynamics : {"single", "unicycle"}
        How a command moves the base (§7.1): the single integrator's ``x ← x + dt·u`` (its camera
        looks along the last command), or the unicycle's ``x ← x + dt·v·(cos φ, sin φ)``,
        ``φ ← φ + dt·ω``.
    dt : float
        Step (s).
    slip : float
        ``σ`` (relative; 0.02 = 2% of the distance travelled).
    runs : int
        ``R``: the per-run errors are drawn for every run at once.
    rng : numpy.random.Generator
        Source of the per-run errors, then of each step's jitter.
    bound : tuple of float, optional
        ``(κ, ν)``: bounded slip instead of ``slip`` — every step errs by at most ``κ‖d̂‖ + ν``
        (ALGORITHMS §12.8, :meth:`bounded_error`); ``None``: the Gaussian slip above.
    toward : callable, optional
        With ``bound``, the worst case: ``toward(x)`` (R, 2), the unit direction toward each robot's
        nearest obstacle, and every error at the bound along it.
    """

    def __init__(
        self,
        dynamics: str,
        dt: float,
        slip: float,
        runs: int,
        rng: np.random.Generator,
        bound: tuple[float, float] | None = None,
        toward: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        self.dynamics, self.dt, self.slip, self.rng = dynamics, float(dt), float(slip), rng
        self.bound, self.toward = bound, toward
        if bound is not None:
            # bounded slip: per run a fixed error direction and size in the robot's frame, per step a
            # jitter, mixed and kept within κ‖d̂‖ + ν (the worst case ignores them)
            angle, size = rng.uniform(-np.pi, np.pi, runs), np.sqrt(rng.uniform(0.0, 1.0, runs))
            self.scale_error, self.heading_bias = size * np.cos(angle), size * np.sin(angle)
        elif self.slip > 0:
            errors = self.slip * rng.standard_normal((runs, 2))
            self.scale_error, self.heading_bias = errors[:, 0].copy(), errors[:, 1].copy()
        else:
            self.scale_error = self.heading_bias = np.zeros(runs)

    def commanded(
        self,
        x: np.ndarray,
        heading: np.ndarray,
        velocity: np.ndarray,
        forward: np.ndarray,
        turn: np.ndarray,
        scanning: np.ndarray,
        last_dir: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The exact displacement of one step (R, 2) and the new camera headings (R,), ALGORITHMS §7.1.

        Parameters
        ----------
        x : ndarray, shape (R, 2)
            Positions (map units).
        heading : ndarray, shape (R,)
            The unicycle's yaw, or the single integrator's camera heading (rad).
        velocity : ndarray, shape (R, 2)
            Single integrator command (map units / s).
        forward, turn : ndarray, shape (R,)
            Unicycle command ``v`` (map units / s) and ``ω`` (rad / s; also the single integrator's
            camera turn while it looks around).
        scanning : ndarray of bool, shape (R,)
            The robot turns in place to look around.
        last_dir : ndarray, shape (R, 2)
            The single integrator's last command direction: its camera looks along it.
        """
        if self.dynamics == "unicycle":
            move = self.dt * forward[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
            return move, bearing.wrap(heading + self.dt * turn)
        look = np.where(scanning, bearing.wrap(heading + self.dt * turn), np.arctan2(last_dir[:, 1], last_dir[:, 0]))
        return self.dt * velocity, look

    def slipped(self, runs: np.ndarray, move: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
        """The true displacements (R, 2) of commanded displacements ``move`` of robots ``runs`` at ``x``."""
        if self.bound is not None and len(runs):
            return move + self.bounded_error(runs, move, x)
        if self.slip <= 0 or not len(runs):
            return move
        jitter = self.slip * self.rng.standard_normal((len(runs), 2))
        scale = 1.0 + self.scale_error[runs] + jitter[:, 0]
        turn = self.heading_bias[runs] + jitter[:, 1]
        c, s = np.cos(turn), np.sin(turn)
        return scale[:, None] * np.column_stack([c * move[:, 0] - s * move[:, 1], s * move[:, 0] + c * move[:, 1]])

    def step(
        self,
        runs: np.ndarray,
        x: np.ndarray,
        heading: np.ndarray,
        velocity: np.ndarray,
        forward: np.ndarray,
        turn: np.ndarray,
        scanning: np.ndarray,
        last_dir: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where the robots ``runs`` (shape (R,)) are after one step, and their new camera headings.

        See :meth:`commanded` for the arguments; the displacement is then :meth:`slipped`.
        """
        move, look = self.commanded(x, heading, velocity, forward, turn, scanning, last_dir)
        return x + self.slipped(runs, move, x), look

    def bounded_error(self, runs: np.ndarray, move: np.ndarray, x: np.ndarray | None) -> np.ndarray:
        """An odometry error within ``κ‖d̂‖ + ν`` for each displacement ``move`` (R, 2); 0 where it is 0.

        Uniform: ``0.7·(per-run error) + 0.3·(per-step jitter)``, both in the unit disc of the
        robot's frame, times the bound. Worst (``toward``): the bound itself, toward the nearest
        obstacle of ``x``.
        """
        kappa, floor = self.bound
        length = np.hypot(move[:, 0], move[:, 1])
        size = np.where(length > 0.0, kappa * length + floor, 0.0)
        if self.toward is not None and x is not None:
            return size[:, None] * self.toward(x)
        angle, radius = self.rng.uniform(-np.pi, np.pi, len(runs)), np.sqrt(self.rng.uniform(0.0, 1.0, len(runs)))
        along = 0.7 * self.scale_error[runs] + 0.3 * radius * np.cos(angle)
        across = 0.7 * self.heading_bias[runs] + 0.3 * radius * np.sin(angle)
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = np.where(length[:, None] > 0, move / length[:, None], 0.0)
        normal = np.column_stack([-unit[:, 1], unit[:, 0]])
        return size[:, None] * (along[:, None] * unit + across[:, None] * normal)


class Contact:
    """Collisions of every run with the world, and the smallest clearance along each run.

    Parameters
    ----------
    space : FreeSpace
        The world the robots drive in (inflated obstacles and the bounds).
    starts : ndarray, shape (R, 2)
        Where the runs begin (their first clearance).
    """

    def __init__(self, space: FreeSpace, starts: np.ndarray) -> None:
        self.space = space
        r = len(starts)
        #: Smallest clearance so far of each run (map units), shape (R,).
        self.clearance = space.clearance(starts) if r else np.zeros(0)
        self.last_clearance = self.clearance.copy()  # at each run's last query ...
        self.since = np.zeros(r)  # ... and the path length driven since

    def free(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Whether each step segment ``p → q`` (shapes (R, 2)) stays free: the exact segment test."""
        return self.space.segments_free(p, q)

    def track(self, runs: np.ndarray, p: np.ndarray, q: np.ndarray) -> None:
        """Update the smallest clearance of ``runs`` after their steps ``p → q``.

        Lazily: a step moves a robot at most its length closer to an obstacle, so a robot whose
        clearance at its last query, minus the distance driven since, is still above its minimum
        needs no query.
        """
        self.since[runs] += np.hypot(*(q - p).T)
        due = self.last_clearance[runs] - self.since[runs] < self.clearance[runs]
        if due.any():
            idx = runs[due]
            measured = self.space.clearance(q[due])
            self.clearance[idx] = np.minimum(self.clearance[idx], measured)
            self.last_clearance[idx], self.since[idx] = measured, 0.0

    def step(self, runs: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """:meth:`free` and :meth:`track` for one step of ``runs``; returns the free mask (R,)."""
        free = self.free(p, q)
        self.track(runs, p, q)
        return free
