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

import math
from dataclasses import dataclass
from typing import Any

from bearnav_cli.errors import InvalidParamsError, ResourceLimitError
from bearnav_cli.runtime.plan_file import human_bytes, memory_budget

__all__ = [
    "check_memory",
    "check_value",
    "check_verify_starts",
    "LIMITS",
    "MAX_RUNS",
    "MAX_STEPS_PER_RUN",
    "option_name",
    "OPTION_NAMES",
    "Range",
    "RUN_BYTES",
    "SEED",
    "TRAJECTORY_POINT_BYTES",
]


@dataclass(frozen=True)
class Range:
    """The documented range of one numeric parameter (docs/cli.md "Option limits" shows :meth:`text`).

    Attributes
    ----------
    low, high : float or None
        Bounds (``None``: none); with ``per_diagonal`` they are multiples of the map's diagonal
        ``D`` and are checked once the map is known.
    low_open : bool
        ``low`` itself is excluded.
    integer : bool
        The value must be an integer.
    per_diagonal : bool
        The bounds scale with ``D`` (a length).
    """

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    integer: bool = False
    per_diagonal: bool = False

    def _bound(self, value: float | None) -> str:
        if value is None:
            return "∞"
        text = f"{value:g}" if not self.integer else str(int(value))
        if self.per_diagonal:
            return "0" if value == 0 else ("D" if value == 1 else f"{text}·D")
        return text

    def text(self) -> str:
        """``"integer in [1, 10000000]"``, ``"(0, 10·D]"`` ..."""
        left = "(" if self.low_open else "["
        right = ")" if self.high is None else "]"
        interval = f"{left}{self._bound(self.low)}, {self._bound(self.high)}{right}"
        return f"integer in {interval}" if self.integer else interval

    def describe(self) -> str:
        """``"an integer in [1, 10000000]"``, ``"in (0, 10·D]"``: for messages."""
        text = self.text()
        return "an " + text if self.integer else "in " + text

    def problem(self, value: Any, diagonal: float | None = None) -> str | None:
        """What is wrong with ``value`` (None when it fits); D-relative bounds only with ``diagonal``."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"expected a number, got {value!r}"
        if isinstance(value, float) and not math.isfinite(value):
            return f"must be finite ({self.describe()}), got {value}"
        if self.integer and not (isinstance(value, int) or float(value).is_integer()):
            return f"must be {self.describe()}, got {value!r}"
        scale = 1.0
        if self.per_diagonal:
            if diagonal is None:  # the map is not known yet: only what does not depend on D
                if self.low is None or value > self.low or (value == self.low and not self.low_open):
                    return None
                return f"must be {self.describe()}, got {value!r}"
            scale = diagonal
        low = None if self.low is None else self.low * scale
        high = None if self.high is None else self.high * scale
        too_low = low is not None and (value < low or (self.low_open and value == low))
        too_high = high is not None and value > high
        if too_low or too_high:
            shown = f" (D = {diagonal:.4g})" if self.per_diagonal and diagonal is not None else ""
            return f"must be {self.describe()}{shown}, got {value!r}"
        return None


#: Seeds: any integer numpy's ``default_rng`` takes that also fits 32 bits; negatives are refused.
SEED = Range(0, 2**32 - 1, integer=True)
#: Most runs ``random:N`` / ``verify --starts`` may ask for (a memory estimate may refuse fewer).
MAX_RUNS = 1_000_000
#: Most steps one closed-loop run may be allowed (``max_steps``, explicit or from speed and dt): about 60
#: times what the example maps need at their speeds, a few minutes of one robot.
MAX_STEPS_PER_RUN = 1_000_000

#: The range of every numeric parameter, by stage (``verify`` holds the options of ``bearnav verify``).
LIMITS: dict[str, dict[str, Range]] = {
    "map": {
        "circle_segments": Range(8, 4096, integer=True),
        "coverage_cells": Range(1, 1000, integer=True),
    },
    "rrtstar": {
        "iterations": Range(1, 10_000_000, integer=True),
        "step": Range(0, 10, low_open=True, per_diagonal=True),
        "seed": SEED,
        "border_spacing": Range(0, 10, per_diagonal=True),
        "clearance": Range(0, 1, per_diagonal=True),
    },
    "simplify": {
        "max_rounds": Range(1, 1000, integer=True),
        "clearance": Range(0, 1, per_diagonal=True),
    },
    "decompose": {
        "exit_inset": Range(0, 1, per_diagonal=True),
        "coverage_target": Range(0, 1),
        "max_added_nodes": Range(0, 100_000, integer=True),
        "n_landmarks": Range(2, 1000, integer=True),
        "barrier_margin": Range(0, 1, per_diagonal=True),
    },
    "synthesize": {
        "u_max": Range(0, 1e6, low_open=True),
        "kappa": Range(0, 1e6, low_open=True),
        "halvings": Range(0, 60, integer=True),
        "w_h": Range(0, 1e6),
        "w_v": Range(0, 1e6),
        "clf_margin": Range(0, 1),
        "goal_tolerance": Range(0, 1, low_open=True, per_diagonal=True),
    },
    "simulate": {
        "fov": Range(0, 360, low_open=True),
        "noise_deg": Range(0, 180),
        "range": Range(0, 1e6, low_open=True, per_diagonal=True),
        "min_spread_deg": Range(0, 90, low_open=True),
        "speed": Range(0, 1e3, low_open=True, per_diagonal=True),
        "alpha": Range(0, 1e3, low_open=True, per_diagonal=True),
        "beta": Range(0, 1e3, low_open=True),
        "initial_heading": Range(-360, 360),
        "hold_time": Range(0, 1e6, low_open=True),
        "max_fix_error": Range(0, 1e3, low_open=True, per_diagonal=True),
        "odometry_noise": Range(0, 1),
        "odometry_drift": Range(0, 1),
        "dt": Range(0, 1e3, low_open=True),
        "goal_tolerance": Range(0, 1, low_open=True, per_diagonal=True),
        "max_steps": Range(1, MAX_STEPS_PER_RUN, integer=True),
        "seed": SEED,
    },
    "verify": {
        "n_starts": Range(0, MAX_RUNS, integer=True),
        "seed": SEED,
        "speed": Range(0, 1e3, low_open=True, per_diagonal=True),
        "min_success": Range(0, 1),
    },
}

#: How the command line spells a parameter when it differs from ``--name-with-dashes``.
OPTION_NAMES = {("simulate", "range"): "--range", ("verify", "n_starts"): "--starts"}


def option_name(stage: str, name: str) -> str:
    """The command-line option of a parameter (``--border-spacing``)."""
    return OPTION_NAMES.get((stage, name), "--" + name.replace("_", "-"))


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
