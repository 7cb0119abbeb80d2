"""Manifests, content hashes, cache keys, freshness, atomic writes and loading checks (DESIGN §3.1)."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from bearnav_cli import artifacts, pipeline
from bearnav_cli.errors import ArtifactError

MANIFEST_FIELDS = {
    "schema",
    "stage",
    "stage_version",
    "params",
    "input",
    "content_sha256",
    "key",
    "software",
    "summary",
    "elapsed_s",
}


def _plan(cli, path, *extra):
    result = cli("plan", path, *extra)  # not --quiet: it leaves only the last stage line
    assert result.exit_code == 0, result.output
    return result.output


def test_plan_writes_every_artifact_with_a_complete_manifest(cli, write_map, small_spec, tmp_path):
    _plan(cli, write_map(small_spec))
    folder = tmp_path / "plans" / "small"
    for stage in pipeline.STAGES:
        loaded = artifacts.load(folder / stage.filename, stage.output_kind)
        manifest = loaded.manifest
        assert MANIFEST_FIELDS <= set(manifest)
        assert manifest["stage"] == stage.name
        assert manifest["schema"] == artifacts.KINDS[stage.output_kind].schema
        # the manifest's params are complete: every field of the stage's Params is there
        assert set(manifest["params"]) == {f for f in stage.module.Params.__dataclass_fields__}
        assert manifest["key"] == artifacts.cache_key(
            stage.name, stage.module.VERSION, manifest["params"], manifest["input"]["content_sha256"]
        )
    # the chain: each stage's input hash is the previous artifact's content hash
    previous = None
    for stage in pipeline.STAGES:
        manifest = artifacts.read_manifest(folder / stage.filename)
        if previous is not None:
            assert manifest["input"]["content_sha256"] == previous["content_sha256"]
        previous = manifest


def test_second_plan_skips_and_changed_parameter_reruns(cli, write_map, small_spec, tmp_path):
    path = write_map(small_spec)
    n = len(pipeline.STAGES)
    first = _plan(cli, path)
    assert first.count(" ran ") == n
    second = _plan(cli, path)
    assert second.count("fresh") == n and " ran " not in second
    third = _plan(cli, path, "--seed", "7")
    assert stage_states(third) == {stage.name: "fresh" if stage.name == "map" else "ran" for stage in pipeline.STAGES}
    forced = _plan(cli, path, "--seed", "7", "--force")
    assert forced.count(" ran ") == n


def stage_states(output: str) -> dict[str, str]:
    """``{stage: "ran" | "fresh"}`` from the lines ``bearnav plan`` prints."""
    names = {stage.name for stage in pipeline.STAGES}
    states = {}
    for line in output.splitlines():
        words = line.split()
        if len(words) > 1 and words[0] in names:
            states[words[0]] = words[1]
    return states


def test_content_identical_rerun_does_not_invalidate_the_next_stage(cli, write_map, small_spec, tmp_path):
    path = write_map(small_spec)
    _plan(cli, path)
    # a comment changes the file (the map stage reruns) but not the map itself
    path.write_text(path.read_text() + "\n# a comment\n")
    out = _plan(cli, path)
    assert stage_states(out) == {stage.name: "ran" if stage.name == "map" else "fresh" for stage in pipeline.STAGES}


@pytest.mark.parametrize("edited", ["simulate", "simplify"])
def test_editing_one_stage_params_reruns_that_stage_and_later_ones_only(cli, write_map, small_spec, tmp_path, edited):
    """Issue 14.1: the map's ``params:`` are out of its content hash; each stage's own are in its key."""
    path = write_map(small_spec)
    _plan(cli, path)
    edit = {"simulate": {"speed": 0.2}, "simplify": {"ctl": "extremes"}}[edited]
    small_spec.setdefault("params", {})[edited] = edit
    write_map(small_spec)
    states = stage_states(_plan(cli, path))
    order = [stage.name for stage in pipeline.STAGES]
    first = order.index(edited) if edited in order else len(order)
    # the map stage reads the YAML, so it always reruns; nothing before the edited stage does
    assert states["map"] == "ran" and all(states[name] == "fresh" for name in order[1:first])
    if edited in order:  # the edited stage reruns (those after it rerun when its output changed)
        assert states[edited] == "ran"
    # plan.npz, fresh or not, embeds the map's current params: alone it drives `bearnav simulate`
    plan = artifacts.load(tmp_path / "plans" / "small" / "plan.npz", "plan")
    assert plan.artifact.map.params == small_spec["params"]
    assert plan.manifest["content_sha256"] == artifacts.content_hash(artifacts.entries_of(plan.artifact), "plan")


def test_same_seed_same_hash_other_seed_other_hash(cli, write_map, small_spec, tmp_path):
    path = write_map(small_spec)
    hashes = []
    for seed, name in ((0, "a"), (0, "b"), (1, "c")):
        result = cli("plan", path, "-o", tmp_path / name, "--seed", seed, "--quiet")
        assert result.exit_code == 0, result.output
        hashes.append(artifacts.read_manifest(tmp_path / name / "tree.npz")["content_sha256"])
    assert hashes[0] == hashes[1] != hashes[2]


def test_exception_during_save_leaves_no_file(cli, write_map, small_spec, tmp_path, monkeypatch):
    _plan(cli, write_map(small_spec))
    loaded = artifacts.load(tmp_path / "plans" / "small" / "tree.npz", "tree")
    target = tmp_path / "out" / "tree.npz"

    def broken(handle, arrays):
        handle.write(b"PK\x03\x04 half an archive")
        raise RuntimeError("disk full")

    monkeypatch.setattr(artifacts.writing, "_write_npz", broken)
    with pytest.raises(RuntimeError):
        artifacts.save(target, loaded.artifact, loaded.manifest)
    assert not target.exists()
    assert list(target.parent.iterdir()) == []  # the temp file is gone too


def test_tampered_and_corrupted_files_are_rejected(cli, write_map, small_spec, tmp_path):
    _plan(cli, write_map(small_spec))
    source = tmp_path / "plans" / "small" / "tree.npz"
    with np.load(source, allow_pickle=False) as npz:
        data = {k: npz[k] for k in npz.files}
    data["nodes"] = data["nodes"] + 1e-6  # an edit that keeps the old manifest
    tampered = tmp_path / "tampered.npz"
    np.savez(tampered, **data)
    with pytest.raises(ArtifactError, match="content hash"):
        artifacts.load(tampered)
    result = cli("simplify", tampered)
    assert result.exit_code == 3 and "content hash" in result.output
    assert not (tmp_path / "simplified.npz").exists()

    corrupted = tmp_path / "corrupted.npz"
    corrupted.write_bytes(source.read_bytes()[:200])
    result = cli("simplify", corrupted)
    assert result.exit_code == 3 and "corrupted" in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_wrong_artifact_type_is_named(cli, write_map, small_spec, tmp_path):
    _plan(cli, write_map(small_spec))
    result = cli("simplify", tmp_path / "plans" / "small" / "map.json")
    assert result.exit_code == 3
    assert "bearnav.map/1" in result.output and "bearnav.tree/1" in result.output


def test_npz_without_manifest_and_nan_entries(tmp_path):
    plain = tmp_path / "plain.npz"
    np.savez(plain, nodes=np.zeros((2, 2)))
    with pytest.raises(ArtifactError, match="manifest"):
        artifacts.load(plain)
    not_zip = tmp_path / "text.npz"
    not_zip.write_text("hello")
    with pytest.raises(ArtifactError):
        artifacts.load(not_zip)
    assert zipfile.is_zipfile(plain)


def test_nan_in_an_artifact_is_rejected(cli, write_map, small_spec, tmp_path):
    _plan(cli, write_map(small_spec))
    source = tmp_path / "plans" / "small" / "tree.npz"
    with np.load(source, allow_pickle=False) as npz:
        data = {k: npz[k] for k in npz.files}
    manifest = json.loads(str(data.pop("manifest")))
    data["cost"] = data["cost"].copy()
    data["cost"][1] = np.nan
    entries = {k: (str(v) if v.dtype.kind == "U" else v) for k, v in data.items()}
    manifest["content_sha256"] = artifacts.content_hash(entries, "tree")  # a consistent but bad file
    np.savez(tmp_path / "nan.npz", manifest=np.array(json.dumps(manifest)), **data)
    with pytest.raises(ArtifactError, match="NaN"):
        artifacts.load(tmp_path / "nan.npz")


def test_artifacts_compare_and_hash_without_raising(small_spec):
    """Frozen artifact types hold arrays: == is identity and hash works (generated ones raised)."""
    from tests.conftest import build_map

    a, b = build_map(small_spec), build_map(small_spec)
    assert a == a and a != b  # equal content, two objects: compare content hashes for content
    assert len({a, b, a}) == 2
    assert len({a.obstacles[0], b.obstacles[0]}) == 2  # polygons hash too


# --------------------------------------------------------------------------- the one schema, pipeline.compute


def test_compute_makes_what_plan_writes(small_spec, tmp_path):
    """``pipeline.compute`` resolves parameters as ``plan`` does: the same artifacts, the same content hashes."""
    from bearnav_cli.stages import map_

    source = map_.MapSource(spec=small_spec, file="small.yaml", sha256="0")
    overrides = {"rrtstar": {"seed": 3}, "synthesize": {"u_max": 0.8}}
    reports = pipeline.plan(source, tmp_path / "small", overrides)
    made = pipeline.compute(source, overrides=overrides)
    assert list(made) == [stage.output_kind for stage in pipeline.STAGES]
    for report in reports:
        kind = pipeline.STAGE_BY_NAME[report.stage].output_kind
        assert artifacts.content_hash(artifacts.entries_of(made[kind]), kind) == report.manifest["content_sha256"]
    # from a normalised map, through any stage: only the artifacts up to it
    partial = pipeline.compute(made["map"], through="simplify", overrides=overrides)
    assert list(partial) == ["map", "tree", "simplified"] and partial["map"] is made["map"]
    assert artifacts.entries_of(partial["simplified"]).keys() == artifacts.entries_of(made["simplified"]).keys()
    with pytest.raises(ValueError, match="unknown stage"):
        pipeline.compute(made["map"], through="plan")


def test_every_artifact_has_the_dtypes_and_shapes_the_schema_declares(small_spec):
    """The containers, the loader's table and the run-time view all read ``runtime.schema``."""
    from bearnav_cli.runtime import PlanArrays, schema
    from bearnav_cli.stages import map_

    made = pipeline.compute(
        map_.MapSource(spec=small_spec, file="small.yaml", sha256="0"),
        through="simulate",
        overrides={"simulate": {"record_trajectories": True}},
    )
    plan = made["plan"]
    cells = plan.cells
    sizes = {
        "N": len(cells.nodes), "C": cells.n_cells, "L": len(plan.landmarks), "S": len(cells.collision_samples),
        "R": len(cells.cell_A), "V": len(cells.cell_vertices), "H": len(cells.cbf_A),
    }  # fmt: skip
    sim = made["simulation"]
    sim_sizes = {"R": len(sim), "P": len(sim.trajectory_coords), "N": sizes["N"], "C": sizes["C"], "V": sizes["V"]}
    tree = made["simplified"]
    for kind, artifact, dims in (
        ("tree", made["tree"], {"N": len(made["tree"].nodes), "S": len(made["tree"].collision_samples)}),
        ("simplified", tree, {"N": len(tree.nodes), "S": len(tree.collision_samples)}),
        ("cells", made["cells"], sizes),
        ("plan", plan, sizes),
        ("simulation", sim, sim_sizes),
    ):
        entries = artifacts.entries_of(artifact)
        assert list(entries) == list(schema.ENTRIES[kind]), kind
        assert artifacts.KINDS[kind].entries is schema.ENTRIES[kind]
        for key, entry in schema.ENTRIES[kind].items():
            value = entries[key]
            if entry.dtype == "str":
                assert isinstance(value, str), (kind, key)
                continue
            assert value.dtype == entry.numpy_dtype and value.shape == entry.resolve(dims), (kind, key)
    view = PlanArrays.from_plan(plan)
    for key in schema.RUNTIME_KEYS:
        entry = schema.ENTRIES["plan"][key]
        if entry.ndim:
            assert getattr(view, key).dtype == entry.numpy_dtype and getattr(view, key).shape == entry.resolve(sizes)


