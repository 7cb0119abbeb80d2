"""``bearnav plan``: every stage from the map to the plan, skipping fresh ones, and the plan's guarantee."""

import functools
from pathlib import Path
from typing import Any, List, Optional

import typer

from bearnav_cli.cli.exits import EXIT_INVALID, EXIT_OUTCOME, fail, handles_errors
from bearnav_cli.cli.hints import camera_words, finish, outcome_failure, plan_guarantee, tags_step
from bearnav_cli.cli.mapfile import parse_xy, read_map_source
from bearnav_cli.cli.options import (
    CAMERA_NOISE,
    CAMERA_RANGE,
    FORCE,
    JSON,
    LOOKAHEAD,
    QUIET,
    check_camera,
    params_options,
    with_options,
)
from bearnav_cli.cli.output import Quiet, out, progress_bar, progress_factory, report_line
from bearnav_cli.errors import InvalidMapError

__all__ = ["CELL_KINDS", "PLAN_OPTIONS", "plan_command"]


#: The options ``bearnav plan`` takes of each stage (to change the others for a whole plan: ``params:``).
PLAN_OPTIONS = {
    "map": ("unknown", "circle_segments"), "rrtstar": ("iterations", "step", "seed"), "decompose": ("cells",),
}  # fmt: skip


@handles_errors
@with_options(
    *(
        functools.partial(params_options, stage, only=names, prefix=f"{stage}: ")
        for stage, names in PLAN_OPTIONS.items()
    )
)
def plan_command(
    source: Path = typer.Argument(
        ..., metavar="MAP", help="Map YAML (bearnav format, or a bare ROS map_server YAML with --goal), or a map.json."
    ),
    out_dir: Optional[Path] = typer.Option(
        None, "-o", "--out", help="Output folder (default plans/<name>/; for a map.json, its folder)."
    ),
    goal: Optional[str] = typer.Option(None, help="Goal X,Y, map units (bare occupancy grids only)."),
    landmark: Optional[List[str]] = typer.Option(
        None, metavar="X,Y", help="Landmark X,Y, map units, repeatable (bare grids only)."
    ),
    start: Optional[List[str]] = typer.Option(
        None, metavar="X,Y", help="Start X,Y, map units, repeatable (bare grids only)."
    ),
    robot_radius: Optional[float] = typer.Option(None, help="Robot radius, map units (bare grids only; 0)."),
    lookahead: Optional[float] = LOOKAHEAD,
    fov: Optional[float] = typer.Option(
        None,
        "--fov",
        help="Check the plan for a camera of this field of view (degrees, (0, 360]): exit 1 where "
        "it sees no usable pair of tags along the field, with the `bearnav tags` command that adds them.",
    ),
    max_range: Optional[float] = CAMERA_RANGE,
    noise_deg: Optional[float] = CAMERA_NOISE,
    bearing_error_deg: Optional[float] = typer.Option(
        None, "--bearing-error-deg", help="Overrides the map's robot.bearing_error_deg (degrees)."
    ),
    compass_error_deg: Optional[float] = typer.Option(
        None, "--compass-error-deg", help="Overrides the map's robot.compass_error_deg (degrees)."
    ),
    slip: Optional[float] = typer.Option(None, "--slip", help="Overrides the map's robot.slip."),
    slip_floor: Optional[float] = typer.Option(
        None, "--slip-floor", help="Overrides the map's robot.slip_floor (map units per step)."
    ),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Run every stage from the map to the last one, skipping fresh stages.

    Takes the same map options as `bearnav map`; a map.json from `bearnav map` starts at rrtstar.
    The error bounds (--bearing-error-deg ...) go into the plan's robot section, which simulate
    --estimator set and verify read; with --fov the plan is also checked for that camera.

    Examples: bearnav plan maps/kitchen.yaml --seed 3;
    bearnav plan lab.yaml --goal 1,1 --landmark 0,2 --landmark 4,0 (a bare map_server YAML)
    """
    from bearnav_cli import pipeline
    from bearnav_cli.limits import option_name

    Quiet.enabled |= quiet
    cells = options["cells"]
    if cells is not None and cells not in CELL_KINDS:  # before any stage runs
        raise fail(f"--cells: must be one of {', '.join(CELL_KINDS)}, got {cells!r}", EXIT_INVALID)
    map_options = {
        "--goal": goal,
        "--landmark": landmark,
        "--start": start,
        "--robot-radius": robot_radius,
        "--lookahead": lookahead,
        **{option_name("map", name): options[name] for name in PLAN_OPTIONS["map"]},
    }
    overrides = {stage: {name: options[name] for name in names} for stage, names in PLAN_OPTIONS.items()}
    robot = {
        key: value
        for key, value in (
            ("bearing_error_deg", bearing_error_deg),
            ("compass_error_deg", compass_error_deg),
            ("slip", slip),
            ("slip_floor", slip_floor),
        )
        if value is not None
    }
    map_options.update({"--" + key.replace("_", "-"): value for key, value in robot.items()})
    if fov is None and (max_range is not None or noise_deg is not None):
        given = "--range" if max_range is not None else "--noise-deg"
        raise fail(f"{given}: only with --fov (the camera it belongs to)", EXIT_INVALID)
    if fov is not None:  # checked before any stage runs
        check_camera(fov, 1.0 if noise_deg is None else noise_deg, max_range)
    if source.is_dir():
        inside = source / "map.json"
        hint = f"; did you mean {inside}?" if inside.is_file() else " (give a map YAML or a map.json)"
        raise fail(f"{source}: is a folder{hint}", EXIT_INVALID)
    if _is_map_artifact(source):
        given = [name for name, value in map_options.items() if value not in (None, [])]
        if given:
            raise fail(
                f"{given[0]}: {source} is a map.json, built already; give the map YAML to change its map options",
                EXIT_INVALID,
            )
        src: Any = source
        target = out_dir or source.parent
    else:
        goal_xy = parse_xy(goal, "--goal") if goal else None
        src = read_map_source(source, goal_xy, landmark, start, robot_radius, lookahead, robot)
        target = out_dir or Path("plans") / str(src.spec.get("name", source.stem))

    def show(report: pipeline.StageReport) -> None:
        if not as_json and (not Quiet.enabled or report.stage == pipeline.STAGES[-1].name):
            out.print(report_line(report), highlight=False, soft_wrap=True)

    with progress_bar() as progress:
        try:
            reports = pipeline.plan(src, target, overrides, force, progress_factory(progress), show)
        except InvalidMapError as exc:  # a robot bound only the option gave: name the option
            key = (exc.field or "").removeprefix("robot.")
            if key not in robot:
                raise
            raise fail(f"--{key.replace('_', '-')}: {exc.reason}", EXIT_INVALID) from None
    plan_words = tuple(camera_words(fov, max_range)) if fov is not None else ()
    plan_words += tuple(word for key, value in robot.items() for word in (f"--{key.replace('_', '-')}", f"{value:g}"))
    seeing, extra = None, None
    plan = reports[-1].artifact
    if fov is not None and outcome_failure(reports[-1].stage, plan) is None:  # the camera's, on a plan passing the rest
        from bearnav_cli import perception

        seeing = perception.perception_coverage(
            plan, fov, 1.0 if noise_deg is None else noise_deg, float("inf") if max_range is None else max_range
        )
        extra = {
            "perception": {
                "fov_deg": fov,
                "range": max_range,
                "noise_deg": seeing.noise_deg,
                "fraction_domain": seeing.fraction_domain,
                "fraction_free": seeing.fraction_free,
            }
        }
        if not as_json:
            out.print(f"  perception: {seeing.summary()}", highlight=False, markup=False, soft_wrap=True)
    finish(reports, as_json, extra, camera=(360.0 if fov is None else fov, max_range), plan_words=plan_words)
    if not as_json and not Quiet.enabled and (seeing is None or seeing.fraction_domain >= 1.0):
        out.print(f"  {plan_guarantee(plan, reports[-1].path, fov)}", highlight=False, markup=False, soft_wrap=True)
    if seeing is not None and seeing.fraction_domain < 1.0:
        from bearnav_cli.datatypes import percent

        raise fail(
            f"a {fov:g}° camera looking along the field sees no usable pair of tags from "
            f"{percent(1.0 - seeing.fraction_domain)} of the certified area: add tags there; "
            + tags_step(reports[-1].path, fov, max_range, plan_words),
            EXIT_OUTCOME,
        )


#: ``decompose --cells`` (and ``plan --cells``) choices.
CELL_KINDS = ("funnel", "funnel-local", "paper")


def _is_map_artifact(path: Path) -> bool:
    """A ``map.json`` written by the map stage (told by its suffix: map YAMLs end in .yaml or .yml)."""
    return path.suffix.lower() == ".json"
