"""``bearnav sweep``: a grid of plans and closed-loop runs, run once each into a content-addressed store (issue 25).

A sweep file (docs/sweeps.md) names lists of maps, plan seeds and closed-loop settings; their
product is the grid, one **job** per cell: the plan it needs (made once per map, seed and tag
set and shared by every job that needs it) and then one :func:`bearnav_cli.stages.simulate.run`.
Every job's random streams come from its own seeds (the plan's ``rrtstar`` seed and the
simulation's ``seed``), never from a shared stream, so a job gives the same result whichever
process runs it and in whatever order.

Store (``sweeps/NAME/`` by default)::

    plans/KEY/plan.npz         a plan, KEY the hash of what makes it (map bytes, seed, stage versions, tags)
    plans/KEY/simplified.npz   the tree a tagged plan of the same map and seed is re-made on
    plans/KEY/plan.json        how it was made (map, seed, tags, seconds)
    jobs/KEY.json              one job: its grid values, outcome counts, certified fractions, times
    results.csv (.parquet)     the table, one row per job of the grid (:func:`table`)
    results.md, success.png    success against noise (:func:`success_curves`)

A job's KEY hashes its plan's key and its complete simulate parameters, so a job file is
written once and never goes stale: an interrupted or repeated sweep runs the jobs whose file is
missing (or records a failure) and nothing else. Files are written by :mod:`bearnav_cli.artifacts`
(atomically), by the process that runs the sweep, never by a worker: workers need no shared
file system (a Dask cluster elsewhere works too).

Executors: anything with ``submit(fn, *args)`` returning a future with ``result()`` (a
:class:`concurrent.futures.ProcessPoolExecutor`, or Dask's ``Client.get_executor()``): results are
collected in submission order, nothing else of either API is used.
"""

from __future__ import annotations

import dataclasses
import glob as globbing
import itertools
import math
import os
import socket
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bearnav_cli import artifacts, pipeline
from bearnav_cli.datatypes import Outcome, replace
from bearnav_cli.errors import BearnavError, InvalidParamsError, InvalidSweepError

__all__ = [
    "AXES",
    "COLUMNS",
    "DETERMINISTIC_COLUMNS",
    "JOB_SCHEMA",
    "Job",
    "Panel",
    "PlanTask",
    "SCHEDULER_TIMEOUT_S",
    "Sweep",
    "SweepReport",
    "TagsChoice",
    "connect_scheduler",
    "expand",
    "expand_maps",
    "local_executor",
    "stop_local",
    "make_plans",
    "markdown",
    "read_sweep",
    "records",
    "run",
    "run_job",
    "success_curves",
    "table",
    "write_results",
]

#: The grid's axes: sweep-file key → the ``simulate`` parameter it sets (None: not a simulate parameter).
AXES: dict[str, str | None] = {
    "maps": None,
    "seeds": None,  # rrtstar's seed
    "fov": "fov",
    "noise_deg": "noise_deg",
    "noise_bound_deg": "noise_bound_deg",
    "dynamics": "dynamics",
    "estimator": "estimator",
    "tags": None,
    "starts": "starts",
    "sim_seeds": "seed",
}
#: Keys of a sweep file besides the axes.
OTHER_KEYS = ("name",)
#: Schema of a job file.
JOB_SCHEMA = "bearnav.sweep-job/1"
#: Seconds ``--scheduler`` may take to answer before the sweep gives up (the issue's limit is 10 s).
SCHEDULER_TIMEOUT_S = 6.0
#: Outcome names, in the enum's order (the table's count columns).
OUTCOMES = tuple(o.name.lower() for o in Outcome)
#: Columns of the table whose values do not depend on the machine or the schedule.
DETERMINISTIC_COLUMNS = (
    "map", "map_file", "seed", "tags", "n_tags", "fov", "noise_deg", "noise_bound_deg", "dynamics", "estimator",
    "starts", "sim_seed", "status", "error", "runs", *OUTCOMES, "success_rate", "certified_step_fraction",
    "in_domain_fraction", "success_rate_in_domain", "plan_tolerance", "plan_cells", "plan_key", "job_key",
)  # fmt: skip
#: Every column of the table: the deterministic ones, then the times (seconds of wall time).
COLUMNS = (*DETERMINISTIC_COLUMNS, "plan_s", "sim_s")


