"""Perception coverage from the command line (issue 11 part 2): `bearnav map --fov` and `bearnav plot --fov`.

`map --fov` reports, before any plan, where some heading and where every heading of the camera
sees a usable pair, without changing the map artifact; `plot --fov` marks on the plan figure where
the rule along the field fails, exactly the points ``perception_coverage`` computes. Bad camera
options and a non-plan artifact exit 3 with one line and write nothing.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bearnav_cli import artifacts, perception, plot
from bearnav_cli.cli.options import CAMERA_OPTIONS

from .test_cli_errors import assert_one_line_error
from .test_hostile_common import small_plan


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> dict[str, Path]:
    return small_plan(tmp_path_factory.mktemp("perception"))


def _manifest(cli, path: Path) -> dict:
    """``bearnav inspect --json`` of an artifact: content hash, key, params, stats, ... (not the run time)."""
    manifest = json.loads(cli("inspect", path, "--json").output)
    manifest.pop("elapsed_s")
    assert len(manifest["content_sha256"]) == 64
    return manifest


# --------------------------------------------------------------------------- bearnav map --fov


def test_map_fov_reports_and_leaves_the_map_artifact_unchanged(cli, write_map, small_spec, tmp_path):
    source = write_map(small_spec)
    plain = cli("map", source, "-o", tmp_path / "plain" / "map.json")
    assert plain.exit_code == 0, plain.output
    seeing = cli("map", source, "-o", tmp_path / "seeing" / "map.json", "--fov", "60")
    assert seeing.exit_code == 0, seeing.output
    assert _manifest(cli, tmp_path / "plain" / "map.json") == _manifest(cli, tmp_path / "seeing" / "map.json")
    lines = seeing.output.splitlines()
    assert lines[0].startswith("map") and lines[1].startswith("  perception:"), seeing.output
    assert "some heading" in lines[1] and "every heading" in lines[1] and "60° camera" in lines[1]
    # rerun into the same file with --force: the same content
    again = cli("map", source, "-o", tmp_path / "plain" / "map.json", "--fov", "90", "--range", "5", "--force")
    assert again.exit_code == 0, again.output
    assert _manifest(cli, tmp_path / "plain" / "map.json") == _manifest(cli, tmp_path / "seeing" / "map.json")
    assert "range 5" in again.output


def test_map_fov_json_carries_the_report_and_the_hint_follows_the_fraction(cli, write_map, small_spec, tmp_path):
    for keep, name in ((5, "five"), (2, "two")):
        spec = dict(small_spec, landmarks=small_spec["landmarks"][:keep])
        source = write_map(spec, f"{name}.yaml")
        result = cli("map", source, "-o", tmp_path / name / "map.json", "--fov", "60", "--json", "-q")
        assert result.exit_code == 0, result.output
        (row,) = json.loads(result.output)
        report = row["perception"]
        assert row["stage"] == "map" and report["fov_deg"] == 60 and report["range"] is None
        assert 0 <= report["fraction_every_heading"] <= report["fraction_some_heading"] <= 1
        expected = perception.heading_coverage(artifacts.load(tmp_path / name / "map.json").artifact, 60.0)
        assert report["fraction_some_heading"] == expected.fraction_some
        assert report["blind_points"] == len(expected.blind) and report["grid_points"] == len(expected.points)
        text = cli("map", source, "-o", tmp_path / name / "map.json", "--fov", "60").output
        # the hint names the plan `bearnav plan` will write next to this map.json, and the map YAML
        tags = f"`bearnav tags {tmp_path / name / 'plan.npz'} --fov 60 --map {source}`"
        assert (tags in text.replace("\n", "")) == (expected.fraction_some < 1.0), text
    assert expected.fraction_some < 1.0  # two tags on the small map leave blind spots
    plain = json.loads(cli("map", source, "-o", tmp_path / "two" / "map.json", "--json", "-q").output)
    assert "perception" not in plain[0]  # without --fov, the same rows as before


@pytest.mark.parametrize(
    "args,option",
    [(("--fov", "0"), "--fov"), (("--fov", "400"), "--fov"), (("--fov", "nan"), "--fov"),
     (("--fov", "60", "--range", "-1"), "--range"), (("--fov", "60", "--range", "0"), "--range"),
     (("--range", "3"), "--range")],
)  # fmt: skip
def test_map_refuses_a_bad_camera_in_one_line_and_writes_nothing(cli, write_map, small_spec, tmp_path, args, option):
    out = tmp_path / "m" / "map.json"
    assert_one_line_error(cli("map", write_map(small_spec), "-o", out, *args), option)
    assert not out.exists() and not (tmp_path / "m").exists()


# --------------------------------------------------------------------------- bearnav plot --fov


def test_plot_fov_draws_what_perception_computes(cli, built, tmp_path, monkeypatch):
    figures = []
    save = plot.save_figure
    monkeypatch.setattr(plot, "save_figure", lambda fig, path: (figures.append(fig), save(fig, path)))
    figure = tmp_path / "f.png"
    result = cli("plot", built["plan"], "--fov", "60", "--noise-deg", "2", "-o", figure)
    assert result.exit_code == 0, result.output
    assert figure.is_file() and figure.stat().st_size > 0
    plan = artifacts.load(built["plan"]).artifact
    expected = perception.perception_coverage(plan, 60.0, 2.0)
    assert f"perception: {expected.summary()}" in result.output.replace("\n", " "), result.output
    (fig,) = figures
    by_gid = {c.get_gid(): c for c in fig.axes[0].collections if c.get_gid()}
    assert len(by_gid["perception-fail-domain"].get_offsets()) == len(expected.failing_domain)
    assert len(by_gid["perception-fail-free"].get_offsets()) == len(expected.failing_free)
    assert (by_gid["perception-fail-domain"].get_offsets() == expected.failing_domain).all()
    assert "field" in by_gid and "cell-outlines" in by_gid  # on top of the usual plan figure
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert any(f"{1 - expected.fraction_domain:.1%} of D" in t for t in labels), labels
    ranged = cli("plot", built["plan"], "--fov", "120", "--range", "3", "-o", tmp_path / "g.svg")
    assert ranged.exit_code == 0 and "range 3" in ranged.output and "1° noise" in ranged.output, ranged.output
    plain = cli("plot", built["plan"], "-o", tmp_path / "h.png")
    assert plain.exit_code == 0 and "perception" not in plain.output


def test_plot_fov_refuses_an_artifact_that_is_not_a_plan(cli, built, tmp_path):
    for kind, schema in (("map", "bearnav.map/1"), ("tree", "bearnav.tree/"), ("simulation", "bearnav.sim/")):
        out = tmp_path / f"{kind}.png"
        assert_one_line_error(cli("plot", built[kind], "--fov", "60", "-o", out), "--fov", schema, "not a plan")
        assert not out.exists()
        assert cli("plot", built[kind], "-o", out).exit_code == 0  # without --fov it draws


@pytest.mark.parametrize(
    "args,option",
    [(("--fov", "0"), "--fov"), (("--fov", "361"), "--fov"), (("--fov", "-60"), "--fov"),
     (("--fov", "60", "--noise-deg", "-1"), "--noise-deg"), (("--fov", "60", "--noise-deg", "inf"), "--noise-deg"),
     (("--fov", "60", "--range", "-2"), "--range"), (("--noise-deg", "1"), "--noise-deg"),
     (("--range", "2"), "--range")],
)  # fmt: skip
def test_plot_refuses_a_bad_camera_in_one_line_and_writes_nothing(cli, built, tmp_path, args, option):
    out = tmp_path / "bad.png"
    assert_one_line_error(cli("plot", built["plan"], *args, "-o", out), option)
    assert not out.exists() and list(tmp_path.glob("*.tmp*")) == []


def test_verify_names_the_camera_options_it_shares(cli, built):
    assert_one_line_error(cli("verify", built["plan"], "--fov", "400", "--starts", "0"), "--fov")
    assert_one_line_error(
        cli("verify", built["plan"], "--fov", "60", "--noise-deg", "-1", "--starts", "0"), "--noise-deg"
    )
    # one table of option names for map, plot and verify: every field the camera check can name
    for field in ("fov", "noise_deg", "range"):
        assert CAMERA_OPTIONS[field].startswith("--")
