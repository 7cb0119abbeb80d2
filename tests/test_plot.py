"""Figures draw what the runtime computes, and a person can read them (issue 10 item 6, issue 13 item 3).

Properties of the drawn artists, not pixels: arrows are based at free points of the certified
domain and point where ``runtime.field`` points, cells are coloured without stacking, uncertified
cells and the uncovered free space stand out, barrier lines and labels only on request.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import shapely  # noqa: E402
from matplotlib import colors as mcolors  # noqa: E402
from matplotlib.quiver import Quiver  # noqa: E402

from bearnav_cli import composition, datatypes, palette, pipeline, plot, runtime  # noqa: E402
from bearnav_cli.datatypes import CellStatus, replace  # noqa: E402
from bearnav_cli.errors import InvalidParamsError  # noqa: E402
from bearnav_cli.funnel import coverage_domain  # noqa: E402
from bearnav_cli.geometry import DEFAULT_CLEARANCE, FreeSpace  # noqa: E402

from .conftest import SMALL_MAP, build_map  # noqa: E402
from .test_cli_errors import assert_one_line_error  # noqa: E402


@pytest.fixture(scope="module")
def small_chain():
    """Every artifact of the small test map, built in-process (``pipeline.compute``)."""
    return pipeline.compute(build_map(SMALL_MAP))


@pytest.fixture(scope="module")
def small_plan(small_chain):
    """A funnel plan of the small test map."""
    return small_chain["plan"]


@pytest.fixture(scope="module")
def paper_plan():
    return pipeline.compute(build_map(SMALL_MAP), overrides={"decompose": {"cells": "paper"}})["plan"]


@pytest.fixture
def draw():
    """``draw(artifact, **options)`` -> the figure's main axes; closes every figure afterwards."""
    figures = []

    def make(artifact, **options):
        figures.append(plot.figure_for(artifact, **options))
        return figures[-1].axes[0]

    yield make
    for fig in figures:
        plt.close(fig)


def the_quiver(ax) -> Quiver:
    quivers = [c for c in ax.collections if isinstance(c, Quiver)]
    assert len(quivers) == 1
    return quivers[0]


def by_gid(ax, gid: str) -> list:
    return [a for a in (*ax.collections, *ax.patches, *ax.texts) if a.get_gid() == gid]


def legend_texts(ax) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


def test_small_plan_is_a_funnel_plan(small_plan):
    assert small_plan.cells.is_funnel and small_plan.cells.node_added.any()


def test_arrows_are_based_at_free_points_of_the_certified_domain(small_plan, draw):
    base = np.asarray(the_quiver(draw(small_plan)).get_offsets())
    assert len(base) > 50
    assert FreeSpace.from_map(small_plan.map).points_free(base).all()
    arrays = runtime.PlanArrays.from_plan(small_plan)
    assert (runtime.least_rank_cell(arrays, base) >= 0).all()


def test_arrows_point_along_the_runtime_field(small_plan, draw):
    q = the_quiver(draw(small_plan))
    base = np.asarray(q.get_offsets())
    arrays = runtime.PlanArrays.from_plan(small_plan)
    u = runtime.field(arrays, runtime.locate(arrays, base), base)
    u /= np.hypot(u[:, 0], u[:, 1])[:, None]
    np.testing.assert_allclose(np.column_stack([q.U, q.V]), u, atol=1e-12)
    assert q.pivot == "tail"  # the offsets are the bases of the arrows


def test_arrows_cover_the_certified_domain(small_plan):
    """Every grid point that is free and in a cell gets its arrow (none is dropped silently)."""
    points, _ = plot.field_samples(small_plan, arrows=20)
    fb = small_plan.map.free_bounds
    step = max(fb[2] - fb[0], fb[3] - fb[1]) / 20
    grid = np.stack(
        np.meshgrid(np.arange(fb[0] + step / 2, fb[2], step), np.arange(fb[1] + step / 2, fb[3], step)), axis=-1
    ).reshape(-1, 2)
    arrays = runtime.PlanArrays.from_plan(small_plan)
    inside = FreeSpace.from_map(small_plan.map).points_free(grid) & (runtime.least_rank_cell(arrays, grid) >= 0)
    assert len(points) == inside.sum()


