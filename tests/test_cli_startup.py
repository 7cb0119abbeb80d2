"""Start-up (issue 14, item 10): ``--help`` and ``inspect`` import only what they need.

Checked on the modules a fresh interpreter holds afterwards, never on timing (bench/README.md
"Start-up" has the times): importing the CLI and every ``--help`` leave numpy, the stages, the
pipeline, logging and rich (typer's rich help formatter, the consoles) out, and a command's options
are generated from its ``Params`` only when that command runs; ``inspect`` of any
artifact imports numpy, shapely (the map's polygons are checked with it) and the loader, not scipy,
highspy, matplotlib or yaml, and of the stages only those whose parameters the artifact's map sets
in ``params:`` (to check them).
"""

from __future__ import annotations

import copy
import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from bearnav_cli.cli import app
from bearnav_cli.cli.main import COMMANDS
from bearnav_cli.cli.plan import PLAN_OPTIONS

from .conftest import REPO, SMALL_MAP

#: Never imported by ``--help`` or ``inspect``.
HEAVY = ("scipy", "highspy", "matplotlib", "yaml", "PIL", "cv2", "rosbags", "typer.rich_utils")
#: Not imported by ``--help`` either (``inspect`` needs them: the artifact, its checks, the printed summary).
NOT_FOR_HELP = (
    *HEAVY,
    "numpy",
    "shapely",
    "rich",
    "logging",
    "bearnav_cli.pipeline",
    "bearnav_cli.artifacts",
    "bearnav_cli.datatypes",
    "bearnav_cli.runtime",
    "bearnav_cli.stages",
)
#: Modules of those packages that import no numpy: the choices and defaults a ``Params`` declaration shows, and
#: the packages' lazy names.
NUMPY_FREE = ("bearnav_cli.runtime", "bearnav_cli.runtime.defaults", "bearnav_cli.runtime.lazy")
#: The command modules (:data:`bearnav_cli.cli.main.COMMANDS`), each imported only by its commands.
COMMAND_MODULES = {f"bearnav_cli.cli.{module}" for module, _function in COMMANDS.values()}
#: Each artifact kind the map stage and the planning stages write, and the simulation.
ARTIFACTS = ("map.json", "tree.npz", "simplified.npz", "cells.npz", "plan.npz", "sim.npz")

#: Runs ``bearnav ARGS...`` for each argument list in ``sys.argv[1]`` (JSON) in this one process, the
#: output thrown away; prints the exit codes, every module imported and the commands whose ``Params`` were
#: read for their options (JSON).
RUN = """
import contextlib, io, json, sys
from bearnav_cli.cli import app, options

read = []
fields = options.params_fields
options.params_fields = lambda command: read.append(command) or fields(command)

codes = []
for args in json.loads(sys.argv[1]):
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            app(args, prog_name="bearnav")
        except SystemExit as exc:
            codes.append(exc.code)
print(json.dumps({"codes": codes, "modules": sorted(sys.modules), "params": sorted(set(read))}))
"""


