"""`bearnav simulate --bag`: ROS 2 bags read back with rosbags (docs/runtime.md "ROS 2 bags")."""

from __future__ import annotations

import shutil
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

# rosbags comes with the test extra (bearnav[ros]): a broken install fails here rather than skipping
from rosbags.highlevel import AnyReader
from typer.testing import CliRunner

from bearnav_cli import artifacts, bag, pipeline
from bearnav_cli.cli import app
from bearnav_cli.errors import InvalidParamsError

from .conftest import planned_small_map
from .test_cli_errors import assert_one_line_error


@pytest.fixture(scope="module")
def plan_path(tmp_path_factory) -> Path:
    """The small map of conftest planned once (a few hundred RRT* iterations)."""
    return planned_small_map(tmp_path_factory)


def simulate(plan: Path, *args) -> object:
    return CliRunner().invoke(app, ["simulate", str(plan), *[str(a) for a in args]])


@pytest.fixture(scope="module")
def written(plan_path, tmp_path_factory):
    """Two unicycle runs simulated with --bag NAME.mcap: (sim, bag path)."""
    folder = tmp_path_factory.mktemp("bag")
    # the filter's runs reach the goal on this plan, which is not live at the default bound (the set
    # estimator's robots would stop and look, and the bag would hold no path to check)
    result = simulate(
        plan_path,
        "-o",
        folder / "sim.npz",
        "--dynamics",
        "unicycle",
        "--estimator",
        "kalman",
        "--bag",
        folder / "runs.mcap",
        "--json",
    )
    assert result.exit_code == 0, result.output
    assert '"bag"' in result.output
    return artifacts.load(folder / "sim.npz", "simulation").artifact, folder / "runs.mcap"


def read(path: Path) -> tuple[dict, dict]:
    """``({topic: (type, count)}, {topic: [(log time, message), ...]})``."""
    with AnyReader([path]) as reader:
        topics = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        messages: dict[str, list] = {}
        for connection, stamp, raw in reader.messages():
            messages.setdefault(connection.topic, []).append((stamp, reader.deserialize(raw, connection.msgtype)))
    return topics, messages


def ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def yaw(q) -> float:
    return 2.0 * np.arctan2(q.z, q.w)


def test_a_bag_from_simulate_has_the_documented_topics_and_the_poses_of_sim_npz(written):
    sim, path = written
    assert path.is_file() and not list(path.parent.glob(".*.tmp*"))
    topics, messages = read(path)
    runs, points = len(sim.outcome), len(sim.trajectory_coords)
    assert runs == 2 and points > 20
    assert topics == {
        "/bearnav/markers": ("visualization_msgs/msg/MarkerArray", 1),
        "/bearnav/path": ("nav_msgs/msg/Path", runs),
        "/bearnav/pose": ("geometry_msgs/msg/PoseStamped", points),
    }
    assert {topic: msgtype for topic, (msgtype, _) in topics.items()} == bag.TOPICS
    # poses over time: point p at t0 + p·dt (t0 = 0), in the map frame, yaw = the recorded heading
    poses = sorted(messages["/bearnav/pose"], key=lambda item: item[0])
    xy = np.array([[m.pose.position.x, m.pose.position.y] for _, m in poses])
    assert np.abs(xy - sim.trajectory_coords).max() <= 1e-9
    headings = np.array([yaw(m.pose.orientation) for _, m in poses])
    assert np.abs(np.angle(np.exp(1j * (headings - sim.trajectory_heading)))).max() <= 1e-9
    assert np.ptp(sim.trajectory_heading) > 0.1  # the unicycle turns: the check means something
    stamps = np.array([ns(m.header.stamp) for _, m in poses])
    assert np.array_equal(stamps, [t for t, _ in poses])
    assert np.abs(stamps - np.arange(points) * sim.dt * 1e9).max() <= 1.0
    assert {m.header.frame_id for _, m in poses} == {bag.FRAME}
    # one Path per run, stamped when the run begins, with the run's own poses
    paths = sorted(messages["/bearnav/path"], key=lambda item: item[0])
    for r, (stamp, message) in enumerate(paths):
        run = sim.trajectory(r)
        assert message.header.frame_id == "map" and len(message.poses) == len(run)
        got = np.array([[p.pose.position.x, p.pose.position.y] for p in message.poses])
        assert np.abs(got - run).max() <= 1e-9
        assert stamp == ns(message.header.stamp) == ns(message.poses[0].header.stamp)
        assert stamp == pytest.approx(sim.trajectory_offsets[r] * sim.dt * 1e9, abs=1.0)


