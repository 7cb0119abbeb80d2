"""Properties of the decomposition (ALGORITHMS §4, §5.4–5.5)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from bearnav_cli import barriers, cell_landmarks, geometry, pipeline
from bearnav_cli.datatypes import CellFlag, Tree
from bearnav_cli.errors import ArtifactError, InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.stages import decompose

from .conftest import SMALL_MAP, build_map


@pytest.fixture(scope="module")
def small_map():
    return build_map(dict(SMALL_MAP))


PAPER = decompose.Params(cells="paper")


@pytest.fixture(scope="module")
def simplified(small_map):
    overrides = {"rrtstar": {"iterations": 600, "seed": 2}}
    return pipeline.compute(small_map, through="simplify", overrides=overrides)["simplified"]


@pytest.fixture(scope="module")
def cells(simplified):
    return decompose.run(simplified)


@pytest.fixture(scope="module")
def wedge_cells(simplified):
    return decompose.run(simplified, decompose.Params(cells="paper", barrier="wedge"))


def random_tree(small_map, seed: int, n: int = 25) -> Tree:
    """A random tree on the small map's bounds (edges need not be free: the cells do not care)."""
    rng = np.random.default_rng(seed)
    nodes = np.vstack([small_map.goal, rng.uniform([0.2, 0.2], [9.8, 7.8], size=(n - 1, 2))])
    parent = np.array([-1] + [int(rng.integers(0, i)) for i in range(1, n)])
    cost = np.zeros(n)
    for i in range(1, n):
        cost[i] = cost[parent[i]] + np.hypot(*(nodes[i] - nodes[parent[i]]))
    samples = rng.uniform([0, 0], [10, 8], size=(40, 2))
    return Tree(small_map, nodes, parent, cost, samples)


def test_cells_are_convex_ccw_with_aligned_unit_rows(cells):
    tol = cells.map.tol
    for c in range(cells.n_cells):
        v = cells.vertices(c)
        A, b = cells.rows(c)
        assert len(v) >= 3
        poly = shapely.Polygon(v)
        assert poly.is_valid and poly.area > 0 and poly.exterior.is_ccw
        assert shapely.equals_exact(poly, shapely.convex_hull(poly).normalize(), 1e-9) or np.isclose(
            poly.area, shapely.convex_hull(poly).area
        )
        np.testing.assert_allclose(np.hypot(A[:, 0], A[:, 1]), 1.0, atol=1e-12)
        assert np.all(v @ A.T <= b + tol)
        # row q is the outward normal of edge q: both ends of edge q lie on its line
        nxt = np.roll(v, -1, axis=0)
        np.testing.assert_allclose(np.einsum("ij,ij->i", A, v), b, atol=1e-9)
        np.testing.assert_allclose(np.einsum("ij,ij->i", A, nxt), b, atol=1e-9)
        assert np.all(np.einsum("ij,ij->i", A, v.mean(axis=0) - v) < 0)  # outward


def test_edge_in_its_cell_and_exit_face_has_length(cells):
    tol = cells.map.tol
    for c in range(1, cells.n_cells):
        A, b = cells.rows(c)
        xi, xj = cells.nodes[c], cells.nodes[cells.parent[c]]
        assert np.all(A @ xi <= b + tol) and np.all(A @ xj <= b + tol)
        z = cells.exit_dir[c]
        np.testing.assert_allclose(z, (xi - xj) / np.hypot(*(xi - xj)))
        np.testing.assert_array_equal(cells.exit_point[c], xj)
        v = cells.vertices(c)
        face = v[np.abs((v - xj) @ z) <= 1e-9]
        assert len(face) >= 2 and np.ptp(face @ np.array([-z[1], z[0]])) > 0


