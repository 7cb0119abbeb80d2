"""``bearnav verify plan.npz``: check a plan without trusting the stages that made it (ALGORITHMS §8).

Three independent checks:

1. **Certificates**, recomputed from ``gain``, ``landmarks`` and the stored rows only,
   with a few lines of numpy (no LP, nothing from ``synthesize``): at every vertex
   ``v_q`` of a cell, ``u_q = a − M v_q`` with ``a = Σ K_k l_k`` and ``M = Σ K_k``; the CBF,
   CLF and input values are the worst case over the vertices, which is the worst case
   over the cell because every condition is affine in ``x``.
2. **Geometry**: the cells cover the bounds (shapely), lie inside them, contain their
   edge; barrier rows are unit-norm and positive at the exit point; tree edges are free;
   the collision samples are those of ``tree.npz`` when it is given.
3. **Monte Carlo**: ``n_starts`` random starts in the goal's free component, run through
   :func:`bearnav_cli.stages.simulate.rollout`, compared with the straight distance and
   with the exact shortest route (:func:`bearnav_cli.routes.route_lengths`). Free regions the
   tree never reached (parts of ``F_m`` cut off from every cell, or for ``paper`` plans from
   every tree edge, by passages narrower than ``2m``) are reported and no start is drawn
   there; any collision of a run fails verification, whatever ``min_success`` says.

:func:`run` returns a :class:`VerifyReport`; :attr:`VerifyReport.failed` is the exit decision.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from bearnav_cli import composition, runtime
from bearnav_cli.composition import Composition
from bearnav_cli.datatypes import CellFlag, CellStatus, Map, Outcome, Plan, Simulation, cell_list, percent, plural
from bearnav_cli.errors import ArtifactError, InvalidParamsError
from bearnav_cli.funnel import coverage_domain, reached_parts
from bearnav_cli.geometry import FreeSpace, inflate
from bearnav_cli.liveness import Liveness
from bearnav_cli.liveness import measure as measure_liveness
from bearnav_cli.routes import MAX_ROUTE_VERTICES, route_lengths, sample_starts
from bearnav_cli.runtime import PlanArrays
from bearnav_cli.runtime.certificate import field_margins, gain_field
from bearnav_cli.stages import simulate

__all__ = ["CERTIFICATE_TOL", "CERTIFIED", "COVERAGE_TOL", "GOAL_FIELD_TOL", "UNIT_TOL", "Certificates", "Geometry",
           "Params", "Unreached", "VerifyReport", "certificate_problems", "certificates", "check_geometry",
           "check_lookahead", "duration_text", "flagged_cells", "guarantee", "loop_speed", "run",
           "unreached_regions"]  # fmt: skip

log = logging.getLogger(__name__)

#: Largest violation (and margin mismatch) a certified cell may show (ALGORITHMS §8).
CERTIFICATE_TOL = 1e-7
#: Relative tolerance of the goal cell's field ``M = cI``, ``a = cg``.
GOAL_FIELD_TOL = 1e-9
#: Uncovered area allowed, as a fraction of ``area(B)``.
COVERAGE_TOL = 1e-9
#: Allowed deviation of a barrier normal's norm from 1.
UNIT_TOL = 1e-9

CERTIFIED = (CellStatus.CERTIFIED, CellStatus.RELAXED, CellStatus.GOAL)


@dataclass(frozen=True)
class Params:
    """Parameters of ``bearnav verify``.

    Attributes
    ----------
    n_starts : int
        Random starts of the Monte-Carlo check (0 skips it).
    seed : int
        Seed of ``numpy.random.default_rng`` for the starts.
    speed : float or None
        Reference speed of the closed loop (map units / s); ``None`` means the map's ``params: simulate:
        speed``, else simulate's default. Both are resolved by :func:`loop_speed`.
    dt : float or None
        Euler step (s); ``None`` takes the simulate default.
    min_success : float or None
        Fail when the success rate is below this fraction (``None``: never on that ground).
    dynamics : {"single", "unicycle"}
        Robot of the closed loop: the single integrator the certificate is stated for, or the unicycle
        (``α`` = the loop's speed). On a plan with a look-ahead ``λ > 0`` the unicycle drives the point
        ``p = x + λh`` as a single integrator (ALGORITHMS §12.6, Lemma 7), inside the certificate;
        with ``λ = 0`` it follows §7.1's rules with ``certified_heading`` on (the heading allowance,
        ``runtime.unicycle.heading_allowance``), outside the certificate: its steps count as uncertified
        and the report says so. Both run with displacements and exact motion. A run from ``D``
        **breaches** the certificate when any of its steps is not certified
        (``runtime.ControlOutput.certified``: a funnel cell's field followed, not a straight
        approach, on an exact estimate; not checked for the unicycle without a look-ahead) or when
        its true position (``p`` with a look-ahead) lies outside every cell of ``D`` after a step;
        any breach or collision of a run from ``D`` fails verify.
    bearing_error_deg : float or None
        The bound on every world-frame bearing error of the liveness report (degrees, in (0, 45));
        ``None`` means the map's ``robot: bearing_error_deg`` plus ``compass_error_deg`` (0.2° by default).
    live_fov : float or None
        Measure liveness (ALGORITHMS §12.5) for a camera of this field of view (degrees, in (0, 360]).
        ``None`` skips it. On a grid per cell, ``ε_c^look`` (the worst over the cell of the best one-look
        bound over the headings), the live cells (``ε_c^look < τ_c − κℓ − ν``), the live fraction of ``D``
        and the certified bearing error ``η*``: a measurement at a stated resolution, not a proof, that
        never fails verify (:func:`bearnav_cli.liveness.measure`).
    slip : float or None
        The odometry error bound of the liveness report, a fraction of each step (in [0, 1)) plus a
        floor (``κ`` and ``ν``). ``None`` means the map's ``robot: slip`` (0.03 by default); the
        floor is the map's ``robot: slip_floor``, else ``1e-4·D``.
    live_resolution : float or None
        Grid spacing of the liveness report (map units, > 0). ``None`` means about 25 points in the
        median cell, at most ``0.01·D`` (:func:`bearnav_cli.liveness.default_resolution`).
    """

    n_starts: int = 200
    seed: int = 0
    speed: float | None = None
    dt: float | None = None
    min_success: float | None = None
    dynamics: str = "single"
    bearing_error_deg: float | None = None
    live_fov: float | None = None
    slip: float | None = None
    live_resolution: float | None = None

    def __post_init__(self) -> None:
        if self.dynamics not in runtime.DYNAMICS:
            raise InvalidParamsError(f"must be one of {', '.join(runtime.DYNAMICS)}, got {self.dynamics!r}",
                                     field="dynamics")  # fmt: skip
        if isinstance(self.n_starts, bool) or int(self.n_starts) != self.n_starts or self.n_starts < 0:
            raise InvalidParamsError(f"must be a non-negative integer, got {self.n_starts}", field="n_starts")
        if self.min_success is not None and not 0.0 <= self.min_success <= 1.0:
            raise InvalidParamsError(f"must lie in [0, 1], got {self.min_success}", field="min_success")
        simulate.Params(**({} if self.speed is None else {"speed": self.speed}), dt=self.dt)  # the loop's checks
        for name, low, high, closed in (("bearing_error_deg", 0.0, 45.0, (False, False)),
                                        ("live_fov", 0.0, 360.0, (False, True)),
                                        ("slip", 0.0, 1.0, (True, False)),
                                        ("live_resolution", 0.0, math.inf, (False, False))):  # fmt: skip
            value = getattr(self, name)
            if value is None:
                continue
            number = isinstance(value, (int, float)) and not isinstance(value, bool)
            inside = number and (value >= low if closed[0] else value > low) and (
                value <= high if closed[1] else value < high)  # fmt: skip
            if not inside:
                interval = f"{'[' if closed[0] else '('}{low:g}, {high:g}{']' if closed[1] else ')'}"
                raise InvalidParamsError(f"must lie in {interval}, got {value!r}", field=name)
            if name != "live_fov" and self.live_fov is None:
                raise InvalidParamsError("only with live_fov (the liveness report it belongs to)", field=name)


def loop_speed(plan: Plan, params: Params) -> float:
    """The speed of the closed loop: ``params.speed``, else the map's ``params: simulate: speed``, else
    simulate's default (the paper maps' units are not metres); ``bearnav verify`` and :func:`run` use it."""
    if params.speed is not None:
        return float(params.speed)
    given = (plan.map.params or {}).get("simulate") or {}
    return float(given.get("speed", simulate.Params().speed)) if isinstance(given, dict) else simulate.Params().speed


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
        m = field_margins(M, a, cells.vertices(c), z, xj, normals, offsets, plan.c_h[c], plan.c_v[c],
                          plan.u_max[c])  # fmt: skip
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
        if status not in CERTIFIED:
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
        Cells with a barrier normal not of unit norm, or ``h(x_j) <= 0`` in an edge cell.
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
    polygons = [shapely.Polygon(cells.vertices(c)) for c in range(cells.n_cells)]
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
        normals, offsets = cells.barrier(c)
        if len(normals):
            unit = np.abs(np.hypot(normals[:, 0], normals[:, 1]) - 1.0) <= UNIT_TOL
            positive = normals @ cells.nodes[j] + offsets > 0 if j >= 0 else np.ones(len(normals), bool)
            if not (unit.all() and positive.all()):
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
        edges = shapely.linestrings(np.stack([cells.nodes[child], cells.nodes[cells.parent[child]]], axis=1)) \
            if len(child) else np.array([shapely.Point(map_.goal)])  # fmt: skip
        full = coverage_domain(component, space.bounds, space.obstacles, margin)
        region = reached_parts(full, shapely.union_all(np.concatenate([edges, [shapely.Point(map_.goal)]])))[1]
    parts = [p for p in shapely.get_parts(region) if p.area > 0]
    parts.sort(key=lambda p: -p.area)
    points = [(float(q.x), float(q.y), float(p.area)) for p, q in ((p, p.representative_point()) for p in parts)]
    avoid = shapely.intersection(shapely.buffer(region, 1.5 * margin), component) if parts else shapely.Polygon()
    return Unreached(region, avoid, float(sum(p.area for p in parts)), float(component.area), points)


def _reached_starts(space: FreeSpace, goal: np.ndarray, count: int, rng: np.random.Generator,
                    avoid: Any) -> np.ndarray:  # fmt: skip
    """``count`` starts of :func:`sample_starts` outside ``avoid`` (redrawn from the same generator)."""
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


# --------------------------------------------------------------------------- the report


def _finite_or_none(values: np.ndarray) -> list:
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, float)]


def _mean_or_nan(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(values.mean()) if len(values) else math.nan


@dataclass(frozen=True, eq=False)
class VerifyReport:
    """Everything ``bearnav verify`` found; :attr:`failed` decides the exit code.

    Attributes
    ----------
    status : ndarray of int8, shape (C,)
        Stored :class:`CellStatus` of each cell.
    certificates : Certificates
        Recomputed values per cell.
    false_certificates : dict of int to str
        Cells with status 0, 1 or 4 whose certificate the recomputation refutes.
    c_h_tilde, c_v_tilde, c_h_over_s_max : ndarray, shape (C,)
        Bearing constants ``c_h/s_min``, ``c_v/s_max`` and ``c_h/s_max`` (ALGORITHMS §5.5).
    flagged : dict of str to list of int
        Cells flagged by decomposition, by flag name.
    geometry : Geometry
        The geometric checks (:func:`check_geometry`).
    starts : ndarray, shape (R, 2)
        Monte-Carlo starts.
    rollouts : Simulation or None
        Their closed-loop runs (None when skipped).
    straight : ndarray, shape (R,)
        ``‖x₀ − g‖``. The path ratios (:attr:`ratio_straight`, :attr:`ratio_route`) are means
        over the successful runs of (path length + ``‖x_end − g‖``) / reference.
    route : ndarray, shape (R,)
        Shortest collision-free route length from each start.
    min_success : float or None
        The success rate below which the plan fails (``Params.min_success``; None: never on that ground).
    skipped : str or None
        Why the Monte-Carlo check did not run.
    goal : ndarray, shape (2,)
        The map's goal (map units), the reference of :attr:`straight`.
    composition : Composition or None
        The composed certificate's checks of a funnel plan (:func:`bearnav_cli.composition.check`);
        None for paper plans.
    world_cells : list of int or None
        Cells that no longer hold (C1) in the ``world`` map given to :func:`run`; None without one.
    unreached : Unreached or None
        The free regions the tree never reached (:func:`unreached_regions`): no start is drawn there.
    breaches : ndarray of bool, shape (R,), or None
        Runs from ``D`` that breached the certificate (:class:`Params` ``dynamics`` defines it).
    lookahead_problems : tuple of str
        What :func:`check_lookahead` found wrong (the plan's ``λ`` against its map's, the obstacles
        against the raw ones inflated by ``ρ + λ``); each fails verify.
    uncovered_dynamics : str or None
        Why the closed loop's robot is outside the certificate (the unicycle on a plan without a
        look-ahead), a note; None when it is inside.
    liveness : Liveness or None
        The liveness measurement of ALGORITHMS §12.5 (:func:`bearnav_cli.liveness.measure`) when
        :class:`Params` ``live_fov`` asks for it; a note, never a failure.
    liveness_note : str or None
        Why liveness was asked for but not measured (a paper plan), a note.
    """

    status: np.ndarray
    certificates: Certificates
    false_certificates: dict[int, str]
    c_h_tilde: np.ndarray
    c_v_tilde: np.ndarray
    c_h_over_s_max: np.ndarray
    flagged: dict[str, list[int]]
    geometry: Geometry
    starts: np.ndarray
    rollouts: Simulation | None
    straight: np.ndarray
    route: np.ndarray
    min_success: float | None
    skipped: str | None
    goal: np.ndarray
    composition: Composition | None = None
    world_cells: list[int] | None = None
    unreached: Unreached | None = None
    breaches: np.ndarray | None = None
    lookahead_problems: tuple[str, ...] = ()
    uncovered_dynamics: str | None = None
    liveness: Liveness | None = None
    liveness_note: str | None = None

    # ------------------------------------------------------------- the composed certificate (§11)
    @property
    def in_domain(self) -> np.ndarray:
        """Runs that started in the certified domain ``D``, shape (R,)."""
        if self.rollouts is None:
            return np.zeros(0, bool)
        return self.rollouts.start_in_domain

    @property
    def success_in_domain(self) -> float:
        """Success rate of the runs from ``D`` (the theorem says 1); NaN without such runs."""
        return self.rollouts.success_rate_of(self.in_domain) if self.rollouts is not None else math.nan

    @property
    def success_outside_domain(self) -> float:
        """Success rate of the runs from ``F \\ D`` (uncertified: straight approach first)."""
        return self.rollouts.success_rate_of(~self.in_domain) if self.rollouts is not None else math.nan

    # ------------------------------------------------------------- Monte-Carlo figures
    @property
    def success_rate(self) -> float:
        return self.rollouts.success_rate if self.rollouts is not None else math.nan

    @property
    def outcome_counts(self) -> dict[str, int]:
        return self.rollouts.counts() if self.rollouts is not None else {}

    @property
    def left_cell_total(self) -> int:
        return int(self.rollouts.left_cell.sum()) if self.rollouts is not None else 0

    @property
    def left_cell_fraction(self) -> float:
        """Fraction of runs with at least one relocation."""
        if self.rollouts is None or not len(self.rollouts):
            return math.nan
        return float(np.mean(self.rollouts.left_cell > 0))

    @property
    def approach_fraction(self) -> float:
        """Fraction of runs that drove straight to a tree node at least once (outside every safe set)."""
        if self.rollouts is None or not len(self.rollouts):
            return math.nan
        return float(np.mean(self.rollouts.approach_steps > 0))

    def _ratio(self, reference: np.ndarray) -> float:
        """Mean of (path length + the last ``‖x_end − g‖``) / reference over the successful runs.

        A run stops within ``goal_tolerance`` of the goal; adding the remaining straight bit
        makes a straight run score exactly 1 against the straight distance.
        """
        if self.rollouts is None:
            return math.nan
        r = self.rollouts
        ok = (r.outcome == Outcome.SUCCESS) & (reference > 0)
        rest = np.hypot(*(r.final_position[ok] - self.goal).T)
        return _mean_or_nan((r.path_length[ok] + rest) / reference[ok])

    @property
    def ratio_straight(self) -> float:
        return self._ratio(self.straight)

    @property
    def ratio_route(self) -> float:
        return self._ratio(self.route)

    # ------------------------------------------------------------- decision
    @property
    def uncertified(self) -> list[int]:
        """Cells with status 2 (not certified) or 3 (solver failure)."""
        bad = (CellStatus.NOT_CERTIFIED, CellStatus.SOLVER_FAILURE)
        return np.flatnonzero(np.isin(self.status, bad)).tolist()

    @property
    def reasons(self) -> list[str]:
        """Why the plan fails verification (empty when it passes)."""
        out = []
        if self.uncertified:
            out.append(f"{plural(len(self.uncertified), 'cell')} not certified (status 2 or 3): "
                       f"{cell_list(self.uncertified)}")  # fmt: skip
        if self.false_certificates:
            items = [f"{c} ({why})" for c, why in sorted(self.false_certificates.items())]
            out.append(f"{len(items)} certified cells fail the recomputation: {cell_list(items)}")
        g = self.geometry
        if not g.coverage_ok:
            out.append(f"cells leave {g.uncovered_area:.3g} map units² of the bounds uncovered")
        for cells, what in (
            (g.cells_outside_bounds, "cells reach outside the bounds"),
            (g.edges_outside_cell, "cells do not contain their edge"),
            (g.bad_barriers, "cells have a barrier row that is not unit-norm or not positive at x_j"),
            (
                g.rows_not_polygon,
                "cells have half-plane rows that are not their polygon (the runtime reads the rows, "
                "the certificate was checked on the polygon)",
            ),
            (g.blocked_edges, "tree edges (by child node) are not free"),
        ):
            if cells:
                out.append(f"{len(cells)} {what}: {cell_list(cells)}")
        if g.samples_unchanged is False:
            out.append("collision samples differ from tree.npz")
        if self.skipped is not None and self.skipped.startswith("malformed"):
            out.append(self.skipped)
        if self.composition is not None:
            out.extend(self.composition.problems)
            if self.rollouts is not None and self.in_domain.any() and self.success_in_domain < 1.0:
                bad = np.flatnonzero(self.in_domain & (self.rollouts.outcome != Outcome.SUCCESS))
                out.append(f"{len(bad)} runs from the certified domain did not reach the goal (the theorem says "
                           f"every one does: a bug): starts {cell_list(bad)}")  # fmt: skip
        if self.rollouts is not None and len(self.rollouts):
            hit = np.flatnonzero(self._collided(certified=True))
            if hit.size:
                whence = " from the certified domain" if self.composition is not None else ""
                out.append(f"{hit.size} of {len(self.rollouts)} closed-loop runs{whence} collided (any collision "
                           f"fails, whatever --min-success says): starts {cell_list(hit)}")  # fmt: skip
        if self.breaches is not None and self.breaches.any():
            bad = np.flatnonzero(self.breaches)
            out.append(f"{bad.size} runs from the certified domain breached it (a step not certified, or a true "
                       f"position outside every cell): starts {cell_list(bad)}")  # fmt: skip
        out.extend(self.lookahead_problems)
        if self.world_cells:
            out.append(f"{len(self.world_cells)} cells no longer hold in the world (C1: they leave B_r or meet an "
                       f"obstacle): {cell_list(self.world_cells)}")  # fmt: skip
        if self.min_success is not None and not self.success_rate >= self.min_success:
            out.append(f"success rate {self.success_rate:.1%} below --min-success {self.min_success:.1%}")
        return out

    def _collided(self, certified: bool) -> np.ndarray:
        """The runs that collided, shape (R,) bool: from D (``certified``) or from outside it.

        A funnel plan's theorem covers the starts in ``D``, so a collision from there fails verify;
        a run from outside ``D`` drives on uncertified rules, and its collision is measured (a note).
        A paper plan certifies no domain: every collision fails.
        """
        hit = self.rollouts.outcome == Outcome.COLLISION
        if self.composition is None:
            return hit if certified else np.zeros_like(hit)
        return hit & (self.in_domain if certified else ~self.in_domain)

    @property
    def notes(self) -> list[str]:
        """What the report adds without failing: the robot outside the certificate, liveness, unreached regions."""
        out = [] if self.uncovered_dynamics is None else [self.uncovered_dynamics]
        if self.rollouts is not None and len(self.rollouts):
            outside = np.flatnonzero(self._collided(certified=False))
            if outside.size:
                out.append(f"{outside.size} of {len(self.rollouts)} closed-loop runs from outside the certified "
                           f"domain collided (measured, not certified: those starts lie in the sliver of free "
                           f"space no cell covers, by an obstacle or a wall): starts {cell_list(outside)}")  # fmt: skip
        if len(self.route) and np.isnan(self.route).all():
            out.append(f"the shortest-route ratio was not computed: the free space has more than "
                       f"{MAX_ROUTE_VERTICES:,} corners (the straight-line ratio is given)")  # fmt: skip
        if self.liveness is not None:
            out.append(self.liveness.summary())
        if self.liveness_note is not None:
            out.append(self.liveness_note)
        u = self.unreached
        if u is None or not u.parts:
            return out
        where = "; ".join(f"({x:.3g}, {y:.3g}) {area:.3g}" for x, y, area in u.parts[:5])
        more = f" … ({len(u.parts)} in all)" if len(u.parts) > 5 else ""
        share = f" ({u.area / u.free_area:.1%} of the free space)" if u.free_area > 0 else ""
        regions = "1 free region" if len(u.parts) == 1 else f"{len(u.parts)} free regions"
        return out + [f"{regions} the tree never reached, {u.area:.3g} map units²{share}, at (x, y) "
                      f"area: {where}{more}; no start was drawn there, the plan says nothing about them"]  # fmt: skip

    @property
    def failed(self) -> bool:
        """The exit decision: True means exit code 1."""
        return bool(self.reasons)

    def summary(self) -> str:
        """One line for the CLI."""
        n = len(self.status)
        certified = int(np.count_nonzero(np.isin(self.status, CERTIFIED))) - len(self.false_certificates)
        comp = self.composition
        if comp is not None:
            tau = comp.usable_by_area
            text = (f"{certified}/{n} funnel cells certified, composition {'proved' if comp.ok else 'FAILS'}, "
                    f"{100 * comp.coverage_free:.1f}% of the free space covered ({100 * comp.coverage:.1f}% of it "
                    f"away from the walls), a position error of {comp.plan_tolerance:.3g} tolerated everywhere "
                    f"({tau['median']:.3g} at the median point, under {tau['p10']:.3g} on 10% of the area), "
                    f"worst-case time to goal {duration_text(comp.time_bound)}")  # fmt: skip
            if self.rollouts is not None and len(self.rollouts):
                d = self.in_domain
                ok = self.rollouts.outcome == Outcome.SUCCESS
                text += f"; from the certified area {int(ok[d].sum())}/{int(d.sum())} reached the goal"
                text += f", from outside it (uncertified) {int(ok[~d].sum())}/{int((~d).sum())}"
                if self.breaches is not None:
                    text += f", {int(self.breaches.sum())} left the certified area"
            return text + self._unreached_text() + ("; FAILED" if self.failed else "")
        text = f"{certified}/{n} cells certified, coverage {'ok' if self.geometry.coverage_ok else 'FAILS'}"
        if self.rollouts is not None:
            counts = self.outcome_counts
            others = ", ".join(f"{k} {v}" for k, v in counts.items() if k != "success" and v)
            text += f", {counts['success']}/{len(self.rollouts)} runs reached the goal"
            text += f" ({others})" if others else ""
            if len(self.rollouts) and self.approach_fraction > 0:
                text += f"; {self.approach_fraction:.0%} started or relocated outside every safe set"
        return text + self._unreached_text() + ("; FAILED" if self.failed else "")

    def _unreached_text(self) -> str:
        u = self.unreached
        if u is None or not u.parts or u.free_area <= 0:
            return ""
        return f"; {u.area / u.free_area:.1%} of the free space never reached by the tree (no starts there)"

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (non-finite numbers become ``null``)."""
        cert = self.certificates
        status_counts = {s.name.lower(): int(np.count_nonzero(self.status == s)) for s in CellStatus}
        g = self.geometry
        out: dict[str, Any] = {
            "failed": self.failed,
            "reasons": self.reasons,
            "summary": self.summary(),
            "cells": {
                "count": len(self.status),
                "status_counts": status_counts,
                "uncertified": self.uncertified,
                "false_certificates": {str(c): why for c, why in sorted(self.false_certificates.items())},
                "max_violation_certified": _finite_or_none(
                    [np.max(cert.violation[np.isin(self.status, CERTIFIED)], initial=0.0)]
                )[0],
                "flagged": self.flagged,
                "per_cell": {
                    "status": self.status.tolist(),
                    "cbf_value": _finite_or_none(cert.value_h),
                    "clf_value": _finite_or_none(cert.value_v),
                    "input_value": _finite_or_none(cert.value_u),
                    "violation": _finite_or_none(cert.violation),
                    "margin_error": _finite_or_none(cert.margin_error),
                    "c_h_tilde": _finite_or_none(self.c_h_tilde),
                    "c_v_tilde": _finite_or_none(self.c_v_tilde),
                    "c_h_over_s_max": _finite_or_none(self.c_h_over_s_max),
                },
            },
            "geometry": {
                "uncovered_area": g.uncovered_area,
                "coverage_ok": g.coverage_ok,
                "cells_outside_bounds": list(g.cells_outside_bounds),
                "edges_outside_cell": list(g.edges_outside_cell),
                "bad_barriers": list(g.bad_barriers),
                "rows_not_polygon": list(g.rows_not_polygon),
                "blocked_edges": list(g.blocked_edges),
                "samples_unchanged": g.samples_unchanged,
            },
        }
        mc: dict[str, Any] = {"n_starts": len(self.starts), "skipped": self.skipped}
        if self.rollouts is not None:
            mc.update(
                success_rate=_finite_or_none([self.success_rate])[0],
                outcomes=self.outcome_counts,
                left_cell_events=self.left_cell_total,
                left_cell_run_fraction=_finite_or_none([self.left_cell_fraction])[0],
                approach_run_fraction=_finite_or_none([self.approach_fraction])[0],
                path_over_straight=_finite_or_none([self.ratio_straight])[0],
                path_over_route=_finite_or_none([self.ratio_route])[0],
                dt=self.rollouts.dt,
                speed=self.rollouts.speed,
                min_success=self.min_success,
            )
        if self.rollouts is not None:
            mc.update(runs_from_domain=int(self.in_domain.sum()),
                      success_rate_in_domain=_finite_or_none([self.success_in_domain])[0],
                      success_rate_outside_domain=_finite_or_none([self.success_outside_domain])[0],
                      certified_step_fraction=self.rollouts.certified_fraction,
                      breaches=None if self.breaches is None else int(self.breaches.sum()))  # fmt: skip
        out["monte_carlo"] = mc
        if self.composition is not None:
            comp = self.composition
            out["composition"] = {
                "proved": comp.ok, "failures": comp.failures, "problems": comp.problems,
                "coverage": comp.coverage, "coverage_free": comp.coverage_free,
                "stored_coverage": comp.stored_coverage,
                "plan_tolerance": _finite_or_none([comp.plan_tolerance])[0],
                "usable_tolerance_by_area": comp.usable_by_area,
                "time_bound_s": _finite_or_none([comp.time_bound])[0], "speed": comp.speed,
            }  # fmt: skip
        if self.world_cells is not None:
            out["world_cells"] = self.world_cells
        if self.unreached is not None:
            u = self.unreached
            out["unreached"] = {"area": u.area, "free_area": u.free_area,
                                "parts": [{"point": [x, y], "area": a} for x, y, a in u.parts]}  # fmt: skip
        if self.liveness is not None:
            out["liveness"] = self.liveness.to_json()
        out["notes"] = self.notes
        return out


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
        problems.append(f"lookahead: the plan's λ = {built:g} differs from its map's robot.lookahead "
                        f"{map_.lookahead:g} (the cells were built for another robot)")  # fmt: skip
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
            problems.append(f"obstacles: the plan's obstacles do not contain the raw obstacles inflated by ρ + λ = "
                            f"{radius:g} ({missing.area:.3g} map units² missing; a free point lies {gap:.6g} from a "
                            f"raw obstacle)")  # fmt: skip
    return problems


