"""The words after a result: why an outcome failed, the command that addresses it, what a plan guarantees.

Every failed outcome and every perception shortfall ends with the command that addresses it, with the
real file names, built here and only here, so that each hint runs as printed (tests/test_cli_hints.py).
"""

from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional

from bearnav_cli.cli.exits import EXIT_OUTCOME, fail
from bearnav_cli.cli.fields import params_fields
from bearnav_cli.cli.mapfile import read_yaml
from bearnav_cli.cli.options import shown_value
from bearnav_cli.cli.output import print_json
from bearnav_cli.errors import BearnavError

if TYPE_CHECKING:
    from bearnav_cli import pipeline

__all__ = [
    "WORDS_NOTE",
    "camera_words",
    "command_text",
    "figure_default",
    "finish",
    "outcome_failure",
    "plan_guarantee",
    "simulate_words",
    "simulation_steps",
    "tags_output",
    "tags_step",
    "verify_steps",
]


def command_text(*words: Any) -> str:
    """A command line as a user pastes it into a shell (paths with spaces quoted)."""
    import shlex

    return shlex.join(str(word) for word in words)


def camera_words(fov: float, max_range: Optional[float] = None) -> list[str]:
    """The options naming a camera, as ``tags``, ``simulate`` and ``plan`` spell them."""
    return ["--fov", f"{fov:g}", *(["--range", f"{max_range:g}"] if max_range is not None else [])]


def tags_output(plan_npz: Path, map_yaml: Optional[Path]) -> Path:
    """Where ``bearnav tags`` writes its map without ``-o``: NAME_tags.yaml next to ``--map`` (NAME_tags2.yaml
    for NAME_tags.yaml, NAME_tags3.yaml for NAME_tags2.yaml ...), else map_tags.yaml next to the plan."""
    import re

    if map_yaml is None:
        return plan_npz.parent / "map_tags.yaml"
    again = re.fullmatch(r"(.+)_tags(\d*)", map_yaml.stem)  # a map tags wrote: count, never NAME_tags_tags
    name = f"{again[1]}_tags{int(again[2] or 1) + 1}" if again else f"{map_yaml.stem}_tags"
    return map_yaml.with_name(f"{name}.yaml")


def _tags_map(plan_npz: Path) -> Optional[Path]:
    """The map YAML ``bearnav tags --map`` can extend for this plan: the one it was planned from (a bearnav map,
    or a bare map_server YAML, which the new map then names as its ``occupancy:``), if it is still there."""
    from bearnav_cli import artifacts

    source = artifacts.map_source_of(plan_npz)
    if source is None:
        return None
    try:
        spec, _ = read_yaml(source)
    except BearnavError:
        return None
    return source if isinstance(spec, dict) else None


def tags_step(
    plan_npz: Path,
    fov: float = 360.0,
    max_range: Optional[float] = None,
    plan_words: tuple[str, ...] = (),
    map_yaml: Optional[Path] = None,
    tags_words: tuple[str, ...] = (),
) -> str:
    """The next step where a camera cannot fix itself: the ``bearnav tags`` command for this plan, the map it
    writes and the ``bearnav plan`` command that re-plans with it (``plan_words``: options to plan it with).

    Parameters
    ----------
    plan_npz : Path
        The plan, as the user named it (or as bearnav wrote it).
    fov, max_range : float
        The camera (degrees; map units, None for unlimited).
    plan_words : tuple of str
        Options of the re-planning command (the camera of ``plan --fov``).
    map_yaml : Path, optional
        The map YAML to give ``--map`` (default: the one the plan was made from, if any).
    tags_words : tuple of str
        Further options of the ``bearnav tags`` command (``--for live`` and its bound).

    Returns
    -------
    str
        ```bearnav tags PLAN --fov F --map M` writes M_tags.yaml; then `bearnav plan M_tags.yaml```.
    """
    map_yaml = map_yaml or _tags_map(plan_npz)
    tags = command_text(
        "bearnav",
        "tags",
        plan_npz,
        *camera_words(fov, max_range),
        *tags_words,
        *(["--map", map_yaml] if map_yaml is not None else []),
    )
    written = tags_output(plan_npz, map_yaml)
    return f"`{tags}` writes {written}; then `{command_text('bearnav', 'plan', written, *plan_words)}`"


def simulate_words(params: dict, **changes: Any) -> list[str]:
    """The ``bearnav simulate`` options that give the loop ``params`` (with ``changes``): those off their defaults."""
    words: list[str] = []
    for field in params_fields("simulate"):
        if field.option is None or field.name not in params:
            continue
        value = changes.get(field.name, params[field.name])
        if value == field.default or value is None:
            continue
        if field.kind is bool:
            words.append(field.option if value else field.off)
        else:
            words += [field.option, shown_value(value).strip("'")]
    return words