# --------------------------------------------------------------------------- the sweep file


@dataclass(frozen=True)
class TagsChoice:
    """The tags a job's plan has: the map's own, or the map's plus those ``bearnav tags`` proposes.

    Attributes
    ----------
    text : str
        As the sweep file writes it: ``own``, ``proposed`` (for the job's own camera: its ``fov``
        and noise) or ``proposed:FOV,NOISE`` (for one camera, degrees, whatever the job's).
    fov, noise_deg : float or None
        The fixed camera of ``proposed:FOV,NOISE``; None otherwise.
    """

    text: str
    fov: float | None = None
    noise_deg: float | None = None

    @property
    def own(self) -> bool:
        return self.text == "own"

    @classmethod
    def parse(cls, value: Any) -> TagsChoice:
        """Read one entry of ``tags``; raises :class:`InvalidParamsError` naming what is wrong."""
        text = str(value).strip() if isinstance(value, str) else None
        if text in ("own", "proposed"):
            return cls(text)
        if text and text.startswith("proposed:"):
            try:
                fov, noise = (float(v) for v in text.removeprefix("proposed:").split(","))
            except ValueError:
                fov = noise = math.nan
            if math.isfinite(fov) and math.isfinite(noise):
                return cls(f"proposed:{fov:g},{noise:g}", fov, noise)
        raise InvalidParamsError(f"expected own, proposed or proposed:FOV,NOISE, got {value!r}")

    def params(self, sim: Any) -> Any:
        """:class:`bearnav_cli.tags.Params` of the proposal for a job of simulate parameters ``sim`` (None: own).

        ``proposed`` places the tags for the job's camera: its field of view, and its Gaussian
        noise σ, or its noise bound when the noise is bounded (a conservative σ).
        """
        from bearnav_cli import tags

        if self.own:
            return None
        if self.fov is not None:
            return tags.Params(fov_deg=self.fov, noise_deg=self.noise_deg)
        noise = sim.noise_deg if sim.noise_bound_deg is None else max(sim.noise_deg, sim.noise_bound_deg)
        return tags.Params(fov_deg=sim.fov, noise_deg=noise, max_range=sim.range or math.inf)


@dataclass(frozen=True)
class Sweep:
    """A sweep file, checked: its name and the values of every axis (a scalar became a list of one).

    Attributes
    ----------
    name : str
        ``name:``, by default the file's stem; the default store is ``sweeps/NAME/``.
    file : str
        The sweep file, for messages.
    axes : dict
        Axis key (:data:`AXES`) → tuple of values; an axis the file leaves out is ``(None,)``:
        the map's ``params:`` or the stage's default decides.
    """

    name: str
    file: str
    axes: dict[str, tuple]


def _as_list(value: Any) -> list:
    return list(value) if isinstance(value, (list, tuple)) else [value]


def read_sweep(spec: Any, file: str) -> Sweep:
    """Check a parsed sweep file (docs/sweeps.md) and return its axes.

    Parameters
    ----------
    spec : Any
        The YAML document, as parsed (a mapping).
    file : str
        Its path, for messages.

    Returns
    -------
    Sweep

    Raises
    ------
    InvalidSweepError
        Naming the file and the key: not a mapping, an unknown key, an empty list, a value of the
        wrong type or out of the stage's range (checked with the stage's own ``Params``).
    """
    if not isinstance(spec, dict):
        raise InvalidSweepError("expected a mapping of keys to lists", file=file)
    for key in spec:
        if key not in AXES and key not in OTHER_KEYS:
            raise InvalidSweepError(f"unknown key (known: {', '.join((*OTHER_KEYS, *AXES))})", file=file,
                                    field=str(key))  # fmt: skip
    name = spec.get("name", Path(file).stem)
    if not isinstance(name, str) or not name or "/" in name or name.startswith("."):
        raise InvalidSweepError(f"expected a plain folder name, got {name!r}", file=file, field="name")
    if "maps" not in spec:
        raise InvalidSweepError("missing: the maps to sweep (paths or globs)", file=file, field="maps")
    axes: dict[str, tuple] = {}
    for key, param in AXES.items():
        values = _as_list(spec[key]) if key in spec else [None]
        if not values:
            raise InvalidSweepError("empty list: give at least one value (leave the key out for the default)",
                                    file=file, field=key)  # fmt: skip
        checked = []
        for value in values:
            try:
                checked.append(_check_value(key, param, value))
            except InvalidParamsError as exc:
                raise InvalidSweepError(exc.reason, file=file, field=key) from None
        if len(set(checked)) != len(checked):
            raise InvalidSweepError(f"a value is listed twice ({values})", file=file, field=key)
        axes[key] = tuple(checked)
    return Sweep(name, file, axes)


