"""Hostile input, part 1: damaged and meaningless artifacts fed to every command that reads them.

Every case copies one artifact of a small plan, damages it (the file, the zip, the manifest, the
entries) or edits its content and recomputes its content hash (a hash proves that a file is
intact, not that it makes sense), and feeds it to each consumer. Each must exit 3 with exactly
one line on stderr naming the file (and the field where there is one), without a traceback, and
write nothing (the scratch folder is byte-for-byte unchanged).
"""

from __future__ import annotations

import json
import os
import re
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
import shapely

from bearnav_cli import artifacts, datatypes, errors

from .test_hostile_common import (
    REPO,
    assert_clean_failure,
    deflate_damaged,
    edit_embedded_map,
    invoke,
    read_npz,
    rewrite_json,
    rewrite_npz,
    small_plan,
    snapshot,
)

NPZ_KINDS = ("tree", "simplified", "cells", "plan", "simulation")
ALL_KINDS = ("map", *NPZ_KINDS)

#: The commands that read each kind (``verify-tree``: ``verify --tree``; ``plot-also``: ``plot --also``).
CONSUMERS = {
    "map": ("rrtstar", "inspect", "plot"),
    "tree": ("simplify", "inspect", "plot", "verify-tree", "plot-also"),
    "simplified": ("decompose", "inspect", "plot", "plot-also"),
    "cells": ("synthesize", "inspect", "plot"),
    "plan": ("verify", "simulate", "inspect", "plot"),
    "simulation": ("inspect", "plot"),
}


@pytest.fixture(scope="session")
def built(tmp_path_factory) -> dict[str, Path]:
    return small_plan(tmp_path_factory.mktemp("hostile_artifacts"))


def command(consumer: str, damaged: Path, built: dict[str, Path], out: Path) -> list[Any]:
    """The command line of ``consumer`` reading ``damaged``, writing (if at all) into ``out``."""
    return {
        "rrtstar": ["rrtstar", damaged, "-o", out / "tree.npz"],
        "simplify": ["simplify", damaged, "-o", out / "simplified.npz"],
        "decompose": ["decompose", damaged, "-o", out / "cells.npz"],
        "synthesize": ["synthesize", damaged, "-o", out / "plan.npz"],
        "verify": ["verify", damaged, "--starts", "2"],
        "verify-tree": ["verify", built["plan"], "--tree", damaged, "--starts", "0"],
        "simulate": ["simulate", damaged, "-o", out / "sim.npz", "--starts", "random:2"],
        "inspect": ["inspect", damaged],
        "plot": ["plot", damaged, "-o", out / "figure.png"],
        "plot-also": ["plot", built["plan"], "--also", damaged, "-o", out / "figure.png"],
    }[consumer]


def check_refused(built: dict[str, Path], tmp_path: Path, consumer: str, damaged: Path, words: tuple[str, ...]):
    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    before = snapshot(tmp_path)
    result = invoke(*command(consumer, damaged, built, out))
    assert_clean_failure(result, 3, (damaged.name, *words))
    assert snapshot(tmp_path) == before, "something was written or changed"


# --------------------------------------------------------------------------- damaged files


def _truncated(src: Path, dst: Path) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: len(data) // 2])
    return dst


def _deflate(src: Path, dst: Path) -> Path:
    """Flip bytes in the middle of the largest compressed member (a damaged deflate stream)."""
    dst.write_bytes(deflate_damaged(src.read_bytes(), src))
    return dst


def _directory(src: Path, dst: Path) -> Path:
    """Scribble over the zip's central directory."""
    data = bytearray(src.read_bytes())
    start = data.find(b"PK\x01\x02")
    data[start : start + 46] = bytes(46)
    dst.write_bytes(bytes(data))
    return dst


def _eocd(src: Path, dst: Path) -> Path:
    """Point the end-of-central-directory record past the end of the file."""
    data = bytearray(src.read_bytes())
    end = data.rfind(b"PK\x05\x06")
    data[end + 16 : end + 20] = struct.pack("<I", len(data) + 1000)
    dst.write_bytes(bytes(data))
    return dst


def _npy(src: Path, dst: Path) -> Path:
    with open(dst, "wb") as handle:
        np.save(handle, np.zeros((3, 2)))
    return dst


