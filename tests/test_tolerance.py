"""Usable tolerances (ALGORITHMS §12.3–§12.4, ``bearnav.plan/3``): Lemma 6's sink, per-cell insets, τ_c.

Properties, not numbers from a run: the sink is the exact maximiser of the side depth along the
exit face (brute force agrees), Lemma 6's field meets (L1)–(L3) with the margins the lemma states
on random convex cells, the synthesis never tolerates less than that field, every stored τ_c is
finite, positive and within ``min(δ_c, δ_e,c/2)``, a constant field's ``δ_c = +inf`` is stored
and τ_c stays finite, and a tampered plan fails ``verify`` in that cell only.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import pytest
import shapely

from bearnav_cli import artifacts, composition, funnel, verify
from bearnav_cli.datatypes import CellStatus
from bearnav_cli.errors import ArtifactError
from bearnav_cli.funnel import cell_tolerance, exit_face, exit_sink, usable_tolerances
from bearnav_cli.geometry import polygon_rows
from bearnav_cli.runtime.certificate import field_margins
from tests.conftest import random_plan
from tests.handmade import write_plan

SEEDS = range(6)


def random_cell(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A random convex cell with an exit face on one edge: ``(vertices, z, x_j, face)``."""
    points = rng.uniform(-1.0, 1.0, (int(rng.integers(5, 12)), 2)) * rng.uniform(0.5, 3.0, 2)
    hull = shapely.convex_hull(shapely.MultiPoint(points))
    V = np.asarray(shapely.geometry.polygon.orient(hull, 1.0).exterior.coords)[:-1]
    k = int(rng.integers(len(V)))
    e0, e1 = V[k], V[(k + 1) % len(V)]
    x_j = e0 + rng.uniform(0.2, 0.8) * (e1 - e0)
    t = (e1 - e0) / np.linalg.norm(e1 - e0)
    z = np.array([-t[1], t[0]])  # CCW polygon: the left normal of an edge points inside
    return V, z, x_j, np.stack([e0, e1])


@pytest.mark.parametrize("seed", range(40))
def test_sink_is_the_exact_maximiser_of_the_side_depth(seed):
    rng = np.random.default_rng(seed)
    V, z, x_j, face = random_cell(rng)
    A, b = polygon_rows(V)
    keep = np.abs(A @ -z - 1.0) > 1e-9  # every row but the exit row
    sink, h_star = exit_sink(face, -A[keep], b[keep])
    assert abs((sink - x_j) @ z) <= 1e-12 * 10  # on the exit line
    t = np.linspace(0.0, 1.0, 20001)
    points = face[0] + t[:, None] * (face[1] - face[0])
    sampled = np.min(b[keep][None, :] - points @ A[keep].T, axis=1)
    assert h_star >= sampled.max() - 1e-12  # no sample beats it
    assert h_star == pytest.approx(float(np.min(b[keep] - A[keep] @ sink)), abs=1e-12)
    assert h_star <= sampled.max() + 1e-3 * np.linalg.norm(face[1] - face[0])  # and it is attained
    assert np.allclose(np.sort(exit_face(V, z, x_j), axis=0), np.sort(face, axis=0))


@pytest.mark.parametrize("seed", range(40))
def test_lemma_6_field_meets_the_certificate_with_the_stated_margins(seed):
    rng = np.random.default_rng(100 + seed)
    V, z, x_j, face = random_cell(rng)
    A, b = polygon_rows(V)
    keep = np.abs(A @ -z - 1.0) > 1e-9
    normals, offsets = -A[keep], b[keep]
    sink, h_star = exit_sink(face, normals, offsets)
    diam = max(np.linalg.norm(p - q) for p in V for q in V)
    c = rng.uniform(0.01, 1.0)
    c_h = c * rng.uniform(1.0, 3.0)
    eps = 0.5 * c * h_star
    u_max = c * diam + eps + rng.uniform(0.01, 1.0)
    M, a = c * np.eye(2), c * sink - eps * z
    m = field_margins(M, a, V, z, x_j, normals, offsets, c_h, c, u_max)
    assert m.cbf <= -(c * h_star - eps) + 1e-12  # σ_h ≥ c·h* − ε
    assert m.clf <= -eps + 1e-12  # σ_v ≥ ε
    assert m.input <= 1e-12
    delta = cell_tolerance(M, normals, -m.cbf_rows, z, -m.clf)
    assert delta >= 0.5 * h_star * (1 - 1e-9)  # Lemma 6: δ_c = h*/2


