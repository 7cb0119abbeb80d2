"""The sweep file and its grid: the checked axes, the map files, and one :class:`Job` per cell, keyed by content."""

from __future__ import annotations

import dataclasses
import glob as globbing
import itertools
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bearnav_cli import artifacts, pipeline
from bearnav_cli.errors import InvalidParamsError, InvalidSweepError

__all__ = ["AXES", "expand", "expand_maps", "Job", "OTHER_KEYS", "read_sweep", "Sweep", "TagsChoice"]


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
            raise InvalidSweepError(
                f"unknown key (known: {', '.join((*OTHER_KEYS, *AXES))})", file=file, field=str(key)
            )
    name = spec.get("name", Path(file).stem)
    if not isinstance(name, str) or not name or "/" in name or name.startswith("."):
        raise InvalidSweepError(f"expected a plain folder name, got {name!r}", file=file, field="name")
    if "maps" not in spec:
        raise InvalidSweepError("missing: the maps to sweep (paths or globs)", file=file, field="maps")
    axes: dict[str, tuple] = {}
    for key, param in AXES.items():
        values = _as_list(spec[key]) if key in spec else [None]
        if not values:
            raise InvalidSweepError(
                "empty list: give at least one value (leave the key out for the default)", file=file, field=key
            )
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
            base_key = _key(
                {"map": source.sha256, "seed": seed, "versions": versions, "format": artifacts.ARTIFACT_FORMAT}
            )
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
                        raise InvalidSweepError(
                            f"{exc.reason} (with {overrides})", file=sweep.file, field=f"{source.file}: {exc.field}"
                        ) from None
                    tags_params = (tags_choice or TagsChoice("own")).params(params)
                    plan_key = (
                        base_key
                        if tags_params is None
                        else _key({"base": base_key, "tags": artifacts.params_dict(tags_params)})
                    )
                    key = _key(
                        {"plan": plan_key, "simulate": artifacts.params_dict(params), "version": simulate.VERSION}
                    )
                    grid = {
                        "map": map_name,
                        "map_file": source.file,
                        "seed": rrt_seed,
                        "tags": (tags_choice or TagsChoice("own")).text,
                        "fov": params.fov,
                        "noise_deg": params.noise_deg,
                        "noise_bound_deg": params.noise_bound_deg,
                        "dynamics": params.dynamics,
                        "estimator": params.estimator,
                        "starts": params.starts,
                        "sim_seed": params.seed,
                    }
                    jobs.append(Job(key, plan_key, base_key, grid, source, seed, tags_params, params))
    return jobs, skipped