def _bytes(content: bytes) -> Callable[[Path, Path], Path]:
    def make(src: Path, dst: Path) -> Path:
        dst.write_bytes(content)
        return dst

    return make


def _folder(src: Path, dst: Path) -> Path:
    dst.mkdir()
    return dst


def _missing(src: Path, dst: Path) -> Path:
    return dst


def _unreadable(src: Path, dst: Path) -> Path:
    if os.geteuid() == 0:
        pytest.skip("root reads every file: permissions cannot be tested")
    dst.write_bytes(src.read_bytes())
    dst.chmod(0)
    return dst


def _fifo(src: Path, dst: Path) -> Path:
    os.mkfifo(dst)  # reading it would block for ever: refused from its stat, never opened
    return dst


def _manifest(change: Callable[[dict], Any], rehashed: bool = False) -> Callable[[Path, Path], Path]:
    """A manifest edit of an npz (``change`` may return a raw replacement of the manifest entry)."""

    def make(src: Path, dst: Path) -> Path:
        return rewrite_npz(src, dst, lambda manifest, entries: change(manifest), rehashed=rehashed)

    return make


def _entries(change: Callable[[dict, dict], Any], rehashed: bool = True) -> Callable[[Path, Path], Path]:
    def make(src: Path, dst: Path) -> Path:
        def edit(manifest: dict, entries: dict) -> Any:
            change(manifest, entries)
            return None

        return rewrite_npz(src, dst, edit, rehashed=rehashed)

    return make


def _without_manifest(src: Path, dst: Path) -> Path:
    with np.load(src, allow_pickle=False) as npz:
        data = {k: npz[k] for k in npz.files if k != "manifest"}
    with open(dst, "wb") as handle:
        np.savez(handle, **data)
    return dst


def _object_entry(src: Path, dst: Path) -> Path:
    with np.load(src, allow_pickle=False) as npz:
        data = {k: npz[k] for k in npz.files}
    data["nodes"] = np.array([{"a": 1}, None], dtype=object)
    with open(dst, "wb") as handle:
        np.savez(handle, **data)
    return dst


#: A number entry of each kind, stored as text / as the wrong dtype.
NUMBER_ENTRY = {
    "tree": "parent",
    "simplified": "parent",
    "cells": "cell_flags",
    "plan": "cell_flags",
    "simulation": "outcome",
}


def _as_text(manifest: dict, entries: dict) -> None:
    key = NUMBER_ENTRY[artifacts.kind_of_schema(manifest["schema"])]
    entries[key] = ",".join(str(v) for v in np.asarray(entries[key]).ravel()[:5])


def _unsigned(manifest: dict, entries: dict) -> None:
    key = NUMBER_ENTRY[artifacts.kind_of_schema(manifest["schema"])]
    entries[key] = np.abs(np.asarray(entries[key])).astype(np.uint64)


def _retired(manifest: dict) -> None:
    manifest["schema"] = {"cells": "bearnav.cells/1", "plan": "bearnav.plan/1"}[
        artifacts.kind_of_schema(manifest["schema"])
    ]


@dataclass(frozen=True)
class Damage:
    make: Callable[[Path, Path], Path]
    kinds: tuple[str, ...]
    words: tuple[str, ...] = ()