def simulation_steps(report: "pipeline.StageReport", plan_npz: Path, min_success: float) -> str:
    """Why too few simulated runs reached the goal, outcome by outcome, and the command that addresses each.

    Parameters
    ----------
    report : StageReport
        The simulate stage's report (its artifact the :class:`~bearnav_cli.datatypes.Simulation`, its
        manifest the loop's parameters).
    plan_npz : Path
        The plan simulated.
    min_success : float
        The ``--min-success`` the runs fell short of.

    Returns
    -------
    str
        One line: the outcome, then ``lost: ...; collision: ...`` and the figure that shows the runs.
    """
    params = dict((report.manifest or {}).get("params") or {})
    counts = report.artifact.counts()
    steps = []
    if counts.get("lost"):
        fov, max_range = float(params.get("fov", 360.0)), params.get("range")
        if params.get("estimator") == "set":
            eta = params.get("bearing_error_deg") or params.get("noise_bound_deg")
            words = ("--for", "live", *(["--bearing-error-deg", f"{eta:g}"] if eta else []))
            steps.append(
                "lost: a look all around left the error bound above what the cell tolerates (the cell is "
                "not live at these bounds); add tags until every cell is: "
                + tags_step(plan_npz, fov, max_range, tags_words=words)
            )
        else:
            hold = params.get("hold_time", 2.0)
            steps.append(
                f"lost: the camera saw fewer than two usable tags for --hold-time {hold:g} s (a {fov:g}° "
                "camera); add tags: " + tags_step(plan_npz, fov, max_range)
            )
    if counts.get("collision") and params.get("estimator") != "set":
        retry = command_text("bearnav", "simulate", plan_npz, *simulate_words(params, estimator="set"))
        steps.append(
            "collision: the position estimate erred beyond the cell's tolerance (noise, slip, a camera or "
            f"a unicycle outside the certificate); `{retry}` drives only where its error bound is "
            "certified"
        )
    elif counts.get("collision"):
        steps.append(
            "collision: the error bounds assumed are below the errors simulated (--bearing-error-deg, "
            "--slip); `bearnav verify " + str(plan_npz) + "` checks the certificate"
        )
    if counts.get("stall") or counts.get("timeout"):
        steps.append("stall or timeout: the field vanished or the run made no progress (outside every cell?)")
    shown = command_text("bearnav", "plot", report.path)
    return (
        f"{report.summary}, fewer than --min-success {min_success:g}: "
        + "; ".join(steps)
        + f"; `{shown}` draws the runs by outcome, into {figure_default(report.path)}"
    )


def verify_steps(report: Any, plan_npz: Path, world: Optional[Path]) -> str:
    """What to do about a plan that fails ``bearnav verify``: one line naming the real files.

    Parameters
    ----------
    report : VerifyReport
        ``verify.run``'s report (its reasons are printed above this line).
    plan_npz : Path
        The plan verified.
    world : Path, optional
        The ``--world`` map, if one was given.

    Returns
    -------
    str
    """
    import numpy as np

    from bearnav_cli import artifacts
    from bearnav_cli.datatypes import Outcome, plural

    steps = []
    if report.world_cells:
        steps.append(f"the world moved: re-plan in it with `{command_text('bearnav', 'plan', world)}`")
    if report.uncertified:
        shown = command_text("bearnav", "inspect", plan_npz, "--cell", report.uncertified[0])
        steps.append(f"`{shown}` shows the first cell not certified")
    composition_fails = report.composition is not None and not report.composition.ok
    breached = report.breaches is not None and bool(report.breaches.any())
    broken = bool(report.false_certificates) or composition_fails or bool(report.lookahead_problems) or breached
    if broken:  # the checks a plan bearnav wrote passes: an edited file, another version's, or a bug
        origin = artifacts.map_source_of(plan_npz)
        again = (
            f"`{command_text('bearnav', 'plan', origin, '--force')}`"
            if origin
            else "`bearnav plan` of the map it was made from, with --force,"
        )
        steps.append(
            f"if the plan was edited or made by another version, {again} makes it again; else please "
            "report it with the plan"
        )
    runs = report.rollouts
    if runs is not None and len(runs) and bool(np.any(np.asarray(runs.outcome) != Outcome.SUCCESS)):
        again = command_text("bearnav", "simulate", plan_npz, "--measurement", "displacement", "--odometry-noise", "0")
        steps.append(
            f"`{again}` drives runs of the same loop and writes them; `bearnav plot` of its sim.npz draws "
            "them by outcome"
        )
    text = f"{plan_npz} fails verification ({plural(len(report.reasons), 'problem')} above)"
    return text + (": " + "; ".join(steps) if steps else "")


