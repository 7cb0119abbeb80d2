"""Drawing every artifact with matplotlib; nothing else in bearnav imports matplotlib.

Each ``plot_<layer>(ax, artifact, ...)`` draws one layer on an existing axes and returns it, in the
manner of python-control's ``*_plot`` functions: compute elsewhere, draw here. :func:`figure_for`
composes the layers that suit an artifact. Importing the package leaves matplotlib's backend alone
(:func:`use_file_backend` picks the file backend). Its modules, each with one job:

- :mod:`~bearnav_cli.plot.style` — colours by role, polygons as patches, shared legend labels;
- :mod:`~bearnav_cli.plot.labels` — label placement where labels collide with nothing, and their keys;
- :mod:`~bearnav_cli.plot.layers` — the map, a tree, its collision samples and the runtime's field;
- :mod:`~bearnav_cli.plot.cells` — the cells: fills, outlines, exit faces, barriers, indices, uncovered space;
- :mod:`~bearnav_cli.plot.runs` — a simulation's runs by outcome, and one run's estimate sets;
- :mod:`~bearnav_cli.plot.frame` — the frame every figure shares: title, legend below, settled layout, saving;
- :mod:`~bearnav_cli.plot.tags` — perception failures, proposed tags and the tags figure (issue 11);
- :mod:`~bearnav_cli.plot.figures` — :func:`figure_for` and :func:`save_animation`;
- :mod:`~bearnav_cli.plot.sweep` — the success figure of ``bearnav sweep``.
"""

from bearnav_cli.plot.cells import (
    CELL_NUMBER_LABEL,
    COLOR_BY,
    LIVE_COLORS,
    NEVER_ACTIVE_LABEL,
    cell_number_keys,
    cell_regions,
    label_cells,
    plot_barriers,
    plot_cells,
    plot_uncovered,
)
from bearnav_cli.plot.figures import figure_for, save_animation
from bearnav_cli.plot.frame import figure_title, save_figure, simulation_config
from bearnav_cli.plot.labels import (
    CENTRED,
    CORNERS,
    HALO,
    LANDMARKS_LABEL,
    MARKER_HALF,
    label_key,
    label_landmarks,
    place_labels,
)
from bearnav_cli.plot.layers import field_samples, map_handles, plot_field, plot_map, plot_samples, plot_tree
from bearnav_cli.plot.runs import OUTCOME_NAMES, plot_estimate_trace, plot_sim_background, plot_trajectories
from bearnav_cli.plot.style import (
    ADDED_COLOR,
    AXIS_UNITS,
    EXIT_COLOR,
    GOAL_COLOR,
    INFLATED_COLOR,
    LANDMARK_COLOR,
    OUTLINE_COLOR,
    RAW_COLOR,
    TREE_COLOR,
    UNCERTIFIED_COLOR,
    UNCOVERED_COLOR,
    UNREACHED_COLOR,
    use_file_backend,
)
from bearnav_cli.plot.sweep import sweep_plot
from bearnav_cli.plot.tags import (
    EXISTING_TAG_COLOR,
    EXISTING_TAGS_LABEL,
    PERCEPTION_FAIL_COLOR,
    PERCEPTION_FAIL_FREE_COLOR,
    PROPOSED_TAG_COLOR,
    PROPOSED_TAGS_LABEL,
    label_tags,
    plot_perception,
    plot_tags,
    tags_figure,
)

__all__ = [
    "ADDED_COLOR",
    "AXIS_UNITS",
    "cell_number_keys",
    "CELL_NUMBER_LABEL",
    "cell_regions",
    "CENTRED",
    "COLOR_BY",
    "CORNERS",
    "EXISTING_TAG_COLOR",
    "EXISTING_TAGS_LABEL",
    "EXIT_COLOR",
    "field_samples",
    "figure_for",
    "figure_title",
    "GOAL_COLOR",
    "HALO",
    "INFLATED_COLOR",
    "label_cells",
    "label_key",
    "label_landmarks",
    "label_tags",
    "LANDMARK_COLOR",
    "LANDMARKS_LABEL",
    "LIVE_COLORS",
    "map_handles",
    "MARKER_HALF",
    "NEVER_ACTIVE_LABEL",
    "OUTCOME_NAMES",
    "OUTLINE_COLOR",
    "PERCEPTION_FAIL_COLOR",
    "PERCEPTION_FAIL_FREE_COLOR",
    "place_labels",
    "plot_barriers",
    "plot_cells",
    "plot_estimate_trace",
    "plot_field",
    "plot_map",
    "plot_perception",
    "plot_samples",
    "plot_sim_background",
    "plot_tags",
    "plot_trajectories",
    "plot_tree",
    "plot_uncovered",
    "PROPOSED_TAG_COLOR",
    "PROPOSED_TAGS_LABEL",
    "RAW_COLOR",
    "save_animation",
    "save_figure",
    "simulation_config",
    "sweep_plot",
    "tags_figure",
    "TREE_COLOR",
    "UNCERTIFIED_COLOR",
    "UNCOVERED_COLOR",
    "UNREACHED_COLOR",
    "use_file_backend",
]