DAMAGES: dict[str, Damage] = {
    "truncated": Damage(_truncated, ALL_KINDS),
    "empty": Damage(_bytes(b""), ALL_KINDS),
    "random-bytes": Damage(_bytes(np.random.default_rng(0).bytes(3000)), ALL_KINDS),
    "deflate-damaged": Damage(_deflate, NPZ_KINDS),
    "zip-directory-damaged": Damage(_directory, NPZ_KINDS),
    "zip-end-record-damaged": Damage(_eocd, NPZ_KINDS),
    "npy-not-npz": Damage(_npy, ALL_KINDS, (".npy",)),
    "json-text": Damage(_bytes(b'{"manifest": {"schema": "bearnav.tree/1"}}'), NPZ_KINDS),
    "folder": Damage(_folder, ALL_KINDS, ("folder",)),
    "missing": Damage(_missing, ALL_KINDS, ("no such file",)),
    "unreadable": Damage(_unreadable, ALL_KINDS, ("permission",)),
    "fifo": Damage(_fifo, ALL_KINDS, ("regular file",)),
    "no-manifest": Damage(_without_manifest, NPZ_KINDS, ("manifest",)),
    "manifest-not-json": Damage(_manifest(lambda m: np.array("{not json")), NPZ_KINDS, ("manifest",)),
    "manifest-a-list": Damage(_manifest(lambda m: np.array("[1, 2]")), NPZ_KINDS, ("manifest",)),
    "manifest-1d": Damage(_manifest(lambda m: np.array(["a", "b"])), NPZ_KINDS, ("manifest",)),
    "manifest-no-stage": Damage(_manifest(lambda m: m.pop("stage") and None), NPZ_KINDS, ("manifest.stage",)),
    "manifest-no-key": Damage(_manifest(lambda m: m.pop("key") and None), NPZ_KINDS, ("manifest.key",)),
    "manifest-no-hash": Damage(_manifest(lambda m: m.pop("content_sha256") and None), NPZ_KINDS,
                               ("manifest.content_sha256",)),
    "stats-not-object": Damage(_manifest(lambda m: m.update(stats=[1, 2])), NPZ_KINDS, ("manifest.stats",)),
    "params-not-object": Damage(_manifest(lambda m: m.update(params="x")), NPZ_KINDS, ("manifest.params",)),
    "input-not-object": Damage(_manifest(lambda m: m.update(input="x")), NPZ_KINDS, ("manifest.input",)),
    "stage-version-text": Damage(_manifest(lambda m: m.update(stage_version="1")), NPZ_KINDS,
                                 ("manifest.stage_version",)),
    "wrong-stage": Damage(_manifest(lambda m: m.update(stage="verify")), NPZ_KINDS, ("manifest.stage",)),
    "schema-unknown": Damage(_manifest(lambda m: m.update(schema="bearnav.tree/9")), NPZ_KINDS, ("schema",)),
    "schema-retired": Damage(_manifest(_retired), ("cells", "plan"), ("no longer reads",)),
    "edited-not-rehashed": Damage(_entries(lambda m, e: e.update(nodes=e["nodes"] + 1e-6), rehashed=False),
                                  NPZ_KINDS, ("content hash",)),
    "entry-missing": Damage(_entries(lambda m, e: e.pop("nodes")), NPZ_KINDS, ("nodes", "missing")),
    "entry-extra": Damage(_entries(lambda m, e: e.update(junk=np.zeros(3))), NPZ_KINDS, ("junk",)),
    "nodes-as-integers": Damage(_entries(lambda m, e: e.update(nodes=e["nodes"].astype(np.int64))), NPZ_KINDS,
                                ("nodes",)),
    "numbers-as-text": Damage(_entries(_as_text), NPZ_KINDS, ("text",)),
    "unsigned-integers": Damage(_entries(_unsigned), NPZ_KINDS),
    "object-entry": Damage(_object_entry, NPZ_KINDS, ("nodes",)),
    "map-not-json": Damage(_entries(lambda m, e: e.update(map="{not json")), NPZ_KINDS, ("map",)),
    "map-a-list": Damage(_entries(lambda m, e: e.update(map="[1, 2]")), NPZ_KINDS, ("map",)),
    "map-without-goal": Damage(_entries(lambda m, e: edit_embedded_map(e, lambda d: d.pop("goal"))), NPZ_KINDS,
                               ("map",)),
}  # fmt: skip


def _json_damage(change: Callable[[Any], Any], rehashed: bool = True) -> Callable[[Path, Path], Path]:
    def make(src: Path, dst: Path) -> Path:
        return rewrite_json(src, dst, change, rehashed=rehashed)

    return make


def _json_top(value: Any) -> Callable[[Path, Path], Path]:
    def make(src: Path, dst: Path) -> Path:
        dst.write_text(json.dumps(value))
        return dst

    return make


