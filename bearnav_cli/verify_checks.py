"""The exact checks ``bearnav verify`` makes of a plan's own data, without a closed loop (ALGORITHMS §8, §12.8).

- :func:`certificates` / :func:`certificate_problems` — every cell's certificate re-checked at its
  vertices from the stored gain and rows only (:func:`bearnav_cli.runtime.certificate.field_margins`,
  numpy, no LP, nothing from ``synthesize``), and the cells whose claimed certificate it refutes;
- :func:`flagged_cells` — decomposition's flags, from the hashed ``cell_flags`` bits only;
- :func:`check_geometry` — the cells cover the bounds, lie inside them, contain their edge; a certified
  cell's barrier rows are unit-norm and positive at the exit point; tree edges are free; the collision
  samples are those of ``tree.npz`` when it is given;
- :func:`unreached_regions` / :func:`reached_starts` — the free regions the tree never reached, and
  random starts outside them;
- :func:`check_lookahead` — the look-ahead plan's ``λ`` and inflation against its map.

:func:`bearnav_cli.verify.run` runs them and reports them in a
:class:`~bearnav_cli.verify_report.VerifyReport`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from bearnav_cli import composition
from bearnav_cli.datatypes import CLAIMS_CERTIFICATE, CellFlag, CellStatus, Plan, cell_polygons
from bearnav_cli.funnel import coverage_domain, reached_parts
from bearnav_cli.geometry import FreeSpace, inflate
from bearnav_cli.routes import sample_starts
from bearnav_cli.runtime.certificate import UNIT_TOL, barrier_fault, field_margins, gain_field

__all__ = [
    "CERTIFICATE_TOL",
    "COVERAGE_TOL",
    "GOAL_FIELD_TOL",
    "Certificates",
    "Geometry",
    "Unreached",
    "certificate_problems",
    "certificates",
    "check_geometry",
    "check_lookahead",
    "flagged_cells",
    "reached_starts",
    "rows_not_polygon",
    "unreached_regions",
]

#: Largest violation (and margin mismatch) a certified cell may show (ALGORITHMS §8).
CERTIFICATE_TOL = 1e-7
#: Relative tolerance of the goal cell's field ``M = cI``, ``a = cg``.
GOAL_FIELD_TOL = 1e-9
#: Uncovered area allowed, as a fraction of ``area(B)``.
COVERAGE_TOL = 1e-9


# --------------------------------------------------------------------------- certificates


@dataclass(frozen=True, eq=False)
class Certificates:
    """Worst-case values of every cell's conditions, recomputed at the vertices (C cells).

    Attributes
    ----------
    value_h : ndarray, shape (C,)
        ``max_{q,k} −(n_k·u_q + c_h h_k(v_q))``; NaN without barrier rows.
    value_v : ndarray, shape (C,)
        ``max_q z·u_q + c_v V(v_q)``; NaN in the goal cell.
    value_u : ndarray, shape (C,)
        ``max_q ‖u_q‖_∞ − u_max``.
    violation : ndarray, shape (C,)
        Largest positive part of the three (``inf`` if a needed constant is NaN).
    margin_error : ndarray, shape (C,)
        ``max(|value_h − margin_h|, |value_v − margin_v|)`` (0 when both are NaN, ``inf``
        when only one is).
    goal_error : ndarray, shape (C,)
        Goal cells: ``max(‖M − cI‖, ‖a − cg‖) / max(1, ‖a‖)`` with ``c = c_v``; NaN elsewhere.
    """

    value_h: np.ndarray
    value_v: np.ndarray
    value_u: np.ndarray
    violation: np.ndarray
    margin_error: np.ndarray
    goal_error: np.ndarray


def _mismatch(value: float, stored: float) -> float:
    if math.isnan(value) and math.isnan(stored):
        return 0.0
    if math.isnan(value) or math.isnan(stored):
        return math.inf
    return abs(value - stored)


def certificates(plan: Plan) -> Certificates:
    """Recompute every cell's CBF, CLF and input values from the stored gain and rows (ALGORITHMS §8).

    The one re-check, :func:`~bearnav_cli.runtime.certificate.field_margins`, on hashed data only: the
    gain, constants and stored margins of ``plan.npz`` and the rows of its cells.
    """
    cells = plan.cells
    landmarks = plan.landmarks
    count = cells.n_cells
    out = {name: np.full(count, np.nan) for name in ("value_h", "value_v", "value_u", "goal_error")}
    violation = np.zeros(count)
    margin_error = np.zeros(count)
    goal = plan.map.goal
    for c in range(count):
        M, a = gain_field(plan.gain[c], landmarks)  # Σ_k K_k, Σ_k K_k l_k
        normals, offsets = cells.barrier(c)
        edge = cells.parent[cells.cell_node[c]] >= 0  # an edge cell; the root's cell is the goal cell
        z, xj = cells.exit_dir[c], cells.exit_point[c]
        m = field_margins(M, a, cells.vertices(c), z, xj, normals, offsets, plan.c_h[c], plan.c_v[c], plan.u_max[c])
        bad = 0.0
        if len(normals):
            out["value_h"][c] = m.cbf
            bad = max(bad, math.inf if math.isnan(m.cbf) else m.cbf)
        if edge:
            out["value_v"][c] = m.clf
            bad = max(bad, m.clf)
        else:
            gain_c = plan.c_v[c]
            scale = max(1.0, float(np.linalg.norm(a)))
            out["goal_error"][c] = (
                max(float(np.linalg.norm(M - gain_c * np.eye(2))), float(np.linalg.norm(a - gain_c * goal))) / scale
            )
        out["value_u"][c] = m.input
        violation[c] = max(bad, m.input, 0.0)
        margin_error[c] = max(
            _mismatch(out["value_h"][c], float(plan.margin_h[c])), _mismatch(out["value_v"][c], float(plan.margin_v[c]))
        )
    return Certificates(violation=violation, margin_error=margin_error, **out)


def certificate_problems(plan: Plan, cert: Certificates) -> dict[int, str]:
    """Cells that claim a certificate (status 0, 1, 4) the recomputation refutes, with the reason."""
    problems = {}
    for c in range(plan.cells.n_cells):
        status = int(plan.status[c])
        if status not in CLAIMS_CERTIFICATE:
            continue
        why = []
        if cert.violation[c] > CERTIFICATE_TOL:
            why.append(f"violation {cert.violation[c]:.3g}")
        if cert.margin_error[c] > CERTIFICATE_TOL:
            why.append(f"stored margins off by {cert.margin_error[c]:.3g}")
        is_root = plan.cells.parent[plan.cells.cell_node[c]] < 0
        if is_root and not cert.goal_error[c] <= GOAL_FIELD_TOL:
            why.append(f"field is not c·(g − x) (error {cert.goal_error[c]:.3g})")
        if status == CellStatus.GOAL and not is_root:
            why.append("goal status on an edge cell (its CLF was checked)")
        if why:
            problems[c] = ", ".join(why)
    return problems


def flagged_cells(plan: Plan) -> dict[str, list[int]]:
    """Cells flagged by decomposition (ALGORITHMS §5.4–5.5), by flag name, from the ``cell_flags`` bits.

    Only hashed data: the manifest's ``stats`` lists (which synthesize writes from the same bits)
    are not covered by the content hash, so an edit there must not change what verify says.
    """
    return {flag.name.lower(): plan.cells.flagged(flag) for flag in CellFlag if flag != CellFlag.NONE}


# --------------------------------------------------------------------------- geometry


@dataclass(frozen=True)
class Geometry:
    """Geometric checks of a plan (ALGORITHMS §8).

    Attributes
    ----------
    uncovered_area : float
        ``area(B \\ ∪ cells)`` (map units²).
    coverage_ok : bool
        ``uncovered_area <= 1e-9·area(B)``.
    cells_outside_bounds : tuple of int
        Cells with a vertex outside ``B`` (beyond ``tol``).
    edges_outside_cell : tuple of int
        Cells that do not contain their node and exit point (the goal cell: the goal).
    bad_barriers : tuple of int
        Cells claiming a certificate (status 0, 1, 4) whose barrier rows cannot carry it: a normal not of
        unit norm, or ``h(x_j) <= 0`` in an edge cell (:func:`~bearnav_cli.runtime.certificate.barrier_fault`,
        the judgement by which ``synthesize`` certifies no such cell; one not certified is reported as such).
    rows_not_polygon : tuple of int
        Cells whose half-plane rows ``cell_A x ≤ cell_b`` (what the runtime tests) are not exactly
        the polygon of their stored vertices (where the certificate was checked): see
        :func:`rows_not_polygon`.
    blocked_edges : tuple of int
        Child nodes whose tree edge to the parent is not free.
    samples_unchanged : bool or None
        Whether the collision samples equal ``tree.npz``'s (None when not given).
    """

    uncovered_area: float
    coverage_ok: bool
    cells_outside_bounds: tuple[int, ...]
    edges_outside_cell: tuple[int, ...]
    bad_barriers: tuple[int, ...]
    rows_not_polygon: tuple[int, ...]
    blocked_edges: tuple[int, ...]
    samples_unchanged: bool | None

    @property
    def ok(self) -> bool:
        return (
            self.coverage_ok
            and not self.cells_outside_bounds
            and not self.edges_outside_cell
            and not self.bad_barriers
            and not self.rows_not_polygon
            and not self.blocked_edges
            and self.samples_unchanged is not False
        )


def rows_not_polygon(cells: Any, tol: float) -> tuple[int, ...]:
    """Cells whose rows are not exactly the polygon of their vertices (vectorised over all rows).

    The certificate is checked at the stored vertices; the runtime decides which cell holds a
    point with the rows. The two are one set when row ``q`` is the unit-normal line of edge
    ``v_q → v_{q+1}`` (both ends on it within ``tol``) and every vertex of the cell meets every row
    of the cell within ``tol``: each row is then a supporting line of the polygon along its own edge,
    which also proves the polygon convex. One row per edge is already an invariant of the cells.

    Parameters
    ----------
    cells : Cells
        ``cell_A``, ``cell_b``, ``cell_row_offsets``, ``cell_vertices``, ``cell_vertex_offsets``.
    tol : float
        Geometric tolerance (map units).
    """
    A, b, verts = cells.cell_A, cells.cell_b, cells.cell_vertices
    offsets = cells.cell_vertex_offsets
    count = np.diff(offsets)
    owner = np.repeat(np.arange(len(count)), count)
    index = np.arange(len(verts))
    following = np.where(index + 1 < offsets[owner + 1], index + 1, offsets[owner])
    unit = np.abs(np.hypot(A[:, 0], A[:, 1]) - 1.0) <= UNIT_TOL
    on_line = (np.abs(np.einsum("ij,ij->i", A, verts) - b) <= tol) & (
        np.abs(np.einsum("ij,ij->i", A, verts[following]) - b) <= tol
    )
    bad = ~(unit & on_line)
    width = int(count.max(initial=0))
    slot = index - offsets[owner]
    padded = np.full((len(count), width, 2), np.nan)
    padded[owner, slot] = verts
    # every row against every vertex of its own cell (padding is NaN and never fails)
    lhs = np.einsum("rk,rwk->rw", A, padded[owner])
    with np.errstate(invalid="ignore"):
        bad |= np.any(lhs > (b + tol)[:, None], axis=1)
    return tuple(int(c) for c in np.unique(owner[bad]))


def check_geometry(plan: Plan, space: FreeSpace, tree_samples: np.ndarray | None = None) -> Geometry:
    """Coverage, containment, barrier rows, free tree edges and unchanged samples (ALGORITHMS §8).

    Parameters
    ----------
    plan : Plan
        The plan checked: its cells (vertices, half-plane and barrier rows), tree and map.
    space : FreeSpace
        The free space of the plan's map: the bounds ``B`` the cells must cover (paper plans) and the
        obstacles the tree edges must miss.
    tree_samples : ndarray, shape (S, 2), optional
        ``collision_samples`` of the ``tree.npz`` the plan came from, compared with the plan's
        (map units); ``None``: not compared (``samples_unchanged`` is None).
    """
    cells, map_ = plan.cells, plan.map
    tol = map_.tol
    box = space.box
    polygons = cell_polygons(cells)
    union = shapely.union_all([p.buffer(0) if not p.is_valid else p for p in polygons])
    uncovered = float(shapely.difference(box, union).area)
    lo, hi = map_.bounds[:2] - tol, map_.bounds[2:] + tol
    outside, off_edge, bad_rows = [], [], []
    for c in range(cells.n_cells):
        verts = cells.vertices(c)
        if np.any(verts < lo) or np.any(verts > hi):
            outside.append(c)
        A, b = cells.rows(c)
        node = cells.cell_node[c]
        j = cells.parent[node]
        anchors = np.stack([cells.nodes[node], cells.nodes[j]]) if j >= 0 else map_.goal[None, :]
        if np.any(anchors @ A.T > b + tol):
            off_edge.append(c)
        if int(plan.status[c]) in CLAIMS_CERTIFICATE and barrier_fault(
            *cells.barrier(c), cells.nodes[j] if j >= 0 else None
        ):
            bad_rows.append(c)
    children = np.flatnonzero(cells.parent >= 0)
    free = space.segments_free(cells.nodes[children], cells.nodes[cells.parent[children]])
    unchanged = None
    if tree_samples is not None:
        theirs = np.asarray(tree_samples, float).reshape(-1, 2)
        ours = cells.collision_samples
        unchanged = bool(theirs.shape == ours.shape and np.array_equal(theirs, ours))
    return Geometry(
        uncovered_area=uncovered,
        # funnel cells cover F_m, not the bounds: composition.check measures that coverage
        coverage_ok=cells.is_funnel or uncovered <= COVERAGE_TOL * box.area,
        cells_outside_bounds=tuple(outside),
        edges_outside_cell=tuple(off_edge),
        bad_barriers=tuple(bad_rows),
        rows_not_polygon=rows_not_polygon(cells, tol),
        blocked_edges=tuple(int(i) for i in children[~free]),
        samples_unchanged=unchanged,
    )


# --------------------------------------------------------------------------- free regions never reached


@dataclass(frozen=True)
class Unreached:
    """The free regions the tree never reached (ALGORITHMS §11.5's unreached parts of ``F_m``).

    Attributes
    ----------
    region : shapely geometry
        The parts of ``F_m`` no cell (funnel plans) or tree edge (paper plans) meets.
    avoid : shapely geometry
        Where no Monte-Carlo start is drawn: ``region`` grown by ``1.5·m`` (its margin band and
        the passage that cuts it off).
    area, free_area : float
        ``area(region)`` and the area of the goal's free component (map units²).
    parts : list of (x, y, area)
        A point inside each part and its area, largest first.
    """

    region: Any
    avoid: Any
    area: float
    free_area: float
    parts: list[tuple[float, float, float]]


def unreached_regions(plan: Plan, space: FreeSpace, regions: composition.CoverageRegions | None = None) -> Unreached:
    """The parts of ``F_m`` the plan never reached (:func:`bearnav_cli.composition.coverage_regions` for funnels).

    Funnel plans: the parts of the goal's free component (eroded by the coverage margin ``m``) that no
    cell meets; paper plans: the parts that no tree edge meets.

    Parameters
    ----------
    plan : Plan
        The plan: its cells (funnel) or tree edges (paper), its map and goal.
    space : FreeSpace
        The free space of the plan's map.
    regions : CoverageRegions, optional
        Funnel plans: the split of ``F_m`` when already made (``Composition.regions`` of
        :func:`bearnav_cli.composition.check`); ``None``: computed here. Ignored for paper plans.
    """
    map_ = plan.map
    margin = composition.coverage_margin(plan)
    component = space.component_of(map_.goal)
    if plan.cells.is_funnel:
        if regions is None:
            regions = composition.coverage_regions(plan.cells, space, margin)
        region = regions.unreached
    else:
        cells = plan.cells
        child = np.flatnonzero(cells.parent >= 0)
        edges = (
            shapely.linestrings(np.stack([cells.nodes[child], cells.nodes[cells.parent[child]]], axis=1))
            if len(child)
            else np.array([shapely.Point(map_.goal)])
        )
        full = coverage_domain(component, space.bounds, space.obstacles, margin)
        region = reached_parts(full, shapely.union_all(np.concatenate([edges, [shapely.Point(map_.goal)]])))[1]
    parts = [p for p in shapely.get_parts(region) if p.area > 0]
    parts.sort(key=lambda p: -p.area)
    points = [(float(q.x), float(q.y), float(p.area)) for p, q in ((p, p.representative_point()) for p in parts)]
    avoid = shapely.intersection(shapely.buffer(region, 1.5 * margin), component) if parts else shapely.Polygon()
    return Unreached(region, avoid, float(sum(p.area for p in parts)), float(component.area), points)


def reached_starts(space: FreeSpace, goal: np.ndarray, count: int, rng: np.random.Generator, avoid: Any) -> np.ndarray:
    """``count`` starts of :func:`~bearnav_cli.routes.sample_starts` outside ``avoid`` (redrawn from one generator).

    Parameters
    ----------
    space : FreeSpace
        The map's free space.
    goal : ndarray, shape (2,)
        The goal (map units): the starts lie in its free component.
    count : int
        How many starts.
    rng : numpy.random.Generator
        The generator they are drawn from.
    avoid : shapely geometry or None
        Where no start may lie (the regions the tree never reached); None or empty: anywhere.
    """
    if avoid is None or avoid.is_empty:
        return sample_starts(space, goal, count, rng)
    shapely.prepare(avoid)
    found, total = [], 0
    for _ in range(1000):
        batch = sample_starts(space, goal, max(2 * (count - total), 16), rng)
        if not len(batch):
            break
        keep = ~shapely.intersects_xy(avoid, batch[:, 0], batch[:, 1])
        found.append(batch[keep])
        total += int(keep.sum())
        if total >= count:
            break
    return np.concatenate(found)[:count] if found else np.zeros((0, 2))


def check_lookahead(plan: Plan, space: FreeSpace | None = None) -> list[str]:
    """The look-ahead checks of ALGORITHMS §12.8, exact, from the plan file: what is wrong (empty: nothing).

    * ``lookahead``: the plan's ``λ`` (the one its cells were built for) equals its map's
      ``robot.lookahead``, to the map tolerance;
    * ``obstacles``: the plan's obstacles contain the raw obstacles inflated by ``ρ + λ``
      (:func:`bearnav_cli.geometry.inflate`, the polygonal buffer the map stage uses), to the map
      tolerance: an exact shapely ``covers`` of the inflated raw obstacles by the plan's obstacles
      grown by ``tol``. With (C1) every cell then lies in the free space of a robot of radius
      ``ρ + λ``, and the body of radius ``ρ`` around the axle ``x = p − λh`` of a look-ahead point
      ``p`` in a cell touches no obstacle. The walls follow from ``B_r``, the bounds shrunk by
      ``ρ + λ`` (``Map.free_bounds``), which (C1) checks the cells against.

    Parameters
    ----------
    plan : Plan
        The plan (its cells' ``lookahead`` and its embedded map).
    space : FreeSpace, optional
        ``FreeSpace.from_map(plan.map)``, whose unions of the raw and the stored obstacles are
        reused (built when None).
    """
    problems = []
    map_ = plan.map
    built = float(plan.cells.lookahead)
    if not abs(built - map_.lookahead) <= map_.tol:
        problems.append(
            f"lookahead: the plan's λ = {built:g} differs from its map's robot.lookahead "
            f"{map_.lookahead:g} (the cells were built for another robot)"
        )
    radius = map_.planning_radius
    space = FreeSpace.from_map(map_) if space is None else space
    raw, stored = space.raw_obstacles, space.obstacles
    if map_.raw_obstacles and not raw.is_empty:
        # only the part inside B matters: the walls of B_r keep the robot farther from the rest
        wanted = shapely.intersection(inflate(raw, radius), shapely.box(*map_.bounds))
        if not shapely.covers(shapely.buffer(stored, map_.tol), wanted):
            missing = shapely.difference(wanted, shapely.buffer(stored, map_.tol))
            free = shapely.difference(shapely.box(*map_.bounds), stored)
            gap = shapely.distance(raw, free) if not free.is_empty else math.inf
            problems.append(
                f"obstacles: the plan's obstacles do not contain the raw obstacles inflated by the "
                f"radius plus the look-ahead, {radius:g} ({missing.area:.3g} map units² missing; a free "
                f"point lies {gap:.6g} from a raw obstacle)"
            )
    return problems