@pytest.mark.parametrize("seed", range(4))
def test_cells_cover_the_bounds_and_contain_voronoi_cells(small_map, seed):
    tree = random_tree(small_map, seed)
    cells = decompose.run(tree, PAPER)
    box = shapely.box(*small_map.free_bounds)  # the robot radius applies to the bounds (ALGORITHMS §11.1)
    union = shapely.union_all([shapely.Polygon(cells.vertices(c)) for c in range(cells.n_cells)])
    assert shapely.difference(box, union).area <= 1e-9 * box.area
    assert shapely.difference(union, box).area <= 1e-9 * box.area
    # every point of a fine grid lies in the cell of its nearest node (Lemma 2)
    xs, ys = np.meshgrid(np.linspace(0.2, 9.8, 81), np.linspace(0.2, 7.8, 65))
    grid = np.column_stack([xs.ravel(), ys.ravel()])
    owner = np.argmin(np.hypot(*(grid[:, None, :] - tree.nodes[None]).transpose(2, 0, 1)), axis=1)
    for c in np.unique(owner):
        A, b = cells.rows(c)
        pts = grid[owner == c]
        assert np.all(pts @ A.T <= b + 1e-9), f"Voronoi points of node {c} outside its cell"


def test_cbf_rows_are_unit_wedges_that_exclude_samples(wedge_cells):
    cells = wedge_cells
    tol = cells.map.tol
    samples = cells.collision_samples
    for c in range(1, cells.n_cells):
        n, q = cells.barrier(c)
        if len(n) == 0:
            continue
        xi, xj = cells.nodes[c], cells.nodes[cells.parent[c]]
        np.testing.assert_allclose(np.hypot(n[:, 0], n[:, 1]), 1.0, atol=1e-12)
        np.testing.assert_allclose(n @ xi + q, 0.0, atol=1e-9)  # apex at the child
        assert np.all(n @ xj + q > 0)
        # no sample of the filtered set lies in the open wedge
        A, b = cells.rows(c)
        e = xj - xi
        t = (samples - xi) @ e / (e @ e)
        considered = samples[(t >= 0) & (t <= 1) & np.all(samples @ A.T <= b + tol, axis=1)]
        inside = np.all(considered @ n.T + q > tol, axis=1)
        assert not inside.any()


def safe_polygon(cells, c: int) -> shapely.Polygon:
    """The cell clipped by every barrier row, exactly (shapely)."""
    n, q = cells.barrier(c)
    poly = shapely.Polygon(cells.vertices(c))
    big = 10 * cells.map.diagonal
    for normal, offset in zip(n, q, strict=True):
        # {h >= 0} as a huge polygon: the side of the line n·x + q = 0 that n points to
        foot = -offset * normal
        along = np.array([-normal[1], normal[0]]) * big
        half = shapely.Polygon([foot - along, foot + along, foot + along + big * normal, foot - along + big * normal])
        poly = shapely.intersection(poly, half)
    return poly


def test_corridor_safe_sets_keep_the_margin_from_every_obstacle(cells, small_map):
    """Every cell's safe set (cell ∩ barrier half-planes) contains its tree edge (or the goal) and
    stays at least min(margin, s·d) away from the inflated obstacles and the walls (exact check;
    ``s = funnel.ROW_SHARE``, ALGORITHMS §11.5 has 1/2, docs/algorithms.md says why a twentieth)."""
    from bearnav_cli.funnel import ROW_SHARE

    space = FreeSpace.from_map(small_map)
    margin = 0.01 * small_map.diagonal
    walls = shapely.difference(shapely.box(*small_map.bounds).buffer(1.0), shapely.box(*small_map.bounds))
    checked = 0
    for c in range(cells.n_cells):
        n, q = cells.barrier(c)
        np.testing.assert_allclose(np.hypot(n[:, 0], n[:, 1]), 1.0, atol=1e-12)
        ends = np.array([small_map.goal]) if c == 0 else cells.nodes[[c, cells.parent[c]]]
        assert np.all(ends @ n.T + q > 0)  # the edge is strictly inside every row
        safe = safe_polygon(cells, c)
        assert not safe.is_empty
        segment = shapely.LineString(ends) if len(ends) == 2 else shapely.Point(ends[0])
        # the rows may only be moved by a share of the segment's own distance from an obstacle
        room = min(margin, ROW_SHARE * shapely.distance(segment, space.obstacles))
        assert shapely.distance(safe, space.obstacles) >= room - 1e-9
        if c > 0:
            assert shapely.distance(safe, walls) >= min(margin, ROW_SHARE * shapely.distance(segment, walls)) - 1e-9
        checked += len(n) > 0
    assert checked > cells.n_cells // 2


