"""The stage table, parameter resolution and limits, freshness and ``bearnav plan`` (DESIGN §3.1, §5).

A stage runs only when no output with the same cache key, naming the current input's content
hash, exists and loads (every check of :func:`bearnav_cli.artifacts.load`). Parameters resolve
as: the stage's defaults, then the map's ``params: {stage: {...}}``, then explicit overrides (the
CLI options); every numeric one must lie in its documented range (:data:`bearnav_cli.limits.LIMITS`)
and each stage refuses requests too big to finish before it starts (its ``check_resources``, called
through :meth:`Stage.check_resources`).

Every output path is checked before any work, and every run holds the lock of its output
folder (:func:`bearnav_cli.artifacts.output_folder`), so two runs never mix their artifacts.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import os
import time
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, Callable, Iterator, Mapping

from bearnav_cli import artifacts
from bearnav_cli.datatypes import Map, replace
from bearnav_cli.errors import ArtifactError, InternalError, InvalidMapError, InvalidParamsError
from bearnav_cli.limits import LIMITS, check_value, option_name

# The stage modules (scipy, highspy and the algorithms) are imported when a stage is used, not with
# the pipeline: loading an artifact (`bearnav inspect`) imports only the stages whose parameters its
# map's ``params:`` sets, to check them (:attr:`Stage.module`).
if TYPE_CHECKING:
    from bearnav_cli.stages import map_
    from bearnav_cli.verdicts import Problem

__all__ = [
    "Activity",
    "ACTIVITY",
    "activity",
    "check_map_params",
    "compute",
    "compute_saved",
    "load",
    "MAP_SUFFIXES",
    "Origins",
    "plan",
    "reset_activity",
    "resolve_params",
    "stage_manifest",
    "run_map",
    "run_stage",
    "SIMULATE",
    "Stage",
    "STAGE_BY_NAME",
    "StageReport",
    "STAGES",
]

#: ``progress(done, total)``, called by long stages.
Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class Stage:
    """One row of the stage table.

    Attributes
    ----------
    name : str
        The stage's name (``"rrtstar"``), as the CLI, the manifests and ``params:`` name it.
    module_name : str
        Its module in :mod:`bearnav_cli.stages` (``"bearnav_cli.stages.rrtstar"``).
    input_kind : str or None
        The artifact kind it reads (a key of :data:`bearnav_cli.artifacts.KINDS`); None for
        ``map``, which reads a map description.
    output_kind : str
        The artifact kind it writes.
    module : ModuleType
        The module itself, imported on first use: ``Params``, ``VERSION``, ``run`` and ``summary``,
        ``check_resources(input, params, given)`` where the stage estimates its requests (``rrtstar``,
        ``simulate``) and ``problems(result)`` where it judges its result (``rrtstar`` to ``synthesize``).
    filename : str
        The conventional file name of its output (``"tree.npz"``).
    """

    name: str
    module_name: str
    input_kind: str | None
    output_kind: str

    @property
    def module(self) -> ModuleType:
        return importlib.import_module(self.module_name)

    @property
    def filename(self) -> str:
        return artifacts.KINDS[self.output_kind].filename

    def check_resources(self, artifact: Any, params: Any, origins: Origins) -> None:
        """The stage's estimates on its input, before it runs (its ``check_resources``; none without one).

        Parameters
        ----------
        artifact : Any
            The stage's input (the map for ``rrtstar``, the plan for ``simulate``).
        params : Params
            Its resolved parameters.
        origins : Origins
            Where each parameter came from: the stage is told which were given, and the field of its
            error, a parameter's name, becomes the option or map field that set it (``--step``,
            ``params.rrtstar.step``).

        Raises
        ------
        ResourceLimitError, InvalidParamsError
            A request over a limit or the memory budget, naming the option to change.
        """
        check = getattr(self.module, "check_resources", None)
        if check is None:
            return
        try:
            check(artifact, params, origins.given)
        except InvalidParamsError as exc:  # ResourceLimitError too: the same class, the field translated
            raise type(exc)(exc.reason, field=origins.field(exc.field)) from None

    def problems(self, result: Any) -> list[Problem]:
        """Why the stage's ``result`` is not usable, worst first (its ``problems``); empty when it is, or
        when the stage judges nothing."""
        judge = getattr(self.module, "problems", None)
        return [] if judge is None else list(judge(result))


STAGES: tuple[Stage, ...] = (
    Stage("map", "bearnav_cli.stages.map_", None, "map"),
    Stage("rrtstar", "bearnav_cli.stages.rrtstar", "map", "tree"),
    Stage("simplify", "bearnav_cli.stages.simplify", "tree", "simplified"),
    Stage("decompose", "bearnav_cli.stages.decompose", "simplified", "cells"),
    Stage("synthesize", "bearnav_cli.stages.synthesize", "cells", "plan"),
)
#: Not part of ``plan``: run on a plan by ``bearnav simulate`` (maps may still set its ``params:``).
SIMULATE = Stage("simulate", "bearnav_cli.stages.simulate", "plan", "simulation")
STAGE_BY_NAME = {stage.name: stage for stage in (*STAGES, SIMULATE)}


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


# --------------------------------------------------------------------------- what is running (interrupts)


@dataclass
class Activity:
    """The stage this process is working on, for the message of an interrupt and of a warning.

    Attributes
    ----------
    stage : str or None
        Set when a stage starts, before its input is read.
    written : bool
        Set once its output is committed (artifacts.save's ``on_commit``, run with SIGINT held back).
    file : str or None
        What the stage reads: the map, or the artifact before it (warnings name it).
    """

    stage: str | None = None
    written: bool = False
    file: str | None = None


ACTIVITY = Activity()


def reset_activity() -> None:
    """Forget the current stage (:data:`ACTIVITY`): nothing is running, nothing written."""
    ACTIVITY.stage, ACTIVITY.written, ACTIVITY.file = None, False, None


def _begin(stage: str, file: str | os.PathLike | None = None) -> None:
    ACTIVITY.stage, ACTIVITY.written, ACTIVITY.file = stage, False, None if file is None else str(file)


@contextlib.contextmanager
def activity(stage: str, file: str | os.PathLike | None = None) -> Iterator[Activity]:
    """Name what the block works on in :data:`ACTIVITY` (nothing written yet), and restore what it named
    before when the block ends.

    An exception leaves it named: the command's error handler, outside the block, says from it what an
    interrupt or a failure left unwritten (and it resets :data:`ACTIVITY` before the next command).

    Parameters
    ----------
    stage : str
        What is being made: a command (``"verify"``) or a file (``"fig.png"``); interrupts and warnings say it.
    file : str or path, optional
        What it reads (warnings say ``STAGE of FILE``).
    """
    before = dataclasses.replace(ACTIVITY)
    _begin(stage, file)
    yield ACTIVITY
    ACTIVITY.stage, ACTIVITY.written, ACTIVITY.file = before.stage, before.written, before.file


def _committed() -> None:
    ACTIVITY.written = True


# --------------------------------------------------------------------------- parameters


@dataclass(frozen=True)
class Origins:
    """Where each parameter of one stage got its value.

    Attributes
    ----------
    fields : mapping of str to str
        Parameter name to the field an error about it names: the option that set it (``--seed``), else
        the map field that did or would (``params.rrtstar.seed``).
    given : frozenset of str
        The names set by the map's ``params:`` or an option, not left at their default.
    """

    fields: Mapping[str, str]
    given: frozenset[str] = frozenset()

    def field(self, name: str | None) -> str | None:
        """The field of parameter ``name`` (a name without one, or None, as it is)."""
        return self.fields.get(name or "", name)


def _coerce(stage: str, name: str, default: Any, value: Any, where: str) -> Any:
    """Check and convert one parameter value against the type of its default."""
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
        try:
            return float(value)
        except OverflowError:
            raise InvalidParamsError(f"out of range, got {value!r}", field=where) from None
    if isinstance(default, str) and isinstance(value, str):
        return value
    if default is None and name in LIMITS.get(stage, {}):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return value
        raise InvalidParamsError(f"expected a number, got {value!r}", field=where)
    if default is None and isinstance(value, (int, float, str)) and not isinstance(value, bool):
        return value
    raise InvalidParamsError(f"expected {kind.__name__}, got {value!r}", field=where)


def _resolve(stage: str, map_params: dict | None, overrides: dict | None,
             diagonal: float | None) -> tuple[Any, Origins]:  # fmt: skip
    """The stage's ``Params`` and, per parameter, where its value came from (``--seed``, ``params.rrtstar.seed``)."""
    params_type = STAGE_BY_NAME[stage].module.Params
    defaults = {f.name: f.default for f in dataclasses.fields(params_type)}
    values = dict(defaults)
    where = {name: f"params.{stage}.{name}" for name in defaults}
    given: set[str] = set()
    source_map = (map_params or {}).get(stage, {})
    if not isinstance(source_map, dict):
        raise InvalidParamsError("expected a mapping of options", field=f"params.{stage}")
    for origin, source in (("map", source_map), ("cli", overrides or {})):
        for name, value in source.items():
            if value is None and origin == "cli":
                continue
            here = f"params.{stage}.{name}" if origin == "map" else option_name(stage, str(name))
            if name not in defaults:
                raise InvalidParamsError(f"unknown parameter (known: {', '.join(defaults)})", field=here)
            values[name] = _coerce(stage, name, defaults[name], value, here)
            where[name] = here
            given.add(str(name))
    for name, value in values.items():
        check_value(stage, name, value, where[name], diagonal)
    origins = Origins(where, frozenset(given))
    try:
        params = params_type(**values)
    except InvalidParamsError as exc:
        raise InvalidParamsError(exc.reason, field=origins.field(exc.field)) from None
    except (TypeError, ValueError, OverflowError) as exc:  # a value the Params checks did not expect
        raise InvalidParamsError(f"invalid value ({exc})", field=f"params.{stage}") from None
    return params, origins


def resolve_params(stage: str, map_params: dict | None, overrides: dict | None = None,
                   diagonal: float | None = None) -> Any:  # fmt: skip
    """Build the stage's frozen ``Params``: defaults, then the map's, then ``overrides``.

    Parameters
    ----------
    stage : str
        The stage's name, a key of :data:`STAGE_BY_NAME`.
    map_params : dict or None
        The map's ``params:`` section, stage name to options; only ``map_params[stage]`` is used.
    overrides : dict, optional
        Explicit values (the CLI options), name to value; a None value is left unset.
    diagonal : float, optional
        The map's diagonal (map units), to check the lengths given relative to it.

    Returns
    -------
    Params
        The stage module's ``Params``, each value converted to its default's type.

    Raises
    ------
    InvalidParamsError
        For an unknown name, a value of the wrong type or outside its range (:data:`~bearnav_cli.limits.LIMITS`;
        lengths relative to the map's diagonal only when ``diagonal`` is given), naming the
        option (``--seed``) or the map field (``params.rrtstar.seed``).
    """
    return _resolve(stage, map_params, overrides, diagonal)[0]


def check_map_params(map_params: Any, file: str, diagonal: float | None = None) -> None:
    """Reject unknown stage names and parameters, and bad values, in a map's ``params:`` section.

    Parameters
    ----------
    map_params : Any
        The map's ``params:`` value: it must be a mapping of stage name to options.
    file : str
        The map's file, named in the error.
    diagonal : float, optional
        The map's diagonal (map units), to check the lengths given relative to it (once the
        map stage knows it).

    Raises
    ------
    InvalidMapError
        Naming the field (``params.rrtstar.seed``) and what is wrong.
    """
    if not isinstance(map_params, dict):
        raise InvalidMapError("expected a mapping of stage name to options", file=file, field="params")
    for stage, options in map_params.items():
        if stage not in STAGE_BY_NAME:
            known = ", ".join(STAGE_BY_NAME)
            raise InvalidMapError(f"unknown stage (known: {known})", file=file, field=f"params.{stage}")
        if not isinstance(options, dict):
            raise InvalidMapError("expected a mapping of options", file=file, field=f"params.{stage}")
        try:
            resolve_params(stage, map_params, diagonal=diagonal)
        except InvalidParamsError as exc:
            raise InvalidMapError(exc.reason, file=file, field=exc.field) from exc


# --------------------------------------------------------------------------- loading and running


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


# --------------------------------------------------------------------------- one stage, in memory or on files
#
# ``plan`` (files, freshness) and ``compute`` (memory) share these three steps of every stage.


def _map_stage_params(source: map_.MapSource, overrides: dict | None) -> Any:
    """The map stage's ``Params``: the YAML's ``params:`` checked against the stage table, then ``overrides``."""
    map_params = source.spec.get("params", {}) if isinstance(source.spec, dict) else {}
    check_map_params(map_params, source.file)
    return resolve_params("map", map_params, overrides)


def _stage_params(name: str, artifact: Any, overrides: dict | None) -> Any:
    """The ``Params`` of stage ``name`` on its input ``artifact``: the defaults, the (embedded) map's ``params:``,
    then ``overrides``, in range for the map's diagonal; then the stage's estimates (:meth:`Stage.check_resources`)."""
    source_map: Map = artifact if isinstance(artifact, Map) else artifact.map
    params, origins = _resolve(name, source_map.params, overrides, source_map.diagonal)
    STAGE_BY_NAME[name].check_resources(artifact, params, origins)
    return params


def _execute(stage: Stage, payload: Any, params: Any, progress: Progress | None, file: str) -> Any:
    """Run the stage; a new map's ``params:`` lengths are checked once its diagonal is known (``file`` names it)."""
    result = stage.module.run(payload, params, progress=progress)
    if isinstance(result, Map):
        check_map_params(result.params, file, diagonal=result.diagonal)
    return result


#: The stages :func:`compute` can run, in order: ``plan``'s, then ``simulate``.
_CHAIN: tuple[Stage, ...] = (*STAGES, SIMULATE)


def compute(
    source: map_.MapSource | Map,
    through: str = "synthesize",
    overrides: dict[str, dict] | None = None,
    progress: Callable[[str], Progress | None] | None = None,
) -> dict[str, Any]:
    """Run the stages from the map through ``through`` in memory: ``plan`` without files, caches or locks.

    Parameters resolve exactly as :func:`plan` resolves them (each stage's defaults, then the map's
    ``params:``, then ``overrides``; ranges and resource estimates checked), so the artifacts are the
    ones ``bearnav plan`` would write (the same content hashes). Invariants are checked where
    artifacts are saved or loaded, not here.

    Parameters
    ----------
    source : MapSource or Map
        The map description (the map stage runs on it) or a normalised map (it does not).
    through : str
        The last stage to run: ``map``, ``rrtstar``, ``simplify``, ``decompose``, ``synthesize``
        (default) or ``simulate``.
    overrides : dict, optional
        ``{stage: {param: value}}``, as the command line gives them.
    progress : callable, optional
        ``progress(stage_name)`` returns a progress callback for that stage, or None.

    Returns
    -------
    dict
        Every artifact made, by kind, in stage order: ``{"map": Map, "tree": Tree, "simplified": Tree,
        "cells": Cells, "plan": Plan}`` (and ``"simulation"``) up to the output of ``through``.

    Raises
    ------
    ValueError
        ``through`` is not a stage name.
    InvalidParamsError, InvalidMapError, ResourceLimitError
        As :func:`plan` raises them.
    """
    made = _chain(source, None, through, overrides, progress, manifests=False)
    return {kind: artifact for kind, (artifact, _) in made.items()}


def compute_saved(
    source: map_.MapSource | Map | Any,
    through: str = "synthesize",
    overrides: dict[str, dict] | None = None,
    after: str | None = None,
) -> dict[str, tuple[Any, dict]]:
    """:func:`compute`, and each artifact's manifest as :func:`plan` would write it (no input path).

    For a caller that stores the artifacts itself (``bearnav sweep``), so that what it saves has
    the manifests of ``bearnav plan``: the same parameters, summaries, statistics and input hashes.

    Parameters
    ----------
    source : MapSource, Map or an artifact
        As :func:`compute`; with ``after``, the output of that stage (a simplified tree, say), and
        the chain goes on from the next stage.
    through : str
        The last stage to run.
    overrides : dict, optional
        ``{stage: {param: value}}``.
    after : str, optional
        The stage whose output ``source`` is (None: ``source`` is the map or its description).

    Returns
    -------
    dict
        ``{kind: (artifact, manifest)}`` of every stage run, in stage order (the map's manifest is
        None when ``source`` was a normalised map).
    """
    return _chain(source, after, through, overrides, None, manifests=True)


def _chain(source: Any, after: str | None, through: str, overrides: dict[str, dict] | None,
           progress: Callable[[str], Progress | None] | None, manifests: bool) -> dict[str, tuple]:  # fmt: skip
    """The stages after ``after`` (None: from the map) through ``through``, each artifact with its manifest
    (None unless ``manifests``: hashing every input is work :func:`compute` does not need)."""
    names = [stage.name for stage in _CHAIN]
    for name in (through, after):
        if name is not None and name not in names:
            raise ValueError(f"unknown stage {name!r}; expected one of {', '.join(names)}")
    overrides = overrides or {}
    made: dict[str, tuple[Any, dict | None]] = {}
    if after is not None:
        artifact = source
        first = names.index(after) + 1
    elif isinstance(source, Map):
        artifact, first = source, 1
        made[_CHAIN[0].output_kind] = (artifact, None)
    else:
        params = _map_stage_params(source, overrides.get("map"))
        artifact = _timed_stage(_CHAIN[0], source, params, None, source.file, source.sha256 if manifests else None,
                                made)  # fmt: skip
        first = 1
    for stage in _CHAIN[first : names.index(through) + 1]:
        params = _stage_params(stage.name, artifact, overrides.get(stage.name))
        input_hash = artifacts.content_hash(artifacts.entries_of(artifact)) if manifests else None
        artifact = _timed_stage(stage, artifact, params, progress(stage.name) if progress else None, stage.name,
                                input_hash, made)  # fmt: skip
    return made


def _timed_stage(stage: Stage, payload: Any, params: Any, progress: Progress | None, file: str,
                 input_hash: str | None, made: dict) -> Any:  # fmt: skip
    """Run one stage of :func:`_chain` and file its artifact in ``made``, with its manifest when ``input_hash``
    is given (timed: the manifest records the stage's wall time)."""
    started = time.perf_counter()
    result = _execute(stage, payload, params, progress, file)
    elapsed = time.perf_counter() - started
    manifest = None if input_hash is None else stage_manifest(stage, result, payload, params, input_hash, None, elapsed)
    made[stage.output_kind] = (result, manifest)
    return result


def stage_manifest(stage: Stage, result: Any, payload: Any, params: Any, input_hash: str,
                   input_path: str | None, elapsed_s: float) -> dict:  # fmt: skip
    """The manifest of ``result``, the output of ``stage`` run on ``payload`` with ``params`` (DESIGN §3.1).

    The one builder of a stage's manifest: :func:`plan` writes it, :func:`compute_saved` returns it.

    Parameters
    ----------
    stage : Stage
        The stage that ran.
    result : Any
        Its output.
    payload : Any
        Its input (the map stage's summary names the obstacles the description listed).
    params : Any
        Its resolved ``Params``.
    input_hash : str
        The input's content hash (for the map stage, its description's SHA-256).
    input_path : str or None
        The input's path as the manifest records it (relative to the output's folder), or None.
    elapsed_s : float
        The stage's wall time (s).
    """
    if isinstance(result, Map):
        from bearnav_cli.stages import map_

        summary = map_.summary(result, map_.listed_obstacles(payload))
    else:
        summary = stage.module.summary(result)
    return artifacts.make_manifest(stage.output_kind, result, stage=stage.name, stage_version=stage.module.VERSION,
                                   params=artifacts.params_dict(params), input_path=input_path,
                                   input_hash=input_hash, summary=summary, elapsed_s=elapsed_s,
                                   stats=getattr(result, "stats", None))  # fmt: skip


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
            _committed()
            summary = loaded.manifest.get("summary", "")
            return StageReport(stage.name, out, False, 0.0, summary, artifact, loaded.manifest)
    started = time.perf_counter()
    result = _execute(stage, payload, params, progress, input_path or str(out))
    elapsed = time.perf_counter() - started
    manifest = stage_manifest(stage, result, payload, params, input_hash, _relative_to_output(input_path, out),
                              elapsed)  # fmt: skip
    summary = manifest["summary"]
    try:
        artifacts.save(out, result, manifest, on_commit=_committed)
    except ArtifactError as exc:
        if exc.file is not None:
            raise
        # the stage's own output breaks its type's invariants: a bug, not the user's input
        raise InternalError(f"{stage.name} made an artifact that fails its own checks, nothing written "
                            f"({exc})", file=str(out)) from None  # fmt: skip
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
        artifacts.check_output_file(path, (path.suffix if path != out else artifacts.KINDS[stage.output_kind].suffix,),
                                    inputs=inputs)  # fmt: skip
        artifacts.check_overwrite(path, stage.name, force=force)


def run_map(source: map_.MapSource, out: Path, overrides: dict | None = None, force: bool = False) -> StageReport:
    """Run the map stage on a source read by the CLI and write ``map.json``.

    Parameters
    ----------
    source : map_.MapSource
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
    _begin("map", source.file)
    out = Path(out)
    _check_outputs(stage, out, (source.file,), force)
    params = _map_stage_params(source, overrides)
    with artifacts.output_folder(out.parent):
        return _run_and_save(stage, source, params, out, source.file, source.sha256, force, None)


def run_stage(
    name: str,
    input_path: Path,
    out: Path | None = None,
    overrides: dict | None = None,
    force: bool = False,
    progress: Progress | None = None,
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

    Returns
    -------
    StageReport
        What happened: ran or kept, the output and its manifest.
    """
    stage = STAGE_BY_NAME[name]
    _begin(name, input_path)
    out = Path(out) if out is not None else Path(input_path).with_name(stage.filename)
    _check_outputs(stage, out, (input_path,), force)
    with artifacts.output_folder(out.parent):
        loaded = load(input_path, stage.input_kind)
        params = _stage_params(name, loaded.artifact, overrides)
        return _run_and_save(
            stage, loaded.artifact, params, out, str(input_path), loaded.manifest["content_sha256"], force, progress
        )


def _spec_params(source: map_.MapSource) -> Any:
    return source.spec.get("params", {}) if isinstance(source.spec, dict) else {}


def _spec_name(source: map_.MapSource) -> str:
    """The name the map stage gives the map of ``source`` (its ``name:``, by default ``map``)."""
    name = source.spec.get("name", "map") if isinstance(source.spec, dict) else "map"
    return str(name)


def _check_plan_params(map_params: Any, source: Any, overrides: dict[str, dict], diagonal: float | None) -> None:
    """Build every stage's ``Params`` before the first one runs, so that a bad option writes nothing.

    Without the map's diagonal (a YAML not yet normalised) the limits given relative to it wait for
    the stage itself (:func:`_stage_params`), as do the resource estimates, which need its input.
    """
    if not isinstance(source, Path):
        _map_stage_params(source, overrides.get("map"))
    for stage in STAGES[1:]:
        resolve_params(stage.name, map_params, overrides.get(stage.name), diagonal)


def _check_chain(reports: list[StageReport]) -> None:
    """Each stage's output names the content hash of the artifact before it (the lock makes this hold)."""
    for before, after in zip(reports[:-1], reports[1:], strict=True):
        if before.manifest is None or after.manifest is None:
            continue
        if after.manifest["input"]["content_sha256"] != before.manifest["content_sha256"]:
            raise ArtifactError(f"was made from another {before.path.name} than the one next to it; rerun with --force",
                                file=str(after.path))  # fmt: skip


def _adopt_map(loaded: artifacts.Loaded, map_json: Path, target: Path) -> StageReport:
    """A ready ``map.json`` (``loaded`` from ``map_json``) as the map stage's report, copied into the plan
    folder when it lies elsewhere."""
    if artifacts.copy_file(map_json, target):  # the same bytes: what was loaded is what is there now
        loaded = dataclasses.replace(loaded, path=target)
    _committed()
    manifest = loaded.manifest
    return StageReport("map", target, False, 0.0, manifest.get("summary", ""), loaded.artifact, manifest)


def plan(
    source: map_.MapSource | Path,
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
    _begin("map", source if isinstance(source, Path) else source.file)
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
            )
            reports.append(report)
            if on_stage:
                on_stage(report)
        _check_chain(reports)
    return reports
