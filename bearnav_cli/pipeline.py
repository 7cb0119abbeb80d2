"""The stage table, parameter resolution, freshness and ``bearnav plan`` (DESIGN §3.1, §5).

A stage runs only when no output with the same cache key and an intact content
hash exists. Parameters resolve as: the stage's defaults, then the map's
``params: {stage: {...}}``, then explicit overrides (the CLI options).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, Callable

from bearnav_cli import artifacts
from bearnav_cli.datatypes import Map
from bearnav_cli.errors import InvalidMapError, InvalidParamsError
from bearnav_cli.stages import decompose, map_, rrtstar, simplify, simulate, synthesize

#: ``progress(done, total)``, called by long stages.
Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class Stage:
    """One row of the stage table."""

    name: str
    module: ModuleType
    input_kind: str | None
    output_kind: str

    @property
    def filename(self) -> str:
        return artifacts.KINDS[self.output_kind].filename


STAGES: tuple[Stage, ...] = (
    Stage("map", map_, None, "map"),
    Stage("rrtstar", rrtstar, "map", "tree"),
    Stage("simplify", simplify, "tree", "simplified"),
    Stage("decompose", decompose, "simplified", "cells"),
    Stage("synthesize", synthesize, "cells", "plan"),
)
#: Not part of ``plan``: run on a plan by ``bearnav simulate`` (maps may still set its ``params:``).
SIMULATE = Stage("simulate", simulate, "plan", "simulation")
STAGE_BY_NAME = {stage.name: stage for stage in (*STAGES, SIMULATE)}


@dataclass(frozen=True)
class StageReport:
    """What happened to one stage: ran or fresh, where, how long, and its summary."""

    stage: str
    path: Path
    ran: bool
    elapsed_s: float
    summary: str
    artifact: Any = dataclasses.field(repr=False, default=None)


def _coerce(stage: str, name: str, default: Any, value: Any, origin: str) -> Any:
    """Check and convert one parameter value against the type of its default."""
    where = f"params.{stage}.{name}" if origin == "map" else f"--{name.replace('_', '-')}"
    kind = type(default)
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise InvalidParamsError(f"expected true or false, got {value!r}", field=where)
        return value
    if isinstance(default, int) and not isinstance(value, bool):
        if isinstance(value, float) and value.is_integer():
            return int(value)
        if isinstance(value, int):
            return value
    if isinstance(default, float) and isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if isinstance(default, str) and isinstance(value, str):
        return value
    if default is None and isinstance(value, (int, float, str)) and not isinstance(value, bool):
        return value
    raise InvalidParamsError(f"expected {kind.__name__}, got {value!r}", field=where)


def resolve_params(stage: str, map_params: dict | None, overrides: dict | None = None) -> Any:
    """Build the stage's frozen ``Params``: defaults, then the map's, then ``overrides``.

    Raises
    ------
    InvalidParamsError
        For an unknown name, a value of the wrong type or out of range (the stage's
        ``Params`` checks its own ranges).
    """
    params_type = STAGE_BY_NAME[stage].module.Params
    defaults = {f.name: f.default for f in dataclasses.fields(params_type)}
    values = dict(defaults)
    for origin, source in (("map", (map_params or {}).get(stage, {})), ("cli", overrides or {})):
        for name, value in source.items():
            if value is None and origin == "cli":
                continue
            if name not in defaults:
                where = f"params.{stage}.{name}" if origin == "map" else f"--{name}"
                raise InvalidParamsError(f"unknown parameter (known: {', '.join(defaults)})", field=where)
            values[name] = _coerce(stage, name, defaults[name], value, origin)
    return params_type(**values)


def check_map_params(map_params: dict, file: str) -> None:
    """Reject unknown stage names and parameters in a map's ``params:`` section."""
    for stage in map_params:
        if stage not in STAGE_BY_NAME:
            known = ", ".join(STAGE_BY_NAME)
            raise InvalidMapError(f"unknown stage (known: {known})", file=file, field=f"params.{stage}")
        try:
            resolve_params(stage, map_params)
        except InvalidParamsError as exc:
            raise InvalidMapError(str(exc).split(": ", 1)[-1], file=file, field=exc.field) from exc


