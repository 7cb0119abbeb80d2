"""What a robot installs: numpy only, next to ``plan.npz`` (DESIGN §2, §6). This is the robot's one import.

- :mod:`~bearnav_cli.runtime.plan_arrays` — the run-time view of a plan (:class:`PlanArrays`);
- :mod:`~bearnav_cli.runtime.bearing` — measurements, field of view, bearing reconstruction (§6);
- :mod:`~bearnav_cli.runtime.cell_policy` — which cell's controller a robot uses (§7.3, §11.3);
- :mod:`~bearnav_cli.runtime.estimate` — the fix and its fusion with odometry;
- :mod:`~bearnav_cli.runtime.step` — one control step for ``R`` robots (:func:`control`);
- :mod:`~bearnav_cli.runtime.controller` — :class:`Controller`, one robot at camera rate;
- :mod:`~bearnav_cli.runtime.camera` — AprilTag detections in an image to world bearings and heading
  (:func:`observe`; ``docs/camera.md``).

``from bearnav_cli.runtime import Controller`` is all a robot needs; ``bearnav simulate`` uses the
same step.
"""

from bearnav_cli.runtime import bearing, camera
from bearnav_cli.runtime.camera import Detection, Intrinsics, Mount, Observation, TagMap, heading_from_tag, observe
from bearnav_cli.runtime.cell_policy import (
    affine_field,
    apply_gain,
    approach_target,
    barrier_values,
    contains,
    displacement,
    field,
    funnel_update,
    in_safe_set,
    least_rank_cell,
    locate,
    lyapunov,
    nearest_node,
    segments_clear,
    switch,
    update,
    voronoi_owner,
)
from bearnav_cli.runtime.controller import Controller
from bearnav_cli.runtime.estimate import Estimate, Fix, fuse, measure
from bearnav_cli.runtime.plan_arrays import RUNTIME_KEYS, PlanArrays, ring_edges, tree_costs
from bearnav_cli.runtime.step import (
    DYNAMICS,
    MEASUREMENTS,
    ControlOutput,
    ControlSettings,
    ControlState,
    control,
    timing,
)

__all__ = [
    "Controller", "ControlOutput", "ControlSettings", "ControlState", "DYNAMICS", "Detection", "Estimate", "Fix",
    "Intrinsics", "MEASUREMENTS", "Mount", "Observation", "PlanArrays", "TagMap", "camera", "heading_from_tag",
    "observe", "RUNTIME_KEYS", "affine_field", "apply_gain", "approach_target", "barrier_values", "bearing",
    "contains", "control", "displacement", "field", "funnel_update", "fuse", "in_safe_set", "least_rank_cell",
    "locate", "lyapunov", "measure", "nearest_node", "ring_edges", "segments_clear", "switch", "timing",
    "tree_costs", "update", "voronoi_owner",
]  # fmt: skip