MAP_DAMAGES: dict[str, Damage] = {
    "a-list": Damage(_json_top([1, 2]), ("map",), ("JSON object",)),
    "not-utf8": Damage(_bytes(b"\xff\xfe{\x00"), ("map",)),
    "no-manifest": Damage(_json_damage(lambda d: d.pop("manifest")), ("map",), ("manifest",)),
    "manifest-a-list": Damage(_json_damage(lambda d: d.update(manifest=[1])), ("map",), ("manifest",)),
    "manifest-no-stage": Damage(_json_damage(lambda d: d["manifest"].pop("stage")), ("map",), ("manifest.stage",)),
    "manifest-no-key": Damage(_json_damage(lambda d: d["manifest"].pop("key")), ("map",), ("manifest.key",)),
    "stats-not-object": Damage(_json_damage(lambda d: d["manifest"].update(stats="x")), ("map",),
                               ("manifest.stats",)),
    "schema-unknown": Damage(_json_damage(lambda d: d["manifest"].update(schema="bearnav.map/7")), ("map",),
                             ("schema",)),
    "edited-not-rehashed": Damage(_json_damage(lambda d: d.update(robot_radius=0.3), rehashed=False), ("map",),
                                  ("content hash",)),
    "field-missing": Damage(_json_damage(lambda d: d.pop("obstacles")), ("map",), ("map",)),
    "bounds-a-string": Damage(_json_damage(lambda d: d.update(bounds="wide")), ("map",), ("map",)),
    "landmark-without-id": Damage(_json_damage(lambda d: d["landmarks"][0].pop("id")), ("map",), ("map",)),
}  # fmt: skip


def _damage_cases():
    for name, damage in DAMAGES.items():
        for kind in damage.kinds:
            for consumer in CONSUMERS[kind]:
                yield pytest.param(kind, name, consumer, id=f"{kind}-{name}-{consumer}")
    for name in MAP_DAMAGES:
        for consumer in CONSUMERS["map"]:
            yield pytest.param("map", f"json:{name}", consumer, id=f"map-json-{name}-{consumer}")


@pytest.mark.parametrize("kind, damage, consumer", list(_damage_cases()))
def test_damaged_artifact_is_one_line_exit_3_and_writes_nothing(built, tmp_path, kind, damage, consumer):
    source = built[kind]
    spec = MAP_DAMAGES[damage[5:]] if damage.startswith("json:") else DAMAGES[damage]
    folder = tmp_path / "in"
    folder.mkdir()
    damaged = spec.make(source, folder / source.name)
    check_refused(built, tmp_path, consumer, damaged, spec.words)


# --------------------------------------------------------------------------- edited and rehashed: meaning


def _obstacle_point(document: dict) -> list[float]:
    ring = document["obstacles"][0]["exterior"]
    return list(shapely.Polygon(ring).representative_point().coords[0])


def _set(path: str, value: Any) -> Callable[[dict], None]:
    def change(document: dict) -> None:
        target = document
        keys = path.split(".")
        for key in keys[:-1]:
            target = target[int(key)] if isinstance(target, list) else target.setdefault(key, {})
        target[int(keys[-1]) if isinstance(target, list) else keys[-1]] = value

    return change


def _goal_in_obstacle(document: dict) -> None:
    document["goal"] = _obstacle_point(document)


def _start_in_obstacle(document: dict) -> None:
    document["starts"] = [_obstacle_point(document)]


def _obstacle_nan(document: dict) -> None:
    document["obstacles"][0]["exterior"][0][0] = float("nan")


def _obstacle_two_points(document: dict) -> None:
    document["obstacles"][0]["exterior"] = document["obstacles"][0]["exterior"][:2]


def _obstacle_bowtie(document: dict) -> None:
    document["obstacles"][0] = {"exterior": [[7, 6], [8, 7], [8, 6], [7, 7]], "holes": []}


def _one_landmark(document: dict) -> None:
    document["landmarks"] = document["landmarks"][:1]


def _duplicate_ids(document: dict) -> None:
    document["landmarks"][1]["id"] = document["landmarks"][0]["id"]


