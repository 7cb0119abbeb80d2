"""The parameters of the simplification (ALGORITHMS §3): :class:`Params`, re-exported by
:mod:`bearnav_cli.stages.simplify`."""

from __future__ import annotations

from dataclasses import dataclass

from bearnav_cli.params.declare import Range, check, param

__all__ = ["CTL_MODES", "Params"]

CTL_MODES = ("middle", "extremes")


@dataclass(frozen=True)
class Params:
    """Parameters of the simplification (ALGORITHMS §3).

    Attributes
    ----------
    max_rounds : int
        Upper bound on the rounds of shortcuts, leaf cutting and crossing removal (at least 1).
        A round is PPR | CtL | RC | CtL.
    ctl : {"middle", "extremes"}
        Which leaves leaf cutting (CtL) keeps among the leaf children of one parent, sorted by
        angle from the incoming edge: the middle one, or the first and last.
    clearance : float or None
        Smallest distance of every new (shortcut) edge from the inflated obstacles and the
        walls (map units); ``None`` means ``0.01·D``, relaxed near a goal by a wall as in
        ``rrtstar``; ``0`` is the paper's
        simplification as written (ALGORITHMS §3).
    """

    max_rounds: int = param(10, range=Range(1, 1000, integer=True))
    ctl: str = param("middle", choices=CTL_MODES)
    clearance: float | None = param(None, range=Range(0, 1, per_diagonal=True), unit="map units")

    def __post_init__(self) -> None:
        check(self)
