"""The map generator of the tests (tests/mapgen.py): deterministic, feasible, varied, and its grids ragged.

Every kind, a few seeds: the map stage loads the map (from memory and from the files
:meth:`~tests.mapgen.MadeMap.write` writes, as ``bearnav plan`` reads them) with the goal and the
starts strictly free and the goal's free component a large part of the bounds; the tags lie on a
wall or a face. The same seed gives the same bytes, and other seeds or kinds other maps.
"""

from __future__ import annotations

import functools
import logging

import numpy as np
import pytest
import shapely

from bearnav_cli.cli import read_map_source
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.occupancy import decode_image
from bearnav_cli.stages import map_
from tests import mapgen
from tests.conftest import build_made

SEEDS = (0, 1, 2)


@functools.cache
def loaded(seed: int, kind: str) -> map_.Map:
    """The map stage's map of ``generate(seed, kind)``, once per test process (the grids take a while)."""
    return build_made(mapgen.generate(seed, kind))


@pytest.fixture(autouse=True)
def _quiet(caplog):
    caplog.set_level(logging.ERROR)  # maps nobody tuned have blind spots: the map stage warns


def _on_a_face(built: map_.Map) -> np.ndarray:
    """Per landmark: on a wall of the bounds or on a raw obstacle's boundary (to the map tolerance)."""
    tol = built.tol
    lm = built.landmarks
    lo, hi = built.bounds[:2], built.bounds[2:]
    wall = np.any((np.abs(lm - lo) <= tol) | (np.abs(lm - hi) <= tol), axis=1)
    raw = shapely.union_all([shapely.Polygon(p.exterior, p.holes) for p in built.raw_obstacles])
    face = shapely.distance(raw.boundary, shapely.points(lm)) <= tol if not raw.is_empty else np.zeros(len(lm), bool)
    return wall | face


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("kind", mapgen.KINDS)
def test_every_kind_loads_feasible(kind, seed):
    made = mapgen.generate(seed, kind)
    built = loaded(seed, kind)
    space = FreeSpace.from_map(built)
    points = np.vstack([built.goal, built.starts])
    assert len(built.starts) >= 1 and space.points_strictly_free(points).all()
    component = space.component_of(built.goal)
    assert all(component.intersects(shapely.Point(p)) for p in built.starts)
    box = shapely.box(*built.bounds)
    assert component.area >= mapgen.MIN_COMPONENT_SHARE * box.area
    assert len(built.landmarks) >= 8 and _on_a_face(built).all()
    assert (made.grid is not None) == (kind == "grid") == ("occupancy" in made.spec)


@pytest.mark.parametrize("kind", mapgen.KINDS)
def test_the_written_files_are_the_same_map(kind, tmp_path):
    path = mapgen.generate(0, kind).write(tmp_path)
    from_files = map_.run(read_map_source(path)).to_json()
    in_memory = loaded(0, kind).to_json()
    # the same map.json but for the input's hash (the CLI hashes every file it read)
    from_files.pop("source"), in_memory.pop("source")
    assert from_files == in_memory


@pytest.mark.parametrize("kind", mapgen.KINDS)
def test_same_seed_same_map_other_seed_other_map(kind):
    first, again, other = mapgen.generate(4, kind), mapgen.generate(4, kind), mapgen.generate(5, kind)
    assert first == again and first.image == again.image
    assert first.spec != other.spec


def test_the_kinds_differ():
    """One seed, four maps: different obstacles, sizes and tags; only the grid kind has an image."""
    made = {kind: mapgen.generate(0, kind) for kind in mapgen.KINDS}
    specs = [m.spec for m in made.values()]
    for k, a in enumerate(specs):
        for b in specs[k + 1 :]:
            assert a.get("obstacles") != b.get("obstacles") and a["landmarks"] != b["landmarks"]
    assert [kind for kind, m in made.items() if m.image is not None] == ["grid"]

    # rooms and mazes are walls: long thin rectangles; clutter is compact shapes
    def thin(kind):
        boxes = [o["rectangle"] for o in made[kind].spec["obstacles"] if "rectangle" in o]
        return np.mean([max(x1 - x0, y1 - y0) / min(x1 - x0, y1 - y0) > 5 for x0, y0, x1, y1 in boxes])

    assert thin("maze") > 0.9 and thin("rooms") > 0.3


@pytest.mark.parametrize("seed", SEEDS)
def test_grids_are_ragged(seed):
    """A grid's obstacles are not a few rectangles: their outlines have many corners, and specks or unknown pixels."""
    made = mapgen.generate(seed, "grid")
    gray, _ = decode_image(made.image, made.grid["image"])
    built = loaded(seed, "grid")
    corners = sum(len(p.exterior) + sum(len(h) for h in p.holes) for p in built.raw_obstacles)
    assert corners > 20 * len(built.raw_obstacles)
    assert set(np.unique(gray)) <= {mapgen.OCCUPIED_GRAY, mapgen.UNKNOWN_GRAY, mapgen.FREE_GRAY}
    # ragged: along a row, the obstacles' edges do not line up with the next row's
    blocked = gray != mapgen.FREE_GRAY
    edges = np.diff(blocked.astype(np.int8), axis=1) != 0
    assert np.mean(np.any(edges[1:] != edges[:-1], axis=1)) > 0.3


def test_an_unknown_kind_is_refused():
    with pytest.raises(ValueError, match="kind"):
        mapgen.generate(0, "cave")
