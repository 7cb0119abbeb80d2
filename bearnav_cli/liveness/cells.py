"""Which cells are live (ALGORITHMS §12.5): each cell's bound after a look against its margin, ``η*_c`` and
``η*``, and the live fraction of ``D``, for a set of landmarks on a :class:`LiveGrid`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from bearnav_cli.datatypes import Plan, percent
from bearnav_cli.liveness.live_grid import LiveGrid, bounds_of, distinct_views, grid
from bearnav_cli.runtime import least_rank_cell, robot

__all__ = ["evaluate", "Liveness", "MAX_ETA_DEG", "measure", "SHRINK", "SHRINK_STEPS"]


#: ``η*_c`` shrinks by at least this factor per re-evaluation ...
SHRINK = 0.9
#: ... at most this many times (then ``η*_c`` is 0, or ``η`` for a cell live at ``η``).
SHRINK_STEPS = 12
#: Largest ``η*_c`` reported (degrees): the 2η cones stay below 90°.
MAX_ETA_DEG = 22.5
#: The headings of a look-ahead robot's starts, one per grid point (rad): ``π(3 − √5)`` apart, evenly spread.
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


@dataclass(frozen=True, eq=False)
class Liveness:
    """The liveness of a funnel plan's cells at ``(η, fov, κ)`` (ALGORITHMS §12.5), measured on a grid.

    Attributes
    ----------
    eps_look : ndarray, shape (C,)
        ``ε_c^look``: the largest over the cell's grid points of the bound after a look, which ends
        with a turn all around: every landmark in sight and in range (map units).
    eps_view : ndarray, shape (C,)
        The same for the look's first view alone: the least one-view bound over the headings
        (``eps_look`` for a camera that sees all around; map units).
    live : ndarray of bool, shape (C,)
        At every grid point of the cell the bound after a look is below the margin there
        (:meth:`LiveGrid.pair_margin`: what the certificate tolerates around the point, the runtime's
        rule, never less than ``margin``); so at least where ``eps_look < margin``.
    view_live : ndarray of bool, shape (C,)
        The same for the look's first view: one view at the best heading is enough, no turn all around.
    cell_eta_star : ndarray, shape (C,)
        ``η*_c`` (rad): the largest bearing error at which the grid found the cell live; 0 where
        it is never live.
    points : ndarray of int, shape (C,)
        Grid points of each cell.
    eta_star : float
        The plan's certified bearing error ``η* = min_c η*_c`` (rad).
    live_fraction : float
        Area of ``D`` whose active cell (the least-rank cell holding the point) is live, over the
        area of ``D``, in [0, 1].
    view_fraction : float
        The same for ``view_live`` (``≤ live_fraction``).
    cover_fraction : float
        Area of the union of the live cells over the area of ``D``, in [0, 1] (``≥ live_fraction``).
    start_fraction : float
        The fraction of ``D`` (its grid points) from which a start is sure to find, after a look all around,
        a cell that holds its whole set and lets it move (:meth:`LiveGrid.sure_start`, §12.3 step 4): a start
        within about ``ε`` of the edge of ``D`` may look and still not know it is in ``D``, in [0, 1]. A
        look-ahead robot's start is its point in ``D`` at any heading, its camera ``λ`` behind (one heading per
        point, :data:`GOLDEN_ANGLE` apart).
    grid : LiveGrid
        Where and at what it was measured: the bearing error ``η``, the camera, the slip, the grid,
        and each cell's ``margin`` and ``tolerance`` (also properties of this object).
    """

    eps_look: np.ndarray
    eps_view: np.ndarray
    live: np.ndarray
    view_live: np.ndarray
    cell_eta_star: np.ndarray
    points: np.ndarray
    eta_star: float
    live_fraction: float
    view_fraction: float
    cover_fraction: float
    start_fraction: float
    grid: LiveGrid

    @property
    def margin(self) -> np.ndarray:
        """``τ_c − κℓ − ν`` (less ``2λ sin(ψ/2)`` with a look-ahead), shape (C,) map units."""
        return self.grid.margin

    @property
    def tolerance(self) -> np.ndarray:
        """``τ_c``, the plan's usable tolerance, shape (C,) map units."""
        return self.grid.tolerance

    @property
    def n_live(self) -> int:
        """Live cells."""
        return int(np.count_nonzero(self.live))

    def summary(self) -> str:
        """One plain sentence: the live fraction, η* and how it was measured."""
        g = self.grid
        camera = "360° camera" if g.fov >= 2.0 * math.pi - 1e-12 else f"{math.degrees(g.fov):g}° camera"
        reach = "" if math.isinf(g.max_range) else f" of range {g.max_range:g}"
        heads = "1 heading (all around)" if g.headings == 1 else f"{g.headings} headings"
        return (
            f"liveness at a bearing error of {math.degrees(g.eta):.3g}°, {camera}{reach}, wheel slip {g.kappa:g}: "
            f"{percent(self.live_fraction)} of the certified area live ({self.n_live}/{len(self.live)} cells; "
            f"{percent(self.view_fraction)} after one view, without turning all around; {percent(self.start_fraction)} "
            "where a start is sure to find its cell after one look); the largest bearing error "
            f"every cell is live at: {math.degrees(self.eta_star):.3g}°; measured on a {g.resolution:.3g}-map-unit "
            f"grid with {heads}, a measurement, not a proof"
        )

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict: degrees for angles, map units for lengths, ``null`` for non-finite numbers."""

        def finite(values: np.ndarray, scale: float = 1.0) -> list:
            return [float(v) * scale if math.isfinite(v) else None for v in np.asarray(values, float)]

        deg = math.degrees(1.0)
        return {
            "eta_deg": round(math.degrees(self.grid.eta), 12),
            "fov_deg": round(math.degrees(self.grid.fov), 12),
            "max_range": None if math.isinf(self.grid.max_range) else self.grid.max_range,
            "kappa": self.grid.kappa,
            "nu": self.grid.nu,
            "step": self.grid.step,
            "swing": self.grid.swing,
            "resolution": self.grid.resolution,
            "headings": self.grid.headings,
            "measured": "on a grid of the stated resolution: a measurement, not a proof",
            "live_fraction": self.live_fraction,
            "view_fraction": self.view_fraction,
            "cover_fraction": self.cover_fraction,
            "start_fraction": self.start_fraction,
            "live_cells": self.n_live,
            "eta_star_deg": math.degrees(self.eta_star),
            "per_cell": {
                "eps_look": finite(self.eps_look),
                "eps_view": finite(self.eps_view),
                "margin": finite(self.margin),
                "tolerance": finite(self.tolerance),
                "live": [bool(v) for v in self.live],
                "view_live": [bool(v) for v in self.view_live],
                "eta_star_deg": finite(self.cell_eta_star, deg),
                "points": [int(v) for v in self.points],
            },
            "summary": self.summary(),
        }


def _cell_max(values: np.ndarray, cell: np.ndarray, n_cells: int) -> np.ndarray:
    out = np.full(n_cells, -np.inf)
    np.maximum.at(out, cell, values)
    return out


def _point_min(values: np.ndarray, row_point: np.ndarray, n_points: int) -> np.ndarray:
    out = np.full(n_points, np.inf)
    np.minimum.at(out, row_point, values)
    return out


def measure(
    plan: Plan,
    eta_deg: float | None = None,
    fov_deg: float = 60.0,
    kappa: float | None = None,
    nu: float | None = None,
    speed: float | None = None,
    resolution: float | None = None,
    headings: int | None = None,
    max_range: float = math.inf,
    landmarks: np.ndarray | None = None,
) -> Liveness:
    """Measure the liveness of a funnel plan's cells on a grid (ALGORITHMS §12.5; see :mod:`bearnav_cli.liveness`).

    Parameters
    ----------
    plan, eta_deg, fov_deg, kappa, nu, speed, resolution, headings, max_range
        As :func:`grid`.
    landmarks : ndarray, shape (L, 2), optional
        The tags to measure with (map units); default the plan's. The cells and their tolerances
        do not depend on them, so proposed tags are measured on the same plan.

    Returns
    -------
    Liveness

    Raises
    ------
    InvalidParamsError
        As :func:`grid`.
    """
    return evaluate(grid(plan, eta_deg, fov_deg, kappa, nu, speed, resolution, headings, max_range), landmarks)


def evaluate(
    g: LiveGrid, landmarks: np.ndarray | None = None, look: tuple[np.ndarray, np.ndarray] | None = None
) -> Liveness:
    """The liveness of the cells on a grid with a set of landmarks.

    Parameters
    ----------
    g : LiveGrid
        The grid, the plan and the bounds (:func:`grid`).
    landmarks : ndarray, shape (L, 2), optional
        The landmarks (map units); default the plan's.
    look : tuple of ndarray, optional
        ``g.look(landmarks)``, when the caller has it already.
    """
    arrays, points, pair_cell, pair_point, margin, eta = g.arrays, g.points, g.pair_cell, g.pair_point, g.margin, g.eta
    lm = arrays.landmarks if landmarks is None else np.asarray(landmarks, float).reshape(-1, 2)
    n_cells = len(margin)
    polygons = list(g.polygons)
    # a look ends with a turn all around (§12.5): its set lies in the cones of every landmark in sight
    all_vis, eps_all = g.look(lm) if look is None else look
    eps_pair = eps_all[pair_point]
    eps_look = _cell_max(eps_pair, pair_cell, n_cells)
    live = _all_below(eps_pair, g, n_cells)
    cell_eta = _eta_star(g, lm, all_vis, eps_look, live)
    if g.fov >= 2.0 * math.pi:
        eps_view, view_live = eps_look, live
    else:  # the look's first view, at the best heading
        row_point, row_vis = distinct_views(arrays, points, g.fov, g.max_range, g.headings, lm)
        row_eps = bounds_of(arrays, points[row_point], row_vis, np.full(len(row_point), eta), lm)
        view_pair = _point_min(row_eps, row_point, len(points))[pair_point]
        eps_view = _cell_max(view_pair, pair_cell, n_cells)
        view_live = _all_below(view_pair, g, n_cells)

    area, regions = g.area, g.regions
    live_area = sum(float(regions[c].area) for c in np.flatnonzero(live))
    view_area = sum(float(regions[c].area) for c in np.flatnonzero(view_live))
    cover = float(shapely.union_all([polygons[c] for c in np.flatnonzero(live)]).area) if live.any() else 0.0
    points_per_cell = np.bincount(pair_cell, minlength=n_cells)
    # the starts: the square grid's points in D (evenly spread); a look-ahead robot's camera stands λ behind its
    # point, at any heading: one per point, spread by the golden angle, so that the share is over headings too
    square = points[: g.grid_points]
    in_d = np.flatnonzero(least_rank_cell(arrays, square) >= 0)
    camera, eps_start = square[in_d], eps_all[in_d]
    if arrays.lookahead > 0:
        camera = robot.lookahead_point(camera, GOLDEN_ANGLE * np.arange(len(in_d)), -float(arrays.lookahead))
        eps_start = g.look(lm, camera)[1]
    sure = g.sure_start(camera, eps_start)
    return Liveness(
        eps_look=eps_look,
        eps_view=eps_view,
        live=live,
        view_live=view_live,
        cell_eta_star=cell_eta,
        points=points_per_cell,
        eta_star=float(np.min(cell_eta)) if n_cells else 0.0,
        live_fraction=min(1.0, live_area / area) if area > 0 else 0.0,
        view_fraction=min(1.0, view_area / area) if area > 0 else 0.0,
        cover_fraction=min(1.0, cover / area) if area > 0 else 0.0,
        start_fraction=float(np.mean(sure)) if len(sure) else 0.0,
        grid=g,
    )


def _all_below(eps_pair: np.ndarray, g: LiveGrid, n_cells: int, sel: Any = slice(None)) -> np.ndarray:
    """Whether every point of each cell has its bound below the margin there (:meth:`LiveGrid.pair_margin`), (C,);
    ``eps_pair`` of the pairs ``sel`` selects (an index of the grid's pairs), default all."""
    short = eps_pair >= g.pair_margin(eps_pair, sel)
    failing = np.bincount(g.pair_cell[sel][short], minlength=n_cells) > 0
    return ~failing


def _eta_star(
    g: LiveGrid, landmarks: np.ndarray, visible: np.ndarray, eps_look: np.ndarray, live: np.ndarray
) -> np.ndarray:
    """``η*_c`` per cell (rad): the linear estimate, re-evaluated on the grid and shrunk until live.

    Every point looks at the landmarks ``visible`` (P, L) (its look all around). The estimate scales ``η`` by the
    cell's least margin over its largest bound; the re-evaluation compares each point with its own margin.
    """
    arrays, points, pair_cell, pair_point, margin, eta = g.arrays, g.points, g.pair_cell, g.pair_point, g.margin, g.eta
    n_cells = len(margin)
    out = np.zeros(n_cells)
    ok = (margin > 0) & (eps_look > 0) & np.isfinite(eps_look)
    guess = np.zeros(n_cells)
    guess[ok] = np.minimum(eta * margin[ok] / eps_look[ok], math.radians(MAX_ETA_DEG))
    out[live] = eta  # live at η already: η*_c ≥ η
    pending = ok & (guess > out)
    for _ in range(SHRINK_STEPS):
        cells = np.flatnonzero(pending)
        if not len(cells):
            break
        sel = np.isin(pair_cell, cells)
        pc, pp = pair_cell[sel], pair_point[sel]
        eps_pair = bounds_of(arrays, points[pp], visible[pp], guess[pc], landmarks)
        eps_cell = _cell_max(eps_pair, pc, n_cells)[cells]
        good = _all_below(eps_pair, g, n_cells, sel)[cells]
        out[cells[good]] = np.maximum(out[cells[good]], guess[cells[good]])
        pending[cells[good]] = False
        bad = cells[~good]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(eps_cell[~good] > 0, margin[bad] / eps_cell[~good], 0.0)
        guess[bad] *= np.minimum(SHRINK, ratio)
        pending[bad] &= guess[bad] > out[bad]  # a cell live at η stops once the guess falls to η
    return out