def _check_value(key: str, param: str | None, value: Any) -> Any:
    """One value of an axis, converted (an int fov becomes a float) and checked by its stage's ``Params``."""
    if value is None and key != "maps":
        return None
    if key == "maps":
        if not isinstance(value, str) or not value.strip():
            raise InvalidParamsError(f"expected a map path or glob, got {value!r}")
        return value
    if key == "seeds":
        if isinstance(value, bool) or not isinstance(value, int):
            raise InvalidParamsError(f"expected an integer seed, got {value!r}")
        pipeline.resolve_params("rrtstar", None, {"seed": value})
        return value
    if key == "tags":
        return TagsChoice.parse(value)
    try:  # the simulate stage's own check of the value alone (the pair noise_deg / noise_bound_deg: expand)
        resolved = pipeline.resolve_params("simulate", None, {param: value})
    except InvalidParamsError as exc:
        raise InvalidParamsError(exc.reason) from None
    if key == "starts" and not (value == "map" or str(value).startswith(("random:", "domain:"))):
        raise InvalidParamsError(f"expected map, random:N or domain:N, got {value!r}")
    return getattr(resolved, param)


def expand_maps(sweep: Sweep, cwd: str | os.PathLike = ".") -> list[Path]:
    """The map files of ``maps:``: each entry a path or a glob, relative to ``cwd``, in the order given.

    Raises
    ------
    InvalidSweepError
        A path that does not exist, or a glob that matches nothing (field ``maps``).
    """
    found: list[Path] = []
    for pattern in sweep.axes["maps"]:
        if globbing.has_magic(pattern):
            matches = sorted(globbing.glob(pattern, root_dir=cwd))
            if not matches:
                raise InvalidSweepError(f"no file matches {pattern!r}", file=sweep.file, field="maps")
            paths = [Path(m) for m in matches]
        else:
            paths = [Path(pattern)]
        for path in paths:
            if not (Path(cwd) / path).is_file():
                raise InvalidSweepError(f"{path} does not exist", file=sweep.file, field="maps")
            if path not in found:
                found.append(path)
    return found


# --------------------------------------------------------------------------- the grid


def _key(document: dict) -> str:
    return artifacts.sha256_text(artifacts.canonical_json(document))


def _versions() -> dict[str, int]:
    """The stage versions a plan's key covers (a new algorithm makes new plans)."""
    return {stage.name: stage.module.VERSION for stage in pipeline.STAGES}


@dataclass(frozen=True)
class Job:
    """One cell of the grid.

    Attributes
    ----------
    key : str
        SHA-256 of the plan key and the complete simulate parameters: the job file's name.
    plan_key : str
        The key of the plan it runs on (:class:`PlanTask`).
    base_key : str
        The key of the plan with the map's own tags, of the same map and seed.
    grid : dict
        Its value of every axis, resolved (``fov`` 360 where the file left it out), for the table.
    source : MapSource
        The map.
    seed : int or None
        ``rrtstar``'s seed (None: the map's).
    tags : TagsParams or None
        :class:`bearnav_cli.tags.Params` of the proposal; None for the map's own tags.
    params : simulate.Params
        The closed loop's parameters, complete.
    """

    key: str
    plan_key: str
    base_key: str
    grid: dict
    source: Any = dataclasses.field(repr=False)
    seed: int | None
    tags: Any
    params: Any = dataclasses.field(repr=False)


