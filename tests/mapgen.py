"""Random maps nobody tuned, for the tests and the benchmarks: clutter, rooms with doors, mazes, ragged grids.

:func:`generate` returns a :class:`MadeMap`: a map description in the YAML format of docs/maps.md
(a dict) and, for the ``grid`` kind, the ROS ``map_server`` YAML and PGM image it refers to. Every
size, count, thickness, door width, radius and tag spacing is drawn from the seed, so nobody chose
the numbers a test then passes on; the same seed and kind always give the same map.

What a map guarantees, checked here with shapely on the generator's own geometry (a radius
rounded up over the map stage's polygonal inflation, so the map stage agrees):

* the goal and the starts lie strictly inside the free space inflated by the robot radius, with a
  margin, all in one free component that covers at least :data:`MIN_COMPONENT_SHARE` of the bounds;
* the landmarks lie exactly on a wall or on an obstacle's face (grids: on a pixel edge) next to
  that component, inside the bounds, spread along the faces (more faces, more tags).

Nothing here imports the planner: numpy, shapely and the map stage's disc polygon only (so that a
tag put on a disc lies exactly on its boundary), and the map stage's input types in
:meth:`MadeMap.source`. Write one map to look at::

    PYTHONPATH=. python -m tests.mapgen 3 --kind grid -o /tmp/maps
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import hashlib
import math
from pathlib import Path

import numpy as np
import shapely
import yaml

from bearnav_cli.geometry import circle_polygon

__all__ = ["KINDS", "MIN_COMPONENT_SHARE", "MadeMap", "generate", "main", "maze_passages"]

#: The kinds of map, each drawn from its own random stream (seed 3 of two kinds are unrelated maps).
KINDS = ("clutter", "rooms", "maze", "grid")
#: Least share of the bounds' area the goal's free component covers (else the layout is drawn again).
MIN_COMPONENT_SHARE = 0.3
#: Layouts drawn before giving up on a seed (a layout fails when its free space falls apart).
MAX_ATTEMPTS = 50
#: Tags of a map: at least, at most, and at most on a grid. The map stage (and every sight test after it)
#: builds one sight region per tag against every obstacle edge, and a grid's ragged edges are many: its
#: cap keeps a grid map loading in about the time a polygon map takes.
MIN_TAGS, MAX_TAGS, GRID_MAX_TAGS = 8, 24, 16
#: Gray levels of the grid image: occupied, unknown (an obstacle by default) and free (map_server trinary).
OCCUPIED_GRAY, UNKNOWN_GRAY, FREE_GRAY = 0, 128, 254
#: The map_server YAML's thresholds (the ROS defaults).
GRID_THRESHOLDS = {"negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196}


@dataclasses.dataclass(frozen=True)
class MadeMap:
    """A generated map: the bearnav map description and, for a grid, its map_server files.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    seed : int
        The seed it was drawn from.
    spec : dict
        The map description (docs/maps.md); a grid's names its map_server YAML under ``occupancy``.
    grid : dict or None
        The map_server YAML (``image``, ``resolution``, ``origin``, thresholds) of a grid map.
    image : bytes or None
        The binary PGM the grid YAML names (row 0 the top of the map).
    """

    kind: str
    seed: int
    spec: dict
    grid: dict | None = None
    image: bytes | None = None

    @property
    def name(self) -> str:
        """The map's name (its files are named after it)."""
        return self.spec["name"]

    def source(self):
        """The map stage's input, as ``bearnav`` would read the files :meth:`write` writes.

        Returns
        -------
        bearnav_cli.stages.map_.MapSource
            A fresh copy of the description, with the grid attached for a grid map.
        """
        from bearnav_cli.stages import map_

        grid = None
        blobs = [yaml.safe_dump(self.spec, sort_keys=False).encode()]
        if self.grid is not None:
            grid = map_.GridSource(dict(self.grid), self.image, self.spec["occupancy"], self.grid["image"])
            blobs.append(self.image)
        sha = hashlib.sha256(b"".join(blobs)).hexdigest()
        return map_.MapSource(spec=copy.deepcopy(self.spec), file=f"{self.name}.yaml", sha256=sha, grid=grid)

    def write(self, folder: Path) -> Path:
        """Write the map YAML (and a grid's YAML and PGM beside it) into ``folder``.

        Parameters
        ----------
        folder : pathlib.Path
            Created if missing.

        Returns
        -------
        pathlib.Path
            The map YAML, for ``bearnav plan``.
        """
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        if self.grid is not None:
            (folder / self.grid["image"]).write_bytes(self.image)
            (folder / self.spec["occupancy"]).write_text(yaml.safe_dump(self.grid, sort_keys=False))
        path = folder / f"{self.name}.yaml"
        path.write_text(yaml.safe_dump(self.spec, sort_keys=False))
        return path


