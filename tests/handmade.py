"""Hand-built maps and plans for the runtime, simulate and verify tests.

The plans are made without the decompose and synthesize stages: cells are the
half-plane intersections of ALGORITHMS §4.1 clipped here with a few lines of
numpy, and each cell gets a chosen affine field ``u = a − M x`` realised by the
minimum-norm gain (ALGORITHMS §5.2, Lemma 3).
"""

from __future__ import annotations

import numpy as np

from bearnav_cli import artifacts
from bearnav_cli.datatypes import Cells, CellStatus, Map, Plan, Polygon, replace
from bearnav_cli.runtime.plan_arrays import tree_costs

LANDMARKS = np.array([[0.0, 8.0], [10.0, 0.0], [10.0, 8.0], [5.0, 0.0]])
#: A chain along y = 1: root (goal) at (1, 1), node 1 at (5, 1), node 2 at (9, 1).
CHAIN_NODES = np.array([[1.0, 1.0], [5.0, 1.0], [9.0, 1.0]])
CHAIN_PARENT = np.array([-1, 0, 1])


def hand_map(obstacles=(), bounds=(0.0, 0.0, 10.0, 8.0), goal=(1.0, 1.0), landmarks=LANDMARKS) -> Map:
    """A map with exact polygon obstacles (robot radius 0, so ``O`` is the raw polygons)."""
    polys = tuple(Polygon(np.asarray(o, float)) for o in obstacles)
    return Map(
        name="hand",
        bounds=np.asarray(bounds, float),
        robot_radius=0.0,
        goal=np.asarray(goal, float),
        starts=np.asarray([goal], float),
        landmark_ids=tuple(str(k) for k in range(len(landmarks))),
        landmarks=np.asarray(landmarks, float),
        obstacles=polys,
        raw_obstacles=polys,
    )


