"""Bad input through the command line: one line naming file and field, exit 3, nothing written."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from .test_map import BAD_MAPS


def assert_one_line_error(result, *words):
    assert result.exit_code == 3, result.output
    lines = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, result.output
    assert "Traceback" not in result.output
    for word in words:
        assert word in lines[0], (word, lines[0])


@pytest.mark.parametrize("edit, field", BAD_MAPS)
def test_every_bad_map_exits_3_naming_file_and_field(cli, write_map, small_spec, tmp_path, edit, field):
    edit(small_spec)
    path = write_map(small_spec)
    result = cli("map", path, "-o", tmp_path / "out.json")
    assert_one_line_error(result, "small.yaml", field)
    assert not (tmp_path / "out.json").exists()
    assert list(tmp_path.glob("*.tmp*")) == []


def test_plan_with_a_bad_map_writes_no_plan_folder(cli, write_map, small_spec, tmp_path):
    small_spec["goal"] = [4.5, 4.5]
    result = cli("plan", write_map(small_spec), "-o", tmp_path / "plans")
    assert_one_line_error(result, "small.yaml", "goal")
    assert not (tmp_path / "plans").exists() or not any((tmp_path / "plans").rglob("*.*"))


def test_missing_file_and_yaml_syntax_error(cli, tmp_path):
    assert_one_line_error(cli("map", tmp_path / "nowhere.yaml"), "nowhere.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("name: x\nbounds: [0, 0, 10\n")
    assert_one_line_error(cli("map", broken), "broken.yaml")
    listing = tmp_path / "list.yaml"
    listing.write_text("- 1\n- 2\n")
    assert_one_line_error(cli("map", listing), "list.yaml", "top level")


def write_grid(tmp_path, image_bytes: bytes, image: str = "grid.pgm") -> None:
    (tmp_path / image).write_bytes(image_bytes)
    meta = {
        "image": image,
        "resolution": 0.1,
        "origin": [0.0, 0.0, 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
        "mode": "trinary",
    }
    (tmp_path / "grid.yaml").write_text(yaml.safe_dump(meta))


def pgm(gray: np.ndarray) -> bytes:
    h, w = gray.shape
    return f"P5\n{w} {h}\n255\n".encode() + gray.astype(np.uint8).tobytes()


def occupancy_map(tmp_path) -> object:
    spec = {
        "name": "grid",
        "occupancy": "grid.yaml",
        "goal": [0.5, 0.5],
        "landmarks": [[0.0, 0.0], [4.0, 3.0], [0.0, 3.0]],
        "starts": [[3.5, 2.5]],
    }
    path = tmp_path / "grid_map.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def test_unreadable_image_is_named(cli, tmp_path):
    write_grid(tmp_path, b"P5\n40 30\n255\n\x00\x01")  # truncated pixel data
    result = cli("map", occupancy_map(tmp_path), "-o", tmp_path / "out.json")
    assert_one_line_error(result, "grid.pgm")
    assert not (tmp_path / "out.json").exists()


def test_missing_image_is_named(cli, tmp_path):
    write_grid(tmp_path, pgm(np.full((30, 40), 254)))
    (tmp_path / "grid.pgm").unlink()
    assert_one_line_error(cli("map", occupancy_map(tmp_path)), "grid.pgm")


def test_occupancy_map_end_to_end(cli, tmp_path):
    gray = np.full((30, 40), 254)
    gray[10:20, 15:25] = 0  # a 1 m x 1 m block in the middle of a 4 m x 3 m room
    write_grid(tmp_path, pgm(gray))
    result = cli("map", occupancy_map(tmp_path), "-o", tmp_path / "out.json")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "out.json").exists()


def test_bare_ros_yaml_needs_a_goal(cli, tmp_path):
    write_grid(tmp_path, pgm(np.full((30, 40), 254)))
    assert_one_line_error(cli("map", tmp_path / "grid.yaml"), "grid.yaml", "goal")
    result = cli(
        "map",
        tmp_path / "grid.yaml",
        "--goal",
        "0.5,0.5",
        "--landmark",
        "0,0",
        "--landmark",
        "4,3",
        "-o",
        tmp_path / "bare.json",
    )
    assert result.exit_code == 0, result.output
    # other options are another input: the map stage reruns (it used to report "fresh")
    again = cli(
        "map",
        tmp_path / "grid.yaml",
        "--goal",
        "0.5,0.5",
        "--landmark",
        "0,0",
        "--landmark",
        "3,3",
        "-o",
        tmp_path / "bare.json",
    )
    assert again.exit_code == 0 and "fresh" not in again.output, again.output
    import json

    landmarks = [lm["position"] for lm in json.loads((tmp_path / "bare.json").read_text())["landmarks"]]
    assert landmarks == [[0.0, 0.0], [3.0, 3.0]]


def test_bad_stage_option_value(cli, write_map, small_spec, tmp_path):
    small_spec["params"]["rrtstar"]["iterations"] = "many"
    assert_one_line_error(cli("plan", write_map(small_spec), "-o", tmp_path / "p"), "small.yaml", "iterations")


def assert_internal_error(result, *words):
    """A bug of bearnav's own: one line, exit 70 (not 3: it must not read as bad input)."""
    assert result.exit_code == 70, result.output
    lines = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and lines[0].startswith("error: internal error"), result.output
    assert "Traceback" not in result.output
    for word in words:
        assert word in lines[0], (word, lines[0])


def test_a_stage_output_that_fails_its_own_checks_is_an_internal_error(
    cli, write_map, small_spec, tmp_path, monkeypatch
):
    from bearnav_cli import artifacts
    from bearnav_cli.errors import ArtifactError

    checks = artifacts.writing.validate_artifact

    def broken(kind, artifact, **kwargs):
        if kind == "cells":
            raise ArtifactError("a broken invariant", field="cell_b")
        return checks(kind, artifact, **kwargs)

    monkeypatch.setattr(artifacts.writing, "validate_artifact", broken)
    result = cli("plan", write_map(small_spec), "-o", tmp_path / "plans")
    assert_internal_error(result, "decompose", "cell_b", "a bug in bearnav")
    assert not (tmp_path / "plans" / "cells.npz").exists() and (tmp_path / "plans" / "simplified.npz").exists()


def test_an_unexpected_exception_is_an_internal_error(cli, write_map, small_spec, tmp_path, monkeypatch):
    from bearnav_cli.stages import simplify

    def crash(*args, **kwargs):
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(simplify, "run", crash)
    assert_internal_error(cli("plan", write_map(small_spec), "-o", tmp_path / "plans"), "simplify", "ZeroDivisionError")
