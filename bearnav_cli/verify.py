"""``bearnav verify plan.npz``: check a plan without trusting the stages that made it (ALGORITHMS §8).

Three independent checks:

The first two are :mod:`bearnav_cli.verify_checks`'s, the report :mod:`bearnav_cli.verify_report`'s.

1. **Certificates**, recomputed from ``gain``, ``landmarks`` and the stored rows only,
   with a few lines of numpy (no LP, nothing from ``synthesize``): at every vertex
   ``v_q`` of a cell, ``u_q = a − M v_q`` with ``a = Σ K_k l_k`` and ``M = Σ K_k``; the CBF,
   CLF and input values are the worst case over the vertices, which is the worst case
   over the cell because every condition is affine in ``x``.
2. **Geometry**: the cells cover the bounds (shapely), lie inside them, contain their
   edge; barrier rows are unit-norm and positive at the exit point; tree edges are free;
   the collision samples are those of ``tree.npz`` when it is given.
3. **Monte Carlo**: ``n_starts`` random starts in the goal's free component, run through
   :func:`bearnav_cli.stages.simulate.rollout`, compared with the straight distance and
   with the exact shortest route (:func:`bearnav_cli.routes.route_lengths`). Free regions the
   tree never reached (parts of ``F_m`` cut off from every cell, or for ``paper`` plans from
   every tree edge, by passages narrower than ``2m``) are reported and no start is drawn
   there; any collision of a run fails verification, whatever ``min_success`` says.

:func:`run` returns a :class:`VerifyReport`; :attr:`VerifyReport.failed` is the exit decision.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np

from bearnav_cli import composition, runtime
from bearnav_cli.datatypes import Map, Plan, percent, plural
from bearnav_cli.errors import ArtifactError, InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.liveness import Liveness
from bearnav_cli.liveness import measure as measure_liveness
from bearnav_cli.params.verify import Params
from bearnav_cli.routes import route_lengths
from bearnav_cli.runtime import PlanArrays
from bearnav_cli.stages import simulate
from bearnav_cli.verify_checks import (
    certificate_problems,
    certificates,
    check_geometry,
    check_lookahead,
    flagged_cells,
    reached_starts,
    unreached_regions,
)
from bearnav_cli.verify_report import VerifyReport, duration_text

__all__ = ["guarantee", "loop_speed", "run"]

log = logging.getLogger(__name__)


def loop_speed(plan: Plan, params: Params) -> float:
    """The speed of the closed loop: ``params.speed``, else the map's ``params: simulate: speed``, else
    simulate's default (the paper maps' units are not metres); ``bearnav verify`` and :func:`run` use it."""
    if params.speed is not None:
        return float(params.speed)
    given = (plan.map.params or {}).get("simulate") or {}
    return float(given.get("speed", simulate.Params().speed)) if isinstance(given, dict) else simulate.Params().speed


def _liveness(plan: Plan, params: Params, speed: float) -> tuple[Liveness | None, str | None]:
    """The liveness report :class:`Params` asks for, at the loop's speed, or why there is none (a note)."""
    if params.live_fov is None:
        return None, None
    if not plan.cells.is_funnel:
        return None, "liveness: not measured, a paper plan has no usable position tolerance"
    names = {"eta_deg": "bearing_error_deg", "fov_deg": "live_fov", "kappa": "slip", "resolution": "live_resolution"}
    try:
        return measure_liveness(
            plan,
            params.bearing_error_deg,
            params.live_fov,
            kappa=params.slip,
            speed=speed,
            resolution=params.live_resolution,
        ), None
    except InvalidParamsError as exc:  # a value only the map can refuse (the grid against D): the user's option
        if exc.field in names:
            raise InvalidParamsError(exc.reason, field=names[exc.field]) from None
        return None, f"liveness: not measured, {exc.field}: {exc.reason}"


