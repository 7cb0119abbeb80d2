"""``bearnav decompose``: one convex cell per tree node, with CLF and CBF rows (ALGORITHMS §4, §5.4–5.5).

Every non-root node ``i`` with parent ``j`` owns the edge cell
``X_ij = B ∩ E_ij ∩ ⋂_{k ∈ K_ij} H_ik`` (bisector half-planes of the nodes whose bisector
does not cross the edge, and the exit half-plane through ``x_j``); the root owns the goal
cell, its Voronoi cell clipped to the bounds. Each cell also gets its barrier rows from
the collision samples, the landmarks its controller will use (line of sight from the
whole free part of the cell) and the fixed landmark that rescales bearings.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import shapely
import shapely.ops

from bearnav_cli import verdicts
from bearnav_cli.barriers import cbf_rows, corridor_rows, goal_cbf_rows, wall_rows
from bearnav_cli.cell_landmarks import cell_landmarks, fixed_landmark, seen_from, segments_seen, witness_points
from bearnav_cli.datatypes import NEGLIGIBLE_SHARE, CellFlag, Cells, Tree, cell_list, plural
from bearnav_cli.errors import ArtifactError
from bearnav_cli.funnel import (
    BAND_NODE_TRIES,
    INSET_LIMIT,
    WALL_LEAF_DEPTH,
    NeckChoice,
    ObstaclePieces,
    Region,
    band_candidates,
    best_neck,
    cells_union,
    coverage_domain,
    densify,
    densify_leaf,
    depth,
    exit_row_index,
    funnel_region,
    join_leaf,
    neck_choice,
    reached_coverage,
    reached_parts,
)
from bearnav_cli.geometry import (
    FreeSpace,
    barrier_margin,
    box_polygon,
    clip,
    landmark_coverage,
    polygon_rows,
)
from bearnav_cli.params.decompose import (
    Params,
)

VERSION = 5  # 4: cover = F and max_added_nodes = 600 by default; free_coverage_m of the final cells;
# 5: rows keep d/20 from a piece, not d/4 (funnel.ROW_SHARE)
log = logging.getLogger(__name__)

#: Re-exported: the cell and barrier helpers are part of this stage's interface.
__all__ = ["VERSION", "problems", "run", "summary"]


# --------------------------------------------------------------------------- cells


def _bisector_cell(nodes: np.ndarray, i: int, skip: np.ndarray, start: np.ndarray, tol: float) -> np.ndarray:
    """Clip ``start`` by the bisector half-planes ``H_ik`` of every node ``k`` not in ``skip``.

    Nodes are taken nearest first; once ``½‖x_k − x_i‖`` exceeds the farthest vertex's
    distance from ``x_i`` no later bisector can cut (ALGORITHMS §4.2).
    """
    xi = nodes[i]
    delta = nodes - xi
    dist = np.hypot(delta[:, 0], delta[:, 1])
    polygon = start
    reach = np.max(np.hypot(*(polygon - xi).T))
    candidates = np.flatnonzero(~skip & (np.arange(len(nodes)) != i) & (0.5 * dist < reach))
    candidates = candidates[np.argsort(dist[candidates], kind="stable")]
    normals = delta[candidates] / dist[candidates, None]
    offsets = normals @ xi + 0.5 * dist[candidates]
    # Clip only by half-planes that cut the current polygon, nearest first, re-testing all
    # remaining ones after each cut: a handful of cuts instead of one pass per candidate.
    while len(candidates):
        cuts = np.max(polygon @ normals.T, axis=0) > offsets
        if not cuts.any():
            break
        first = int(np.argmax(cuts))
        polygon = clip(polygon, normals[first], offsets[first], tol)
        keep = cuts.copy()
        keep[first] = False
        candidates, normals, offsets = candidates[keep], normals[keep], offsets[keep]
    return polygon


def edge_cell(nodes: np.ndarray, i: int, j: int, bounds: np.ndarray, tol: float) -> np.ndarray:
    """The edge cell ``X_ij`` of ALGORITHMS §4.1 as a CCW polygon, shape (p, 2): the bisectors that cross the
    edge dropped (``bisector_rule=crossing``, the authors' code), so the cell holds the edge and its exit face."""
    xi, xj = nodes[i], nodes[j]
    z = (xi - xj) / np.hypot(*(xi - xj))
    polygon = clip(box_polygon(bounds), -z, -(z @ xj), tol)  # exit half-plane z·(x − x_j) >= 0
    # drop the parent's bisector and every one that crosses [x_i, x_j]: x_j not strictly inside H_ik
    skip = np.hypot(*(nodes - xj).T) <= np.hypot(*(xi - xj)) + tol
    skip[j] = True
    polygon = _bisector_cell(nodes, i, skip, polygon, tol)
    if len(polygon) < 3:
        raise ArtifactError(f"cell of node {i} degenerated while clipping (Lemma 1 rules this out)", field="nodes")
    return polygon


def goal_cell(nodes: np.ndarray, bounds: np.ndarray, tol: float) -> np.ndarray:
    """The goal cell ``X_r = B ∩ ⋂ H_rk``: the root's Voronoi cell clipped to the bounds (§4.3)."""
    polygon = _bisector_cell(nodes, 0, np.zeros(len(nodes), bool), box_polygon(bounds), tol)
    if len(polygon) < 3:
        raise ArtifactError("the goal cell degenerated while clipping", field="nodes")
    return polygon


# --------------------------------------------------------------------------- funnel cells (ALGORITHMS §11.5)


@dataclass
class _Layout:
    """The cells of one decomposition before landmarks: per cell a region, exit data and barrier rows."""

    nodes: np.ndarray
    parent: np.ndarray
    cost: np.ndarray
    regions: list  # (polygon, A, b, exit_row)
    cbf: list  # (normals, offsets): h = n·x + q >= 0
    flags: np.ndarray
    node_added: np.ndarray
    exit_inset: np.ndarray | None = None  # (N,): δ_e,c by node, NaN at the root; None: 0 (paper)
    free_coverage: float = math.nan
    stats: dict | None = None


def _funnel_layout(tree: Tree, params: Params, space: FreeSpace, margin: float) -> _Layout:
    """Funnel cells of every edge, the goal cell, necks and densification (ALGORITHMS §11.5)."""
    map_ = tree.map
    tol, free_bounds, goal = map_.tol, space.bounds, map_.goal
    pieces = ObstaclePieces.from_obstacles(space.obstacles)
    nodes, parent = tree.nodes.copy(), tree.parent.copy()
    cost = np.array(tree.cost, float)
    local = params.cells == "funnel-local"
    children = np.flatnonzero(parent >= 0)
    blocked = children[~space.segments_free(nodes[children], nodes[parent[children]])]
    if len(blocked):  # (C1) rests on free edges: a corridor cannot be cut around an edge through an obstacle
        raise ArtifactError(
            f"tree edges are not free (child nodes {cell_list(blocked)}): funnel cells need "
            "collision-free edges; re-run rrtstar and simplify",
            field="nodes",
        )

    def region_of(i: int, j: int, all_nodes: np.ndarray) -> Region:
        start = edge_cell(all_nodes, i, j, free_bounds, tol) if local else None
        try:
            return funnel_region(pieces, free_bounds, all_nodes[[i, j]], margin, tol, start)
        except ValueError as exc:
            raise ArtifactError(f"cell of node {i}: {exc}", field="nodes") from exc

    insets = {}  # δ_e,c of every edge cell, by node
    usable = {}  # min(h*/2, δ_e,c/2): the τ_c Lemma 6's field gives each edge cell, by node
    capped = []

    def neck_of(region: Region, i: int, j: int, x_i: np.ndarray) -> NeckChoice:
        # §12.4: the inset that maximises τ_c = min(h*/2, δ_e,c/2), or the one the user fixed
        try:
            if params.exit_inset is None:
                return best_neck(region, x_i, nodes[j], regions[j], tol)
            room = INSET_LIMIT * depth(regions[j].A, regions[j].b, nodes[j])
            if params.exit_inset > room:
                capped.append(i)
            return neck_choice(region, x_i, nodes[j], regions[j], min(params.exit_inset, room), tol)
        except ValueError as exc:  # x_j lies inside its parent's cell (C2): a bug
            raise ArtifactError(f"cell of node {i}: {exc}", field="exit_inset") from exc

    def neck(region: Region, i: int, j: int, choice: NeckChoice | None = None) -> Region:
        choice = choice or neck_of(region, i, j, nodes[i])
        insets[i], usable[i] = choice.inset, choice.usable
        return choice.region

    goal_start = goal_cell(nodes, free_bounds, tol) if local else None
    regions = [funnel_region(pieces, free_bounds, goal[None, :], margin, tol, goal_start)]
    regions += [region_of(i, int(parent[i]), nodes) for i in range(1, len(nodes))]
    for i in np.argsort(cost, kind="stable")[1:]:  # parents before children: their final cells exist
        regions[i] = neck(regions[i], i, parent[i])

    # coverage of F_m, and densification (§11.5 step 3); the coverage of F is measured at the end
    free = space.component_of(goal)
    full_domain = coverage_domain(free, free_bounds, space.obstacles, margin)
    covered = cells_union(regions)
    domain, _ = reached_parts(full_domain, covered)  # the parts of F_m the tree's cells can reach
    domain_area = float(domain.area)
    uncovered = shapely.difference(domain, covered)
    # the uncovered part as separate pockets: a new cell only cuts the pockets it meets
    pockets = [[g, float(g.area), False] for g in shapely.get_parts(uncovered) if g.area > 0]
    before = 1.0 - sum(p[1] for p in pockets) / domain_area if domain_area > 0 else 1.0
    # the boundary of F_m, a hair thick: a pocket's boundary off it is where the pocket meets the cells
    domain_edge = shapely.buffer(domain.boundary, 1e3 * tol)
    shapely.prepare(domain_edge)
    reach = space.planning_space(None, goal, map_.diagonal)
    added = []

    trial = {}  # the band leaf band_leaf accepted last, with its built cell: (point, node, NeckChoice)

    def add_leaf(p: np.ndarray, n: int) -> shapely.Polygon:
        nonlocal nodes, parent, cost
        nodes = np.vstack([nodes, p])
        parent = np.append(parent, n)
        cost = np.append(cost, cost[n] + math.hypot(*(p - nodes[n])))
        i = len(nodes) - 1
        built = trial.pop("leaf", None)
        choice = built[2] if built and built[1] == n and np.array_equal(built[0], p) else None
        regions.append(neck(region_of(i, n, nodes) if choice is None else None, i, n, choice))
        added.append(i)
        return shapely.Polygon(regions[-1].polygon)

    def band_leaf(pocket: shapely.Geometry) -> tuple[np.ndarray, int] | None:
        # the first candidate whose cell keeps the floor, joined to the nearest of the nodes it
        # sees whose cell does (up to BAND_NODE_TRIES of them): a band cell that would lower the
        # plan's least τ_c is not built, and the next node, then the pocket's next candidate is tried
        candidates = band_candidates(pocket, offset)
        if refused and len(candidates):  # a refused leaf would be refused again: its nodes stay
            known = np.array(refused)
            candidates = candidates[~np.any(np.all(candidates[:, None, :] == known[None], axis=2), axis=1)]
        while len(candidates) and len(joinable):
            leaf = join_leaf(candidates, nodes, cost, near_wall, tol, joinable, nearest=True)
            if leaf is None:
                return None
            p, n = leaf
            tried = [n]
            while True:
                choice = neck_of(region_of(len(nodes), n, np.vstack([nodes, p])), len(nodes), n, p)
                if choice.usable >= floor:
                    trial["leaf"] = (p, n, choice)
                    return p, n
                others = np.setdiff1d(joinable, tried, assume_unique=True)
                other = (
                    join_leaf(p[None], nodes, cost, near_wall, tol, others, nearest=True)
                    if len(tried) < BAND_NODE_TRIES and len(others)
                    else None
                )
                if other is None:
                    break
                n = other[1]
                tried.append(n)
            refused.append(p)
            candidates = candidates[np.flatnonzero(np.all(candidates == p, axis=1))[0] + 1 :]
        return None

    allowed = (1.0 - params.coverage_target) * domain_area
    pockets = densify(
        pockets,
        allowed,
        params.max_added_nodes,
        lambda g: densify_leaf(g, nodes, cost, reach, tol, domain_edge),
        add_leaf,
    )
    uncovered_area = sum(p[1] for p in pockets)
    unreachable = [p for p in pockets if p[2]]
    if added:  # an added cell may reach into a part of F_m that no tree cell met: count that part too
        covered = cells_union(regions)
        final, _ = reached_parts(full_domain, covered)
        if final.area > domain_area * (1.0 + 1e-12):
            domain, domain_area = final, float(final.area)
            uncovered_area = float(shapely.difference(domain, covered).area)
    unreached_area = max(float(full_domain.area) - domain_area, 0.0)
    if unreached_area > NEGLIGIBLE_SHARE * max(float(full_domain.area), 1e-300):
        log.warning(
            "%.1f%% of the free space away from the walls (F_m, %.3g map units²) is cut off from every "
            "cell by passages narrower than %.3g, twice the wall margin (a robot keeping that margin cannot "
            "get there): coverage is of the rest; a smaller decompose.barrier_margin or a wider passage "
            "would join it",
            100 * unreached_area / full_domain.area,
            unreached_area,
            2 * margin,
        )
    after = 1.0 - uncovered_area / domain_area if domain_area > 0 else 1.0
    # F_m's densification is done: its shortfall is warned of here (the band's cells can reach into parts
    # of F_m past passages narrower than 2m without covering them, which the F warning below explains)
    if after < params.coverage_target:
        log.warning(
            "the cells cover %.1f%% of the free space away from the walls (F_m; target %.1f%%): %d pockets no node "
            "reaches with clearance%s",
            100 * after,
            100 * params.coverage_target,
            len(unreachable),
            " and the max_added_nodes limit was reached" if len(added) >= params.max_added_nodes else "",
        )
    # §12.7: the domain reaches the walls. The band within m of O stays outside every cell above;
    # leaves a band depth q = WALL_LEAF_DEPTH·m from O get cells that keep only min(m, s·d) = q/20
    # from the piece beside them, so densifying F with them leaves a band of about q/20
    in_fm = len(added)
    # ``covered`` is the union of every cell so far (recomputed above when leaves were added)
    whole_free = coverage_domain(free, free_bounds, space.obstacles, 0.0)
    reached_free, _ = reached_parts(whole_free, covered)
    free_area = float(reached_free.area)
    band = [
        [g, float(g.area), False] for g in shapely.get_parts(shapely.difference(reached_free, covered)) if g.area > 0
    ]
    free_before = 1.0 - sum(p[1] for p in band) / free_area if free_area > 0 else 1.0
    depth_q = WALL_LEAF_DEPTH * margin
    refused = []  # band leaves whose cells would have lowered the plan's least τ_c
    # band cells may not lower the least τ_c of the cells before them (Lemma 6's, which the
    # synthesis only raises): a cell that would is left out, and its part of the band uncovered
    floor = min(usable.values(), default=0.0)
    # τ_c ≤ δ_e,c/2 and the exit face holds x_j, so no band cell under a node shallower in its own
    # cell than 2·floor/INSET_LIMIT keeps the floor
    room = np.array([depth(regions[n].A, regions[n].b, nodes[n]) for n in range(len(nodes))])
    joinable = np.flatnonzero(INSET_LIMIT * room >= 2.0 * floor)
    if params.cover == "F":
        offset = shapely.boundary(coverage_domain(free, free_bounds, space.obstacles, depth_q))
        shapely.prepare(offset)
        near_wall = space.with_clearance(0.5 * depth_q)
        band = densify(
            band, (1.0 - params.coverage_target) * free_area, params.max_added_nodes - len(added), band_leaf, add_leaf
        )
    band_unreachable = sum(1 for p in band if p[2])
    free_after = 1.0 - sum(p[1] for p in band) / free_area if free_area > 0 else 1.0
    if len(added) > in_fm:  # the added cells may meet parts of F no cell met before: measure again
        covered = cells_union(regions)
        free_area, free_after, _ = reached_coverage(whole_free, covered)
        # the band cells reach into F_m too: its recorded coverage is of the final cells, as verify recomputes it
        domain_area, after, uncovered_area = reached_coverage(full_domain, covered)
    if free_after < params.coverage_target and params.cover == "F":
        # the part of F_m past passages narrower than 2m (warned above) is not a band the leaves can fill
        cut_off = unreached_area > NEGLIGIBLE_SHARE * max(free_area, 1e-300)
        why = (
            f"{100 * unreached_area / free_area:.1f}% of the free space lies past passages narrower than "
            f"{2 * margin:.3g} (twice the wall margin) that no tree edge crosses (a smaller "
            "decompose.barrier_margin would join it); the rest"
            if cut_off
            else "the rest"
        )
        log.warning(
            "the cells cover %.1f%% of the free space (of F; target %.1f%%): %s lies within the wall margin "
            "%.3g of an obstacle or a wall%s",
            100 * free_after,
            100 * params.coverage_target,
            why,
            margin,
            (
                f", in {band_unreachable} pockets no node reaches with clearance {0.5 * depth_q:.3g}"
                + (
                    f" by a cell that tolerates the plan's least position error {floor:.3g} ({len(refused)} such "
                    "cells were left out)"
                    if refused
                    else ""
                )
            )
            if band_unreachable
            else " (the max_added_nodes limit was reached)",
        )
    if capped:
        log.warning(
            "exit_inset %.4g capped in %d cells at %.0f%% of their exit point's depth in the parent cell "
            "(first: node %d)",
            params.exit_inset,
            len(capped),
            100 * INSET_LIMIT,
            capped[0],
        )
    exit_inset = np.array([math.nan] + [insets[i] for i in range(1, len(nodes))])
    cbf = []
    for r in regions:
        keep = np.arange(len(r.b)) != r.exit_row
        cbf.append((-r.A[keep], r.b[keep]))  # h_k = b_k − A_k·x >= 0 inside the cell
    node_added = np.zeros(len(nodes), bool)
    node_added[len(tree.nodes) :] = True
    stats = {
        "exit_inset_min": float(np.min(exit_inset[1:])) if len(nodes) > 1 else None,
        "exit_inset_median": float(np.median(exit_inset[1:])) if len(nodes) > 1 else None,
        "barrier_margin": margin,  # m of F_m: verify recomputes the coverage with it
        "necked_cells": [i for i, r in enumerate(regions) if r.necked],
        "free_coverage_before": before,
        "free_coverage_m": after,
        "free_coverage_f_before": free_before,
        "free_coverage": free_after,
        "band_leaves": len(added) - in_fm,
        "band_depth": depth_q,
        "band_unreachable_pockets": band_unreachable,
        "band_refused_leaves": len(refused),
        "band_tolerance_floor": floor,
        "added_nodes": len(added),
        "unreachable_pockets": len(unreachable),
        "uncovered_area": uncovered_area,
        "coverage_domain_area": domain_area,
        "unreached_area": unreached_area,
        "obstacle_pieces": len(pieces),
    }
    return _Layout(
        nodes,
        parent,
        cost,
        [(r.polygon, r.A, r.b, r.exit_row) for r in regions],
        cbf,
        np.zeros(len(nodes), np.int64),
        node_added,
        exit_inset,
        free_after,
        stats,
    )


# --------------------------------------------------------------------------- paper cells (ALGORITHMS §4)


def _paper_layout(tree: Tree, params: Params, space: FreeSpace, margin: float) -> _Layout:
    """The §4 cells (bisectors, exit half-plane, the bounds) with their barrier rows."""
    map_ = tree.map
    nodes, parent, samples = tree.nodes, tree.parent, tree.collision_samples
    tol, bounds = map_.tol, space.bounds
    n = len(nodes)
    if params.cbf_apex == "parent":
        log.warning(
            "cbf_apex=parent: the barrier and Lyapunov rows force a zero-margin LP (ALGORITHMS §4.5); "
            "synthesize certifies no cell whose wedge is zero at its exit point"
        )
    flags = np.zeros(n, np.int64)
    regions, cbf = [], []
    for c in range(n):
        if c == 0:
            polygon = goal_cell(nodes, bounds, tol)
            A, b = polygon_rows(polygon)
            if params.barrier == "corridor":
                normals, offsets, _ = corridor_rows(map_.goal[None, :], polygon, space.obstacles, margin)
            else:
                normals, offsets = goal_cbf_rows(map_.goal, samples, polygon, bounds, tol)
            exit_row = -1
        else:
            j = parent[c]
            polygon = edge_cell(nodes, c, j, bounds, tol)
            A, b = polygon_rows(polygon)
            if params.barrier == "corridor":
                normals, offsets, _ = corridor_rows(
                    nodes[[c, j]], polygon, space.obstacles, margin, walls=wall_rows(polygon, bounds, margin + tol)
                )
                on_edge = False
            else:
                normals, offsets, on_edge = cbf_rows(
                    nodes[c], nodes[j], samples, A, b, tol, apex=params.cbf_apex, sample_filter=params.cbf_filter
                )
            if on_edge:
                flags[c] |= CellFlag.SAMPLE_ON_EDGE
                log.warning("cell %d: a collision sample on the edge line was skipped", c)
            z = (nodes[c] - nodes[j]) / np.hypot(*(nodes[c] - nodes[j]))
            exit_row = exit_row_index(A, b, z, nodes[j], tol)  # edge_cell keeps the face: a ValueError is a bug
        regions.append((polygon, A, b, exit_row))
        cbf.append((normals, offsets))
    return _Layout(nodes, parent, np.array(tree.cost, float), regions, cbf, flags, np.zeros(n, bool), stats={})


# --------------------------------------------------------------------------- the stage


def run(tree: Tree, params: Params = Params(), progress: Callable[[int, int], None] | None = None) -> Cells:
    """Cut the free space into one convex cell per node of a (simplified) tree.

    Parameters
    ----------
    tree : Tree
        The simplified tree (node 0 at the goal) with its collision samples.
    params : Params
        Cell mode, barrier rows, margins and coverage target; a ``None`` barrier margin is
        ``0.01·D`` of the tree's map, a ``None`` exit inset derives from it.
    progress : callable, optional
        ``progress(done, total)`` every few cells.

    Returns
    -------
    Cells
        ``C = N`` cells (N including the nodes densification added); cell ``c`` belongs to
        node ``c`` (ALGORITHMS §4, §11).

    Raises
    ------
    ArtifactError
        Coincident nodes (the tree stages keep them distinct).
    """
    map_ = tree.map
    tol = map_.tol
    nodes = tree.nodes
    if len(nodes) > 1:
        order = np.lexsort((nodes[:, 1], nodes[:, 0]))
        gaps = np.hypot(*np.diff(nodes[order], axis=0).T)
        if np.any(gaps <= tol):
            k = order[int(np.argmax(gaps <= tol))]
            raise ArtifactError(f"coincident tree nodes near {nodes[k].tolist()}", field="nodes")
    space = FreeSpace.from_map(map_)
    margin = barrier_margin(params.barrier_margin, map_.diagonal)
    funnel = params.cells != "paper"
    layout = (_funnel_layout if funnel else _paper_layout)(tree, params, space, margin)
    nodes, parent, flags = layout.nodes, layout.parent, layout.flags
    n = len(nodes)
    landmarks = map_.landmarks
    # Blind spots: the free points of the map stage's coverage grid (spacing D/100) that see
    # fewer than 2 landmarks. A cell holding one cannot be driven by bearings everywhere.
    sight = space.visibility_regions(landmarks)
    grid, counts = landmark_coverage(map_, space)
    blind = grid[counts < 2]
    exit_point = np.zeros((n, 2))
    exit_dir = np.zeros((n, 2))
    used = np.zeros((n, len(landmarks)), bool)
    fixed = np.zeros(n, np.int64)
    s_min = np.zeros(n)
    s_max = np.zeros(n)
    anchors = [map_.goal[None, :]] + [nodes[[c, parent[c]]] for c in range(1, n)]
    witnesses = [witness_points(space, r[0], anchors[c]) for c, r in enumerate(layout.regions)]
    # every cell's witnesses against every landmark in one pass per landmark; the anchors are rows of them
    wo = np.concatenate([[0], np.cumsum([len(w) for w in witnesses])]).tolist()
    flat = np.concatenate(witnesses)
    if funnel:  # cells at positive distance from O: the regions answer as the segment test does
        seen_all = seen_from(sight, flat)
    else:  # §4 cells touch O (radius 0: on P_raw itself): the exact segment test, from just off the wall
        seen_all = segments_seen(space, flat, landmarks, from_boundary=True)
        ends = np.concatenate(anchors)
        seen_ends = segments_seen(space, ends, landmarks)
        eo = np.concatenate([[0], np.cumsum([len(a) for a in anchors])]).tolist()
    for c, (polygon, A, b, _) in enumerate(layout.regions):
        if c > 0:
            j = parent[c]
            exit_point[c] = nodes[j]
            exit_dir[c] = (nodes[c] - nodes[j]) / np.hypot(*(nodes[c] - nodes[j]))
        seen = seen_all[wo[c] : wo[c + 1]]
        if funnel:
            at_anchor = (witnesses[c][:, None, :] == anchors[c][None, :, :]).all(axis=2).any(axis=1)
            from_anchors = seen[at_anchor]
        else:
            from_anchors = seen_ends[eo[c] : eo[c + 1]]
        chosen, few = cell_landmarks(landmarks, seen, from_anchors, anchors[c], params.n_landmarks)
        if few:
            flags[c] |= CellFlag.FEW_LANDMARKS
        if np.any(np.all(blind @ A.T <= b + tol, axis=1)):
            flags[c] |= CellFlag.BLIND_SPOT
        used[c, chosen] = True
        fixed[c], s_min[c], s_max[c], flag = fixed_landmark(landmarks, chosen, polygon, tol)
        flags[c] |= flag
        if progress is not None and (c % 16 == 15 or c == n - 1):
            progress(c + 1, n)
    polygons = [r[0] for r in layout.regions]
    counts = np.array([len(p) for p in polygons])
    cbf_counts = np.array([len(q) for _, q in layout.cbf])
    stats = {
        "cells": n,
        "certificate": "funnel" if funnel else "paper",
        "vertices": int(counts.sum()),
        "cbf_rows": int(cbf_counts.sum()),
        "cells_without_cbf": int(np.count_nonzero(cbf_counts[1:] == 0)),
        **(layout.stats or {}),
    }
    for flag in CellFlag:
        if flag != CellFlag.NONE:
            stats[flag.name.lower()] = np.flatnonzero(flags & flag).tolist()
    for flag, what in (
        (CellFlag.FEW_LANDMARKS, "no 2 landmarks are visible from the whole free part (topped up with the nearest)"),
        (CellFlag.BLIND_SPOT, "free points that see fewer than 2 landmarks: a robot cannot locate itself there"),
    ):
        if stats[flag.name.lower()]:
            flagged = stats[flag.name.lower()]
            log.warning("%s: %s: %s", plural(len(flagged), "cell"), what, cell_list(flagged))
    return Cells(
        map=map_,
        nodes=nodes,
        parent=parent,
        collision_samples=tree.collision_samples,
        cell_node=np.arange(n),
        cell_A=np.concatenate([r[1] for r in layout.regions]),
        cell_b=np.concatenate([r[2] for r in layout.regions]),
        cell_row_offsets=np.concatenate([[0], np.cumsum(counts)]),
        cell_vertices=np.concatenate(polygons),
        cell_vertex_offsets=np.concatenate([[0], np.cumsum(counts)]),
        exit_point=exit_point,
        exit_dir=exit_dir,
        cbf_A=np.concatenate([r[0] for r in layout.cbf]) if layout.cbf else np.zeros((0, 2)),
        cbf_b=np.concatenate([r[1] for r in layout.cbf]) if layout.cbf else np.zeros(0),
        cbf_offsets=np.concatenate([[0], np.cumsum(cbf_counts)]),
        cell_landmarks=used,
        fixed_landmark=fixed,
        s_min=s_min,
        s_max=s_max,
        cell_flags=flags,
        certificate="funnel" if funnel else "paper",
        cell_exit_row=np.array([r[3] for r in layout.regions], np.int64),
        cell_rank=layout.cost,
        exit_inset=np.where(np.arange(n) == 0, math.nan, 0.0) if layout.exit_inset is None else layout.exit_inset,
        node_added=layout.node_added,
        free_coverage=layout.free_coverage,
        lookahead=getattr(map_, "lookahead", 0.0),
        stats=stats,
    )


def summary(cells: Cells) -> str:
    """One line: cells, barrier rows and flagged cells."""
    text = f"{plural(cells.n_cells, 'cell')}, {plural(len(cells.cbf_b), 'barrier row')}"
    bare = cells.stats.get("cells_without_cbf", 0)
    if bare:
        text += f" ({plural(bare, 'cell')} without one)"
    few = np.count_nonzero(cells.cell_flags & CellFlag.FEW_LANDMARKS)
    if few:
        text += f"; {plural(few, 'cell')} topped up with landmarks not visible everywhere"
    blind = cells.flagged(CellFlag.BLIND_SPOT)
    if blind:
        text += f"; blind spots (< 2 landmarks in sight) in cells {cell_list(blind)}"
    return text


def problems(cells: Cells) -> list[verdicts.Problem]:
    """Why the cells are not usable (a list of :class:`~bearnav_cli.verdicts.Problem`, worst first): no route
    (the tree is only its root, leaving out the nodes added to cover the free space), then blind-spot cells."""
    return verdicts.cell_problems(cells)
