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

Every name is re-exported here; the modules, each with one job:

- :mod:`~bearnav_cli.sweep.grid` — the sweep file, its map files and the grid of keyed jobs;
- :mod:`~bearnav_cli.sweep.work` — what workers run: a map's plans, one job's closed loop;
- :mod:`~bearnav_cli.sweep.executors` — a local process pool or a Dask cluster;
- :mod:`~bearnav_cli.sweep.store` — :func:`run`: the missing jobs into the store, job files as they end;
- :mod:`~bearnav_cli.sweep.results` — the table and the success figure's data and numbers.
"""

from bearnav_cli.sweep.executors import SCHEDULER_TIMEOUT_S, connect_scheduler, local_executor, stop_local
from bearnav_cli.sweep.grid import AXES, Job, Sweep, TagsChoice, expand, expand_maps, read_sweep
from bearnav_cli.sweep.results import (
    COLUMNS,
    DETERMINISTIC_COLUMNS,
    Panel,
    markdown,
    success_curves,
    table,
    write_results,
)
from bearnav_cli.sweep.store import JOB_SCHEMA, SweepReport, records, run
from bearnav_cli.sweep.work import PlanTask, make_plans, run_job

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
