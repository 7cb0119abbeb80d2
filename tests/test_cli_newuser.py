"""Issue 13, "the first hour of a new user": plan takes the map options and a map.json, wrong-kind
files get advice, inspect is short with the detail on demand, help and output say what they mean."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from rich.progress import Progress

from bearnav_cli.cli import output
from bearnav_cli.stages import map_

from .conftest import REPO
from .test_cli_errors import assert_one_line_error
from .test_hostile_common import small_plan

STOREROOM_TAGS = ["0.15,1.2", "0.15,4.0", "3.0,0.15", "5.85,2.5", "2.0,4.85", "5.0,4.85", "2.3,2.5", "3.75,1.4"]


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> dict[str, Path]:
    return small_plan(tmp_path_factory.mktemp("newuser"))


@pytest.fixture
def grid(tmp_path) -> Path:
    for name in ("storeroom_grid.yaml", "storeroom.pgm"):
        shutil.copy(REPO / "maps" / name, tmp_path / name)
    return tmp_path / "storeroom_grid.yaml"


def landmark_options() -> list[str]:
    return [word for tag in STOREROOM_TAGS for word in ("--landmark", tag)]


# --------------------------------------------------------------------------- plan: map options, map.json


def test_plan_takes_the_map_options_for_a_bare_grid_then_plans_from_its_map_json(cli, grid, tmp_path):
    result = cli(
        "-q",
        "plan",
        grid,
        "--goal",
        "0.6,2.5",
        "--robot-radius",
        "0.15",
        "--start",
        "5.3,0.6",
        *landmark_options(),
        "-o",
        tmp_path / "bare",
    )
    assert result.exit_code == 0, result.output
    assert (tmp_path / "bare" / "plan.npz").is_file()
    again = cli("plan", tmp_path / "bare" / "map.json")  # its own folder by default: every stage fresh
    assert again.exit_code == 0, again.output
    assert again.output.count("fresh") == 5, again.output
    other = cli("-q", "plan", tmp_path / "bare" / "map.json", "--cells", "funnel-local", "-o", tmp_path / "local")
    assert other.exit_code == 0, other.output
    assert (tmp_path / "local" / "map.json").read_bytes() == (tmp_path / "bare" / "map.json").read_bytes()
    assert (tmp_path / "local" / "plan.npz").is_file()
    manifest = cli("inspect", tmp_path / "local" / "cells.npz", "--json")
    assert json.loads(manifest.output)["params"]["cells"] == "funnel-local"


def test_tags_of_a_bare_grid_plan_keeps_the_grid_and_needs_no_goal(cli, grid, tmp_path, monkeypatch):
    """Issue 23: the blind-spot hint of a plan from a bare map_server YAML names that YAML as ``--map``; the map
    ``tags`` writes names the grid as its ``occupancy:`` (the PGM stays a PGM, no polygons), takes the goal and
    the tags from the plan (no --goal), and plans as it is."""
    import yaml

    from .test_cli_hints import commands, error_line

    monkeypatch.chdir(tmp_path)  # the commands the hint prints are relative to here
    result = cli(
        "-q",
        "plan",
        grid.name,
        "--goal",
        "0.6,2.5",
        "--robot-radius",
        "0.15",
        *[word for tag in STOREROOM_TAGS[:3] for word in ("--landmark", tag)],
    )
    assert result.exit_code == 1, result.output
    tags, plan = commands(error_line(result))
    assert tags[tags.index("--map") + 1] == grid.name, tags
    assert cli(*tags).exit_code == 0
    written = yaml.safe_load(Path(plan[1]).read_text())
    assert written["occupancy"] == grid.name and "obstacles" not in written and "bounds" not in written, written
    assert written["goal"] == [0.6, 2.5] and len(written["landmarks"]) > 3, written
    again = cli("-q", *plan)
    assert again.exit_code == 0, again.output


def test_a_bare_grid_without_goal_says_which_option(cli, grid, tmp_path):
    assert_one_line_error(cli("plan", grid, "-o", tmp_path / "p"), "--goal")


def test_bare_grid_options_are_refused_for_a_bearnav_map(cli, built, tmp_path):
    result = cli("plan", built["yaml"], "--goal", "1,1", "-o", tmp_path / "p")
    assert_one_line_error(result, "--goal", "bare map_server YAML")
    assert not (tmp_path / "p").exists()


def test_map_options_are_refused_for_a_map_json(cli, built, tmp_path):
    result = cli("plan", built["map"], "--landmark", "1,1", "-o", tmp_path / "p")
    assert_one_line_error(result, "--landmark", "map.json")


def test_plan_refuses_an_unknown_cells_kind_before_any_work(cli, built, tmp_path):
    assert_one_line_error(cli("plan", built["yaml"], "--cells", "bogus", "-o", tmp_path / "p"), "--cells", "funnel")
    assert not (tmp_path / "p").exists()


def test_map_given_a_map_json_says_to_plan_from_it(cli, built, tmp_path):
    assert_one_line_error(cli("map", built["map"], "-o", tmp_path / "m" / "map.json"), "artifact", "bearnav plan")


def test_the_map_summary_says_when_obstacles_were_merged(cli, write_map, small_spec, tmp_path):
    small_spec["obstacles"] += [{"rectangle": [6, 4, 7, 5]}]  # touches the rectangle [4, 4, 6, 5]
    result = cli("map", write_map(small_spec), "-o", tmp_path / "m" / "map.json")
    assert result.exit_code == 0, result.output
    assert "4 obstacles merged into 3 (touching or overlapping)" in result.output
    plain = map_.summary(map_.run(map_.MapSource(spec={**small_spec, "obstacles": []}, file="x", sha256="0")), 0)
    assert "0 obstacles (robot radius 0.2)" in plain


# --------------------------------------------------------------------------- wrong-kind files


@pytest.mark.parametrize("command", [["inspect"], ["plot", "-o", "fig.png"], ["verify"], ["simulate"]])
def test_a_map_yaml_given_as_an_artifact_gets_advice(cli, built, command):
    result = cli(command[0], built["yaml"], *command[1:])
    assert_one_line_error(result, "is a map YAML", "bearnav plan")
    assert "pickle" not in result.output


def test_a_plan_folder_points_at_the_plan_inside(cli, built):
    assert_one_line_error(cli("verify", built["plan"].parent), "did you mean", str(built["plan"]))
    assert_one_line_error(cli("inspect", built["plan"].parent), "did you mean", "plan.npz")


def test_plan_given_a_plan_folder_points_at_its_map_json(cli, built):
    assert_one_line_error(cli("plan", built["plan"].parent), "did you mean", "map.json")


def test_sim_json_points_at_sim_npz(cli, built):
    assert_one_line_error(cli("inspect", built["simulation"].with_suffix(".json")), "sim.npz")


# --------------------------------------------------------------------------- inspect


def test_inspect_is_short_by_default_with_the_detail_on_demand(cli, built):
    short = cli("inspect", built["plan"])
    assert short.exit_code == 0, short.output
    assert len(short.output.splitlines()) <= 20, short.output
    assert "--cells adds a table of the cells" in short.output and '"attempts"' not in short.output
    full = cli("inspect", built["plan"], "--cells")
    assert full.exit_code == 0 and '"attempts"' not in full.output and "τ_c" in full.output  # a table, not JSON
    assert cli("inspect", built["plan"], "-q").exit_code == 0


def test_inspect_cell_shows_one_cell(cli, built):
    result = cli("inspect", built["plan"], "--cell", "1")
    assert result.exit_code == 0, result.output
    for word in ("cell 1 of", "status", "δ_c", "vertices", "rows", "<- exit", "landmarks", "flags"):
        assert word in result.output, word
    data = json.loads(cli("inspect", built["cells"], "--cell", "0", "--json").output)
    assert data["cell"] == 0 and data["exit_row"] == -1 and len(data["rows"]) == len(data["vertices"])


def test_inspect_cell_errors(cli, built):
    assert_one_line_error(cli("inspect", built["plan"], "--cell", "100000"), "--cell", "cells 0 to")
    assert_one_line_error(cli("inspect", built["tree"], "--cell", "0"), "--cell", "holds no cells")


# --------------------------------------------------------------------------- help and output


def test_plot_accepts_quiet(cli, built, tmp_path):
    result = cli("plot", built["map"], "-o", tmp_path / "figs" / "map.png", "-q")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "figs" / "map.png").is_file()


@pytest.mark.parametrize("command", ["plan", "map", "verify", "inspect", "plot", "simulate", "rrtstar"])
def test_usage_lines_name_arguments_plainly(cli, command):
    result = cli(command, "--help")
    assert result.exit_code == 0
    usage = next(line for line in result.output.splitlines() if "Usage:" in line)
    assert "{" not in usage and "<list" not in result.output and "<bool>" not in result.output, usage


def test_plan_help_lists_the_map_options(cli):
    text = cli("plan", "--help")
    for option in ("--goal", "--landmark", "--start", "--robot-radius", "--unknown", "--circle-segments", "--cells"):
        assert option in text.output, option


def test_progress_shows_no_count_before_the_total_is_known():
    progress = Progress(output.count_column()())
    task = progress.add_task("x", total=None)
    column = output.count_column()()
    assert str(column.render(progress.tasks[task])) == ""
    progress.update(task, completed=3, total=10)
    assert str(column.render(progress.tasks[task])) == "3/10"


def test_stage_lines_align_the_longest_stage_name():
    from bearnav_cli.pipeline import StageReport

    lines = [output.report_line(StageReport(name, Path("x"), True, 1.0, "s")) for name in ("map", "synthesize")]
    assert lines[0].index("ran") == lines[1].index("ran")


def test_simulate_and_verify_output_give_units_and_point_at_the_words(cli, built, tmp_path):
    sim = cli("simulate", built["plan"], "--starts", "random:3", "--min-success", "0", "-o", tmp_path / "s" / "sim.npz")
    assert sim.exit_code == 0, sim.output
    assert "min clearance (map units)" in sim.output and "Words in the output" in sim.output
    ver = cli("verify", built["plan"], "--starts", "3")
    assert "displacements" in ver.output and "Words in the output" in ver.output
    assert "## Words in the output" in (REPO / "docs" / "cli.md").read_text()


# --------------------------------------------------------------------------- figures


def legend_texts(fig) -> list[str]:
    return [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()]


def test_figures_name_the_simplified_tree_and_the_run_starts(built):
    from bearnav_cli import artifacts, plot

    sim = artifacts.load(built["simulation"]).artifact
    texts = legend_texts(plot.figure_for(sim))
    assert "run starts" in texts and "simplified tree" in texts and "map starts" in texts, texts
    simplified = artifacts.load(built["simplified"]).artifact
    tree = artifacts.load(built["tree"]).artifact
    texts = legend_texts(plot.figure_for(simplified, background=[tree]))
    assert "simplified tree" in texts and "RRT* tree" in texts, texts
    assert "RRT* tree" in legend_texts(plot.figure_for(tree))
    import matplotlib.pyplot as plt

    plt.close("all")
