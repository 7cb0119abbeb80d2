"""The lock-step loop of ``bearnav simulate``: every robot's state in the simulated world, advanced one step at a time.

Each step asks the camera what the robots see, hands it to :func:`bearnav_cli.runtime.control` (the
very function a robot runs), moves the bases and tests the contact (:mod:`bearnav_cli.world.motion`),
then books what ended (ALGORITHMS §7.2): the goal reached, lost, stalled (the no-progress window),
a collision, the step limit. It also keeps the §12.8 counts of the estimator and the recorded
trajectories. ``stages.simulate.start_loop`` builds a :class:`Loop` and ``rollout`` steps it until
every run has ended; :func:`trace_estimates` records one run's estimate sets on the way.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from bearnav_cli import runtime
from bearnav_cli.datatypes import Outcome
from bearnav_cli.runtime import ControlState, PlanArrays, bearing
from bearnav_cli.runtime import bounded as runtime_bounded
from bearnav_cli.runtime import robot as runtime_robot
from bearnav_cli.world.camera import Camera
from bearnav_cli.world.motion import Base, Contact

__all__ = ["EstimateTrace", "Loop", "RUNNING", "trace_estimates"]

#: Outcome of a robot still running.
RUNNING = -1


class Loop:
    """Mutable state of every robot during ``stages.simulate.rollout`` (arrays indexed by run).

    The world around the controller is three objects: ``camera`` (None for the displacement
    measurement), ``base`` (:class:`~bearnav_cli.world.motion.Base`) and ``contact``
    (:class:`~bearnav_cli.world.motion.Contact`); the rest is the loop's own bookkeeping. ``s`` and
    ``params`` are the simulate stage's ``Settings`` (``goal_tolerance``, ``control``, ``speed``, ``dt``)
    and ``Params`` (``measurement``, ``record_trajectories``); ``window`` is its no-progress window
    (``PROGRESS_WINDOW``, in steps with a fix).

    Parameters
    ----------
    arrays : PlanArrays
        The plan's run-time view.
    camera : Camera or None
        What measures the bearings (None: the true displacements are fed).
    base : Base
        The robots' motion.
    contact : Contact
        The collision test and the clearance.
    starts : ndarray, shape (R, 2)
        Start of every run (map units; a look-ahead robot's look-ahead point).
    heading : ndarray, shape (R,)
        Initial headings (rad).
    s : Settings
        The loop's constants.
    params : Params
        The stage's parameters.
    limits : ndarray of int, shape (R,)
        Step limit of every run.
    world_landmarks : ndarray, shape (L, 2), optional
        The landmarks of the world the robots drive in; default the plan's.
    lookahead : float
        ``λ`` (map units): the plan is about the point ``λ`` ahead of the axle.
    window : int
        The no-progress window (steps with a fix).
    compass : ndarray, shape (R,), optional
        Each run's compass error (rad): the heading the robot reads is the true one plus it, so every world-frame
        bearing it forms turns by it, and a world-frame command it gives is turned back by it; default none.
    """

    def __init__(
        self,
        arrays: PlanArrays,
        camera: Camera | None,
        base: Base,
        contact: Contact,
        starts: np.ndarray,
        heading: np.ndarray,
        s: Any,
        params: Any,
        limits: np.ndarray,
        world_landmarks: np.ndarray | None = None,
        lookahead: float = 0.0,
        *,
        window: int,
        compass: np.ndarray | None = None,
    ):
        r = len(starts)
        self.compass = np.zeros(r) if compass is None else np.asarray(compass, float).reshape(r)
        self.arrays, self.camera, self.base, self.contact = arrays, camera, base, contact
        self.s, self.params, self.limits = s, params, limits
        self.window = int(window)
        # λ of a unicycle on a look-ahead plan (ALGORITHMS §12.6): the world state is the axle x and
        # the heading; the plan, the goal and what is recorded are about the point p = x + λh(φ)
        self.lookahead = float(lookahead)
        self.phi = heading.copy()  # unicycle yaw; the single integrator's camera looks along its last command
        self.x = runtime_robot.lookahead_point(starts, heading, -self.lookahead)  # the axle, λ behind p
        self.state = ControlState.initial(heading)
        self.outcome = np.full(r, RUNNING, np.int8)
        self.steps = np.zeros(r, np.int64)
        self.moving_steps = np.zeros(r, np.int64)  # steps with a fix: the no-progress window counts these
        self.length = np.zeros(r)
        self.left = np.zeros(r, np.int64)
        self.approach = np.zeros(r, np.int64)
        self.held = np.zeros(r, np.int64)
        self.certified = np.zeros(r, np.int64)
        # ALGORITHMS §12.8's counts: steps that translated, looks begun and steps spent looking, empty
        # sets, and steps on which the truth lay outside the estimate's set (or beyond its bound)
        self.moved = np.zeros(r, np.int64)
        self.looks = np.zeros(r, np.int64)
        self.look_steps = np.zeros(r, np.int64)
        self.inconsistencies = np.zeros(r, np.int64)
        self.violations = np.zeros(r, np.int64)
        self.was_looking = np.zeros(r, bool)
        # the claimed error e_t against the true one, over the steps with a finite claim: sums and the
        # largest share of its claim an error used (above 1 only where a bound was broken)
        self.claims = np.zeros(3)  # steps, Σ e_t, Σ ‖x − x̂‖
        self.claim_used = 0.0
        self.history = np.zeros((self.window + 1, r, 2))  # ring buffer of positions, by moving steps
        self.history[0] = starts
        self.trace: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self.world = arrays.landmarks if world_landmarks is None else np.asarray(world_landmarks, float)
        # paper B's deformed world, displacement-fed: the controller measures the moved landmarks
        self.moved_world = self.world is not arrays.landmarks and params.measurement == "displacement"

    def finish(self, runs: np.ndarray, outcome: Outcome) -> None:
        self.outcome[runs] = outcome

    def reference(self, x: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """The point the plan is about: the axle ``x`` itself, or ``x + λh(φ)`` with a look-ahead, shape (R, 2)."""
        return runtime_robot.lookahead_point(x, heading, self.lookahead)

    @property
    def position(self) -> np.ndarray:
        """:meth:`reference` of every run now (R, 2): what the goal test, the record and the metrics use."""
        return self.reference(self.x, self.phi)

    def measure(self, idx: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World-frame bearings (R, L, 2) and what the camera sees (R, L), ALGORITHMS §6.1."""
        if self.camera is None:  # displacement measurement: no camera
            n_lm = len(self.world)
            return np.zeros((len(idx), n_lm, 2)), np.ones((len(idx), n_lm), bool)
        return self.camera.measure(idx, p, self.phi[idx])

    def step(self, active: np.ndarray) -> np.ndarray:
        """Advance the robots ``active`` by one step (ALGORITHMS §7.2); return those still running."""
        s, arrays, params = self.s, self.arrays, self.params
        p = self.x[active]  # the axle, where the camera is and what the body's collisions are about
        ref = self.reference(p, self.phi[active])
        arrived = np.hypot(*(ref - arrays.goal).T) <= s.goal_tolerance
        if arrived.any():
            self.finish(active[arrived], Outcome.SUCCESS)
            active, p, ref = active[~arrived], p[~arrived], ref[~arrived]
            if not active.size:
                return active
        bearings, seen = self.measure(active, p)
        compass = self.compass[active]
        biased = bool(compass.any())
        if biased:  # the robot turns its camera's bearings into the world frame with the heading it reads
            bearings = bearing.rotated(bearings, compass[:, None])
        measured = (self.world[None] - p[:, None, :]) if self.moved_world else None
        out = runtime.control(
            arrays,
            s.control,
            self.state.take(active),
            bearings,
            seen,
            self.phi[active] + compass,
            x_true=p,
            displacements=measured,
        )
        heading = self.phi[active]
        self.state.put(active, out.state)
        self.left[active] += out.relocated
        self.approach[active] += out.state.target >= 0
        self.held[active] += ~out.fix
        ended = np.zeros(len(active), bool)
        for mask, outcome in ((out.lost, Outcome.LOST), (out.stalled, Outcome.STALL)):
            hit = mask & ~ended
            if hit.any():
                self.finish(active[hit], outcome)
                ended |= hit
        # a certified step is one the robot takes: a run that ends lost or stalled here takes none
        # (counting it broke `certified_steps <= steps` of sim.npz for every stalled run)
        self.certified[active[~ended]] += out.certified[~ended]
        self.count_estimates(active, p, ref, out)
        # the no-progress window counts steps with a fix the robot drives on (not those it waits out)
        command = (out.velocity, out.forward, out.turn, out.scanning, out.fix & ~out.looking)
        if ended.any():
            keep = ~ended
            active, p, ref, heading = active[keep], p[keep], ref[keep], heading[keep]
            command = tuple(c[keep] for c in command)
            if not active.size:
                return active
        velocity, forward, turn, scanning, fix = command
        last_dir = self.state.last_dir[active]
        if biased:  # a world-frame command goes to the wheels through the heading read: it turns by −(compass error)
            # (a unicycle's forward speed and turn rate do not; its true heading carries them)
            back = -self.compass[active]
            velocity, last_dir = bearing.rotated(velocity, back), bearing.rotated(last_dir, back)
        q, self.phi[active] = self.base.step(active, p, self.phi[active], velocity, forward, turn, scanning, last_dir)
        free = self.contact.free(p, q)
        if params.record_trajectories:
            self.trace.append((active, ref, self.state.cell[active].copy(), heading))
        self.x[active] = q
        moved_to = self.reference(q, self.phi[active])
        self.steps[active] += 1
        self.length[active] += np.hypot(*(moved_to - ref).T)
        self.contact.track(active, p, q)
        if not free.all():
            self.finish(active[~free], Outcome.COLLISION)
            active, moved_to, fix = active[free], moved_to[free], fix[free]
        # no-progress window (§7.2), over the steps with a fix: a robot holding still to turn is not stuck
        moved = active[fix]
        self.moving_steps[moved] += 1
        k = self.moving_steps[moved]
        self.history[k % (self.window + 1), moved] = moved_to[fix]
        old = self.history[(k - self.window) % (self.window + 1), moved]
        stuck = (k >= self.window) & (np.hypot(*(moved_to[fix] - old).T) < 2.0 * s.speed * s.dt)
        if stuck.any():
            self.finish(moved[stuck], Outcome.STALL)
            active = active[~np.isin(active, moved[stuck])]
        late = self.steps[active] > self.limits[active]
        if late.any():
            self.finish(active[late], Outcome.TIMEOUT)
            active = active[~late]
        return active

    def count_estimates(self, active: np.ndarray, axle: np.ndarray, ref: np.ndarray, out) -> None:
        """Add one step of §12.8's counts for the runs ``active``: looks, moves, empty sets, violations.

        A violation is a step on which the truth lies outside what the estimator claims: outside the
        set ``X_t`` (the axle's, for the set estimator), or farther from ``x̂`` than its 3σ (the filter).
        """
        translated = np.any(out.velocity != 0.0, axis=1) | (out.forward != 0.0)
        self.moved[active] += translated
        looking = out.looking
        self.looks[active] += looking & ~self.was_looking[active]
        self.look_steps[active] += looking
        self.was_looking[active] = looking
        self.inconsistencies[active] += out.inconsistent
        known = out.state.known
        if self.s.control.estimator == "set":
            inside = runtime_bounded.contains(out.state.set_vertices, out.state.set_count, axle, 10.0 * self.arrays.tol)
        else:
            with np.errstate(invalid="ignore"):
                inside = np.hypot(*(ref - out.x_hat).T) <= out.error_bound + 10.0 * self.arrays.tol
            known = known & np.isfinite(out.error_bound) & np.any(out.x_hat != 0.0, axis=1)
        self.violations[active] += known & ~inside
        claimed = known & np.isfinite(out.error_bound) & (out.error_bound > 0.0)
        if claimed.any():
            bound = out.error_bound[claimed]
            true = np.hypot(*(ref[claimed] - out.x_hat[claimed]).T)
            self.claims += (len(bound), float(bound.sum()), float(true.sum()))
            self.claim_used = max(self.claim_used, float(np.max(true / bound)))

    def estimate_counts(self) -> dict:
        """The totals of :meth:`count_estimates` over every run, for the metrics."""
        steps, bound, true = self.claims
        return {
            "moved_steps": int(self.moved.sum()),
            "looks": int(self.looks.sum()),
            "look_steps": int(self.look_steps.sum()),
            "inconsistencies": int(self.inconsistencies.sum()),
            "containment_violations": int(self.violations.sum()),
            "error_bound_mean": bound / steps if steps else None,
            "true_error_mean": true / steps if steps else None,
            "error_used_max": self.claim_used if steps else None,
        }

    def trajectories(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Coords, cells, headings and offsets of every run (departure points, then the final point)."""
        r = len(self.x)
        if not self.params.record_trajectories:
            return np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0), np.zeros(r + 1, np.int64)
        runs = np.concatenate([*(t[0] for t in self.trace), np.arange(r)])
        points = np.concatenate([*(t[1] for t in self.trace), self.position]) if r else np.zeros((0, 2))
        cells = np.concatenate([*(t[2] for t in self.trace), self.state.cell])
        heading = np.concatenate([*(t[3] for t in self.trace), self.phi])
        order = np.argsort(runs, kind="stable")  # steps were appended in time order
        offsets = np.concatenate([[0], np.cumsum(np.bincount(runs, minlength=r))]).astype(np.int64)
        return points[order], cells[order], heading[order], offsets


@dataclass(frozen=True, eq=False)
class EstimateTrace:
    """One run's estimate sets along its path (ALGORITHMS §12.2), every ``every`` steps: what a figure draws.

    Attributes
    ----------
    truth : ndarray, shape (K, 2)
        The true position of the axle (the point the set is about) at each recorded step (map units).
    x_hat : ndarray, shape (K, 2)
        The estimate there (map units).
    error : ndarray, shape (K,)
        Its error radius ``e`` (map units).
    set_coords : ndarray, shape (V, 2)
        The sets' vertices, one after another (map units; shapely's ragged layout).
    set_offsets : ndarray of int64, shape (K + 1,)
        Where each recorded set's vertices begin in ``set_coords``.
    looking : ndarray of bool, shape (K,)
        The robot was looking (not driving) at that step.
    outcome : int
        The run's :class:`~bearnav_cli.datatypes.Outcome`.
    """

    truth: np.ndarray
    x_hat: np.ndarray
    error: np.ndarray
    set_coords: np.ndarray
    set_offsets: np.ndarray
    looking: np.ndarray
    outcome: int


def trace_estimates(loop: Loop, active: np.ndarray, every: int) -> EstimateTrace:
    """Step one robot's ``loop`` (of the set estimator) until it ends, recording its sets every ``every`` steps.

    Parameters
    ----------
    loop : Loop
        A loop of one run, before its first step, whose estimator is ``"set"``.
    active : ndarray of int
        The runs to step (``[0]``, or empty when the start was not free).
    every : int
        Record one step in this many (and the last).
    """
    records = []  # (axle, set vertices, looking) of the recorded steps
    step, last = 0, None  # last: the latest step's record, kept until recorded
    while active.size:
        axle = loop.x[0].copy()  # where the robot was when the step's bearings were taken
        active = loop.step(active)
        step += 1
        if not active.size and loop.outcome[0] == Outcome.SUCCESS:
            # arrival ends a step before its bearings are taken: the set is still the previous step's,
            # which holds the previous axle, not this one
            break
        n = int(loop.state.set_count[0])
        last = (axle, loop.state.set_vertices[0, :n].copy(), bool(loop.was_looking[0])) if n else None
        if last is not None and not (step % every and active.size):
            records.append(last)
            last = None
    if last is not None:  # the last step with a set, when it was not one of every `every`
        records.append(last)
    truth = [r[0] for r in records]
    sets = [r[1] for r in records]
    looking = [r[2] for r in records]
    centres = [runtime_bounded.centre(v[None], np.array([len(v)])) for v in sets]
    x_hat = [c[0][0] for c in centres]
    error = [c[1][0] for c in centres]
    offsets = np.concatenate([[0], np.cumsum([len(v) for v in sets])]).astype(np.int64)
    return EstimateTrace(
        np.array(truth).reshape(-1, 2),
        np.array(x_hat).reshape(-1, 2),
        np.array(error),
        np.concatenate(sets) if sets else np.zeros((0, 2)),
        offsets,
        np.array(looking, bool),
        int(loop.outcome[0]),
    )
