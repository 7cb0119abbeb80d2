"""``bearnav sweep`` (issue 25): a grid of plans and closed loops, run into a store; its table and figure."""

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer

from bearnav_cli.cli.exits import (
    EXIT_INTERRUPTED,
    EXIT_INVALID,
    EXIT_OUTCOME,
    EXIT_TERMINATED,
    Terminated,
    fail,
    handles_errors,
)
from bearnav_cli.cli.mapfile import read_map_source, read_yaml
from bearnav_cli.cli.options import JSON, QUIET
from bearnav_cli.cli.output import FIGURE_SUFFIXES, Quiet, count_column, err, out, plotting

if TYPE_CHECKING:
    from rich.progress import Progress

__all__ = ["sweep_command"]


def _sweep_progress() -> "Progress":
    """The sweep's bar: jobs done, failed and left, and the time left (rich's estimate from the pace so far)."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    return Progress(
        TextColumn("{task.description:<10}"),
        BarColumn(),
        count_column()(),
        TextColumn("{task.fields[failed]} failed, {task.fields[left]} left"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=err.console,
        transient=True,
        disable=Quiet.enabled or not err.is_terminal,
    )


@handles_errors
def sweep_command(
    sweep_yaml: Path = typer.Argument(..., metavar="SWEEP", help="Sweep file (docs/sweeps.md)."),
    out_dir: Optional[Path] = typer.Option(None, "-o", "--out", help="The store folder (default sweeps/NAME/)."),
    jobs: Optional[int] = typer.Option(None, "--jobs", "-j", help="Local worker processes (default: every CPU)."),
    scheduler: Optional[str] = typer.Option(
        None,
        "--scheduler",
        metavar="ADDRESS",
        help="Run the jobs on this Dask scheduler (tcp://HOST:PORT; needs bearnav[dask]), not in local processes.",
    ),
    report: bool = typer.Option(False, "--report", help="Only redraw the table and figure from the store."),
    figure: Optional[Path] = typer.Option(None, "--figure", help="The figure (default STORE/success.png)."),
    quiet: bool = QUIET,
    as_json: bool = JSON,
) -> None:
    """Run a grid of plans and closed-loop runs (maps × seeds × fov × noise × ...), each job once, into a store.

    Each job's result is a small file of the store: an interrupted or repeated sweep runs only what is
    missing. Writes results.csv (and .parquet with pyarrow), results.md and a figure of success against
    noise. Exit 1 when a job failed (its error is in the table).

    Examples: bearnav sweep repro/robustness.yaml --jobs 2;
    bearnav sweep small.yaml --scheduler tcp://10.0.0.5:8786;
    bearnav sweep small.yaml --report
    """
    from bearnav_cli import artifacts, sweep

    Quiet.enabled |= quiet
    if jobs is not None and jobs < 1:
        raise fail(f"--jobs: must be at least 1, got {jobs}", EXIT_INVALID)
    if jobs is not None and scheduler is not None:
        raise fail("--jobs: not with --scheduler (the cluster's workers run the jobs)", EXIT_INVALID)
    if figure is not None:
        artifacts.check_output_file(figure, FIGURE_SUFFIXES, "--figure", inputs=(sweep_yaml,))
    spec, _ = read_yaml(sweep_yaml)
    grid = sweep.read_sweep(spec, str(sweep_yaml))
    sources = [read_map_source(path) for path in sweep.expand_maps(grid)]
    job_list, left_out = sweep.expand(grid, sources)
    store = out_dir or Path("sweeps") / grid.name
    artifacts.check_output_folder(store)
    figure = figure or store / "success.png"
    if report and not store.is_dir():
        raise fail(f"--report: {store} holds no sweep yet (run `bearnav sweep {sweep_yaml}` first)", EXIT_INVALID)
    outcome = None
    if not report:
        close = None
        if scheduler is not None:
            executor, close = sweep.connect_scheduler(scheduler)
        else:
            executor = sweep.local_executor(jobs or os.cpu_count() or 1)
        interrupted = True
        try:
            with _sweep_progress() as progress:
                plans = progress.add_task("plans", total=None, failed=0, left="")
                task = progress.add_task("jobs", total=len(job_list), failed=0, left=len(job_list))

                def on_job(done: int, failed: int, total: int) -> None:
                    progress.update(task, completed=done, failed=failed, left=total - done)

                def on_plans(done: int, total: int) -> None:
                    progress.update(plans, completed=done, total=total, left=total - done)

                outcome = sweep.run(job_list, store, executor, on_job, on_plans)
            interrupted = False
        except KeyboardInterrupt as exc:
            done = len([r for r in sweep.records(store, job_list).values() if r.get("status") == "done"])
            word = "terminated" if isinstance(exc, Terminated) else "interrupted"
            err.print(
                f"{word}; {done} of {len(job_list)} jobs are in {store}, the next `bearnav sweep` runs the others",
                highlight=False,
                soft_wrap=True,
                markup=False,
            )
            raise typer.Exit(EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED) from None
        finally:
            if close is not None:
                close()
            else:
                sweep.stop_local(executor, interrupted)
    found = sweep.records(store, job_list)
    rows = sweep.table(job_list, found)
    written = sweep.write_results(store, rows)
    panels = sweep.success_curves(rows)
    runs = sorted({r["runs"] for r in rows if r["runs"] is not None})
    title = f"{grid.name}: success against bearing noise" + (f" ({'/'.join(map(str, runs))} runs each)" if runs else "")
    markdown = store / "results.md"
    artifacts.atomic_write(markdown, lambda f: f.write(sweep.markdown(panels, title).encode()))
    plot = plotting()
    with artifacts.atomic_output(figure) as tmp:
        plot.save_figure(plot.sweep_plot(panels, title), str(tmp))
    failed = [r for r in rows if r["status"] != "done"]
    summary = {
        "store": str(store),
        "jobs": len(job_list),
        "in_store": len(rows),
        "failed": len(failed),
        "left_out": left_out,
        "files": [str(p) for p in (*written, markdown, figure)],
    }
    if outcome is not None:
        summary.update(
            ran=outcome.ran,
            from_store=outcome.stored,
            plans_made=outcome.plans_made,
            elapsed_s=round(outcome.elapsed_s, 3),
        )
    if as_json:
        out.print_json(json.dumps(summary))
    else:
        if outcome is not None:
            out.print(
                f"sweep      {store}: {len(job_list)} jobs, {outcome.ran} ran, {outcome.stored} from the store, "
                f"{len(failed)} failed ({outcome.plans_made} plans made, {outcome.elapsed_s:.1f} s)",
                highlight=False,
                soft_wrap=True,
            )
        else:
            out.print(
                f"report     {store}: {len(rows)} of {len(job_list)} jobs in the store, {len(failed)} failed",
                highlight=False,
                soft_wrap=True,
            )
        if left_out:
            out.print(
                f"left out {left_out} cells with both noise_deg and noise_bound_deg (simulate takes one)",
                highlight=False,
                soft_wrap=True,
            )
        for row in failed[:5]:
            out.print(
                f"failed     {row['map']} fov {row['fov']:g} noise {row['noise_deg']:g}: {row['error']}",
                highlight=False,
                markup=False,
                soft_wrap=True,
            )
        out.print("wrote " + ", ".join(summary["files"]), highlight=False, soft_wrap=True)
    if failed:
        raise typer.Exit(EXIT_OUTCOME)
