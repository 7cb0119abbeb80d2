"""What a sweep's workers run: the plans of one map and seed, and one job's closed loop (no files touched)."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any

from bearnav_cli import pipeline
from bearnav_cli.datatypes import replace
from bearnav_cli.errors import BearnavError
from bearnav_cli.sweep.grid import Job
from bearnav_cli.sweep.results import OUTCOMES

__all__ = ["make_plans", "one_line", "PlanTask", "run_job"]


@dataclass(frozen=True)
class PlanTask:
    """The plans of one map and seed a sweep still needs: the map's own, and each tag set's.

    Attributes
    ----------
    base_key : str
        The key of the plan with the map's own tags.
    source : MapSource
        The map.
    seed : int or None
        ``rrtstar``'s seed (None: the map's).
    tagged : tuple of (str, TagsParams)
        The key and proposal parameters of every tagged plan to make.
    need_base : bool
        Whether the plan with the map's own tags must be made (else ``base`` holds it).
    base : tuple of (Tree, Plan) or None
        The simplified tree and the plan with the map's own tags, from the store.
    """

    base_key: str
    source: Any = dataclasses.field(repr=False)
    seed: int | None
    tagged: tuple
    need_base: bool
    base: tuple | None = dataclasses.field(default=None, repr=False)


def one_line(exc: BaseException) -> str:
    """An error as one line: bearnav's own message, any other exception with its type's name first."""
    text = str(exc).replace("\n", " ").strip()
    return text if isinstance(exc, BearnavError) else f"{type(exc).__name__}: {text}"


def _tagged_plan(task: PlanTask, simplified: Any, plan: Any, tags_params: Any) -> tuple[Any, dict, dict]:
    """The plan re-made with the tags ``bearnav tags`` proposes (repro/robustness.py's recipe, now here).

    The map stage reads the map with the proposal appended (``tags.map_spec_with_tags``), and
    decompose and synthesize run again on the same simplified tree: the fields do not depend on
    the landmarks (ALGORITHMS Lemma 3), so the cells stay and only the gains change.
    """
    from bearnav_cli import tags
    from bearnav_cli.stages import map_ as map_stage

    proposal = tags.propose_tags(plan, tags_params)
    info = {"new_tags": proposal.count, "proposal": proposal.summary()}
    if proposal.count == 0:
        return plan, None, info
    source = task.source
    spec = tags.map_spec_with_tags(source.spec, proposal)
    with_tags = map_stage.MapSource(
        spec=spec, file=source.file, sha256=f"{source.sha256}+{proposal.count} tags", grid=source.grid
    )
    new_map = pipeline.compute(with_tags, through="map")["map"]
    made, manifest = pipeline.compute_saved(replace(simplified, map=new_map), after="simplify")["plan"]
    return made, manifest, info


def make_plans(task: PlanTask) -> dict:
    """Make the plans of one :class:`PlanTask` (in a worker: no files are touched).

    Returns
    -------
    dict
        ``{"simplified": (Tree, manifest) or None, "plans": {key: {"plan": Plan, "manifest": dict or None,
        "info": dict} or {"error": str}}}``: every plan the task asked for, or the one-line error that
        stopped it (every plan after a failed base fails with the base's error).
    """
    out: dict[str, Any] = {"simplified": None, "plans": {}}
    began = time.perf_counter()
    try:
        if task.base is not None:
            simplified, plan = task.base
        else:
            overrides = {"rrtstar": {"seed": task.seed}} if task.seed is not None else {}
            made = pipeline.compute_saved(task.source, through="synthesize", overrides=overrides)
            (simplified, _), (plan, manifest) = made["simplified"], made["plan"]
            out["simplified"] = made["simplified"]
            out["plans"][task.base_key] = {
                "plan": plan,
                "manifest": manifest,
                "info": {"elapsed_s": time.perf_counter() - began},
            }
    except Exception as exc:  # noqa: BLE001 - recorded with the jobs that needed the plan
        error = one_line(exc)
        return {"simplified": None, "plans": {key: {"error": error} for key in (task.base_key, *dict(task.tagged))}}
    for key, tags_params in task.tagged:
        began = time.perf_counter()
        try:
            tagged, manifest, info = _tagged_plan(task, simplified, plan, tags_params)
            out["plans"][key] = {
                "plan": tagged,
                "manifest": manifest,
                "info": {**info, "elapsed_s": time.perf_counter() - began},
            }
        except Exception as exc:  # noqa: BLE001 - recorded with the jobs that needed the plan
            out["plans"][key] = {"error": one_line(exc)}
    return out


def run_job(job: Job, plan: Any) -> dict:
    """Run one job's closed loop (in a worker: no files are touched) and return its record's results.

    Returns
    -------
    dict
        ``{"status": "done", "result": {...}, "sim_s": float}`` or ``{"status": "failed", "error": str}``.
    """
    from bearnav_cli.stages import simulate

    began = time.perf_counter()
    try:
        sim = simulate.run(plan, job.params)
    except Exception as exc:  # noqa: BLE001 - a failed job is recorded and the sweep goes on
        return {"status": "failed", "error": one_line(exc), "sim_s": time.perf_counter() - began}
    stats = sim.stats
    runs = len(sim)
    result = {
        "runs": runs,
        **{name: int(sim.counts().get(name, 0)) for name in OUTCOMES},
        "success_rate": stats["success_rate"],
        "certified_step_fraction": stats["certified_step_fraction"],
        "in_domain_fraction": stats["runs_from_certified_domain"] / runs if runs else None,
        "success_rate_in_domain": stats["success_rate_in_domain"],
        "time_mean_s": stats["time_mean_s"],
        "min_clearance": stats["min_clearance"],
    }
    return {"status": "done", "result": result, "sim_s": time.perf_counter() - began}