def test_an_artifacts_stats_and_params_are_read_only(small_spec):
    """Issue 14.5: frozen artifacts hold read-only mappings; readers see plain dicts (JSON, ==)."""
    import copy

    from bearnav_cli import pipeline
    from bearnav_cli.datatypes import FrozenDict
    from tests.conftest import build_map

    built = pipeline.compute(build_map(small_spec), through="simplify")
    tree, map_ = built["simplified"], built["map"]
    for mapping in (tree.stats, map_.params, map_.params["rrtstar"], map_.source):
        assert isinstance(mapping, FrozenDict)
        with pytest.raises(TypeError, match="read-only"):
            mapping["x"] = 1
        with pytest.raises(TypeError):
            mapping.update(x=1)
    assert map_.params == small_spec["params"] and json.loads(json.dumps(map_.params)) == small_spec["params"]
    editable = copy.deepcopy(map_.params)
    editable["rrtstar"]["seed"] = 9  # a copy is a plain dict, and the artifact does not change
    assert (
        type(editable["rrtstar"]) is dict and map_.params["rrtstar"]["seed"] == small_spec["params"]["rrtstar"]["seed"]
    )
    assert type(map_.to_json()["params"]) is dict  # what YAML and JSON writers get


@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_a_written_file_has_the_umasks_mode_and_the_umask_is_left_alone(tmp_path, monkeypatch, mask):
    import os

    artifacts.atomic._umask.cache_clear()
    old = os.umask(mask)
    try:
        calls = []
        real = os.umask
        monkeypatch.setattr(artifacts.atomic.os, "umask", lambda m: calls.append(m) or real(m))
        artifacts.atomic_write(tmp_path / "x.txt", lambda handle: handle.write(b"x"))
        assert (tmp_path / "x.txt").stat().st_mode & 0o777 == 0o666 & ~mask
        if os.path.exists("/proc/self/status"):
            assert calls == []  # read from /proc: the umask was never changed, not even briefly
    finally:
        os.umask(old)
        artifacts.atomic._umask.cache_clear()


