"""Small random maps for the funnel-cell property tests (tests/test_funnel.py).

:func:`random_spec` returns a map description in the YAML format of DESIGN §4 (as a dict):
rectangles and discs in a small box, a goal in the free space with some clearance, and
landmarks on the walls and on the obstacles' boundaries. The same seed always gives the same
map. Nothing here imports the package's planner: only numpy, shapely and the circle polygon
the map stage uses (so that a tag put on a disc lies exactly on its boundary). Larger maps of more
kinds (rooms, mazes, occupancy grids) come from :mod:`tests.mapgen`.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from bearnav_cli.geometry import CIRCLE_SEGMENTS, circle_polygon

__all__ = ["ITERATIONS", "PIPELINE", "cluttered_spec", "random_spec"]

#: The stages after ``map`` that make a plan.
PIPELINE = ["rrtstar", "simplify", "decompose", "synthesize"]
#: RRT* iterations of the random test maps: enough for their small boxes, each plan under a second.
ITERATIONS = 300


def _round(value: float) -> float:
    return round(float(value), 3)


def random_spec(seed: int, iterations: int = 300, rrt_seed: int = 0) -> dict:
    """A random small map as a spec dict.

    Parameters
    ----------
    seed : int
        Seeds the map itself.
    iterations, rrt_seed : int
        ``params.rrtstar`` of the map (the tree stage's budget and seed).

    Returns
    -------
    dict
        ``name``, ``bounds`` (a box of 4–7 × 4–7 units), ``robot_radius``, ``goal``, no
        ``starts``, 2–5 ``obstacles`` (rectangles and circles, possibly overlapping), 6–10
        ``landmarks`` (about half on the walls, half on obstacle boundaries) and ``params``.
    """
    rng = np.random.default_rng(seed)
    W, H = _round(rng.uniform(4.0, 7.0)), _round(rng.uniform(4.0, 7.0))
    radius = _round(rng.uniform(0.08, 0.15))
    rects, discs = [], []
    for _ in range(int(rng.integers(2, 6))):
        cx, cy = rng.uniform([0.8, 0.8], [W - 0.8, H - 0.8])
        if rng.random() < 0.6:
            w, h = rng.uniform(0.3, 1.5, 2)
            rects.append([_round(cx - w / 2), _round(cy - h / 2), _round(cx + w / 2), _round(cy + h / 2)])
        else:
            discs.append(([_round(cx), _round(cy)], _round(rng.uniform(0.2, 0.6))))
    raw = [shapely.box(*r) for r in rects] + [shapely.Polygon(circle_polygon(c, r)) for c, r in discs]
    union = shapely.union_all(raw)
    inflated = shapely.buffer(union, radius)
    inner = shapely.box(radius, radius, W - radius, H - radius)
    # the goal: a point of the free space well away from obstacles and walls
    goal = None
    for _ in range(1000):
        p = rng.uniform([0.5, 0.5], [W - 0.5, H - 0.5])
        point = shapely.Point(p)
        if inner.contains(point) and shapely.distance(inflated, point) > 0.35:
            goal = [_round(p[0]), _round(p[1])]
            break
    if goal is None:  # pragma: no cover - a 4×4 box with five small obstacles always has room
        raise RuntimeError(f"seed {seed}: no room for the goal")
    landmarks: list[list[float]] = []
    wanted = int(rng.integers(6, 11))
    for _ in range(500):
        if len(landmarks) >= wanted:
            break
        if rng.random() < 0.5:  # on a wall of the box
            side = int(rng.integers(4))
            t = rng.uniform(0.05, 0.95)
            p = [[t * W, 0.0], [W, t * H], [t * W, H], [0.0, t * H]][side]
        elif rng.random() < 0.6 and rects:  # on a side of a rectangle
            x0, y0, x1, y1 = rects[int(rng.integers(len(rects)))]
            side, t = int(rng.integers(4)), rng.uniform(0.1, 0.9)
            p = [
                [x0 + t * (x1 - x0), y0],
                [x1, y0 + t * (y1 - y0)],
                [x0 + t * (x1 - x0), y1],
                [x0, y0 + t * (y1 - y0)],
            ][side]
        elif discs:  # a vertex of a disc's polygon: exactly on its boundary
            c, r = discs[int(rng.integers(len(discs)))]
            p = circle_polygon(c, r)[int(rng.integers(CIRCLE_SEGMENTS))].tolist()
        else:
            continue
        p = [float(p[0]), float(p[1])]
        if not (0.0 <= p[0] <= W and 0.0 <= p[1] <= H):
            continue
        if shapely.contains_xy(union, *p):  # inside another (overlapping) obstacle
            continue
        if any(math.hypot(p[0] - q[0], p[1] - q[1]) < 0.2 for q in landmarks):
            continue
        landmarks.append(p)
    return _spec(f"funnel_random_{seed}", W, H, radius, goal, rects, discs, landmarks, iterations, rrt_seed)


def _spec(name, W, H, radius, goal, rects, discs, landmarks, iterations, rrt_seed) -> dict:
    """The map spec dict of a box ``W × H`` with rectangles, discs and landmarks (no starts)."""
    obstacles = [{"rectangle": r} for r in rects] + [{"circle": {"center": c, "radius": r}} for c, r in discs]
    return {
        "name": name,
        "bounds": [0.0, 0.0, W, H],
        "robot_radius": radius,
        "goal": goal,
        "starts": [],
        "obstacles": obstacles,
        "landmarks": landmarks,
        "params": {"rrtstar": {"iterations": int(iterations), "seed": int(rrt_seed)}},
    }


def cluttered_spec(seed: int, iterations: int = 400) -> dict:
    """A random cluttered map: many small obstacles and a small robot radius (issue 21's crash case).

    Parameters
    ----------
    seed : int
        Seeds the map itself (the tree's seed is 0).
    iterations : int
        ``params.rrtstar.iterations``.

    Returns
    -------
    dict
        A 6 × 6 box, robot radius 0.05, 20–28 small discs and rectangles that never cover the goal,
        and 14 landmarks on the walls.
    """
    rng = np.random.default_rng(10_000 + seed)
    W = H = 6.0
    radius = 0.05
    goal = [_round(rng.uniform(0.6, 1.4)), _round(rng.uniform(0.6, 1.4))]
    rects, discs = [], []
    for _ in range(int(rng.integers(20, 29))):
        cx, cy = rng.uniform([0.4, 0.4], [W - 0.4, H - 0.4])
        if math.hypot(cx - goal[0], cy - goal[1]) < 0.7:
            continue
        if rng.random() < 0.5:
            w, h = rng.uniform(0.1, 0.45, 2)
            rects.append([_round(cx - w / 2), _round(cy - h / 2), _round(cx + w / 2), _round(cy + h / 2)])
        else:
            discs.append(([_round(cx), _round(cy)], _round(rng.uniform(0.06, 0.22))))
    ts = (np.arange(14) + rng.uniform(0.2, 0.8, 14)) / 14.0
    landmarks = []
    for t in ts:
        side, u = divmod(t * 4.0, 1.0)
        landmarks.append([[u * W, 0.0], [W, u * H], [(1 - u) * W, H], [0.0, (1 - u) * H]][int(side)])
    landmarks = [[_round(x), _round(y)] for x, y in landmarks]
    return _spec(f"cluttered_{seed}", W, H, radius, goal, rects, discs, landmarks, iterations, 0)
