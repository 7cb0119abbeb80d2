"""Shared fixtures: small maps as dicts and YAML files, and a CLI runner in a scratch folder."""

from __future__ import annotations

import copy
import fcntl
import functools
import os
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from bearnav_cli.stages import map_

REPO = Path(__file__).resolve().parents[1]
# figures are drawn into files only, whatever display the machine running the tests has
os.environ.setdefault("MPLBACKEND", "Agg")

SMALL_MAP = {
    "name": "small",
    "bounds": [0, 0, 10, 8],
    "robot_radius": 0.2,
    "goal": [0.5, 0.5],
    "starts": [[9, 7], [5, 7.5]],
    "obstacles": [
        {"polygon": [[1, 2], [3, 2], [3, 3]]},
        {"rectangle": [4, 4, 6, 5]},
        {"circle": {"center": [8, 2], "radius": 0.5}},
    ],
    "landmarks": [[0, 8], {"id": "tag12", "position": [10, 0]}, [10, 8], [5, 0], [0, 4]],
    "params": {"rrtstar": {"iterations": 400, "step": 1.0, "seed": 0}},
}


@pytest.fixture
def small_spec() -> dict:
    """A fresh copy of a small valid map description (edit it freely)."""
    return copy.deepcopy(SMALL_MAP)


def build_map(spec: dict, **params) -> map_.Map:
    """Run the map stage on a spec dict."""
    return map_.run(map_.MapSource(spec=spec, file="test.yaml", sha256="0"), map_.Params(**params))


EXAMPLE_MAPS = ("kitchen", "storeroom", "paper_sim_circles", "paper_b_circles")


def example_plan(name: str, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``plan.npz`` of ``maps/NAME.yaml`` planned by the pipeline as ``bearnav plan`` does (read only).

    Planned once per test run, not once per worker: under pytest-xdist the workers share the
    run's temp root, and a file lock makes the first worker plan while the others wait for it.
    """
    from bearnav_cli import pipeline
    from bearnav_cli.cli import read_map_source

    base = tmp_path_factory.getbasetemp()
    root = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "example-plans"
    root.mkdir(exist_ok=True)
    folder = root / name
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        done = folder / "planned"
        if not done.exists():
            pipeline.plan(read_map_source(REPO / "maps" / f"{name}.yaml"), folder)
            done.touch()
    return folder / "plan.npz"


def planned_small_map(tmp_path_factory: pytest.TempPathFactory, name: str = "small") -> Path:
    """``plan.npz`` of :data:`SMALL_MAP` planned by the pipeline into a new folder (half a second)."""
    from bearnav_cli import pipeline
    from bearnav_cli.cli import read_map_source

    folder = tmp_path_factory.mktemp(name)
    source = folder / "small.yaml"
    source.write_text(yaml.safe_dump(SMALL_MAP, sort_keys=False))
    pipeline.plan(read_map_source(source), folder)
    return folder / "plan.npz"


@functools.cache
def random_plan(seed: int, lookahead: float = 0.0):
    """The plan of ``funnel_maps.random_spec(seed)`` (computed in memory once per test process); with a
    ``lookahead`` for a look-ahead unicycle's point (ALGORITHMS §12.6)."""
    from bearnav_cli import pipeline
    from tests.funnel_maps import ITERATIONS, random_spec

    spec = random_spec(seed, ITERATIONS)
    if lookahead:
        spec["robot"] = {"lookahead": lookahead}
    return pipeline.compute(build_map(spec))["plan"]


def build_made(made) -> map_.Map:
    """Run the map stage on a :class:`tests.mapgen.MadeMap` (a grid map with its image, as the CLI reads it)."""
    from bearnav_cli import pipeline

    return map_.run(made.source(), pipeline.resolve_params("map", made.spec.get("params")))


@functools.cache
def made_plan(seed: int, kind: str):
    """The plan of ``mapgen.generate(seed, kind)`` with the random maps' tree budget (once per test process)."""
    from bearnav_cli import pipeline
    from tests import mapgen
    from tests.funnel_maps import ITERATIONS

    made = mapgen.generate(seed, kind, params={"rrtstar": {"iterations": ITERATIONS, "seed": 0}})
    return pipeline.compute(build_made(made))["plan"]


@pytest.fixture
def write_map(tmp_path):
    """Write a spec dict as YAML in the scratch folder and return its path."""

    def write(spec: dict, name: str = "small.yaml") -> Path:
        path = tmp_path / name
        path.write_text(yaml.safe_dump(spec, sort_keys=False))
        return path

    return write


@pytest.fixture
def cli(tmp_path, monkeypatch):
    """Invoke ``bearnav`` inside the scratch folder; returns the typer result."""
    from bearnav_cli.cli import app

    monkeypatch.chdir(tmp_path)
    runner = CliRunner()

    def invoke(*args: str):
        return runner.invoke(app, [str(a) for a in args])

    return invoke
