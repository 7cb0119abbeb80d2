"""``bearnav sweep`` (issue 25): the same table on one process, two and a Dask cluster; resuming; bad input.

The maps are two tiny boxes with one obstacle (120 RRT* iterations, a coarse step and a fast
robot in their ``params: simulate``), so that the 8 jobs of the grid (2 maps × 2 fields of view
× 2 noises, 20 random starts) cost about 3 s of CPU per run.
"""

from __future__ import annotations

import csv
import json
import shutil
import socket
from concurrent.futures import Future
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from bearnav_cli import sweep
from bearnav_cli.cli import app

SWEEP = {
    "name": "small",
    "maps": ["maps/tiny*.yaml"],
    "fov": [360, 180],
    "noise_deg": [0, 0.5],
    "dynamics": ["single"],
    "starts": "random:20",
}


def tiny_map(i: int) -> dict:
    """A 4 × 3 box with one rectangle (shifted by ``i``) and six tags; a robot fast enough for 80-step runs."""
    return {
        "name": f"tiny{i}",
        "bounds": [0, 0, 4, 3],
        "robot_radius": 0.1,
        "goal": [0.4, 0.4],
        "obstacles": [{"rectangle": [1.5 + 0.3 * i, 1.0, 2.5 + 0.3 * i, 2.0]}],
        "landmarks": [[0, 3], [4, 0], [4, 3], [2, 0], [0, 1.5], [2, 3]],
        "params": {
            "rrtstar": {"iterations": 120, "seed": 0},
            "simulate": {"dt": 0.1, "speed": 1.0, "alpha": 1.0, "beta": 2.0},
        },
    }


@pytest.fixture
def folder(tmp_path, monkeypatch) -> Path:
    """A scratch folder (the current one) with maps/tiny0.yaml, maps/tiny1.yaml and small.yaml."""
    (tmp_path / "maps").mkdir()
    for i in (0, 1):
        (tmp_path / "maps" / f"tiny{i}.yaml").write_text(yaml.safe_dump(tiny_map(i), sort_keys=False))
    (tmp_path / "small.yaml").write_text(yaml.safe_dump(SWEEP, sort_keys=False))
    monkeypatch.chdir(tmp_path)
    return tmp_path


def invoke(*args: str):
    return CliRunner().invoke(app, ["sweep", *map(str, args)])


def deterministic(store: Path) -> list[dict]:
    """results.csv without the times."""
    with (store / "results.csv").open() as handle:
        return [{c: row[c] for c in sweep.DETERMINISTIC_COLUMNS} for row in csv.DictReader(handle)]


def grid(path: str = "small.yaml") -> list[sweep.Job]:
    from bearnav_cli.cli import read_map_source

    read = sweep.read_sweep(yaml.safe_load(Path(path).read_text()), path)
    return sweep.expand(read, [read_map_source(p) for p in sweep.expand_maps(read)])[0]