def test_corridor_rows_keep_each_obstacle_piece_behind_its_own_row():
    """Separating half-planes: a row per convex piece, with the whole piece at h <= level = −m
    and the segment at h >= d − m, so a robot whose h never decreases cannot reach the piece."""
    square = shapely.box(4.0, 1.0, 6.0, 3.0)
    ell = shapely.union(shapely.box(2.0, -4.0, 8.0, -3.0), shapely.box(7.0, -4.0, 8.0, 3.5))  # wraps the edge
    obstacles = shapely.union(square, ell)
    polygon = geometry.box_polygon(np.array([0.0, -6.0, 10.0, 6.0]))
    ends = np.array([[1.0, 0.0], [6.5, 0.0]])
    n, q, level = barriers.corridor_rows(ends, polygon, obstacles, margin=0.25)
    assert len(n) >= 3  # the L is not convex around the edge: split into triangles
    np.testing.assert_allclose(np.hypot(n[:, 0], n[:, 1]), 1.0, atol=1e-12)
    np.testing.assert_allclose(level, -0.25)
    assert np.all(ends @ n.T + q >= 0.25)
    # every obstacle vertex is behind at least one row at its level, and inside no safe point
    pts = shapely.get_coordinates(obstacles)
    assert np.all(np.min(pts @ n.T + q - level, axis=1) <= 1e-12)
    grid = np.stack(np.meshgrid(np.linspace(0, 10, 101), np.linspace(-6, 6, 121)), -1).reshape(-1, 2)
    safe = np.all(grid @ n.T + q >= 0, axis=1)
    assert not shapely.intersects_xy(obstacles.buffer(0.25 - 1e-9), grid[safe, 0], grid[safe, 1]).any()
    # edges that touch the segment cannot be separated: they get no row (and a warning); the
    # box's far edge still does, and every row still holds the segment
    n2, q2, _ = barriers.corridor_rows(ends, polygon, shapely.box(3.0, -0.5, 3.5, 0.0), margin=0.25)
    assert len(n2) == 1 and np.all(ends @ n2.T + q2 > 0)


def test_smallest_angle_not_smallest_distance():
    # ALGORITHMS §4.5: o1 is nearer the edge line, o2 makes the smaller angle
    child, parent = np.array([0.0, 0.0]), np.array([10.0, 0.0])
    samples = np.array([[1.0, 0.5], [9.0, 0.9]])
    A, b = geometry.polygon_rows(geometry.box_polygon(np.array([-1.0, -5.0, 11.0, 5.0])))
    n, q, _ = barriers.cbf_rows(child, parent, samples, A, b, 1e-12)
    assert len(n) == 1
    h = samples @ n[0] + q[0]
    assert h[1] == pytest.approx(0.0, abs=1e-12) and h[0] < 0  # o2 on the line, o1 outside the wedge


def test_a_side_without_samples_gets_no_row_and_edge_samples_are_skipped():
    child, parent = np.array([0.0, 0.0]), np.array([10.0, 0.0])
    A, b = geometry.polygon_rows(geometry.box_polygon(np.array([-1.0, -5.0, 11.0, 5.0])))
    n, _, on_edge = barriers.cbf_rows(child, parent, np.array([[5.0, 2.0], [5.0, 0.0]]), A, b, 1e-12)
    assert len(n) == 1 and n[0][1] < 0 and on_edge