def clip(polygon: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Convex CCW polygon ∩ {x : normal·x <= offset}, near-duplicate vertices dropped."""
    side = polygon @ normal - offset
    out = []
    for q in range(len(polygon)):
        r = (q + 1) % len(polygon)
        if side[q] <= 0:
            out.append(polygon[q])
        if (side[q] < 0 < side[r]) or (side[r] < 0 < side[q]):
            out.append(polygon[q] + side[q] / (side[q] - side[r]) * (polygon[r] - polygon[q]))
    keep = [p for k, p in enumerate(out) if np.linalg.norm(p - out[k - 1]) > 1e-7]
    return np.array(keep)


def first_cells(cells: Cells, count: int) -> Cells:
    """The same decomposition with only its first ``count`` cells (a deliberately broken one)."""
    r = cells.cell_row_offsets[count]
    h = cells.cbf_offsets[count]
    return replace(
        cells,
        cell_node=cells.cell_node[:count],
        cell_A=cells.cell_A[:r],
        cell_b=cells.cell_b[:r],
        cell_row_offsets=cells.cell_row_offsets[: count + 1],
        cell_vertices=cells.cell_vertices[:r],
        cell_vertex_offsets=cells.cell_vertex_offsets[: count + 1],
        exit_point=cells.exit_point[:count],
        exit_dir=cells.exit_dir[:count],
        cbf_A=cells.cbf_A[:h],
        cbf_b=cells.cbf_b[:h],
        cbf_offsets=cells.cbf_offsets[: count + 1],
        cell_landmarks=cells.cell_landmarks[:count],
        fixed_landmark=cells.fixed_landmark[:count],
        s_min=cells.s_min[:count],
        s_max=cells.s_max[:count],
        cell_flags=cells.cell_flags[:count],
        cell_exit_row=cells.cell_exit_row[:count],
        cell_rank=cells.cell_rank[:count],
        exit_inset=cells.exit_inset[:count],
    )


def first_plan_cells(plan: Plan, count: int) -> Plan:
    """The same plan with only its first ``count`` cells and their controllers (:func:`first_cells`)."""
    keep = slice(None, count)
    return Plan(
        first_cells(plan.cells, count),
        plan.gain[keep],
        plan.c_h[keep],
        plan.c_v[keep],
        plan.u_max[keep],
        plan.margin_h[keep],
        plan.margin_v[keep],
        plan.status[keep],
        plan.goal_tolerance,
        plan.tolerance[keep],
        plan.usable_tolerance[keep],
        plan.plan_tolerance,
    )


def cell_polygons(nodes: np.ndarray, parent: np.ndarray, bounds: np.ndarray) -> list[np.ndarray]:
    """The cells of ALGORITHMS §4.1 (crossing rule) and §4.3, one CCW polygon per node."""
    xmin, ymin, xmax, ymax = bounds
    box = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]], float)
    out = []
    for i, xi in enumerate(nodes):
        poly = box
        j = parent[i]
        for k, xk in enumerate(nodes):
            if k == i or k == j:
                continue
            if j >= 0 and np.linalg.norm(nodes[j] - xk) <= np.linalg.norm(nodes[j] - xi):
                continue  # the bisector crosses the edge
            n = (xk - xi) / np.linalg.norm(xk - xi)
            poly = clip(poly, n, n @ xi + 0.5 * np.linalg.norm(xk - xi))
        if j >= 0:
            z = (xi - nodes[j]) / np.linalg.norm(xi - nodes[j])
            poly = clip(poly, -z, -(z @ nodes[j]))
        out.append(poly)
    return out


def rows_of(polygon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals and offsets, row q for edge v_q → v_{q+1}."""
    edge = np.roll(polygon, -1, axis=0) - polygon
    normal = np.column_stack([edge[:, 1], -edge[:, 0]])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    return normal, np.einsum("ij,ij->i", normal, polygon)


def gain_for(landmarks: np.ndarray, M: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The minimum-norm gain K (2, 2L) with ``Σ K_k = M`` and ``Σ K_k l_k = a``."""
    G = np.column_stack([np.tile(np.eye(2), (len(landmarks), 1)), landmarks.ravel()])  # (2L, 3)
    return np.column_stack([M, a]) @ np.linalg.solve(G.T @ G, G.T)


def hand_plan(
    map_: Map,
    nodes: np.ndarray = CHAIN_NODES,
    parent: np.ndarray = CHAIN_PARENT,
    fields: dict | None = None,
    barriers: dict | None = None,
    polygons: list | None = None,
    samples: np.ndarray | None = None,
) -> Plan:
    """A plan over the given tree with chosen fields, certified where the field allows.

    Defaults: an edge cell's field points at its exit point, ``u = k(x_j − x)``, the goal
    cell's at the goal, ``u = c(g − x)``, with ``k``, ``c`` as large as the box ``u_max = 1``
    allows; ``c_v = k/2`` (so the CLF holds with margin 0) and ``c_h = c_v``.
    ``fields[c] = (M, a)`` overrides a cell's field, ``barriers[c] = (normals, offsets)`` adds
    barrier rows. Margins are the vertex values; status 0 (4 for the goal cell) where every
    condition holds, else 2.
    """
    fields = fields or {}
    barriers = barriers or {}
    polygons = polygons if polygons is not None else cell_polygons(nodes, parent, map_.bounds)
    n, lm = len(polygons), map_.landmarks
    gain = np.zeros((n, 2, 2 * len(lm)))
    c_h, c_v, m_h, m_v = (np.full(n, np.nan) for _ in range(4))
    status = np.zeros(n, np.int8)
    exit_point, exit_dir = np.zeros((n, 2)), np.zeros((n, 2))
    cbf_n, cbf_q = [], []
    for c, poly in enumerate(polygons):
        j = parent[c]
        target = nodes[j] if j >= 0 else map_.goal
        k = 1.0 / np.max(np.abs(poly - target))
        M, a = fields.get(c, (k * np.eye(2), k * target))
        gain[c] = gain_for(lm, np.asarray(M, float), np.asarray(a, float))
        u = a - poly @ np.asarray(M, float).T
        c_v[c] = k if j < 0 else k / 2
        ok = np.max(np.abs(u)) <= 1.0 + 1e-12
        if j >= 0:
            exit_point[c] = nodes[j]
            exit_dir[c] = (nodes[c] - nodes[j]) / np.linalg.norm(nodes[c] - nodes[j])
            m_v[c] = np.max(u @ exit_dir[c] + c_v[c] * ((poly - nodes[j]) @ exit_dir[c]))
            ok &= m_v[c] <= 1e-12
        normals, offsets = barriers.get(c, (np.zeros((0, 2)), np.zeros(0)))
        if len(normals):
            c_h[c] = c_v[c]
            m_h[c] = np.max(-(u @ normals.T + c_h[c] * (poly @ normals.T + offsets)))
            ok &= m_h[c] <= 1e-12
        cbf_n.append(np.asarray(normals, float).reshape(-1, 2))
        cbf_q.append(np.asarray(offsets, float).reshape(-1))
        status[c] = CellStatus.GOAL if j < 0 else (CellStatus.CERTIFIED if ok else CellStatus.NOT_CERTIFIED)
    rows = [rows_of(p) for p in polygons]
    counts = np.array([len(p) for p in polygons])
    offsets_v = np.concatenate([[0], np.cumsum(counts)])
    cells = Cells(
        map=map_,
        nodes=nodes,
        parent=parent,
        collision_samples=np.zeros((0, 2)) if samples is None else samples,
        cell_node=np.arange(n),
        cell_A=np.concatenate([r[0] for r in rows]),
        cell_b=np.concatenate([r[1] for r in rows]),
        cell_row_offsets=offsets_v,
        cell_vertices=np.concatenate(polygons),
        cell_vertex_offsets=offsets_v,
        exit_point=exit_point,
        exit_dir=exit_dir,
        cbf_A=np.concatenate(cbf_n),
        cbf_b=np.concatenate(cbf_q),
        cbf_offsets=np.concatenate([[0], np.cumsum([len(q) for q in cbf_q])]),
        cell_landmarks=np.ones((n, len(lm)), bool),
        fixed_landmark=np.zeros(n, np.int64),
        s_min=np.ones(n),
        s_max=np.full(n, 20.0),
        cell_flags=np.zeros(n, np.int64),
        certificate="paper",
        cell_exit_row=np.array(
            [-1 if parent[c] < 0 else paper_exit_row(*rows[c], exit_dir[c], exit_point[c]) for c in range(n)], np.int64
        ),  # fmt: skip
        cell_rank=tree_costs(nodes, parent),
        exit_inset=np.where(parent < 0, np.nan, 0.0),
        node_added=np.zeros(n, bool),
        free_coverage=np.nan,
    )
    return Plan(
        cells=cells,
        gain=gain,
        c_h=c_h,
        c_v=c_v,
        u_max=np.ones(n),
        margin_h=m_h,
        margin_v=m_v,
        status=status,
        goal_tolerance=0.01 * map_.diagonal,
        tolerance=np.full(n, np.nan),
        usable_tolerance=np.full(n, np.nan),
        plan_tolerance=np.nan,
    )


def paper_exit_row(A: np.ndarray, b: np.ndarray, z: np.ndarray, x_j: np.ndarray) -> int:
    """The row of a §4 cell on the exit line: normal ``−z`` through ``x_j``."""
    return int(np.argmax(A @ -z - np.abs(A @ x_j - b)))


def write_plan(path, plan: Plan):
    """Save ``plan`` as ``plan.npz`` at ``path`` with a manifest and its content hash (what a robot loads)."""
    manifest = artifacts.make_manifest(
        "plan",
        plan,
        stage="synthesize",
        stage_version=1,
        params={},
        input_path=None,
        input_hash="0",
        summary="",
        elapsed_s=0.0,
    )
    return artifacts.save(path, plan, manifest)