def _liveness(plan: Plan, params: Params, speed: float) -> tuple[Liveness | None, str | None]:
    """The liveness report :class:`Params` asks for, at the loop's speed, or why there is none (a note)."""
    if params.live_fov is None:
        return None, None
    if not plan.cells.is_funnel:
        return None, "liveness: not measured, a paper plan has no usable position tolerance"
    names = {"eta_deg": "bearing_error_deg", "fov_deg": "live_fov", "kappa": "slip", "resolution": "live_resolution"}
    try:
        return measure_liveness(plan, params.bearing_error_deg, params.live_fov, kappa=params.slip, speed=speed,
                                resolution=params.live_resolution), None  # fmt: skip
    except InvalidParamsError as exc:  # a value only the map can refuse (the grid against D): the user's option
        if exc.field in names:
            raise InvalidParamsError(exc.reason, field=names[exc.field]) from None
        return None, f"liveness: not measured, {exc.field}: {exc.reason}"


def duration_text(seconds: float) -> str:
    """``"≤ 1.387e+04 s (3.9 h)"``: a time bound in seconds, and in minutes or hours when it is long."""
    if not math.isfinite(seconds):
        return "unbounded"
    text = f"≤ {seconds:.4g} s"
    if seconds >= 3600:
        return text + f" ({seconds / 3600:.2g} h)"
    if seconds >= 120:
        return text + f" ({seconds / 60:.2g} min)"
    return text


