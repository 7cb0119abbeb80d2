"""Issue 23 item 2: every failed outcome names its likely cause and the next command, with the real files.

The hints are commands a user pastes as printed: the tests parse them out of the message and run
them, so a hint that names a placeholder (``PLAN.npz``), a file that is not there or an option the
command does not take fails here.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shlex
from pathlib import Path

import pytest

from .test_cli_errors import assert_one_line_error

#: A map whose two landmarks both sit left of the one obstacle: the free space behind it sees neither
#: (a blind spot, so `plan` exits 1); small and few iterations, so that planning it takes a tenth of a second.
BLIND_MAP = {
    "name": "blind",
    "bounds": [0, 0, 4, 3],
    "robot_radius": 0.1,
    "goal": [0.5, 0.5],
    "obstacles": [{"rectangle": [1.5, 1, 2.5, 2]}],
    "landmarks": [[0, 3], [0, 0]],
    "params": {"rrtstar": {"iterations": 150, "seed": 0}},
}


def error_line(result) -> str:
    lines = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, result.output
    return lines[0]


def commands(text: str) -> list[list[str]]:
    """The ``bearnav ...`` commands quoted in a message, as argument lists (``bearnav`` left out)."""
    return [shlex.split(code)[1:] for code in re.findall(r"`([^`]+)`", text) if code.startswith("bearnav ")]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """The small plan (and a 5-run simulation) the CLI tests share."""
    from .test_hostile_common import small_plan

    return small_plan(tmp_path_factory.mktemp("hints"))


@pytest.fixture
def blind_plan(cli, write_map):
    """``bearnav plan blind.yaml`` run from the scratch folder, as a user types it: exit 1, files written."""
    write_map(BLIND_MAP, "blind.yaml")
    result = cli("plan", "blind.yaml")
    assert result.exit_code == 1, result.output
    return result


def test_the_blind_spot_hint_runs_as_printed_and_its_map_plans_past_the_check(cli, blind_plan, tmp_path):
    line = error_line(blind_plan)
    assert "fewer than 2 landmarks" in line and "PLAN" not in line, line
    tags, plan = commands(line)
    assert tags[:2] == ["tags", "plans/blind/plan.npz"] and "--map" in tags and "blind.yaml" in tags, line
    assert (tmp_path / "plans" / "blind" / "plan.npz").is_file()  # the plan the hint names was written
    ran = cli(*tags)
    assert ran.exit_code == 0, ran.output
    assert plan[0] == "plan" and (tmp_path / plan[1]).is_file(), line  # the map the hint says tags writes
    replanned = cli(*plan)
    assert replanned.exit_code == 0, replanned.output
    assert "blind spot" not in replanned.output and "error:" not in replanned.output, replanned.output
    # issue 23 item 3: a plan that passes ends with what is certified, for which robot, and what proves it
    sentence = next(line for line in replanned.output.splitlines() if "guarantee" in line)
    assert "radius 0.1" in sentence and "certified area" in sentence and "camera is not checked" in sentence
    (verify,) = commands(sentence)
    assert verify[0] == "verify" and (tmp_path / verify[1]).is_file() and verify[1].endswith("plan.npz"), sentence
    assert "§" not in sentence and "δ" not in sentence, sentence


def test_plan_fov_checks_the_camera_and_hints_with_its_options(cli, write_map, tmp_path):
    # a tag in every corner: no blind spot, but a 60° camera of range 3 looking along the field misses pairs
    write_map(dict(BLIND_MAP, name="corners", landmarks=[[0, 3], [0, 0], [4, 0], [4, 3]]), "corners.yaml")
    result = cli("plan", "corners.yaml", "--fov", "60", "--range", "3", "--slip", "0.05")
    assert result.exit_code == 1, result.output
    assert "perception:" in result.output and "60° camera, range 3" in result.output, result.output
    assert "δ*" not in result.output and "nothing here proves" in result.output, result.output  # says why runs succeed
    line = error_line(result)
    tags, plan = commands(line)
    assert tags[:2] == ["tags", "plans/corners/plan.npz"] and "corners.yaml" in tags, line
    assert tags[tags.index("--fov") + 1] == "60" and tags[tags.index("--range") + 1] == "3", line
    # the re-planning command keeps the camera and the robot bound the user gave
    assert plan[:2] == ["plan", "corners_tags.yaml"], line
    assert plan[plan.index("--fov") + 1] == "60" and plan[plan.index("--slip") + 1] == "0.05", line
    from bearnav_cli import artifacts

    robot = artifacts.load(tmp_path / "plans" / "corners" / "plan.npz").artifact.map.robot
    assert robot["slip"] == 0.05  # --slip went into the plan's robot section
    assert cli("plan", "corners.yaml", "--slip", "0.05").exit_code == 0  # without a camera: no perception check


@pytest.mark.parametrize(
    "args, option",
    [(("--range", "3"), "--range"), (("--noise-deg", "1"), "--noise-deg"), (("--fov", "0"), "--fov"),
     (("--slip", "-1"), "--slip"), (("--bearing-error-deg", "95"), "--bearing-error-deg")],
)  # fmt: skip
def test_plan_refuses_a_bad_camera_or_robot_bound_naming_the_option(cli, write_map, tmp_path, args, option):
    write_map(BLIND_MAP, "blind.yaml")
    assert_one_line_error(cli("plan", "blind.yaml", *args), option)
    assert not (tmp_path / "plans" / "blind" / "plan.npz").exists()


def test_a_retired_artifact_names_the_command_that_remakes_it_from_its_own_files(cli, built, tmp_path):
    from .test_hostile_common import copy_plan, rewrite_npz

    folder = copy_plan(built, tmp_path / "old")  # the map YAML stays behind: the map.json beside the plan is named

    def retire(schema):
        return lambda manifest, entries: manifest.update(schema=schema)

    plan = rewrite_npz(folder / "plan.npz", folder / "plan.npz", retire("bearnav.plan/2"), rehashed=False)
    line = error_line(cli("inspect", plan))
    assert f"`bearnav plan {folder / 'map.json'} --force` to get bearnav.plan/3" in line, line
    sim = rewrite_npz(folder / "sim.npz", folder / "sim.npz", retire("bearnav.sim/1"), rehashed=False)
    line = error_line(cli("inspect", sim))
    assert f"`bearnav simulate {folder / 'plan.npz'} --force`" in line and "PLAN" not in line, line


# --------------------------------------------------------------------------- item 6: messages that are right


@pytest.mark.parametrize(
    "start, words",
    [("-1,2", ("outside the bounds [0, 10]",)), ("0.15,2", ("within the robot radius 0.2 of a wall", "[0.2, 9.8]")),
     ("3.9,4.5", ("inside an obstacle grown by the robot radius 0.2",))],
)  # fmt: skip
def test_a_start_near_a_wall_or_an_obstacle_is_told_apart_from_one_outside(cli, built, tmp_path, start, words):
    result = cli("simulate", built["plan"], "--starts", start, "-o", tmp_path / "s" / "sim.npz")
    assert_one_line_error(result, f"start 0 ({start.replace(',', ', ')})", *words)
    assert "outside the bounds" not in error_line(result) or start == "-1,2"


def test_a_goal_outside_the_free_space_names_the_inflation(cli, write_map):
    spec = dict(BLIND_MAP, goal=[0.05, 0.5])  # inside the bounds, within the radius of the wall
    assert_one_line_error(cli("map", write_map(spec, "goal.yaml")), "goal", "grown by the robot radius 0.1")


def test_plan_refuses_a_bad_option_before_it_prints_or_writes_anything(cli, write_map, tmp_path):
    write_map(BLIND_MAP, "blind.yaml")
    result = cli("plan", "blind.yaml", "--iterations", "-5")
    assert_one_line_error(result, "--iterations")
    assert result.output.startswith("error:"), result.output  # no "map fresh" or "map ran" line before it
    assert not (tmp_path / "plans").exists()


def test_counts_of_one_are_singular_and_slivers_are_not_zero():
    from bearnav_cli.datatypes import percent, plural

    assert plural(1, "obstacle") == "1 obstacle" and plural(3, "obstacle") == "3 obstacles"
    assert plural(0, "start") == "0 starts"
    assert percent(0.0) == "0.0%" and percent(1.0) == "100.0%" and percent(0.25) == "25.0%"
    assert percent(1e-5) == "< 0.1%" and percent(1 - 1e-5) == "> 99.9%"


def test_the_map_summary_counts_one_obstacle_in_the_singular(cli, write_map):
    result = cli("map", write_map(BLIND_MAP, "blind.yaml"), "-o", "one/map.json")
    assert result.exit_code == 0, result.output
    assert "1 obstacle (" in result.output and "1 obstacles" not in result.output, result.output


# --------------------------------------------------------------------------- simulate's failures, -q, plot's default


def test_lost_runs_name_the_tags_command_and_the_figure_that_shows_them(cli, write_map, tmp_path):
    write_map(dict(BLIND_MAP, name="corners", landmarks=[[0, 3], [0, 0], [4, 0], [4, 3]]), "corners.yaml")
    assert cli("-q", "plan", "corners.yaml").exit_code == 0
    # the filter's robot is lost where it never sees two tags: the hint is the fix rule's `tags --fov`
    result = cli(
        "-q", "simulate", "plans/corners/plan.npz", "--fov", "60", "--starts", "random:4", "--estimator", "kalman"
    )
    assert result.exit_code == 1, result.output
    # -q: the result line and the error, no table, no note
    out_lines = [line for line in result.stdout.splitlines() if line.strip()]
    assert len(out_lines) == 1 and out_lines[0].startswith("simulate"), result.stdout
    line = error_line(result)
    assert "lost" in line and "fewer than --min-success 1" in line, line
    tags, plan, figure = commands(line)
    assert tags[:2] == ["tags", "plans/corners/plan.npz"] and tags[tags.index("--fov") + 1] == "60", line
    assert tags[tags.index("--map") + 1] == "corners.yaml" and plan == ["plan", "corners_tags.yaml"], line
    drawn = cli(*figure)  # `bearnav plot plans/corners/sim.npz`: no -o, the figure goes next to the runs
    assert drawn.exit_code == 0, drawn.output
    assert (tmp_path / "plans" / "corners" / "sim.png").stat().st_size > 0
    assert f"wrote {Path('plans/corners/sim.png')}" in drawn.output


def test_lost_set_estimator_runs_name_tags_for_live(cli, write_map, tmp_path):
    """A set-estimator robot is lost when looks all around do not shrink its bound enough: the hint is
    ``bearnav tags --for live`` at the bound simulated, not the fix rule."""
    write_map(dict(BLIND_MAP, name="corners", landmarks=[[0, 3], [0, 0], [4, 0], [4, 3]]), "corners.yaml")
    assert cli("-q", "plan", "corners.yaml").exit_code == 0
    result = cli(
        "-q",
        "simulate",
        "plans/corners/plan.npz",
        "--fov",
        "60",
        "--starts",
        "random:4",
        "--estimator",
        "set",
        "--noise-bound-deg",
        "25",
    )
    assert result.exit_code == 1, result.output
    line = error_line(result)
    assert "lost" in line and "not live" in line, line
    tags, plan, _ = commands(line)
    assert tags[tags.index("--for") + 1] == "live" and tags[tags.index("--bearing-error-deg") + 1] == "25", line
    assert plan == ["plan", "corners_tags.yaml"], line


def test_simulate_words_give_the_loop_back_as_options():
    from bearnav_cli.cli.hints import simulate_words
    from bearnav_cli.stages import simulate

    params = dataclasses.asdict(simulate.Params(fov=60.0, dynamics="unicycle", occlusion=False))
    words = simulate_words(params, estimator="kalman")
    assert words == ["--dynamics", "unicycle", "--fov", "60", "--no-occlusion", "--estimator", "kalman"], words
    assert simulate_words(params, estimator="set") == words[:-2]  # the default is not spelled out
    assert simulate_words(dataclasses.asdict(simulate.Params())) == []


# --------------------------------------------------------------------------- item 7: inspect --cells, JSON


def test_inspect_cells_is_a_table_with_units_and_json_rows_for_machines(cli, built):
    from bearnav_cli import artifacts

    plan = artifacts.load(built["plan"]).artifact
    text = cli("inspect", built["plan"], "--cells")
    assert text.exit_code == 0, text.output
    lines = text.output.splitlines()
    head = next(k for k, line in enumerate(lines) if line.startswith("cell "))
    assert "τ_c" in lines[head] and "[u]" in lines[head + 1] and "map units" in text.output
    rows = lines[head + 2 : head + 2 + plan.cells.n_cells]
    assert [int(row.split()[0]) for row in rows] == list(range(plan.cells.n_cells))  # one row per cell, in order
    data = json.loads(cli("inspect", built["plan"], "--cells", "--json").output)
    assert len(data["cells"]) == plan.cells.n_cells and data["units"]["tau_c"] == "map unit"
    for c, row in enumerate(data["cells"]):
        assert row["cell"] == c and row["status"] in ("goal", "certified", "relaxed")
        assert row["tau_c"] is None or row["tau_c"] == pytest.approx(float(plan.usable_tolerance[c]))
    cells = json.loads(cli("inspect", built["cells"], "--cells", "--json").output)
    assert len(cells["cells"]) == plan.cells.n_cells and "status" not in cells["cells"][0]


def test_json_is_never_wrapped_whatever_the_terminal(cli, built):
    from typer.testing import CliRunner

    from bearnav_cli.cli import app

    narrow = CliRunner().invoke(app, ["inspect", str(built["plan"]), "--json"], env={"COLUMNS": "40"})
    manifest = json.loads(narrow.output)  # parses: no string broken across lines
    assert any(len(line) > 40 for line in narrow.output.splitlines())
    assert manifest["schema"].startswith("bearnav.plan/")
    text = CliRunner().invoke(app, ["inspect", str(built["plan"])], env={"COLUMNS": "40"}).output
    params = next(line for line in text.splitlines() if line.startswith("params"))
    json.loads(params.removeprefix("params").strip())  # the text view's JSON line is whole too


def test_help_describes_a_map_without_the_source_tree(cli):
    text = cli("--help").output
    for word in ("A map is a YAML file", "bounds", "robot_radius", "obstacles", "landmarks", "map_server"):
        assert word in text, word
    assert "quiet" in text.lower() and "final result" in text


def test_make_demo_installs_bearnav_alone_and_make_test_the_test_extra(tmp_path):
    import shutil
    import subprocess

    from .conftest import REPO

    if shutil.which("make") is None:
        pytest.skip("no make")
    venv = tmp_path / "venv"  # never made: -n prints the recipes

    def recipes(target: str) -> str:
        return subprocess.run(
            ["make", "-n", "-C", str(REPO), target, f"VENV={venv}"], capture_output=True, text=True, check=True
        ).stdout

    demo, test = recipes("demo"), recipes("test")
    assert "pip install --quiet -e ." in demo and "[test]" not in demo, demo
    assert "pip install --quiet -e '.[test]'" in test and "pytest" in test, test


def test_verify_failing_in_a_moved_world_names_the_replan_in_it(cli, write_map):
    write_map(dict(BLIND_MAP, name="corners", landmarks=[[0, 3], [0, 0], [4, 0], [4, 3]]), "corners.yaml")
    assert cli("-q", "plan", "corners.yaml").exit_code == 0
    moved = dict(
        BLIND_MAP,
        name="moved",
        obstacles=[{"rectangle": [1.5, 0.8, 2.6, 2.2]}],
        landmarks=[[0, 3], [0, 0], [4, 0], [4, 3]],
    )
    write_map(moved, "moved.yaml")
    result = cli("verify", "plans/corners/plan.npz", "--starts", "0", "--world", "moved.yaml")
    assert result.exit_code == 1, result.output
    line = error_line(result)
    assert "plans/corners/plan.npz fails verification" in line and commands(line) == [["plan", "moved.yaml"]], line


# --------------------------------------------------------------------------- item 3: what is guaranteed


def test_verify_ends_with_what_is_proven_measured_and_not_covered(cli, built):
    from bearnav_cli import artifacts

    plan = artifacts.load(built["plan"]).artifact
    result = cli("verify", built["plan"], "--starts", "2")
    assert result.exit_code == 0, result.output
    line = next(line for line in result.output.splitlines() if line.strip().startswith("guarantee:"))
    for words in (
        "proven from the plan file",
        f"radius {plan.map.robot_radius:g}",
        "starts in the certified area",
        "tolerates",
        "a worst case",
        "η = 0.2°",
        "measured only: 2 closed-loop runs",
        "not covered",
    ):
        assert words in line, (words, line)
    assert "worst-case time to goal ≤" in result.output  # the summary labels the loose bound too
    quiet = cli("-q", "verify", built["plan"], "--starts", "0")
    assert "guarantee" not in quiet.output and len(quiet.stdout.splitlines()) == 1, quiet.output


def test_a_long_time_bound_is_also_given_in_hours():
    from bearnav_cli.verify import duration_text

    assert duration_text(13870.0) == "≤ 1.387e+04 s (3.9 h)" and duration_text(30.0) == "≤ 30 s"
    assert duration_text(float("inf")) == "unbounded"


def test_synthesize_ends_with_what_its_plan_certifies(cli, built, tmp_path):
    """Issue 23 item 3: `bearnav synthesize` alone ends with the plan's guarantee sentence, naming the
    `bearnav verify` command for the plan it wrote."""
    out = tmp_path / "again.npz"
    result = cli("synthesize", built["cells"], "-o", out)
    assert result.exit_code == 0, result.output
    sentence = next(line for line in result.output.splitlines() if "guarantee" in line)
    (verify,) = commands(sentence)
    assert verify == ["verify", str(out)], sentence
    quiet = cli("synthesize", built["cells"], "-o", out, "-q", "--force")
    assert quiet.exit_code == 0 and "guarantee" not in quiet.output, quiet.output
