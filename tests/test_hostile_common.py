"""Shared pieces of the hostile-input suite (tests/test_hostile_*.py): no tests of its own.

* :func:`assert_clean_failure`: the property every hostile case must have: the expected exit
  code, exactly one line on stderr naming what is wrong, no traceback, no internal error.
* :func:`rewrite_npz` / :func:`rewrite_json`: copy an artifact with an edit, optionally
  recomputing its content hash (an "edited and rehashed" file, whose hash proves nothing).
* :func:`snapshot`: every file of a folder with its bytes' hash, to assert that nothing changed.
* :func:`small_plan`: one small plan (the conftest's ``SMALL_MAP``) with a simulation, built once
  per test session and copied by the tests that damage it.
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import shutil
import struct
import subprocess
import sys
import zipfile
from pathlib import Path
from typing import Any, Callable
from unittest import mock

import numpy as np
import typer.testing
import yaml
from typer.testing import CliRunner

from bearnav_cli import artifacts, pipeline
from bearnav_cli.cli import app

from .conftest import REPO, SMALL_MAP

BEARNAV = Path(sys.executable).with_name("bearnav")

#: Seeds of the concurrent plans and the map used by the slow cases.
SEEDS = (0, 1)


_COMMAND: list = []


def invoke(*args: Any, env: dict | None = None):
    """Run ``bearnav ARGS`` in-process; stdout and stderr stay apart (``result.stderr``).

    typer rebuilds the click command from the app on every ``invoke`` (25 ms, most of a case's
    time); the suite builds it once and hands it to typer's runner.
    """
    getter = getattr(typer.testing, "_get_command", None)
    if getter is None:  # another typer: the plain way
        return CliRunner().invoke(app, [str(a) for a in args], env=env)
    if not _COMMAND:
        _COMMAND.append(getter(app))
    with mock.patch.object(typer.testing, "_get_command", lambda _app: _COMMAND[0]):
        return CliRunner().invoke(app, [str(a) for a in args], env=env)


def stderr_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


def assert_clean_failure(result, code: int = 3, words: tuple[str, ...] = (), stderr: str | None = None) -> str:
    """Exit ``code``, one line on stderr that contains every word, no traceback; returns the line."""
    err = result.stderr if stderr is None else stderr
    out = getattr(result, "stdout", "") or ""
    exit_code = result.exit_code if hasattr(result, "exit_code") else result.returncode
    assert exit_code == code, f"exit {exit_code}, expected {code}\nstdout: {out}\nstderr: {err}"
    lines = stderr_lines(err)
    assert len(lines) == 1, f"expected one stderr line, got {len(lines)}:\n{err}"
    assert "Traceback" not in err + out, err + out
    assert "internal error" not in lines[0], lines[0]
    for word in words:
        assert word in lines[0], f"{word!r} not in {lines[0]!r}"
    if hasattr(result, "exception") and code != 0:
        assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    return lines[0]


def snapshot(folder: Path) -> dict[str, str]:
    """``{relative path: sha256 of the bytes}`` of every file under ``folder`` (hidden files too)."""
    out = {}
    for path in sorted(Path(folder).rglob("*")):
        if path.is_file():
            out[str(path.relative_to(folder))] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def temp_files(folder: Path) -> list[Path]:
    return [p for p in Path(folder).rglob("*") if ".bearnav-" in p.name or p.name.endswith(".tmp")]


# --------------------------------------------------------------------------- editing artifacts


def read_npz(path: Path) -> tuple[dict, dict[str, Any]]:
    """Manifest and entries of an npz artifact (0-d texts as ``str``), for editing."""
    with np.load(path, allow_pickle=False) as npz:
        data = {key: npz[key] for key in npz.files}
    manifest = json.loads(str(data.pop("manifest")))
    entries = {k: (str(v) if v.dtype.kind == "U" and v.ndim == 0 else v.copy()) for k, v in data.items()}
    return manifest, entries


def rehash(manifest: dict, entries: dict[str, Any]) -> None:
    kind = artifacts.kind_of_schema(manifest.get("schema"))
    manifest["content_sha256"] = artifacts.content_hash(entries, kind)


def write_npz(path: Path, manifest: Any, entries: dict[str, Any], raw_manifest: Any = None) -> None:
    arrays = {k: (np.array(v) if isinstance(v, str) else v) for k, v in entries.items()}
    if raw_manifest is not None:
        arrays["manifest"] = raw_manifest
    elif manifest is not None:
        arrays["manifest"] = np.array(json.dumps(manifest))
    with open(path, "wb") as handle:
        np.savez(handle, **arrays)


def rewrite_npz(source: Path, target: Path, edit: Callable[[dict, dict], Any], rehashed: bool = True) -> Path:
    """Copy ``source`` to ``target`` after ``edit(manifest, entries)``, with a recomputed hash when ``rehashed``."""
    manifest, entries = read_npz(source)
    raw = edit(manifest, entries)
    if rehashed and isinstance(manifest, dict) and raw is None:
        rehash(manifest, entries)
    write_npz(target, manifest, entries, raw_manifest=raw)
    return target


def edit_embedded_map(entries: dict, change: Callable[[dict], None]) -> None:
    document = json.loads(entries["map"])
    change(document)
    entries["map"] = json.dumps(document, sort_keys=True, separators=(",", ":"))


def rewrite_json(source: Path, target: Path, change: Callable[[dict], None], rehashed: bool = True) -> Path:
    """Copy ``map.json`` with ``change(document)`` (manifest included), rehashed when asked."""
    document = json.loads(source.read_text())
    change(document)
    if rehashed and isinstance(document, dict) and isinstance(document.get("manifest"), dict):
        body = {k: v for k, v in document.items() if k != "manifest"}
        document["manifest"]["content_sha256"] = artifacts.content_hash({"map": artifacts.canonical_json(body)}, "map")
    target.write_text(json.dumps(document))
    return target


# --------------------------------------------------------------------------- one small plan per session

_BUILT: dict[str, Path] = {}


def small_spec(**params: dict) -> dict:
    spec = copy.deepcopy(SMALL_MAP)
    for stage, values in params.items():
        spec.setdefault("params", {}).setdefault(stage, {}).update(values)
    return spec


def write_yaml(path: Path, spec: dict) -> Path:
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def small_plan(root: Path) -> dict[str, Path]:
    """``{kind: path}`` of a plan of the small map plus a 5-run simulation, built once under ``root``."""
    if _BUILT and all(p.exists() for p in _BUILT.values()):
        return dict(_BUILT)
    folder = root / "small_plan"
    folder.mkdir(parents=True, exist_ok=True)
    yaml_path = write_yaml(root / "small.yaml", small_spec())
    result = invoke("-q", "plan", yaml_path, "-o", folder)
    assert result.exit_code == 0, result.output
    result = invoke("-q", "simulate", folder / "plan.npz", "--starts", "random:5", "--min-success", "0")
    assert result.exit_code == 0, result.output
    _BUILT.update({stage.output_kind: folder / stage.filename for stage in pipeline.STAGES})
    _BUILT["simulation"] = folder / "sim.npz"
    _BUILT["yaml"] = yaml_path
    return dict(_BUILT)


def copy_plan(built: dict[str, Path], target: Path) -> Path:
    """A private copy of the small plan's folder."""
    shutil.copytree(built["plan"].parent, target)
    return target