@pytest.mark.parametrize("seed", SEEDS)
def test_every_funnel_cell_has_a_finite_positive_usable_tolerance_within_its_bounds(seed):
    plan = random_plan(seed)
    cells = plan.cells
    edge = cells.parent[cells.cell_node] >= 0
    tau = plan.usable_tolerance
    assert np.all(np.isfinite(tau)) and np.all(tau > 0)
    assert np.all(tau[edge] <= np.fmin(plan.tolerance[edge], 0.5 * cells.exit_inset[edge]) * (1 + 1e-12))
    assert plan.plan_tolerance == pytest.approx(float(tau.min()))
    assert np.all(np.isnan(cells.exit_inset[~edge])) and np.all(cells.exit_inset[edge] > 0)


@pytest.mark.parametrize("seed", SEEDS)
def test_synthesis_never_tolerates_less_than_lemma_6(seed):
    plan = random_plan(seed)
    cells = plan.cells
    for c in np.flatnonzero(np.isin(plan.status, [CellStatus.CERTIFIED, CellStatus.RELAXED])):
        verts, z, x_j = cells.vertices(c), cells.exit_dir[c], cells.exit_point[c]
        normals, offsets = cells.barrier(c)
        _, h_star = exit_sink(exit_face(verts, z, x_j), normals, offsets)
        diam = max(np.linalg.norm(p - q) for p in verts for q in verts)
        c_v, u_max = plan.c_v[c], plan.u_max[c]
        eps = min(0.5 * c_v * h_star, 0.5 * (u_max - c_v * diam))
        lemma6 = min(h_star - eps / c_v, eps / c_v)
        assert plan.tolerance[c] >= lemma6 * (1 - 1e-6), f"cell {c}: δ_c below Lemma 6's field"


@pytest.mark.parametrize("seed", SEEDS)
def test_the_batched_sinks_are_each_cells_own(seed):
    """cell_fields.cell_sinks takes every exit face in one sort: the same faces, sinks and ``h*`` as
    :func:`funnel.exit_face` and :func:`funnel.exit_sink` cell by cell (ragged cells, ties included)."""
    from bearnav_cli.cell_fields import cell_sinks

    cells = random_plan(seed).cells
    edge = np.flatnonzero(cells.parent[cells.cell_node] >= 0)
    verts = [cells.vertices(c) for c in edge]
    rows = [cells.barrier(c) for c in edge]
    z, x_j = cells.exit_dir[edge], cells.exit_point[edge]
    sink, h_star = cell_sinks(
        np.concatenate(verts),
        np.array([len(v) for v in verts]),
        np.concatenate([n for n, _ in rows]),
        np.concatenate([q for _, q in rows]),
        np.array([len(q) for _, q in rows]),
        z,
        x_j,
    )
    for k, c in enumerate(edge):
        one_sink, one_h = exit_sink(exit_face(verts[k], z[k], x_j[k]), *rows[k])
        assert np.allclose(sink[k], one_sink, atol=1e-12) and h_star[k] == pytest.approx(one_h, abs=1e-12), c


@pytest.mark.parametrize("seed", SEEDS)
def test_each_inset_is_the_exit_faces_slack_in_its_parent(seed):
    plan = random_plan(seed)
    comp = composition.check(plan, 0.1)
    edge = plan.cells.parent[plan.cells.cell_node] >= 0
    assert comp.ok, comp.problems
    # the stored inset is what the face achieves (to rounding), not merely a bound below it
    assert np.allclose(comp.exit_inset[edge], plan.cells.exit_inset[edge], rtol=1e-9, atol=1e-12)


def test_usable_tolerance_of_a_constant_field_is_finite():
    """A constant field (``M = 0``) tolerates any error: ``δ_c = +inf``, and ``τ_c = δ_e,c/2``."""
    normals = np.array([[0.0, 1.0], [-1.0, 0.0]])
    assert cell_tolerance(np.zeros((2, 2)), normals, np.array([0.1, 0.2]), np.array([1.0, 0.0]), 0.3) == math.inf
    tau = usable_tolerances(np.array([0.02, math.inf, 0.5, math.nan]), np.array([math.nan, 0.04, 2.0, 1.0]))
    assert tau[0] == 0.02 and tau[1] == 0.02 and tau[2] == 0.5 and math.isnan(tau[3])
    assert funnel.plan_tolerance_of(tau) == 0.02


