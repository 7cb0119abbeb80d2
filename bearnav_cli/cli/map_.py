"""``bearnav map``: validate a map and write map.json (with --fov, where a camera can fix itself)."""

import functools
from pathlib import Path
from typing import Any, List, Optional

import typer

from bearnav_cli.cli.exits import EXIT_INVALID, fail, handles_errors
from bearnav_cli.cli.hints import command_text, finish, tags_step
from bearnav_cli.cli.mapfile import parse_xy, read_map_source
from bearnav_cli.cli.options import (
    CAMERA_RANGE,
    FORCE,
    JSON,
    LOOKAHEAD,
    MAP_ARG,
    QUIET,
    check_camera,
    params_options,
    with_options,
)
from bearnav_cli.cli.output import Quiet, out, report_line

__all__ = ["map_command"]


@handles_errors
@with_options(functools.partial(params_options, "map"), before="goal")
def map_command(
    source: Path = MAP_ARG,
    out_path: Optional[Path] = typer.Option(None, "-o", "--out", help="Output (default plans/<name>/map.json)."),
    goal: Optional[str] = typer.Option(None, help="Goal X,Y (bare occupancy grids only)."),
    landmark: Optional[List[str]] = typer.Option(None, help="Landmark X,Y, repeatable (bare grids only)."),
    start: Optional[List[str]] = typer.Option(None, help="Start X,Y, repeatable (bare grids only)."),
    robot_radius: Optional[float] = typer.Option(None, help="Robot radius (bare grids only)."),
    lookahead: Optional[float] = LOOKAHEAD,
    fov: Optional[float] = typer.Option(
        None, "--fov", help="Also report where a camera of this field of view (degrees, (0, 360]) can fix itself."
    ),
    max_range: Optional[float] = CAMERA_RANGE,
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Validate a map and write map.json.

    Example: bearnav map maps/kitchen.yaml -o /tmp/kitchen/map.json --fov 60
    """
    from bearnav_cli import pipeline

    Quiet.enabled |= quiet
    if fov is None and max_range is not None:
        raise fail("--range: only with --fov (the camera it belongs to)", EXIT_INVALID)
    if fov is not None:  # checked before anything is written
        check_camera(fov, 0.0, max_range)
    goal_xy = parse_xy(goal, "--goal") if goal else None
    src = read_map_source(source, goal_xy, landmark, start, robot_radius, lookahead)
    target = out_path or Path("plans") / str(src.spec.get("name", source.stem)) / "map.json"
    report = pipeline.run_map(src, target, options, force)
    seeing = None
    if fov is not None:  # the map artifact is written already, without it
        from bearnav_cli import perception

        seeing = perception.heading_coverage(report.artifact, fov, float("inf") if max_range is None else max_range)
    extra = None
    if seeing is not None:
        extra = {
            "perception": {
                "fov_deg": seeing.fov_deg,
                "range": max_range,
                "grid_points": len(seeing.points),
                "fraction_some_heading": seeing.fraction_some,
                "fraction_every_heading": seeing.fraction_every,
                "blind_points": len(seeing.blind),
            }
        }
    if not as_json:
        out.print(report_line(report), highlight=False, soft_wrap=True)
        if seeing is not None:
            # the plan `bearnav plan` makes of this map.json lands next to it; of the YAML, in plans/NAME/
            default = target == Path("plans") / str(src.spec.get("name", source.stem)) / "map.json"
            planning = command_text("bearnav", "plan", source if default else target)
            bearnav_map = source if src.grid is None or "occupancy" in src.spec else None  # a bare grid needs options
            step = tags_step(target.parent / "plan.npz", fov, max_range, map_yaml=bearnav_map)
            hint = f"; to place tags where it fails, `{planning}`, then {step}"
            out.print(
                f"  perception: {seeing.summary()}{hint if seeing.fraction_some < 1.0 else ''}",
                highlight=False,
                markup=False,
                soft_wrap=True,
            )
    finish([report], as_json, extra)