#: Edits of a map (map.json, or the map embedded in a later artifact) and the field the error names.
MAP_EDITS: dict[str, tuple[Callable[[dict], None], str]] = {
    "goal-outside-bounds": (_set("goal", [25.0, 1.0]), "goal"),
    "goal-in-obstacle": (_goal_in_obstacle, "goal"),
    "goal-nan": (_set("goal", [float("nan"), 1.0]), "goal"),
    "goal-on-wall": (_set("goal", [0.0, 4.0]), "goal"),
    "start-in-obstacle": (_start_in_obstacle, "starts"),
    "obstacle-nan-vertex": (_obstacle_nan, "obstacles"),
    "obstacle-two-points": (_obstacle_two_points, "obstacles"),
    "obstacle-self-intersecting": (_obstacle_bowtie, "obstacles"),
    "robot-radius-negative": (_set("robot_radius", -0.5), "robot_radius"),
    "robot-radius-inf": (_set("robot_radius", float("inf")), "robot_radius"),
    "bounds-inverted": (_set("bounds", [10.0, 0.0, 0.0, 8.0]), "bounds"),
    "one-landmark": (_one_landmark, "landmarks"),
    "landmark-ids-repeated": (_duplicate_ids, "landmarks"),
    # issue 27 item 11: the YAML reader refused these, map.json did not
    "landmarks-at-one-position": (
        lambda d: d["landmarks"][1].update(position=d["landmarks"][0]["position"]),
        "landmarks",
    ),
    "facing-true": (lambda d: d["landmarks"][0].update(facing=True), "landmarks.facing"),
    "name-a-path": (_set("name", "../escape"), "name"),
    "params-wrong-type": (_set("params.rrtstar.iterations", "many"), "params.rrtstar.iterations"),
    "params-seed-negative": (_set("params.rrtstar.seed", -1), "params.rrtstar.seed"),
    "params-not-a-mapping": (_set("params.rrtstar", 5), "params"),
    "params-unknown-stage": (_set("params.nosuch", {"x": 1}), "params.nosuch"),
    "params-unknown-name": (_set("params.simulate.warp", 9), "params.simulate.warp"),
    "params-a-list-value": (_set("params.decompose.barrier_margin", [1, 2]), "params.decompose.barrier_margin"),
}


def _tree_cycle(m: dict, e: dict) -> None:
    parent = e["parent"]
    parent[1], parent[2] = 2, 1


def _set_entry(key: str, index: Any, value: Any) -> Callable[[dict, dict], None]:
    def change(m: dict, e: dict) -> None:
        array = np.array(e[key])
        array[index] = value
        e[key] = array

    return change


def _scalar(key: str, value: float) -> Callable[[dict, dict], None]:
    return lambda m, e: e.update({key: np.array(value)})


def _cost_off(m: dict, e: dict) -> None:
    e["cost"] = e["cost"].copy()
    e["cost"][1] += 1.0


def _root_moved(m: dict, e: dict) -> None:
    e["nodes"] = e["nodes"].copy()
    e["nodes"][0] += 0.5


def _clockwise(m: dict, e: dict) -> None:
    off = e["cell_vertex_offsets"]
    verts = e["cell_vertices"].copy()
    verts[off[1] : off[2]] = verts[off[1] : off[2]][::-1]
    e["cell_vertices"] = verts


def _offsets_decreasing(key: str) -> Callable[[dict, dict], None]:
    def change(m: dict, e: dict) -> None:
        off = e[key].copy()
        off[1], off[2] = off[2], off[1]
        e[key] = off

    return change


def _duplicate_cell_node(m: dict, e: dict) -> None:
    e["cell_node"] = e["cell_node"].copy()
    e["cell_node"][1] = e["cell_node"][2]


def _exit_dir_zero(m: dict, e: dict) -> None:
    e["exit_dir"] = e["exit_dir"].copy()
    e["exit_dir"][1] = 0.0


def _landmark_moved(m: dict, e: dict) -> None:
    e["landmarks"] = e["landmarks"].copy()
    e["landmarks"][0] += 1.0