def test_a_plan_stores_an_infinite_tolerance_and_round_trips_it(tmp_path):
    plan = random_plan(0)
    c = int(np.flatnonzero(plan.cells.parent[plan.cells.cell_node] >= 0)[0])
    tolerance = plan.tolerance.copy()
    tolerance[c] = math.inf
    constant = dataclasses.replace(plan, tolerance=tolerance)
    path = tmp_path / "plan.npz"
    write_plan(path, constant)
    again = artifacts.load(path).artifact
    assert again.tolerance[c] == math.inf and np.isfinite(again.usable_tolerance).all()
    tolerance[c] = -math.inf
    with pytest.raises(ArtifactError, match="tolerance"):
        write_plan(tmp_path / "bad.npz", dataclasses.replace(plan, tolerance=tolerance))


def _tampered(plan, **changes):
    cells = plan.cells
    cell_changes = {k: v for k, v in changes.items() if k in ("exit_inset",)}
    if cell_changes:
        plan = dataclasses.replace(plan, cells=dataclasses.replace(cells, **cell_changes))
    rest = {k: v for k, v in changes.items() if k not in cell_changes}
    return dataclasses.replace(plan, **rest) if rest else plan


def test_verify_names_the_cell_whose_usable_tolerance_is_above_its_bound():
    plan = random_plan(1)
    c = int(np.flatnonzero(plan.cells.parent[plan.cells.cell_node] >= 0)[-1])
    usable = plan.usable_tolerance.copy()
    usable[c] = 1.5 * min(plan.tolerance[c], 0.5 * plan.cells.exit_inset[c])
    report = verify.run(_tampered(plan, usable_tolerance=usable), verify.Params(n_starts=0))
    assert report.failed
    assert report.composition.failures["usable_tolerance"] == [c]
    assert any("usable tolerance" in r and str(c) in r for r in report.reasons)


def test_verify_names_the_cell_whose_exit_face_leaves_its_parent_eroded_by_its_own_inset():
    plan = random_plan(2)
    c = int(np.flatnonzero(plan.cells.parent[plan.cells.cell_node] >= 0)[0])
    inset = plan.cells.exit_inset.copy()
    inset[c] *= 3.0
    usable = plan.usable_tolerance  # unchanged: within min(δ_c, δ_e,c/2) still
    report = verify.run(_tampered(plan, exit_inset=inset, usable_tolerance=usable), verify.Params(n_starts=0))
    assert report.failed
    assert report.composition.failures["c4_exit_contained"] == [c]
    assert not report.composition.failures["usable_tolerance"]


def test_a_plan_2_file_names_the_command_that_rebuilds_it(tmp_path):
    plan = random_plan(0)
    path = tmp_path / "plan.npz"
    write_plan(path, plan)
    with np.load(path, allow_pickle=False) as data:
        entries = {k: data[k] for k in data.files}
    import json

    manifest = json.loads(str(entries["manifest"][()]))
    manifest["schema"] = "bearnav.plan/2"
    entries["manifest"] = np.array(json.dumps(manifest))
    old = tmp_path / "old.npz"
    np.savez(old, **entries)
    with pytest.raises(ArtifactError, match=r"bearnav.plan/2.*`bearnav plan.*--force"):
        artifacts.load(old)
    from bearnav_cli.runtime import PlanArrays

    with pytest.raises(ArtifactError, match=r"bearnav.plan/2.*bearnav plan MAP.yaml --force"):
        PlanArrays.from_npz(old)


@functools.cache
def cluttered_plan(seed: int):
    from bearnav_cli import pipeline
    from tests.conftest import build_map
    from tests.funnel_maps import cluttered_spec

    return pipeline.compute(build_map(cluttered_spec(seed, iterations=300)))["plan"]


@pytest.mark.parametrize("seed", [0, 1])
def test_cluttered_maps_plan_with_finite_usable_tolerances(seed):
    """Many small obstacles and a small radius (issue 21's exit-70 case): every τ_c finite and positive,
    a cell whose δ_c is +inf has a constant field and τ_c = δ_e,c/2, and the composition is proved."""
    plan = cluttered_plan(seed)
    assert np.all(np.isfinite(plan.usable_tolerance)) and np.all(plan.usable_tolerance > 0)
    M = plan.gain.reshape(plan.cells.n_cells, 2, -1, 2).sum(axis=2)
    for c in np.flatnonzero(plan.tolerance == math.inf):
        assert np.allclose(M[c], 0.0, atol=1e-12), f"cell {c}: δ_c = inf but the field is not constant"
        assert plan.usable_tolerance[c] == pytest.approx(0.5 * plan.cells.exit_inset[c])
    comp = composition.check(plan, 0.1)
    assert comp.ok, comp.problems


