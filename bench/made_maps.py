"""Three kinds of map nobody tuned bearnav for: an office of rooms and doors, a maze, a cluttered floor.

Issue 11 measures bearings "on maps nobody tuned": each generator here takes a seed and returns a
map description in the YAML format of DESIGN §4 (a dict), with the tags such a map would come with
(12, spread over the walls at random, at least a metre apart), not the ones bearnav would ask for.
Nothing here imports the planner (numpy, shapely and the map stage's disc polygon only), so a map
does not depend on the code it measures.

Run from the repository root to write the three maps of the measurement::

    PYTHONPATH=. python bench/made_maps.py --seed 0 -o bench/maps
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import shapely
import yaml

from bearnav_cli.geometry import circle_polygon
from tests.mapgen import maze_passages

__all__ = ["KINDS", "clutter", "maze", "office"]

#: Wall thickness (m) of the office and the maze.
WALL = 0.1
#: Tags a generated map comes with, and their least spacing along the walls (m).
N_TAGS, TAG_SPACING = 12, 1.0


def _r(value: float) -> float:
    return round(float(value), 3)


def _rect(x0: float, y0: float, x1: float, y1: float) -> dict:
    return {"rectangle": [_r(x0), _r(y0), _r(x1), _r(y1)]}


def _raw(obstacles: list[dict]) -> shapely.Geometry:
    parts = []
    for o in obstacles:
        if "rectangle" in o:
            parts.append(shapely.box(*o["rectangle"]))
        else:
            # the map stage's own polygon of a disc, so that a tag put on it lies exactly on its boundary
            parts.append(shapely.Polygon(circle_polygon(o["circle"]["center"], o["circle"]["radius"])))
    return shapely.union_all(parts)


def _finish(
    name: str, bounds: list[float], obstacles: list[dict], rng: np.random.Generator, radius: float = 0.15
) -> dict:
    """Goal, two starts and the tags on the free space's boundary, for the obstacles given."""
    box = shapely.box(*bounds)
    free = box.difference(_raw(obstacles))
    room = free.buffer(-(radius + 0.4))  # points with clearance for the goal and the starts
    if room.is_empty:
        raise ValueError(f"{name}: no room for the goal")

    def point_in(region: shapely.Geometry) -> list[float]:
        x0, y0, x1, y1 = region.bounds
        while True:
            p = rng.uniform([x0, y0], [x1, y1])
            if region.contains(shapely.Point(p)):
                return [_r(p[0]), _r(p[1])]

    goal = point_in(room)
    starts = []
    while len(starts) < 2:
        p = point_in(room)
        if np.hypot(p[0] - goal[0], p[1] - goal[1]) > 0.4 * np.hypot(bounds[2] - bounds[0], bounds[3] - bounds[1]):
            starts.append(p)
    # tags on the boundary of the free space (walls and obstacles, facing the free side)
    boundary = free.boundary
    length = boundary.length
    tags: list[list[float]] = []
    tries = 0
    while len(tags) < N_TAGS and tries < 10_000:
        tries += 1
        p = boundary.interpolate(rng.uniform(0.0, length))
        xy = [_r(p.x), _r(p.y)]
        if all(np.hypot(xy[0] - t[0], xy[1] - t[1]) >= TAG_SPACING for t in tags):
            tags.append(xy)
    return {
        "name": name,
        "bounds": [_r(b) for b in bounds],
        "robot_radius": radius,
        "goal": goal,
        "starts": starts,
        "obstacles": obstacles,
        "landmarks": [{"id": f"tag{k}", "position": t} for k, t in enumerate(tags)],
        "params": {"rrtstar": {"iterations": 3000, "seed": 0}},
    }


def office(seed: int) -> dict:
    """Rooms on both sides of a corridor, one door (0.9 m) per room, 14 × 9 m."""
    rng = np.random.default_rng([seed, 11])
    W, H, y0, y1 = 14.0, 9.0, 3.8, 5.2  # the corridor between y0 and y1
    obstacles = []
    for lo, hi, door_y in ((0.0, y0, y0), (y1, H, y1)):
        # the wall along the corridor, split into rooms 3–4 m wide, one door each
        cuts = [0.0]
        while W - cuts[-1] > 7.0:  # the last room gets 3–7 m
            cuts.append(cuts[-1] + rng.uniform(3.0, 4.0))
        cuts.append(W)
        for a, b in zip(cuts[:-1], cuts[1:], strict=False):
            door = rng.uniform(a + 0.4, b - 1.3)
            wy = door_y - WALL / 2
            obstacles += [_rect(a, wy, door, wy + WALL), _rect(door + 0.9, wy, b, wy + WALL)]
            if b < W:  # the wall between two rooms
                obstacles.append(_rect(b - WALL / 2, lo, b + WALL / 2, hi - (WALL / 2 if hi == y0 else 0.0)))
    # some furniture in the rooms
    for _ in range(6):
        cx, cy = rng.uniform([1.0, 0.8], [W - 1.0, H - 0.8])
        if y0 - 0.8 < cy < y1 + 0.8:
            continue
        w, h = rng.uniform(0.5, 1.2, 2)
        obstacles.append(_rect(cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2))
    return _finish(f"office{seed}", [0.0, 0.0, W, H], obstacles, rng)


def maze(seed: int) -> dict:
    """A perfect maze (depth-first) of 4 × 3 cells of 2.5 m, walls 0.1 m thick."""
    rng = np.random.default_rng([seed, 12])
    nx, ny, s = 4, 3, 2.5
    open_walls = maze_passages(rng, nx, ny, (0, 0))
    obstacles = []
    h = WALL / 2
    for i in range(nx):
        for j in range(ny):
            if i + 1 < nx and (i, j, i + 1, j) not in open_walls:  # wall on the east side
                obstacles.append(_rect((i + 1) * s - h, j * s, (i + 1) * s + h, (j + 1) * s))
            if j + 1 < ny and (i, j, i, j + 1) not in open_walls:  # wall on the north side
                obstacles.append(_rect(i * s, (j + 1) * s - h, (i + 1) * s, (j + 1) * s + h))
    return _finish(f"maze{seed}", [0.0, 0.0, nx * s, ny * s], obstacles, rng)


def clutter(seed: int) -> dict:
    """A floor of 10 × 8 m with 16 boxes and discs (overlaps allowed)."""
    rng = np.random.default_rng([seed, 13])
    W, H = 10.0, 8.0
    obstacles = []
    while len(obstacles) < 16:
        cx, cy = rng.uniform([0.8, 0.8], [W - 0.8, H - 0.8])
        if rng.random() < 0.6:
            w, h = rng.uniform(0.3, 1.4, 2)
            obstacles.append(_rect(cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2))
        else:
            obstacles.append({"circle": {"center": [_r(cx), _r(cy)], "radius": _r(rng.uniform(0.2, 0.5))}})
    return _finish(f"clutter{seed}", [0.0, 0.0, W, H], obstacles, rng)


KINDS = {"office": office, "maze": maze, "clutter": clutter}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("-o", "--out", type=Path, default=Path("bench/maps"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for make in KINDS.values():
        spec = make(args.seed)
        path = args.out / f"{spec['name']}.yaml"
        path.write_text(yaml.safe_dump(spec, sort_keys=False))
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