TREE_EDITS = {
    "parent-cycle": (_tree_cycle, "parent"),
    "parent-out-of-range": (_set_entry("parent", 1, 10**6), "parent"),
    "two-roots": (_set_entry("parent", 1, -1), "parent"),
    "nodes-nan": (_set_entry("nodes", (1, 0), np.nan), "nodes"),
    "nodes-inf": (_set_entry("nodes", (1, 1), np.inf), "nodes"),
    "root-not-at-goal": (_root_moved, "nodes"),
    "cost-inf": (_set_entry("cost", 1, np.inf), "cost"),
    "cost-inconsistent": (_cost_off, "cost"),
    "samples-nan": (_set_entry("collision_samples", (0, 0), np.nan), "collision_samples"),
}
CELL_EDITS = {
    "parent-cycle": (_tree_cycle, "parent"),
    "nodes-nan": (_set_entry("nodes", (1, 0), np.nan), "nodes"),
    "offsets-not-from-0": (_set_entry("cell_vertex_offsets", 0, 1), "offsets"),
    "row-offsets-decreasing": (_offsets_decreasing("cell_row_offsets"), "offsets"),
    "barrier-offsets-decreasing": (_offsets_decreasing("cbf_offsets"), "offsets"),
    "clockwise-cell": (_clockwise, "cell_vertices"),
    "row-not-unit": (_set_entry("cell_A", 0, [2.0, 0.0]), "cell_A"),
    "unknown-flag-bit": (_set_entry("cell_flags", 0, 64), "cell_flags"),
    "s-min-above-s-max": (lambda m, e: _set_entry("s_min", 0, float(e["s_max"][0]) + 1.0)(m, e), "s_min"),
    "s-max-nan": (_set_entry("s_max", 0, np.nan), "s_max"),
    "cell-node-repeated": (_duplicate_cell_node, "cell_node"),
    "cell-node-out-of-range": (_set_entry("cell_node", 0, 10**6), "cell_node"),
    "exit-dir-zero": (_exit_dir_zero, "exit_dir"),
    "exit-row-out-of-range": (_set_entry("cell_exit_row", 1, 99), "cell_exit_row"),
    "fixed-landmark-out-of-range": (_set_entry("fixed_landmark", 0, 99), "fixed_landmark"),
    "rank-negative": (_set_entry("cell_rank", 1, -1.0), "cell_rank"),
    "coverage-above-1": (_scalar("free_coverage", 2.0), "free_coverage"),
    "certificate-unknown": (lambda m, e: e.update(certificate="magic"), "certificate"),
    "exit-inset-negative": (_scalar("exit_inset", -1.0), "exit_inset"),
}
PLAN_EDITS = {
    "goal-tolerance-nan": (_scalar("goal_tolerance", np.nan), "goal_tolerance"),
    "goal-tolerance-negative": (_scalar("goal_tolerance", -0.1), "goal_tolerance"),
    "u-max-zero": (_set_entry("u_max", 0, 0.0), "u_max"),
    "c-v-negative": (_set_entry("c_v", 1, -1.0), "c_v"),
    "gain-nan": (_set_entry("gain", (0, 0, 0), np.nan), "gain"),
    "margin-inf": (_set_entry("margin_h", 0, np.inf), "margin_h"),
    "tolerance-negative": (_set_entry("tolerance", 0, -1.0), "tolerance"),
    "plan-tolerance-negative": (_scalar("plan_tolerance", -1.0), "plan_tolerance"),
    "status-unknown": (_set_entry("status", 0, 7), "status"),
    "landmarks-differ-from-map": (_landmark_moved, "landmarks"),
}
SIM_EDITS = {
    "parent-cycle": (_tree_cycle, "parent"),
    "outcome-unknown": (_set_entry("outcome", 0, 9), "outcome"),
    "trajectory-nan": (_set_entry("trajectory_coords", (3, 0), np.nan), "trajectory_coords"),
    "trajectory-offsets-decreasing": (_offsets_decreasing("trajectory_offsets"), "trajectory_offsets"),
    "trajectory-cell-out-of-range": (_set_entry("trajectory_cells", 0, 10**6), "trajectory_cells"),
    "start-nan": (_set_entry("starts", (0, 0), np.nan), "starts"),
    "time-negative": (_set_entry("time", 0, -1.0), "time"),
    "dt-zero": (_scalar("dt", 0.0), "dt"),
    "cell-status-unknown": (_set_entry("cell_status", 0, 9), "cell_status"),
    "cell-offsets-decreasing": (_offsets_decreasing("cell_vertex_offsets"), "cell_vertex_offsets"),
}
KIND_EDITS = {
    "tree": TREE_EDITS,
    "simplified": TREE_EDITS,
    "cells": CELL_EDITS,
    "plan": {**CELL_EDITS, **PLAN_EDITS},
    "simulation": SIM_EDITS,
}


def _meaning_cases():
    for name, (_, field) in MAP_EDITS.items():
        for kind in ALL_KINDS:
            for consumer in CONSUMERS[kind]:
                yield pytest.param(kind, f"map:{name}", field, consumer, id=f"{kind}-map-{name}-{consumer}")
    for kind, edits in KIND_EDITS.items():
        for name, (_, field) in edits.items():
            for consumer in CONSUMERS[kind]:
                yield pytest.param(kind, name, field, consumer, id=f"{kind}-{name}-{consumer}")


