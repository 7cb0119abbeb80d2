"""The stage table, parameter resolution, freshness, ``bearnav plan`` and the same chain in memory (DESIGN §3.1, §5).

A stage runs only when no output with the same cache key, naming the current input's content
hash, exists and loads (every check of :func:`bearnav_cli.artifacts.load`). Parameters resolve
as: the stage's defaults, then the map's ``params: {stage: {...}}``, then explicit overrides (the
CLI options); every numeric one must lie in its documented range (:data:`bearnav_cli.limits.LIMITS`)
and each stage refuses requests too big to finish before it starts (its ``check_resources``).

Every output path is checked before any work, and every run holds the lock of its output
folder (:func:`bearnav_cli.artifacts.output_folder`), so two runs never mix their artifacts.

The modules, each importing only those above it:

- :mod:`~bearnav_cli.pipeline.table`: the stage table (:class:`Stage`, :data:`STAGES`), the one way to a
  stage: no module of the pipeline imports a stage by name (tests/test_layering.py);
- :mod:`~bearnav_cli.pipeline.params`: :func:`resolve_params`, :class:`Origins`, the map's ``params:``;
- :mod:`~bearnav_cli.pipeline.chain`: :func:`compute` and :func:`compute_saved`, the chain in memory;
- :mod:`~bearnav_cli.pipeline.current`: what is running (:data:`ACTIVITY`, :func:`activity`);
- :mod:`~bearnav_cli.pipeline.files`: :func:`plan`, :func:`run_stage`, :func:`run_map`, :func:`load`.

This package re-exports what the command line, ``sweep``, the benchmarks and the tests use.
"""

from bearnav_cli.pipeline.chain import compute, compute_saved
from bearnav_cli.pipeline.current import ACTIVITY, Activity, activity, reset_activity
from bearnav_cli.pipeline.files import StageReport, load, plan, run_map, run_stage
from bearnav_cli.pipeline.params import check_map_params, resolve_params
from bearnav_cli.pipeline.table import SIMULATE, STAGE_BY_NAME, STAGES, Origins, Progress, Stage

__all__ = [
    "ACTIVITY",
    "Activity",
    "activity",
    "check_map_params",
    "compute",
    "compute_saved",
    "load",
    "Origins",
    "plan",
    "Progress",
    "reset_activity",
    "resolve_params",
    "run_map",
    "run_stage",
    "SIMULATE",
    "Stage",
    "STAGE_BY_NAME",
    "StageReport",
    "STAGES",
]
