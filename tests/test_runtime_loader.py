"""The robot's loader refuses what the CLI's loader refuses (issue 27 item 3).

One small plan (conftest's ``SMALL_MAP``) is planned once for the module; each case copies its
``plan.npz`` with one edit: of its meaning with the content hash recomputed (a hash proves that a
file is intact, not that it makes sense), of its data without rehashing, or of its bytes. Both
``Controller.from_plan`` (numpy only, what a robot runs) and ``artifacts.load`` (``bearnav
inspect``) must refuse it with one :class:`ArtifactError` naming the file and the field, never a
raw ``zlib.error``, ``EOFError``, ``IndexError``, ``ValueError`` or ``TypeError``.
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest

from bearnav_cli import artifacts, datatypes
from bearnav_cli.errors import ArtifactError
from bearnav_cli.runtime import Controller, PlanArrays, invariants, plan_file, tree_costs

from .conftest import planned_small_map
from .test_hostile_common import deflate_damaged, edit_embedded_map, rewrite_npz


@pytest.fixture(scope="module")
def plan_path(tmp_path_factory) -> Path:
    """The small map of conftest planned once (half a second)."""
    return planned_small_map(tmp_path_factory, "loader")


def refused_by_both(path: Path, field: str | None, words: str = "") -> None:
    """Both loaders raise ArtifactError naming ``path`` and ``field`` (None: no field), with ``words`` in it."""
    for load in (lambda: Controller.from_plan(str(path)), lambda: artifacts.load(path)):
        with pytest.raises(ArtifactError) as caught:
            load()
        error = caught.value
        assert type(error) is ArtifactError, repr(error)
        assert error.file == str(path), str(error)
        assert error.field == field, str(error)
        assert words in str(error), str(error)


def _cycle(length: int) -> Callable[[dict, dict], None]:
    """Nodes 1..length point at each other in a ring, off the root: a cycle of ``length``."""

    def edit(manifest: dict, entries: dict) -> None:
        parent = entries["parent"]
        assert len(parent) > length
        ring = np.arange(1, length + 1)
        parent[ring] = np.roll(ring, -1)

    return edit


def _set(name: str, value: Any, where: Any = 0) -> Callable[[dict, dict], None]:
    def edit(manifest: dict, entries: dict) -> None:
        if np.ndim(entries[name]) == 0:
            entries[name] = np.array(value, entries[name].dtype)
        else:
            entries[name][where] = value

    return edit


def _edge_cell(entries: dict) -> int:
    """A cell that is not the goal cell."""
    return int(np.flatnonzero(entries["parent"][entries["cell_node"]] >= 0)[0])


def _zero_exit_dir(manifest: dict, entries: dict) -> None:
    entries["exit_dir"][_edge_cell(entries)] = 0.0


def _clockwise(manifest: dict, entries: dict) -> None:
    c = _edge_cell(entries)
    lo, hi = entries["cell_vertex_offsets"][c : c + 2]
    entries["cell_vertices"][lo:hi] = entries["cell_vertices"][lo:hi][::-1].copy()


def _fixed_landmark_out_of_range(manifest: dict, entries: dict) -> None:
    entries["fixed_landmark"][_edge_cell(entries)] = len(entries["landmarks"])


def _landmarks_moved(manifest: dict, entries: dict) -> None:
    entries["landmarks"][0] += 0.5


def _map_landmarks_moved(manifest: dict, entries: dict) -> None:
    edit_embedded_map(entries, lambda doc: doc["landmarks"][0].update(position=[1.0, 7.5]))


def _parent_as_float(manifest: dict, entries: dict) -> None:
    entries["parent"] = entries["parent"].astype(float)


def _gain_short(manifest: dict, entries: dict) -> None:
    entries["gain"] = entries["gain"][:, :, :-2].copy()


def _extra_entry(manifest: dict, entries: dict) -> None:
    entries["notes"] = np.zeros(3)


def _missing_entry(manifest: dict, entries: dict) -> None:
    del entries["c_v"]


def _manifest(change: Callable[[dict], Any]) -> Callable[[dict, dict], None]:
    def edit(manifest: dict, entries: dict) -> None:
        change(manifest)  # what it returns (dict.pop's value) must not reach rewrite_npz as a raw manifest

    return edit


#: Rehashed edits of the plan's meaning, its entries or its manifest: (edit, field named, words in the error).
REHASHED = {
    "cycle of 2": (_cycle(2), "parent", "cycle"),
    "cycle of 4": (_cycle(4), "parent", "cycle"),
    "status 9": (_set("status", 9), "status", ""),
    "negative u_max": (_set("u_max", -1.0), "u_max", "positive"),
    "infinite goal tolerance": (_set("goal_tolerance", np.inf), "goal_tolerance", ""),
    "goal tolerance beyond the map": (_set("goal_tolerance", 100.0), "goal_tolerance", "diagonal"),
    "negative c_v": (_set("c_v", -0.5), "c_v", ""),
    "negative rank": (_set("cell_rank", -1.0, 1), "cell_rank", ""),
    "negative plan_tolerance": (_set("plan_tolerance", -1.0), "plan_tolerance", ""),
    "zero exit_dir": (_zero_exit_dir, "exit_dir", "norm"),
    "clockwise cell": (_clockwise, "cell_vertices", "counter-clockwise"),
    "fixed_landmark out of range": (_fixed_landmark_out_of_range, "fixed_landmark", ""),
    "landmarks moved": (_landmarks_moved, "landmarks", "embedded map"),
    "robot slip as text": (
        lambda m, e: edit_embedded_map(e, lambda doc: doc.update(robot={"slip": "lots"})),
        "map.robot.slip",
        "finite",
    ),
    "robot section a list": (lambda m, e: edit_embedded_map(e, lambda doc: doc.update(robot=[1])), "map", "malformed"),
    "robot key unknown": (
        lambda m, e: edit_embedded_map(e, lambda doc: doc.update(robot={"wheels": 3})),
        "map.robot",
        "wheels",
    ),
    "the map's landmarks moved": (_map_landmarks_moved, "landmarks", "embedded map"),
    "parent as float": (_parent_as_float, "parent", "array"),
    "gain of the wrong shape": (_gain_short, "gain", "shape"),
    "unexpected entry": (_extra_entry, "notes", "unexpected"),
    "missing entry": (_missing_entry, "c_v", "missing"),
    "schema of cells": (_manifest(lambda m: m.update(schema="bearnav.cells/3")), None, "bearnav.cells/3"),
    "unknown schema": (_manifest(lambda m: m.update(schema="bearnav.plan/9")), "manifest.schema", ""),
    "retired schema": (_manifest(lambda m: m.update(schema="bearnav.plan/2")), "manifest.schema", "re-run"),
    "wrong stage": (_manifest(lambda m: m.update(stage="simulate")), "manifest.stage", ""),
    "no key": (_manifest(lambda m: m.pop("key")), "manifest.key", "missing"),
    "params not an object": (_manifest(lambda m: m.update(params=[1])), "manifest.params", ""),
}


@pytest.mark.parametrize("case", REHASHED)
def test_both_loaders_refuse_a_rehashed_edit(plan_path, tmp_path, case):
    edit, field, words = REHASHED[case]
    path = rewrite_npz(plan_path, tmp_path / "plan.npz", edit)
    if case == "schema of cells":  # the CLI names the kinds it expected; the robot, the manifest's schema
        for load in (lambda: Controller.from_plan(str(path)), lambda: artifacts.load(path, "plan")):
            with pytest.raises(ArtifactError, match="bearnav.cells/3") as caught:
                load()
            assert caught.value.file == str(path)
        return
    refused_by_both(path, field, words)


#: Edits of the data without a new content hash.
UNHASHED = {
    "u_max doubled": lambda manifest, entries: entries.update(u_max=entries["u_max"] * 2),
    "one gain changed": _set("gain", 0.25, (1, 0, 0)),
    "map robot radius": lambda manifest, entries: edit_embedded_map(entries, lambda doc: doc.update(robot_radius=0.3)),
    "hash of another plan": lambda manifest, entries: manifest.update(content_sha256="0" * 64),
}


@pytest.mark.parametrize("case", UNHASHED)
def test_both_loaders_refuse_an_edit_without_rehash(plan_path, tmp_path, case):
    path = rewrite_npz(plan_path, tmp_path / "plan.npz", UNHASHED[case], rehashed=False)
    refused_by_both(path, None, "content hash mismatch")


def _truncated(data: bytes, path: Path) -> bytes:
    return data[: len(data) // 2]


def _directory_scribbled(data: bytes, path: Path) -> bytes:
    out = bytearray(data)
    start = out.find(b"PK\x01\x02")
    out[start : start + 46] = bytes(46)
    return bytes(out)


#: Damaged bytes: (damage, field named, words in the error).
DAMAGED = {
    "truncated": (_truncated, None, "damaged zip"),
    "bytes flipped in a member": (deflate_damaged, "found", "damaged entry"),
    "central directory scribbled": (_directory_scribbled, None, "damaged zip"),
    "not a zip": (lambda data, path: b"plan.npz\n" * 40, None, "not an npz archive"),
    "an npy": (lambda data, path: b"\x93NUMPY" + data[6:200], None, ".npy"),
    "empty": (lambda data, path: b"", None, "not an npz archive"),
}


@pytest.mark.parametrize("case", DAMAGED)
def test_both_loaders_refuse_a_damaged_file(plan_path, tmp_path, case):
    damage, field, words = DAMAGED[case]
    path = tmp_path / "plan.npz"
    path.write_bytes(damage(plan_path.read_bytes(), plan_path))
    if field == "found":  # the entry that failed to decompress: any of the file's, named
        with zipfile.ZipFile(plan_path) as archive:
            field = max(archive.infolist(), key=lambda i: i.compress_size).filename.removesuffix(".npy")
    refused_by_both(path, field, words)


def test_a_missing_file_and_a_folder_are_named(tmp_path):
    refused_by_both(tmp_path / "nothing.npz", None, "no such file")
    (tmp_path / "folder.npz").mkdir()
    refused_by_both(tmp_path / "folder.npz", None, "folder")


def test_a_good_plan_loads_in_both_and_drives(plan_path):
    loaded = artifacts.load(plan_path, "plan")
    robot = Controller.from_plan(str(plan_path))
    assert np.array_equal(robot.arrays.gain, loaded.artifact.gain)
    assert np.array_equal(robot.arrays.cell_vertices, PlanArrays.from_plan(loaded.artifact).cell_vertices)
    assert loaded.manifest["content_sha256"] == plan_file.content_hash(
        plan_file.parse_npz(plan_path.read_bytes(), str(plan_path))[1]
    )
    x = np.array([9.0, 7.0])  # a start of the map
    landmarks = robot.arrays.landmarks
    bearings = (landmarks - x) / np.hypot(*(landmarks - x).T)[:, None]
    visible = np.ones(len(landmarks), bool)
    commands = [robot.command(bearings, visible) for _ in range(3)]
    assert all(c.shape == (2,) and np.all(np.isfinite(c)) for c in commands)
    assert robot.cell >= 0 and np.linalg.norm(commands[-1]) > 0


def test_the_two_loaders_share_one_copy_of_the_checks():
    """datatypes' invariants are the runtime's objects; artifacts hashes with the runtime's function."""
    assert datatypes.INVARIANTS["plan"] == invariants.CELLS_INVARIANTS + invariants.PLAN_INVARIANTS
    entries = {"map": '{"a":1,"source":{"file":"x"}}', "x": np.arange(3)}
    assert artifacts.content_hash(entries, "plan") == plan_file.content_hash(entries)


@pytest.mark.parametrize("length", [1, 2, 3, 4, 8])
def test_tree_costs_refuses_a_cycle_of_any_length(length):
    """Pointer doubling alone stops at a fixed point, which a cycle of length 2^k also reaches."""
    n = length + 2
    nodes = np.column_stack([np.arange(n, dtype=float), np.zeros(n)])
    parent = np.r_[-1, 0, np.roll(np.arange(2, n), -1)]  # node 1 on the root, nodes 2.. in a ring
    with pytest.raises(ArtifactError, match="tree"):
        tree_costs(nodes, parent)
    assert invariants.tree_problem(nodes, parent).endswith("(a cycle)")
