"""The command-line options are generated from the ``Params`` dataclasses (issue 14, items 2 and 10).

For every command and every ``Params`` field with an option: the option's name, type, default and
help agree with the dataclass and its docstring; a field whose docstring entry is gone fails.
``import bearnav_cli.cli`` reads the ``Params`` from the sources, so it imports none of numpy,
scipy, shapely, highspy or matplotlib; what it reads equals the imported dataclasses. The control
settings have one builder and one set of defaults (simulate and the robot's Controller), and
``bearnav verify`` and ``verify.run`` drive the loop at the same speed.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import math
import subprocess
import sys

import pytest
import typer.main

from bearnav_cli import limits, pipeline, runtime, verify
from bearnav_cli.cli import app
from bearnav_cli.cli import fields as cli_fields
from bearnav_cli.cli import options as cli_options
from bearnav_cli.cli.plan import PLAN_OPTIONS
from bearnav_cli.runtime import settings
from bearnav_cli.stages import simulate

from .conftest import REPO

#: command -> (the stages whose options it takes, fields it takes or None for all but PARAMS_ONLY)
COMMANDS = {
    "map": {"map": None}, "rrtstar": {"rrtstar": None}, "simplify": {"simplify": None},
    "decompose": {"decompose": None}, "synthesize": {"synthesize": None}, "simulate": {"simulate": None},
    "verify": {"verify": None}, "plan": {stage: names for stage, names in PLAN_OPTIONS.items()},
}  # fmt: skip


def click_command(name: str):
    group = typer.main.get_command(app)
    return group.commands[name]


def expected_fields(command: str) -> list[tuple[str, cli_fields.ParamField]]:
    out = []
    for stage, names in COMMANDS[command].items():
        for field in cli_fields.params_fields(stage):
            if (names is None and field.name not in cli_fields.PARAMS_ONLY[stage]) or (names and field.name in names):
                out.append((stage, field))
    return out


def problems(command: str, fields: list[tuple[str, cli_fields.ParamField]]) -> list[str]:
    """What disagrees between a command's options and the fields (and their docstring entries)."""
    found = []
    options = {p.name: p for p in click_command(command).params if p.param_type_name == "option"}
    for stage, field in fields:
        where = f"{command} {stage}.{field.name}"
        if not field.doc.strip():
            found.append(f"{where}: no docstring entry under Attributes")
            continue
        option = options.get(field.name)
        if option is None:
            found.append(f"{where}: no option")
            continue
        name = limits.option_name(stage, field.name)
        if name not in option.opts:
            found.append(f"{where}: option {option.opts}, expected {name}")
        if field.kind is bool and not option.secondary_opts:
            found.append(f"{where}: a bool field needs an on/off flag")
        default = field.default if command == "verify" else None
        if option.default != default:
            found.append(f"{where}: option default {option.default!r}, expected {default!r}")
        first_words = cli_options._plain(field.doc).split()[:4]
        if option.help is None or " ".join(first_words).rstrip(".") not in option.help:
            found.append(f"{where}: help {option.help!r} does not start from the docstring")
        shown = cli_options.shown_value(field.default)
        if command != "verify" and field.default is not None and shown not in option.help and field.kind is not bool:
            found.append(f"{where}: help does not give the default {field.default!r}")
        kind = {int: "int", float: "float", str: "str"}.get(field.kind)
        if kind is not None and option.type.name != kind:
            found.append(f"{where}: option type {option.type.name}, expected {kind}")
    return found


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_field_has_its_option(command):
    assert not problems(command, expected_fields(command)), "\n".join(problems(command, expected_fields(command)))


def test_a_field_without_its_docstring_entry_fails():
    """Remove ``iterations`` from rrtstar.Params' docstring: the check reports it."""
    doc = importlib.import_module("bearnav_cli.stages.rrtstar").Params.__doc__
    without = doc.replace("    iterations : int\n        Random samples drawn, collision samples included.\n", "")
    assert without != doc
    docs = cli_fields._attribute_docs(without)
    fields = [
        (stage, dataclasses.replace(f, doc=docs.get(f.name, ("", ()))[0])) for stage, f in expected_fields("rrtstar")
    ]
    assert problems("rrtstar", fields) == ["rrtstar rrtstar.iterations: no docstring entry under Attributes"]


def test_the_fields_are_the_imported_dataclasses():
    for command in cli_fields.PARAMS_MODULES:
        params_type = importlib.import_module(cli_fields.PARAMS_MODULES[command]).Params
        assert [f.name for f in cli_fields.params_fields(command)] == [f.name for f in dataclasses.fields(params_type)]


def test_every_option_is_a_field_or_hand_written():
    """The generated options are exactly the fields; the hand-written ones are not fields."""
    hand_written = {
        "out_path",
        "out_dir",
        "force",
        "quiet",
        "as_json",
        "goal",
        "landmark",
        "start",
        "robot_radius",
        "lookahead",
        "min_success",
        "gif",
        "bag",
        "tree",
        "world",
        "fov",
        "noise_deg",
        "max_range",
        "help",
        # plan's error bounds: the map's robot section, spelled as simulate's fields are
        "bearing_error_deg",
        "compass_error_deg",
        "slip",
        "slip_floor",
    }
    for command in COMMANDS:
        names = {p.name for p in click_command(command).params if p.param_type_name == "option"}
        fields = {f.name for _, f in expected_fields(command)}
        assert names - fields <= hand_written, (command, names - fields - hand_written)