def test_axes_are_labelled_with_units(small_plan, draw):
    for artifact in (small_plan, small_plan.map, small_plan.cells):
        ax = draw(artifact)
        assert ax.get_xlabel() == "x (map units)" and ax.get_ylabel() == "y (map units)"


def test_barrier_lines_only_on_request(small_plan, draw):
    assert not by_gid(draw(small_plan), "barrier-lines")
    (lines,) = by_gid(draw(small_plan, barriers=True), "barrier-lines")
    assert len(lines.get_segments()) > small_plan.cells.n_cells


def test_exit_faces_are_the_exit_rows_edges(small_plan, draw):
    cells = small_plan.cells
    (faces,) = by_gid(draw(small_plan), "exit-faces")
    edge = [c for c in range(cells.n_cells) if cells.cell_exit_row[c] >= 0]
    assert len(faces.get_segments()) == len(edge)
    for seg, c in zip(faces.get_segments(), edge, strict=True):
        mid = seg.mean(axis=0)  # on the exit line z·(x − x_j) = 0
        assert abs(cells.exit_dir[c] @ (mid - cells.exit_point[c])) < 1e-9 * cells.map.diagonal


@pytest.mark.parametrize("bad", [CellStatus.NOT_CERTIFIED, CellStatus.SOLVER_FAILURE])
def test_an_uncertified_cell_is_hatched_red(small_plan, draw, bad):
    status = np.array(small_plan.status)
    status[7] = bad
    ax = draw(replace(small_plan, status=status))
    highlighted = [a for a in ax.patches if str(a.get_gid()).startswith("uncertified-cell-")]
    assert [a.get_gid() for a in highlighted] == ["uncertified-cell-7"]
    patch = highlighted[0]
    assert patch.get_hatch() and patch.get_zorder() > 3  # above fills, outlines and obstacles
    assert mcolors.to_hex(patch.get_edgecolor()) == mcolors.to_hex(plot.UNCERTIFIED_COLOR)
    np.testing.assert_allclose(patch.get_path().vertices[:-1], small_plan.cells.vertices(7))  # closed ring
    assert "uncertified cell (status 2/3)" in legend_texts(ax)
    assert not [a for a in draw(small_plan).patches if str(a.get_gid()).startswith("uncertified-cell-")]


def test_active_regions_are_where_the_runtime_uses_each_cell(small_plan):
    cells = small_plan.cells
    regions = plot.cell_regions(cells)
    total = shapely.union_all(datatypes.cell_polygons(cells)).area
    assert sum(r.area for r in regions) == pytest.approx(total, rel=1e-9)  # a partition of D: no stacking
    rng = np.random.default_rng(0)
    points = rng.uniform(cells.map.bounds[:2], cells.map.bounds[2:], (3000, 2))
    chosen = runtime.least_rank_cell(runtime.PlanArrays.from_plan(small_plan), points)
    edges = shapely.union_all([r.boundary for r in regions])
    clear = shapely.distance(edges, shapely.points(points)) > 1e-6 * cells.map.diagonal
    found = np.full(len(points), -1)
    for c, region in enumerate(regions):
        found[shapely.contains_xy(region, points[:, 0], points[:, 1])] = c
    assert clear.sum() > 2500
    np.testing.assert_array_equal(found[clear], chosen[clear])


def test_the_figure_hatches_the_uncovered_free_space_it_is_given(small_plan, draw):
    """The plot draws composition's split of F_m (it does not recompute it), and only when given it."""
    space = FreeSpace.from_map(small_plan.map)
    margin = DEFAULT_CLEARANCE * small_plan.map.diagonal
    full = coverage_domain(space.component_of(small_plan.map.goal), space.bounds, space.obstacles, margin)
    regions = composition.coverage_regions(small_plan.cells, space)
    # the split is a partition of F_m: reached ∪ unreached, and uncovered is the reached part less D
    assert regions.domain.area + regions.unreached.area == pytest.approx(full.area, rel=1e-9)
    expected = (1 - composition.coverage(small_plan, space)) * regions.domain.area
    assert regions.uncovered.area == pytest.approx(expected, rel=1e-6, abs=1e-9 * full.area)
    assert regions.uncovered.area > 0
    (patch,) = by_gid(draw(small_plan, coverage=regions), "uncovered")
    assert patch.get_hatch()
    drawn = sum(abs(shapely.Polygon(poly).area) for poly in patch.get_path().to_polygons())
    assert drawn >= regions.uncovered.area * (1 - 1e-6)
    assert not by_gid(draw(small_plan), "uncovered")