def test_the_markers_draw_obstacles_cells_tags_tree_and_runs(written):
    sim, path = written
    _, messages = read(path)
    ((stamp, array),) = messages["/bearnav/markers"]
    assert stamp == 0
    markers = array.markers
    count = Counter(m.ns for m in markers)
    rings = sum(1 + len(p.holes) for p in sim.map.raw_obstacles)
    assert count["obstacles"] == rings and count["inflated"] == sum(1 + len(p.holes) for p in sim.map.obstacles)
    assert count["cells"] == len(sim.cell_status)
    assert count["tags"] == count["tag_ids"] == len(sim.map.landmarks)
    assert count["tree"] == count["goal"] == count["bounds"] == 1
    assert count["runs"] == len(sim.outcome)
    assert {m.header.frame_id for m in markers} == {"map"}
    assert len({(m.ns, m.id) for m in markers}) == len(markers)  # ids unique within a namespace
    by = {(m.ns, m.id): m for m in markers}
    # cells: closed rings of the cells' vertices; colour by status
    o = sim.cell_vertex_offsets
    for c in range(len(sim.cell_status)):
        points = np.array([[q.x, q.y] for q in by["cells", c].points])
        assert np.array_equal(points[:-1], sim.cell_vertices[o[c] : o[c + 1]]) and np.array_equal(points[0], points[-1])
    assert by["cells", 0].type == by["obstacles", 0].type == 4  # LINE_STRIP
    for c, status in enumerate(sim.cell_status):
        color = by["cells", c].color
        assert (color.r, color.g, color.b, color.a) == pytest.approx(bag.STATUS_RGBA[status], abs=1e-6)
    # tags: CUBEs at the landmarks with their ids as text
    tags = [by["tags", k] for k in range(len(sim.map.landmarks))]
    assert all(t.type == 1 for t in tags)
    assert np.array_equal([[t.pose.position.x, t.pose.position.y] for t in tags], sim.map.landmarks)
    assert [by["tag_ids", k].text for k in range(len(tags))] == list(sim.map.landmark_ids)
    # the tree: a LINE_LIST, two points per edge
    tree = by["tree", 0]
    child = np.flatnonzero(sim.parent >= 0)
    assert tree.type == 5 and len(tree.points) == 2 * len(child)
    ends = np.array([[q.x, q.y] for q in tree.points]).reshape(-1, 2, 2)
    assert np.array_equal(ends[:, 0], sim.nodes[child]) and np.array_equal(ends[:, 1], sim.nodes[sim.parent[child]])
    assert len(by["runs", 1].points) == len(sim.trajectory(1))


def test_a_bag_folder_is_replaced_whole_and_a_failed_write_leaves_the_old_one(
    plan_path, written, tmp_path, monkeypatch
):
    sim, _ = written
    folder = tmp_path / "runs"
    assert bag.write(folder, sim)["/bearnav/pose"] == len(sim.trajectory_coords)
    assert sorted(p.name for p in folder.iterdir()) == ["metadata.yaml", "runs.mcap"]
    one = pipeline.run_stage("simulate", plan_path, tmp_path / "one" / "sim.npz", {"starts": "9,7"}).artifact
    shutil.rmtree(tmp_path / "one")
    bag.write(folder, one)  # an existing bag is replaced
    topics, _ = read(folder)
    assert topics["/bearnav/path"] == ("nav_msgs/msg/Path", 1)
    before = (folder / "runs.mcap").read_bytes()
    calls = iter(range(10**6))

    def broken(*args):
        if next(calls) == 30:
            raise RuntimeError("disk on fire")
        return real(*args)

    real = bag._pose
    monkeypatch.setattr(bag, "_pose", broken)
    for target in (folder, tmp_path / "new.mcap"):
        calls = iter(range(10**6))
        with pytest.raises(RuntimeError, match="disk on fire"):
            bag.write(target, sim)
    assert (folder / "runs.mcap").read_bytes() == before  # the old bag, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]  # no temp folder, no new.mcap


@pytest.mark.parametrize(
    "name, words",
    [
        ("missing/runs.mcap", ["--bag", "does not exist"]),
        ("runs.bag", ["--bag", "extension '.bag'", ".mcap"]),
        ("runs.db3", ["--bag", "extension '.db3'"]),
        ("a_folder.mcap", ["--bag", "is a folder"]),
        ("not_a_bag", ["--bag", "not a ROS 2 bag"]),
        ("a_file", ["--bag", "is a file"]),
    ],
)
def test_bad_bag_paths_exit_3_in_one_line_before_any_work(plan_path, tmp_path, name, words):
    (tmp_path / "a_folder.mcap").mkdir()
    (tmp_path / "not_a_bag").mkdir()
    (tmp_path / "not_a_bag" / "notes.txt").write_text("mine")
    (tmp_path / "a_file").write_text("mine")
    before = sorted(tmp_path.rglob("*"))
    result = simulate(plan_path, "-o", tmp_path / "sim.npz", "--bag", tmp_path / name)
    assert_one_line_error(result, *words)
    assert sorted(tmp_path.rglob("*")) == before  # not even sim.npz
    assert (tmp_path / "not_a_bag" / "notes.txt").read_text() == "mine"


def test_without_rosbags_the_error_says_what_to_install(plan_path, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags.rosbag2", None)  # import rosbags.rosbag2 now fails
    with pytest.raises(InvalidParamsError, match=r"pip install 'bearnav\[ros\]'"):
        bag.check_path(tmp_path / "runs.mcap")
    result = simulate(plan_path, "-o", tmp_path / "sim.npz", "--bag", tmp_path / "runs.mcap")
    assert_one_line_error(result, "--bag", "rosbags")
    assert not (tmp_path / "sim.npz").exists()
