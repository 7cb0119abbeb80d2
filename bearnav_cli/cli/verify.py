"""``bearnav verify``: check a plan's certificate from the plan alone, and print the report."""

import functools
from pathlib import Path
from typing import Any, Optional

import typer

from bearnav_cli.cli.exits import EXIT_INVALID, EXIT_OUTCOME, fail, handles_errors
from bearnav_cli.cli.hints import WORDS_NOTE, verify_steps
from bearnav_cli.cli.mapfile import read_map_source
from bearnav_cli.cli.options import JSON, QUIET, check_camera, params_options, with_options
from bearnav_cli.cli.output import Quiet, out, print_json, progress_bar, progress_factory
from bearnav_cli.errors import InvalidParamsError

__all__ = ["verify_command"]


@handles_errors
@with_options(functools.partial(params_options, "verify", defaults=True), before="tree")
def verify_command(
    plan_npz: Path = typer.Argument(..., metavar="PLAN_NPZ", help="plan.npz from `bearnav synthesize`."),
    tree: Optional[Path] = typer.Option(None, help="tree.npz whose collision samples the plan must keep."),
    world: Optional[Path] = typer.Option(
        None, help="Another map YAML in the same frame: list the cells that are no longer obstacle-free there."
    ),
    fov: Optional[float] = typer.Option(
        None, "--fov", help="Also report perception coverage for a camera of this field of view, degrees (0, 360]."
    ),
    noise_deg: float = typer.Option(1.0, "--noise-deg", help="Bearing noise (1σ, degrees) of that report."),
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Prove the plan's certificate from the plan alone (no solver): every cell, coverage, tolerance, the loop.

    Example: bearnav verify plans/kitchen/plan.npz --starts 500 --min-success 0.99
    """
    from bearnav_cli import limits, pipeline, verify  # scipy.sparse and the closed loop: only for this command

    Quiet.enabled |= quiet
    for name, value in options.items():
        limits.check_value("verify", name, value, limits.option_name("verify", name))
    try:
        params = verify.Params(**options)
    except InvalidParamsError as exc:  # name the option the user typed
        raise fail(f"{limits.option_name('verify', exc.field or '')}: {exc.reason}", EXIT_INVALID) from None
    starts = params.n_starts
    with pipeline.activity("verify"):  # what an interrupt, an error or a warning names
        loaded = pipeline.load(plan_npz, "plan")
        samples = pipeline.load(tree, ("tree", "simplified")).artifact.collision_samples if tree else None
        plan = loaded.artifact
        where_speed = "--speed" if params.speed is not None else "params.simulate.speed"
        speed = verify.loop_speed(plan, params)  # the speed verify.run drives at (the map's, else simulate's)
        limits.check_value("verify", "speed", speed, where_speed, plan.map.diagonal)
        if starts:  # the closed loop's estimates (simulate's), then the shortest routes' (verify's)
            loop = pipeline.resolve_params(
                "simulate",
                {},
                {
                    "speed": speed,
                    "measurement": "displacement",
                    "record_trajectories": False,
                    "starts": f"random:{starts}",
                },
            )
            origins = pipeline.Origins({"starts": "--starts", "speed": where_speed})
            pipeline.SIMULATE.check_resources(plan, loop, origins)
            limits.check_verify_starts(plan, starts)
        world_map = _load_world(world) if world is not None else None
        seeing = None
        if fov is not None:  # checked before the closed loop runs
            from bearnav_cli import perception

            check_camera(fov, noise_deg)
        with progress_bar() as progress:
            track = progress_factory(progress)("verify")
            try:
                report = verify.run(plan, params, tree_samples=samples, progress=track, world=world_map)
            except InvalidParamsError as exc:  # a liveness option only the map refuses (--live-resolution against D)
                if exc.field not in options:
                    raise
                raise fail(f"{limits.option_name('verify', exc.field)}: {exc.reason}", EXIT_INVALID) from None
        if fov is not None:
            seeing = perception.perception_coverage(plan, fov, noise_deg)
    if as_json:
        data = report.to_json()
        if seeing is not None:
            data["perception"] = {
                "fov_deg": fov,
                "noise_deg": noise_deg,
                "fraction_domain": seeing.fraction_domain,
                "fraction_free": seeing.fraction_free,
                "median_predicted_error": seeing.median_error_domain,
                "fraction_within_tolerance": seeing.fraction_within_tolerance,
            }
        print_json(data)
    else:
        out.print(f"verify    {plan_npz}  {report.summary()}", highlight=False, soft_wrap=True)
        for reason in report.reasons:
            out.print(f"  - {reason}", highlight=False, soft_wrap=True)
        for note in [] if Quiet.enabled else getattr(report, "notes", []):
            out.print(f"  note: {note}", highlight=False, soft_wrap=True)
        if seeing is not None:
            out.print(
                f"  perception: {seeing.summary()} (the rule: `bearnav tags` places tags where it fails)",
                highlight=False,
                soft_wrap=True,
            )
        if not Quiet.enabled:  # what the certificate says, in words, whatever else was printed
            out.print(f"  {verify.guarantee(plan, report)}", highlight=False, markup=False, soft_wrap=True)
        if starts and not Quiet.enabled:
            out.print(
                f"  the {starts} runs drive with displacements (exact positions) and a full view, at speed "
                f"{speed:g} map units/s: `bearnav simulate` adds bearings, a camera and noise; {WORDS_NOTE}",
                highlight=False,
                markup=False,
                soft_wrap=True,
            )
    if report.failed:
        raise fail(verify_steps(report, plan_npz, world), EXIT_OUTCOME)


def _load_world(path: Path):
    """The normalised map of a ``--world`` YAML (validated like any map)."""
    from bearnav_cli.stages import map_

    return map_.run(read_map_source(path))
