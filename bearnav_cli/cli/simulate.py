"""``bearnav simulate``: drive robots with a plan's controllers, print the metrics (and write a GIF or a bag)."""

import functools
from pathlib import Path
from typing import Any, Optional

import typer

from bearnav_cli.cli.exits import EXIT_INVALID, EXIT_OUTCOME, fail, handles_errors
from bearnav_cli.cli.hints import WORDS_NOTE, simulation_steps
from bearnav_cli.cli.options import FORCE, JSON, QUIET, params_options, with_options
from bearnav_cli.cli.output import Quiet, err, out, plotting, print_json, progress_bar, progress_factory, report_line

__all__ = ["simulate_command"]


@handles_errors
@with_options(functools.partial(params_options, "simulate"), before="min_success")
def simulate_command(
    plan_npz: Path = typer.Argument(
        ..., metavar="PLAN_NPZ", help="plan.npz from `bearnav synthesize` or `bearnav plan`."
    ),
    out_path: Optional[Path] = typer.Option(None, "-o", "--out", help="Output (default sim.npz next to the plan)."),
    min_success: float = typer.Option(1.0, help="Exit 1 when fewer runs than this fraction reach the goal."),
    gif: Optional[Path] = typer.Option(None, help="Also write an animation of the runs (.gif)."),
    bag: Optional[Path] = typer.Option(
        None, help="Also write the runs as a ROS 2 bag: NAME.mcap (one MCAP file) or NAME (a bag folder)."
    ),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Drive robots with the plan's controllers from bearings: field of view, noise, unicycle.

    Example: bearnav simulate plans/kitchen/plan.npz --fov 60 --dynamics unicycle --starts random:200
    """
    from bearnav_cli import artifacts, pipeline

    Quiet.enabled |= quiet
    if not 0.0 <= min_success <= 1.0:
        raise fail(f"--min-success: must lie in [0, 1], got {min_success}", EXIT_INVALID)
    overrides = options
    sim_npz = out_path or plan_npz.with_name(pipeline.STAGE_BY_NAME["simulate"].filename)
    # -o's own form first (a sim.json given as -o is a wrong extension, not a clash with its metrics),
    # then every output against every other before any work: a bag folder around sim.npz would replace it
    artifacts.check_output_file(sim_npz, (artifacts.KINDS["simulation"].suffix,), inputs=(plan_npz,))
    artifacts.check_distinct(
        {"-o/--out": sim_npz, "sim.json": artifacts.metrics_path(sim_npz), "--gif": gif, "--bag": bag}
    )
    if gif is not None:  # before any work, like every output path
        artifacts.check_output_file(gif, (".gif",), "--gif", inputs=(plan_npz,))
    if bag is not None:  # before any work too: suffix, folder, what is there, rosbags installed
        from bearnav_cli import bag as ros_bag

        ros_bag.check_path(bag, "--bag", force=force)
    with progress_bar() as progress:
        report = pipeline.run_stage(
            "simulate", plan_npz, out_path, overrides, force, progress_factory(progress)("simulate")
        )
    sim = report.artifact
    metrics = sim.stats
    if bag is not None:  # an interrupt names the bag, and what is written already; a warning the plan too
        with pipeline.activity(f"{bag} (sim.npz and sim.json were written)", file=plan_npz):
            if not Quiet.enabled and not as_json and len(sim.trajectory_coords) > 50_000:  # about a second each
                err.print(f"writing {bag} ({len(sim.trajectory_coords)} poses) ...", highlight=False, markup=False)
            ros_bag.write(bag, sim, option="--bag", force=force)
    if as_json:
        shown = {"sim": str(report.path), "ran": report.ran, "metrics": metrics}
        print_json(shown if bag is None else dict(shown, bag=str(bag)))
    elif Quiet.enabled:  # -q: the result's one line (and, on stderr, what failed)
        out.print(report_line(report), highlight=False, soft_wrap=True)
    else:
        from rich.table import Table

        out.print(report_line(report), highlight=False, soft_wrap=True)
        table = Table(title=None, box=None, show_header=True, header_style="bold")
        table.add_column("metric")
        table.add_column("value", justify="right")
        for name, value in _metric_rows(metrics):
            table.add_row(name, value)
        out.print(table)
        out.print(WORDS_NOTE, highlight=False, markup=False, soft_wrap=True)
        if bag is not None:
            out.print(f"wrote {bag}", highlight=False)
    if gif is not None:
        plot = plotting()  # matplotlib only when asked

        with pipeline.activity(f"{gif} (sim.npz and sim.json were written)", file=plan_npz):  # as the bag's
            if not Quiet.enabled and not as_json:  # a GIF takes seconds: say what is happening
                err.print(f"writing {gif} (80 frames) ...", highlight=False, markup=False)
            with artifacts.atomic_output(gif) as tmp:
                plot.save_animation(sim, str(tmp), params=(report.manifest or {}).get("params"))
        if not as_json:
            out.print(f"wrote {gif}", highlight=False)
    rate = metrics.get("success_rate")
    if rate is None or rate < min_success:
        raise fail(simulation_steps(report, plan_npz, min_success), EXIT_OUTCOME)


def _metric_rows(metrics: dict) -> list[tuple[str, str]]:
    """The metrics table of ``bearnav simulate``: (name, formatted value) rows."""

    def num(value: Any, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    rows = [
        ("runs", str(metrics["runs"])),
        ("success rate", num(metrics["success_rate"], ".1%")),
    ]
    rows += [(f"  {name}", str(n)) for name, n in metrics["outcomes"].items() if n]
    rows += [
        ("mean time (s)", num(metrics["time_mean_s"], ".1f")),
        ("mean path length (map units)", num(metrics["path_length_mean"], ".2f")),
        ("path / tree route", num(metrics["path_over_tree_route_mean"], ".3f")),
        ("min clearance (map units)", num(metrics["min_clearance"], ".3f")),
        ("left-cell events", str(metrics["left_cell_events"])),
        ("runs with an approach", str(metrics["runs_with_approach"])),
        ("hold time total (s)", num(metrics["hold_time_total_s"], ".1f")),
        ("certified moving steps", num(metrics.get("certified_step_fraction"), ".1%")),
    ]
    if metrics.get("estimator") == "set":  # ALGORITHMS §12.8: how the bounded-error robot spent its time
        rows += [
            ("success from the certified area", num(metrics.get("success_rate_in_domain"), ".1%")),
            ("looks per run", num(metrics.get("looks_per_run"), ".1f")),
            ("mean look (s)", num(metrics.get("look_time_mean_s"), ".2f")),
            ("truth outside its set (steps)", str(metrics.get("containment_violations"))),
            ("empty sets (broken bounds)", str(metrics.get("inconsistencies"))),
            ("error bound e_t, mean (map units)", num(metrics.get("error_bound_mean"), ".3g")),
            ("true error, mean (map units)", num(metrics.get("true_error_mean"), ".3g")),
            ("largest true error / e_t", num(metrics.get("error_used_max"), ".2f")),
        ]
    return rows
