"""The parameters of RRT* (ALGORITHMS §2): :class:`Params`, re-exported by :mod:`bearnav_cli.stages.rrtstar`."""

from __future__ import annotations

from dataclasses import dataclass

from bearnav_cli.params.declare import SEED, Range, check, param

__all__ = ["POLICIES", "Params"]

POLICIES = ("skip", "extend")


@dataclass(frozen=True)
class Params:
    """Parameters of RRT* (ALGORITHMS §2).

    Attributes
    ----------
    iterations : int
        Random samples drawn, collision samples included.
    step : float
        Steering distance η (map units); also caps the rewiring radius.
    seed : int
        Seed of ``numpy.random.default_rng``.
    collision_policy : {"skip", "extend"}
        After storing a collision sample, end the iteration (``skip``, paper B) or
        keep steering toward it (``extend``, the authors' code).
    border_spacing : float or None
        Largest gap between border pseudo-samples (map units); ``None`` means
        ``step / 10``; ``0`` turns them off.
    clearance : float or None
        Smallest distance of every tree edge from the inflated obstacles and the walls (map
        units); ``None`` means ``0.01·D`` (D the bounds' diagonal); ``0`` is the plain
        RRT* (ALGORITHMS §2). Within four clearances of a goal nearer the walls than twice
        it, half the goal's own clearance (``FreeSpace.planning_space``). The barrier rows of
        ``decompose`` need it: a node on an obstacle's boundary leaves a robot no room.
    """

    iterations: int = param(1500, range=Range(1, 10_000_000, integer=True))
    step: float = param(1.0, range=Range(0, 10, low_open=True, per_diagonal=True), unit="map units")
    seed: int = param(0, range=SEED)
    collision_policy: str = param("skip", choices=POLICIES)
    border_spacing: float | None = param(None, range=Range(0, 10, per_diagonal=True), unit="map units")
    clearance: float | None = param(None, range=Range(0, 1, per_diagonal=True), unit="map units")

    def __post_init__(self) -> None:
        check(self)
        if self.border_spacing is None:
            object.__setattr__(self, "border_spacing", self.step / 10.0)
