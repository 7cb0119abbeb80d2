"""Hostile runs: interrupts, kills, two runs into one folder, cache history, degenerate geometry, scale.

In-process cases raise the interrupt at a chosen point (deterministic, fast); real-process cases
send SIGINT / SIGKILL to the installed ``bearnav`` at a few moments of its run. The denser sweeps
(and the bigger maps) run only with ``BEARNAV_HOSTILE_FULL=1``; by default a small sample runs, so
``make test`` stays within its budget.

Properties, never numbers from a run: the exit code, exactly one stderr line, no traceback, no
temp file left, every artifact present loads, and the content hashes after a rerun equal those of
a clean run in a fresh folder.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import shapely

from bearnav_cli import artifacts, pipeline, verify
from bearnav_cli.stages import decompose, map_, rrtstar, simplify, simulate, synthesize

from .funnel_maps import random_spec
from .test_hostile_common import (
    BEARNAV,
    assert_clean_failure,
    copy_plan,
    invoke,
    rewrite_npz,
    run_program,
    small_plan,
    small_spec,
    snapshot,
    temp_files,
    write_yaml,
)

FULL = bool(os.environ.get("BEARNAV_HOSTILE_FULL"))
full_only = pytest.mark.skipif(not FULL, reason="the full sweep: BEARNAV_HOSTILE_FULL=1")
NAMES = [stage.filename for stage in pipeline.STAGES]


@pytest.fixture(scope="session")
def built(tmp_path_factory) -> dict[str, Path]:
    return small_plan(tmp_path_factory.mktemp("hostile_runs"))


@pytest.fixture(scope="session")
def reference(built) -> dict[str, str]:
    """Content hashes of the small map's plan made in a fresh folder."""
    return hashes(built["plan"].parent)


def hashes(folder: Path) -> dict[str, str]:
    return {name: artifacts.read_manifest(folder / name)["content_sha256"] for name in NAMES}


def assert_consistent(folder: Path) -> None:
    """Every artifact present loads, no temp file is left, and each names the one before it."""
    assert temp_files(folder) == [], temp_files(folder)
    previous = None
    for name in NAMES:
        path = folder / name
        if not path.exists():
            previous = None
            continue
        manifest = pipeline.load(path).manifest
        if previous is not None:
            assert manifest["input"]["content_sha256"] == previous["content_sha256"], name
        previous = manifest


def plan_small(folder: Path, *extra: str, yaml_path: Path | None = None):
    yaml_path = yaml_path or write_yaml(folder.parent / "small.yaml", small_spec())
    return invoke("-q", "plan", yaml_path, "-o", folder, *extra)


# --------------------------------------------------------------------------- interrupts, in-process

STAGE_MODULES = {
    "map": map_,
    "rrtstar": rrtstar,
    "simplify": simplify,
    "decompose": decompose,
    "synthesize": synthesize,
}


@pytest.mark.parametrize("stage", list(STAGE_MODULES))
def test_sigint_inside_a_stage_names_it_and_writes_nothing_for_it(tmp_path, monkeypatch, reference, stage):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(STAGE_MODULES[stage], "run", interrupted)
    folder = tmp_path / "p"
    result = plan_small(folder)
    assert_clean_failure(result, 130, (f"interrupted; nothing written for {stage}",))
    index = NAMES.index(pipeline.STAGE_BY_NAME[stage].filename)
    assert not any((folder / name).exists() for name in NAMES[index:])
    if folder.exists():
        assert_consistent(folder)
    monkeypatch.undo()
    assert plan_small(folder).exit_code == 0
    assert hashes(folder) == reference