@pytest.mark.parametrize("seed", [0, 2])
def test_cover_F_reaches_into_the_band_along_the_walls(seed):
    """ALGORITHMS §12.7: ``cover = F`` adds band leaves after F_m; the cells still compose, each band leaf
    hangs from a node that is not a band leaf, the recomputed coverage of F is the stored one, and no
    band cell lowers the least τ_c of the cells before the band (the floor the stage records)."""
    from bearnav_cli import pipeline
    from bearnav_cli.stages import decompose
    from tests.conftest import build_map
    from tests.funnel_maps import ITERATIONS, random_spec

    map_ = build_map(random_spec(seed, ITERATIONS))
    tree = pipeline.compute(map_, through="simplify")["simplified"]
    near = decompose.run(tree, decompose.Params(cover="F_m"))
    far = decompose.run(tree)  # cover = F is the default
    band = far.stats["band_leaves"]
    assert near.stats["band_leaves"] == 0 and band > 0
    assert far.free_coverage > near.free_coverage
    assert (
        far.free_coverage >= decompose.Params().coverage_target
        or far.n_cells - len(tree.nodes) == decompose.Params().max_added_nodes
    )
    assert far.stats["free_coverage_m"] >= near.stats["free_coverage_m"] - 1e-12
    first_band = far.n_cells - band
    assert np.all(far.parent[first_band:] < first_band)  # never from another band leaf
    from bearnav_cli.stages import synthesize

    plan = synthesize.run(far)
    comp = composition.check(plan, 0.1)
    assert comp.ok, comp.problems
    assert comp.coverage_free == pytest.approx(far.free_coverage, rel=1e-6)
    # the recorded coverage of F_m is of the final cells, band included, as verify recomputes it
    assert comp.coverage == pytest.approx(far.stats["free_coverage_m"], rel=1e-9)
    assert np.all(np.isfinite(plan.usable_tolerance)) and np.all(plan.usable_tolerance > 0)
    # the floor is the least Lemma-6 τ_c of the cells before the band, which synthesis only raises
    floor = far.stats["band_tolerance_floor"]
    near_plan = synthesize.run(near)
    assert floor <= near_plan.plan_tolerance * (1 + 1e-9)
    assert np.min(plan.usable_tolerance[first_band:]) >= floor * (1 - 1e-9)
    assert plan.plan_tolerance >= floor * (1 - 1e-9)


def test_coverage_of_f_short_because_of_a_narrow_passage_names_the_passage(caplog):
    """A room behind a passage narrower than twice the barrier margin is free space no tree edge reaches: the
    warning about the coverage of F says so (not that the rest lies along the walls)."""
    import logging

    from bearnav_cli import pipeline
    from tests.conftest import build_map

    gap = 0.45  # the robot (0.4 wide) passes; a tree edge keeping the margin (0.094 from each side) does not
    low, high = 2.5 - gap / 2, 2.5 + gap / 2
    spec = {
        "name": "passage", "bounds": [0, 0, 8, 5], "robot_radius": 0.2, "goal": [1.0, 2.5],
        "landmarks": [[0, 0], [0, 5], [8, 0], [8, 5], [4.1, 1.0], [3.9, 4.0], [4.1, 4.0], [3.9, 1.0]],
        "obstacles": [{"rectangle": [3.9, 0, 4.1, low]}, {"rectangle": [3.9, high, 4.1, 5]}],
        "params": {"rrtstar": {"iterations": 600, "seed": 0}},
    }  # fmt: skip
    with caplog.at_level(logging.WARNING, logger="bearnav_cli.stages.decompose"):
        cells = pipeline.compute(build_map(spec), through="decompose")["cells"]
    assert cells.free_coverage < 0.9
    said = [r.getMessage() for r in caplog.records if "(of F; target" in r.getMessage()]
    assert len(said) == 1 and "past passages narrower than" in said[0] and "twice the wall margin" in said[0], said