def expand(sweep: Sweep, sources: Sequence[Any]) -> tuple[list[Job], int]:
    """Every job of the grid, in the order the axes are listed (maps outermost), and how many cells were left out.

    A cell with both a Gaussian ``noise_deg`` > 0 and a ``noise_bound_deg`` is left out (the
    closed loop takes one noise or the other); any other combination the simulate stage refuses,
    with the map's ``params:``, is an error.

    Parameters
    ----------
    sweep : Sweep
        The checked sweep file.
    sources : sequence of MapSource
        The maps of :func:`expand_maps`, read.

    Raises
    ------
    InvalidSweepError
        A cell whose parameters the stage refuses for a map (field: the map's file).
    """
    from bearnav_cli.stages import simulate

    versions = _versions()
    jobs: list[Job] = []
    skipped = 0
    other = [k for k in AXES if k not in ("maps", "seeds", "tags")]
    for source in sources:
        spec_params = source.spec.get("params") if isinstance(source.spec.get("params"), dict) else {}
        map_name = str(source.spec.get("name", Path(source.file).stem))
        for seed in sweep.axes["seeds"]:
            rrt_seed = pipeline.resolve_params("rrtstar", spec_params, {"seed": seed}).seed
            base_key = _key({"map": source.sha256, "seed": seed, "versions": versions,
                             "format": artifacts.ARTIFACT_FORMAT})  # fmt: skip
            for tags_choice in sweep.axes["tags"]:
                for values in itertools.product(*(sweep.axes[k] for k in other)):
                    overrides = {AXES[k]: v for k, v in zip(other, values, strict=True) if v is not None}
                    if overrides.get("noise_deg") and overrides.get("noise_bound_deg") is not None:
                        skipped += 1
                        continue
                    overrides["record_trajectories"] = False  # the table needs none: memory stays small
                    try:
                        params = pipeline.resolve_params("simulate", spec_params, overrides)
                    except InvalidParamsError as exc:
                        raise InvalidSweepError(f"{exc.reason} (with {overrides})", file=sweep.file,
                                                field=f"{source.file}: {exc.field}") from None  # fmt: skip
                    tags_params = (tags_choice or TagsChoice("own")).params(params)
                    plan_key = base_key if tags_params is None else _key(
                        {"base": base_key, "tags": artifacts.params_dict(tags_params)})  # fmt: skip
                    key = _key({"plan": plan_key, "simulate": artifacts.params_dict(params),
                                "version": simulate.VERSION})  # fmt: skip
                    grid = {
                        "map": map_name, "map_file": source.file, "seed": rrt_seed,
                        "tags": (tags_choice or TagsChoice("own")).text, "fov": params.fov,
                        "noise_deg": params.noise_deg, "noise_bound_deg": params.noise_bound_deg,
                        "dynamics": params.dynamics, "estimator": params.estimator, "starts": params.starts,
                        "sim_seed": params.seed,
                    }  # fmt: skip
                    jobs.append(Job(key, plan_key, base_key, grid, source, seed, tags_params, params))
    return jobs, skipped


# --------------------------------------------------------------------------- what workers run


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


def _one_line(exc: BaseException) -> str:
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
    with_tags = map_stage.MapSource(spec=spec, file=source.file, sha256=f"{source.sha256}+{proposal.count} tags",
                                    grid=source.grid)  # fmt: skip
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
            out["plans"][task.base_key] = {"plan": plan, "manifest": manifest,
                                           "info": {"elapsed_s": time.perf_counter() - began}}  # fmt: skip
    except Exception as exc:  # noqa: BLE001 - recorded with the jobs that needed the plan
        error = _one_line(exc)
        return {"simplified": None, "plans": {key: {"error": error} for key in (task.base_key, *dict(task.tagged))}}
    for key, tags_params in task.tagged:
        began = time.perf_counter()
        try:
            tagged, manifest, info = _tagged_plan(task, simplified, plan, tags_params)
            out["plans"][key] = {"plan": tagged, "manifest": manifest,
                                 "info": {**info, "elapsed_s": time.perf_counter() - began}}  # fmt: skip
        except Exception as exc:  # noqa: BLE001 - recorded with the jobs that needed the plan
            out["plans"][key] = {"error": _one_line(exc)}
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
        return {"status": "failed", "error": _one_line(exc), "sim_s": time.perf_counter() - began}
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


# --------------------------------------------------------------------------- running a sweep


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
    document = {"schema": "bearnav.sweep-plan/1", "key": key, "map": job.grid["map"],
                "map_file": job.grid["map_file"], "seed": job.grid["seed"], "tags": tags, **info}  # fmt: skip
    artifacts.write_record(folder / "plan.json", document)