def test_parent_apex_passes_through_the_parent():
    child, parent = np.array([0.0, 0.0]), np.array([10.0, 0.0])
    A, b = geometry.polygon_rows(geometry.box_polygon(np.array([-1.0, -5.0, 11.0, 5.0])))
    n, q, _ = barriers.cbf_rows(child, parent, np.array([[5.0, 2.0], [5.0, -3.0]]), A, b, 1e-12, apex="parent")
    np.testing.assert_allclose(n @ parent + q, 0.0, atol=1e-12)
    assert np.all(n @ child + q > 0)


def test_goal_cell_rows(small_map):
    tree = random_tree(small_map, 7)
    goal_poly = decompose.goal_cell(tree.nodes, small_map.bounds, small_map.tol)
    border = np.array([[0.0, 0.3], [0.4, 0.0]])
    samples = np.vstack([tree.collision_samples, border, goal_poly.mean(axis=0) + [0.3, 0.2]])
    n, q = barriers.goal_cbf_rows(small_map.goal, samples, goal_poly, small_map.bounds, small_map.tol)
    assert len(n) >= 1
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 8, size=(50, 2))
    c = 0.7
    g = small_map.goal
    for nk, qk in zip(n, q, strict=True):
        h = x @ nk + qk
        hdot = (c * (g - x)) @ nk
        # ḣ + c·h = c·‖g − o‖ = c·h(g) everywhere (ALGORITHMS §4.6)
        np.testing.assert_allclose(hdot + c * h, c * (nk @ g + qk), atol=1e-9)
        assert nk @ g + qk > 0 and np.hypot(*nk) == pytest.approx(1.0)
        o = samples[np.argmin(np.abs(samples @ nk + qk))]
        assert nk @ g + qk == pytest.approx(np.hypot(*(g - o)))
    # no border sample produces a row: a border sample's row would pass through it
    for s in border:
        assert not np.any(np.abs(n @ s + q) <= 1e-9)


def test_landmark_choice_and_fixed_landmark_rules():
    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    # a landmark inside the cell is never fixed while another qualifies
    landmarks = np.array([[1.0, 1.0], [5.0, 1.0], [1.0, 6.0]])
    f, s_min, s_max, flag = cell_landmarks.fixed_landmark(landmarks, np.array([0, 1, 2]), square, 1e-12)
    assert f != 0 and s_min > 0
    # the line through l_f and l_k must miss the cell: (5,1) and (-3,1) line crosses the square
    landmarks = np.array([[5.0, 1.0], [-3.0, 1.0], [1.0, 7.0]])
    f, s_min, s_max, flag = cell_landmarks.fixed_landmark(landmarks, np.array([0, 1]), square, 1e-12)
    assert flag == CellFlag.DEGENERATE_RISK
    f, s_min, s_max, flag = cell_landmarks.fixed_landmark(landmarks, np.array([0, 2]), square, 1e-12)
    assert flag == CellFlag.NONE
    # s_min attained inside an edge, not at a vertex
    assert f in (0, 2)
    assert s_min == pytest.approx(3.0 if f == 0 else 5.0)
    # every candidate inside: s_min = 0 and the flag says so
    f, s_min, s_max, flag = cell_landmarks.fixed_landmark(
        np.array([[0.5, 0.5], [1.5, 1.5]]), np.array([0, 1]), square, 1e-12
    )
    assert s_min == 0.0 and flag == CellFlag.LANDMARK_INSIDE


def test_fixed_landmark_is_outside_its_cell(cells):
    for c in range(cells.n_cells):
        if cells.cell_flags[c] & CellFlag.LANDMARK_INSIDE:
            continue
        poly = shapely.Polygon(cells.vertices(c))
        lf = cells.map.landmarks[cells.fixed_landmark[c]]
        assert cells.s_min[c] > 0
        assert cells.s_min[c] == pytest.approx(poly.distance(shapely.Point(lf)), abs=1e-9)
        assert cells.s_max[c] == pytest.approx(shapely.hausdorff_distance(shapely.Point(lf), poly), rel=1e-9)
        assert cells.cell_landmarks[c, cells.fixed_landmark[c]]


