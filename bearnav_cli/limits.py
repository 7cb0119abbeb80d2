"""What a request may ask: the range of every numeric parameter, and the memory a run may use.

Every numeric parameter has a documented range (:data:`LIMITS`, docs/cli.md "Option limits"), checked
before any work by :func:`check_value`. Big requests are checked against a memory estimate before they
start: each stage estimates its own (``check_resources`` of ``stages.rrtstar`` and ``stages.simulate``),
and :func:`check_memory` turns an estimate over the budget (half of this machine's memory) into one
error naming the option and what fits. The closed loop's model (:data:`RUN_BYTES`,
:data:`TRAJECTORY_POINT_BYTES`) is here because ``simulate`` and ``verify`` both run it
(:func:`check_verify_starts`).

Numbers and the standard library only (and :mod:`bearnav_cli.runtime.plan_file`'s budget), so that the
stages below the pipeline can use it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping
from typing import Any

from bearnav_cli.errors import InvalidParamsError, ResourceLimitError
from bearnav_cli.params import MODULES, declare
from bearnav_cli.params.declare import declared, params_type
from bearnav_cli.runtime.plan_file import human_bytes, memory_budget

__all__ = [
    "check_memory",
    "check_value",
    "check_verify_starts",
    "LIMITS",
    "MAX_RUNS",
    "MAX_STEPS_PER_RUN",
    "option_name",
    "Range",
    "RUN_BYTES",
    "SEED",
    "TRAJECTORY_POINT_BYTES",
]


#: The range type, the seeds' range and the run and step caps, declared with the parameters
#: (:mod:`bearnav_cli.params.declare`); the names every check of a request reads here.
Range = declare.Range
SEED = declare.SEED
MAX_RUNS = declare.MAX_RUNS
MAX_STEPS_PER_RUN = declare.MAX_STEPS_PER_RUN


class _DeclaredLimits(Mapping):
    """The declared ranges of each command's fields, by command, each read from its ``Params`` on first use.

    A stage run imports its own ``Params`` module only (``bearnav rrtstar`` not simulate's or verify's);
    iterating over every command reads them all.
    """

    def __init__(self) -> None:
        self._read: dict[str, dict[str, Range]] = {}

    def __iter__(self) -> Iterator[str]:
        return iter(MODULES)

    def __len__(self) -> int:
        return len(MODULES)

    def __getitem__(self, command: str) -> dict[str, Range]:
        if command not in self._read:
            if command not in MODULES:
                raise KeyError(command)
            self._read[command] = {
                field.name: declared(field).range
                for field in dataclasses.fields(params_type(command))
                if declared(field).range is not None
            }
        return self._read[command]


#: The range of every numeric parameter, by stage (``verify`` holds the options of ``bearnav verify``): the
#: ranges :func:`~bearnav_cli.params.declare.param` declares.
LIMITS: Mapping[str, dict[str, Range]] = _DeclaredLimits()


def option_name(stage: str, name: str) -> str:
    """The command-line option of a parameter (``--border-spacing``; ``--starts`` for verify's ``n_starts``):
    :func:`bearnav_cli.params.declare.option_name`, the one place that reads it from the declaration."""
    return declare.option_name(stage, name)


def check_value(stage: str, name: str, value: Any, where: str, diagonal: float | None = None) -> None:
    """Raise :class:`InvalidParamsError` (field ``where``) if ``value`` lies outside ``LIMITS[stage][name]``.

    Parameters
    ----------
    stage : str
        The stage (``"rrtstar"``, ``"simulate"``, ``"verify"``), a key of :data:`LIMITS`.
    name : str
        The parameter's name (``"step"``); a name without an entry in :data:`LIMITS` is not checked.
    value : Any
        Its value (a number; anything else is an error); None is not checked.
    where : str
        Where the value came from, the error's field (``--step``, ``params.rrtstar.step``).
    diagonal : float, optional
        The map's diagonal (map units): with it, the limits given per diagonal are checked
        too; without it, only the absolute ones.

    Raises
    ------
    InvalidParamsError
        The value lies outside the range, with the range's text.
    """
    limit = LIMITS.get(stage, {}).get(name)
    if limit is None or value is None:
        return
    problem = limit.problem(value, diagonal)
    if problem is not None:
        raise InvalidParamsError(problem, field=where)


# --------------------------------------------------------------------------- memory


#: Bytes per closed-loop run without its trajectory (state arrays and a 201-step position ring).
RUN_BYTES = 4_000
#: Bytes per recorded trajectory point (position, cell, heading, run index; twice while sorting).
TRAJECTORY_POINT_BYTES = 80


def check_memory(count: int, what: str, per_item: float, field: str | None, fixed: float = 0, note: str = "") -> None:
    """Refuse ``count`` items of ``per_item`` bytes each (plus ``fixed``) beyond the memory budget.

    Parameters
    ----------
    count : int
        How many items the request asks for (iterations, runs, starts).
    what : str
        Their name in the message (``"runs"``).
    per_item, fixed : float
        The estimate: bytes per item, and bytes that do not depend on ``count``.
    field : str or None
        The parameter (or option) that gave ``count``: the error's field.
    note : str
        Words after "at most N fit" (another way to make the request fit).

    Raises
    ------
    ResourceLimitError
        ``count · per_item + fixed`` exceeds the budget (:func:`~bearnav_cli.runtime.plan_file.memory_budget`,
        half of this machine's memory): how much it needs, the budget, and how many items fit.
    """
    need = count * per_item + fixed
    budget = memory_budget()
    if need > budget:
        fits = max(0, (budget - fixed) // per_item)
        raise ResourceLimitError(
            f"{count:,} {what} needs about {human_bytes(need)} of memory, more than the "
            f"{human_bytes(budget)} a run may use (half of this machine's); at most {fits:,} fit{note}",
            field=field,
        )


def check_verify_starts(plan: Any, n_starts: int, where: str = "--starts") -> None:
    """``verify``'s starts: the closed loop's memory plus the route matrix (starts × free-space vertices).

    Parameters
    ----------
    plan : Plan
        The plan verified: its map's obstacle vertices (plus the 4 corners) size the route matrix.
    n_starts : int
        Number of starts ``verify`` draws.
    where : str, default "--starts"
        The option that gave ``n_starts``, the error's field.

    Raises
    ------
    ResourceLimitError
        The starts need more memory than the budget, with how many fit.
    """
    vertices = 4 + sum(len(p.exterior) + sum(len(h) for h in p.holes) for p in plan.map.obstacles)
    check_memory(n_starts, "starts", RUN_BYTES + 40 * vertices, where)
