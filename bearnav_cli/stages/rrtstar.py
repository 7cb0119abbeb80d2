"""Stage ``rrtstar``: RRT* rooted at the goal that keeps its collision samples (ALGORITHMS §2).

The tree grows from the goal (node 0). Random samples that fall inside the
inflated obstacles are stored in ``collision_samples`` instead of being thrown
away; border pseudo-samples on the bounds are appended after them. Edge tests
are exact segment-against-polygon tests through :class:`~bearnav_cli.geometry.FreeSpace`.

Speed comes from four things: every sample's collision status is decided in one
vectorised call up front (it does not depend on the tree); the nodes within a step
of a sample come from a bucket grid kept sorted by bucket (:class:`_BucketGrid`)
in one gather, which serves both the nearest node and, when the sample lies within a
step of it, the neighbours; an iteration tests its edges in one exact call (the
nearest node's, the first parent candidates', and those of every neighbour that the
cheapest possible new node could rewire), only for the neighbours whose cost could
improve; and the loop reads scalars as Python floats. The tree is the one the
straightforward loop grows (ALGORITHMS §2), decision for decision.
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
    "DENSE_BUCKETS",
    "MAX_BORDER_SAMPLES",
    "MAX_GRID_CELLS",
    "PARENT_CANDIDATES_FIRST",
    "UNSORTED_NODES",
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


#: Parent candidates whose edges are tested with the others of an iteration; the rest only if all
#: of these are blocked (the first free one wins, and it is almost always among them).
PARENT_CANDIDATES_FIRST = 4
#: Below this many nodes, nearest-neighbour queries scan every node instead of the buckets.
BRUTE_FORCE_NODES = 512
#: Nodes inserted since the grid's last sort, which every query measures on top of its buckets;
#: one more sorts the grid again (an argsort of all nodes).
UNSORTED_NODES = 128
#: Up to this many buckets, the grid also keeps where each bucket's run starts (one bincount per sort),
#: so a query reads its runs' ends instead of searching for them.
DENSE_BUCKETS = 1 << 16


class _BucketGrid:
    """Uniform grid of buckets for nearest and radius queries over the nodes.

    The nodes sorted so far are kept ordered by bucket (``ix·ny + iy``, then index), so the
    buckets of one grid column within a block are one slice, found by one ``searchsorted``
    for the whole block (or read from the runs' starts, up to :data:`DENSE_BUCKETS`); the
    nodes inserted since (the *tail*, at most :data:`UNSORTED_NODES`) are measured by every
    query. A query gathers the block's slices and the tail and
    finishes with one vectorised distance computation. Nothing is stored per bucket, so a
    large grid costs no memory.
    """

    def __init__(self, bounds: np.ndarray, cell: float, nodes: np.ndarray):
        self.origin = np.asarray(bounds[:2], float)
        self.ox, self.oy = (float(v) for v in self.origin)
        self.cell = cell
        self.shape = (
            max(1, math.ceil((bounds[2] - bounds[0]) / cell)),
            max(1, math.ceil((bounds[3] - bounds[1]) / cell)),
        )
        self.nodes = nodes  # shared, filled by the caller
        self.order = np.zeros(0, np.int64)  # sorted nodes, by (bucket, index)
        self.keys = np.zeros(0, np.int64)  # their buckets, ascending
        self.sorted = 0  # nodes 0 … sorted − 1 are in ``order``; the tail follows
        self.size = 0  # nodes inserted so far (indices 0 … size − 1)
        self.offsets: dict[tuple[int, int], np.ndarray] = {}  # a block's search keys, by its shape, less its first
        self.starts: np.ndarray | None = None  # where each bucket's run starts in ``order`` (dense grids)
        self.ids = np.arange(len(nodes))

    def _cell_of(self, x: float, y: float) -> tuple[int, int]:
        ix = min(max(int((x - self.ox) // self.cell), 0), self.shape[0] - 1)
        iy = min(max(int((y - self.oy) // self.cell), 0), self.shape[1] - 1)
        return ix, iy

    def insert(self, index: int) -> None:
        """Add node ``index`` (the next one: nodes are inserted in index order)."""
        self.size = index + 1
        if self.size - self.sorted > UNSORTED_NODES:
            self._sort()

    def _sort(self) -> None:
        p = self.nodes[: self.size]
        ix = np.clip((p[:, 0] - self.ox) // self.cell, 0, self.shape[0] - 1).astype(np.int64)
        iy = np.clip((p[:, 1] - self.oy) // self.cell, 0, self.shape[1] - 1).astype(np.int64)
        flat = ix * self.shape[1] + iy
        self.order = np.argsort(flat, kind="stable")
        self.keys = flat[self.order]
        self.sorted = self.size
        cells = self.shape[0] * self.shape[1]
        if cells <= DENSE_BUCKETS:
            self.starts = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=cells))])

    def block(self, x: float, y: float, reach: int) -> np.ndarray:
        """Indices of the nodes in the buckets within ``reach`` buckets (Chebyshev) of the point's, and of the tail.

        Every node outside lies farther than ``reach·cell`` from the point.
        """
        nx, ny = self.shape
        ix, iy = self._cell_of(x, y)
        x0, x1 = max(ix - reach, 0), min(ix + reach, nx - 1)
        y0, y1 = max(iy - reach, 0), min(iy + reach, ny - 1)
        # each column's buckets y0 … y1 are one run of the sorted keys: its two ends in one search
        shape = (x1 - x0 + 1, y1 - y0 + 1)
        offsets = self.offsets.get(shape)
        if offsets is None:
            offsets = self.offsets[shape] = (np.arange(shape[0])[:, None] * ny + [0, shape[1]]).ravel()
        keys = offsets + (x0 * ny + y0)
        ends = (self.starts[keys] if self.starts is not None else np.searchsorted(self.keys, keys)).tolist()
        order = self.order
        parts = [order[a:b] for a, b in zip(ends[::2], ends[1::2], strict=True) if b > a]
        if self.size > self.sorted:
            parts.append(self.ids[self.sorted : self.size])
        if not parts:
            return np.empty(0, np.int64)
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def nearest(self, x: float, y: float, reach: int = 1) -> int:
        """Index of the node nearest to ``(x, y)`` (ties: lowest index), searching from ``reach`` buckets out."""
        if self.size <= BRUTE_FORCE_NODES:
            # A young tree in a large map leaves most buckets empty, and the ring scan would
            # visit thousands of them; one vectorised pass over a few hundred nodes is cheaper.
            d = self.nodes[: self.size] - (x, y)
            return int(np.argmin(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]))
        while True:
            idx = self.block(x, y, reach)
            if not len(idx):
                reach *= 2
                continue
            d = self.nodes[idx] - (x, y)
            d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
            low = d2.min()
            # every node outside the block lies at least reach·cell from the point
            if math.sqrt(low) < reach * self.cell or reach > max(self.shape):
                return int(idx[d2 == low].min())
            # the nearest lies within √low: a block reaching past it holds it
            reach = max(reach + 1, int(math.sqrt(low) // self.cell) + 1)

    def within(self, x: float, y: float, radius: float) -> np.ndarray:
        """Sorted indices of nodes with ``‖node − (x, y)‖ ≤ radius``."""
        if radius <= 0:
            return np.empty(0, np.int64)
        idx = self.block(x, y, max(1, math.ceil(radius / self.cell)))
        d = self.nodes[idx] - (x, y)
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
    # per-sample values as Python floats: the loop reads them one at a time
    sample_xy = samples.tolist()
    blocked = (in_obstacle & (params.collision_policy == "skip")).tolist()
    gx, gy = (float(v) for v in map_.goal)
    xy = [(gx, gy)]  # node positions as Python floats, alongside ``nodes``
    px, py = np.empty(capacity), np.empty(capacity)  # and as columns, for distances to many nodes
    px[0], py[0] = gx, gy

    for it in range(params.iterations):
        if progress is not None and it % report_every == 0:
            progress(it, params.iterations)
        if blocked[it]:
            continue
        x, y = sample_xy[it]
        # one gather serves the nearest node and, when the sample is within a step of it, the
        # neighbours too: every node outside the block lies farther than a step from the sample
        if n <= BRUTE_FORCE_NODES:
            # a young tree in a large map leaves most buckets empty: measure every node; in index
            # order, the first minimum has the lowest index
            around, reach = grid.ids[:n], math.inf
            ax, ay = px[:n] - x, py[:n] - y
            d2 = ax * ax + ay * ay
            vn = int(d2.argmin())
        else:
            around, reach = grid.block(x, y, BUCKETS_PER_STEP), BUCKETS_PER_STEP * grid.cell
            ax, ay = px[around] - x, py[around] - y
            d2 = ax * ax + ay * ay
            low = d2.min() if len(d2) else math.inf
            if math.sqrt(low) < reach:
                vn = int(around[d2 == low].min())
            else:  # a sparse part of the tree: search farther out, past the nearest gathered node if any
                far = 2 * BUCKETS_PER_STEP if low == math.inf else int(math.sqrt(low) // grid.cell) + 1
                vn = grid.nearest(x, y, far)
        vx, vy = xy[vn]
        dx, dy = x - vx, y - vy
        dist = math.hypot(dx, dy)
        if dist > eta:
            scale = eta / dist
            x, y = vx + scale * dx, vy + scale * dy
        if min(dist, eta) <= tol:
            skipped_duplicates += 1
            continue
        # a sample beyond a step lies in a sparse part of the tree, where the steered edge is often
        # blocked: test it alone first; near the tree it is almost always free and joins the batch
        first = [] if dist > eta else [vn]
        if dist > eta and not space.segment_free(vx, vy, x, y):
            continue

        radius = rewiring_radius(n, free_area, eta)
        if radius <= 0:
            near = np.empty(0, np.int64)
        elif dist <= eta and radius <= reach:  # the sample is the new node: its neighbours were gathered
            near = np.sort(around[d2 <= radius * radius])
        elif n <= BRUTE_FORCE_NODES:
            ax, ay = px[:n] - x, py[:n] - y
            near = np.flatnonzero(ax * ax + ay * ay <= radius * radius)
        else:
            near = grid.within(x, y, radius)
        near = near[near != vn]
        best_parent, best_cost = vn, float(cost[vn]) + math.hypot(x - vx, y - vy)
        if not len(near):  # no parent to choose and none to rewire (a sparse part of the tree)
            if first and not space.segment_free(vx, vy, x, y):
                continue
            n = _add_node(n, x, y, best_parent, best_cost, nodes, px, py, xy, parent, cost, children, grid)
            continue
        d_near = np.hypot(px[near] - x, py[near] - y)
        # parent candidates: cheaper than through the nearest node, by (cost, index)
        cost_near = cost[near]
        through = cost_near + d_near
        better = (through < best_cost) | ((through == best_cost) & (near < vn))
        cand = near[better]
        order = np.lexsort((cand, through[better]))
        cand, cand_cost = cand[order], through[better][order]
        # rewiring candidates for the cheapest cost the new node can get: a superset of those
        # for the cost it does get (costs and sums round monotonically)
        lowest = min(best_cost, float(cand_cost[0])) if len(cand) else best_cost
        maybe = np.flatnonzero(cost_near - (lowest + d_near) > tol)
        # the edges this iteration tests, in one exact call: the nearest node's (unless tested), the
        # first few parent candidates (the first free one in (cost, index) order wins, and that is
        # almost always among them) and the rewiring candidates
        head = cand[:PARENT_CANDIDATES_FIRST]
        ends = np.concatenate([first, head, near[maybe]]).astype(np.int64)
        free = space.segments_free(nodes[ends], (x, y), known_in_box=True) if len(ends) else np.ones(0, bool)
        if first and not free[0]:
            continue
        free = free[len(first) :]
        hit = np.flatnonzero(free[: len(head)])
        if not len(hit) and len(cand) > len(head):  # all of them blocked: test the others
            hit = len(head) + np.flatnonzero(space.segments_free(nodes[cand[len(head) :]], (x, y), known_in_box=True))
        if len(hit):
            best_parent, best_cost = int(cand[hit[0]]), float(cand_cost[hit[0]])
        new = n
        n = _add_node(n, x, y, best_parent, best_cost, nodes, px, py, xy, parent, cost, children, grid)

        # rewire the neighbours that get cheaper through the new node
        gain = cost_near - (best_cost + d_near)
        rewire = np.flatnonzero((gain > tol) & (near != best_parent))
        if len(rewire):
            free_near = np.zeros(len(near), bool)
            free_near[maybe] = free[len(head) :]
            rewire = rewire[free_near[rewire]]
            for v, dv in zip(near[rewire].tolist(), d_near[rewire].tolist(), strict=True):
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


def _add_node(n, x, y, up, c, nodes, px, py, xy, parent, cost, children, grid) -> int:
    """Store node ``n`` at ``(x, y)`` below ``up`` with cost ``c``, in every view of the tree; returns ``n + 1``."""
    nodes[n] = x, y
    px[n], py[n] = x, y
    xy.append((x, y))
    parent[n] = up
    cost[n] = c
    children.append([])
    children[up].append(n)
    grid.insert(n)
    return n + 1


def _shift_subtree(root: int, delta: float, cost: np.ndarray, children: list[list[int]]) -> None:
    """Add ``delta`` to the cost of ``root`` and of every descendant."""
    subtree = [root]
    for v in subtree:  # the list grows while it is walked: breadth first
        below = children[v]
        if below:  # most nodes are leaves
            subtree.extend(below)
    cost[subtree] += delta  # one addition per node, as one at a time would do


def summary(tree: Tree) -> str:
    """One line for ``inspect`` and ``plan``."""
    s = tree.stats
    return (
        f"{plural(len(tree.nodes), 'node')} from {s.get('iterations', '?')} iterations, "
        f"{s.get('random_collision_samples', '?')} collision samples + {s.get('border_samples', '?')} on the border"
    )


# --------------------------------------------------------------------------- checks and verdict

#: Most cells of RRT*'s neighbour grid (3 per step along each side of the bounds). The sorted grid stores
#: nothing per bucket beyond :data:`DENSE_BUCKETS`, but a nearest-node query widens its block bucket by bucket,
#: so a grid far finer than the tree is slow, not large.
MAX_GRID_CELLS = 10_000_000
#: Most border pseudo-samples of RRT* (they become collision samples every later stage reads).
MAX_BORDER_SAMPLES = 200_000
#: Bytes per RRT* iteration (sample, node, parent, cost, child list, bucket slot), measured on the kitchen.
RRT_BYTES_PER_ITERATION = 400
#: Bytes per cell of RRT*'s neighbour grid: where each bucket's run starts (int64), kept only up to
#: :data:`DENSE_BUCKETS` buckets (:class:`_BucketGrid`).
RRT_BYTES_PER_GRID_CELL = 8


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
    fixed = (min(grid, DENSE_BUCKETS) + 1) * RRT_BYTES_PER_GRID_CELL + border * 64
    limits.check_memory(params.iterations, "iterations", RRT_BYTES_PER_ITERATION, "iterations", fixed)


def problems(tree: Tree) -> list[verdicts.Problem]:
    """Why the tree is not usable: no route (only its root)."""
    return verdicts.no_route(tree.nodes)
