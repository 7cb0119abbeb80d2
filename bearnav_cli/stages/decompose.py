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

from bearnav_cli.barriers import cbf_rows, corridor_rows, goal_cbf_rows, wall_rows
from bearnav_cli.datatypes import CellFlag, Cells, Tree, cell_list
from bearnav_cli.errors import ArtifactError, InvalidParamsError
from bearnav_cli.geometry import (
    DEFAULT_CLEARANCE,
    FreeSpace,
    box_polygon,
    clip,
    landmark_coverage,
    point_polygon_distance,
    polygon_rows,
)

VERSION = 2
log = logging.getLogger(__name__)

#: Re-exported: the cell and barrier helpers are part of this stage's interface.
__all__ = ["box_polygon", "cbf_rows", "clip", "corridor_rows", "goal_cbf_rows", "point_polygon_distance",
           "polygon_rows", "wall_rows", "Params", "run", "summary"]  # fmt: skip

BARRIERS = ("corridor", "wedge")
BISECTOR_RULES = ("crossing", "parent")
CBF_APEXES = ("child", "parent")
CBF_FILTERS = ("both", "projection", "cell")


@dataclass(frozen=True)
class Params:
    """Parameters of the decomposition (ALGORITHMS §4, §5.4).

    Attributes
    ----------
    bisector_rule : {"crossing", "parent"}
        ``crossing`` drops every bisector that crosses the edge (the authors' code);
        ``parent`` drops only the parent's (paper B's text; can cut the edge, warns).
    cbf_apex : {"child", "parent"}
        Apex of the barrier wedge; ``parent`` reproduces the paper's degenerate LP (warns).
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
        ``corridor`` only: each row is moved ``min(margin, d/2)`` toward the edge (``d`` the
        piece's distance from it), so the safe set keeps that distance from the obstacles
        (map units); ``None`` means ``0.01·D``.
    """

    bisector_rule: str = "crossing"
    cbf_apex: str = "child"
    cbf_filter: str = "both"
    n_landmarks: int = 4
    barrier: str = "corridor"
    barrier_margin: float | None = None

    def __post_init__(self) -> None:
        if self.barrier_margin is not None and not (self.barrier_margin >= 0 and math.isfinite(self.barrier_margin)):
            raise InvalidParamsError(f"must be zero or positive, got {self.barrier_margin}", field="barrier_margin")
        for name, allowed in (
            ("barrier", BARRIERS),
            ("bisector_rule", BISECTOR_RULES),
            ("cbf_apex", CBF_APEXES),
            ("cbf_filter", CBF_FILTERS),
        ):
            if getattr(self, name) not in allowed:
                value = getattr(self, name)
                raise InvalidParamsError(f"must be one of {', '.join(allowed)}, got {value!r}", field=name)
        if not isinstance(self.n_landmarks, int) or self.n_landmarks < 2:
            raise InvalidParamsError(f"must be an integer of at least 2, got {self.n_landmarks!r}", field="n_landmarks")


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


def edge_cell(nodes: np.ndarray, i: int, j: int, bounds: np.ndarray, tol: float, rule: str) -> np.ndarray:
    """The edge cell ``X_ij`` of ALGORITHMS §4.1 as a CCW polygon, shape (p, 2)."""
    xi, xj = nodes[i], nodes[j]
    z = (xi - xj) / np.hypot(*(xi - xj))
    polygon = clip(box_polygon(bounds), -z, -(z @ xj), tol)  # exit half-plane z·(x − x_j) >= 0
    skip = np.zeros(len(nodes), bool)
    skip[j] = True
    if rule == "crossing":
        # drop every bisector that crosses [x_i, x_j]: x_j not strictly inside H_ik
        skip |= np.hypot(*(nodes - xj).T) <= np.hypot(*(xi - xj)) + tol
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


# --------------------------------------------------------------------------- landmarks


