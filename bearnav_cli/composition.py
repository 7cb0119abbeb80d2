"""The composition proof of a funnel plan, re-checked from ``plan.npz`` alone (ALGORITHMS §11.6).

Every check is finite and exact (shapely polygons, numpy at the vertices, no LP):

- (C1) each cell lies in ``B_r`` and meets no obstacle;
- (C2) each cell holds its edge, and ``x_j`` lies strictly inside every row but the exit row;
- (C3) the exit row is ``−z·x ≤ −z·x_j``;
- (C4) both ends of the exit face satisfy the parent cell's rows with slack ``≥ δ_e,c − tol``
  (each cell's own inset, ALGORITHMS §12.3), and that least slack is recomputed;
- the barrier rows are exactly the cell's non-exit rows (so (L1) is about the cell itself), and
  (L1)–(L3) hold at every vertex with ``σ_h ≥ 0`` and ``σ_v > 0`` (:mod:`bearnav_cli.verify`
  recomputes the values; this module checks the signs and the strictness);
- ranks decrease along every exit; ``δ_c`` is recomputed, and no stored ``τ_c`` exceeds
  ``min(δ_c, δ_e,c/2)`` (§12.8);
- the coverage of ``F`` and of ``F_m`` (§12.7), and the worst-case time to the goal.

:func:`check` returns a :class:`Composition`; its :attr:`Composition.problems` name each failing
cell and check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import shapely

from bearnav_cli.datatypes import Cells, Map, Plan, cell_list, cell_polygons, tolerance_by_area
from bearnav_cli.funnel import (
    cell_tolerance,
    coverage_domain,
    depth,
    plan_tolerance_of,
    reached_parts,
    usable_tolerances,
)
from bearnav_cli.geometry import FreeSpace, barrier_margin

__all__ = [
    "PAPER_CLAIM",
    "Composition",
    "CoverageRegions",
    "check",
    "coverage",
    "coverage_margin",
    "coverage_regions",
    "covered_fraction",
    "robot_words",
    "time_bound",
    "world_violations",
]

#: Relative agreement of a recomputed tolerance with the stored one.
TOLERANCE_RTOL = 1e-6


@dataclass(frozen=True, eq=False)
class Composition:
    """The §11.6 checks of a funnel plan (C cells).

    Attributes
    ----------
    failures : dict of str to list of int
        For each check that fails somewhere, the cells where it fails (``c1_free``, ``c2_edge``,
        ``c3_exit_row``, ``c4_exit_contained``, ``barrier_rows``, ``l1_barrier``, ``l2_progress``,
        ``rank``, ``tolerance``, ``usable_tolerance``).
    tolerance : ndarray, shape (C,)
        ``δ_c`` recomputed.
    plan_tolerance : float
        ``min_c τ_c`` recomputed from the recomputed ``δ_c`` and the stored insets.
    coverage : float
        ``area(D ∩ F_m) / area(F_m)`` recomputed (exact polygon areas).
    stored_coverage : float
        The coverage the plan's cells record (``cells.free_coverage``, of ``F``), to compare with
        ``coverage_free``.
    time_bound : float
        The worst-case time to the goal at ``speed`` (s), :func:`time_bound`.
    speed : float
        The closed-loop speed the time bound assumes (map units/s).
    notes : list of str
        Problems that are not per-cell failures (a stored ``δ*`` that differs from the
        recomputed one); :attr:`problems` lists them after the failing checks.
    regions : CoverageRegions or None
        The split of ``F_m`` the coverage was measured on (:func:`coverage_regions`).
    exit_inset : ndarray, shape (C,)
        ``δ_e,c`` recomputed: the least slack of each exit face's ends in the parent's rows (map
        units; NaN for the goal cell).
    usable_tolerance : ndarray, shape (C,)
        ``τ_c = min(δ_c, δ_e,c/2)`` from the recomputed ``δ_c`` and the stored insets.
    coverage_free : float
        ``area(D ∩ F) / area(F)`` over the reached part of ``F`` (ALGORITHMS §12.7).
    free_regions : CoverageRegions or None
        The split of ``F`` that ``coverage_free`` was measured on.
    usable_by_area : dict
        :func:`tolerance_by_area` of the recomputed ``τ_c``: minimum, p10, median, p90 (map units).
    """

    failures: dict[str, list[int]]
    tolerance: np.ndarray
    plan_tolerance: float
    coverage: float
    stored_coverage: float
    time_bound: float
    speed: float
    notes: list[str] = field(default_factory=list)
    regions: CoverageRegions | None = None
    exit_inset: np.ndarray | None = None
    usable_tolerance: np.ndarray | None = None
    coverage_free: float = math.nan
    free_regions: CoverageRegions | None = None
    usable_by_area: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not any(self.failures.values())

    @property
    def problems(self) -> list[str]:
        """One line per failing check, naming the cells."""
        words = {
            "c1_free": "(C1) cells not inside B_r or meeting an obstacle",
            "c2_edge": "(C2) cells that do not hold their edge strictly",
            "c3_exit_row": "(C3) cells whose exit row is not −z·x ≤ −z·x_j",
            "c4_exit_contained": "(C4) cells whose exit face leaves the parent cell eroded by its own inset δ_e,c",
            "barrier_rows": "cells whose barrier rows are not their own non-exit rows",
            "l1_barrier": "(L1) cells with a negative barrier margin",
            "l2_progress": "(L2) cells without a strictly positive progress margin",
            "rank": "cells whose exit does not lead to a smaller rank",
            "tolerance": "cells whose stored tolerance δ_c differs from the recomputed one",
            "usable_tolerance": "cells whose stored usable tolerance τ_c exceeds min(δ_c, δ_e,c/2)",
        }
        return [f"{len(v)} {words[k]}: {cell_list(v)}" for k, v in self.failures.items() if v] + self.notes


def _parent_cells(plan: Plan) -> np.ndarray:
    cells = plan.cells
    node_cell = np.full(len(cells.nodes), -1, np.int64)
    node_cell[cells.cell_node] = np.arange(cells.n_cells)
    up = cells.parent[cells.cell_node]
    return np.where(up >= 0, node_cell[np.maximum(up, 0)], -1)


def _field(plan: Plan, c: int) -> tuple[np.ndarray, np.ndarray]:
    """``(a, M)`` with ``u(x) = a − M x`` from the stored gain."""
    K = plan.gain[c]
    return K @ plan.landmarks.ravel(), K.reshape(2, -1, 2).sum(axis=1)


def check(plan: Plan, speed: float, space: FreeSpace | None = None) -> Composition:
    """Run every §11.6 check on a funnel plan.

    Parameters
    ----------
    plan : Plan
        With ``cells.certificate == "funnel"``.
    speed : float
        Closed-loop speed for the time bound (map units / s).
    space : FreeSpace, optional
        The world to check (C1) against; default the plan's own map.
    """
    cells, map_ = plan.cells, plan.map
    tol = map_.tol
    space = FreeSpace.from_map(map_) if space is None else space
    up = _parent_cells(plan)
    failures: dict[str, list[int]] = {
        k: []
        for k in (
            "c1_free",
            "c2_edge",
            "c3_exit_row",
            "c4_exit_contained",
            "barrier_rows",
            "l1_barrier",
            "l2_progress",
            "rank",
            "tolerance",
            "usable_tolerance",
        )
    }
    failures["c1_free"] = world_violations(plan, space)
    tolerance = np.zeros(cells.n_cells)
    inset = cells.exit_inset
    slack = np.full(cells.n_cells, math.nan)  # δ_e,c recomputed
    for c in range(cells.n_cells):
        A, b = cells.rows(c)
        verts = cells.vertices(c)
        k = int(cells.cell_exit_row[c])
        node = cells.cell_node[c]
        j = up[c]
        keep = np.arange(len(b)) != k
        normals, offsets = cells.barrier(c)
        if normals.shape != (int(keep.sum()), 2) or not (
            np.allclose(normals, -A[keep], rtol=0, atol=1e-12) and np.allclose(offsets, b[keep], rtol=0, atol=1e-12)
        ):
            failures["barrier_rows"].append(c)
        a, M = _field(plan, c)
        u = a - verts @ M.T
        h = b[keep][None, :] - verts @ A[keep].T  # h_k(v_q) >= 0 on the cell
        l1 = u @ A[keep].T - plan.c_h[c] * h  # (L1): <= −σ_h
        sigma_h = -np.max(l1, axis=0) if len(h) else np.zeros(0)
        if np.any(sigma_h < -1e-9):
            failures["l1_barrier"].append(c)
        if j < 0:  # the goal cell: g strictly inside every row
            if not np.all(b - A @ map_.goal > tol):
                failures["c2_edge"].append(c)
            tolerance[c] = cell_tolerance(M, A[keep], sigma_h, None, None)
            continue
        x_i, x_j = cells.nodes[node], cells.exit_point[c]
        z = cells.exit_dir[c]
        if not (np.all(A @ x_i <= b + tol) and np.all(A @ x_j <= b + tol) and np.all(b[keep] - A[keep] @ x_j > tol)):
            failures["c2_edge"].append(c)
        if k < 0 or not (np.allclose(A[k], -z, atol=1e-9) and abs(b[k] + z @ x_j) <= 1e3 * tol):
            failures["c3_exit_row"].append(c)
            tolerance[c] = 0.0
            continue
        face = verts[[k, (k + 1) % len(verts)]]
        A_j, b_j = cells.rows(j)
        slack[c] = depth(A_j, b_j, face)
        if not slack[c] >= inset[c] - 1e3 * tol:
            failures["c4_exit_contained"].append(c)
        sigma_v = -float(np.max(u @ z + plan.c_v[c] * ((verts - x_j) @ z)))
        if not sigma_v > 0:
            failures["l2_progress"].append(c)
        if not cells.cell_rank[j] < cells.cell_rank[c]:
            failures["rank"].append(c)
        tolerance[c] = cell_tolerance(M, A[keep], sigma_h, z, sigma_v)
    stored = np.asarray(plan.tolerance, float)
    off = ~np.isclose(tolerance, stored, rtol=TOLERANCE_RTOL, atol=1e-12)
    failures["tolerance"] = np.flatnonzero(off).tolist()
    # §12.8: no stored τ_c above min(δ_c, δ_e,c/2), with δ_c recomputed and δ_e,c within its slack (C4)
    usable = usable_tolerances(tolerance, inset)
    above = ~(np.asarray(plan.usable_tolerance, float) <= usable * (1.0 + TOLERANCE_RTOL) + 1e-12)
    failures["usable_tolerance"] = np.flatnonzero(above).tolist()
    plan_tolerance = plan_tolerance_of(usable)
    notes = []
    if not math.isclose(plan_tolerance, plan.plan_tolerance, rel_tol=TOLERANCE_RTOL, abs_tol=1e-12):
        notes.append(
            f"stored plan tolerance {plan.plan_tolerance:.6g} differs from the recomputed min τ_c {plan_tolerance:.6g}"
        )
    regions = coverage_regions(cells, space, coverage_margin(plan))
    free_regions = coverage_regions(cells, space, 0.0)
    if not math.isclose(covered_fraction(free_regions), float(cells.free_coverage), rel_tol=1e-6, abs_tol=1e-9):
        notes.append(
            f"stored coverage of F {cells.free_coverage:.6g} differs from the recomputed "
            f"{covered_fraction(free_regions):.6g}"
        )
    return Composition(
        failures,
        tolerance,
        plan_tolerance,
        covered_fraction(regions),
        float(cells.free_coverage),
        time_bound(plan, speed),
        speed,
        notes,
        regions,
        slack,
        usable,
        covered_fraction(free_regions),
        free_regions,
        tolerance_by_area(cells, usable),
    )


def world_violations(plan: Plan, space: FreeSpace) -> list[int]:
    """(C1) against a world: the cells that leave its ``B_r`` or meet one of its obstacles (exact)."""
    cells = plan.cells
    tol = plan.map.tol
    lo, hi = space.bounds[:2] - tol, space.bounds[2:] + tol
    polygons = cell_polygons(cells)
    hits = (
        shapely.intersects(space.obstacles, polygons) if not space.obstacles.is_empty else np.zeros(len(polygons), bool)
    )
    out = []
    for c in range(cells.n_cells):
        v = cells.vertices(c)
        if hits[c] or np.any(v < lo) or np.any(v > hi):
            out.append(c)
    return out


class CoverageRegions(NamedTuple):
    """The free space the cells must cover, split (ALGORITHMS §11.1, §11.5; :func:`coverage_regions`).

    Attributes
    ----------
    domain : shapely geometry
        ``F_m`` of the goal's free component less its parts that no cell meets
        (:func:`bearnav_cli.funnel.reached_parts`), map units.
    uncovered : shapely geometry
        ``domain \\ D``: free space of the domain that no cell (no certificate) covers.
    unreached : shapely geometry
        The parts of ``F_m`` cut off from every cell by passages narrower than ``2m``.
    """

    domain: shapely.Geometry
    uncovered: shapely.Geometry
    unreached: shapely.Geometry


def coverage_margin(artifact: Cells | Plan) -> float:
    """The barrier margin ``m`` of ``F_m`` that decompose used (map units).

    From the artifact's statistics (decompose records it, synthesize copies it: DESIGN §3.3 has no
    key for it, and a margin given on the command line is not in the map), else the map's own
    ``decompose.barrier_margin``, else the default ``0.01·D``.
    """
    stats = artifact.stats if isinstance(artifact.stats, dict) else {}
    recorded = stats.get("barrier_margin")
    if (
        isinstance(recorded, (int, float))
        and not isinstance(recorded, bool)
        and math.isfinite(recorded)
        and recorded > 0
    ):
        return float(recorded)
    map_ = artifact.map
    requested = map_.params.get("decompose", {}).get("barrier_margin") if isinstance(map_.params, dict) else None
    return barrier_margin(requested, map_.diagonal)


def coverage_regions(cells: Cells, space: FreeSpace | None = None, margin: float | None = None) -> CoverageRegions:
    """``F_m`` of the goal's free component, what of it the cells reach, and what they leave uncovered.

    Parameters
    ----------
    cells : Cells
        The decomposition (or a plan's ``cells``); its map gives the goal, bounds and obstacles.
    space : FreeSpace, optional
        The free space of ``cells.map`` (built from the map when None); pass it to reuse one.
    margin : float, optional
        The barrier margin ``m`` of ``F_m`` (map units); default :func:`coverage_margin` of
        ``cells``.

    Returns
    -------
    CoverageRegions
    """
    map_ = cells.map
    space = FreeSpace.from_map(map_) if space is None else space
    margin = coverage_margin(cells) if margin is None else margin  # 0: the regions of F itself
    full = coverage_domain(space.component_of(map_.goal), space.bounds, space.obstacles, margin)
    union = shapely.union_all(cell_polygons(cells))
    domain, unreached = reached_parts(full, union)
    return CoverageRegions(domain, shapely.difference(domain, union), unreached)


def coverage(plan: Plan, space: FreeSpace) -> float:
    """``area(D ∩ F_m) / area(F_m)`` over the parts of ``F_m`` the cells reach (§11.1, :func:`coverage_regions`)."""
    return covered_fraction(coverage_regions(plan.cells, space, coverage_margin(plan)))


def covered_fraction(regions: CoverageRegions) -> float:
    """The covered fraction of the reached part of ``F_m`` (1 when it is empty)."""
    if regions.domain.area <= 0:
        return 1.0
    return float(1.0 - regions.uncovered.area / regions.domain.area)


def time_bound(plan: Plan, speed: float) -> float:
    """Worst-case time to the goal from anywhere in ``D`` at constant ``speed`` (ALGORITHMS §11.3), s.

    A robot drives ``ẋ = s·u/‖u‖``; (L2) holds on the whole cell (affine, checked at the vertices) as
    ``zᵀu ≤ −c_v V − σ_v``, so ``V̇ ≤ −k(c_v V + σ_v)`` with ``k = s / max_{P_c} ‖u‖``. From
    ``V ≤ V̄ = max_{P_c} V`` the exit line ``V = 0`` is reached within
    ``T_c = ln(1 + c_v V̄/σ_v) / (k c_v)`` (``V̄/(k σ_v)`` when ``c_v = 0``, the limit; the decay
    term makes the bound logarithmic in ``V̄/σ_v``). A robot leaving ``P_c`` lands on its exit face and switches
    to a containing cell of smaller rank, which must meet that face. ``W(c) = T_c + max W(k)``
    over those cells, in rank order; the goal cell takes at most ``max ‖v − g‖ / s``. Returns
    ``max_c W(c)`` (``inf`` if a cell has no positive progress margin).
    """
    cells = plan.cells
    n = cells.n_cells
    order = np.argsort(cells.cell_rank, kind="stable")
    polygons = cell_polygons(cells)
    tree = shapely.STRtree(polygons)
    worst = np.zeros(n)
    for c in order:
        verts = cells.vertices(c)
        a, M = _field(plan, c)
        u = a - verts @ M.T
        k = int(cells.cell_exit_row[c])
        if k < 0:
            worst[c] = float(np.max(np.hypot(*(verts - plan.map.goal).T))) / speed
            continue
        z, x_j = cells.exit_dir[c], cells.exit_point[c]
        sigma_v = -float(np.max(u @ z + plan.c_v[c] * ((verts - x_j) @ z)))
        if not sigma_v > 0:
            worst[c] = math.inf
            continue
        v_top = float(np.max((verts - x_j) @ z))
        k_rate = speed / float(np.max(np.hypot(u[:, 0], u[:, 1])))
        c_v = float(plan.c_v[c])
        ratio = c_v * v_top / sigma_v
        t_c = math.log1p(ratio) / (k_rate * c_v) if c_v > 0 and ratio > 1e-12 else v_top / (k_rate * sigma_v)
        face = shapely.LineString(verts[[k, (k + 1) % len(verts)]])
        landing = [int(m) for m in tree.query(face, predicate="intersects") if cells.cell_rank[m] < cells.cell_rank[c]]
        worst[c] = t_c + (max(worst[m] for m in landing) if landing else math.inf)
    return float(worst.max()) if n else 0.0


def map_frame_problem(plan_map: Map, world: Map) -> str | None:
    """Why ``world`` cannot be checked against the plan's map (another frame), or ``None``."""
    if not np.allclose(plan_map.bounds, world.bounds):
        return f"bounds {world.bounds.tolist()} differ from the plan's {plan_map.bounds.tolist()} (another frame)"
    if not math.isclose(plan_map.robot_radius, world.robot_radius):
        return f"robot_radius {world.robot_radius} differs from the plan's {plan_map.robot_radius}"
    return None


#: What a paper plan's certificates give (ALGORITHMS §4): each cell alone, no route to the goal.
PAPER_CLAIM = (
    "each certified cell's controller keeps a robot that knows its position in that cell and drives it "
    "out of the cell's exit; that the cells chain into a route to the goal is not proven for paper cells"
)


def robot_words(map_: Map) -> str:
    """The robot a funnel plan's guarantee is about: ``a robot of radius ρ``, commanded in velocity or
    driven through its look-ahead point (the subject of ``verify``'s and ``plan``'s guarantee sentences)."""
    who = f"a robot of radius {map_.robot_radius:g}"
    if map_.lookahead > 0:
        return f"{who} driven through its point {map_.lookahead:g} ahead of the axle (a unicycle)"
    return f"{who} commanded in velocity"
