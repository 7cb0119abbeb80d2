"""``bearnav plot``: draw an artifact into a figure file."""

from pathlib import Path
from typing import List, Optional

import typer

from bearnav_cli.cli.exits import EXIT_INVALID, fail, handles_errors
from bearnav_cli.cli.hints import figure_default
from bearnav_cli.cli.options import CAMERA_NOISE, CAMERA_RANGE, QUIET, check_camera
from bearnav_cli.cli.output import FIGURE_SUFFIXES, Quiet, out, plotting
from bearnav_cli.errors import InvalidParamsError

__all__ = ["plot_command"]


@handles_errors
def plot_command(
    artifact: Path = typer.Argument(..., metavar="ARTIFACT", help="Any bearnav artifact (map.json, *.npz)."),
    out_path: Optional[Path] = typer.Option(
        None, "-o", "--out", help="Figure file (.png, .pdf, .svg; default: the artifact's name with .png, next to it)."
    ),
    also: Optional[List[Path]] = typer.Option(None, "--also", help="Tree artifact drawn faintly underneath."),
    title: Optional[str] = typer.Option(None, help="Figure title."),
    color_by: Optional[str] = typer.Option(
        None,
        "--color-by",
        help="Cell fill: rank, tolerance (the position error the cell tolerates), status, or live "
        "(red where a cell is not live) (default: rank; status for paper plans).",
    ),
    barriers: bool = typer.Option(False, "--barriers", help="Also draw every barrier line h = 0."),
    labels: Optional[bool] = typer.Option(
        None, "--labels/--no-labels", help="Landmark ids: all, or none (default: those that do not collide)."
    ),
    cell_numbers: bool = typer.Option(False, "--cell-numbers", help="Write each cell's index where it is active."),
    fov: Optional[float] = typer.Option(
        None, "--fov", help="Mark where a camera of this field of view (degrees, (0, 360]) fails along a plan's field."
    ),
    noise_deg: Optional[float] = CAMERA_NOISE,
    max_range: Optional[float] = CAMERA_RANGE,
    live_fov: Optional[float] = typer.Option(
        None, "--live-fov", help="With --color-by live: the camera's field of view, degrees, (0, 360] (default 60)."
    ),
    bearing_error_deg: Optional[float] = typer.Option(
        None,
        "--bearing-error-deg",
        help="With --color-by live: the bearing error bound η, degrees, (0, 45) "
        "(default: the map's robot.bearing_error_deg plus compass_error_deg).",
    ),
    quiet: bool = QUIET,
) -> None:
    """Draw an artifact: map, tree, collision samples, cells, the plan's field, simulated runs.

    Example: bearnav plot plans/kitchen/plan.npz -o plan.png --color-by tolerance --cell-numbers
    """
    from bearnav_cli import artifacts, pipeline
    from bearnav_cli.datatypes import Cells, Plan

    Quiet.enabled |= quiet
    out_path = out_path or figure_default(artifact)
    artifacts.check_output_file(out_path, FIGURE_SUFFIXES, "-o/--out", inputs=(artifact, *(also or [])))
    if fov is None and (noise_deg is not None or max_range is not None):
        given = "--noise-deg" if noise_deg is not None else "--range"
        raise fail(f"{given}: only with --fov (the camera it belongs to)", EXIT_INVALID)
    noise_deg = 1.0 if noise_deg is None else noise_deg
    if fov is not None:
        check_camera(fov, noise_deg, max_range)
    # matplotlib is slow to import: only here
    from bearnav_cli import composition

    plot = plotting()

    if color_by is not None and color_by not in plot.COLOR_BY:
        raise fail(f"--color-by: must be one of {', '.join(plot.COLOR_BY)}, got {color_by!r}", EXIT_INVALID)

    with pipeline.activity(str(out_path)):  # what an interrupt, an error or a warning names
        loaded = pipeline.load(artifact)
        background = [pipeline.load(p, ("tree", "simplified")).artifact for p in also or []]
        shown = loaded.artifact
        seeing = None
        if fov is not None:
            if not isinstance(shown, Plan):
                schema = loaded.manifest.get("schema", "not a plan")
                raise fail(
                    f"--fov: {artifact} is {schema}, not a plan (bearnav.plan/2): the camera looks along "
                    "the plan's field",
                    EXIT_INVALID,
                )
            from bearnav_cli import perception

            max_range_or_inf = float("inf") if max_range is None else max_range
            seeing = perception.perception_coverage(shown, fov, noise_deg, max_range_or_inf)
        live = None
        if color_by == "live" or live_fov is not None or bearing_error_deg is not None:
            if color_by != "live":
                given = "--live-fov" if live_fov is not None else "--bearing-error-deg"
                raise fail(f"{given}: only with --color-by live (the liveness it measures)", EXIT_INVALID)
            if not isinstance(shown, Plan) or not shown.cells.is_funnel:
                schema = loaded.manifest.get("schema", "not a plan")
                raise fail(
                    f"--color-by live: {artifact} is {schema}, not a funnel plan: liveness needs its usable "
                    "tolerances τ_c",
                    EXIT_INVALID,
                )
            from bearnav_cli import liveness

            names = {"eta_deg": "--bearing-error-deg", "fov_deg": "--live-fov"}
            try:
                live = liveness.measure(shown, bearing_error_deg, 60.0 if live_fov is None else live_fov)
            except InvalidParamsError as exc:
                raise fail(f"{names.get(exc.field or '', exc.field)}: {exc.reason}", EXIT_INVALID) from None
        cells = shown.cells if isinstance(shown, Plan) else shown if isinstance(shown, Cells) else None
        # plan/3 covers F (ALGORITHMS §12.7): hatch what of F no cell covers
        coverage = composition.coverage_regions(cells, margin=0.0) if cells is not None and cells.is_funnel else None
        fig = plot.figure_for(
            shown,
            background=background,
            title=title,
            color_by=color_by,
            barriers=barriers,
            labels=labels,
            cell_numbers=cell_numbers,
            coverage=coverage,
            perception=seeing,
            liveness=live,
            params=loaded.manifest.get("params"),
        )
        with artifacts.atomic_output(out_path) as tmp:
            plot.save_figure(fig, str(tmp))
    if seeing is not None:
        out.print(f"perception: {seeing.summary()}", highlight=False, markup=False, soft_wrap=True)
    if live is not None:
        out.print(live.summary(), highlight=False, markup=False, soft_wrap=True)
    out.print(f"wrote {out_path}", highlight=False)