def test_cell_landmarks_are_visible_from_the_free_part(cells):
    space = FreeSpace.from_map(cells.map)
    for c in range(cells.n_cells):
        used = np.flatnonzero(cells.cell_landmarks[c])
        assert 2 <= len(used) <= 4
        if cells.cell_flags[c] & CellFlag.FEW_LANDMARKS:
            continue
        free = shapely.difference(shapely.Polygon(cells.vertices(c)), space.obstacles)
        pts = np.concatenate([np.asarray(p.exterior.coords) for p in shapely.get_parts(free)])
        for k in used:
            assert space.visible(pts, cells.map.landmarks[k], from_boundary=True).all()


def test_coincident_nodes_and_bad_params(small_map):
    tree = random_tree(small_map, 1, n=5)
    nodes = tree.nodes.copy()
    nodes[3] = nodes[2]
    with pytest.raises(ArtifactError):
        decompose.run(Tree(small_map, nodes, tree.parent, tree.cost, tree.collision_samples))
    for kwargs, field in (({"n_landmarks": 1}, "n_landmarks"), ({"cbf_apex": "middle"}, "cbf_apex")):
        with pytest.raises(InvalidParamsError) as info:
            decompose.Params(**kwargs)
        assert info.value.field == field


def test_single_node_tree_gives_the_goal_cell_over_the_bounds(small_map):
    tree = Tree(small_map, small_map.goal[None], [-1], [0.0], np.zeros((0, 2)))
    cells = decompose.run(tree, PAPER)
    assert cells.n_cells == 1
    assert shapely.Polygon(cells.vertices(0)).area == pytest.approx(9.6 * 7.6)  # B_r


def test_a_tree_edge_that_is_not_free_is_refused_by_funnel_cells(small_map):
    tree = random_tree(small_map, 0)  # random edges cross the obstacles
    with pytest.raises(ArtifactError, match="not free"):
        decompose.run(tree)


def test_same_tree_same_cells(small_map):
    tree = random_tree(small_map, 3)
    a, b = decompose.run(tree, PAPER), decompose.run(tree, PAPER)
    for key, value in a.arrays().items():
        np.testing.assert_array_equal(value, b.arrays()[key])


def test_one_free_space_per_content_and_its_results_are_a_fresh_computation():
    """``FreeSpace.from_map`` gives the same space for another map object of the same content (as each stage of a
    plan reads the map back from the previous artifact) and another for other obstacles; its kept visibility
    regions and coverage grid equal a fresh build's."""
    from bearnav_cli.datatypes import replace

    map_ = build_map(SMALL_MAP)
    copy = replace(map_, params=dict(map_.params))
    assert copy is not map_ and FreeSpace.from_map(copy) is FreeSpace.from_map(map_)
    moved = replace(
        map_,
        obstacles=tuple(geometry.from_shapely(shapely.affinity.translate(geometry.to_shapely(map_.obstacles[0]), 0.01)))
        + tuple(map_.obstacles[1:]),
    )
    assert FreeSpace.from_map(moved) is not FreeSpace.from_map(map_)
    space, fresh = FreeSpace.from_map(map_), FreeSpace._build(map_)
    for first, second in zip(
        space.visibility_regions(map_.landmarks), fresh.visibility_regions(map_.landmarks), strict=True
    ):
        assert shapely.equals_exact(first, second, 0.0)
    points, counts = geometry.landmark_coverage(map_, space)
    counts[:] = -1  # a caller's edit of what it got does not reach what the space keeps
    points_fresh, counts_fresh = geometry.landmark_coverage(map_, fresh)
    again_points, again_counts = geometry.landmark_coverage(map_, space)
    assert np.array_equal(again_points, points_fresh) and np.array_equal(again_counts, counts_fresh)