def test_choices_are_the_values_params_accepts():
    for command in cli_fields.PARAMS_MODULES:
        params_type = importlib.import_module(cli_fields.PARAMS_MODULES[command]).Params
        for field in cli_fields.params_fields(command):
            if not field.choices:
                continue
            for choice in field.choices:
                params_type(**{field.name: choice})
            if (command, field.name) != ("map", "unknown"):  # checked when a grid is read
                with pytest.raises(ValueError):
                    params_type(**{field.name: "no-such-choice"})


def test_odometry_drift_is_an_option_passed_to_the_filter():
    assert "--odometry-drift" in {o for p in click_command("simulate").params for o in p.opts}
    plan = verify_plan_fixture_free()
    assert simulate.settings(plan, simulate.Params(odometry_drift=0.2)).control.odometry_drift == 0.2
    with pytest.raises(ValueError):
        simulate.Params(odometry_drift=-1.0)


def verify_plan_fixture_free():
    from .handmade import hand_map, hand_plan

    return hand_plan(hand_map())


# --------------------------------------------------------------------------- the control settings


def test_simulate_and_the_controller_build_their_settings_alike(tmp_path):
    """One builder, one set of defaults: the Controller's settings are simulate's for the same options."""
    from .handmade import write_plan

    plan = verify_plan_fixture_free()
    path = tmp_path / "plan.npz"
    write_plan(path, plan)
    robot = runtime.Controller.from_plan(str(path)).settings
    sim = simulate.settings(plan, simulate.Params(noise_deg=1.0)).control
    assert robot == sim
    assert robot.bearing_sigma == settings.BEARING_SIGMA == math.radians(1.0)
    assert robot.speed == simulate.Params().speed == settings.SPEED
    assert robot.alpha == simulate.Params().alpha == settings.ALPHA
    assert robot.odometry_drift == simulate.Params().odometry_drift == settings.ODOMETRY_DRIFT
    unicycle = runtime.Controller.from_plan(str(path), dynamics="unicycle", alpha=0.3).settings
    assert unicycle == simulate.settings(plan, simulate.Params(noise_deg=1.0, dynamics="unicycle", alpha=0.3)).control


def test_verify_and_its_command_drive_at_the_maps_speed(cli, small_spec, write_map, tmp_path):
    small_spec["params"]["simulate"] = {"speed": 0.2}
    folder = tmp_path / "p"
    result = cli("-q", "plan", write_map(small_spec), "-o", folder)
    assert result.exit_code == 0, result.output
    result = cli("verify", folder / "plan.npz", "--starts", "3", "--json")
    assert result.exit_code in (0, 1), result.output
    from_cli = json.loads(result.output)["monte_carlo"]["speed"]
    plan = pipeline.load(folder / "plan.npz", "plan").artifact
    report = verify.run(plan, verify.Params(n_starts=3))
    assert from_cli == report.rollouts.speed == verify.loop_speed(plan, verify.Params()) == 0.2
    assert verify.loop_speed(plan, verify.Params(speed=0.3)) == 0.3
    plan_without = dataclasses.replace(
        plan, cells=dataclasses.replace(plan.cells, map=dataclasses.replace(plan.map, params={}))
    )
    assert verify.loop_speed(plan_without, verify.Params()) == simulate.Params().speed


# --------------------------------------------------------------------------- start-up


def test_importing_the_cli_imports_no_heavy_library():
    heavy = ("numpy", "scipy", "shapely", "highspy", "matplotlib", "yaml")
    code = f"import bearnav_cli.cli, sys; print(sorted(m for m in sys.modules if m.split('.')[0] in {set(heavy)!r}))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    assert out.stdout.strip() == "[]", out.stdout
    code = (
        "import bearnav_cli.cli, json, sys; "
        "print(json.dumps(sorted(m for m in sys.modules if m.startswith('bearnav_cli.'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    modules = json.loads(out.stdout)
    # the app and its command table, the exits, the output and the map reader the package exports, and the
    # errors: no command's module (each is imported when its command runs, shows its help or completes)
    assert modules == [
        "bearnav_cli.cli",
        "bearnav_cli.cli.exits",
        "bearnav_cli.cli.main",
        "bearnav_cli.cli.mapfile",
        "bearnav_cli.cli.output",
        "bearnav_cli.cli.startup",
        "bearnav_cli.errors",
    ], modules


def test_help_builds_without_importing_the_stages():
    code = (
        "import sys; from typer.testing import CliRunner; from bearnav_cli.cli import app; "
        "r = CliRunner().invoke(app, ['simulate', '--help']); assert r.exit_code == 0, r.output; "
        "assert '--odometry-drift' in r.output; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in {'numpy', 'scipy', 'shapely'}))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout
