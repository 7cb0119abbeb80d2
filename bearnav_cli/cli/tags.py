"""``bearnav tags``: where to glue more tags, written as a new map YAML and a figure."""

import math
from pathlib import Path
from typing import Optional

import typer

from bearnav_cli.cli.exits import EXIT_INVALID, EXIT_OUTCOME, fail, handles_errors
from bearnav_cli.cli.hints import camera_words, command_text, tags_output
from bearnav_cli.cli.mapfile import is_bare_grid, read_bytes, read_grid, read_map_source
from bearnav_cli.cli.options import CAMERA_OPTIONS, JSON, QUIET
from bearnav_cli.cli.output import FIGURE_SUFFIXES, Quiet, err, out, plotting, print_json
from bearnav_cli.errors import InvalidParamsError

__all__ = ["tags_command"]


@handles_errors
def tags_command(
    plan_npz: Path = typer.Argument(..., metavar="PLAN_NPZ", help="plan.npz from `bearnav plan`."),
    fov: float = typer.Option(60.0, "--fov", help="Camera field of view, degrees, in (0, 360]."),
    max_range: Optional[float] = typer.Option(None, "--range", help="Camera range, map units (default: unlimited)."),
    noise_deg: float = typer.Option(1.0, "--noise-deg", help="Bearing noise (1σ, degrees) of the predicted fix error."),
    error_target: Optional[float] = typer.Option(
        None, "--error-target", help="Also require a predicted fix error (3σ) of at most this, map units."
    ),
    max_tags: Optional[int] = typer.Option(
        None, "--max-tags", help="At most this many new tags (exit 1 if the rule then still fails somewhere)."
    ),
    map_yaml: Optional[Path] = typer.Option(
        None,
        "--map",
        help="The map YAML to add the tags to, kept as it is (default: the plan's map, written as polygons); "
        "a bare map_server YAML is named by the new map as its occupancy grid.",
    ),
    out_path: Optional[Path] = typer.Option(
        None,
        "-o",
        "--out",
        help="Map YAML with the new tags, a new file (default: NAME_tags.yaml next to the --map "
        "YAML, else map_tags.yaml next to the plan).",
    ),
    figure: Optional[Path] = typer.Option(
        None, "--figure", help="Where to glue them, a figure (default: the map YAML's name with .png)."
    ),
    force: bool = typer.Option(False, "--force", help="Replace an -o file that is not a map bearnav tags wrote."),
    target: str = typer.Option(
        "fix",
        "--for",
        help="fix: a usable pair in view where the robot drives; live: every cell live, so that a "
        "look all around always lets the robot move on, at --bearing-error-deg and --slip (one of fix, live).",
    ),
    bearing_error_deg: Optional[float] = typer.Option(
        None,
        "--bearing-error-deg",
        help="With --for live: the bound on every world-frame bearing error (degrees, "
        "in (0, 45)); None means the map's robot: bearing_error_deg plus compass_error_deg.",
    ),
    slip: Optional[float] = typer.Option(
        None,
        "--slip",
        help="With --for live: the odometry error bound, a fraction of each step (in [0, 1)); None "
        "means the map's robot: slip.",
    ),
    live_resolution: Optional[float] = typer.Option(
        None,
        "--live-resolution",
        help="With --for live: grid spacing of the liveness measurement (map units, > 0); "
        "None means about 25 points in the median cell, at most 0.01·D.",
    ),
    quiet: bool = QUIET,
    as_json: bool = JSON,
) -> None:
    """Propose tag positions so that a camera looking along the fields sees a usable pair in the certified area.

    With --for live, so that every cell is live instead: a look all around brings the set
    estimator's error bound below what the cell tolerates (the fix rule is the default).

    The tags go on obstacle and wall boundaries, facing the free side, a tag's width apart; the
    existing tags stay. Writes the map with the new tags and a figure of where to glue them; the
    cells do not depend on the tags, so re-planning with the new map only changes the gains.

    Example: bearnav tags plans/kitchen/plan.npz --fov 60 --noise-deg 1 -o kitchen_tags.yaml
    """
    import yaml

    from bearnav_cli import artifacts, composition, pipeline, tags
    from bearnav_cli.stages import map_

    Quiet.enabled |= quiet
    if out_path is None:  # a new file: the map given stays as it is
        out_path = tags_output(plan_npz, map_yaml)
    artifacts.check_output_file(
        out_path, (".yaml", ".yml"), "-o/--out", inputs=tuple(p for p in (plan_npz, map_yaml) if p is not None)
    )
    artifacts.check_overwrite(out_path, "tags", force=force)
    figure = figure or out_path.with_suffix(".png")
    artifacts.check_output_file(figure, FIGURE_SUFFIXES, "--figure")
    artifacts.check_distinct({"-o/--out": out_path, "--figure": figure})
    options = {
        **CAMERA_OPTIONS,
        "error_target": "--error-target",
        "max_tags": "--max-tags",
        "target": "--for",
        "eta_deg": "--bearing-error-deg",
        "kappa": "--slip",
        "resolution": "--live-resolution",
    }
    if target != "live" and (bearing_error_deg is not None or slip is not None or live_resolution is not None):
        raise fail("--bearing-error-deg, --slip and --live-resolution are for --for live", EXIT_INVALID)
    try:
        params = tags.Params(
            fov_deg=fov,
            max_range=float("inf") if max_range is None else max_range,
            noise_deg=noise_deg,
            error_target=error_target,
            max_tags=max_tags,
            target=target,
            bearing_error_deg=bearing_error_deg,
            slip=slip,
            resolution=live_resolution,
        )
    except InvalidParamsError as exc:  # name the option the user typed
        raise fail(f"{options.get(exc.field, exc.field)}: {exc.reason}", EXIT_INVALID) from None
    with pipeline.activity("tags"):  # what an interrupt, an error or a warning names
        plan = pipeline.load(plan_npz, "plan").artifact
        spec = map_.spec_of(plan.map)
        original = None  # the YAML text the user wrote, kept as it is in the new map
        grid = None  # the occupancy grid the new map names, when it keeps the map's own text
        if map_yaml is not None and is_bare_grid(map_yaml):
            # a bare map_server YAML holds no goal, tags or robot: the new map wraps the grid (occupancy:, its
            # path relative to the new map) and takes the rest from the plan's map, so the PGM stays a PGM
            import os

            grid, _ = read_grid(map_yaml, str(map_yaml), "--map")
            wrapped = {key: value for key, value in spec.items() if key not in ("name", "bounds", "obstacles")}
            spec = {"name": spec["name"], "occupancy": os.path.relpath(map_yaml, out_path.resolve().parent), **wrapped}
            wrapper = map_.MapSource(spec=spec, file=str(out_path), sha256="", grid=grid)
            problem = composition.map_frame_problem(plan.map, map_.run(wrapper))
            if problem:
                raise fail(f"{map_yaml}: {problem}: not the plan's occupancy grid", EXIT_INVALID)
        elif map_yaml is not None:
            source = read_map_source(map_yaml)
            problem = composition.map_frame_problem(plan.map, map_.run(source))
            if problem:
                raise fail(f"{map_yaml}: {problem}: not the plan's map", EXIT_INVALID)
            grid_elsewhere = "occupancy" in source.spec and map_yaml.resolve().parent != out_path.resolve().parent
            spec = spec if grid_elsewhere else source.spec  # an occupancy image path is relative to its YAML
            grid = None if grid_elsewhere else source.grid
            bare_grid = source.grid is not None and "occupancy" not in source.spec  # its spec comes from options
            if not grid_elsewhere and not bare_grid:
                original = read_bytes(map_yaml).decode("utf-8", errors="replace")
        try:
            proposal = tags.propose(plan, params)
        except InvalidParamsError as exc:  # liveness's own checks: η, the slip, a paper plan
            where = "" if exc.field == "plan" else f"{options.get(exc.field, exc.field)}: "
            raise fail(f"{plan_npz}: {where}{exc.reason}", EXIT_INVALID) from None
        # another name: re-planning it makes its own folder
        name = tags.tagged_name(str(spec.get("name", plan.map.name)))
        new_spec = tags.map_spec_with_tags(spec, proposal)
        new_spec = {"name": name, **{key: value for key, value in new_spec.items() if key != "name"}}
        map_.run(map_.MapSource(spec=new_spec, file=str(out_path), sha256="", grid=grid))  # the map stage accepts it
        header = (
            f"{artifacts.TAGS_MARKER} {proposal.count} new tags for a {fov:g}° camera, from {plan_npz} "
            f"(and {map_yaml or 'its map'}); plan it with `bearnav plan {out_path}`"
        )
        text = tags.map_text_with_tags(original, proposal, name, header) if original is not None else None
        if text is not None:
            try:
                kept = yaml.safe_load(text)
            except yaml.YAMLError:
                kept = None
            meant = dict(yaml.safe_load(original), name=name, landmarks=new_spec["landmarks"])
            if kept != meant:
                text = None  # a layout the text edit got wrong: the map is written afresh (its comments are lost)
        if text is None:
            if original is not None and not Quiet.enabled:
                err.print(
                    f"[yellow]warning:[/yellow] {out_path}: bearnav cannot extend the landmarks of {map_yaml} "
                    "where they are; the map is written afresh, without its comments",
                    highlight=False,
                    soft_wrap=True,
                )
            text = header + "\n" + yaml.safe_dump(new_spec, sort_keys=False, default_flow_style=None)
        artifacts.atomic_write(out_path, lambda f: f.write(text.encode()))
        plot = plotting()  # matplotlib is slow to import: only here

        fig = plot.tags_figure(proposal, plan.map)  # its title states the camera, the noise and the coverage
        with artifacts.atomic_output(figure) as tmp:
            plot.save_figure(fig, str(tmp))
    if as_json:
        print_json(
            {
                "map": str(out_path),
                "figure": str(figure),
                "new_tags": proposal.count,
                "lower_bound": proposal.lower_bound,
                "ids": list(proposal.ids),
                "positions": [[float(v) for v in p] for p in proposal.positions],
                "target_reached": proposal.target_reached,
                "domain_before": proposal.before.fraction_domain,
                "domain_after": proposal.after.fraction_domain,
                "free_before": proposal.before.fraction_free,
                "free_after": proposal.after.fraction_free,
                "for": target,
                **(
                    {
                        "live_before": proposal.live_before.live_fraction,
                        "live_after": proposal.live_after.live_fraction,
                        "eta_deg": math.degrees(proposal.live_after.grid.eta),
                        "eta_star_deg_before": math.degrees(proposal.live_before.eta_star),
                        "eta_star_deg_after": math.degrees(proposal.live_after.eta_star),
                    }
                    if proposal.live_after is not None
                    else {}
                ),
            }
        )
    else:
        out.print(f"tags      {out_path}  {proposal.summary()}", highlight=False, soft_wrap=True)
        if not Quiet.enabled:
            out.print(
                f"wrote {out_path} and {figure}; re-plan with `{command_text('bearnav', 'plan', out_path)}`",
                highlight=False,
                soft_wrap=True,
            )
    if not proposal.target_reached and proposal.live_after is not None:
        from bearnav_cli.datatypes import percent

        live = proposal.live_after
        why = (
            f"--max-tags {max_tags} allowed too few"
            if max_tags is not None and proposal.count >= max_tags
            else "no tag makes the grey points live: their cells tolerate less than any look gives (a smaller "
            "--bearing-error-deg, the heading from the bearings, or a plan with larger tolerances)"
        )
        raise fail(
            f"{len(live.live) - live.n_live} cells are still not live ({percent(1.0 - live.live_fraction)} of "
            f"the certified area): {why}; {out_path} has the tags placed",
            EXIT_OUTCOME,
        )
    if not proposal.target_reached:
        from bearnav_cli.datatypes import percent

        short = 1.0 - proposal.after.fraction_domain
        if max_tags is not None and proposal.count >= max_tags:
            again = command_text(
                "bearnav",
                "tags",
                plan_npz,
                *camera_words(fov, max_range),
                *(["--noise-deg", f"{noise_deg:g}"] if noise_deg != 1.0 else []),
                *(["--error-target", f"{error_target:g}"] if error_target is not None else []),
                *(["--map", map_yaml] if map_yaml is not None else []),
                "-o",
                out_path,
            )
            fix = (
                f"--max-tags {max_tags} allowed too few (at least {proposal.lower_bound} are needed); "
                f"`{again}` places as many as the rule needs"
            )
        else:
            fix = (
                "the rest sees no wall or obstacle a tag could go on in view: a wider --fov, a longer "
                "--range or a lower --error-target"
            )
        raise fail(
            f"two usable tags are still not in view on {percent(short)} of the certified area: {fix}; "
            f"{out_path} has the tags placed",
            EXIT_OUTCOME,
        )
