"""Stage ``rrtstar``: RRT* rooted at the goal that keeps its collision samples (ALGORITHMS §2).

The tree grows from the goal (node 0). Random samples that fall inside the
inflated obstacles are stored in ``collision_samples`` instead of being thrown
away; border pseudo-samples on the bounds are appended after them. Edge tests
are exact segment-against-polygon tests through :class:`~bearnav_cli.geometry.FreeSpace`.

Speed comes from three things: every sample's collision status is decided in one
vectorised call up front (it does not depend on the tree), neighbours come from
a uniform bucket grid (:class:`_BucketGrid`), and edges are tested lazily, only
for the neighbours whose cost could improve.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from bearnav_cli import limits, verdicts
from bearnav_cli.datatypes import Map, Tree, plural
from bearnav_cli.errors import ResourceLimitError
from bearnav_cli.geometry import FreeSpace, barrier_margin
from bearnav_cli.params.rrtstar import Params

__all__ = [
    "border_samples",
    "BRUTE_FORCE_NODES",
    "BUCKETS_PER_STEP",
    "check_resources",
    "MAX_BORDER_SAMPLES",
    "MAX_GRID_CELLS",
    "problems",
    "rewiring_radius",
    "RRT_BYTES_PER_GRID_CELL",
    "RRT_BYTES_PER_ITERATION",
    "run",
    "summary",
    "VERSION",
]

VERSION = 1
#: Buckets per step length along each axis: smaller buckets make nearest-node queries in a
#: dense tree cheaper, at the price of more buckets to visit for a radius query.
BUCKETS_PER_STEP = 3


def rewiring_radius(n: int, free_area: float, step: float) -> float:
    """Paper B's radius ``r(n) = min(γ·(ln n / n)^(1/3), η)``, ``γ = √(6·A_free/π)``; ``r(1) = 0``.

    The radius within which a new node looks for a cheaper parent and rewires its neighbours
    (ALGORITHMS §2).

    Parameters
    ----------
    n : int
        Number of nodes in the tree.
    free_area : float
        ``A_free``, the area of the free space (map units²).
    step : float
        The steering step ``η`` (map units), an upper bound of the radius.

    Returns
    -------
    float
        ``r(n)`` in map units.
    """
    if n <= 1:
        return 0.0
    gamma = math.sqrt(6.0 * free_area / math.pi)
    return min(gamma * (math.log(n) / n) ** (1.0 / 3.0), step)


def border_samples(bounds: np.ndarray, spacing: float) -> np.ndarray:
    """Points on ``∂B`` at most ``spacing`` apart, corners included.

    Side ``s`` of length ``ℓ_s`` gets ``ceil(ℓ_s / spacing)`` evenly spaced points
    starting at its first corner, so there are ``Σ_s ceil(ℓ_s/spacing)`` in all.

    Returns
    -------
    ndarray, shape (P, 2)
    """
    if spacing <= 0:
        return np.empty((0, 2))
    xmin, ymin, xmax, ymax = bounds
    corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]], float)
    out = []
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        count = math.ceil(np.linalg.norm(b - a) / spacing)
        t = np.arange(count)[:, None] / count
        out.append(a + t * (b - a))
    return np.concatenate(out)


#: Below this many nodes, nearest-neighbour queries scan every node instead of the buckets.
BRUTE_FORCE_NODES = 512


class _BucketGrid:
    """Uniform grid of buckets holding node indices, for nearest and radius queries.

    Each bucket is a growable int64 array; a query gathers the buckets around the
    point and finishes with one vectorised distance computation.
    """

    def __init__(self, bounds: np.ndarray, cell: float, nodes: np.ndarray):
        self.origin = np.asarray(bounds[:2], float)
        self.cell = cell
        self.shape = (
            max(1, math.ceil((bounds[2] - bounds[0]) / cell)),
            max(1, math.ceil((bounds[3] - bounds[1]) / cell)),
        )
        self.nodes = nodes  # shared, filled by the caller
        self.members: list[np.ndarray] = [np.empty(4, np.int64) for _ in range(self.shape[0] * self.shape[1])]
        self.counts = np.zeros(self.shape[0] * self.shape[1], np.int64)
        self.size = 0  # nodes inserted so far (indices 0 … size − 1)

    def _cell_of(self, p: np.ndarray) -> tuple[int, int]:
        ix = min(max(int((p[0] - self.origin[0]) // self.cell), 0), self.shape[0] - 1)
        iy = min(max(int((p[1] - self.origin[1]) // self.cell), 0), self.shape[1] - 1)
        return ix, iy

    def insert(self, index: int) -> None:
        ix, iy = self._cell_of(self.nodes[index])
        flat = ix * self.shape[1] + iy
        count = self.counts[flat]
        bucket = self.members[flat]
        if count == len(bucket):
            bucket = np.concatenate([bucket, np.empty(len(bucket), np.int64)])
            self.members[flat] = bucket
        bucket[count] = index
        self.counts[flat] = count + 1
        self.size = max(self.size, index + 1)

    def _ring_cells(self, ix: int, iy: int, ring: int) -> list[int]:
        """Flat ids of the buckets at Chebyshev distance exactly ``ring`` from bucket (ix, iy)."""
        nx, ny = self.shape
        if ring == 0:
            return [ix * ny + iy]
        x0, x1, y0, y1 = ix - ring, ix + ring, iy - ring, iy + ring
        cells = []
        for jx in (x0, x1):  # the left and right columns, full height
            if 0 <= jx < nx:
                cells.extend(jx * ny + jy for jy in range(max(y0, 0), min(y1, ny - 1) + 1))
        for jy in (y0, y1):  # the top and bottom rows, without the corners already taken
            if 0 <= jy < ny:
                cells.extend(jx * ny + jy for jx in range(max(x0 + 1, 0), min(x1 - 1, nx - 1) + 1))
        return cells

    def _gather(self, cells: list[int]) -> np.ndarray:
        """Node indices held in the given buckets."""
        counts = self.counts
        parts = [self.members[c][: counts[c]] for c in cells if counts[c]]
        if not parts:
            return np.empty(0, np.int64)
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def nearest(self, p: np.ndarray) -> int:
        """Index of the node nearest to ``p`` (ties: lowest index)."""
        if self.size <= BRUTE_FORCE_NODES:
            # A young tree in a large map leaves most buckets empty, and the ring scan would
            # visit thousands of them; one vectorised pass over a few hundred nodes is cheaper.
            d = self.nodes[: self.size] - p
            return int(np.argmin(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]))
        ix, iy = self._cell_of(p)
        best_d2, best = math.inf, -1
        ring = 0
        max_ring = max(self.shape)
        while ring <= max_ring:
            idx = self._gather(self._ring_cells(ix, iy, ring))
            if len(idx):
                d = self.nodes[idx] - p
                d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
                k = int(np.argmin(d2))
                low = d2[k]
                if low < best_d2 or (low == best_d2 and idx[k] < best):
                    ties = idx[d2 == low]
                    best_d2, best = low, int(ties.min())
            # every bucket at ring distance > ring lies farther than ring·cell from p
            if best >= 0 and math.sqrt(best_d2) <= ring * self.cell:
                break
            ring += 1
        return best

    def within(self, p: np.ndarray, radius: float) -> np.ndarray:
        """Sorted indices of nodes with ``‖x − p‖ ≤ radius``."""
        if radius <= 0:
            return np.empty(0, np.int64)
        ix, iy = self._cell_of(p)
        reach = max(1, math.ceil(radius / self.cell))
        nx, ny = self.shape
        xs = range(max(ix - reach, 0), min(ix + reach, nx - 1) + 1)
        ys = range(max(iy - reach, 0), min(iy + reach, ny - 1) + 1)
        idx = self._gather([jx * ny + jy for jx in xs for jy in ys])
        d = self.nodes[idx] - p
        keep = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] <= radius * radius
        return np.sort(idx[keep])


def run(map_: Map, params: Params = Params(), progress: Callable[[int, int], None] | None = None) -> Tree:
    """Grow an RRT* tree rooted at the goal, keeping collision samples.

    Parameters
    ----------
    map_ : Map
        The normalised map.
    params : Params
        Iterations, step, seed, collision policy, border spacing.
    progress : callable, optional
        ``progress(done, total)`` called about a hundred times.

    Returns
    -------
    Tree
        Nodes (node 0 is the goal), parents, costs and collision samples.
    """
    space = FreeSpace.from_map(map_)
    tol = map_.tol
    eta = params.step
    rng = np.random.default_rng(params.seed)
    xmin, ymin, xmax, ymax = map_.bounds
    samples = rng.uniform((xmin, ymin), (xmax, ymax), size=(params.iterations, 2))
    # independent of the tree: one vectorised call; a sample in the band B \ B_r lies in a wall
    in_obstacle = space.in_obstacle(samples) | ~space.in_bounds(samples)
    free_area = space.free_area
    clearance = barrier_margin(params.clearance, map_.diagonal)
    space = space.planning_space(params.clearance, map_.goal, map_.diagonal)  # samples are still tested against O

    capacity = params.iterations + 1
    nodes = np.empty((capacity, 2))
    parent = np.full(capacity, -1, np.int64)
    cost = np.zeros(capacity)
    children: list[list[int]] = [[]]
    nodes[0] = map_.goal
    n = 1
    grid = _BucketGrid(map_.bounds, eta / BUCKETS_PER_STEP, nodes)
    grid.insert(0)
    report_every = max(1, params.iterations // 100)
    skipped_duplicates = 0

    for it in range(params.iterations):
        if progress is not None and it % report_every == 0:
            progress(it, params.iterations)
        xr = samples[it]
        if in_obstacle[it] and params.collision_policy == "skip":
            continue
        vn = grid.nearest(xr)
        delta = xr - nodes[vn]
        dist = math.hypot(delta[0], delta[1])
        xn = xr if dist <= eta else nodes[vn] + (eta / dist) * delta
        if min(dist, eta) <= tol:
            skipped_duplicates += 1
            continue
        if not space.segments_free(nodes[vn], xn, known_in_box=True)[0]:
            continue

        radius = rewiring_radius(n, free_area, eta)
        near = grid.within(xn, radius)
        near = near[near != vn]
        d_near = np.hypot(nodes[near, 0] - xn[0], nodes[near, 1] - xn[1])
        # choose the parent: candidates by (cost, index); the first free edge wins
        best_parent, best_cost = vn, cost[vn] + math.hypot(xn[0] - nodes[vn, 0], xn[1] - nodes[vn, 1])
        through = cost[near] + d_near
        better = (through < best_cost) | ((through == best_cost) & (near < vn))
        if better.any():
            cand = near[better]
            order = np.lexsort((cand, through[better]))
            cand, cand_cost = cand[order], through[better][order]
            free = space.segments_free(nodes[cand], xn, known_in_box=True)
            hit = np.flatnonzero(free)
            if len(hit):
                best_parent, best_cost = int(cand[hit[0]]), float(cand_cost[hit[0]])
        new = n
        nodes[new] = xn
        parent[new] = best_parent
        cost[new] = best_cost
        children.append([])
        children[best_parent].append(new)
        grid.insert(new)
        n += 1

        # rewire the neighbours that get cheaper through the new node
        gain = cost[near] - (best_cost + d_near)
        cand_mask = (gain > tol) & (near != best_parent)
        if cand_mask.any():
            cand = near[cand_mask]
            free = space.segments_free(nodes[cand], xn, known_in_box=True)
            for v, dv in zip(cand[free], d_near[cand_mask][free], strict=True):
                v = int(v)
                new_cost = best_cost + dv
                if new_cost < cost[v] - tol:  # costs only fall during rewiring: re-check
                    children[parent[v]].remove(v)
                    parent[v] = new
                    children[new].append(v)
                    _shift_subtree(v, new_cost - cost[v], cost, children)

    if progress is not None:
        progress(params.iterations, params.iterations)
    border = border_samples(map_.bounds, params.border_spacing)
    random_hits = samples[in_obstacle]
    stats = {
        "iterations": params.iterations,
        "clearance": clearance,
        "nodes": n,
        "random_collision_samples": int(len(random_hits)),
        "border_samples": int(len(border)),
        "duplicate_samples_skipped": skipped_duplicates,
        "free_area": free_area,
    }
    return Tree(
        map=map_,
        nodes=nodes[:n],
        parent=parent[:n],
        cost=cost[:n],
        collision_samples=np.concatenate([random_hits, border]),
        stats=stats,
    )


def _shift_subtree(root: int, delta: float, cost: np.ndarray, children: list[list[int]]) -> None:
    """Add ``delta`` to the cost of ``root`` and of every descendant."""
    stack = [root]
    while stack:
        v = stack.pop()
        cost[v] += delta
        stack.extend(children[v])


def summary(tree: Tree) -> str:
    """One line for ``inspect`` and ``plan``."""
    s = tree.stats
    return (
        f"{plural(len(tree.nodes), 'node')} from {s.get('iterations', '?')} iterations, "
        f"{s.get('random_collision_samples', '?')} collision samples + {s.get('border_samples', '?')} on the border"
    )


# --------------------------------------------------------------------------- checks and verdict

#: Most cells of RRT*'s neighbour grid (3 per step along each side of the bounds).
MAX_GRID_CELLS = 10_000_000
#: Most border pseudo-samples of RRT* (they become collision samples every later stage reads).
MAX_BORDER_SAMPLES = 200_000
#: Bytes per RRT* iteration (sample, node, parent, cost, child list, bucket slot), measured on the kitchen.
RRT_BYTES_PER_ITERATION = 400
#: Bytes per cell of RRT*'s neighbour grid (an empty 4-slot bucket and its bookkeeping).
RRT_BYTES_PER_GRID_CELL = 150


def _count(cells: float) -> float:
    """``ceil(cells)``, kept a float beyond 2**53: a tiny step makes counts past any integer a float
    holds exactly, or ``inf``, and those are only compared with the limits and refused."""
    return math.ceil(cells) if cells < 2.0**53 else cells


def check_resources(map_: Map, params: Params, given: frozenset[str] = frozenset()) -> None:
    """Refuse a run that cannot finish before it starts: the neighbour grid, the border samples, the memory.

    Parameters
    ----------
    map_ : Map
        The map RRT* would run on (its bounds).
    params : Params
        The resolved parameters.
    given : frozenset of str
        The parameters set by the map's ``params:`` or an option, not left at their default: a
        ``border_spacing`` left at ``step/10`` is blamed on ``step``.

    Raises
    ------
    ResourceLimitError
        The grid exceeds :data:`MAX_GRID_CELLS` (with the smallest step that fits), the border
        :data:`MAX_BORDER_SAMPLES` (with the smallest spacing), or the iterations the memory budget
        (with how many fit); its field is the parameter to change (``step``, ``border_spacing``,
        ``iterations``), which the pipeline turns into the option or map field that set it.
    """
    xmin, ymin, xmax, ymax = (float(v) for v in map_.bounds)  # Python floats overflow to inf quietly
    width, height = xmax - xmin, ymax - ymin
    cell = params.step / BUCKETS_PER_STEP
    grid = _count(width / cell) * _count(height / cell)
    if grid > MAX_GRID_CELLS:
        smallest = BUCKETS_PER_STEP * math.sqrt(width * height / MAX_GRID_CELLS)
        raise ResourceLimitError(
            f"{params.step:g} makes RRT*'s neighbour grid {grid:.3g} cells over {width:g} x {height:g} "
            f"(limit {MAX_GRID_CELLS:.0e}); use at least {smallest:.3g}",
            field="step",
        )
    spacing = params.border_spacing
    border = 0 if spacing == 0 else 2 * (_count(width / spacing) + _count(height / spacing))
    if border > MAX_BORDER_SAMPLES:
        smallest = 2 * (width + height) / MAX_BORDER_SAMPLES
        derived = "border_spacing" not in given
        hint = f"(step/10 = {params.border_spacing:g}) " if derived else ""
        raise ResourceLimitError(
            f"border pseudo-samples every {params.border_spacing:g} {hint}would be {border:,.0f} points (limit "
            f"{MAX_BORDER_SAMPLES:,}); use a --border-spacing of at least {smallest:.3g} (or 0: none)",
            field="step" if derived else "border_spacing",
        )
    fixed = grid * RRT_BYTES_PER_GRID_CELL + border * 64
    limits.check_memory(params.iterations, "iterations", RRT_BYTES_PER_ITERATION, "iterations", fixed)


def problems(tree: Tree) -> list[verdicts.Problem]:
    """Why the tree is not usable: no route (only its root)."""
    return verdicts.no_route(tree.nodes)
