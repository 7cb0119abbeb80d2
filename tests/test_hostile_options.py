"""Hostile input, part 2: option extremes and output paths.

Every numeric option has a documented range (``limits.LIMITS``, docs/cli.md "Option limits");
big requests are checked against a memory (or step) estimate before they start; every output
path is checked before any work. Each refused case exits 3 with one line on stderr naming the
option (or the map field, or the path) and writes nothing.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from bearnav_cli import artifacts, limits

from .test_hostile_common import (
    REPO,
    assert_clean_failure,
    copy_plan,
    invoke,
    small_plan,
    small_spec,
    snapshot,
    temp_files,
    write_yaml,
)


@pytest.fixture(scope="session")
def built(tmp_path_factory) -> dict[str, Path]:
    return small_plan(tmp_path_factory.mktemp("hostile_options"))


#: (command, input kind, options, the words of the one error line). The input is the small plan's.
OPTION_CASES = [
    ("rrtstar", "map", ["--seed", "-1"], "--seed"),
    ("rrtstar", "map", ["--seed", str(2**32)], "--seed"),
    ("rrtstar", "map", ["--seed", str(10**30)], "--seed"),
    ("rrtstar", "map", ["--iterations", "0"], "--iterations"),
    ("rrtstar", "map", ["--iterations", str(10**12)], "--iterations"),
    ("rrtstar", "map", ["--iterations", str(10**7 + 1)], "--iterations"),
    ("rrtstar", "map", ["--step", "1e-4"], "--step"),
    ("rrtstar", "map", ["--step", "1e-300"], "--step"),  # a grid count beyond any float (was exit 70)
    ("rrtstar", "map", ["--step", "1e-320"], "--step"),
    ("rrtstar", "map", ["--step", "1e-300", "--border-spacing", "1e-310"], "--"),
    ("rrtstar", "map", ["--step", "0"], "--step"),
    ("rrtstar", "map", ["--step", "-1"], "--step"),
    ("rrtstar", "map", ["--step", "1e300"], "--step"),
    ("rrtstar", "map", ["--step", "nan"], "--step"),
    ("rrtstar", "map", ["--step", "inf"], "--step"),
    ("rrtstar", "map", ["--step", "0.001"], "--step"),
    ("rrtstar", "map", ["--border-spacing", "1e-12"], "--border-spacing"),
    ("rrtstar", "map", ["--border-spacing", "-1"], "--border-spacing"),
    ("rrtstar", "map", ["--clearance", "1e300"], "--clearance"),
    ("rrtstar", "map", ["--clearance", "-0.1"], "--clearance"),
    ("rrtstar", "map", ["--collision-policy", "bounce"], "--collision-policy"),
    ("simplify", "tree", ["--max-rounds", "0"], "--max-rounds"),
    ("simplify", "tree", ["--max-rounds", str(10**9)], "--max-rounds"),
    ("simplify", "tree", ["--clearance", "nan"], "--clearance"),
    ("decompose", "simplified", ["--barrier-margin", "1e300"], "--barrier-margin"),
    ("decompose", "simplified", ["--barrier-margin", "-1"], "--barrier-margin"),
    ("decompose", "simplified", ["--exit-inset", "-1"], "--exit-inset"),
    ("decompose", "simplified", ["--exit-inset", "1e300"], "--exit-inset"),
    ("decompose", "simplified", ["--coverage-target", "2"], "--coverage-target"),
    ("decompose", "simplified", ["--max-added-nodes", "-1"], "--max-added-nodes"),
    ("decompose", "simplified", ["--max-added-nodes", str(10**9)], "--max-added-nodes"),
    ("decompose", "simplified", ["--n-landmarks", "1"], "--n-landmarks"),
    ("decompose", "simplified", ["--n-landmarks", str(10**6)], "--n-landmarks"),
    ("decompose", "simplified", ["--cells", "hexagons"], "--cells"),
    ("decompose", "simplified", ["--bisector-rule", "parent"], "--bisector-rule"),  # paper B's text: not offered
    ("synthesize", "cells", ["--u-max", "0"], "--u-max"),
    ("synthesize", "cells", ["--u-max", "1e300"], "--u-max"),
    ("synthesize", "cells", ["--kappa", "nan"], "--kappa"),
    ("synthesize", "cells", ["--halvings", str(10**6)], "--halvings"),
    ("synthesize", "cells", ["--halvings", "-1"], "--halvings"),
    ("synthesize", "cells", ["--goal-tolerance", "-1"], "--goal-tolerance"),
    ("synthesize", "cells", ["--goal-tolerance", "1e300"], "--goal-tolerance"),
    ("simulate", "plan", ["--seed", "-1"], "--seed"),
    ("simulate", "plan", ["--starts", "random:100000000"], "--starts"),
    ("simulate", "plan", ["--starts", "random:0"], "starts"),
    ("simulate", "plan", ["--starts", "everywhere"], "starts"),
    ("simulate", "plan", ["--starts", "1e400,1"], "starts"),
    ("simulate", "plan", ["--starts", "50,50"], "starts"),
    ("simulate", "plan", ["--fov", "0"], "--fov"),
    ("simulate", "plan", ["--fov", "1000"], "--fov"),
    ("simulate", "plan", ["--noise-deg", "-1"], "--noise-deg"),
    ("simulate", "plan", ["--noise-deg", "1e300"], "--noise-deg"),
    ("simulate", "plan", ["--speed", "0"], "--speed"),
    ("simulate", "plan", ["--speed", "1e-12"], "--speed"),
    ("simulate", "plan", ["--speed", "1e300"], "--speed"),
    ("simulate", "plan", ["--dt", "1e-12"], "--dt"),
    ("simulate", "plan", ["--dt", "1e300"], "--dt"),
    ("simulate", "plan", ["--range", "0"], "--range"),
    ("simulate", "plan", ["--hold-time", "1e300"], "--hold-time"),
    ("simulate", "plan", ["--odometry-noise", "5"], "--odometry-noise"),
    ("simulate", "plan", ["--alpha", "-1", "--dynamics", "unicycle"], "--alpha"),
    ("simulate", "plan", ["--beta", "inf", "--dynamics", "unicycle"], "--beta"),
    ("simulate", "plan", ["--min-success", "2"], "--min-success"),
    ("simulate", "plan", ["--dynamics", "teleport"], "--dynamics"),
    # issue 22's bounded noise: negative, non-finite or >= 45 degrees
    ("simulate", "plan", ["--noise-bound-deg", "-1"], "--noise-bound-deg"),
    ("simulate", "plan", ["--noise-bound-deg", "nan"], "--noise-bound-deg"),
    ("simulate", "plan", ["--noise-bound-deg", "inf"], "--noise-bound-deg"),
    ("simulate", "plan", ["--noise-bound-deg", "45"], "--noise-bound-deg"),
    ("simulate", "plan", ["--compass-error-deg", "-0.1"], "--compass-error-deg"),
    ("simulate", "plan", ["--slip", "-1"], "--slip"),
    ("simulate", "plan", ["--slip-floor", "inf"], "--slip-floor"),
    ("verify", "plan", ["--seed", "-1"], "--seed"),
    ("verify", "plan", ["--starts", "10000000"], "--starts"),
    ("verify", "plan", ["--starts", "-1"], "--starts"),
    ("verify", "plan", ["--speed", "0"], "--speed"),
    ("verify", "plan", ["--speed", "1e-12"], "--speed"),
    ("verify", "plan", ["--min-success", "2"], "--min-success"),
    ("verify", "plan", ["--live-fov", "0"], "--live-fov"),
    ("verify", "plan", ["--live-fov", "60", "--bearing-error-deg", "45"], "--bearing-error-deg"),
    ("verify", "plan", ["--live-fov", "60", "--slip", "1"], "--slip"),
    ("verify", "plan", ["--live-fov", "60", "--live-resolution", "0"], "--live-resolution"),
]


def _output(command: str, tmp_path: Path) -> list:
    name = {
        "rrtstar": "tree.npz",
        "simplify": "simplified.npz",
        "decompose": "cells.npz",
        "synthesize": "plan.npz",
        "simulate": "sim.npz",
    }.get(command)
    return ["-o", tmp_path / "out" / name] if name else []


@pytest.mark.parametrize(
    "command, kind, options, word", OPTION_CASES, ids=[f"{c}-{' '.join(o)}" for c, _, o, _ in OPTION_CASES]
)
def test_odd_option_is_one_line_exit_3_naming_it(built, tmp_path, command, kind, options, word):
    folder = copy_plan(built, tmp_path / "plan")
    (tmp_path / "out").mkdir()
    before = snapshot(tmp_path)
    result = invoke(command, folder / built[kind].name, *_output(command, tmp_path), *options)
    assert_clean_failure(result, 3, (word,))
    assert snapshot(tmp_path) == before


PLAN_OPTION_CASES = [
    (["--seed", "-1"], "--seed"),
    (["--iterations", str(10**12)], "--iterations"),
    (["--iterations", "0"], "--iterations"),
    (["--step", "1e-4"], "--step"),
    (["--step", "-3"], "--step"),
]


@pytest.mark.parametrize("options, word", PLAN_OPTION_CASES, ids=[" ".join(o) for o, _ in PLAN_OPTION_CASES])
def test_plan_refuses_odd_options_before_any_stage(tmp_path, options, word):
    yaml_path = write_yaml(tmp_path / "small.yaml", small_spec())
    result = invoke("plan", yaml_path, "-o", tmp_path / "p", *options)
    assert_clean_failure(result, 3, (word,))
    # the map stage may have run (its options are fine); nothing of the refused stage or after it
    assert not any((tmp_path / "p" / name).exists() for name in ("tree.npz", "simplified.npz", "cells.npz"))
    assert temp_files(tmp_path) == []


MAP_PARAM_CASES = [
    ({"rrtstar": {"seed": -1}}, "params.rrtstar.seed"),
    ({"rrtstar": {"iterations": 1e12}}, "params.rrtstar.iterations"),
    ({"rrtstar": {"iterations": "many"}}, "params.rrtstar.iterations"),
    ({"rrtstar": {"step": 1e-4}}, "params.rrtstar.step"),
    ({"rrtstar": {"border_spacing": "tiny"}}, "params.rrtstar.border_spacing"),
    ({"rrtstar": 5}, "params.rrtstar"),
    ({"decompose": {"barrier_margin": 1e300}}, "params.decompose.barrier_margin"),
    ({"simulate": {"seed": -5}}, "params.simulate.seed"),
    ({"simulate": {"max_steps": 10**12}}, "params.simulate.max_steps"),
    ({"map": {"circle_segments": 10**9}}, "params.map.circle_segments"),
    ({"map": {"coverage_cells": 10**7}}, "params.map.coverage_cells"),
    ({"warp": {"speed": 9}}, "params.warp"),
]


@pytest.mark.parametrize("params, word", MAP_PARAM_CASES, ids=[w for _, w in MAP_PARAM_CASES])
def test_odd_map_params_are_one_line_naming_the_field(tmp_path, params, word):
    spec = small_spec()
    spec["params"] = params
    yaml_path = write_yaml(tmp_path / "small.yaml", spec)
    result = invoke("plan", yaml_path, "-o", tmp_path / "p")
    assert_clean_failure(result, 3, ("small.yaml", word) if not word.startswith("params.rrtstar.step") else (word,))
    assert not (tmp_path / "p" / "tree.npz").exists()
    assert temp_files(tmp_path) == []


def test_the_step_limit_names_the_step_that_fits(built, tmp_path):
    line = assert_clean_failure(invoke("rrtstar", built["map"], "-o", tmp_path / "t.npz", "--step", "1e-4"), 3)
    assert re.search(r"use at least \d", line), line
    line = assert_clean_failure(
        invoke("rrtstar", built["map"], "-o", tmp_path / "t.npz", "--border-spacing", "1e-5"), 3
    )
    assert "--border-spacing" in line and re.search(r"at least \d", line), line


def test_memory_estimates_refuse_with_the_numbers(built, tmp_path, monkeypatch):
    """With a small budget every estimate refuses, saying how much it needs and what fits."""
    monkeypatch.setattr(limits, "memory_budget", lambda: 50_000_000)
    line = assert_clean_failure(invoke("rrtstar", built["map"], "-o", tmp_path / "t.npz", "--iterations", "1000000"))
    assert "--iterations" in line and "needs about" in line and re.search(r"at most [\d,]+ fit", line), line
    line = assert_clean_failure(
        invoke("simulate", built["plan"], "-o", tmp_path / "s.npz", "--starts", "random:100000")
    )
    assert "--starts" in line and "needs about" in line and "at most" in line, line
    line = assert_clean_failure(invoke("verify", built["plan"], "--starts", "100000"))
    assert "--starts" in line and "needs about" in line, line
    assert list(tmp_path.iterdir()) == []


def test_seed_range_is_what_numpy_takes_in_32_bits(built, tmp_path):
    for seed in ("0", str(2**32 - 1)):
        result = invoke(
            "-q", "rrtstar", built["map"], "-o", tmp_path / f"t{seed}.npz", "--seed", seed, "--iterations", "50"
        )
        assert result.exit_code in (0, 1), result.output
    assert limits.SEED.text() == "integer in [0, 4294967295]"


def test_version_exits_0():
    result = invoke("--version")
    assert result.exit_code == 0 and result.stdout.startswith("bearnav "), result.output


# --------------------------------------------------------------------------- output paths


def _stage_outputs(built: dict, tmp_path: Path) -> dict[str, list]:
    return {
        "simplify": ["simplify", built["tree"]],
        "rrtstar": ["rrtstar", built["map"]],
        "simulate": ["simulate", built["plan"], "--starts", "random:2"],
        "plot": ["plot", built["plan"]],
    }


OUTPUT_CASES = [
    # (command, how to make the -o path, the words)
    ("simplify", "existing-folder", "is a folder"),
    ("simplify", "parent-is-a-file", "is a file"),
    ("simplify", "unknown-extension", "extension"),
    ("simplify", "no-extension", "no extension"),
    ("simplify", "is-the-input", "is the input"),
    ("rrtstar", "existing-folder", "is a folder"),
    ("rrtstar", "unknown-extension", "extension"),
    ("simulate", "existing-folder", "is a folder"),
    ("simulate", "json-extension", "extension"),
    ("simulate", "metrics-path-is-a-folder", "is a folder"),
    ("plot", "existing-folder", "is a folder"),
    ("plot", "no-extension", "no extension"),
    ("plot", "unknown-extension", "extension"),
    ("plot", "parent-is-a-file", "is a file"),
    ("plot", "is-the-input", "extension"),
]


def _make_out(how: str, tmp_path: Path, built: dict, command: str) -> Path:
    suffix = ".png" if command == "plot" else ".npz"
    if how == "existing-folder":
        path = tmp_path / f"already{suffix}"
        path.mkdir()
        (path / "keep.txt").write_text("mine")
        return path
    if how == "parent-is-a-file":
        (tmp_path / "afile").write_text("x")
        return tmp_path / "afile" / f"out{suffix}"
    if how == "unknown-extension":
        return tmp_path / "out.dat"
    if how == "no-extension":
        return tmp_path / "out"
    if how == "json-extension":
        return tmp_path / "sim.json"
    if how == "metrics-path-is-a-folder":
        (tmp_path / "sim.json").mkdir()
        return tmp_path / "sim.npz"
    if how == "is-the-input":
        return built["tree"] if command == "simplify" else built["plan"]
    raise AssertionError(how)


@pytest.mark.parametrize("command, how, word", OUTPUT_CASES, ids=[f"{c}-{h}" for c, h, _ in OUTPUT_CASES])
def test_bad_output_path_is_refused_before_any_work(built, tmp_path, command, how, word):
    plan_folder = copy_plan(built, tmp_path / "plan")
    local = {k: plan_folder / v.name for k, v in built.items() if k != "yaml"}
    target = _make_out(how, tmp_path, local, command)
    before = snapshot(tmp_path)
    result = invoke(*_stage_outputs(local, tmp_path)[command], "-o", target)
    assert_clean_failure(result, 3, (word, "-o/--out"))
    assert snapshot(tmp_path) == before
    assert temp_files(tmp_path) == []


def test_plot_into_an_existing_folder_writes_no_png_beside_it(built, tmp_path):
    (tmp_path / "figs").mkdir()
    assert_clean_failure(invoke("plot", built["plan"], "-o", tmp_path / "figs"), 3, ("is a folder",))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figs"] and not any((tmp_path / "figs").iterdir())


@pytest.mark.parametrize("command", ["simplify", "plot"])
def test_a_missing_parent_folder_is_created(built, tmp_path, command):
    suffix = ".png" if command == "plot" else ".npz"
    target = tmp_path / "new" / "deeper" / f"out{suffix}"
    result = invoke("-q", *_stage_outputs(built, tmp_path)[command], "-o", target)
    assert result.exit_code == 0, result.output
    assert target.is_file() and temp_files(tmp_path) == []


@pytest.mark.parametrize(
    "how, word", [("folder", "is a folder"), ("extension", "extension"), ("parent-file", "is a file")]
)
def test_gif_path_is_checked_before_the_simulation_runs(built, tmp_path, how, word):
    if how == "folder":
        gif = tmp_path / "anim.gif"
        gif.mkdir()
    elif how == "extension":
        gif = tmp_path / "anim.png"
    else:
        (tmp_path / "f").write_text("x")
        gif = tmp_path / "f" / "anim.gif"
    before = snapshot(tmp_path)
    result = invoke("simulate", built["plan"], "-o", tmp_path / "sim.npz", "--starts", "random:2", "--gif", gif)
    assert_clean_failure(result, 3, ("--gif", word))
    assert snapshot(tmp_path) == before  # no sim.npz / sim.json either


def test_plan_into_a_file_or_over_a_folder_is_refused(tmp_path):
    yaml_path = write_yaml(tmp_path / "small.yaml", small_spec())
    (tmp_path / "plainfile").write_text("x")
    assert_clean_failure(invoke("plan", yaml_path, "-o", tmp_path / "plainfile"), 3, ("is a file",))
    (tmp_path / "p" / "tree.npz").mkdir(parents=True)
    before = snapshot(tmp_path)
    assert_clean_failure(invoke("plan", yaml_path, "-o", tmp_path / "p"), 3, ("tree.npz", "is a folder"))
    assert snapshot(tmp_path) == before and not (tmp_path / "p" / "map.json").exists()


def test_map_output_checks(tmp_path):
    yaml_path = write_yaml(tmp_path / "small.yaml", small_spec())
    (tmp_path / "m.json").mkdir()
    assert_clean_failure(invoke("map", yaml_path, "-o", tmp_path / "m.json"), 3, ("is a folder",))
    assert_clean_failure(invoke("map", yaml_path, "-o", tmp_path / "m.npz"), 3, ("extension",))


def test_an_unwritable_folder_is_refused(built, tmp_path, monkeypatch):
    """As root every folder is writable, so the permission answer is simulated (``os.access``)."""
    locked = tmp_path / "locked"
    locked.mkdir()
    real = os.access
    monkeypatch.setattr(artifacts.outputs.os, "access", lambda p, mode: False if Path(p) == locked else real(p, mode))
    for args in (
        ["simplify", built["tree"], "-o", locked / "s.npz"],
        ["plot", built["plan"], "-o", locked / "f.png"],
        ["plan", built["yaml"], "-o", locked / "p"],
    ):
        assert_clean_failure(invoke(*args), 3, ("not writable",))
    assert list(locked.iterdir()) == []


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes everywhere")
def test_a_really_unwritable_folder_is_refused(built, tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        assert_clean_failure(invoke("simplify", built["tree"], "-o", locked / "s.npz"), 3, ("not writable",))
    finally:
        locked.chmod(0o700)


# --------------------------------------------------------------------------- the documented limits


def test_every_limit_is_documented():
    text = (REPO / "docs" / "cli.md").read_text()
    rows = dict(re.findall(r"^\| ([a-z]+ `[a-z_]+`) \| ([^|]+) \|", text, flags=re.M))
    for stage, ranges in limits.LIMITS.items():
        for name, limit in ranges.items():
            key = f"{stage} `{name}`"
            assert key in rows, f"{key} missing from docs/cli.md 'Option limits'"
            assert rows[key].strip() == limit.text(), key
    assert len(rows) == sum(len(v) for v in limits.LIMITS.values())


@pytest.mark.skipif(not os.environ.get("BEARNAV_HOSTILE_FULL"), reason="a GIF takes seconds: BEARNAV_HOSTILE_FULL=1")
def test_gif_into_a_missing_folder_is_created(built, tmp_path):
    gif = tmp_path / "new" / "anim.gif"
    result = invoke(
        "-q",
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
    )
    assert result.exit_code == 0, result.output
    assert gif.is_file() and temp_files(tmp_path) == []
