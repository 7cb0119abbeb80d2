"""The parameters of the decomposition (ALGORITHMS §4, §5.4, §11): :class:`Params`, re-exported by
:mod:`bearnav_cli.stages.decompose`."""

from __future__ import annotations

from dataclasses import dataclass

from bearnav_cli.params.declare import Range, check, param

__all__ = ["BARRIERS", "BISECTOR_RULES", "CBF_APEXES", "CBF_FILTERS", "CELL_MODES", "COVER_DOMAINS", "Params"]

CELL_MODES = ("funnel", "funnel-local", "paper")
COVER_DOMAINS = ("F", "F_m")  # the default first, as every choice tuple
BARRIERS = ("corridor", "wedge")
#: Paper B's text keeps every bisector but the parent's: on our trees that cuts the edge out of nearly
#: every edge cell (kitchen 130 of 132, paper_b_circles 99 of 102), so it is not offered (issue 24).
BISECTOR_RULES = ("crossing",)
CBF_APEXES = ("child", "parent")
CBF_FILTERS = ("both", "projection", "cell")


@dataclass(frozen=True)
class Params:
    """Parameters of the decomposition (ALGORITHMS §4, §5.4, §11).

    Attributes
    ----------
    cells : {"funnel", "funnel-local", "paper"}
        ``funnel`` (default): obstacle-free convex cells that hand the robot on from one to the
        next (ALGORITHMS §11.5): the corridor around each tree edge, narrowed where its exit
        would leave the next cell, with cells added until they cover ``coverage_target`` of the
        free space at least the barrier margin from obstacles and walls. ``funnel-local``
        starts each region from the §4.1 cell (bisector rows). ``paper``: the §4 cells with
        per-cell barrier rows, to reproduce the papers (the options below marked *paper* apply).
    exit_inset : float or None
        Funnel: how far inside the next cell each cell's exit lies (map units, ALGORITHMS §12.4).
        ``None`` (default): per cell, the inset that makes the position error the cell tolerates
        largest (``funnel.best_neck``); a number: that inset in every cell, capped at 98% of the
        exit point's depth in the next cell (warns). In the symbols of docs/algorithms.md the
        inset is ``δ_e,c`` and the tolerance ``τ_c = min(h*/2, δ_e,c/2)``.
    coverage_target : float
        Funnel: add cells until they cover this fraction of the free space at least the barrier
        margin from obstacles and walls (``cover = F_m``, ALGORITHMS §11.5 step 3), then, with
        ``cover = F``, of all the free space.
    cover : {"F", "F_m"}
        Funnel: the area the added cells fill. ``F`` (default): all the free space (ALGORITHMS
        §12.7): after ``F_m``, leaves in the band along the obstacles and walls,
        ``WALL_LEAF_DEPTH·m`` from ``O`` (the band curve's corners first), whose cells reach within
        a twentieth of that of the walls (``funnel.ROW_SHARE``), so robots parked there start inside the certificate. A
        band cell never lowers the least ``τ_c`` of the cells before the band: a leaf whose cell
        would is joined to the next node (up to ``BAND_NODE_TRIES``) or left out, and the warning
        says so. Kitchen, seeds 0–4: 99.0% of ``F``, the same least ``τ_c`` as ``F_m``, about 1.8×
        the cells. ``F_m``: only the free space at least the barrier margin from obstacles and
        walls (ALGORITHMS §11.5); the band nearer to them stays outside the certified area
        (kitchen: 99.0% of ``F_m``, 89.1% of the free space), for about half the planning time.
    max_added_nodes : int
        Funnel: at most this many leaf nodes are added by densification, ``F_m`` and the band
        together. The band along a cluttered floor's obstacles needs many (the made office and
        clutter maps: 290–370 for 99% of ``F``; 200 left them at 97.8–99.0%).
    bisector_rule : {"crossing"}
        *paper* and ``funnel-local``. ``crossing`` drops every bisector that crosses the edge (the authors' code).
        Paper B's text drops only the parent's, which cuts the edge out of nearly every cell of a tree: not offered.
    cbf_apex : {"child", "parent"}
        Apex of the barrier wedge; ``parent`` reproduces the paper's degenerate LP (warns). Its wedge is
        zero at the exit point, so ``synthesize`` certifies no cell that has one.
    cbf_filter : {"both", "projection", "cell"}
        Which collision samples a barrier may come from: projection onto the edge within
        the edge, inside the cell, or both.
    n_landmarks : int
        Landmarks per cell controller (the nearest visible ones, at least 2).
    barrier : {"corridor", "wedge"}
        ``corridor`` (default): one separating half-plane between the tree edge (the goal for
        the goal cell) and every convex piece of the inflated obstacles near the cell, and one
        per wall within the margin, so the safe set is obstacle-free (docs/choices.md).
        ``wedge``: ALGORITHMS §4.5–4.6 as written, lines through collision samples; its safe
        set overlaps the obstacles between samples.
    barrier_margin : float or None
        How far the safe set keeps from the obstacles and walls (map units). ``None`` means
        ``0.01·D``. With ``m`` the margin, a ``corridor`` barrier row is moved ``min(m, d/2)``
        toward the edge (``d`` the piece's distance from it); a funnel cell's row keeps
        ``min(m, d/20)`` (``funnel.ROW_SHARE``), and ``F_m`` is the free space at least ``m`` from
        ``O``.
    """

    cells: str = param("funnel", choices=CELL_MODES)
    exit_inset: float | None = param(None, range=Range(0, 1, per_diagonal=True), unit="map units")
    coverage_target: float = param(0.99, range=Range(0, 1), capped=True)
    cover: str = param("F", choices=COVER_DOMAINS)
    max_added_nodes: int = param(600, range=Range(0, 100_000, integer=True), capped=True)
    bisector_rule: str = param("crossing", choices=BISECTOR_RULES)
    cbf_apex: str = param("child", choices=CBF_APEXES)
    cbf_filter: str = param("both", choices=CBF_FILTERS)
    n_landmarks: int = param(4, range=Range(2, 1000, integer=True))
    barrier: str = param("corridor", choices=BARRIERS)
    barrier_margin: float | None = param(None, range=Range(0, 1, per_diagonal=True), unit="map units")

    def __post_init__(self) -> None:
        check(self)