def generate(seed: int, kind: str = "clutter", params: dict | None = None) -> MadeMap:
    """The map ``seed`` of ``kind``.

    Parameters
    ----------
    seed : int
        Any non-negative integer.
    kind : str
        ``clutter`` (rectangles, discs and turned boxes in a box), ``rooms`` (a floor of rooms with a door
        in every wall a spanning tree needs and some more, and furniture), ``maze`` (a perfect maze with a
        few walls knocked out) or ``grid`` (one of the three drawn into an occupancy grid with ragged,
        SLAM-like edges, specks and sometimes an unknown margin).
    params : dict, optional
        The map's ``params:`` (per-stage parameters); none by default, so every stage runs its defaults.

    Returns
    -------
    MadeMap
        The map, its name ``made_KIND_SEED``.

    Raises
    ------
    ValueError
        For an unknown kind.
    RuntimeError
        When :data:`MAX_ATTEMPTS` layouts in a row leave no large enough free component (not seen).
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    rng = np.random.default_rng([int(seed), KINDS.index(kind)])
    for _ in range(MAX_ATTEMPTS):
        made = _attempt(rng, int(seed), kind)
        if made is not None:
            if params:
                made.spec["params"] = copy.deepcopy(params)
            return made
    raise RuntimeError(f"{kind} {seed}: no layout with a free component of {MIN_COMPONENT_SHARE:.0%} of the map")


# --------------------------------------------------------------------------- layouts


def _r(value: float) -> float:
    """Map numbers with 3 decimals: readable YAML, and the geometry here is built from the same numbers."""
    return round(float(value), 3)


@dataclasses.dataclass
class _Layout:
    """Obstacles in the spec's form and as the map stage will build them (shapely)."""

    width: float
    height: float
    obstacles: list = dataclasses.field(default_factory=list)
    shapes: list = dataclasses.field(default_factory=list)

    def rect(self, x0: float, y0: float, x1: float, y1: float) -> None:
        box = [_r(x0), _r(y0), _r(x1), _r(y1)]
        if box[0] < box[2] and box[1] < box[3]:
            self.obstacles.append({"rectangle": box})
            self.shapes.append(shapely.box(*box))

    def disc(self, cx: float, cy: float, radius: float) -> None:
        c, r = [_r(cx), _r(cy)], _r(radius)
        self.obstacles.append({"circle": {"center": c, "radius": r}})
        self.shapes.append(shapely.Polygon(circle_polygon(c, r)))  # the map stage's own polygon of the disc

    def turned_box(self, cx: float, cy: float, w: float, h: float, angle: float) -> None:
        u, v = np.array([math.cos(angle), math.sin(angle)]), np.array([-math.sin(angle), math.cos(angle)])
        corners = [np.array([cx, cy]) + a * w / 2 * u + b * h / 2 * v for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        points = [[_r(p[0]), _r(p[1])] for p in corners]
        self.obstacles.append({"polygon": points})
        self.shapes.append(shapely.Polygon(points))

    def raw(self) -> shapely.Geometry:
        return shapely.union_all(self.shapes) if self.shapes else shapely.Polygon()


def _clutter(rng: np.random.Generator) -> _Layout:
    """Boxes, discs and turned boxes anywhere in a box (overlapping, or crossing the walls)."""
    out = _Layout(_r(rng.uniform(5.0, 14.0)), _r(rng.uniform(4.0, 11.0)))
    area = out.width * out.height
    for _ in range(int(rng.integers(3, 4 + area * rng.uniform(0.04, 0.16)))):
        cx, cy = rng.uniform([0.0, 0.0], [out.width, out.height])
        pick = rng.random()
        if pick < 0.45:
            w, h = rng.uniform(0.15, 2.0, 2)
            out.rect(cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2)
        elif pick < 0.8:
            out.disc(cx, cy, rng.uniform(0.1, 1.0))
        else:
            w, h = rng.uniform(0.2, 2.0, 2)
            out.turned_box(cx, cy, w, h, rng.uniform(0.0, math.pi))
    return out


def _cuts(rng: np.random.Generator, length: float, n: int, least: float) -> list[float]:
    """``n`` parts of ``[0, length]``, each at least ``least`` long, at random (the cut positions, ends included)."""
    share = rng.dirichlet(np.ones(n))
    sizes = least + share * (length - n * least)
    return [0.0, *np.cumsum(sizes)[:-1].tolist(), length]


def _rooms(rng: np.random.Generator, radius: float) -> _Layout:
    """A floor of rooms on a random rectangular grid; doors in a spanning tree of walls and in some others."""
    nx, ny = int(rng.integers(2, 5)), int(rng.integers(1, 4))
    out = _Layout(_r(rng.uniform(2.5 * nx, 4.5 * nx)), _r(rng.uniform(2.5 * ny, 4.5 * ny)))
    xs, ys = _cuts(rng, out.width, nx, 2.0), _cuts(rng, out.height, ny, 2.0)
    half = rng.uniform(0.03, 0.12)  # half the wall thickness
    # the walls between neighbouring rooms: (room a, room b, fixed coordinate, span along the wall, vertical?)
    walls = []
    for i in range(nx):
        for j in range(ny):
            if i + 1 < nx:
                walls.append(((i, j), (i + 1, j), xs[i + 1], (ys[j], ys[j + 1]), True))
            if j + 1 < ny:
                walls.append(((i, j), (i, j + 1), ys[j + 1], (xs[i], xs[i + 1]), False))
    # a door in every wall of a random spanning tree (every room reachable), and in others at random
    order = rng.permutation(len(walls))
    group = {(i, j): (i, j) for i in range(nx) for j in range(ny)}

    def root(room):
        while group[room] != room:
            room = group[room]
        return room

    extra = rng.uniform(0.0, 0.7)
    for k in order:
        a, b, at, (lo, hi), vertical = walls[k]
        joins = root(a) != root(b)
        if joins:
            group[root(a)] = root(b)
        pieces = [(lo - half, hi + half)]
        if joins or rng.random() < extra:
            width = min(rng.uniform(max(0.6, 2 * radius + 0.1), 1.6), hi - lo - 0.3)
            start = rng.uniform(lo + 0.15, hi - 0.15 - width)
            pieces = [(lo - half, start), (start + width, hi + half)]
        for p0, p1 in pieces:
            if vertical:
                out.rect(at - half, p0, at + half, p1)
            else:
                out.rect(p0, at - half, p1, at + half)
    # furniture: it may block a door; a layout whose rooms fall apart is drawn again
    for i in range(nx):
        for j in range(ny):
            for _ in range(int(rng.integers(0, 3))):
                cx = rng.uniform(xs[i] + 0.5, xs[i + 1] - 0.5)
                cy = rng.uniform(ys[j] + 0.5, ys[j + 1] - 0.5)
                if rng.random() < 0.6:
                    w, h = rng.uniform(0.2, 1.2, 2)
                    out.rect(cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2)
                else:
                    out.disc(cx, cy, rng.uniform(0.1, 0.5))
    return out


def maze_passages(rng: np.random.Generator, nx: int, ny: int, start: tuple[int, int]) -> set[tuple[int, int, int, int]]:
    """The passages of a perfect maze on an ``nx × ny`` grid of cells, dug depth-first from ``start``.

    Parameters
    ----------
    rng : numpy.random.Generator
        Picks the next neighbour at every step.
    nx, ny : int
        Cells along x and y.
    start : tuple of int
        The cell the dig starts from.

    Returns
    -------
    set of tuple
        ``(i0, j0, i1, j1)`` (lower cell first) for every wall that is open.
    """
    seen = np.zeros((nx, ny), bool)
    opened: set[tuple[int, int, int, int]] = set()
    stack = [start]
    seen[start] = True
    while stack:
        i, j = stack[-1]
        nbrs = [
            (i + di, j + dj)
            for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))
            if 0 <= i + di < nx and 0 <= j + dj < ny and not seen[i + di, j + dj]
        ]
        if not nbrs:
            stack.pop()
            continue
        a, b = nbrs[int(rng.integers(len(nbrs)))]
        opened.add((min(i, a), min(j, b), max(i, a), max(j, b)))
        seen[a, b] = True
        stack.append((a, b))
    return opened