def guarantee(plan: Plan, report: VerifyReport) -> str:
    """One sentence for a robotics engineer: what ``report`` proves of ``plan``, what it only measured, what it leaves.

    Proven: from which starts (``D``), for which robot (radius, single integrator or look-ahead
    point), under which position error (``τ_c``), and the worst-case time. Measured only: the
    closed-loop runs and liveness. Not covered: starts outside ``D``, errors beyond the robot
    section's bounds, a camera that sees fewer than two tags.

    Parameters
    ----------
    plan : Plan
        The plan verified.
    report : VerifyReport
        What :func:`run` found.

    Returns
    -------
    str
    """
    comp = report.composition
    if report.failed:
        return "guarantee: none, the plan fails verification (above)"
    runs = report.rollouts
    measured = (f"measured only: {plural(len(runs), 'closed-loop run')} with exact positions (`bearnav simulate` adds "
                "a camera and noise)") if runs is not None and len(runs) else "nothing measured (no runs)"  # fmt: skip
    if comp is None:  # a paper plan: per-cell certificates (§4), no composition theorem
        return f"guarantee: {composition.PAPER_CLAIM}; {measured}"
    robot = runtime.robot.robot_parameters(plan.map.robot)
    who = composition.robot_words(plan.map)
    if plan.map.lookahead <= 0:
        who += " (a single integrator; a unicycle only through `bearnav plan --lookahead`)"
    tol = comp.usable_by_area
    eta = float(robot["bearing_error_deg"]) + float(robot["compass_error_deg"] or 0.0)
    if report.liveness is not None:
        measured += (f", and at η = {math.degrees(report.liveness.grid.eta):.3g}°: "
                     f"{report.liveness.live_fraction:.0%} of the certified area where a look all around is sure to "
                     "be good enough (on a grid)")  # fmt: skip
    proven = (f"proven from the plan file, {who} that starts in the certified area ({percent(comp.coverage_free)} of "
              f"the free space) and knows its position to within what the cell it is in tolerates (at least "
              f"{comp.plan_tolerance:.3g} map units, {tol['median']:.3g} at the median point) reaches the goal "
              f"without touching an obstacle or a wall, at speed {comp.speed:g} map units/s in "
              f"{duration_text(comp.time_bound)} (a worst case, from the least progress each cell's certificate "
              "guarantees, not an estimate of a run's time)")  # fmt: skip
    bounded = (f"with bearings erring by at most η = {eta:g}° and wheel slip within {robot['slip']:g} of each step "
               "(the map's robot section) the `simulate --estimator set` robot moves only where it knows that much, "
               "and never gets stuck where a look all around is good enough (`--live-fov F` measures where; "
               "`bearnav tags --for live` adds tags until it is everywhere)")  # fmt: skip
    uncovered = ("not covered: starts outside the certified area, errors beyond those bounds, places where the camera "
                 "sees fewer than two tags (`bearnav verify --fov F` measures them)")  # fmt: skip
    return f"guarantee: {proven}; {bounded}; {measured}; {uncovered}"