def guarantee(plan: Plan, report: VerifyReport) -> str:
    """One sentence for a robotics engineer: what ``report`` proves of ``plan``, what it only measured, what it leaves.

    Proven: from which starts (``D``), for which robot (radius, single integrator or look-ahead
    point), under which position error (``τ_c``), and the worst-case time. Measured only: the
    closed-loop runs and liveness. Not covered: starts outside ``D``, errors beyond the robot
    section's bounds, a camera that sees fewer than two tags.

    Parameters
    ----------
    plan : Plan
        The plan verified.
    report : VerifyReport
        What :func:`run` found.

    Returns
    -------
    str
    """
    comp = report.composition
    if report.failed:
        return "guarantee: none, the plan fails verification (above)"
    runs = report.rollouts
    measured = (
        (
            f"measured only: {plural(len(runs), 'closed-loop run')} with exact positions (`bearnav simulate` adds "
            "a camera and noise)"
        )
        if runs is not None and len(runs)
        else "nothing measured (no runs)"
    )
    if comp is None:  # a paper plan: per-cell certificates (§4), no composition theorem
        return f"guarantee: {composition.PAPER_CLAIM}; {measured}"
    robot = runtime.robot.robot_parameters(plan.map.robot)
    who = composition.robot_words(plan.map)
    if plan.map.lookahead <= 0:
        who += " (a single integrator; a unicycle only through `bearnav plan --lookahead`)"
    tol = comp.usable_by_area
    eta = float(robot["bearing_error_deg"]) + float(robot["compass_error_deg"] or 0.0)
    if report.liveness is not None:
        measured += (
            f", and at η = {math.degrees(report.liveness.grid.eta):.3g}°: "
            f"{report.liveness.live_fraction:.0%} of the certified area where a look all around is sure to "
            f"be good enough, {report.liveness.start_fraction:.0%} where a robot is also sure to find the cell it "
            "starts in (on a grid)"
        )
    proven = (
        f"proven from the plan file, {who} that starts in the certified area ({percent(comp.coverage_free)} of "
        f"the free space) and knows its position to within what the cell it is in tolerates (at least "
        f"{comp.plan_tolerance:.3g} map units, {tol['median']:.3g} at the median point) reaches the goal "
        f"without touching an obstacle or a wall, at speed {comp.speed:g} map units/s in "
        f"{duration_text(comp.time_bound)} (a worst case, from the least progress each cell's certificate "
        "guarantees, not an estimate of a run's time)"
    )
    bounded = (
        f"with bearings erring by at most η = {eta:g}° and wheel slip within {robot['slip']:g} of each step "
        "(the map's robot section) the `bearnav simulate` robot (its default set estimator) moves only where it "
        "knows that much, "
        "and never gets stuck where a look all around is good enough (`--live-fov F` measures where; "
        "`bearnav tags --for live` adds tags until it is everywhere)"
    )
    uncovered = (
        "not covered: starts outside the certified area, errors beyond those bounds, places where the camera "
        "sees fewer than two tags (`bearnav verify --fov F` measures them)"
    )
    return f"guarantee: {proven}; {bounded}; {measured}; {uncovered}"


