"""Parameter resolution: each stage's ``Params`` from its defaults, the map's ``params:`` and the options.

Parameters resolve as: the stage's defaults, then the map's ``params: {stage: {...}}``, then explicit
overrides (the CLI options); every numeric one must lie in its documented range
(:data:`bearnav_cli.limits.LIMITS`), and the stage's own estimates on its input refuse requests too big
to finish (:meth:`~bearnav_cli.pipeline.table.Stage.check_resources`). :class:`Origins` records where
each value came from, so that every error names the option or map field that set it.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from bearnav_cli.datatypes import Map
from bearnav_cli.errors import InvalidMapError, InvalidParamsError
from bearnav_cli.limits import LIMITS, check_value, option_name
from bearnav_cli.pipeline.table import STAGE_BY_NAME, Origins

__all__ = ["check_map_params", "map_stage_params", "resolve", "resolve_params", "stage_params"]


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


def resolve(
    stage: str, map_params: dict | None, overrides: dict | None, diagonal: float | None = None
) -> tuple[Any, Origins]:
    """:func:`resolve_params`, and where each value came from.

    Parameters
    ----------
    stage : str
        The stage's name.
    map_params : dict or None
        The map's ``params:`` section.
    overrides : dict or None
        Explicit values (the CLI options); a None value is left unset.
    diagonal : float, optional
        The map's diagonal (map units), to check the lengths given relative to it.

    Returns
    -------
    tuple of Params and Origins
        The parameters, and where each came from (the fields the errors about them name).
    """
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


def resolve_params(
    stage: str, map_params: dict | None, overrides: dict | None = None, diagonal: float | None = None
) -> Any:
    """Build the stage's frozen ``Params``: defaults, then the map's, then ``overrides``.

    Parameters
    ----------
    stage : str
        The stage's name, a key of :data:`~bearnav_cli.pipeline.table.STAGE_BY_NAME`.
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
    return resolve(stage, map_params, overrides, diagonal)[0]


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


# --------------------------------------------------------------------------- the parameters of one stage
#
# ``plan`` (files, freshness) and ``compute`` (memory) resolve every stage's parameters with these two.


def map_stage_params(source: Any, overrides: dict | None) -> Any:
    """The map stage's ``Params`` for a ``MapSource``: the YAML's ``params:`` checked against the stage
    table, then ``overrides``."""
    map_params = source.spec.get("params", {}) if isinstance(source.spec, dict) else {}
    check_map_params(map_params, source.file)
    params, origins = resolve("map", map_params, overrides)
    STAGE_BY_NAME["map"].check_resources(source, params, origins)
    return params


def stage_params(name: str, artifact: Any, overrides: dict | None) -> Any:
    """The ``Params`` of stage ``name`` on its input: the defaults, the (embedded) map's ``params:``, then
    ``overrides``, in range for the map's diagonal; then the stage's estimates on its input
    (:meth:`~bearnav_cli.pipeline.table.Stage.check_resources`).

    Parameters
    ----------
    name : str
        The stage after ``map`` (a key of :data:`~bearnav_cli.pipeline.table.STAGE_BY_NAME`).
    artifact : Map, Tree, Cells or Plan
        Its input, whose (embedded) map gives the ``params:`` and the diagonal.
    overrides : dict or None
        Explicit values (the CLI options).
    """
    source_map: Map = artifact if isinstance(artifact, Map) else artifact.map
    params, origins = resolve(name, source_map.params, overrides, source_map.diagonal)
    STAGE_BY_NAME[name].check_resources(artifact, params, origins)
    return params
