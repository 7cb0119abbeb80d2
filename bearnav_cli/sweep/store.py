"""Running a sweep into its store: the jobs whose file is missing, on an executor, each job file written as it ends.

The store holds the plans (``plans/KEY/``) and one file per job (``jobs/KEY.json``); only this
process writes it, through :mod:`bearnav_cli.artifacts`, never a worker.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bearnav_cli import artifacts
from bearnav_cli.errors import BearnavError
from bearnav_cli.sweep.grid import Job
from bearnav_cli.sweep.work import PlanTask, make_plans, one_line, run_job

__all__ = ["JOB_SCHEMA", "records", "run", "SweepReport"]


#: Schema of a job file.
JOB_SCHEMA = "bearnav.sweep-job/1"


@dataclass(frozen=True)
class SweepReport:
    """What a run of the sweep did.

    Attributes
    ----------
    total : int
        Jobs in the grid.
    ran : int
        Jobs run now (failed ones included).
    stored : int
        Jobs whose result was in the store already.
    failed : tuple of str
        The one-line error of each job that failed now.
    plans_made : int
        Plans made now (the others came from the store).
    elapsed_s : float
        Wall time (s).
    """

    total: int
    ran: int
    stored: int
    failed: tuple[str, ...]
    plans_made: int
    elapsed_s: float


def _job_path(store: Path, key: str) -> Path:
    return store / "jobs" / f"{key[:24]}.json"


def _plan_folder(store: Path, key: str) -> Path:
    return store / "plans" / key[:24]


def records(store: str | os.PathLike, jobs: Iterable[Job]) -> dict[str, dict]:
    """The job files of ``jobs`` the store holds, by job key (a file that does not load is left out)."""
    found = {}
    for job in jobs:
        record = artifacts.read_record(_job_path(Path(store), job.key), JOB_SCHEMA)
        if record is not None and record.get("key") == job.key:
            found[job.key] = record
    return found


def _load_plan(store: Path, key: str) -> tuple[Any, dict] | None:
    folder = _plan_folder(store, key)
    try:
        plan = artifacts.load(folder / "plan.npz", "plan").artifact
    except BearnavError:
        return None
    info = artifacts.read_record(folder / "plan.json", "bearnav.sweep-plan/1") or {}
    return plan, info


def _save_plan(store: Path, key: str, plan: Any, manifest: dict | None, info: dict, job: Job) -> None:
    """plans/KEY/plan.npz and plan.json (the npz first: a plan.json always has its plan)."""
    folder = _plan_folder(store, key)
    own = key == job.base_key
    if manifest is None:  # a tagged plan to which the proposal added nothing: the plan with the map's tags
        artifacts.copy_file(_plan_folder(store, job.base_key) / "plan.npz", folder / "plan.npz")
    else:
        artifacts.save(folder / "plan.npz", plan, manifest)
    tags = "own" if own else artifacts.params_dict(job.tags)
    document = {
        "schema": "bearnav.sweep-plan/1",
        "key": key,
        "map": job.grid["map"],
        "map_file": job.grid["map_file"],
        "seed": job.grid["seed"],
        "tags": tags,
        **info,
    }
    artifacts.write_record(folder / "plan.json", document)


def run(
    jobs: Sequence[Job],
    store: str | os.PathLike,
    executor: Any,
    progress: Callable[[int, int, int], None] | None = None,
    on_plans: Callable[[int, int], None] | None = None,
) -> SweepReport:
    """Run every job of ``jobs`` whose result the store lacks, on ``executor``; write each job file as it ends.

    Plans first, one task per map and seed (in the store already: loaded, not made); each task's
    jobs are submitted as soon as its plans are back. Results are collected in submission order
    (``future.result()`` only) and each job file is written before the next result is read, so an
    interrupt leaves every finished job in the store.

    Parameters
    ----------
    jobs : sequence of Job
        The grid (:func:`expand`).
    store : path-like
        The store folder (created; locked while the sweep runs).
    executor : object
        ``submit(fn, *args) -> future``, ``future.result()``.
    progress : callable, optional
        ``progress(done, failed, total)`` after each job (those in the store count as done).
    on_plans : callable, optional
        ``on_plans(done, total)`` after each plan task.

    Returns
    -------
    SweepReport
    """
    store = Path(store)
    began = time.perf_counter()
    with artifacts.output_folder(store):
        have = records(store, jobs)
        stored = sum(1 for job in jobs if have.get(job.key, {}).get("status") == "done")
        todo = [job for job in jobs if have.get(job.key, {}).get("status") != "done"]
        done, failed = stored, []
        if progress:
            progress(done, 0, len(jobs))
        groups = _plan_tasks(store, todo)
        plan_futures = [(group, task, task and executor.submit(make_plans, task)) for group, task in groups]
        job_futures: list[tuple[Job, Any, dict]] = []
        plans_made = 0
        for n, (group, task, future) in enumerate(plan_futures, 1):
            made: dict = {"plans": {}}
            if future is not None:
                made = _result(future, lambda error: {"simplified": None, "plans": {}, "error": error})
                plans_made += _store_plans(store, task, made, group)
            for job in group:
                loaded = _load_plan(store, job.plan_key)
                if loaded is None:
                    error = made["plans"].get(job.plan_key, {}).get("error") or made.get("error") or "not made"
                    job_futures.append((job, None, {"error": f"plan: {error}"}))
                    continue
                plan, info = loaded
                job_futures.append((job, executor.submit(run_job, job, plan), {"plan": plan, "info": info}))
            if on_plans:
                on_plans(n, len(plan_futures))
        for job, future, plan_data in job_futures:
            if future is None:
                outcome = {"status": "failed", "error": plan_data["error"]}
            else:
                outcome = _result(future, lambda error: {"status": "failed", "error": error})
            artifacts.write_record(_job_path(store, job.key), _record(job, outcome, plan_data))
            if outcome["status"] != "done":
                failed.append(outcome["error"])
            done += 1
            if progress:
                progress(done, len(failed), len(jobs))
    return SweepReport(len(jobs), len(todo), stored, tuple(failed), plans_made, time.perf_counter() - began)


def _result(future: Any, failure: Callable[[str], dict]) -> dict:
    """``future.result()``; a worker that died (not the job's own error, which it returns) as a failure."""
    try:
        return future.result()
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:  # noqa: BLE001 - a lost worker fails its job, not the sweep
        return failure(f"worker: {one_line(exc)}")


def _plan_tasks(store: Path, todo: Sequence[Job]) -> list[tuple[list[Job], PlanTask | None]]:
    """The jobs to run grouped by map and seed, each group with the task that makes its missing plans (or None)."""
    groups: dict[tuple, list[Job]] = {}
    for job in todo:
        groups.setdefault((job.source.sha256, job.seed), []).append(job)
    out = []
    for group in groups.values():
        first = group[0]
        tagged = {job.plan_key: job.tags for job in group if job.tags is not None}
        missing = tuple((key, p) for key, p in tagged.items() if _load_plan(store, key) is None)
        base_plan = _load_plan(store, first.base_key)
        base = None
        if base_plan is not None and missing:
            try:
                simplified = artifacts.load(_plan_folder(store, first.base_key) / "simplified.npz", "simplified")
                base = (simplified.artifact, base_plan[0])
            except BearnavError:
                base_plan = None  # the tree is gone: make the plan again
        task = None
        if base_plan is None or missing:
            task = PlanTask(first.base_key, first.source, first.seed, missing, base_plan is None, base)
        out.append((group, task))
    return out


def _store_plans(store: Path, task: PlanTask, made: dict, group: Sequence[Job]) -> int:
    """Write what a plan task made into the store; the number of plans written."""
    by_plan = {job.plan_key: job for job in group}
    written = 0
    if made.get("simplified") is not None:
        simplified, manifest = made["simplified"]
        artifacts.save(_plan_folder(store, task.base_key) / "simplified.npz", simplified, manifest)
    order = sorted(made["plans"], key=lambda key: key != task.base_key)  # the base first: a copy may need it
    for key in order:
        entry = made["plans"][key]
        job = by_plan.get(key) or group[0]
        if "error" in entry:
            continue
        _save_plan(store, key, entry["plan"], entry["manifest"], entry["info"], job)
        written += 1
    return written


def _record(job: Job, outcome: dict, plan_data: dict) -> dict:
    """The job file: schema, key, grid values, status, results, the plan's figures and the times."""
    plan = plan_data.get("plan")
    info = plan_data.get("info") or {}
    figures = None
    if plan is not None:
        figures = {
            "tolerance": _finite(getattr(plan, "plan_tolerance", None)),
            "cells": int(len(plan.cells.cell_node)),
            "n_tags": int(len(plan.map.landmarks)),
            "new_tags": info.get("new_tags"),
        }
    return {
        "schema": JOB_SCHEMA,
        "key": job.key,
        "plan_key": job.plan_key,
        "grid": job.grid,
        "params": artifacts.params_dict(job.params),
        "status": outcome["status"],
        "error": outcome.get("error"),
        "result": outcome.get("result"),
        "plan": figures,
        "times": {"plan_s": info.get("elapsed_s"), "sim_s": outcome.get("sim_s")},
        "software": artifacts.software_versions(),
    }


def _finite(value: Any) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None