def _maze(rng: np.random.Generator) -> _Layout:
    """A perfect maze (depth-first) on a random grid of random cell size, a few walls knocked out (loops)."""
    nx, ny, size = int(rng.integers(3, 7)), int(rng.integers(3, 6)), rng.uniform(1.0, 2.2)
    out = _Layout(_r(nx * size), _r(ny * size))
    half = rng.uniform(0.03, 0.1)
    opened = maze_passages(rng, nx, ny, (int(rng.integers(nx)), int(rng.integers(ny))))
    loops = rng.uniform(0.0, 0.2)
    for i in range(nx):
        for j in range(ny):
            if i + 1 < nx and (i, j, i + 1, j) not in opened and rng.random() >= loops:  # east wall
                out.rect((i + 1) * size - half, j * size - half, (i + 1) * size + half, (j + 1) * size + half)
            if j + 1 < ny and (i, j, i, j + 1) not in opened and rng.random() >= loops:  # north wall
                out.rect(i * size - half, (j + 1) * size - half, (i + 1) * size + half, (j + 1) * size + half)
    return out


# --------------------------------------------------------------------------- grids


def _raster(layout: _Layout, rng: np.random.Generator) -> tuple[np.ndarray, float, tuple[float, float]]:
    """The layout drawn into pixels with ragged edges: (gray image, row 0 at the top; resolution; origin).

    A pixel is occupied when its centre lies within half a pixel of an obstacle (so that a wall thinner
    than a pixel stays closed); then the free pixels next to an obstacle become occupied at random, in
    one or two passes (a SLAM map's ragged edges never shrink an obstacle), a few specks of one to four
    pixels appear in the free space, and sometimes a margin of unknown pixels runs along the border.
    """
    res = _r(rng.uniform(0.05, 0.1))
    origin = (_r(-rng.uniform(0.0, 3.0)), _r(-rng.uniform(0.0, 3.0)))
    nx, ny = math.ceil(layout.width / res), math.ceil(layout.height / res)
    xs, ys = (np.arange(nx) + 0.5) * res, (np.arange(ny) + 0.5) * res  # layout frame, row 0 at the bottom
    X, Y = np.meshgrid(xs, ys)
    occ = shapely.contains_xy(shapely.buffer(layout.raw(), 0.5 * res), X, Y)
    for _ in range(1 if rng.random() < 0.8 else 2):
        near = np.zeros_like(occ)
        near[1:] |= occ[:-1]
        near[:-1] |= occ[1:]
        near[:, 1:] |= occ[:, :-1]
        near[:, :-1] |= occ[:, 1:]
        occ |= near & ~occ & (rng.random(occ.shape) < rng.uniform(0.1, 0.3))
    for _ in range(int(rng.integers(0, 1 + nx * ny // 2000))):
        i, j = int(rng.integers(ny - 1)), int(rng.integers(nx - 1))
        h, w = rng.integers(1, 3, 2)
        occ[i : i + h, j : j + w] = True
    gray = np.where(occ, OCCUPIED_GRAY, FREE_GRAY).astype(np.uint8)
    if rng.random() < 0.5:  # unknown beyond a ragged margin, as a map cut out of a larger scan
        # its depth per side, per row or column, steps every few pixels (not at every one)
        steps = rng.integers(0, 3, (4, max(nx, ny) // 4 + 1)).repeat(int(rng.integers(4, 16)), axis=1)
        depth = rng.integers(1, 4) + steps[:, : max(nx, ny)]
        i, j = np.mgrid[0:ny, 0:nx]
        margin = (j < depth[0, i]) | (j >= nx - depth[1, i]) | (i < depth[2, j]) | (i >= ny - depth[3, j])
        gray[margin & ~occ] = UNKNOWN_GRAY
    return gray[::-1].copy(), res, origin


def _pixels(gray: np.ndarray, res: float, origin: tuple[float, float]) -> shapely.Geometry:
    """The non-free pixels (occupied and unknown: both obstacles by default) as one exact shape, row runs unioned."""
    blocked = gray[::-1] != FREE_GRAY  # row 0 at the bottom
    ox, oy = origin
    boxes = []
    for i, row in enumerate(blocked):
        step = np.diff(np.concatenate([[0], row.astype(np.int8), [0]]))
        lo, hi = np.flatnonzero(step == 1), np.flatnonzero(step == -1)
        if lo.size:
            boxes.append(shapely.box(ox + lo * res, oy + i * res, ox + hi * res, oy + (i + 1) * res))
    return shapely.union_all(np.concatenate(boxes)) if boxes else shapely.Polygon()


def _pgm(gray: np.ndarray) -> bytes:
    """A binary 8-bit PGM (``P5``) of a gray image."""
    return f"P5\n{gray.shape[1]} {gray.shape[0]}\n255\n".encode() + gray.astype(np.uint8).tobytes()


# --------------------------------------------------------------------------- goal, starts, tags


def _attempt(rng: np.random.Generator, seed: int, kind: str) -> MadeMap | None:
    """One layout with its goal, starts and tags; None when its free space falls apart."""
    radius = _r(rng.uniform(0.05, 0.25))
    base = kind if kind != "grid" else ("clutter", "rooms", "maze")[int(rng.integers(3))]
    layout = _clutter(rng) if base == "clutter" else _rooms(rng, radius) if base == "rooms" else _maze(rng)
    name = f"made_{kind}_{seed}"
    grid = image = None
    if kind == "grid":
        gray, res, origin = _raster(layout, rng)
        raw = _pixels(gray, res, origin)
        bounds = [origin[0], origin[1], origin[0] + gray.shape[1] * res, origin[1] + gray.shape[0] * res]
        grid = {"image": f"{name}.pgm", "resolution": res, "origin": [origin[0], origin[1], 0.0], **GRID_THRESHOLDS}
        image = _pgm(gray)
    else:
        raw = layout.raw()
        bounds = [0.0, 0.0, layout.width, layout.height]
    # the map stage inflates by ρ/cos(π/32) with a polygon around the disc; 2% more (and the
    # polygon inside its circle here) errs on the side of less free space
    grown = radius * 1.02 + 1e-3
    box = shapely.box(*bounds)
    free = shapely.difference(
        shapely.box(bounds[0] + grown, bounds[1] + grown, bounds[2] - grown, bounds[3] - grown),
        shapely.buffer(raw, grown),
    )
    parts = sorted(shapely.get_parts(free), key=lambda p: -p.area)
    if not parts or parts[0].area < MIN_COMPONENT_SHARE * box.area:
        return None
    reach = parts[0]
    room = shapely.buffer(reach, -rng.uniform(0.02, 0.3))  # the goal's margin, drawn too
    points = _points_in(room, rng, 1 + int(rng.integers(1, 4)))
    if points is None:
        return None
    tags = _tags(box, raw, reach, grown, rng, GRID_MAX_TAGS if kind == "grid" else MAX_TAGS)
    if len(tags) < 2:
        return None
    spec = {"name": name}
    if grid is None:
        spec["bounds"] = bounds
    spec.update({"robot_radius": radius, "goal": points[0], "starts": points[1:]})
    if grid is None:
        spec["obstacles"] = layout.obstacles
    else:
        spec["occupancy"] = f"{name}_grid.yaml"
    spec["landmarks"] = [{"id": f"m{k}", "position": p} for k, p in enumerate(tags)]
    return MadeMap(kind, seed, spec, grid, image)


def _points_in(region: shapely.Geometry, rng: np.random.Generator, n: int) -> list[list[float]] | None:
    """``n`` points drawn uniformly in ``region`` (3 decimals, still inside), or None if it is too thin."""
    if region.is_empty:
        return None
    x0, y0, x1, y1 = region.bounds
    shapely.prepare(region)
    out: list[list[float]] = []
    for _ in range(20):
        p = np.round(rng.uniform([x0, y0], [x1, y1], (64, 2)), 3)
        out += p[shapely.contains_xy(region, p[:, 0], p[:, 1])].tolist()
        if len(out) >= n:
            return [[float(x), float(y)] for x, y in out[:n]]
    return None


def _tags(
    box: shapely.Geometry,
    raw: shapely.Geometry,
    reach: shapely.Geometry,
    grown: float,
    rng: np.random.Generator,
    most: int,
) -> list[list[float]]:
    """Tags on the walls and faces next to the reachable free space, one every 2–4 units of face, ``most`` at most.

    The faces are the boundary of the raw free space (the bounds less the raw obstacles), so a tag lies
    exactly on a wall or an obstacle's face; only faces within reach of the component of the goal count
    (a tag in a walled-off pocket helps nobody). Tags closer than 3% of the diagonal to another are
    dropped (two tags at one place are one tag).
    """
    near = shapely.intersection(shapely.difference(box, raw).boundary, shapely.buffer(reach, 1.5 * grown + 0.05))
    # the intersection may hold stray points where a face only touches the buffer: lines only
    faces = shapely.multilinestrings([g for g in shapely.get_parts(near) if g.geom_type == "LineString"])
    length = faces.length
    if length <= 0:
        return []
    x0, y0, x1, y1 = box.bounds
    gap = 0.03 * math.hypot(x1 - x0, y1 - y0)
    wanted = int(np.clip(round(length / rng.uniform(2.0, 4.0)), MIN_TAGS, most))
    tags: list[list[float]] = []
    for at in rng.uniform(0.0, length, 20 * wanted):
        p = shapely.line_interpolate_point(faces, at)
        xy = [float(p.x), float(p.y)]
        if all(math.dist(xy, q) >= gap for q in tags):
            tags.append(xy)
            if len(tags) == wanted:
                break
    return tags


def main(argv: list[str] | None = None) -> None:
    """Write the map ``SEED`` of ``--kind`` into ``-o FOLDER`` and print the map YAML's path.

    Parameters
    ----------
    argv : list of str, optional
        The arguments (``sys.argv[1:]`` by default).
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seed", type=int)
    parser.add_argument("--kind", choices=KINDS, default="clutter")
    parser.add_argument("-o", "--out", type=Path, default=Path("."), help="folder (created if missing)")
    args = parser.parse_args(argv)
    print(generate(args.seed, args.kind).write(args.out))


if __name__ == "__main__":
    main()
