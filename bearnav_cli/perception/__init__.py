"""Perception coverage: where a camera looking along the plan's field gets a usable fix (issue 11, part 2).

The **perception rule** at a point ``x`` (docs/algorithms.md, "Perception coverage and tag
placement"): the camera looks where the robot drives there, and the tags it sees give a fix the
runtime would use, noise-free, with an acceptable predicted error. Concretely, with the runtime's
own code (:mod:`bearnav_cli.runtime`):

1. **Heading** (:func:`camera_headings`). Inside the certified domain ``D`` the robot follows the
   field ``u(x) = a_c − M_c x`` of the containing cell of least rank (ALGORITHMS §11.3,
   ``cell_policy.least_rank_cell``); the camera looks along ``u(x)`` (the unicycle turns first, so
   along the field). Outside ``D`` the robot drives straight to the node of
   ``cell_policy.approach_target`` (ALGORITHMS §11.5 step 4), and the camera looks that way.
2. **Visible tags** (:func:`visible_landmarks`, ALGORITHMS §6.1): in the field of view
   (``bearing.in_field_of_view`` on the true direction), within range (``bearing.in_range``) and in
   line of sight through the raw obstacles (``FreeSpace.visibility_regions``, as ``simulate`` does).
3. **Usable fix** (:func:`fix_quality`): the runtime's ``lsq`` fix of the exact bearings
   (``bearing.reconstruct(..., method="lsq", min_spread=θ_min)``) is usable: two or more tags,
   spread by ``λ_min(Σ P_k) ≥ 1 − cos θ_min`` (ALGORITHMS §6.2). Its predicted error is the
   runtime's error bound ``3·sqrt(bearing.fix_variance(..., σ))`` (map units; 0 noise-free,
   ``inf`` without a usable fix).
4. With an **error target** ``E`` the rule also needs predicted error ``≤ E``.

:func:`perception_coverage` evaluates the rule on a grid over ``D`` (the union of the plan's cells)
and over the free space ``F`` and returns a :class:`PerceptionCoverage`; ``plot.plot_perception``
draws it. Before a plan there is no field and the heading is free: :func:`heading_coverage` gives,
over ``F``, where some heading and where every heading of the camera passes steps 2 and 3 (a
:class:`HeadingCoverage`, ``bearnav map --fov``). Nothing here prints, plots or writes files.
Every name is re-exported here; the modules, each with one job:

- :mod:`~bearnav_cli.perception.grid` — the camera's parameters, the evaluation grid, step 1 (headings);
- :mod:`~bearnav_cli.perception.rule` — steps 2 to 4 and the coverage of a plan;
- :mod:`~bearnav_cli.perception.headings` — before a plan: some heading, every heading.
"""

from bearnav_cli.perception.grid import (
    GRID_CELLS,
    MAX_GRID_POINTS,
    EvaluationGrid,
    camera_headings,
    check_params,
    evaluation_grid,
)
from bearnav_cli.perception.headings import HeadingCoverage, heading_coverage
from bearnav_cli.perception.rule import (
    PerceptionCoverage,
    evaluate,
    fix_quality,
    perception_coverage,
    visible_landmarks,
)

__all__ = [
    "GRID_CELLS",
    "MAX_GRID_POINTS",
    "EvaluationGrid",
    "HeadingCoverage",
    "PerceptionCoverage",
    "camera_headings",
    "check_params",
    "evaluation_grid",
    "evaluate",
    "fix_quality",
    "heading_coverage",
    "perception_coverage",
    "visible_landmarks",
]