def run_program(*args: Any, cwd: Path | None = None, env: dict | None = None, timeout: float = 120):
    """Run the installed ``bearnav`` program (a real process: signals, locks)."""
    full_env = dict(os.environ, **(env or {}))
    return subprocess.run(
        [str(BEARNAV), *map(str, args)], cwd=cwd, env=full_env, capture_output=True, text=True, timeout=timeout
    )


__all__ = [
    "BEARNAV",
    "REPO",
    "SEEDS",
    "assert_clean_failure",
    "copy_plan",
    "edit_embedded_map",
    "invoke",
    "read_npz",
    "rehash",
    "rewrite_json",
    "rewrite_npz",
    "run_program",
    "small_plan",
    "small_spec",
    "snapshot",
    "stderr_lines",
    "temp_files",
    "write_npz",
    "write_yaml",
]


def deflate_damaged(data: bytes, path: Path) -> bytes:
    """``data`` (the bytes of the npz at ``path``) with 24 bytes flipped in the middle of its largest
    member's deflate stream: a damaged entry inside an intact zip."""
    out = bytearray(data)
    with zipfile.ZipFile(path) as archive:
        info = max(archive.infolist(), key=lambda i: i.compress_size)
    name_len, extra_len = struct.unpack("<HH", out[info.header_offset + 26 : info.header_offset + 30])
    start = info.header_offset + 30 + name_len + extra_len + info.compress_size // 2
    for k in range(start, start + 24):
        out[k] ^= 0x5A
    return bytes(out)
