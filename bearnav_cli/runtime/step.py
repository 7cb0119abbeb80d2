"""The control step: one camera frame in, one command out, for ``R`` robots (ALGORITHMS §7, §11.3–11.4, §12.3).

Numpy only. :func:`control` (the filter) and :func:`bounded_control` (the set estimator) compose
steps that can be tested alone: the fix and its fusion with odometry
(:mod:`~bearnav_cli.runtime.estimate`), the cell policy and the field (:func:`follow_fields`),
looking for landmarks (:mod:`~bearnav_cli.runtime.looking`), the safety rules
(:mod:`~bearnav_cli.runtime.safety`) and the unicycle (:mod:`~bearnav_cli.runtime.unicycle`); the
constants, memory and output of the step are in :mod:`~bearnav_cli.runtime.settings`. ``bearnav
simulate`` advances its robots with :func:`control`, and
:class:`~bearnav_cli.runtime.controller.Controller` takes the same step on a robot, so what is
simulated is what runs on the robot.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from bearnav_cli.runtime import bearing, bounded
from bearnav_cli.runtime.cell_policy import (
    affine_field,
    apply_gain,
    cell_slack,
    displacement,
    least_rank_cell,
    least_rank_cell_holding,
    update,
)
from bearnav_cli.runtime.estimate import Estimate, bounded_update, fuse, measure
from bearnav_cli.runtime.looking import look_around, look_time
from bearnav_cli.runtime.plan_arrays import PlanArrays
from bearnav_cli.runtime.robot import lookahead_command, lookahead_point
from bearnav_cli.runtime.safety import (
    StepError,
    bend_inward,
    carry_inside,
    certified_pace,
    error_ball_pace,
    steer_clear,
)
from bearnav_cli.runtime.settings import ControlOutput, ControlSettings, ControlState
from bearnav_cli.runtime.tolerance import set_tolerance, step_reach
from bearnav_cli.runtime.unicycle import heading_allowance, unicycle_command

__all__ = ["STALL_FIELD", "bounded_control", "control", "follow_fields"]

#: ``‖a − M x̂‖ < STALL_FIELD · u_max`` is a stall: the field has (almost) an equilibrium there.
STALL_FIELD = 1e-6
#: How many times a step that slides along a near face is bent inward (:func:`~bearnav_cli.runtime.safety.bend_inward`)
#: before the best pace found is taken: each bend is sized for the step's error at the last direction.
BENDS = 3
#: How many headings, evenly spaced, a look-ahead unicycle without a cell tries for one that starts the certificate
#: (5° apart: ``p`` moves ``0.09λ`` between two).
HEADINGS = 72


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
    cell, target, last_dir, u, stalled, relocated = follow_fields(
        arrays, policy, state, est, bearings, visible, displacements
    )
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
    new = ControlState(
        cell,
        target,
        last_dir,
        est.hold,
        np.where(est.known[:, None], x_hat, state.x_hat),
        motion,
        est.known,
        est.var,
        scanning,
        spin,
        look,
        np.where(scanning & ~state.scanning, est.hold - s.dt, state.scan_from),
        state.set_vertices,
        state.set_count,
        state.resume,
        state.bound_scale,
    )
    # certified (§11.4): a funnel plan, driven by a certified cell's field (not a straight approach),
    # on an estimate whose error bound is within the cell's τ_c; a unicycle only as the
    # look-ahead point of §12.6 (λ > 0), and not on a step the reverse clamp changed
    certified = arrays.funnel & est.steer & (target < 0) & (cell >= 0) & within & ~clamped
    if s.dynamics == "unicycle" and not ahead:
        certified = np.zeros(len(cell), bool)  # λ = 0: the heading rules keep it safe in practice, unproven
    return ControlOutput(
        velocity,
        forward,
        turn,
        scanning,
        new,
        est.fix,
        lost,
        stalled,
        relocated,
        np.where(est.steer[:, None], x_hat, 0.0),
        certified,
        waiting,
        scanning | waiting,
        est.error_bound,
        np.zeros(len(cell), bool),
    )


def bounded_control(
    arrays: PlanArrays,
    s: ControlSettings,
    state: ControlState,
    bearings: np.ndarray,
    visible: np.ndarray,
    heading: np.ndarray,
    x_true: np.ndarray | None = None,
) -> ControlOutput:
    """One step of the certified policy of ALGORITHMS §12.3 on the estimate sets of §12.2, for ``R`` robots.

    The set ``X_t`` and its estimate ``x̂`` with error ``e`` come from
    :func:`~bearnav_cli.runtime.estimate.bounded_update`; a look-ahead unicycle's policy runs at
    ``p̂ = x̂ + λh(θ)`` with the error ``e + 2λ sin(ψ/2)``. Then, for each robot:

    - **in a cell** (the least-rank cell ``k`` with ``p̂ ∈ P_k ⊖ e``, switched to only at lower rank,
      :func:`~bearnav_cli.runtime.cell_policy.update` with erosion ``e``): it **moves** with the cell's
      field only while ``e + κℓ + ν`` is at most ``τ_c`` or what the cell tolerates over the set
      (:func:`~bearnav_cli.runtime.tolerance.set_tolerance`; ``ℓ = v·dt``); every such step is certified;
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
    slip, floor = (0.0, 0.0) if s.measurement == "displacement" else (s.drift, s.slip_floor)
    margin = slip * step_len + floor
    est = Estimate(
        reference, error**2 / 9.0, sets.seen, known & np.isfinite(error), known, np.where(known, state.hold, 0.0), error
    )
    reach = step_reach(step_len, slip, floor, lam)

    def step_pace(k: np.ndarray, point: np.ndarray, e: np.ndarray, direction: np.ndarray, heading: np.ndarray):
        """The certified pace of a step along ``direction`` in cells ``k`` from ``point`` with error ``e``, and the
        direction bent inward where that lets it go farther (a field may slide along a near face)."""

        # the motion's own error: the odometry bound, and a look-ahead point's swing on the arc its turn
        # rate gives (no odometry enters a measured displacement)
        def motion(d: np.ndarray, who: np.ndarray) -> StepError:
            return StepError.of(step_len, slip, floor, d, heading[who], lam if ahead else 0.0)

        everyone = np.arange(len(k))
        direction = direction.copy()
        pace = certified_pace(arrays, k, point, e, direction, motion(direction, everyone))
        slow = np.flatnonzero(pace < 1.0)
        bent = direction[slow]
        for _ in range(BENDS):  # bend inward just enough, if that helps (a bend turns the look-ahead point's step
            # across the heading, so its own swing grows: bend again, those still short of a whole step)
            bent = bend_inward(arrays, k[slow], point[slow], e[slow], bent, motion(bent, slow))
            better = certified_pace(arrays, k[slow], point[slow], e[slow], bent, motion(bent, slow))
            take = better > pace[slow]
            direction[slow[take]], pace[slow[take]] = bent[take], better[take]
            short = pace[slow] < 1.0
            slow, bent = slow[short], bent[short]
            if not len(slow):
                break
        return direction, pace

    def placed(who: np.ndarray, point: np.ndarray) -> np.ndarray:
        """The sets of robots ``who`` moved with their estimates to the reference points ``point`` (the look-ahead
        point's set is ``X_t + λh(θ)``), (R', W, 2)."""
        return sets.vertices[who] + (point - sets.x_hat[who])[:, None, :]

    def certified_step(who, k, point, heading, direction, local):
        """Whether robots ``who`` may step in cells ``k`` from the reference points ``point`` at ``heading``: their
        error within what the cell tolerates (over their sets, where ``local``: the truth is known to be in that
        cell; else ``τ_c``), and the step's certified pace and (bent) direction, both 0 where they may not."""
        e = error[who]
        tau = arrays.tolerance_in(k)
        short = np.flatnonzero(local & (e + margin > tau + s.tol))
        if len(short):  # τ_c is the least over the cell; where the set lies, the cell may tolerate more
            at = placed(who[short], point[short])
            valid = bounded.valid_vertices(at, sets.count[who[short]])
            tau[short] = set_tolerance(arrays, k[short], at, valid, swing, reach)
        direction, pace = direction.copy(), np.zeros(len(k))
        go = np.flatnonzero(e + margin <= tau + s.tol)
        if len(go):
            direction[go], pace[go] = step_pace(k[go], point[go], e[go], direction[go], heading[go])
        return direction, pace

    def certified_heading(who: np.ndarray, prefer: np.ndarray) -> np.ndarray:
        """A heading for each look-ahead unicycle ``who`` from which the whole set of ``p`` lies in a cell and a
        certified step exists there, shape (R',); NaN where no candidate heading has one.

        Turning in place leaves the body where it is and swings ``p`` on its circle around the axle, so a robot
        without a cell may start the certificate at any heading (ALGORITHMS §12.3 step 4, §12.6): of
        :data:`HEADINGS` headings evenly spaced from ``prefer``, the least-rank cell's, the nearest to ``prefer``
        among equals."""
        n = len(who)
        ring = np.arange(HEADINGS)
        # 0, +Δ, −Δ, +2Δ, … : the first of equals is the least turn from ``prefer``
        offsets = (2.0 * math.pi / HEADINGS) * np.where(ring % 2, (ring + 1) // 2, -(ring // 2))
        theta = prefer[:, None] + offsets[None, :]
        rep, th = np.repeat(who, HEADINGS), theta.ravel()
        point = lookahead_point(sets.x_hat[rep], th, lam)
        k = least_rank_cell_holding(arrays, point, placed(rep, point), sets.count[rep], swing)
        j = np.flatnonzero(k >= 0)
        rank = np.full(len(k), np.inf)
        if len(j):
            field, ok = _unit_field(arrays, k[j], point[j])
            _, pace = certified_step(rep[j], k[j], point[j], th[j], field, np.ones(len(j), bool))
            j = j[ok & (pace > 0.0)]
            rank[j] = arrays.cell_rank[k[j]]
        rank = rank.reshape(n, HEADINGS)
        best = np.argmin(rank, axis=1)
        rows = np.arange(n)
        return np.where(np.isfinite(rank[rows, best]), bearing.wrap(theta[rows, best]), np.nan)

    # the truth is in the active cell (Theorem 2), so its estimate may lie up to e outside it; not after a
    # look-ahead unicycle's look swung p around the axle: then p̂ must lie in a cell eroded by e
    swung = np.isfinite(state.resume) if ahead else np.zeros(r, bool)
    keep = np.where(swung, -error, error)
    cell, target, last_dir, u, stalled, relocated = follow_fields(arrays, s, state, est, bearings, visible, keep=keep)
    if arrays.funnel:
        # a cell a robot did not keep must hold p̂ eroded by e; an approach within eps_sw of its node takes the
        # node's cell (cell_policy.funnel_update) without asking that (certified steps ended 3 cm outside their
        # cell, from starts at the corners of D after a look-ahead look): then the robot has no cell yet
        came = np.flatnonzero((cell >= 0) & (target < 0) & ((cell != state.cell) | (state.target >= 0)))
        cell[came[cell_slack(arrays, cell[came], reference[came]) < error[came] - arrays.tol]] = -1
    in_cell = (cell >= 0) & (target < 0) & known
    holder = np.full(r, -1, np.int64)
    if arrays.funnel:
        # a cell grown by e holds p̂ (the robot may be in it) but none eroded by e does
        open_ = np.flatnonzero(known & ~in_cell)
        holder[open_] = least_rank_cell(arrays, reference[open_], -error[open_])
        # unless a cell holds the whole set (exactly: its vertices; the look-ahead point's set is X_t + λh(θ̂)
        # grown by the swing): then the truth is in that cell, and its certified policy applies; of those cells
        # the least rank, which need not be the one holding p̂ (near a boundary between two cells, a third may)
        if len(open_):
            k = least_rank_cell_holding(
                arrays, reference[open_], placed(open_, reference[open_]), sets.count[open_], swing
            )
            sure, k = open_[k >= 0], k[k >= 0]
            field, ok = _unit_field(arrays, k, reference[sure])
            sure, k, field = sure[ok], k[ok], field[ok]
            u[sure], last_dir[sure] = field, field
            cell[sure], target[sure], stalled[sure], in_cell[sure], holder[sure] = k, -1, False, True, -1
        # no cell holds the set: stop and look until one does (ALGORITHMS §12.3 step 4; the look shrinks the set and,
        # for a look-ahead unicycle, swings it through every heading), and only when a whole look has not told
        # (worst-case bearings repeat the same set) drive uncertified, rather than stay stuck looking
        looked = state.known & (state.hold + s.dt >= look_time(s, arrays))
        undecided = (holder >= 0) & ((error + margin > arrays.tolerance_in(holder) + s.tol) | ~looked)
    else:
        undecided = np.zeros(r, bool)
    # undecided robots have not chosen a cell: they look before any approach
    cell, target = np.where(undecided, -1, cell), np.where(undecided, -1, target)
    outside = known & ~in_cell & ~undecided
    move = in_cell.copy()
    pace = np.where(move, 1.0, 0.0)
    if arrays.funnel and move.any():
        # the truth is in the active cell: what that cell tolerates over the set (runtime.tolerance; a long cell's
        # far end no longer waits for its exit's neck), and the certified pace
        idx = np.flatnonzero(move)
        u[idx], pace[idx] = certified_step(idx, cell[idx], reference[idx], phi[idx], u[idx], True)
        move[idx] = pace[idx] > 0.0
    # robots driving a cell's field without knowing the truth is in it: the state keeps no cell for them
    unsure = np.zeros(r, bool)
    if arrays.funnel:
        # at the edge of D after a whole look (a cell grown by e holds p̂, none holds the set): that cell's field,
        # uncertified, at the error ball's pace; it leads deeper into the cell, where the switch applies. The
        # cell is not the robot's yet (kept, the next step took the truth to be in it and certified steps that
        # ended outside it), and nor is the look undone: it drives on so, without looking again, until a cell
        # holds its set or p̂ eroded by e
        edge = np.flatnonzero(outside & (holder >= 0))
        unsure[edge] = True
        if len(edge):
            u[edge], ok = _unit_field(arrays, holder[edge], reference[edge])
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
        worse = (
            pending
            & had
            & (cell >= 0)
            & (arrays.cell_rank[np.maximum(cell, 0)] >= arrays.cell_rank[np.maximum(state.cell, 0)])
        )
        move &= ~worse
    drive = (move | (outside & (pace > 0.0) & ~pending)) & np.any(u != 0.0, axis=1)
    back = np.zeros(r, bool)
    if ahead:
        resume[drive] = np.nan
        returning = ~drive & known & pending
        if returning.any():  # the look is over when e would let it move where it was (or it was outside D)
            idx = np.flatnonzero(returning)
            there = lookahead_point(sets.x_hat[idx], resume[idx], lam)
            over = np.zeros(len(idx), bool)
            if arrays.funnel:
                had = state.cell[idx]
                # a robot without a cell turns to any heading that starts the certificate, not only back
                free = np.flatnonzero(had < 0)
                if len(free):
                    theta = certified_heading(idx[free], resume[idx[free]])
                    got = np.isfinite(theta)
                    resume[idx[free[got]]], over[free[got]] = theta[got], True
                # in the cell it will drive in there: the one it keeps, unless a cell of lower rank
                # holds p̂ eroded by e (the switch); the least-rank cell merely holding p̂ may have a
                # larger τ_c, and a look ended on it turned back into a cell that made it look again
                k = least_rank_cell(
                    arrays, there, error[idx], below=np.where(had >= 0, arrays.cell_rank[np.maximum(had, 0)], np.inf)
                )
                k = np.where(k >= 0, k, had)
                local = k >= 0  # a cell it drives in there: what it tolerates over its set
                # without a cell, the one a robot there would wait in (a cell grown by e holds p̂): its τ_c, for the
                # robot there is not in it yet and moves only once e lets a cell hold p̂ eroded by e
                k = np.where(k >= 0, k, least_rank_cell(arrays, there, -error[idx]))
            else:
                k, local = np.full(len(idx), -1), np.zeros(len(idx), bool)
            # a robot without a cell ends its look early only at a certified heading: turned back, it is undecided
            # until its whole look is done and looks again (a look ended one step in by the rules below, over and
            # over, never turned past its first view, and its set stayed that view's)
            waiting = (had < 0) & ~looked[idx] if arrays.funnel else np.zeros(len(idx), bool)
            # the look is over where the robot may step there (a large e near a face may leave no pace: a look ended
            # there turned back, stood, and began the look again, never turning all around)
            able = np.flatnonzero((k >= 0) & ~over & ~waiting)
            if len(able):
                field, ok = _unit_field(arrays, k[able], there[able])
                _, pace_there = certified_step(idx[able], k[able], there[able], resume[idx[able]], field, local[able])
                over[able] = ok & (pace_there > 0.0)
            out = np.flatnonzero((k < 0) & ~over & ~waiting)
            if len(out):
                # outside D there: the uncertified rules move it only at a positive error-ball pace; a
                # look ended at pace 0 turned back to wait, and waiting began the look again
                over[out] = error_ball_pace(arrays, s, k[out], there[out], error[idx[out]])[0] > 0.0
            back[idx[over]] = True
        # the swung p says nothing about the cell the robot will drive in: it keeps the one it had
        cell[returning], target[returning], relocated[returning] = state.cell[returning], state.target[returning], False
    # the clock of a look runs from the start too: a robot that never sees two landmarks turns all around
    # and is lost, as the filter's is, instead of waiting for its time to run out
    hold = np.where(drive & ~unsure, 0.0, state.hold + s.dt)
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
    new = ControlState(
        np.where(unsure, -1, cell),
        target,
        last_dir,
        hold,
        np.where(known[:, None], sets.x_hat, state.x_hat),
        motion,
        known,
        est.var,
        scanning,
        spin,
        look,
        np.where(scanning & ~state.scanning, hold - s.dt, state.scan_from),
        sets.vertices,
        sets.count,
        resume,
        sets.bound_scale,
    )
    certified = arrays.funnel & move & drive & ~clamped
    if s.dynamics == "unicycle" and not ahead:
        certified = np.zeros(r, bool)  # λ = 0: the unicycle is not the single integrator of the certificate
    looking = known & ~drive
    return ControlOutput(
        velocity,
        forward,
        turn,
        scanning,
        new,
        sets.seen,
        lost & ~drive,
        stalled & drive,
        relocated,
        np.where(known[:, None], reference, 0.0),
        certified,
        looking & ~scanning & ~back,
        looking | ~known,
        error,
        sets.inconsistent,
    )


def _unit_field(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The unit direction of each cell's affine field at ``x`` (R, 2; zero where the field vanishes) and where it
    does not vanish (R,) bool."""
    field = affine_field(arrays, cell, x)
    size = np.hypot(field[:, 0], field[:, 1])
    ok = size > 0.0
    return np.where(ok[:, None], field / np.where(ok, size, 1.0)[:, None], 0.0), ok


def follow_fields(
    arrays: PlanArrays,
    s: ControlSettings,
    state: ControlState,
    est: Estimate,
    bearings: np.ndarray,
    visible: np.ndarray,
    displacements: np.ndarray | None = None,
    keep: np.ndarray | None = None,
) -> tuple[np.ndarray, ...]:
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
        erosion = (
            est.error_bound[idx] if s.estimator == "set" else np.minimum(est.error_bound[idx], arrays.plan_tolerance)
        )
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
        rec = bearing.reconstruct(
            bearings[idx],
            visible[idx],
            arrays.landmarks,
            f,
            method=s.reconstruction,
            min_spread=s.min_spread,
            tol=s.tol,
        )
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