def test_manifests_record_the_input_relative_to_the_artifact(cli, write_map, small_spec, tmp_path):
    """Issue 27 (security): a shared artifact does not reveal the absolute paths of the machine that made it."""
    import os

    path = write_map(small_spec)
    out = tmp_path / "deep" / "p"
    assert cli("-q", "plan", os.path.abspath(path), "-o", out).exit_code == 0
    for name, source in (("map.json", path), ("tree.npz", out / "map.json"), ("plan.npz", out / "cells.npz")):
        recorded = artifacts.read_manifest(out / name)["input"]["path"]
        assert not os.path.isabs(recorded), (name, recorded)
        assert (out / recorded).resolve() == source.resolve(), (name, recorded)


def test_software_versions_are_the_installed_distributions():
    """The versions read from the dist-info folders' names are importlib.metadata's."""
    from importlib import metadata

    from bearnav_cli.artifacts import manifest

    for package in ("numpy", "shapely", "scipy", "highspy", "typer"):
        assert manifest._distribution_version(package) == metadata.version(package)
    assert manifest._distribution_version("no_such_distribution_here") is None
    versions = artifacts.software_versions()
    assert {k: versions[k] for k in ("numpy", "shapely", "scipy", "highspy")} == {
        k: metadata.version(k) for k in ("numpy", "shapely", "scipy", "highspy")
    }


def test_a_map_text_made_from_its_document_hashes_as_one_parsed_back(small_spec):
    """``plan_file.map_text`` writes the canonical text of a map document and what its content hash hashes from
    the document itself: the same texts as writing it and parsing it back (map.json as read, a stage's map as
    embedded), with and without the fields left out of the hash."""
    from bearnav_cli.runtime import plan_file

    from .conftest import build_map

    document = build_map(small_spec).to_json()
    document["params"] = {"rrtstar": {"seed": 3, "step": 0.5}, "simulate": {"starts": [[1.0, 2.0]]}}
    for doc in (document, {k: v for k, v in document.items() if k != "source"}, {"name": "x", "bounds": [0, 1]}):
        text = plan_file.map_text(doc)
        assert text == plan_file.canonical_json(doc)
        remembered = plan_file.content_hash({"map": text})
        plan_file._HASHED_MAP_TEXTS.clear()
        assert plan_file.content_hash({"map": text}) == remembered
    # a key json.dumps would write as a string: the plain canonical text, nothing remembered from the document
    assert plan_file.map_text({1: "a", 2: "b"}) == plan_file.canonical_json({1: "a", 2: "b"}) == '{"1":"a","2":"b"}'