@pytest.mark.parametrize("kind, edit, field, consumer", list(_meaning_cases()))
def test_rehashed_nonsense_is_refused_naming_the_field(built, tmp_path, kind, edit, field, consumer):
    source = built[kind]
    folder = tmp_path / "in"
    folder.mkdir()
    target = folder / source.name
    if edit.startswith("map:"):
        change = MAP_EDITS[edit[4:]][0]
        if kind == "map":
            rewrite_json(source, target, change)
        else:
            rewrite_npz(source, target, lambda m, e: edit_embedded_map(e, change))
        field = field if kind == "map" else f"map.{field}"
    else:
        rewrite_npz(source, target, lambda m, e: KIND_EDITS[kind][edit][0](m, e))
    # the edited file is intact: its hash matches, only its meaning is wrong
    if kind != "map":
        manifest, entries = read_npz(target)
        assert artifacts.content_hash(entries, kind) == manifest["content_sha256"]
    check_refused(built, tmp_path, consumer, target, (field,))


def test_decompose_never_writes_cells_from_a_cyclic_tree(built, tmp_path):
    """The issue's example: a cycle in ``parent`` with a recomputed hash used to give a cells.npz."""
    target = rewrite_npz(built["simplified"], tmp_path / "simplified.npz", lambda m, e: _tree_cycle(m, e))
    result = invoke("decompose", target)
    assert_clean_failure(result, 3, ("simplified.npz", "parent", "cycle"))
    assert not (tmp_path / "cells.npz").exists()


# --------------------------------------------------------------------------- the declarations and the docs


def documented_invariants() -> dict[str, dict[str, str]]:
    """``{schema: {field: rule}}`` from the "Checked on load" lists of docs/artifacts.md."""
    text = (REPO / "docs" / "artifacts.md").read_text()
    found: dict[str, dict[str, str]] = {}
    for section in re.split(r"^## ", text, flags=re.M)[1:]:
        head = re.match(r".*`(bearnav\.[a-z]+/\d+)`", section.splitlines()[0])
        if not head:
            continue
        block = re.search(r"Checked on load[^\n]*\n\s*\n((?:- `[^`]+`: .*\n)+)", section)
        if block:
            found[head.group(1)] = dict(re.findall(r"^- `([^`]+)`: (.*)$", block.group(1), flags=re.M))
    return found


def test_every_invariant_is_documented_next_to_its_schema():
    docs = documented_invariants()
    for kind, invariants in datatypes.INVARIANTS.items():
        schema = artifacts.KINDS[kind].schema
        assert schema in docs, f"no 'Checked on load' list for {schema} in docs/artifacts.md"
        declared = {inv.field: inv.rule for inv in invariants}
        assert docs[schema] == declared, schema


def test_the_loader_and_the_writer_share_the_declarations(built, tmp_path):
    """save() refuses an artifact that fails its invariants: nothing meaningless is ever written."""
    loaded = artifacts.load(built["tree"], "tree")
    parent = np.array(loaded.artifact.parent)
    parent[1], parent[2] = 2, 1
    bad = datatypes.replace(loaded.artifact, parent=parent)
    manifest = dict(loaded.manifest, content_sha256=artifacts.content_hash(artifacts.entries_of(bad), "tree"))
    with pytest.raises(errors.ArtifactError, match="cycle"):
        artifacts.save(tmp_path / "tree.npz", bad, manifest)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("kind, consumer", [(k, c) for k in ("map", "plan") for c in CONSUMERS[k]])
def test_unreadable_file_as_any_user(built, tmp_path, monkeypatch, kind, consumer):
    """Root reads every file, so a missing read permission is simulated where the file is read."""
    target = tmp_path / "in" / built[kind].name
    target.parent.mkdir()
    target.write_bytes(built[kind].read_bytes())
    real = Path.read_bytes

    def read_bytes(self):
        if self == target:
            raise PermissionError(13, "Permission denied", str(self))
        return real(self)

    out = tmp_path / "out"
    out.mkdir()
    before = snapshot(tmp_path)
    monkeypatch.setattr(Path, "read_bytes", read_bytes)
    result = invoke(*command(consumer, target, built, out))
    monkeypatch.undo()
    assert_clean_failure(result, 3, (target.name, "permission denied"))
    assert snapshot(tmp_path) == before
