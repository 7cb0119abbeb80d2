"""Helpers shared by the scripts of ``repro/``: loading plans, running the closed loop, writing the numbers.

The scripts import this module as ``common`` (Python puts a script's own folder first on
``sys.path``), so ``.venv/bin/python repro/<name>.py`` works from the repository root.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.lines import Line2D

from bearnav_cli import artifacts, pipeline
from bearnav_cli.datatypes import Map, Outcome, Polygon, Simulation
from bearnav_cli.palette import OUTCOME_COLORS
from bearnav_cli.plot import OUTCOME_NAMES
from bearnav_cli.stages import simulate


def arguments(description: str, inputs: list[tuple[str, str]]) -> argparse.Namespace:
    """Parse ``INPUT... -o FIGURE`` from the command line.

    Parameters
    ----------
    description : str
        The script's help text.
    inputs : list of (name, help)
        The positional input artifacts, in order.

    Returns
    -------
    argparse.Namespace
        One attribute per input (a :class:`~pathlib.Path`) and ``out``, the figure path.
    """
    parser = argparse.ArgumentParser(description=description)
    for name, text in inputs:
        parser.add_argument(name, type=Path, help=text)
    parser.add_argument("-o", "--out", type=Path, required=True, help="Figure (.png); the numbers go next to it.")
    return parser.parse_args()


def load(path: Path, kind: str) -> tuple[Any, dict]:
    """Load an artifact of ``kind``, returning it and its provenance (path and content hash)."""
    loaded = artifacts.load(path, kind)
    return loaded.artifact, {"path": str(path), "content_sha256": loaded.manifest["content_sha256"]}


def sim_params(plan, **overrides: Any) -> simulate.Params:
    """Closed-loop parameters as ``bearnav simulate`` resolves them: defaults, the map's ``params:``, ``overrides``."""
    return pipeline.resolve_params("simulate", plan.map.params, overrides)


def outcome_name(value: int) -> str:
    """``success``, ``collision``, ``stall``, ``timeout`` or ``lost``."""
    return Outcome(int(value)).name.lower()


def run_rows(rollouts: Simulation) -> list[dict]:
    """One JSON-ready record per run: start, outcome, time, path length, steps, clearance, end point."""
    return [
        {
            "start": [float(v) for v in rollouts.starts[r]],
            "outcome": outcome_name(rollouts.outcome[r]),
            "time_s": round(float(rollouts.time[r]), 6),
            "path_length": round(float(rollouts.path_length[r]), 6),
            "steps": int(rollouts.steps[r]),
            "min_clearance": round(float(rollouts.min_clearance[r]), 6),
            "final_position": [round(float(v), 6) for v in rollouts.final_position[r]],
        }
        for r in range(len(rollouts))
    ]


def experiment(rollouts: Simulation, params: simulate.Params, runs: bool = True) -> dict:
    """Success rate, outcome counts, the parameters and (optionally) every run of one rollout."""
    record = {
        "params": artifacts.params_dict(params),
        "runs": len(rollouts),
        "success_rate": rollouts.success_rate,
        "outcomes": rollouts.counts(),
        "dt": rollouts.dt,
    }
    if runs:
        record["per_run"] = run_rows(rollouts)
    return record


def write_json(path: Path, data: dict) -> None:
    """Write ``data`` as indented JSON (NaN written as null)."""

    def clean(value: Any) -> Any:
        if isinstance(value, float) and not math.isfinite(value):
            return None
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [clean(v) for v in value]
        return value

    path.write_text(json.dumps(clean(data), indent=2) + "\n")


def rotate_points(points: np.ndarray, degrees: float, center: np.ndarray) -> np.ndarray:
    """``p ↦ R(θ)(p − c) + c`` for every row of ``points`` (shape (n, 2)); ``θ`` counter-clockwise."""
    theta = math.radians(degrees)
    rotation = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    points = np.asarray(points, float).reshape(-1, 2)
    return (points - center) @ rotation.T + center


def rotate_map(map_: Map, degrees: float, center: tuple[float, float]) -> Map:
    """The map with its obstacles (inflated and raw), landmarks and starts rotated about ``center``.

    Bounds, goal and parameters stay: this is the deformed world of paper B's robustness test,
    in which the controllers of the undeformed plan are run.
    """
    c = np.asarray(center, float)

    def turn(polygon: Polygon) -> Polygon:
        holes = tuple(rotate_points(h, degrees, c) for h in polygon.holes)
        return Polygon(rotate_points(polygon.exterior, degrees, c), holes)

    return dataclasses.replace(
        map_,
        obstacles=tuple(turn(p) for p in map_.obstacles),
        raw_obstacles=tuple(turn(p) for p in map_.raw_obstacles),
        landmarks=rotate_points(map_.landmarks, degrees, c),
        # a tag turns with its wall (NaN, a free-standing tag, stays NaN)
        landmark_facing=map_.landmark_facing + math.radians(degrees),
        starts=rotate_points(map_.starts, degrees, c),
    )


def draw_runs(ax, rollouts: Simulation, *, linestyle: str = "-", lw: float = 1.1) -> None:
    """Every run's path coloured by outcome, its start (circle) and, if it failed, its end (cross)."""
    for r in range(len(rollouts)):
        path = rollouts.trajectory(r)
        if not len(path):
            continue
        color = OUTCOME_COLORS[int(rollouts.outcome[r])]
        ax.plot(*path.T, color=color, lw=lw, ls=linestyle, alpha=0.9, zorder=4)
        ax.plot(*path[0], "o", ms=4, mfc="white", mec=color, zorder=5)
        if rollouts.outcome[r] != Outcome.SUCCESS:
            ax.plot(*path[-1], "x", ms=6, mew=1.5, color=color, zorder=5)


def outcome_handles(*rollouts: Simulation) -> list[Line2D]:
    """Legend entries for the outcomes that occur in ``rollouts``."""
    seen = sorted({int(o) for r in rollouts for o in r.outcome})
    return [Line2D([], [], color=OUTCOME_COLORS[o], lw=1.5, label=OUTCOME_NAMES[o]) for o in seen]