def test_colour_by_rank_tolerance_and_status(small_plan, draw):
    ax = draw(small_plan)
    assert len(ax.figure.axes) == 2 and "rank" in ax.figure.axes[1].get_ylabel()
    ax = draw(small_plan, color_by="tolerance")
    assert "τ_c" in ax.figure.axes[1].get_ylabel()  # the usable tolerance (ALGORITHMS §12.3)
    lo, hi = ax.figure.axes[1].get_ylim()
    tau = small_plan.usable_tolerance
    assert lo == pytest.approx(tau.min()) and hi == pytest.approx(tau.max())
    ax = draw(small_plan, color_by="status")
    assert len(ax.figure.axes) == 1 and "cells: certified" in legend_texts(ax)
    with pytest.raises(InvalidParamsError, match="color_by"):
        plot.figure_for(small_plan, color_by="colour")
    with pytest.raises(InvalidParamsError, match="plan"):
        plot.figure_for(small_plan.cells, color_by="tolerance")


def test_legend_names_every_layer(small_plan, draw):
    texts = " | ".join(legend_texts(draw(small_plan, coverage=composition.coverage_regions(small_plan.cells))))
    for word in (
        "obstacles",
        "inflated by the robot radius",
        "tree",
        "added nodes",
        "landmarks",
        "goal",
        "no cell covers",
        "exit faces",
        "field direction",
    ):
        assert word in texts, word


def test_landmark_labels_never_collide_unless_asked(small_plan, draw):
    ids = set(small_plan.map.landmark_ids)
    assert {t.get_text() for t in by_gid(draw(small_plan, labels=True), "landmark-label")} == ids
    assert not by_gid(draw(small_plan, labels=False), "landmark-label")
    ax = draw(small_plan)
    renderer = ax.figure.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for t in by_gid(ax, "landmark-label")]
    assert boxes and {t.get_text() for t in by_gid(ax, "landmark-label")} <= ids
    assert not any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1 :])


def test_cell_numbers_on_request(small_plan, draw):
    assert not by_gid(draw(small_plan), "cell-number")
    assert plot.CELL_NUMBER_LABEL not in legend_texts(draw(small_plan))


def test_paper_plans_are_coloured_by_status(paper_plan, draw):
    assert not paper_plan.cells.is_funnel
    ax = draw(paper_plan)
    assert len(ax.figure.axes) == 1 and "cells: certified" in legend_texts(ax)
    assert len(the_quiver(ax).get_offsets()) > 50
    with pytest.raises(InvalidParamsError, match="funnel"):
        plot.figure_for(paper_plan, color_by="tolerance")


def test_cli_plot_writes_a_png_and_rejects_a_bad_colour(cli, write_map, small_spec, tmp_path):
    assert cli("plan", write_map(small_spec)).exit_code == 0
    plan = tmp_path / "plans" / "small" / "plan.npz"
    result = cli("plot", plan, "-o", "x.png", "--color-by", "tolerance", "--cell-numbers")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "x.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert cli("plot", plan, "-o", "y.png", "--barriers", "--labels").exit_code == 0
    assert_one_line_error(cli("plot", plan, "-o", "z.png", "--color-by", "colour"), "--color-by", "rank")
    assert not (tmp_path / "z.png").exists()
    assert_one_line_error(
        cli("plot", tmp_path / "plans" / "small" / "cells.npz", "-o", "z.png", "--color-by", "tolerance"), "color_by"
    )


def test_no_arrows_draws_no_field(small_plan, draw):
    assert plot.field_samples(small_plan, arrows=0)[0].shape == (0, 2)
    ax = draw(small_plan, arrows=0)
    assert not [c for c in ax.collections if isinstance(c, Quiver)]


def test_importing_plot_keeps_the_callers_backend():
    """plot does not switch matplotlib's backend (a notebook keeps its own); the CLI picks Agg."""
    import subprocess
    import sys

    code = "import matplotlib; matplotlib.use('svg'); import bearnav_cli.plot; print(matplotlib.get_backend())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().lower() == "svg"