def run(
    plan: Plan,
    params: Params = Params(),
    tree_samples: np.ndarray | None = None,
    progress: Callable[[int, int], None] | None = None,
    world: Map | None = None,
) -> VerifyReport:
    """Verify a plan: certificates, geometry and the Monte-Carlo closed loop (ALGORITHMS §8).

    Parameters
    ----------
    plan : Plan
        The plan to verify (``plan.npz``, with its embedded map).
    params : Params
        The Monte-Carlo check: number of starts, seed, the loop's speed, ``dt`` and dynamics, and
        ``min_success``.
    tree_samples : ndarray, shape (S, 2), optional
        ``collision_samples`` of the ``tree.npz`` the plan came from, to check they survived.
    world : Map, optional
        Another map in the same frame: (C1) is re-checked against its obstacles and the cells
        that no longer hold are listed (paper B's deformation question, answered exactly).
    progress : callable, optional
        ``progress(finished_runs, n_starts)`` during the Monte-Carlo runs.

    Returns
    -------
    VerifyReport
    """
    cells = plan.cells
    cert = certificates(plan)
    problems = certificate_problems(plan, cert)
    with np.errstate(divide="ignore", invalid="ignore"):
        c_h_tilde = np.where(cells.s_min > 0, plan.c_h / cells.s_min, np.where(np.isnan(plan.c_h), np.nan, np.inf))
        c_v_tilde = plan.c_v / cells.s_max
        c_h_smax = plan.c_h / cells.s_max
    space = FreeSpace.from_map(plan.map)
    geometry = check_geometry(plan, space, tree_samples)
    speed = loop_speed(plan, params)
    comp = composition.check(plan, speed, space) if plan.cells.is_funnel else None
    world_cells = None
    if world is not None:
        problem = composition.map_frame_problem(plan.map, world)
        if problem is not None:
            raise InvalidParamsError(problem, field="world")
        world_cells = composition.world_violations(plan, FreeSpace.from_map(world))

    unreached = unreached_regions(plan, space, comp.regions if comp is not None else None)
    live, live_note = _liveness(plan, params, speed)
    starts = np.zeros((0, 2))
    rollouts, skipped, breaches = None, None, None
    if params.n_starts == 0:
        skipped = "n_starts is 0"
    else:
        try:
            arrays = PlanArrays.from_plan(plan)
        except ArtifactError as exc:
            skipped = f"malformed plan, no closed loop: {exc}"
        if skipped is None:
            rng = np.random.default_rng(params.seed)
            starts = _reached_starts(space, plan.map.goal, params.n_starts, rng, unreached.avoid)
            # the certificates are stated for the displacement output and the exact motion of §7.1:
            # bearings and wheel slip are `bearnav simulate`'s job
            sim = simulate.Params(speed=speed, alpha=speed, dt=params.dt, measurement="displacement",
                                  odometry_noise=0.0, dynamics=params.dynamics, certified_heading=True,
                                  record_trajectories=False)  # fmt: skip
            breach = np.zeros(len(starts), bool)
            # the unicycle without a look-ahead is outside the certificate: no step of it is certified
            steps_certified = params.dynamics != "unicycle" or arrays.lookahead > 0

            def watch(runs: np.ndarray, x: np.ndarray, certified: np.ndarray) -> None:
                if arrays.funnel:  # a step not certified, or a true position (p) outside every cell of D
                    uncertified = ~certified if steps_certified else np.zeros(len(runs), bool)
                    breach[runs] |= uncertified | (runtime.least_rank_cell(arrays, x) < 0)

            rollouts = simulate.rollout(plan, starts, sim, progress=progress, on_step=watch, arrays=arrays, space=space)
            breaches = breach & rollouts.start_in_domain
    straight = np.hypot(*(starts - plan.map.goal).T) if len(starts) else np.zeros(0)
    route = route_lengths(space, plan.map.goal, starts) if len(starts) else np.zeros(0)
    uncovered = None
    if params.dynamics == "unicycle" and plan.map.lookahead <= 0 and params.n_starts > 0:
        uncovered = ("the unicycle on a plan without a look-ahead (λ = 0) is outside the certificate: its steps count "
                     "as uncertified, and a breach is only a true position outside D; plan with `--lookahead L`, "
                     "L at least the speed over the turn rate, to drive it inside")  # fmt: skip
    report = VerifyReport(
        status=np.asarray(plan.status),
        certificates=cert,
        false_certificates=problems,
        c_h_tilde=c_h_tilde,
        c_v_tilde=c_v_tilde,
        c_h_over_s_max=c_h_smax,
        flagged=flagged_cells(plan),
        geometry=geometry,
        starts=starts,
        rollouts=rollouts,
        straight=straight,
        route=route,
        min_success=params.min_success,
        skipped=skipped,
        goal=np.asarray(plan.map.goal, float),
        composition=comp,
        world_cells=world_cells,
        unreached=unreached,
        breaches=breaches,
        lookahead_problems=tuple(check_lookahead(plan, space)),
        uncovered_dynamics=uncovered,
        liveness=live,
        liveness_note=live_note,
    )
    log.info("verify: %s", report.summary())
    return report