def outcome_failure(
    stage: str,
    artifact: Any,
    path: Optional[Path] = None,
    camera: tuple[float, Optional[float]] = (360.0, None),
    plan_words: tuple[str, ...] = (),
) -> str | None:
    """Why a finished run's result is not usable (exit 1) and what to do next, or None.

    The verdict is the stage's (its first ``problems(result)``, :mod:`bearnav_cli.verdicts`); the next step
    is added here. ``stage`` names the stage that made ``artifact``, ``path`` is the artifact's file (the
    hints name it), ``camera`` the (fov, range) the tags are proposed for, ``plan_words`` the options of the
    re-planning command.
    """
    from bearnav_cli import pipeline, verdicts

    found = pipeline.STAGE_BY_NAME[stage].problems(artifact)
    if not found:
        return None
    problem = found[0]
    if path is None:
        return problem.text
    if problem.kind == verdicts.NO_ROUTE:
        return f"{problem.text}; `{command_text('bearnav', 'plot', path)}` draws it"
    if problem.kind == verdicts.BLIND_SPOT:
        from bearnav_cli.datatypes import Plan  # here: a tree's verdict needs no cells' module

        if isinstance(artifact, Plan):  # tags places landmarks along a plan's fields
            step = tags_step(path, *camera, plan_words=plan_words)
        else:  # cells.npz: synthesize it first
            plan_npz = path.with_name("plan.npz")
            step = f"`{command_text('bearnav', 'synthesize', path, '-o', plan_npz)}`, then " + tags_step(
                plan_npz, *camera, plan_words=plan_words
            )
        return f"{problem.text}: add landmarks there; {step}"
    if problem.kind == verdicts.NOT_CERTIFIED:
        return f"{problem.text}; `bearnav inspect {path} --cell {problem.cells[0]}` shows the first"
    return problem.text


def finish(
    reports: "list[pipeline.StageReport]",
    as_json: bool,
    extra: Optional[dict] = None,
    camera: "tuple[float, float | None]" = (360.0, None),
    plan_words: tuple[str, ...] = (),
) -> None:
    """Print the reports' JSON rows (the last with ``extra`` fields) and exit 1 on a failed outcome."""
    if as_json:
        rows = [
            {"stage": r.stage, "ran": r.ran, "elapsed_s": r.elapsed_s, "path": str(r.path), "summary": r.summary}
            for r in reports
        ]
        if rows and extra:
            rows[-1].update(extra)
        print_json(rows)
    last = reports[-1] if reports else None
    problem = outcome_failure(last.stage, last.artifact, last.path, camera, plan_words) if last else None
    if problem:
        raise fail(problem, EXIT_OUTCOME)


def plan_guarantee(plan: Any, path: Path, fov: Optional[float] = None) -> str:
    """The sentence ``plan`` ends with: what the synthesis certified, for which robot, and what proves it.

    Parameters
    ----------
    plan : Plan
        The plan just made (every check of ``plan`` passed).
    path : Path
        Its ``plan.npz``, for the ``bearnav verify`` command the sentence names.
    fov : float, optional
        The camera ``plan --fov`` checked, if any.
    """
    from bearnav_cli import composition
    from bearnav_cli.datatypes import percent

    check = f"`{command_text('bearnav', 'verify', path)}` proves it from the file alone"
    camera = (
        f"a {fov:g}° camera sees a usable pair of tags along the field everywhere in that area (measured on a grid)"
        if fov is not None
        else "the camera is not checked (add --fov)"
    )
    if not plan.cells.is_funnel:
        return f"guarantee: {composition.PAPER_CLAIM}; {camera}"
    by_area = composition.tolerance_by_area(plan.cells, plan.usable_tolerance)
    robot = composition.robot_words(plan.map)
    where = f"the certified area ({percent(plan.cells.free_coverage)} of the free space)"
    known = f"{plan.plan_tolerance:.3g} map units (median {by_area['median']:.3g} by area)"
    return (
        f"guarantee (by construction): {robot} that starts in {where} and knows its position to within "
        f"{known} reaches the goal without touching an obstacle or a wall; {check}; {camera}"
    )


def figure_default(artifact: Path) -> Path:
    """Where ``bearnav plot`` draws an artifact without ``-o``: next to it, its name with .png (plan.npz: plan.png)."""
    return artifact.with_suffix(".png")


#: Where the words of the verify and simulate output are defined.
WORDS_NOTE = 'lost, stall, left-cell events, approach, hold, certified, D, F_m: docs/cli.md "Words in the output"'
