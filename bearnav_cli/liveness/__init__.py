"""Liveness of a funnel plan at a bearing error, a camera and a slip (ALGORITHMS §12.5, §12.8).

A robot at ``x`` whose camera looks along the heading ``θ`` sees the landmarks ``S_fov(x, θ)`` (in
the field of view, in range, in line of sight: ``runtime.looking.views``). A look's set then errs by
at most ``ε(x, S)`` (``runtime.look_bound.one_look_bound``: §12.2's static bound, tightened, see its
docstring). A look (§12.5, ``runtime.step.look_around``) turns to the best heading and, when that
view is not enough, turns all around; turning in place does not grow the set, so it ends inside the
cones of every landmark in sight, ``S_all(x)``. Per cell ``c``:

- ``ε_c^look = max_{x ∈ P_c} ε(x, S_all(x))``, the worst over the cell of the look. §12.5 takes
  the best single view, ``min_θ ε(x, S_fov(x, θ))``, which ignores the turn all around that §12.5's
  own look ends with; that is kept as ``eps_view`` (a look of one view, no turn all around);
- the **margin** ``τ_c − κℓ − ν`` (``τ_c`` the plan's usable tolerance, ``ℓ = v·dt`` one step,
  ``κ`` the slip, ``ν`` its floor; a look-ahead plan also loses the swing ``2λ sin(ψ/2)`` of its
  point, §12.6);
- the cell is **live** when ``ε_c^look`` is below the margin: after every look the robot may move
  on (Theorem 2's proviso);
- ``η*_c``, its largest live bearing error: ``ε`` scales about linearly with ``η``, so the
  estimate ``η·margin/ε_c^look`` is re-evaluated on the same grid and shrunk (by the measured
  ratio, at least ×0.9 a step) until the cell is live; 0 where the margin is not positive or no
  step made it live. The plan's **certified bearing error** ``η*`` is the least ``η*_c``.

``ε_c^look`` is evaluated on a grid, not proved: the points of a square grid of spacing
``resolution`` inside each cell, and every cell's vertices (pulled ``0.1%`` toward its centroid)
and its centroid, so that small cells get points and corners are seen. A look-ahead plan's cells
hold the point ``p`` ahead of the axle, but the camera looks from the axle, anywhere within
``λ`` of ``p``: there the grid covers ``P_c ⊕ B_λ``, a superset of the axle's places. The one-view
minimum over headings takes ``headings`` evenly spaced headings (1 for a camera that sees all
around); a heading whose view is a subset of another's at the same point can only do worse and is
not evaluated.

The **live fraction** of ``D`` is the area where the cell the funnel policy uses (the least-rank
cell holding the point, ``datatypes.active_regions``) is live, over the area of ``D``
(shapely, exact for the polygons); :attr:`Liveness.cover_fraction` is the area some live cell
covers. The cells of a plan overlap a great deal (the kitchen's areas sum to 4.5 times its ``D``),
so neither is a sum of cell areas.

The **start fraction** (:attr:`Liveness.start_fraction`, :meth:`LiveGrid.sure_start`) is what §12.5 leaves
out: the share of ``D``'s grid points from which a start is sure, after a look all around, to find a cell
that holds its whole set (§12.3 step 4). Within about ``ε`` of the edge of ``D`` no look can show that.

:func:`measure` returns a :class:`Liveness`; ``bearnav verify --live-fov`` prints it and
``bearnav plot --color-by live`` draws it. Nothing here prints, plots or writes files.
Every name is re-exported here; the modules, each with one job:

- :mod:`~bearnav_cli.liveness.live_grid` — where and against what: the grid, the margins, the one-look bound;
- :mod:`~bearnav_cli.liveness.cells` — which cells are live, ``η*``, the live fraction (:func:`measure`).
"""

from bearnav_cli.liveness.cells import MAX_ETA_DEG, SHRINK, SHRINK_STEPS, Liveness, evaluate, measure
from bearnav_cli.liveness.live_grid import (
    HEADINGS,
    MAX_GRID_POINTS,
    POINTS_PER_CELL,
    RESOLUTION_PER_DIAGONAL,
    VERTEX_INSET,
    LiveGrid,
    default_resolution,
    grid,
)

__all__ = [
    "HEADINGS",
    "MAX_ETA_DEG",
    "MAX_GRID_POINTS",
    "POINTS_PER_CELL",
    "RESOLUTION_PER_DIAGONAL",
    "SHRINK",
    "SHRINK_STEPS",
    "VERTEX_INSET",
    "LiveGrid",
    "Liveness",
    "default_resolution",
    "evaluate",
    "grid",
    "measure",
]