def _run_and_save(
    stage: Stage,
    payload: Any,
    params: Any,
    out: Path,
    input_path: str | None,
    input_hash: str,
    force: bool,
    progress: Progress | None,
) -> StageReport:
    params_json = artifacts.params_dict(params)
    key = artifacts.cache_key(stage.name, stage.module.VERSION, params_json, input_hash)
    if not force and artifacts.is_fresh(out, key):
        loaded = artifacts.load(out, stage.output_kind)
        return StageReport(stage.name, out, False, 0.0, loaded.manifest.get("summary", ""), loaded.artifact)
    started = time.perf_counter()
    result = stage.module.run(payload, params, progress=progress)
    elapsed = time.perf_counter() - started
    summary = stage.module.summary(result)
    manifest = artifacts.make_manifest(
        stage.output_kind,
        result,
        stage=stage.name,
        stage_version=stage.module.VERSION,
        params=params_json,
        input_path=input_path,
        input_hash=input_hash,
        summary=summary,
        elapsed_s=elapsed,
        stats=getattr(result, "stats", None),
    )
    artifacts.save(out, result, manifest)
    return StageReport(stage.name, out, True, elapsed, summary, result)


def run_map(source: map_.MapSource, out: Path, overrides: dict | None = None, force: bool = False) -> StageReport:
    """Run the map stage on a source read by the CLI and write ``map.json``."""
    map_params = source.spec.get("params", {}) if isinstance(source.spec, dict) else {}
    if not isinstance(map_params, dict):
        raise InvalidMapError("expected a mapping of stage name to options", file=source.file, field="params")
    check_map_params(map_params, source.file)
    params = resolve_params("map", map_params, overrides)
    return _run_and_save(STAGE_BY_NAME["map"], source, params, out, source.file, source.sha256, force, None)


def run_stage(
    name: str,
    input_path: Path,
    out: Path | None = None,
    overrides: dict | None = None,
    force: bool = False,
    progress: Progress | None = None,
) -> StageReport:
    """Run one stage after ``map`` on the artifact at ``input_path``.

    The output goes to ``out`` or, by default, the stage's conventional file name
    next to the input. A fresh output is kept unless ``force``.
    """
    stage = STAGE_BY_NAME[name]
    loaded = artifacts.load(input_path, stage.input_kind)
    source_map: Map = loaded.artifact if isinstance(loaded.artifact, Map) else loaded.artifact.map
    params = resolve_params(name, source_map.params, overrides)
    out = Path(out) if out is not None else Path(input_path).with_name(stage.filename)
    return _run_and_save(
        stage, loaded.artifact, params, out, str(input_path), loaded.manifest["content_sha256"], force, progress
    )


def plan(
    source: map_.MapSource,
    out_dir: Path,
    overrides: dict[str, dict] | None = None,
    force: bool = False,
    progress: Callable[[str], Progress | None] | None = None,
    on_stage: Callable[[StageReport], None] | None = None,
) -> list[StageReport]:
    """Run every stage from the map description into ``out_dir``, skipping fresh ones.

    Parameters
    ----------
    source : MapSource
        The map description.
    out_dir : Path
        Folder for ``map.json``, ``tree.npz`` ...
    overrides : dict, optional
        ``{stage: {param: value}}`` from the command line.
    force : bool
        Rerun every stage.
    progress : callable, optional
        ``progress(stage_name)`` returns a progress callback for that stage, or None.
    on_stage : callable, optional
        Called with each :class:`StageReport` as soon as the stage is done.
    """
    overrides = overrides or {}
    reports = [run_map(source, out_dir / STAGES[0].filename, overrides.get("map"), force)]
    if on_stage:
        on_stage(reports[-1])
    for stage in STAGES[1:]:
        report = run_stage(
            stage.name,
            reports[-1].path,
            out_dir / stage.filename,
            overrides.get(stage.name),
            force,
            progress(stage.name) if progress else None,
        )
        reports.append(report)
        if on_stage:
            on_stage(report)
    return reports