def _worker_signals() -> None:
    """A local worker leaves Ctrl-C to the sweep, which stops it (:func:`stop_local`); SIGTERM ends it at once.

    A forked worker inherits the command line's handlers, which turn both signals into exceptions
    that a long job may not see for seconds.
    """
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def local_executor(jobs: int) -> Any:
    """A :class:`concurrent.futures.ProcessPoolExecutor` of ``jobs`` processes (``--jobs``)."""
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(max_workers=jobs, initializer=_worker_signals)


def stop_local(executor: Any, interrupted: bool) -> None:
    """Shut a :func:`local_executor` down: wait for it after a sweep, end its workers at once after an interrupt."""
    if not interrupted:
        executor.shutdown(wait=True)
        return
    # the executor has no public way to end running jobs: its worker processes (a CPython attribute since 3.2)
    for process in list((getattr(executor, "_processes", None) or {}).values()):
        process.terminate()
    executor.shutdown(wait=True, cancel_futures=True)


def connect_scheduler(address: str, timeout: float = SCHEDULER_TIMEOUT_S) -> tuple[Any, Callable[[], None]]:
    """Dask's executor on the scheduler at ``address`` (``--scheduler``), and a function that closes it.

    Only here is ``distributed`` imported (``bearnav[dask]``). A refused or unknown address fails at
    once, a silent one after ``timeout`` seconds.

    Raises
    ------
    BearnavError
        ``distributed`` is not installed, or the scheduler cannot be reached (naming the address).
    """
    try:
        from distributed import Client
    except ImportError:
        raise BearnavError("--scheduler: needs Dask's distributed (pip install 'bearnav[dask]')") from None
    host_port = address.split("://", 1)[-1]
    host, _, port = host_port.rpartition(":")
    try:  # a plain TCP probe first: a refused port or an unknown host answers at once
        socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), timeout=timeout).close()
    except (OSError, ValueError) as exc:
        raise BearnavError(f"--scheduler: cannot reach the Dask scheduler at {address} ({_one_line(exc)})") from None
    try:
        client = Client(address, timeout=f"{timeout}s")
    except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, whatever the protocol says: one line
        raise BearnavError(f"--scheduler: cannot reach the Dask scheduler at {address} ({_one_line(exc)})") from None
    return client.get_executor(), client.close


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
        return failure(f"worker: {_one_line(exc)}")


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
        figures = {"tolerance": _finite(getattr(plan, "plan_tolerance", None)), "cells": int(len(plan.cells.cell_node)),
                   "n_tags": int(len(plan.map.landmarks)), "new_tags": info.get("new_tags")}  # fmt: skip
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


# --------------------------------------------------------------------------- the table and the figure


def table(jobs: Sequence[Job], found: dict[str, dict]) -> list[dict]:
    """One row of :data:`COLUMNS` per job of the grid that has a file in the store, in grid order.

    A failed job has its grid values, ``status`` ``failed`` and its ``error``; its counts are None.
    """
    rows = []
    for job in jobs:
        record = found.get(job.key)
        if record is None:
            continue
        result = record.get("result") or {}
        plan = record.get("plan") or {}
        times = record.get("times") or {}
        row = {**record["grid"], "status": record["status"], "error": record.get("error"),
               "n_tags": plan.get("n_tags"), "plan_tolerance": plan.get("tolerance"), "plan_cells": plan.get("cells"),
               "plan_key": job.plan_key[:24], "job_key": job.key[:24], "plan_s": times.get("plan_s"),
               "sim_s": times.get("sim_s")}  # fmt: skip
        for name in ("runs", *OUTCOMES, "success_rate", "certified_step_fraction", "in_domain_fraction",
                     "success_rate_in_domain"):  # fmt: skip
            row[name] = result.get(name)
        rows.append({column: row.get(column) for column in COLUMNS})
    return rows


def write_results(store: str | os.PathLike, rows: Sequence[dict]) -> list[Path]:
    """``results.csv`` and, when pyarrow is installed, ``results.parquet`` in the store; the files written."""
    store = Path(store)
    written = [artifacts.write_table(store / "results.csv", COLUMNS, rows)]
    parquet = artifacts.write_parquet(store / "results.parquet", COLUMNS, rows)
    return written + ([parquet] if parquet is not None else [])