def test_sigint_inside_an_extension_import_is_an_interrupt_not_an_internal_error(tmp_path, monkeypatch, built):
    # pybind11 turns a KeyboardInterrupt raised while its module initialises into
    # "ImportError: initialization failed" (raised from it); CI once hit this inside highspy's import
    def import_interrupted(*args, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise ImportError("initialization failed") from exc

    monkeypatch.setattr(synthesize, "run", import_interrupted)
    result = plan_small(tmp_path / "p")
    assert_clean_failure(result, 130, ("interrupted; nothing written for synthesize",))


def test_sigint_while_an_artifact_is_written_leaves_no_temp_file(tmp_path, monkeypatch, built):
    def half_then_interrupt(handle, arrays):
        handle.write(b"PK\x03\x04 half an archive")
        raise KeyboardInterrupt

    monkeypatch.setattr(artifacts.writing, "_write_npz", half_then_interrupt)
    result = invoke("simplify", built["tree"], "-o", tmp_path / "s.npz")
    assert_clean_failure(result, 130, ("interrupted; nothing written for simplify",))
    assert list(tmp_path.iterdir()) == []


def test_sigint_while_the_input_is_read(tmp_path, monkeypatch, built):
    real = artifacts.reading.read_file

    def read(path):
        if Path(path).name == "plan.npz":
            raise KeyboardInterrupt
        return real(path)

    monkeypatch.setattr(artifacts.reading, "read_file", read)
    result = invoke("simulate", built["plan"], "-o", tmp_path / "sim.npz", "--starts", "random:2")
    assert_clean_failure(result, 130, ("interrupted; nothing written for simulate",))
    assert list(tmp_path.iterdir()) == []


def test_sim_npz_and_sim_json_land_together_even_when_interrupted_between(tmp_path, monkeypatch, built):
    """An interrupt already pending when the two renames begin is delivered after both."""
    real = os.replace
    calls = []

    def replace(src, dst):
        real(src, dst)
        calls.append(dst)
        if len(calls) == 1:
            raise KeyboardInterrupt

    monkeypatch.setattr(artifacts.atomic.os, "replace", replace)
    out = tmp_path / "sim.npz"
    result = invoke("simulate", built["plan"], "-o", out, "--starts", "random:2", "--min-success", "0")
    monkeypatch.undo()
    assert_clean_failure(result, 130, ("simulate was written",))
    manifest = artifacts.read_manifest(out)
    assert json.loads(out.with_suffix(".json").read_text())["manifest"] == manifest
    assert temp_files(tmp_path) == []
    again = invoke("simulate", built["plan"], "-o", out, "--starts", "random:2", "--min-success", "0")
    assert again.exit_code == 0 and again.stdout.split()[1] == "fresh", again.output


def test_sigint_while_the_gif_is_written_names_it_after_the_simulation(tmp_path, monkeypatch, built):
    """``simulate --gif``: the simulation is written, then an interrupt inside the GIF names the GIF."""
    from bearnav_cli import plot

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(plot, "save_animation", interrupted)
    gif = tmp_path / "runs.gif"
    result = invoke(
        "simulate",
        built["plan"],
        "-o",
        tmp_path / "sim.npz",
        "--starts",
        "random:2",
        "--min-success",
        "0",
        "--gif",
        gif,
        "-q",
    )
    assert_clean_failure(result, 130, (f"interrupted; nothing written for {gif} (sim.npz and sim.json were written)",))
    assert not gif.exists() and (tmp_path / "sim.npz").exists() and temp_files(tmp_path) == []


def test_an_activity_names_its_block_and_then_what_was_named_before():
    """``pipeline.activity``: set for the block, restored after it; an exception leaves it set, for the error
    handler outside the block to name."""
    pipeline.reset_activity()
    with pipeline.activity("simulate", "plan.npz"):
        pipeline.ACTIVITY.written = True
        with pipeline.activity("runs.gif", file="plan.npz") as inner:
            assert (inner.stage, inner.written, inner.file) == ("runs.gif", False, "plan.npz")
        assert (pipeline.ACTIVITY.stage, pipeline.ACTIVITY.written) == ("simulate", True)
    assert pipeline.ACTIVITY == pipeline.Activity()
    with pytest.raises(KeyboardInterrupt), pipeline.activity("verify"):
        raise KeyboardInterrupt
    assert pipeline.ACTIVITY.stage == "verify"
    pipeline.reset_activity()


def test_sigterm_is_one_line_and_exit_143(tmp_path, monkeypatch, built):
    def terminated(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)  # the handler raises before this ends
        raise AssertionError("SIGTERM was not delivered")

    monkeypatch.setattr(simplify, "run", terminated)
    result = invoke("simplify", built["tree"], "-o", tmp_path / "s.npz")
    assert_clean_failure(result, 143, ("terminated; nothing written for simplify",))
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- interrupts and kills, real processes


def _duration(args: list, cwd: Path) -> float:
    started = time.perf_counter()
    result = run_program(*args, cwd=cwd)
    assert result.returncode == 0, result.stderr
    return time.perf_counter() - started


def _interrupt_at(args: list, cwd: Path, delay: float, sig: int = signal.SIGINT) -> subprocess.CompletedProcess:
    """Run ``bearnav args`` and send ``sig`` after ``delay`` s; the result's ``signalled`` says whether the
    program was still running when the signal was sent (else it had finished first, and the run
    tested nothing about the signal)."""
    process = subprocess.Popen(
        [str(BEARNAV), *map(str, args)], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    time.sleep(delay)
    running = process.poll() is None
    process.send_signal(sig)
    out, err = process.communicate(timeout=120)
    result = subprocess.CompletedProcess(process.args, process.returncode, out, err)
    result.signalled = running
    return result


#: Moments of the SIGINT, as fractions of an uninterrupted run (start-up, the stages, the end).
SAMPLE_MOMENTS = (0.35, 0.75, 0.9)
FULL_MOMENTS = tuple(round(0.1 + 0.05 * k, 2) for k in range(18))


_DURATION: list[float] = []


def _sigint_plan(tmp_path: Path, reference: dict, moment: float) -> None:
    yaml_path = write_yaml(tmp_path / "small.yaml", small_spec())
    if not _DURATION:  # one uninterrupted run, timed (start-up included)
        _DURATION.append(_duration(["-q", "plan", yaml_path, "-o", tmp_path / "timing"], tmp_path))
    total = _DURATION[0]
    folder = tmp_path / "p"
    delay = max(0.1, moment * total)
    for _ in range(4):  # on a busy machine a run can finish before its moment: then try earlier
        result = _interrupt_at(["-q", "plan", yaml_path, "-o", folder], tmp_path, delay)
        if result.signalled:
            break
        delay *= 0.5
    assert result.signalled, "every run finished before its SIGINT: the test proved nothing"
    if result.returncode != 0:  # a signal after the last stage was saved may still end in exit 0
        line = assert_clean_failure(result, 130, ("interrupted;",), stderr=result.stderr)
        assert line.startswith("interrupted; "), line
    if folder.exists():
        assert_consistent(folder)
    again = run_program("-q", "plan", yaml_path, "-o", folder, cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert hashes(folder) == reference


@pytest.mark.parametrize("moment", SAMPLE_MOMENTS)
def test_sigint_during_a_real_plan(tmp_path, reference, moment):
    _sigint_plan(tmp_path, reference, moment)


@full_only
@pytest.mark.parametrize("moment", FULL_MOMENTS)
def test_sigint_during_a_real_plan_full_sweep(tmp_path, reference, moment):
    _sigint_plan(tmp_path, reference, moment)


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_temp_files_of_a_killed_run_are_removed_by_the_next(tmp_path, built):
    folder = copy_plan(built, tmp_path / "p")
    stale = folder / f"{artifacts.atomic._temp_prefix(folder / 'sim.npz', _dead_pid())}abc123.tmp"
    stale.write_bytes(b"PK\x03\x04 half of a simulation")
    alive = folder / f"{artifacts.atomic._temp_prefix(folder / 'sim.npz')}def456.tmp"  # a live writer's: left alone
    alive.write_bytes(b"busy")
    result = invoke("-q", "simulate", folder / "plan.npz", "--starts", "random:2", "--min-success", "0")
    assert result.exit_code == 0, result.output
    assert not stale.exists() and alive.exists()
    alive.unlink()


def _kill_simulate(tmp_path: Path, built: dict, delay: float) -> None:
    folder = copy_plan(built, tmp_path / "p")
    args = ["-q", "simulate", folder / "plan.npz", "--starts", "random:40", "--min-success", "0", "--force"]
    result = _interrupt_at(args, tmp_path, delay, signal.SIGKILL)
    assert result.returncode in (0, -signal.SIGKILL)
    sim, metrics = folder / "sim.npz", folder / "sim.json"
    if sim.exists():
        pipeline.load(sim)  # never half-written
    again = run_program(
        "-q", "simulate", folder / "plan.npz", "--starts", "random:40", "--min-success", "0", cwd=tmp_path
    )
    assert again.returncode == 0, again.stderr
    assert temp_files(folder) == []
    assert json.loads(metrics.read_text())["manifest"] == artifacts.read_manifest(sim)


@pytest.mark.parametrize("delay", [0.9])
def test_sigkill_during_simulate_leaves_nothing_mixed(tmp_path, built, delay):
    _kill_simulate(tmp_path, built, delay)


@full_only
@pytest.mark.parametrize("delay", [0.5, 0.7, 0.8, 1.0, 1.1, 1.2, 1.4, 1.6, 2.0])
def test_sigkill_during_simulate_full_sweep(tmp_path, built, delay):
    _kill_simulate(tmp_path, built, delay)


@pytest.mark.parametrize("damage", ["json-deleted", "json-edited", "npz-deleted", "untouched"])
def test_sim_pair_is_fresh_only_together(tmp_path, built, damage):
    folder = copy_plan(built, tmp_path / "p")
    args = ["-q", "simulate", folder / "plan.npz", "--starts", "random:5", "--min-success", "0"]
    sim, metrics = folder / "sim.npz", folder / "sim.json"
    if damage == "json-deleted":
        metrics.unlink()
    elif damage == "json-edited":
        document = json.loads(metrics.read_text())
        document["manifest"]["key"] = "0" * 64
        metrics.write_text(json.dumps(document))
    elif damage == "npz-deleted":
        sim.unlink()
    result = invoke(*args)
    assert result.exit_code == 0, result.output
    fresh = result.stdout.split()[1] == "fresh"
    assert fresh == (damage == "untouched"), result.stdout
    assert json.loads(metrics.read_text())["manifest"] == artifacts.read_manifest(sim)


# --------------------------------------------------------------------------- two runs into one folder


def test_a_second_run_into_a_locked_folder_refuses_in_one_line(tmp_path, built):
    folder = copy_plan(built, tmp_path / "p")
    before = snapshot(folder)
    with artifacts.output_folder(folder):
        plan = run_program("plan", built["yaml"], "-o", folder, "--seed", "1", cwd=tmp_path)
        sim = run_program("simulate", folder / "plan.npz", "--starts", "random:2", cwd=tmp_path)
    for result in (plan, sim):
        assert_clean_failure(result, 3, ("another bearnav run",), stderr=result.stderr)
    assert snapshot(folder) == before


def test_the_lock_of_a_killed_run_is_released(tmp_path, built):
    folder = tmp_path / "p"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\nfrom bearnav_cli import artifacts\n"
            f"with artifacts.output_folder({str(folder)!r}):\n    print('held', flush=True)\n    time.sleep(60)",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert holder.stdout.readline().strip() == "held"
    busy = run_program("-q", "plan", built["yaml"], "-o", folder, cwd=tmp_path)
    assert_clean_failure(busy, 3, ("another bearnav run",), stderr=busy.stderr)
    holder.kill()
    holder.wait()
    again = run_program("-q", "plan", built["yaml"], "-o", folder, cwd=tmp_path)
    assert again.returncode == 0, again.stderr


def _race(tmp_path: Path, reference: dict) -> None:
    yaml_path = write_yaml(tmp_path / "small.yaml", small_spec())
    folder = tmp_path / "p"
    processes = [
        subprocess.Popen(
            [str(BEARNAV), "-q", "plan", str(yaml_path), "-o", str(folder), "--seed", str(s)],
            cwd=tmp_path,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for s in (0, 1)
    ]
    results = [p.communicate(timeout=120) + (p.returncode,) for p in processes]
    assert any(code == 0 for _, _, code in results), results
    for _, err, code in results:
        if code != 0:
            line = assert_clean_failure(subprocess.CompletedProcess([], code, "", err), 3, stderr=err)
            assert "another bearnav run" in line, line
    assert_consistent(folder)
    again = run_program("-q", "plan", yaml_path, "-o", folder, "--seed", "0", cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert hashes(folder) == reference


def test_two_plans_with_different_seeds_into_one_folder(tmp_path, reference):
    _race(tmp_path, reference)


@full_only
@pytest.mark.parametrize("round_", range(6))
def test_two_plans_into_one_folder_full_sweep(tmp_path, reference, round_):
    _race(tmp_path, reference)


# --------------------------------------------------------------------------- cache history and determinism


def _other_map_then_small(folder: Path) -> None:
    other = write_yaml(folder.parent / "other.yaml", random_spec(3, iterations=200))
    assert invoke("-q", "plan", other, "-o", folder).exit_code in (0, 1)


def _same_map_other_file(folder: Path) -> None:
    spec = small_spec()
    path = folder.parent / "renamed.yaml"
    path.write_text("# the same map, another file and a comment\n" + write_yaml(path, spec).read_text())
    assert invoke("-q", "plan", path, "-o", folder).exit_code == 0


def _other_seed(folder: Path) -> None:
    assert plan_small(folder, "--seed", "1").exit_code == 0


def _damaged(folder: Path) -> None:
    assert plan_small(folder).exit_code == 0
    tree = folder / "tree.npz"
    tree.write_bytes(tree.read_bytes()[:500])
    (folder / "simplified.npz").unlink()
    rewrite_npz(folder / "cells.npz", folder / "cells.npz", lambda m, e: e["parent"].__setitem__(slice(1, 3), [2, 1]))


def _stale_other_params(folder: Path) -> None:
    assert plan_small(folder).exit_code == 0
    assert invoke("-q", "decompose", folder / "simplified.npz", "--coverage-target", "0.5").exit_code == 0


HISTORIES = {
    "another-maps-plan": _other_map_then_small,
    "same-map-other-yaml-file": _same_map_other_file,
    "other-seed": _other_seed,
    "damaged-and-cyclic-artifacts": _damaged,
    "a-stage-run-alone-with-other-options": _stale_other_params,
}


#: Histories that leave what bearnav will not replace without --force: another map's plan folder, a
#: tree.npz too damaged to show its manifest (bearnav cannot tell it wrote it).
NEEDS_FORCE = {"another-maps-plan": "p", "damaged-and-cyclic-artifacts": "tree.npz"}


@pytest.mark.parametrize("history", list(HISTORIES))
def test_same_input_same_hashes_whatever_the_folder_held(tmp_path, reference, history):
    folder = tmp_path / "p"
    HISTORIES[history](folder)
    result = plan_small(folder)
    if history in NEEDS_FORCE:
        assert result.exit_code == 3 and NEEDS_FORCE[history] in result.output and "--force" in result.output
        result = plan_small(folder, "--force")
    assert result.exit_code == 0, result.output
    assert hashes(folder) == reference
    assert_consistent(folder)


def test_force_gives_the_same_hashes(tmp_path, reference):
    folder = tmp_path / "p"
    assert plan_small(folder).exit_code == 0
    assert plan_small(folder, "--force").exit_code == 0
    assert hashes(folder) == reference


# --------------------------------------------------------------------------- degenerate geometry: verify

WALL_MAP = {
    "bounds": [0, 0, 8, 5], "robot_radius": 0.2, "goal": [1.0, 2.5], "starts": [[1.5, 1.0]],
    "landmarks": [[0, 0], [0, 5], [8, 0], [8, 5], [4.1, 1.0], [3.9, 4.0], [4.1, 4.0], [3.9, 1.0]],
    "params": {"rrtstar": {"iterations": 600, "seed": 0}},
}  # fmt: skip


def wall_map(name: str, gap: float) -> dict:
    """A wall across the room with one gap of ``gap`` map units (the robot is 0.4 wide)."""
    low, high = 2.5 - gap / 2, 2.5 + gap / 2
    return dict(WALL_MAP, name=name, obstacles=[{"rectangle": [3.9, 0, 4.1, low]}, {"rectangle": [3.9, high, 4.1, 5]}])


GAPS = {
    "doorway-narrower-than-the-robot": 0.3,
    "gap-0.2mm-wider-than-the-robot": 0.4002,
    "passage-narrower-than-the-margin": 0.45,
}


@pytest.mark.parametrize("case", list(GAPS))
def test_verify_fails_on_collisions_and_never_samples_unreached_regions(tmp_path, case):
    path = write_yaml(tmp_path / f"{case}.yaml", wall_map(case.split("-")[0], GAPS[case]))
    result = invoke("-q", "plan", path, "-o", tmp_path / "p")
    assert result.exit_code in (0, 1), result.output
    report = invoke("-q", "verify", tmp_path / "p" / "plan.npz", "--starts", "50", "--json")
    assert report.exit_code in (0, 1), report.output
    data = json.loads(report.stdout)
    collided = data["monte_carlo"]["outcomes"].get("collision", 0)
    assert (report.exit_code == 1) == data["failed"]
    if collided:  # from D it fails verify (the theorem says never); from outside D it is measured, a note
        said = [r for r in data["reasons"] + data["notes"] if "collided" in r]
        assert said and (report.exit_code == 1) == any("collided" in r for r in data["reasons"])
    # no start drawn where the tree never went
    plan = pipeline.load(tmp_path / "p" / "plan.npz").artifact
    full = verify.run(plan, verify.Params(n_starts=50, speed=0.1))
    if full.unreached.parts:
        assert not shapely.intersects_xy(full.unreached.region, *full.starts.T).any()
        assert data["unreached"]["area"] > 0 and data["notes"]


def test_one_collision_fails_verify_whatever_min_success_says(built, monkeypatch):
    """One collision from the certified domain fails verify (a funnel plan's theorem says it never happens)."""
    real = simulate.rollout

    def one_collision(*args, **kwargs):
        runs = real(*args, **kwargs)
        outcome = np.array(runs.outcome)
        outcome[np.flatnonzero(runs.start_in_domain)[0]] = simulate.Outcome.COLLISION
        return dataclasses.replace(runs, outcome=outcome)

    monkeypatch.setattr(simulate, "rollout", one_collision)
    result = invoke("verify", built["plan"], "--starts", "4", "--min-success", "0")
    assert result.exit_code == 1, result.output
    assert "collided" in result.stdout and "Traceback" not in result.output


# --------------------------------------------------------------------------- scale


def test_coordinates_times_1000(tmp_path):
    spec = small_spec()
    scale = 1000.0

    def grow(value):
        return [grow(v) for v in value] if isinstance(value, list) else value * scale

    spec["bounds"], spec["goal"], spec["starts"] = grow(spec["bounds"]), grow(spec["goal"]), grow(spec["starts"])
    spec["robot_radius"] *= scale
    spec["landmarks"] = [
        grow(lm) if isinstance(lm, list) else dict(lm, position=grow(lm["position"])) for lm in spec["landmarks"]
    ]
    spec["obstacles"] = [
        {"polygon": grow(spec["obstacles"][0]["polygon"])},
        {"rectangle": grow([4, 4, 6, 5])},
        {"circle": {"center": grow([8, 2]), "radius": 0.5 * scale}},
    ]
    spec["params"] = {"rrtstar": {"iterations": 400, "step": 1000.0, "seed": 0}}
    path = write_yaml(tmp_path / "big.yaml", spec)
    result = invoke("-q", "plan", path, "-o", tmp_path / "p")
    assert result.exit_code in (0, 1) and "Traceback" not in result.output, result.output
    # the default speed, 0.1 map units/s, would take millions of steps per run here: refused at once
    slow = invoke("-q", "verify", tmp_path / "p" / "plan.npz", "--starts", "5")
    assert_clean_failure(slow, 3, ("params.simulate.speed", "raise the speed"))
    check = invoke("-q", "verify", tmp_path / "p" / "plan.npz", "--starts", "5", "--speed", "100")
    assert check.exit_code in (0, 1) and "Traceback" not in check.output, check.output


@full_only
def test_2000_obstacles(tmp_path):
    rng = np.random.default_rng(0)
    centres = rng.uniform(1, 99, size=(2000, 2))
    spec = small_spec()
    spec.update(
        name="crowd",
        bounds=[0, 0, 100, 100],
        goal=[0.5, 0.5],
        starts=[],
        obstacles=[
            {"circle": {"center": c.round(3).tolist(), "radius": 0.3}} for c in centres if np.hypot(*(c - 0.5)) > 3
        ],
        landmarks=[[0, 0], [100, 0], [0, 100], [100, 100], [50, 0], [0, 50]],
        params={"rrtstar": {"iterations": 1500, "step": 2.0}},
    )
    path = write_yaml(tmp_path / "crowd.yaml", spec)
    made = invoke("-q", "map", path, "-o", tmp_path / "p" / "map.json")
    assert made.exit_code == 0, made.output
    result = invoke("-q", "rrtstar", tmp_path / "p" / "map.json")  # the map stage and RRT* (exact edge tests)
    assert result.exit_code in (0, 1) and "Traceback" not in result.output, result.output


@full_only
def test_100000_iterations(tmp_path):
    path = write_yaml(tmp_path / "small.yaml", small_spec(rrtstar={"iterations": 100_000}))
    assert invoke("-q", "map", path, "-o", tmp_path / "p" / "map.json").exit_code == 0
    result = invoke("-q", "rrtstar", tmp_path / "p" / "map.json")
    assert result.exit_code == 0 and "Traceback" not in result.output, result.output


def test_a_mixed_sim_pair_is_refused_by_every_reader(tmp_path, built):
    """Issue 27 item 7: a kill between the two renames leaves a new sim.npz beside another run's
    sim.json; every reader of sim.npz (plot, inspect) refuses that pair in one line (exit 3), naming
    sim.json, and the next simulate rewrites both."""
    folder = copy_plan(built, tmp_path / "p")
    old_metrics = (folder / "sim.json").read_text()  # copy_plan's simulation
    second = invoke("-q", "simulate", folder / "plan.npz", "--starts", "random:4", "--min-success", "0")
    assert second.exit_code == 0, second.output
    (folder / "sim.json").write_text(old_metrics)  # the pair a kill between the renames leaves
    for args in (["plot", folder / "sim.npz", "-o", tmp_path / "s.png"], ["inspect", folder / "sim.npz"]):
        assert_clean_failure(invoke(*args), 3, ("sim.json", "another run"))
    assert not (tmp_path / "s.png").exists()
    again = invoke("-q", "simulate", folder / "plan.npz", "--starts", "random:4", "--min-success", "0")
    assert again.exit_code == 0 and again.stdout.split()[1] != "fresh", again.output
    assert json.loads((folder / "sim.json").read_text())["manifest"] == artifacts.read_manifest(folder / "sim.npz")