def run(*commands: list[str], params: list[str] | None = None) -> tuple[list[int], set[str]]:
    """Exit codes of the commands, run one after the other in a fresh interpreter, and the modules it imported;
    with ``params``, also checks which commands' ``Params`` were read for their options."""
    done = subprocess.run(
        [sys.executable, "-c", RUN, json.dumps([[str(a) for a in c] for c in commands])],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    if params is not None:
        assert result["params"] == params, result["params"]
    return result["codes"], set(result["modules"])


def imported(modules: set[str], names: tuple[str, ...]) -> list[str]:
    """The modules of ``modules`` that are one of ``names`` or inside one of them."""
    return sorted(m for m in modules if any(m == name or m.startswith(name + ".") for name in names))


@pytest.fixture(scope="module")
def plans(tmp_path_factory) -> dict[str, Path]:
    """``{"bare": folder, "params": folder}``: the small map planned and simulated without a ``params:``
    section (its rrtstar settings given as options) and with its ``params: rrtstar:``."""
    root = tmp_path_factory.mktemp("startup")
    runner = CliRunner()
    folders = {}
    bare = copy.deepcopy(SMALL_MAP)
    rrtstar = bare.pop("params")["rrtstar"]
    for name, spec, options in (("bare", bare, [f"--{k}={v}" for k, v in rrtstar.items()]), ("params", SMALL_MAP, [])):
        path = root / f"{name}.yaml"
        path.write_text(yaml.safe_dump(spec, sort_keys=False))
        folder = root / name
        result = runner.invoke(app, ["-q", "plan", str(path), "-o", str(folder), *options])
        assert result.exit_code == 0, result.output
        result = runner.invoke(
            app, ["-q", "simulate", str(folder / "plan.npz"), "--starts", "random:3", "--min-success", "0"]
        )
        assert result.exit_code == 0, result.output
        folders[name] = folder
    return folders


def test_importing_the_cli_and_every_help_import_no_numpy_rich_or_stage():
    commands = [["--help"], ["--version"], []]  # bare `bearnav` prints the help too (exit 2)
    commands += [
        [name, "--help"]
        for name in (
            "map",
            "rrtstar",
            "simplify",
            "decompose",
            "synthesize",
            "verify",
            "simulate",
            "plan",
            "inspect",
            "tags",
            "plot",
        )
    ]
    codes, modules = run(*commands)
    assert codes == [0, 0, 2] + [0] * (len(commands) - 3)
    # typer.rich_utils among them: typer's rich help imports rich.markdown and pygments, 0.1 s of every --help
    found = [m for m in imported(modules, NOT_FOR_HELP) if m not in NUMPY_FREE]
    assert not found, found


def test_the_options_from_params_are_made_for_the_command_run_only():
    """``bearnav --help`` reads no ``Params`` source, ``bearnav simulate --help`` simulate's only."""
    assert run(["--help"], ["--version"], [], params=[])[0] == [0, 0, 2]
    assert run(["simulate", "--help"], params=["simulate"])[0] == [0]
    assert run(["verify", "--help"], params=["verify"])[0] == [0]
    assert run(["plan", "--help"], params=sorted(PLAN_OPTIONS))[0] == [0]


def test_help_is_plain_text_with_the_options_defaults_and_examples():
    result = CliRunner().invoke(app, ["simulate", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    text = result.output
    assert "╭" not in text and "\\[" not in text and "\x1b[" not in text
    assert "Example: bearnav simulate plans/kitchen/plan.npz --fov 60 --dynamics unicycle" in text
    assert "--fov <float>" in text and "(default: 360)" in text and "[default: 1.0]" in text  # --min-success
    alpha = next(line for line in text.splitlines() if "--alpha" in line)
    beta = next(line for line in text.splitlines() if "--beta" in line)
    assert "forward gain" in alpha and "turn gain" not in alpha, alpha
    assert "turn gain" in beta and "forward gain" not in beta, beta
    plain = CliRunner().invoke(app, [])
    assert plain.exit_code == 2 and "[OPTIONS] COMMAND [ARGS]" in plain.output and "inspect" in plain.output


def test_usage_errors_keep_their_panel():
    result = CliRunner().invoke(app, ["plan"])
    assert result.exit_code == 2
    assert "Missing argument 'MAP'" in result.output and "╭─ Error" in result.output


def test_inspect_imports_the_loader_and_numpy_only(plans):
    codes, modules = run(
        *(["inspect", plans["bare"] / name] for name in ARTIFACTS),
        ["inspect", plans["bare"] / "plan.npz", "--cell", "0"],
        params=[],
    )
    assert codes == [0] * (len(ARTIFACTS) + 1)
    found = imported(modules, (*HEAVY, "bearnav_cli.stages", "bearnav_cli.verify", "bearnav_cli.geometry"))
    assert not found, found
    assert "numpy" in modules and "bearnav_cli.artifacts" in modules  # the check is the loader's, as before
    runtime = imported(modules, ("bearnav_cli.runtime",))
    # the schema, the robot section's defaults the map type reads, and the one copy of the file reader
    # and the invariants the robot's loader shares (numpy only, no controller); not the defaults the declared
    # ``Params`` show: no command's ``Params`` is read (``limits`` reads one on first use)
    assert runtime == [
        "bearnav_cli.runtime",
        "bearnav_cli.runtime.invariants",
        "bearnav_cli.runtime.lazy",
        "bearnav_cli.runtime.plan_file",
        "bearnav_cli.runtime.robot",
        "bearnav_cli.runtime.schema",
    ], runtime


def test_a_stage_command_imports_its_own_command_module_and_stage_only(plans, tmp_path):
    """``bearnav rrtstar`` (whose whole process bench/rrtstar_process.py times against OMPL's) imports the
    command module ``stage`` and no other command's, and of the stages rrtstar only."""
    codes, modules = run(
        ["-q", "rrtstar", plans["bare"] / "map.json", "-o", tmp_path / "tree.npz", "--iterations", "50"],
        params=["rrtstar"],
    )
    assert codes == [0]
    commands = imported(modules, ("bearnav_cli.cli",))
    assert not [m for m in commands if m in COMMAND_MODULES and m != "bearnav_cli.cli.stage"], commands
    assert imported(modules, ("bearnav_cli.stages",)) == ["bearnav_cli.stages", "bearnav_cli.stages.rrtstar"]
    # the ranges of rrtstar's options only (limits.LIMITS reads a command's Params on first use), and the map
    # stage's circle segments, which the geometry shares
    params = imported(modules, ("bearnav_cli.params",))
    assert params == [
        "bearnav_cli.params",
        "bearnav_cli.params.declare",
        "bearnav_cli.params.map_",
        "bearnav_cli.params.rrtstar",
    ], params
    # a map in, a tree out: the datatypes of the map and the tree (and the shared helpers), not the cells' or the
    # simulation's (bearnav_cli.datatypes imports a module when one of its names is first used)
    datatypes = imported(modules, ("bearnav_cli.datatypes",))
    assert datatypes == [
        "bearnav_cli.datatypes",
        "bearnav_cli.datatypes.frozen",
        "bearnav_cli.datatypes.kinds",
        "bearnav_cli.datatypes.map_",
        "bearnav_cli.datatypes.tree",
        "bearnav_cli.datatypes.words",
    ], datatypes
    found = imported(modules, HEAVY)
    assert not found, found


def test_inspect_imports_the_stages_the_maps_params_name(plans):
    """The small map sets ``params: rrtstar:``: checking them needs ``rrtstar.Params``, and no other stage."""
    codes, modules = run(*(["inspect", plans["params"] / name] for name in ARTIFACTS))
    assert codes == [0] * len(ARTIFACTS)
    assert imported(modules, ("bearnav_cli.stages",)) == ["bearnav_cli.stages", "bearnav_cli.stages.rrtstar"]
    found = imported(modules, HEAVY)
    assert not found, found


#: A program that runs the app after registering an ``atexit`` function (unflushed output) and keeping an
#: object that says when the interpreter tears it down.
PROGRAM = """
import atexit
class Teardown:
    def __del__(self):
        print("torn down", flush=True)
kept = Teardown()
atexit.register(lambda: print("atexit ran"))
from bearnav_cli.cli import app
app()
"""


def run_named(tmp_path: Path, source: str, *args: str) -> list[tuple[bool, subprocess.CompletedProcess]]:
    """``source`` run as a program named ``bearnav`` (the ``bearnav`` program) and as ``other.py`` (a program that
    uses the app), with ``args``: ``[(True, done), (False, done)]``."""
    runs = []
    for name in ("bearnav", "other.py"):
        program = tmp_path / name
        program.write_text(source)
        done = subprocess.run([sys.executable, str(program), *args], capture_output=True, text=True, cwd=tmp_path)
        runs.append((name == "bearnav", done))
    return runs


@pytest.mark.parametrize("args, code", [(["--version"], 0), (["nope"], 2), (["inspect", "missing.npz"], 3)])
def test_the_program_ends_without_the_interpreters_teardown(tmp_path, args, code):
    """Run as ``bearnav``, the app ends once its command is done: the ``atexit`` functions run and stdout is
    flushed, the modules and objects are not torn down (bench/README.md "RRT* as whole processes"); called from
    another program (a test, a library) it leaves the exit to Python."""
    for as_program, done in run_named(tmp_path, PROGRAM, *args):
        assert done.returncode == code, (as_program, done.stderr)
        teardown = "" if as_program else "torn down\n"
        assert done.stdout.endswith("atexit ran\n" + teardown), (as_program, done.stdout)


#: A program that reports whether the garbage collector runs while a command does its work.
COLLECTOR = """
import atexit, gc, sys
import bearnav_cli.pipeline as pipeline
from bearnav_cli.cli import app
seen = []
real = pipeline.reset_activity
def spy(*args, **kwargs):
    seen.append(gc.isenabled())
    return real(*args, **kwargs)
pipeline.reset_activity = spy
importing = gc.isenabled()
atexit.register(lambda: print("importing", importing, "command", seen, "frozen", gc.get_freeze_count() > 0,
                              file=sys.stderr, flush=True))
app()
"""


def test_the_program_collects_no_garbage_while_it_imports(tmp_path, plans):
    """Run as ``bearnav``, the collector is off while Python imports (nothing it makes is garbage) and back on,
    with the start-up's objects frozen, when the command works; a test or a library keeps its collector."""
    for as_program, done in run_named(tmp_path, COLLECTOR, "inspect", str(plans["bare"] / "plan.npz")):
        assert done.returncode == 0, (as_program, done.stderr)
        expected = f"importing {not as_program} command [True] frozen {as_program}"
        assert expected in done.stderr, (as_program, done.stderr)
