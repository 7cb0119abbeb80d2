"""The single-stage commands, one stage each from the file before it: ``rrtstar``, ``simplify``, ``decompose``,
``synthesize``."""

import functools
from pathlib import Path
from typing import Any, Optional

import typer

from bearnav_cli.cli.exits import handles_errors
from bearnav_cli.cli.hints import finish, plan_guarantee
from bearnav_cli.cli.options import FORCE, JSON, QUIET, params_options, with_options
from bearnav_cli.cli.output import Quiet, out, progress_bar, progress_factory, report_line

__all__ = ["decompose_command", "rrtstar_command", "simplify_command", "synthesize_command"]


@handles_errors
@with_options(functools.partial(params_options, "rrtstar"))
def rrtstar_command(
    map_json: Path = typer.Argument(..., metavar="MAP_JSON", help="map.json from `bearnav map`."),
    out_path: Optional[Path] = typer.Option(None, "-o", "--out", help="Output (default tree.npz next to the input)."),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Grow an RRT* tree rooted at the goal, keeping the collision samples.

    Example: bearnav rrtstar plans/kitchen/map.json --iterations 3000 --seed 1
    """
    Quiet.enabled |= quiet
    _run_one("rrtstar", map_json, out_path, options, force, as_json)


@handles_errors
@with_options(functools.partial(params_options, "simplify"))
def simplify_command(
    tree_npz: Path = typer.Argument(..., metavar="TREE_NPZ", help="tree.npz from `bearnav rrtstar`."),
    out_path: Optional[Path] = typer.Option(
        None, "-o", "--out", help="Output (default simplified.npz next to the input)."
    ),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Simplify the tree: shortcuts, leaf cutting and crossing removal to a fixed point.

    Example: bearnav simplify plans/kitchen/tree.npz
    """
    Quiet.enabled |= quiet
    _run_one("simplify", tree_npz, out_path, options, force, as_json)


@handles_errors
@with_options(functools.partial(params_options, "decompose"))
def decompose_command(
    tree_npz: Path = typer.Argument(..., metavar="SIMPLIFIED_NPZ", help="simplified.npz from `bearnav simplify`."),
    out_path: Optional[Path] = typer.Option(None, "-o", "--out", help="Output (default cells.npz next to the input)."),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Cut the free space into one convex cell per tree node: funnel cells that compose (default).

    Example: bearnav decompose plans/kitchen/simplified.npz --cells paper
    """
    Quiet.enabled |= quiet
    _run_one("decompose", tree_npz, out_path, options, force, as_json)


@handles_errors
@with_options(functools.partial(params_options, "synthesize"))
def synthesize_command(
    cells_npz: Path = typer.Argument(..., metavar="CELLS_NPZ", help="cells.npz from `bearnav decompose`."),
    out_path: Optional[Path] = typer.Option(None, "-o", "--out", help="Output (default plan.npz next to the input)."),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Synthesise a certified linear controller per cell (one robust LP each, HiGHS).

    Example: bearnav synthesize plans/kitchen/cells.npz --lp-form dual
    """
    Quiet.enabled |= quiet
    _run_one("synthesize", cells_npz, out_path, options, force, as_json)


def _run_one(stage: str, source: Path, out_path: Optional[Path], overrides: dict, force: bool, as_json: bool) -> None:
    from bearnav_cli import pipeline

    with progress_bar() as progress:
        report = pipeline.run_stage(stage, source, out_path, overrides, force, progress_factory(progress)(stage))
    if not as_json:
        out.print(report_line(report), highlight=False, soft_wrap=True)
    finish([report], as_json)
    if stage == "synthesize" and not as_json and not Quiet.enabled:  # the plan: what it certifies, in words
        out.print(f"  {plan_guarantee(report.artifact, report.path)}", highlight=False, markup=False, soft_wrap=True)
