"""bearnav never deletes or replaces what it did not write (issue 23 item 1, issue 27 items 1, 7 and 10)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from bearnav_cli import artifacts, pipeline, tags
from bearnav_cli.cli import read_map_source

from .conftest import SMALL_MAP
from .test_cli_errors import assert_one_line_error

#: A map as people write them: comments, a description, a circle, landmarks in two styles.
HAND_WRITTEN = """\
# the office, drawn by hand
name: office
description: the second floor   # not a key bearnav reads
bounds: [0, 0, 10, 8]
robot_radius: 0.2
goal: [0.5, 0.5]
starts: [[9, 7], [5, 7.5]]
obstacles:
  - {polygon: [[1, 2], [3, 2], [3, 3]]}
  - {rectangle: [4, 4, 6, 5]}
  - circle: {center: [8, 2], radius: 0.5}   # the pillar
landmarks:
  - [0, 8]
  # the tag on the door
  - {id: tag12, position: [10, 0]}

params: {rrtstar: {iterations: 200, step: 1.0, seed: 0}}
"""


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """The hand-written map and its plan folder (planned once for the module; tests copy it)."""
    root = tmp_path_factory.mktemp("outputs")
    source = root / "office.yaml"
    source.write_text(HAND_WRITTEN)
    pipeline.plan(read_map_source(source), root / "office")
    return root


@pytest.fixture
def office(planned, tmp_path):
    shutil.copy(planned / "office.yaml", tmp_path / "office.yaml")
    shutil.copytree(planned / "office", tmp_path / "office")
    return tmp_path


def _names(folder):
    return sorted(path.name for path in folder.iterdir())


def test_bag_folder_around_sim_npz_is_refused_before_any_work(cli, office):
    out = office / "OUT"
    out.mkdir()
    (out / "metadata.yaml").write_text("rosbag2_bagfile_information: {custom_data: {bearnav.map: office}}\n")
    plan = office / "office" / "plan.npz"
    for bag in (out, office / "EMPTY"):  # an existing bag, then an empty folder
        bag.mkdir(exist_ok=True)
        result = cli("simulate", plan, "--starts", "random:2", "-o", bag / "sim.npz", "--bag", bag)
        assert_one_line_error(result, "--bag")
        assert not (bag / "sim.npz").exists() and not (bag / "sim.json").exists()
    assert _names(out) == ["metadata.yaml"]  # the bag that was there is untouched
    assert not (office / "office" / "sim.npz").exists()


def test_upper_case_mcap_is_refused(cli, office):
    result = cli("simulate", office / "office" / "plan.npz", "--starts", "random:2", "--bag", office / "run.MCAP")
    assert_one_line_error(result, ".mcap")
    assert not (office / "office" / "sim.npz").exists()


def test_a_file_bearnav_did_not_write_is_kept_without_force(cli, office):
    mine = office / "office" / "notes.npz"
    mine.write_bytes(b"my own numbers")
    result = cli("simulate", office / "office" / "plan.npz", "--starts", "random:2", "-o", mine)
    assert_one_line_error(result, "notes.npz")
    assert mine.read_bytes() == b"my own numbers"
    # another stage's artifact is not simulate's to replace either
    tree = office / "office" / "tree.npz"
    before = tree.read_bytes()
    assert_one_line_error(cli("simulate", office / "office" / "plan.npz", "-o", tree), "rrtstar")
    assert tree.read_bytes() == before


def test_written_by_tells_bearnav_outputs_from_others(office, tmp_path):
    folder = office / "office"
    assert artifacts.written_by(folder / "map.json") == artifacts.Origin("map", "office")
    assert artifacts.written_by(folder / "plan.npz") == artifacts.Origin("synthesize", "office")
    damaged = tmp_path / "damaged.npz"
    damaged.write_bytes((folder / "tree.npz").read_bytes()[:300])
    assert artifacts.written_by(damaged) is None and artifacts.written_by(office / "office.yaml") is None


def test_tags_writes_a_new_map_that_keeps_the_hand_written_text(cli, office):
    source, plan = office / "office.yaml", office / "office" / "plan.npz"
    result = cli("tags", plan, "--map", source, "-q")
    assert result.exit_code == 0, result.output
    assert source.read_text() == HAND_WRITTEN  # the map given is never touched
    written = office / "office_tags.yaml"  # the default: a new file next to it
    text = written.read_text()
    body = text.split("\n", 1)[1]
    # every line of the original is still there (but the name), in the same order
    kept = [line for line in HAND_WRITTEN.splitlines() if not line.startswith("name:")]
    assert [line for line in body.splitlines() if line in kept] == kept
    spec = yaml.safe_load(text)
    assert spec["name"] != "office"  # another plan folder when it is planned
    assert spec["obstacles"][2] == {"circle": {"center": [8, 2], "radius": 0.5}}
    assert spec["description"] == "the second floor" and len(spec["landmarks"]) > 2
    # its own output may be written again (a second run takes seconds: what allows it is checked); the map
    # given may not, even with --force
    artifacts.check_overwrite(written, "tags")
    assert_one_line_error(cli("tags", plan, "--map", source, "-o", source, "--force"), "office.yaml")
    assert source.read_text() == HAND_WRITTEN


def test_tags_refuses_a_yaml_it_did_not_write_without_force(cli, office):
    mine = office / "mine.yaml"
    mine.write_text("# my notes\nname: mine\n")
    result = cli("tags", office / "office" / "plan.npz", "-o", mine)
    assert_one_line_error(result, "mine.yaml")
    assert mine.read_text() == "# my notes\nname: mine\n"


def test_map_text_with_tags_edits_block_and_flow_lists():
    proposal = SimpleNamespace(ids=("t9",), positions=np.array([[1.5, 0.0]]))  # what the edit reads of one
    for text in (
        HAND_WRITTEN,
        yaml.safe_dump(SMALL_MAP, sort_keys=False, default_flow_style=None),
        "landmarks:\n- [0, 8]\nname: x  # old\n",
    ):
        new = tags.map_text_with_tags(text, proposal, "x_tags", "# bearnav tags: test")
        spec = yaml.safe_load(new)
        assert spec["name"] == "x_tags" and spec["landmarks"][-1] == {"id": "t9", "position": [1.5, 0.0]}
        assert len(spec["landmarks"]) == len(yaml.safe_load(text)["landmarks"]) + 1
        assert new.startswith("# bearnav tags:")


def test_a_plan_folder_of_another_map_is_refused(cli, office):
    other = office / "other.yaml"
    other.write_text(HAND_WRITTEN.replace("name: office", "name: kitchen"))
    before = {name: (office / "office" / name).read_bytes() for name in _names(office / "office")}
    result = cli("plan", other, "-o", office / "office")
    assert_one_line_error(result, "office")
    assert "'office'" in result.output  # the map the folder belongs to
    assert {name: (office / "office" / name).read_bytes() for name in _names(office / "office")} == before
    # the same map again, with other options, is the normal case
    result = cli("plan", office / "office.yaml", "-o", office / "office", "--seed", "1", "-q")
    assert result.exit_code in (0, 1), result.output
    assert artifacts.read_manifest(office / "office" / "tree.npz")["params"]["seed"] == 1


@pytest.mark.parametrize("option", [("--seed", "-1"), ("--iterations", "-1"), ("--step", "0")])
def test_bad_plan_options_write_nothing(cli, office, option):
    result = cli("plan", office / "office.yaml", "-o", office / "new", *option)
    assert_one_line_error(result, option[0])
    assert not (office / "new").exists()


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_stale_staging_folders_and_temp_files_are_removed_by_the_next_write(tmp_path):
    dead = _dead_pid()
    prefix = artifacts.atomic._temp_prefix  # the names bearnav gives
    staging = tmp_path / f"{prefix(tmp_path / 'b.mcap', dead)}k3x_9.tmp"
    (staging / "b").mkdir(parents=True)
    (staging / "b" / "b.mcap").write_bytes(b"half a bag")
    stale = tmp_path / f"{prefix(tmp_path / 'map.yaml', dead)}abc123.tmp.yaml"
    stale.write_text("half a map")
    live = tmp_path / f"{prefix(tmp_path / 'x.png', 1)}abc.tmp.png"  # pid 1 is alive: left alone
    live.write_text("busy")
    # issue 27 (security): a user's file that only looks like a temp file of a dead process is kept
    lookalike = tmp_path / f".notes.bearnav-{dead}-x.tmp"
    lookalike.write_text("my notes")
    artifacts.atomic_write(tmp_path / "map.yaml", lambda f: f.write(b"name: x\n"))  # what tags does
    assert not staging.exists() and not stale.exists() and live.exists() and lookalike.exists()
    staging.mkdir()
    with artifacts.staging_folder(tmp_path / "b.mcap") as mine:  # what --bag does
        assert not staging.exists() and mine.is_dir()
    assert not mine.exists()