def cell_landmarks(
    space: FreeSpace,
    landmarks: np.ndarray,
    polygon: np.ndarray,
    anchors: np.ndarray,
    n_landmarks: int,
) -> tuple[np.ndarray, bool]:
    """The landmarks a cell's controller uses (ALGORITHMS §5.4).

    Parameters
    ----------
    space : FreeSpace
    landmarks : ndarray, shape (L, 2)
    polygon : ndarray, shape (p, 2)
        The cell.
    anchors : ndarray, shape (a, 2)
        ``x_i, x_j`` of an edge cell, or ``g`` for the goal cell; their mean is the
        point the landmarks are ranked by distance from.
    n_landmarks : int

    Returns
    -------
    chosen : ndarray of int64, shape (n,)
        Landmark indices, nearest first, ``2 <= n <= n_landmarks``.
    flagged : bool
        True when fewer than 2 landmarks are visible from the whole free part (the choice
        was then topped up).
    """
    free_part = shapely.difference(shapely.Polygon(polygon), space.obstacles)
    witnesses = [anchors]
    for part in shapely.get_parts(free_part):
        if isinstance(part, shapely.Polygon) and not part.is_empty:
            witnesses.append(np.asarray(part.exterior.coords)[:-1])
            witnesses.extend(np.asarray(h.coords)[:-1] for h in part.interiors)
    points = np.unique(np.concatenate(witnesses), axis=0)
    n_lm = len(landmarks)
    pairs_p = np.repeat(points, n_lm, axis=0)
    pairs_l = np.tile(landmarks, (len(points), 1))
    seen = space.visible(pairs_p, pairs_l, from_boundary=True).reshape(len(points), n_lm)
    centre = anchors.mean(axis=0)
    dist = np.hypot(*(landmarks - centre).T)
    order = np.lexsort((np.arange(n_lm), dist))
    everywhere = seen.all(axis=0)
    chosen = [k for k in order if everywhere[k]][:n_landmarks]
    flagged = len(chosen) < 2
    if flagged:
        ends = space.visible(np.repeat(anchors, n_lm, axis=0), np.tile(landmarks, (len(anchors), 1)))
        from_ends = ends.reshape(len(anchors), n_lm).all(axis=0)
        for pool in ([k for k in order if from_ends[k]], list(order)):
            for k in pool:
                if len(chosen) >= 2:
                    break
                if k not in chosen:
                    chosen.append(k)
    return np.array(chosen, np.int64), flagged


def fixed_landmark(
    landmarks: np.ndarray, chosen: np.ndarray, polygon: np.ndarray, tol: float
) -> tuple[int, float, float, CellFlag]:
    """The fixed landmark ``f`` of a cell and the exact ``s_min``, ``s_max`` (ALGORITHMS §5.5).

    Returns
    -------
    f : int
        Landmark index.
    s_min, s_max : float
        ``dist(l_f, X_c)`` (0 if inside) and ``max_q ‖l_f − v_q‖``, map units.
    flag : CellFlag
        ``DEGENERATE_RISK`` or ``LANDMARK_INSIDE`` when rules 2 or 1 could not be met.
    """
    A, b = polygon_rows(polygon)
    s_min = np.array([point_polygon_distance(landmarks[k], polygon, A, b) for k in chosen])
    s_max = np.array([np.max(np.hypot(*(polygon - landmarks[k]).T)) for k in chosen])
    outside = s_min > tol
    clear = np.zeros(len(chosen), bool)
    for a, f in enumerate(chosen):
        if not outside[a]:
            continue
        ok = True
        for k in chosen:
            if k == f:
                continue
            d = landmarks[k] - landmarks[f]
            side = d[0] * (polygon[:, 1] - landmarks[f][1]) - d[1] * (polygon[:, 0] - landmarks[f][0])
            scale = tol * np.hypot(*d)
            if not (np.all(side > scale) or np.all(side < -scale)):
                ok = False
                break
        clear[a] = ok
    ratio = np.where(outside, s_max / np.where(outside, s_min, 1.0), np.inf)
    for pool, flag in ((clear, CellFlag.NONE), (outside, CellFlag.DEGENERATE_RISK)):
        if pool.any():
            idx = np.flatnonzero(pool)
            best = idx[np.lexsort((chosen[idx], ratio[idx]))[0]]
            return int(chosen[best]), float(s_min[best]), float(s_max[best]), flag
    best = int(np.lexsort((chosen, s_max))[0])
    return int(chosen[best]), 0.0, float(s_max[best]), CellFlag.LANDMARK_INSIDE


# --------------------------------------------------------------------------- the stage