@dataclass(frozen=True)
class Panel:
    """One panel of the success figure: one map and dynamics, success against noise, a line per curve.

    Attributes
    ----------
    map, dynamics : str
        What the panel shows.
    lines : tuple of dict
        Each ``{"fov": float, "variant": str, "variant_index": int, "noise": list of float,
        "success": list of float}``: success rates (0–1) against the noise (degrees: ``noise_deg``, or
        ``noise_bound_deg`` for a bounded noise), sorted by noise; ``variant`` names the values of the
        other axes that vary in the sweep (``tags=own``), ``""`` when none does.
    tags : str
        The tag counts of the panel's plans (``"6 → 9 tags"``).
    """

    map: str
    dynamics: str
    lines: tuple
    tags: str


#: Axes that tell lines of one panel and field of view apart.
_VARIANT_AXES = ("tags", "estimator", "seed", "sim_seed", "starts", "noise_kind")


def success_curves(rows: Sequence[dict]) -> list[Panel]:
    """The success figure's data (drawn by :func:`bearnav_cli.plot.sweep_plot`): a panel per map and dynamics.

    Parameters
    ----------
    rows : sequence of dict
        Rows of :func:`table`; failed jobs are left out.
    """
    done = [dict(r, noise_kind="bounded" if r["noise_bound_deg"] is not None else "gaussian") for r in rows
            if r["status"] == "done" and r["success_rate"] is not None]  # fmt: skip
    varying = [axis for axis in _VARIANT_AXES if len({r[axis] for r in done}) > 1]
    variants: list[tuple] = []
    panels = []
    for map_name, dynamics in dict.fromkeys((r["map"], r["dynamics"]) for r in done):
        here = [r for r in done if (r["map"], r["dynamics"]) == (map_name, dynamics)]
        lines = []
        for fov, variant in dict.fromkeys((r["fov"], tuple(r[a] for a in varying)) for r in here):
            points = sorted((_noise(r), r["success_rate"]) for r in here
                            if r["fov"] == fov and tuple(r[a] for a in varying) == variant)  # fmt: skip
            if variant not in variants:
                variants.append(variant)
            label = ", ".join(f"{axis}={value}" for axis, value in zip(varying, variant, strict=True))
            lines.append({"fov": fov, "variant": label, "variant_index": variants.index(variant),
                          "noise": [p[0] for p in points], "success": [p[1] for p in points]})  # fmt: skip
        counts = sorted({r["n_tags"] for r in here if r["n_tags"] is not None})
        panels.append(Panel(map_name, dynamics, tuple(lines), " → ".join(map(str, counts)) + " tags" if counts else ""))
    return panels


def _noise(row: dict) -> float:
    return row["noise_bound_deg"] if row["noise_bound_deg"] is not None else row["noise_deg"]


def markdown(panels: Sequence[Panel], title: str) -> str:
    """The figure's numbers as tables: per panel, noise × field of view, variants as ``a → b``."""
    lines = [f"# {title}", "", "Success rate of the runs (`results.csv` has every count).", ""]
    for panel in panels:
        fovs = list(dict.fromkeys(line["fov"] for line in panel.lines))
        noises = sorted({n for line in panel.lines for n in line["noise"]})
        variants = list(dict.fromkeys(line["variant"] for line in panel.lines))
        heading = f"## {panel.map}, {panel.dynamics}" + (f" ({panel.tags})" if panel.tags else "")
        note = " → ".join(variants) if variants != [""] else ""
        lines += [heading, ""] + ([f"Each cell: {note}.", ""] if note else [])
        lines += ["| noise | " + " | ".join(f"{f:g}° view" for f in fovs) + " |",
                  "| ---: | " + " | ".join("---:" for _ in fovs) + " |"]  # fmt: skip
        for noise in noises:
            cells = []
            for fov in fovs:
                values = []
                for variant in variants:
                    line = next((x for x in panel.lines if x["fov"] == fov and x["variant"] == variant), None)
                    value = dict(zip(line["noise"], line["success"], strict=True)).get(noise) if line else None
                    values.append("–" if value is None else f"{100 * value:.1f}%")
                cells.append(values[0] if len(set(values)) == 1 else " → ".join(values))
            lines.append(f"| {noise:g}° | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)
