"""What a robot installs: numpy only, next to ``plan.npz`` (DESIGN §2, §6). This is the robot's one import.

- :mod:`~bearnav_cli.runtime.plan_arrays` — the run-time view of a plan (:class:`PlanArrays`);
- :mod:`~bearnav_cli.runtime.plan_file` — the one loader of ``plan.npz`` (:func:`load_plan`: file, manifest,
  entries, content hash), with the checks of :mod:`~bearnav_cli.runtime.invariants` the CLI's loader shares;
- :mod:`~bearnav_cli.runtime.bearing` — measurements, field of view, bearing reconstruction (§6);
- :mod:`~bearnav_cli.runtime.cell_policy` — which cell's controller a robot uses (§7.3, §11.3);
- :mod:`~bearnav_cli.runtime.bounded` — convex sets that hold the robot (ALGORITHMS §12.2);
- :mod:`~bearnav_cli.runtime.look_bound` — the static bound ``ε(x, S)`` of one look (§12.2, §12.5);
- :mod:`~bearnav_cli.runtime.estimate` — the fix and its fusion with odometry, and the estimate sets;
- :mod:`~bearnav_cli.runtime.robot` — the robot's parameters (the map's ``robot:`` section) and the
  look-ahead point of a unicycle (ALGORITHMS §12.6, Lemma 7);
- :mod:`~bearnav_cli.runtime.settings` — the step's constants (:class:`ControlSettings`), memory
  (:class:`ControlState`) and output (:class:`ControlOutput`);
- :mod:`~bearnav_cli.runtime.unicycle`, :mod:`~bearnav_cli.runtime.looking`, :mod:`~bearnav_cli.runtime.safety` —
  the unicycle's, looking's and safety's rules of the step;
- :mod:`~bearnav_cli.runtime.step` — one control step for ``R`` robots (:func:`control`);
- :mod:`~bearnav_cli.runtime.controller` — :class:`Controller`, one robot at camera rate;
- :mod:`~bearnav_cli.runtime.certificate` — the one re-check of a cell's certificate at its vertices (ALGORITHMS §8);
- :mod:`~bearnav_cli.runtime.camera` — AprilTag detections in an image to world bearings and heading
  (:func:`observe`; ``docs/camera.md``), with the camera's intrinsics and mount in
  :mod:`~bearnav_cli.runtime.camera_model`.

``from bearnav_cli.runtime import Controller`` is all a robot needs; ``bearnav simulate`` uses the
same step.
"""

from bearnav_cli.runtime.lazy import lazy_names

#: Where each name of ``__all__`` is defined: the submodules are imported when a name is first used
#: (PEP 562), so that reading ``runtime.schema`` (every artifact load) does not import the controller.
_ORIGIN = {
    **dict.fromkeys(("Detection", "Observation", "TagMap", "heading_from_tag", "observe"), "camera"),
    **dict.fromkeys(("Intrinsics", "Mount"), "camera_model"),
    **dict.fromkeys(("affine_field", "apply_gain", "approach_target", "barrier_values", "contains", "displacement",
                     "field", "funnel_update", "in_safe_set", "least_rank_cell", "least_rank_cell_holding", "locate",
                     "nearest_node", "switch", "update", "voronoi_owner"), "cell_policy"),
    "segments_clear": "sight",
    "Controller": "controller",
    **dict.fromkeys(("Estimate", "Fix", "SetEstimate", "bounded_update", "fuse", "measure"), "estimate"),
    **dict.fromkeys(("RUNTIME_KEYS", "PlanArrays", "ring_edges", "tree_costs"), "plan_arrays"),
    **dict.fromkeys(("ROBOT_DEFAULTS", "lookahead_command", "lookahead_point"), "robot"),
    **dict.fromkeys(("DYNAMICS", "ESTIMATORS", "MEASUREMENTS"), "defaults"),
    **dict.fromkeys(("ControlOutput", "ControlSettings", "ControlState", "timing"), "settings"),
    **dict.fromkeys(("bounded_control", "control"), "step"),
}  # fmt: skip
#: The submodules, also attributes of the package once imported (``runtime.step``, ``runtime.bearing``).
_SUBMODULES = (
    "bearing",
    "bounded",
    "camera",
    "camera_model",
    "cell_policy",
    "certificate",
    "controller",
    "defaults",
    "estimate",
    "invariants",
    "looking",
    "pairs",
    "plan_arrays",
    "plan_file",
    "planar",
    "robot",
    "safety",
    "schema",
    "settings",
    "sight",
    "step",
    "unicycle",
)


__getattr__, __dir__ = lazy_names(__name__, globals(), _ORIGIN, _SUBMODULES)


#: Every name of ``_ORIGIN``, and the two submodules the package has always exported.
__all__ = [*_ORIGIN, "bearing", "camera"]
