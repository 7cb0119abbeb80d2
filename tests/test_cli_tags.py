"""`bearnav tags` and `bearnav verify --fov` from the command line (issue 11 parts 1-2)."""

from __future__ import annotations

import yaml

from bearnav_cli.cli import read_map_source
from bearnav_cli.stages import map_

from .test_cli_errors import assert_one_line_error


def _plan(cli, write_map, small_spec, tmp_path):
    spec = dict(small_spec)
    spec["landmarks"] = spec["landmarks"][:2]  # too few for a 60° camera: tags are needed
    spec.setdefault("params", {})["rrtstar"] = {"iterations": 300, "seed": 0}
    result = cli("plan", write_map(spec), "-o", tmp_path / "p", "-q")
    assert (tmp_path / "p" / "plan.npz").exists(), result.output
    return tmp_path / "p" / "plan.npz"


def test_tags_writes_a_map_with_the_new_tags_and_a_figure(cli, write_map, small_spec, tmp_path):
    plan = _plan(cli, write_map, small_spec, tmp_path)
    out = tmp_path / "with_tags.yaml"
    result = cli("tags", plan, "--fov", "60", "-o", out)
    assert result.exit_code == 0, result.output
    assert out.exists() and out.with_suffix(".png").exists()
    spec = yaml.safe_load(out.read_text())
    ids = [t["id"] for t in spec["landmarks"]]
    assert len(ids) > 2 and len(set(ids)) == len(ids)  # new tags, new ids
    # the existing tags are kept as they were (their facing too, which the map stage inferred: on a wall)
    kept = [{"id": str(t["id"]), "position": t["position"], "facing": t.get("facing")} for t in spec["landmarks"][:2]]
    assert spec["landmarks"][:2] == kept and all(t["facing"] is not None for t in kept)
    new_map = map_.run(read_map_source(out))  # the map stage accepts it as it is
    assert len(new_map.landmarks) == len(ids)
    assert "new tags" in result.output and "two usable tags in view on" in result.output


def test_tags_with_too_few_tags_allowed_reports_and_exits_1(cli, write_map, small_spec, tmp_path):
    plan = _plan(cli, write_map, small_spec, tmp_path)
    result = cli("tags", plan, "--fov", "60", "--max-tags", "0", "-o", tmp_path / "none.yaml")
    assert result.exit_code == 1, result.output
    assert "target NOT reached" in result.output
    assert (tmp_path / "none.yaml").exists()  # it finishes and writes what it reached


def test_tags_and_verify_refuse_bad_camera_options_in_one_line(cli, write_map, small_spec, tmp_path):
    plan = _plan(cli, write_map, small_spec, tmp_path)
    for args, option in (
        (("--fov", "0"), "--fov"),
        (("--fov", "400"), "--fov"),
        (("--noise-deg", "-1"), "--noise-deg"),
        (("--range", "-2"), "--range"),
        (("--max-tags", "-1"), "--max-tags"),
    ):
        result = cli("tags", plan, *args, "-o", tmp_path / "bad.yaml")
        assert_one_line_error(result, option)
        assert not (tmp_path / "bad.yaml").exists()
    assert_one_line_error(cli("verify", plan, "--fov", "0", "--starts", "0"), "--fov")
    assert_one_line_error(cli("tags", plan, "-o", tmp_path / "bad.txt"), "bad.txt")


def test_verify_reports_perception_coverage(cli, write_map, small_spec, tmp_path):
    plan = _plan(cli, write_map, small_spec, tmp_path)
    result = cli("verify", plan, "--fov", "60", "--noise-deg", "1", "--starts", "0")
    assert "perception:" in result.output and "60° camera" in result.output, result.output


def test_tags_of_a_tags_map_counts_instead_of_repeating_the_suffix(tmp_path):
    """The default output of ``bearnav tags --map NAME_tags.yaml`` is NAME_tags2.yaml (a map planned from a map tags
    wrote, tagged again), never NAME_tags_tags.yaml; a map of another name gets NAME_tags.yaml."""
    from bearnav_cli.cli.hints import tags_output

    plan = tmp_path / "plans" / "office" / "plan.npz"
    names = {
        m: tags_output(plan, tmp_path / m).name
        for m in ("office.yaml", "office_tags.yaml", "office_tags2.yaml", "my_tags_room.yaml")
    }
    assert names == {
        "office.yaml": "office_tags.yaml",
        "office_tags.yaml": "office_tags2.yaml",
        "office_tags2.yaml": "office_tags3.yaml",
        "my_tags_room.yaml": "my_tags_room_tags.yaml",
    }
    assert tags_output(plan, None) == plan.parent / "map_tags.yaml"


def test_tags_extends_a_map_that_names_an_occupancy_grid(cli, tmp_path):
    """``bearnav tags PLAN --map M.yaml`` for a map with ``occupancy:`` beside it (what plan's blind-spot error
    prints): the new map keeps the grid and is accepted, written where tags_step said (M_tags.yaml), and plans."""
    from bearnav_cli.cli.hints import tags_output
    from tests import mapgen

    made = mapgen.generate(4, "grid", params={"rrtstar": {"iterations": 300, "seed": 0}})  # a small one: 0.4 s
    source = made.write(tmp_path / "maps")
    cli("plan", source, "-o", tmp_path / "p", "-q")
    plan = tmp_path / "p" / "plan.npz"
    assert plan.exists()
    result = cli("tags", plan, "--fov", "360", "--map", source, "-q")
    assert result.exit_code in (0, 1), result.output  # 1: the tag budget did not reach the target
    written = tags_output(plan, source)
    assert written == source.with_name(f"{source.stem}_tags.yaml") and written.exists()
    spec = yaml.safe_load(written.read_text())
    assert spec["occupancy"] == made.spec["occupancy"]
    assert map_.run(read_map_source(written)).landmarks.shape[0] == len(spec["landmarks"])