# --------------------------------------------------------------------------- issue 23 item 5: figures a new user reads
#
# Each figure is drawn once (a module fixture) and read by several tests: every drawn mark has a legend
# entry, no two labels overlap, the title states the configuration, the colours are the palette's.
# test_tags.py reads the tags figure with the same checks (assert_reads_well).


@pytest.fixture(scope="module")
def figures(small_chain, small_plan):
    """``{name: figure}``: the plan with cell indices, a simulation and the simplified tree."""
    import dataclasses

    from bearnav_cli.stages import simulate

    params = simulate.Params(fov=90.0, noise_deg=0.5, dynamics="unicycle", max_steps=40)  # 2 map starts, time out
    sim = simulate.run(small_plan, params)
    coverage = composition.coverage_regions(small_plan.cells)
    made = {
        "plan": plot.figure_for(small_plan, cell_numbers=True, coverage=coverage),
        "sim": plot.figure_for(sim, params=dataclasses.asdict(params)),
        "tree": plot.figure_for(small_chain["simplified"], background=[small_chain["tree"]]),
    }
    yield made
    for fig in made.values():
        plt.close(fig)


def drawn(ax) -> list:
    """The marks of the axes a reader sees: visible artists with something to draw."""
    marks = []
    for a in (*ax.lines, *ax.collections, *ax.patches, *ax.texts):
        if not a.get_visible() or a.get_gid() == "label-key":  # legend keys of the labels draw nothing
            continue
        if isinstance(a, matplotlib.lines.Line2D) and not len(a.get_xdata()):
            continue
        if isinstance(a, matplotlib.collections.Collection) and not (len(a.get_offsets()) or len(a.get_paths())):
            continue
        marks.append(a)
    return marks


def _rgb(color) -> str:
    return mcolors.to_hex(mcolors.to_rgba(color)[:3])


def unexplained_marks(ax) -> set:
    """``(gid, label)`` of the drawn marks without a legend entry.

    An artist's label (``_label`` for one that shares an entry) is to be a legend entry; the map's
    frame needs none, and a fill by rank or ``τ_c`` is read off the colour bar.
    """
    entries = set(legend_texts(ax))
    has_bar = len(ax.figure.axes) > 1
    return {
        (a.get_gid(), a.get_label())
        for a in drawn(ax)
        if a.get_label().lstrip("_") not in entries
        and a.get_gid() != "bounds"
        and not (a.get_gid() == "cell-fill" and has_bar)
    }


def overlapping_labels(fig) -> list:
    """Pairs of visible texts of the main axes whose renderer window extents overlap."""
    ax = fig.axes[0]
    renderer = fig.canvas.get_renderer()
    texts = [t for t in ax.texts if t.get_visible() and t.get_text()]
    boxes = [t.get_window_extent(renderer) for t in texts]
    return [
        (a.get_text(), b.get_text())
        for i, a in enumerate(texts)
        for j, b in enumerate(texts)
        if j > i and boxes[i].overlaps(boxes[j])
    ]


def colours_outside_the_palette(ax) -> set:
    """The colours of categorical marks that are not palette.PALETTE's (a fill read off a colour bar aside)."""
    from bearnav_cli.palette import PALETTE

    used = set()
    for a in drawn(ax):
        if a.get_gid() == "cell-fill" and len(ax.figure.axes) > 1:
            continue
        if isinstance(a, matplotlib.lines.Line2D):
            used |= {_rgb(a.get_color()), _rgb(a.get_markerfacecolor()), _rgb(a.get_markeredgecolor())}
        elif isinstance(a, matplotlib.text.Text):
            used.add(_rgb(a.get_color()))
        elif isinstance(a, matplotlib.collections.Collection):
            used |= {_rgb(c) for c in (*a.get_facecolor(), *a.get_edgecolor())}
        else:
            used |= {_rgb(c) for c in (a.get_facecolor(), a.get_edgecolor()) if mcolors.to_rgba(c)[3] > 0}
    return used - {c.lower() for c in PALETTE.values()}


