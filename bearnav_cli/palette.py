"""The one palette of every bearnav figure and bag: Okabe and Ito's colour-blind-safe eight, and greys.

Every categorical mark (a layer of a figure, a cell status, a run outcome, a marker in a ROS 2
bag) takes its colour from :data:`PALETTE`, by role, here and nowhere else: :mod:`bearnav_cli.plot`
draws with these colours and :mod:`bearnav_cli.bag` writes them as RGBA. Continuous values
(rank, ``τ_c``, an error radius) use matplotlib's perceptually uniform colour maps instead.
Plain data, no matplotlib: a module that does not draw may use it.

The eight are from M. Okabe and K. Ito, *Color Universal Design* (2008), https://jfly.uni-koeln.de/color/:
told apart by readers with any of the common colour-vision deficiencies.
"""

from __future__ import annotations

from bearnav_cli.datatypes import CellStatus, Outcome

__all__ = [
    "OUTCOME_COLORS",
    "PALETTE",
    "ROLE_COLORS",
    "STATUS_COLORS",
    "rgba",
]

#: Okabe–Ito's eight colours, then the greys the map itself is drawn in (obstacles, their inflation,
#: outlines) and white (marker edges, halos behind text).
PALETTE = {
    "black": "#000000",
    "orange": "#E69F00",
    "sky blue": "#56B4E9",
    "bluish green": "#009E73",
    "yellow": "#F0E442",
    "blue": "#0072B2",
    "vermillion": "#D55E00",
    "reddish purple": "#CC79A7",
    "dark grey": "#4D4D4D",
    "grey": "#999999",
    "light grey": "#CCCCCC",
    "white": "#FFFFFF",
}

#: The colour of each kind of mark. Marks that share a colour differ in shape (a landmark's triangle,
#: a collision's path and cross) and never mean the same thing in one figure.
ROLE_COLORS = {
    "raw obstacle": PALETTE["dark grey"],
    "inflated obstacle": PALETTE["light grey"],
    "bounds": PALETTE["black"],
    "cell outline": PALETTE["dark grey"],
    "exit face": PALETTE["black"],
    "field": PALETTE["black"],
    "tree": PALETTE["blue"],
    "rrt tree": PALETTE["sky blue"],
    "background tree": PALETTE["dark grey"],  # under simulated runs: apart from every outcome's colour
    "added node": PALETTE["reddish purple"],
    "collision sample": PALETTE["orange"],
    "landmark": PALETTE["vermillion"],
    "proposed tag": PALETTE["blue"],
    "goal": PALETTE["yellow"],
    "start": PALETTE["black"],
    "uncertified": PALETTE["vermillion"],
    "uncovered": PALETTE["orange"],
    "unreached": PALETTE["grey"],
    "barrier": PALETTE["reddish purple"],
    "perception fail": PALETTE["reddish purple"],
    "perception fail outside": PALETTE["orange"],
    "uncoverable": PALETTE["grey"],
    "live": PALETTE["bluish green"],
    "not live": PALETTE["vermillion"],
    "estimate path": PALETTE["dark grey"],
    "looked": PALETTE["vermillion"],
    "edge": PALETTE["white"],
    "text": PALETTE["black"],
}

#: Fill colour of each cell status (``plan.npz`` ``status``): certified green, relaxed yellow, the two
#: failures orange and vermillion, the goal cell sky blue.
STATUS_COLORS = {
    CellStatus.CERTIFIED: PALETTE["bluish green"],
    CellStatus.RELAXED: PALETTE["yellow"],
    CellStatus.NOT_CERTIFIED: PALETTE["orange"],
    CellStatus.SOLVER_FAILURE: PALETTE["vermillion"],
    CellStatus.GOAL: PALETTE["sky blue"],
}

#: Path colour of each run outcome (``sim.npz`` ``outcome``).
OUTCOME_COLORS = {
    int(Outcome.SUCCESS): PALETTE["bluish green"],
    int(Outcome.COLLISION): PALETTE["vermillion"],
    int(Outcome.STALL): PALETTE["orange"],
    int(Outcome.TIMEOUT): PALETTE["reddish purple"],
    int(Outcome.LOST): PALETTE["black"],
}


def rgba(color: str, alpha: float = 1.0) -> tuple[float, float, float, float]:
    """``"#RRGGBB"`` as an ``(r, g, b, a)`` tuple of floats in [0, 1] (for a bag's ``ColorRGBA``)."""
    value = color.lstrip("#")
    r, g, b = (int(value[i : i + 2], 16) / 255.0 for i in (0, 2, 4))
    return (r, g, b, float(alpha))