def run(tree: Tree, params: Params = Params(), progress: Callable[[int, int], None] | None = None) -> Cells:
    """Cut the bounds into one convex cell per node of a (simplified) tree.

    Parameters
    ----------
    tree : Tree
        The simplified tree (node 0 at the goal) with its collision samples.
    params : Params
    progress : callable, optional
        ``progress(done, total)`` every few cells.

    Returns
    -------
    Cells
        ``C = N`` cells; cell ``c`` belongs to node ``c`` (ALGORITHMS §4).

    Raises
    ------
    ArtifactError
        Coincident nodes (the tree stages keep them distinct).
    """
    map_ = tree.map
    nodes, parent, samples = tree.nodes, tree.parent, tree.collision_samples
    tol, bounds = map_.tol, map_.bounds
    n = len(nodes)
    if n > 1:
        order = np.lexsort((nodes[:, 1], nodes[:, 0]))
        gaps = np.hypot(*np.diff(nodes[order], axis=0).T)
        if np.any(gaps <= tol):
            k = order[int(np.argmax(gaps <= tol))]
            raise ArtifactError(f"coincident tree nodes near {nodes[k].tolist()}", field="nodes")
    if params.bisector_rule == "parent":
        log.warning("bisector_rule=parent: a third node's bisector can cut an edge out of its cell")
    if params.cbf_apex == "parent":
        log.warning("cbf_apex=parent: the barrier and Lyapunov rows force a zero-margin LP (ALGORITHMS §4.5)")
    space = FreeSpace.from_map(map_)
    landmarks = map_.landmarks
    # Blind spots: the free points of the map stage's coverage grid (spacing D/100) that see
    # fewer than 2 landmarks. A cell holding one cannot be driven by bearings everywhere.
    grid, counts = landmark_coverage(map_, space)
    blind = grid[counts < 2]
    margin = DEFAULT_CLEARANCE * map_.diagonal if params.barrier_margin is None else params.barrier_margin
    polygons, rows, cbf_n, cbf_q = [], [], [], []
    exit_point = np.zeros((n, 2))
    exit_dir = np.zeros((n, 2))
    used = np.zeros((n, len(landmarks)), bool)
    fixed = np.zeros(n, np.int64)
    s_min = np.zeros(n)
    s_max = np.zeros(n)
    flags = np.zeros(n, np.int8)
    for c in range(n):
        if c == 0:
            polygon = goal_cell(nodes, bounds, tol)
            A, b = polygon_rows(polygon)
            if params.barrier == "corridor":
                normals, offsets, _ = corridor_rows(map_.goal[None, :], polygon, space.obstacles, margin)
            else:
                normals, offsets = goal_cbf_rows(map_.goal, samples, polygon, bounds, tol)
            anchors = map_.goal[None, :]
        else:
            j = parent[c]
            polygon = edge_cell(nodes, c, j, bounds, tol, params.bisector_rule)
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
            exit_point[c] = nodes[j]
            exit_dir[c] = (nodes[c] - nodes[j]) / np.hypot(*(nodes[c] - nodes[j]))
            anchors = np.stack([nodes[c], nodes[j]])
        chosen, few = cell_landmarks(space, landmarks, polygon, anchors, params.n_landmarks)
        if few:
            flags[c] |= CellFlag.FEW_LANDMARKS
        if np.any(np.all(blind @ A.T <= b + tol, axis=1)):
            flags[c] |= CellFlag.BLIND_SPOT
        used[c, chosen] = True
        fixed[c], s_min[c], s_max[c], flag = fixed_landmark(landmarks, chosen, polygon, tol)
        flags[c] |= flag
        polygons.append(polygon)
        rows.append((A, b))
        cbf_n.append(normals)
        cbf_q.append(offsets)
        if progress is not None and (c % 16 == 15 or c == n - 1):
            progress(c + 1, n)
    counts = np.array([len(p) for p in polygons])
    cbf_counts = np.array([len(q) for q in cbf_q])
    stats = {
        "cells": n,
        "vertices": int(counts.sum()),
        "cbf_rows": int(cbf_counts.sum()),
        "cells_without_cbf": int(np.count_nonzero(cbf_counts[1:] == 0)),
    }
    for flag in CellFlag:
        if flag != CellFlag.NONE:
            stats[flag.name.lower()] = np.flatnonzero(flags & flag).tolist()
    for flag, what in (
        (CellFlag.FEW_LANDMARKS, "no 2 landmarks are visible from the whole free part (topped up with the nearest)"),
        (CellFlag.BLIND_SPOT, "free points that see fewer than 2 landmarks: a robot cannot locate itself there"),
    ):
        if stats[flag.name.lower()]:
            log.warning("%d cells: %s: %s", len(stats[flag.name.lower()]), what, cell_list(stats[flag.name.lower()]))
    return Cells(
        map=map_,
        nodes=nodes,
        parent=parent,
        collision_samples=samples,
        cell_node=np.arange(n),
        cell_A=np.concatenate([r[0] for r in rows]),
        cell_b=np.concatenate([r[1] for r in rows]),
        cell_row_offsets=np.concatenate([[0], np.cumsum(counts)]),
        cell_vertices=np.concatenate(polygons),
        cell_vertex_offsets=np.concatenate([[0], np.cumsum(counts)]),
        exit_point=exit_point,
        exit_dir=exit_dir,
        cbf_A=np.concatenate(cbf_n) if cbf_n else np.zeros((0, 2)),
        cbf_b=np.concatenate(cbf_q) if cbf_q else np.zeros(0),
        cbf_offsets=np.concatenate([[0], np.cumsum(cbf_counts)]),
        cell_landmarks=used,
        fixed_landmark=fixed,
        s_min=s_min,
        s_max=s_max,
        cell_flags=flags,
        stats=stats,
    )


def summary(cells: Cells) -> str:
    """One line: cells, barrier rows and flagged cells."""
    text = f"{cells.n_cells} cells, {len(cells.cbf_b)} barrier rows"
    bare = cells.stats.get("cells_without_cbf", 0)
    if bare:
        text += f" ({bare} cells without one)"
    few = np.count_nonzero(cells.cell_flags & CellFlag.FEW_LANDMARKS)
    if few:
        text += f"; {few} cells topped up with landmarks not visible everywhere"
    blind = cells.flagged(CellFlag.BLIND_SPOT)
    if blind:
        text += f"; blind spots (< 2 landmarks in sight) in cells {cell_list(blind)}"
    return text
