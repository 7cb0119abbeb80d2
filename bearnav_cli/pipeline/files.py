"""``bearnav plan`` and the single-stage commands on files: freshness, output checks, locks (DESIGN §3.1, §5).

A stage runs only when no output with the same cache key, naming the current input's content
hash, exists and loads (every check of :func:`bearnav_cli.artifacts.load`). Parameters resolve as
:mod:`bearnav_cli.pipeline.params` says, and the stage runs and its manifest is made as
:mod:`bearnav_cli.pipeline.chain` does it in memory.

Every output path is checked before any work, and every run holds the lock of its output
folder (:func:`bearnav_cli.artifacts.output_folder`), so two runs never mix their artifacts.
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from bearnav_cli import artifacts
from bearnav_cli.datatypes import Map, replace
from bearnav_cli.errors import ArtifactError, InternalError, InvalidMapError
from bearnav_cli.pipeline.chain import execute, stage_manifest
from bearnav_cli.pipeline.current import begin, committed
from bearnav_cli.pipeline.params import check_map_params, map_stage_params, resolve_params, stage_params
from bearnav_cli.pipeline.table import STAGE_BY_NAME, STAGES, Progress, Stage

__all__ = ["load", "MAP_SUFFIXES", "plan", "run_map", "run_stage", "StageReport"]


@dataclass(frozen=True)
class StageReport:
    """What happened to one stage: ran or fresh, where, how long, and its summary.

    Attributes
    ----------
    stage : str
        The stage's name.
    path : Path
        Its output file.
    ran : bool
        True if it ran; False if a fresh output was kept.
    elapsed_s : float
        Wall-clock time of the run (s); 0 when it did not run.
    summary : str
        The one-line summary (the manifest's ``summary``).
    artifact : Map, Tree, Cells, Plan or Simulation, optional
        The output, as written or loaded (default None, for a report made without it).
    manifest : dict, optional
        The output's manifest (default None, for a report made without it).
    """

    stage: str
    path: Path
    ran: bool
    elapsed_s: float
    summary: str
    artifact: Any = dataclasses.field(repr=False, default=None)
    manifest: dict | None = dataclasses.field(repr=False, default=None)


# --------------------------------------------------------------------------- loading


#: Suffixes of files that are map descriptions, not artifacts.
MAP_SUFFIXES = (".yaml", ".yml")


def _check_artifact_path(path: Path, expect: str | tuple[str, ...] | None) -> None:
    """Advice for the usual wrong-kind inputs before the loader's generic message: a folder, a map YAML."""
    wanted = (expect,) if isinstance(expect, str) else tuple(expect or ())
    names = [artifacts.KINDS[kind].filename for kind in wanted] or ["plan.npz", "map.json"]
    if path.is_dir():
        inside = [path / name for name in names if (path / name).is_file()]
        hint = f"; did you mean {inside[0]}?" if inside else f" (expected a file such as {names[0]})"
        raise ArtifactError(f"is a folder, not an artifact file{hint}", file=str(path))
    if path.suffix.lower() in MAP_SUFFIXES and path.is_file():
        folder = Path("plans") / path.stem
        raise ArtifactError(
            f"is a map YAML, not an artifact: run `bearnav plan {path}` first (it writes {folder}/map.json ... "
            f"{folder}/plan.npz), then give one of those",
            file=str(path),
        )


def load(path: str | Path, expect: str | tuple[str, ...] | None = None) -> artifacts.Loaded:
    """:func:`bearnav_cli.artifacts.load`, plus the map's ``params:`` checked against the stage table.

    Raises
    ------
    ArtifactError
        Everything :func:`artifacts.load` checks, and a ``params`` entry of the (embedded) map
        that names an unknown stage or parameter or has a value of the wrong type or range.
    """
    _check_artifact_path(Path(path), expect)
    loaded = artifacts.load(path, expect)
    map_ = loaded.artifact if isinstance(loaded.artifact, Map) else loaded.artifact.map
    try:
        check_map_params(map_.params, str(path), diagonal=map_.diagonal)
    except InvalidMapError as exc:
        prefix = "" if isinstance(loaded.artifact, Map) else "map."
        raise ArtifactError(exc.reason, file=str(path), field=prefix + (exc.field or "params")) from None
    return loaded


# --------------------------------------------------------------------------- running, on files


def _relative_to_output(input_path: str | None, out: Path) -> str | None:
    """The input's path as the manifest records it: relative to the output's folder.

    An artifact shared with others then reveals no absolute path of the machine that made it, and
    stays right when its folder moves together with its inputs.
    """
    if input_path is None:
        return None
    try:
        return os.path.relpath(os.path.abspath(input_path), os.path.abspath(out.parent))
    except ValueError:  # another drive (Windows): no relative path exists
        return input_path


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
    if not force:
        loaded = artifacts.fresh(out, stage.output_kind, key, input_hash)
        if loaded is not None:
            artifact = _with_current_params(loaded, payload, out)
            committed()
            summary = loaded.manifest.get("summary", "")
            return StageReport(stage.name, out, False, 0.0, summary, artifact, loaded.manifest)
    started = time.perf_counter()
    result = execute(stage, payload, params, progress, input_path or str(out))
    elapsed = time.perf_counter() - started
    manifest = stage_manifest(stage, result, payload, params, input_hash, _relative_to_output(input_path, out), elapsed)
    summary = manifest["summary"]
    try:
        artifacts.save(out, result, manifest, on_commit=committed)
    except ArtifactError as exc:
        if exc.file is not None:
            raise
        # the stage's own output breaks its type's invariants: a bug, not the user's input
        raise InternalError(
            f"{stage.name} made an artifact that fails its own checks, nothing written ({exc})", file=str(out)
        ) from None
    return StageReport(stage.name, out, True, elapsed, summary, result, manifest)


def _with_current_params(loaded: artifacts.Loaded, payload: Any, out: Path) -> Any:
    """A fresh artifact whose embedded map carries the input's ``params:`` (rewritten if they differ).

    The map's ``params`` stay out of content hashes (:func:`artifacts.content_hash`), so an edit of
    ``params: simulate:`` leaves every planning stage fresh; but ``plan.npz`` alone must drive
    ``bearnav simulate`` with the map's current ``params:``, so the file is written again with the
    new ones: same data, same content hash, same manifest, no stage rerun.
    """
    artifact = loaded.artifact
    current = payload.map if hasattr(payload, "map") else payload
    if isinstance(artifact, Map) or not isinstance(current, Map) or artifact.map.params == current.params:
        return artifact
    refreshed = replace(artifact, map=current)
    artifacts.save(out, refreshed, loaded.manifest)
    return refreshed


def _check_outputs(stage: Stage, out: Path, inputs: tuple[str | Path, ...] = (), force: bool = False) -> None:
    """Every file the stage writes at ``out``: a fitting path, not an input, and nothing bearnav's stage did not
    write (unless ``force``)."""
    for path in artifacts.output_files(stage.output_kind, out):
        artifacts.check_output_file(
            path, (path.suffix if path != out else artifacts.KINDS[stage.output_kind].suffix,), inputs=inputs
        )
        artifacts.check_overwrite(path, stage.name, force=force)


def run_map(source: Any, out: Path, overrides: dict | None = None, force: bool = False) -> StageReport:
    """Run the map stage on a source read by the CLI and write ``map.json``.

    Parameters
    ----------
    source : MapSource
        The parsed map description, with its file name and input hash (``sha256``).
    out : Path
        The ``map.json`` to write; checked before any work, its folder locked while writing.
    overrides : dict, optional
        Explicit map-stage parameters (CLI options), over the description's ``params: map:``.
    force : bool, default False
        Run even if ``out`` is fresh (same cache key and input hash).

    Returns
    -------
    StageReport
        What happened: ran or kept, the map and its manifest.
    """
    stage = STAGE_BY_NAME["map"]
    begin("map", source.file)
    out = Path(out)
    _check_outputs(stage, out, (source.file,), force)
    params = map_stage_params(source, overrides)
    with artifacts.output_folder(out.parent):
        return _run_and_save(stage, source, params, out, source.file, source.sha256, force, None)


def run_stage(
    name: str,
    input_path: Path,
    out: Path | None = None,
    overrides: dict | None = None,
    force: bool = False,
    progress: Progress | None = None,
    given: StageReport | None = None,
) -> StageReport:
    """Run one stage after ``map`` on the artifact at ``input_path``.

    The output goes to ``out`` or, by default, the stage's conventional file name next to the
    input; it is checked before the input is read. A fresh output is kept unless ``force``.

    Parameters
    ----------
    name : str
        The stage (``"rrtstar"``, ``"simplify"``, ``"decompose"``, ``"synthesize"``,
        ``"simulate"``), a key of :data:`STAGE_BY_NAME`.
    input_path : Path
        The input artifact, of the stage's ``input_kind``.
    out : Path, optional
        The output file; by default the stage's conventional file name next to the input.
    overrides : dict, optional
        Explicit parameters (CLI options), over the embedded map's ``params:`` and the defaults.
    force : bool, default False
        Run even if the output is fresh.
    progress : callable, optional
        ``progress(done, total)``, called by long stages.
    given : StageReport, optional
        The report of the stage that wrote ``input_path`` in this process, under the same lock
        (:func:`plan`): its artifact and manifest are what the file holds, so the input is taken
        from them instead of being read, parsed and hashed again.

    Returns
    -------
    StageReport
        What happened: ran or kept, the output and its manifest.
    """
    stage = STAGE_BY_NAME[name]
    begin(name, input_path)
    out = Path(out) if out is not None else Path(input_path).with_name(stage.filename)
    _check_outputs(stage, out, (input_path,), force)
    with artifacts.output_folder(out.parent):
        if given is not None and given.artifact is not None and given.manifest is not None:
            artifact, manifest = given.artifact, given.manifest
        else:
            loaded = load(input_path, stage.input_kind)
            artifact, manifest = loaded.artifact, loaded.manifest
        params = stage_params(name, artifact, overrides)
        return _run_and_save(stage, artifact, params, out, str(input_path), manifest["content_sha256"], force, progress)


def _spec_params(source: Any) -> Any:
    return source.spec.get("params", {}) if isinstance(source.spec, dict) else {}


def _spec_name(source: Any) -> str:
    """The name the map stage gives the map of ``source`` (its ``name:``, by default ``map``)."""
    name = source.spec.get("name", "map") if isinstance(source.spec, dict) else "map"
    return str(name)


def _check_plan_params(map_params: Any, source: Any, overrides: dict[str, dict], diagonal: float | None) -> None:
    """Build every stage's ``Params`` before the first one runs, so that a bad option writes nothing.

    Without the map's diagonal (a YAML not yet normalised) the limits given relative to it wait for
    the stage itself (:func:`~bearnav_cli.pipeline.params.stage_params`), as do the resource estimates,
    which need its input.
    """
    if not isinstance(source, Path):
        map_stage_params(source, overrides.get("map"))
    for stage in STAGES[1:]:
        resolve_params(stage.name, map_params, overrides.get(stage.name), diagonal)


def _check_chain(reports: list[StageReport]) -> None:
    """Each stage's output names the content hash of the artifact before it (the lock makes this hold)."""
    for before, after in zip(reports[:-1], reports[1:], strict=True):
        if before.manifest is None or after.manifest is None:
            continue
        if after.manifest["input"]["content_sha256"] != before.manifest["content_sha256"]:
            raise ArtifactError(
                f"was made from another {before.path.name} than the one next to it; rerun with --force",
                file=str(after.path),
            )


def _adopt_map(loaded: artifacts.Loaded, map_json: Path, target: Path) -> StageReport:
    """A ready ``map.json`` (``loaded`` from ``map_json``) as the map stage's report, copied into the plan
    folder when it lies elsewhere."""
    if artifacts.copy_file(map_json, target):  # the same bytes: what was loaded is what is there now
        loaded = dataclasses.replace(loaded, path=target)
    committed()
    manifest = loaded.manifest
    return StageReport("map", target, False, 0.0, manifest.get("summary", ""), loaded.artifact, manifest)


def plan(
    source: Any,
    out_dir: Path,
    overrides: dict[str, dict] | None = None,
    force: bool = False,
    progress: Callable[[str], Progress | None] | None = None,
    on_stage: Callable[[StageReport], None] | None = None,
) -> list[StageReport]:
    """Run every stage from the map description into ``out_dir``, skipping fresh ones.

    The folder is checked first (a file in its place, a folder where an artifact goes,
    unwritable) and locked for the whole run.

    Parameters
    ----------
    source : MapSource or Path
        The map description, or a ``map.json`` already written by the map stage (copied into
        ``out_dir`` when it lies elsewhere; the map stage then does not run).
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
    out_dir = Path(out_dir)
    begin("map", source if isinstance(source, Path) else source.file)
    names = tuple(stage.filename for stage in STAGES)
    artifacts.check_output_folder(out_dir, names)
    adopted = load(source, "map") if isinstance(source, Path) else None
    map_params = adopted.artifact.params if adopted is not None else _spec_params(source)
    map_name = adopted.artifact.name if adopted is not None else _spec_name(source)
    _check_plan_params(map_params, source, overrides, adopted.artifact.diagonal if adopted is not None else None)
    artifacts.check_plan_folder(out_dir, names, map_name, force=force)
    for stage in STAGES:  # before any stage runs: nothing of the plan is written when one of them is refused
        _check_outputs(stage, out_dir / stage.filename, (), force)  # a map.json given is copied over map.json
    with artifacts.output_folder(out_dir):
        if isinstance(source, Path):
            reports = [_adopt_map(adopted, source, out_dir / STAGES[0].filename)]
        else:
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
                given=reports[-1],  # what the previous stage wrote (or kept) a moment ago, under this lock
            )
            reports.append(report)
            if on_stage:
                on_stage(report)
        _check_chain(reports)
    return reports