def run(
    plan: Plan,
    params: Params = Params(),
    tree_samples: np.ndarray | None = None,
    progress: Callable[[int, int], None] | None = None,
    world: Map | None = None,
) -> VerifyReport:
    """Verify a plan: certificates, geometry and the Monte-Carlo closed loop (ALGORITHMS §8).

    Parameters
    ----------
    plan : Plan
        The plan to verify (``plan.npz``, with its embedded map).
    params : Params
        The Monte-Carlo check: number of starts, seed, the loop's speed, ``dt`` and dynamics, and
        ``min_success``.
    tree_samples : ndarray, shape (S, 2), optional
        ``collision_samples`` of the ``tree.npz`` the plan came from, to check they survived.
    world : Map, optional
        Another map in the same frame: (C1) is re-checked against its obstacles and the cells
        that no longer hold are listed (paper B's deformation question, answered exactly).
    progress : callable, optional
        ``progress(finished_runs, n_starts)`` during the Monte-Carlo runs.

    Returns
    -------
    VerifyReport
    """
    cells = plan.cells
    cert = certificates(plan)
    problems = certificate_problems(plan, cert)
    with np.errstate(divide="ignore", invalid="ignore"):
        c_h_tilde = np.where(cells.s_min > 0, plan.c_h / cells.s_min, np.where(np.isnan(plan.c_h), np.nan, np.inf))
        c_v_tilde = plan.c_v / cells.s_max
        c_h_smax = plan.c_h / cells.s_max
    space = FreeSpace.from_map(plan.map)
    geometry = check_geometry(plan, space, tree_samples)
    speed = loop_speed(plan, params)
    comp = composition.check(plan, speed, space) if plan.cells.is_funnel else None
    world_cells = None
    if world is not None:
        problem = composition.map_frame_problem(plan.map, world)
        if problem is not None:
            raise InvalidParamsError(problem, field="world")
        world_cells = composition.world_violations(plan, FreeSpace.from_map(world))

    unreached = unreached_regions(plan, space, comp.regions if comp is not None else None)
    live, live_note = _liveness(plan, params, speed)
    starts = np.zeros((0, 2))
    rollouts, skipped, breaches = None, None, None
    if params.n_starts == 0:
        skipped = "n_starts is 0"
    else:
        try:
            arrays = PlanArrays.from_plan(plan)
        except ArtifactError as exc:
            skipped = f"malformed plan, no closed loop: {exc}"
        if skipped is None:
            rng = np.random.default_rng(params.seed)
            starts = reached_starts(space, plan.map.goal, params.n_starts, rng, unreached.avoid)
            # the certificates are stated for the displacement output and the exact motion of §7.1:
            # bearings and wheel slip are `bearnav simulate`'s job
            sim = simulate.Params(
                speed=speed,
                alpha=speed,
                dt=params.dt,
                measurement="displacement",
                odometry_noise=0.0,
                dynamics=params.dynamics,
                certified_heading=True,
                record_trajectories=False,
            )
            breach = np.zeros(len(starts), bool)
            # the unicycle without a look-ahead is outside the certificate: no step of it is certified
            steps_certified = params.dynamics != "unicycle" or arrays.lookahead > 0

            def watch(runs: np.ndarray, x: np.ndarray, certified: np.ndarray) -> None:
                if arrays.funnel:  # a step not certified, or a true position (p) outside every cell of D
                    uncertified = ~certified if steps_certified else np.zeros(len(runs), bool)
                    breach[runs] |= uncertified | (runtime.least_rank_cell(arrays, x) < 0)

            rollouts = simulate.rollout(plan, starts, sim, progress=progress, on_step=watch, arrays=arrays, space=space)
            breaches = breach & rollouts.start_in_domain
    straight = np.hypot(*(starts - plan.map.goal).T) if len(starts) else np.zeros(0)
    route = route_lengths(space, plan.map.goal, starts) if len(starts) else np.zeros(0)
    uncovered = None
    if params.dynamics == "unicycle" and plan.map.lookahead <= 0 and params.n_starts > 0:
        uncovered = (
            "the unicycle on a plan without a look-ahead (λ = 0) is outside the certificate: its steps count "
            "as uncertified, and a breach is only a true position outside D; plan with `--lookahead L`, "
            "L at least the speed over the turn rate, to drive it inside"
        )
    report = VerifyReport(
        status=np.asarray(plan.status),
        certificates=cert,
        false_certificates=problems,
        c_h_tilde=c_h_tilde,
        c_v_tilde=c_v_tilde,
        c_h_over_s_max=c_h_smax,
        flagged=flagged_cells(plan),
        geometry=geometry,
        starts=starts,
        rollouts=rollouts,
        straight=straight,
        route=route,
        min_success=params.min_success,
        skipped=skipped,
        goal=np.asarray(plan.map.goal, float),
        composition=comp,
        world_cells=world_cells,
        unreached=unreached,
        breaches=breaches,
        lookahead_problems=tuple(check_lookahead(plan, space)),
        uncovered_dynamics=uncovered,
        liveness=live,
        liveness_note=live_note,
    )
    log.info("verify: %s", report.summary())
    return report