def assert_reads_well(fig) -> None:
    """Every mark has a legend entry (each entry once, the field's key an arrow), no two labels overlap, labels,
    title and legend lie inside the figure, and every categorical colour is the palette's."""
    ax = fig.axes[0]
    assert not unexplained_marks(ax)
    texts = legend_texts(ax)
    assert len(set(texts)) == len(texts)
    legend = ax.get_legend()
    for key, text in zip(legend.legend_handles, legend.get_texts(), strict=True):
        if text.get_text().startswith("field direction"):
            assert not isinstance(key, matplotlib.patches.Patch)  # an arrow, not a box like an obstacle's
    assert [t for t in ax.texts if t.get_visible() and t.get_text()]
    assert not overlapping_labels(fig)
    renderer = fig.canvas.get_renderer()
    page = fig.bbox
    for box in [t.get_window_extent(renderer) for t in ax.texts] + [
        ax.title.get_window_extent(renderer),
        legend.get_window_extent(renderer),
    ]:
        assert page.x0 - 1 <= box.x0 and box.x1 <= page.x1 + 1 and page.y0 - 1 <= box.y0 and box.y1 <= page.y1 + 1
    assert not colours_outside_the_palette(ax)


@pytest.mark.parametrize("name", ["plan", "sim", "tree"])
def test_the_figures_read_well(figures, name):
    assert_reads_well(figures[name])


def test_cell_indices_give_way_to_landmark_ids(figures, small_plan):
    """Landmark ids are placed first; every index is a cell's, at most once, and the indices have a legend key."""
    ax = figures["plan"].axes[0]
    ids = {t.get_text() for t in by_gid(ax, "landmark-label")}
    assert ids == set(small_plan.map.landmark_ids)  # the small map's ids all fit, cell indices or not
    numbers = [int(t.get_text()) for t in by_gid(ax, "cell-number")]
    assert len(numbers) == len(set(numbers)) and set(numbers) <= set(range(small_plan.cells.n_cells))
    assert len(numbers) > 0.6 * small_plan.cells.n_cells
    assert plot.CELL_NUMBER_LABEL in legend_texts(ax)


def test_titles_state_the_configuration(figures, small_plan):
    sim_title = figures["sim"].axes[0].get_title()
    for words in (
        "small — simulate",
        "of 2 runs reached the goal",
        "the map's starts",
        "fov 90°",
        "bearing noise 0.5° (1σ)",
        "unicycle dynamics",
        "set estimator",
    ):
        assert words in sim_title, words
    assert figures["plan"].axes[0].get_title().startswith(f"small — plan: {small_plan.cells.n_cells} funnel cells")
    assert figures["tree"].axes[0].get_title().startswith("small — simplified tree:")
    assert "unknown" in plot.simulation_config(None)  # a sim.npz without its manifest says so, not a guess


def test_the_simulations_tree_and_cells_stand_apart_from_its_runs(figures):
    """The tree under the runs is not blue-green like success, and certified cells are not filled green."""
    ax = figures["sim"].axes[0]
    (tree,) = by_gid(ax, "tree")
    assert _rgb(tree.get_edgecolor()[0]) not in {_rgb(c) for c in palette.OUTCOME_COLORS.values()}
    fills = {_rgb(a.get_facecolor()) for a in by_gid(ax, "cell-fill")}
    assert _rgb(palette.OUTCOME_COLORS[0]) not in fills


def test_bags_and_figures_share_the_palette():
    """One source: the bag's RGBA are the palette's colours, and plot's role names point into it."""
    from bearnav_cli import bag

    for status, color in palette.STATUS_COLORS.items():
        assert bag.STATUS_RGBA[status][:3] == pytest.approx(mcolors.to_rgb(color))
    for outcome, color in palette.OUTCOME_COLORS.items():
        assert bag.OUTCOME_RGBA[outcome][:3] == pytest.approx(mcolors.to_rgb(color))
    assert plot.cells.STATUS_COLORS is palette.STATUS_COLORS and plot.runs.OUTCOME_COLORS is palette.OUTCOME_COLORS
    assert set(palette.ROLE_COLORS.values()) <= set(palette.PALETTE.values())
    assert len(set(palette.OUTCOME_COLORS.values())) == len(palette.OUTCOME_COLORS)  # outcomes told apart
