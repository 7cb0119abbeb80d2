"""The parameters of the synthesis (ALGORITHMS §5): :class:`Params`, re-exported by
:mod:`bearnav_cli.stages.synthesize`."""

from __future__ import annotations

from dataclasses import dataclass

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.params.declare import Range, check, param

__all__ = ["GAIN_STRUCTURES", "LP_FORMS", "Params"]

GAIN_STRUCTURES = ("full", "diag", "scalar")
LP_FORMS = ("vertex", "dual")


@dataclass(frozen=True)
class Params:
    """Parameters of the synthesis (ALGORITHMS §5).

    Attributes
    ----------
    u_max : float
        Input box ``|u_1|, |u_2| ≤ u_max`` (map units per second).
    kappa : float
        Initial scale of the rates in each cell's barrier and exit conditions, halved while the LP
        is infeasible. It is ``κ_h = κ_v`` of the constants ``c_h``, ``c_v`` (§5.3).
    halvings : int
        How many times ``kappa`` may be halved after an infeasible LP before the
        least-violation solve (so ``halvings + 1`` feasibility attempts).
    gain_structure : {"full", "diag", "scalar"}
        The controller gain of each cell: any 2×2 matrix, diagonal, or a multiple of the identity.
        ``full`` is solved in field space (the minimum-norm gain ``K_k`` by Lemma 3), the others in
        gain space.
    lp_form : {"vertex", "dual"}
        Constraints at the cell's vertices, or through LP duality (§5.2).
    w_h, w_v : float
        Objective weights of the CBF and CLF slacks.
    clf_margin : float
        The CLF slack must satisfy ``S_V <= −clf_margin·u_max`` (a finite-time exit and no
        equilibrium in the cell); ``0`` is ALGORITHMS §5.2 as written. A cell that cannot
        meet it at any κ is solved with ``S_V <= 0`` and gets status 1.
    goal_tolerance : float or None
        Success radius around the goal (map units); ``None`` means ``0.01·D``.
    tolerant : bool
        Funnel cells: keep whichever of two fields tolerates the larger position error, the LP's or
        one that heads straight for the exit point (ALGORITHMS §11.4). The second is Lemma 4's
        field ``c_v(x_j − x) − εz`` (``ε`` chosen for the largest tolerance ``δ_c``). The LP
        maximises the sum of its margins, which leaves ``δ_c`` at a fraction of a millimetre on
        the example maps; Lemma 4's field tolerates half the depth of
        ``x_j`` in the cell. ``False``: the LP's field always.
    """

    u_max: float = param(1.0, range=Range(0, 1e6, low_open=True), unit="map units/s")
    kappa: float = param(0.5, range=Range(0, 1e6, low_open=True))
    halvings: int = param(6, range=Range(0, 60, integer=True))
    gain_structure: str = param("full", choices=GAIN_STRUCTURES)
    lp_form: str = param("vertex", choices=LP_FORMS)
    w_h: float = param(1.0, range=Range(0, 1e6), option=None)
    w_v: float = param(1.0, range=Range(0, 1e6), option=None)
    clf_margin: float = param(0.01, range=Range(0, 1), option=None)
    goal_tolerance: float | None = param(None, range=Range(0, 1, low_open=True, per_diagonal=True), unit="map units")
    tolerant: bool = param(True, off="--lp-field")

    def __post_init__(self) -> None:
        check(self)
        for name in ("u_max", "kappa", "w_h", "w_v", "clf_margin", "goal_tolerance"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, float(getattr(self, name)))
        if not isinstance(self.tolerant, bool):
            raise InvalidParamsError(f"must be true or false, got {self.tolerant!r}", field="tolerant")
