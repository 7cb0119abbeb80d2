"""The chain in memory: :func:`compute` runs ``plan``'s stages (and ``simulate``) without files, caches or locks.

Parameters resolve exactly as ``bearnav plan`` resolves them (:mod:`bearnav_cli.pipeline.params`), and
:func:`execute` and :func:`stage_manifest` are the steps both share, so the artifacts are the ones
``plan`` writes, with the same content hashes and manifests.
"""

from __future__ import annotations

import time
from typing import Any, Callable

from bearnav_cli import artifacts
from bearnav_cli.datatypes import Map
from bearnav_cli.pipeline.params import check_map_params, map_stage_params, stage_params
from bearnav_cli.pipeline.table import CHAIN, Progress, Stage

__all__ = ["compute", "compute_saved", "execute", "stage_manifest"]


def execute(stage: Stage, payload: Any, params: Any, progress: Progress | None, file: str) -> Any:
    """Run the stage; a new map's ``params:`` lengths are checked once its diagonal is known.

    Parameters
    ----------
    stage : Stage
        The stage to run.
    payload : Any
        Its input (a ``MapSource`` for the map stage).
    params : Params
        Its resolved parameters.
    progress : callable or None
        ``progress(done, total)``, called by long stages.
    file : str
        What the errors about the new map's ``params:`` name (its description, or the stage).
    """
    result = stage.module.run(payload, params, progress=progress)
    if isinstance(result, Map):
        check_map_params(result.params, file, diagonal=result.diagonal)
    return result


def stage_manifest(
    stage: Stage, result: Any, payload: Any, params: Any, input_hash: str, input_path: str | None, elapsed_s: float
) -> dict:
    """The manifest of ``result``, the output of ``stage`` run on ``payload`` with ``params`` (DESIGN §3.1).

    The one builder of a stage's manifest: ``plan`` writes it, :func:`compute_saved` returns it.

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
    return artifacts.make_manifest(
        stage.output_kind,
        result,
        stage=stage.name,
        stage_version=stage.module.VERSION,
        params=artifacts.params_dict(params),
        input_path=input_path,
        input_hash=input_hash,
        summary=stage.summary(result, payload),
        elapsed_s=elapsed_s,
        stats=getattr(result, "stats", None),
    )


def compute(
    source: Any,
    through: str = "synthesize",
    overrides: dict[str, dict] | None = None,
    progress: Callable[[str], Progress | None] | None = None,
) -> dict[str, Any]:
    """Run the stages from the map through ``through`` in memory: ``plan`` without files, caches or locks.

    Parameters resolve exactly as ``plan`` resolves them (each stage's defaults, then the map's
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
        As ``plan`` raises them.
    """
    made = _chain(source, None, through, overrides, progress, manifests=False)
    return {kind: artifact for kind, (artifact, _) in made.items()}


def compute_saved(
    source: Any,
    through: str = "synthesize",
    overrides: dict[str, dict] | None = None,
    after: str | None = None,
) -> dict[str, tuple[Any, dict]]:
    """:func:`compute`, and each artifact's manifest as ``plan`` would write it (no input path).

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


def _chain(
    source: Any,
    after: str | None,
    through: str,
    overrides: dict[str, dict] | None,
    progress: Callable[[str], Progress | None] | None,
    manifests: bool,
) -> dict[str, tuple]:
    """The stages after ``after`` (None: from the map) through ``through``, each artifact with its manifest
    (None unless ``manifests``: hashing every input is work :func:`compute` does not need)."""
    names = [stage.name for stage in CHAIN]
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
        made[CHAIN[0].output_kind] = (artifact, None)
    else:
        params = map_stage_params(source, overrides.get("map"))
        artifact = _timed_stage(CHAIN[0], source, params, None, source.file, source.sha256 if manifests else None, made)
        first = 1
    for stage in CHAIN[first : names.index(through) + 1]:
        params = stage_params(stage.name, artifact, overrides.get(stage.name))
        input_hash = artifacts.content_hash(artifacts.entries_of(artifact)) if manifests else None
        artifact = _timed_stage(
            stage, artifact, params, progress(stage.name) if progress else None, stage.name, input_hash, made
        )
    return made


def _timed_stage(
    stage: Stage, payload: Any, params: Any, progress: Progress | None, file: str, input_hash: str | None, made: dict
) -> Any:
    """Run one stage of :func:`_chain` and file its artifact in ``made``, with its manifest when ``input_hash``
    is given (timed: the manifest records the stage's wall time)."""
    started = time.perf_counter()
    result = execute(stage, payload, params, progress, file)
    elapsed = time.perf_counter() - started
    manifest = None if input_hash is None else stage_manifest(stage, result, payload, params, input_hash, None, elapsed)
    made[stage.output_kind] = (result, manifest)
    return result