def test_same_table_on_one_two_processes_and_a_cluster_and_resume(folder):
    distributed = pytest.importorskip("distributed")
    jobs = grid()
    assert len(jobs) == 8 and len({j.key for j in jobs}) == 8 and len({j.plan_key for j in jobs}) == 2

    # --jobs 1, interrupted after its third job: the three are in the store, the rerun runs the other five
    executor = sweep.local_executor(1)

    def stop(done: int, failed: int, total: int) -> None:
        if done == 3:
            raise KeyboardInterrupt

    try:
        with pytest.raises(KeyboardInterrupt):
            sweep.run(jobs, folder / "one", executor, stop)
    finally:
        sweep.stop_local(executor, interrupted=True)
    assert len(sweep.records(folder / "one", jobs)) == 3
    result = invoke("small.yaml", "--jobs", "1", "-o", "one", "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert (summary["ran"], summary["from_store"], summary["failed"], summary["plans_made"]) == (5, 3, 0, 0)
    one = deterministic(folder / "one")
    assert len(one) == 8 and all(row["status"] == "done" and row["runs"] == "20" for row in one)

    # --jobs 2 and a 2-worker LocalCluster, each on a store holding the plans only (the plans are the same
    # content either way; the jobs are what is scheduled)
    for name in ("two", "cluster"):
        shutil.copytree(folder / "one" / "plans", folder / name / "plans")
    result = invoke("small.yaml", "--jobs", "2", "-o", "two", "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["ran"] == 8
    assert deterministic(folder / "two") == one
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        result = invoke("small.yaml", "--scheduler", cluster.scheduler_address, "-o", "cluster", "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["ran"] == 8
    assert deterministic(folder / "cluster") == one

    # two job files lost: only those two run again, and the table is the same
    for job in jobs[2:4]:
        (folder / "two" / "jobs" / f"{job.key[:24]}.json").unlink()
    result = invoke("small.yaml", "-j", "2", "-o", "two", "--json")
    assert result.exit_code == 0, result.output
    assert (json.loads(result.output)["ran"], json.loads(result.output)["from_store"]) == (2, 6)
    assert deterministic(folder / "two") == one

    # --report redraws from the store and runs nothing
    (folder / "two" / "success.png").unlink()
    result = invoke("small.yaml", "-o", "two", "--report", "--json")
    assert result.exit_code == 0, result.output
    assert "ran" not in json.loads(result.output) and (folder / "two" / "success.png").stat().st_size > 0


class Inline:
    """An executor that runs each job at once in this process (``submit`` and ``result`` only)."""

    def submit(self, fn, *args):
        future: Future = Future()
        future.set_result(fn(*args))
        return future

    def shutdown(self, **kwargs) -> None:
        pass


def test_a_failed_job_is_recorded_and_the_sweep_goes_on(folder, monkeypatch):
    from bearnav_cli.stages import simulate

    spec = dict(SWEEP, maps=["maps/tiny0.yaml"], noise_deg=[0], starts="random:3")
    (folder / "small.yaml").write_text(yaml.safe_dump(spec))
    run = simulate.run

    def fail_at_180(plan, params, progress=None):
        if params.fov == 180:
            raise RuntimeError("camera\nbroke")
        return run(plan, params, progress)

    monkeypatch.setattr(simulate, "run", fail_at_180)
    monkeypatch.setattr(sweep, "local_executor", lambda jobs: Inline())
    result = invoke("small.yaml", "--json")
    assert result.exit_code == 1, result.output
    assert json.loads(result.output)["failed"] == 1
    with (folder / "sweeps" / "small" / "results.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert [(r["fov"], r["status"], r["error"]) for r in rows] == [
        ("360.0", "done", ""),
        ("180.0", "failed", "RuntimeError: camera broke"),
    ]
    monkeypatch.setattr(simulate, "run", run)  # fixed: the failed job runs again, the other stays
    result = invoke("small.yaml", "--json")
    assert result.exit_code == 0, result.output
    assert (json.loads(result.output)["ran"], json.loads(result.output)["from_store"]) == (1, 1)


def _refused_address() -> str:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp://127.0.0.1:{probe.getsockname()[1]}"  # closed again: nothing listens there


@pytest.mark.parametrize(
    "change, args, message",
    [
        ({"colour": ["red"]}, (), "small.yaml: colour: unknown key"),
        ({"fov": []}, (), "small.yaml: fov: empty list"),
        ({"maps": ["maps/none.yaml"]}, (), "small.yaml: maps: maps/none.yaml does not exist"),
        ({"maps": ["maps/none*.yaml"]}, (), "small.yaml: maps: no file matches"),
        ({"fov": [400]}, (), "small.yaml: fov: "),
        ({"tags": ["theirs"]}, (), "small.yaml: tags: expected own, proposed or proposed:FOV,NOISE"),
        ({}, ("--jobs", "0"), "--jobs: must be at least 1, got 0"),
        ({}, ("--scheduler", "REFUSED"), "--scheduler: cannot reach the Dask scheduler at tcp://127.0.0.1:"),
        ({}, ("--report",), "--report: sweeps/small holds no sweep yet"),
    ],
)
def test_bad_input_is_one_line_exit_3_and_nothing_written(folder, change, args, message):
    if "REFUSED" in args:
        pytest.importorskip("distributed")
        args = tuple(_refused_address() if a == "REFUSED" else a for a in args)
    (folder / "small.yaml").write_text(yaml.safe_dump({**SWEEP, **change}))
    result = invoke("small.yaml", *args)
    assert result.exit_code == 3, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and message in lines[0].replace("error: ", ""), result.output
    assert not (folder / "sweeps").exists()


def test_a_sweep_file_reads_scalars_as_lists_and_leaves_unset_axes_to_the_defaults():
    read = sweep.read_sweep({"maps": "a.yaml", "fov": 90, "tags": ["own", "proposed:60,1"]}, "s.yaml")
    assert read.name == "s" and read.axes["maps"] == ("a.yaml",) and read.axes["fov"] == (90.0,)
    assert read.axes["noise_deg"] == (None,) and [t.text for t in read.axes["tags"]] == ["own", "proposed:60,1"]
