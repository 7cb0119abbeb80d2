"""Funnel cells: obstacle-free convex cells whose exits land in their parents (ALGORITHMS §11.1, §11.5).

A funnel cell of the tree edge ``[x_i, x_j]`` is the largest convex region around the edge that
the corridor rows allow: one row per convex obstacle piece (a convex part of ``O``, or a boundary
edge of a non-convex part) that a spatial index says can reach it, one per wall of ``B_r``, and
the exit row ``z·(x − x_j) ≥ 0``. When its exit face is not inside the parent cell eroded by the
exit inset ``δ_e``, two neck rows through the ends of ``(P_j ⊖ δ_e) ∩ {V = 0}`` narrow it (§11.5
step 2). Where the cells leave part of ``F`` uncovered, :func:`densify` adds leaf nodes there.

Everything here is geometry on numpy arrays and shapely 2; :mod:`bearnav_cli.stages.decompose`
assembles the cells.
Every name is re-exported here; the modules, each with one job:

- :mod:`~bearnav_cli.funnel.region` — the corridor region of an edge (obstacle pieces, walls, exit row);
- :mod:`~bearnav_cli.funnel.neck` — neck rows and each cell's exit inset;
- :mod:`~bearnav_cli.funnel.coverage` — ``F_m`` and the parts of it the cells reach;
- :mod:`~bearnav_cli.funnel.densify` — leaves in the pockets the cells leave (``F_m``, then the band along ``O``);
- :mod:`~bearnav_cli.funnel.tolerance` — exit faces, their sinks and the tolerances ``δ_c``, ``τ_c``, ``δ*``.
"""

from bearnav_cli.funnel.coverage import coverage_domain, reached_parts
from bearnav_cli.funnel.densify import (
    BAND_CORNER_TURN,
    BAND_NODE_TRIES,
    DENSIFY_BATCH,
    DENSIFY_GRID,
    DENSIFY_NEAREST,
    WALL_LEAF_DEPTH,
    band_candidates,
    cells_union,
    densify,
    densify_leaf,
    join_leaf,
    pocket_mouth,
    reached_coverage,
)
from bearnav_cli.funnel.neck import (
    INSET_LIMIT,
    INSET_SAMPLES,
    NECK_ANGLE,
    NeckChoice,
    best_neck,
    depth,
    exit_interval,
    neck_choice,
    neck_rows,
    necked,
)
from bearnav_cli.funnel.region import (
    PIECE_BATCH,
    ROW_SHARE,
    ObstaclePieces,
    Region,
    exit_row_index,
    funnel_region,
    inset_walls,
)
from bearnav_cli.funnel.tolerance import (
    cell_tolerance,
    exit_face,
    exit_sink,
    exit_sinks,
    plan_tolerance_of,
    usable_tolerances,
)

__all__ = [
    "BAND_CORNER_TURN",
    "BAND_NODE_TRIES",
    "DENSIFY_BATCH",
    "DENSIFY_GRID",
    "DENSIFY_NEAREST",
    "WALL_LEAF_DEPTH",
    "band_candidates",
    "cells_union",
    "densify",
    "densify_leaf",
    "join_leaf",
    "pocket_mouth",
    "reached_coverage",
    "INSET_LIMIT",
    "INSET_SAMPLES",
    "NECK_ANGLE",
    "PIECE_BATCH",
    "ROW_SHARE",
    "NeckChoice",
    "ObstaclePieces",
    "Region",
    "best_neck",
    "cell_tolerance",
    "coverage_domain",
    "depth",
    "exit_face",
    "exit_interval",
    "exit_sink",
    "exit_sinks",
    "exit_row_index",
    "funnel_region",
    "inset_walls",
    "neck_choice",
    "neck_rows",
    "necked",
    "plan_tolerance_of",
    "reached_parts",
    "usable_tolerances",
]
