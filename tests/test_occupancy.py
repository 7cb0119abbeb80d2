"""ROS map_server occupancy grids to polygons (bearnav_cli.occupancy)."""

from __future__ import annotations

import io
import time

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from PIL import Image

from bearnav_cli.errors import BearnavError, InvalidMapError
from bearnav_cli.occupancy import classify, decode_image, grid_obstacles, vectorize

RES, ORIGIN = 0.05, (-1.0, 2.0)
H, W = 40, 60


# --- helpers ------------------------------------------------------------------------------


def cell_box(h, r0, r1, c0, c1, res=RES, origin=ORIGIN):
    """World rectangle of rows r0..r1-1 and columns c0..c1-1 of an h-row grid."""
    ox, oy = origin
    return shapely.box(ox + c0 * res, oy + (h - r1) * res, ox + c1 * res, oy + (h - r0) * res)


def pixel_union(mask, res=RES, origin=ORIGIN):
    """The reference answer: the union of one box per blocked pixel."""
    rows, cols = np.nonzero(mask)
    return shapely.union_all(
        [cell_box(mask.shape[0], r, r + 1, c, c + 1, res, origin) for r, c in zip(rows, cols, strict=True)]
    )


def p5(gray, maxval=255, comment=b"# made by hand\n"):
    h, w = gray.shape
    raster = gray.astype(">u2" if maxval > 255 else "u1").tobytes()
    return b"P5\n" + comment + b"%d %d\n%d\n" % (w, h, maxval) + raster


def p2(gray, maxval=255):
    h, w = gray.shape
    rows = [" ".join(str(int(v)) for v in row) for row in gray]
    raster = "\n".join(rows)
    return f"P2\n# ascii\n{w} {h} # size\n{maxval}\n# raster\n{raster}\n".encode()


def png(pixels, mode=None):
    buf = io.BytesIO()
    Image.fromarray(pixels, mode).save(buf, format="PNG")
    return buf.getvalue()


def meta(**extra):
    return {"image": "map.pgm", "resolution": RES, "origin": [*ORIGIN, 0.0], **extra}


@pytest.fixture
def scene():
    """A border-touching rectangle, an L-shape and a square ring, as mask and true shapes."""
    mask = np.zeros((H, W), dtype=bool)
    mask[0:10, 0:15] = True
    mask[20:36, 5:10] = True
    mask[31:36, 5:25] = True
    mask[5:25, 30:50] = True
    mask[10:20, 35:45] = False
    shapes = [
        cell_box(H, 0, 10, 0, 15),
        cell_box(H, 20, 36, 5, 10).union(cell_box(H, 31, 36, 5, 25)),
        cell_box(H, 5, 25, 30, 50).difference(cell_box(H, 10, 20, 35, 45)),
    ]
    return mask, shapes


# --- vectorize ----------------------------------------------------------------------------


def test_vectorize_matches_known_shapes(scene):
    mask, shapes = scene
    polys = vectorize(mask, RES, ORIGIN)
    truth = shapely.union_all(shapes)
    diff = shapely.union_all(polys).symmetric_difference(truth).area
    assert diff <= RES * truth.boundary.length  # the general bound for a pixel mask
    assert diff < 1e-9  # pixel-aligned shapes come out exact
    assert len(polys) == 3
    assert all(p.is_valid for p in polys)
    ring = next(p for p in polys if len(p.interiors) > 0)
    assert len(ring.interiors) == 1
    assert shapely.Polygon(ring.interiors[0]).area == pytest.approx(100 * RES**2)
    assert ring.area == pytest.approx(300 * RES**2)
    ell = next(p for p in polys if p.equals(shapes[1]))
    assert len(ell.exterior.coords) == 7  # 6 corners, no collinear vertices
    keys = [p.bounds[:2] for p in polys]
    assert keys == sorted(keys)


def test_vectorize_empty_and_full():
    assert vectorize(np.zeros((5, 7), dtype=bool), RES, ORIGIN) == []
    (full,) = vectorize(np.ones((5, 7), dtype=bool), RES, ORIGIN)
    assert len(full.exterior.coords) == 5
    assert full.bounds == pytest.approx((-1.0, 2.0, -1.0 + 7 * RES, 2.0 + 5 * RES))


def test_vectorize_corner_contacts_stay_valid():
    diagonal = np.array([[1, 0], [0, 1]], dtype=bool)
    assert len(vectorize(diagonal, 1.0, (0.0, 0.0))) == 2
    closed_by_corner = np.array([[1, 1, 1, 1], [1, 0, 0, 1], [1, 0, 0, 1], [0, 1, 1, 1]])
    holes_by_corner = np.ones((4, 4), dtype=bool)
    holes_by_corner[1, 1] = holes_by_corner[2, 2] = False
    for mask in (closed_by_corner.astype(bool), holes_by_corner):
        polys = vectorize(mask, 1.0, (0.0, 0.0))
        assert len(polys) == 1 and polys[0].is_valid
        assert polys[0].area == mask.sum()
        assert polys[0].equals(pixel_union(mask, 1.0, (0.0, 0.0)))
    assert len(polys[0].interiors) == 2


def test_vectorize_nested_rings_get_their_own_holes():
    mask = np.zeros((11, 11), dtype=bool)
    mask[[0, -1], :] = mask[:, [0, -1]] = True  # outer ring
    mask[2:9, 2:9] = True
    mask[4:7, 4:7] = False  # an inner ring in its hole
    mask[5, 5] = True  # and an island in the inner ring's hole
    polys = vectorize(mask, RES, ORIGIN)
    assert len(polys) == 3 and all(p.is_valid for p in polys)
    assert [len(p.interiors) for p in polys] == [1, 1, 0]
    assert [round(p.area / RES**2) for p in polys] == [40, 40, 1]
    # Exact up to the 1e-12 m rounding of world coordinates.
    assert shapely.union_all(polys).symmetric_difference(pixel_union(mask)).area < 1e-12


@settings(max_examples=100, deadline=None)
@given(arrays(np.bool_, st.tuples(st.integers(1, 12), st.integers(1, 12))))
def test_vectorize_is_the_exact_pixel_union(mask):
    polys = vectorize(mask, 0.5, ORIGIN)
    assert all(isinstance(p, shapely.Polygon) and p.is_valid for p in polys)
    assert sum(p.area for p in polys) == pytest.approx(mask.sum() * 0.25)  # no overlaps
    truth = pixel_union(mask, 0.5, ORIGIN)
    assert shapely.union_all(polys).symmetric_difference(truth).area < 1e-9
    parts = shapely.normalize(shapely.simplify(shapely.get_parts(truth), 0.0))  # same pieces
    assert sorted(p.wkt for p in polys) == sorted(p.wkt for p in parts)
    keys = [p.bounds for p in polys]
    assert keys == sorted(keys)
    for p in polys:  # every vertex is a corner
        for ring in [p.exterior, *p.interiors]:
            xy = np.asarray(ring.coords)[:-1]
            turn = np.roll(xy, -1, axis=0) - 2 * xy + np.roll(xy, 1, axis=0)
            assert np.all(np.abs(turn).sum(axis=1) > 0)


def test_vectorize_large_grid_is_fast():
    rng = np.random.default_rng(0)
    mask = np.zeros((2000, 2000), dtype=bool)
    mask[:, :5] = mask[:5, :] = mask[-5:, :] = mask[:, -5:] = True
    mask[::100, :] = True
    mask[:, ::150] = True
    mask |= rng.random(mask.shape) < 0.002
    start = time.perf_counter()
    polys = vectorize(mask, RES, ORIGIN)
    assert time.perf_counter() - start < 3.0
    assert sum(p.area for p in polys) == pytest.approx(mask.sum() * RES**2)


# --- decode_image -------------------------------------------------------------------------


def test_decode_same_array_from_pgm_p5_p2_and_png(scene):
    mask, _ = scene
    gray = np.where(mask, 0, 254).astype(np.uint8)
    gray[-1, :] = 205
    gray[-2, :] = np.arange(W)
    decoded = [decode_image(data, "map") for data in (p5(gray), p2(gray), png(gray))]
    for g, alpha in decoded:
        assert alpha is None
        assert g.dtype == np.float64 and g.shape == (H, W)
        np.testing.assert_array_equal(g, gray)
    rgb, _ = decode_image(png(np.dstack([gray] * 3)), "map.png")
    np.testing.assert_array_equal(rgb, gray)


def test_decode_colour_alpha_and_16_bit():
    rgba = np.zeros((2, 3, 4), dtype=np.uint8)
    rgba[..., 0], rgba[..., 1], rgba[..., 2], rgba[..., 3] = 30, 60, 90, 255
    rgba[1, 2, 3] = 10
    gray, alpha = decode_image(png(rgba), "map.png")
    np.testing.assert_allclose(gray, 60.0)  # the mean of the colour channels
    assert alpha[1, 2] == 10 and alpha[0, 0] == 255
    la, alpha = decode_image(png(np.dstack([rgba[..., 0], rgba[..., 3]]), "LA"), "map.png")
    np.testing.assert_array_equal(la, 30.0)
    assert alpha[1, 2] == 10
    values = np.arange(12, dtype=np.uint16).reshape(3, 4) * 20
    g16, _ = decode_image(p5(values * 257, maxval=65535), "map16.pgm")
    np.testing.assert_array_equal(g16, values)
    wide = np.array([[1, 256, 4660, 65535]], dtype=np.uint16)  # 4660 = 0x1234
    for data in (p5(wide, maxval=65535), p2(wide, maxval=65535), png(wide)):  # PNG: mode I;16
        g16, _ = decode_image(data, "map16")
        np.testing.assert_allclose(g16, wide * 255.0 / 65535.0)
    g16, _ = decode_image(p5(np.array([[0, 300, 600]]), maxval=600), "map.pgm")
    np.testing.assert_array_equal(g16, [[0.0, 127.5, 255.0]])
    g2, _ = decode_image(p2(np.array([[0, 500, 1000]]), maxval=1000), "map.pgm")
    np.testing.assert_array_equal(g2, [[0.0, 127.5, 255.0]])


@pytest.mark.parametrize(
    "data",
    [
        p5(np.zeros((4, 5)))[:-1],  # truncated raster
        p5(np.zeros((4, 5)))[:6],  # truncated header
        p2(np.zeros((4, 5)))[:-4],
        p2(np.array([[3, 300]])),  # sample above maxval
        b"P2 2 1 255\n3 x\n",
        b"this is not an image",
        b"",
        png(np.zeros((4, 5), dtype=np.uint8))[:40],
    ],
)
def test_decode_rejects_bad_data(data):
    with pytest.raises(InvalidMapError) as err:
        decode_image(data, "broken.pgm")
    assert err.value.field == "image" and err.value.file == "broken.pgm"
    assert "unreadable image" in str(err.value)


# --- classify -----------------------------------------------------------------------------

GRADIENT = np.arange(256, dtype=np.float64).reshape(16, 16)


def reference(p, negate, occupied, free):
    occ = p / 255 if negate else (255 - p) / 255
    return 1 if occ > occupied else 0 if occ < free else -1


@pytest.mark.parametrize("negate", [False, True])
@pytest.mark.parametrize("occupied,free", [(0.65, 0.196), (0.9, 0.1), (0.5, 0.25), (1.0, 0.0)])
def test_trinary_thresholds_follow_the_formula(negate, occupied, free):
    cells = classify(GRADIENT, None, negate=negate, occupied_thresh=occupied, free_thresh=free, mode="trinary")
    assert cells.dtype == np.int8 and cells.shape == GRADIENT.shape
    expected = [reference(p, negate, occupied, free) for p in GRADIENT.ravel()]
    assert cells.ravel().tolist() == expected


@pytest.mark.parametrize("occupied", [0.65, 0.8, 0.55])
def test_negate_swaps_occupied_and_free(occupied):
    kw = {"occupied_thresh": occupied, "free_thresh": 1 - occupied, "mode": "trinary"}
    plain = classify(GRADIENT, None, negate=False, **kw)
    negated = classify(GRADIENT, None, negate=True, **kw)
    np.testing.assert_array_equal(plain == 1, negated == 0)
    np.testing.assert_array_equal(plain == 0, negated == 1)
    np.testing.assert_array_equal(negated, classify(255 - GRADIENT, None, negate=False, **kw))
    assert (plain == 0).any() and (plain == 1).any()


def test_scale_mode_partial_and_transparent_cells_are_unknown():
    gray = np.array([[0.0, 100.0, 254.0, 0.0]])
    alpha = np.array([[255.0, 255.0, 255.0, 254.0]])
    kw = {"negate": False, "occupied_thresh": 0.65, "free_thresh": 0.196, "mode": "scale"}
    assert classify(gray, alpha, **kw).tolist() == [[1, -1, 0, -1]]
    assert classify(gray, None, **kw).tolist() == [[1, -1, 0, 1]]
    assert classify(gray, alpha, **{**kw, "mode": "trinary"}).tolist() == [[1, -1, 0, 1]]


def test_raw_mode():
    values = np.array([[0, 1, 19, 20, 50, 65, 66, 99, 100, 101, 255]], dtype=np.float64)
    for negate in (False, True):  # raw ignores negate
        cells = classify(values, None, negate=negate, occupied_thresh=0.65, free_thresh=0.196, mode="raw")
        assert cells.tolist() == [[0, 0, 0, -1, -1, -1, 1, 1, 1, -1, -1]]


@pytest.mark.parametrize(
    "kw,field",
    [
        ({"mode": "foo"}, "mode"),
        ({"free_thresh": 0.7}, "free_thresh"),
        ({"free_thresh": -0.1}, "free_thresh"),
        ({"occupied_thresh": 1.5}, "occupied_thresh"),
        ({"occupied_thresh": "high"}, "occupied_thresh"),
        ({"free_thresh": float("nan")}, "free_thresh"),
    ],
)
def test_classify_rejects_bad_parameters(kw, field):
    args = {"negate": False, "occupied_thresh": 0.65, "free_thresh": 0.196, "mode": "trinary"}
    with pytest.raises(InvalidMapError) as err:
        classify(GRADIENT, None, **{**args, **kw}, file="map.yaml")
    assert err.value.field == field and err.value.file == "map.yaml"


# --- grid_obstacles -----------------------------------------------------------------------


def test_single_top_left_pixel_maps_to_top_left_of_extent():
    gray = np.full((5, 7), 254, dtype=np.uint8)
    gray[0, 0] = 0
    polys, info = grid_obstacles(meta(), p5(gray), file="map.yaml", image_name="map.pgm")
    xmin, ymin, xmax, ymax = info["extent"]
    assert info["extent"] == pytest.approx([-1.0, 2.0, -1.0 + 7 * RES, 2.0 + 5 * RES])
    assert len(polys) == 1
    assert polys[0].bounds == pytest.approx((xmin, ymax - RES, xmin + RES, ymax))


def test_grid_obstacles_scene_and_unknown_policy(scene):
    mask, shapes = scene
    gray = np.where(mask, 0, 254).astype(np.uint8)
    gray[30:40, 50:60] = 205  # ROS's unknown gray, partly overlapping nothing
    gray[0:3, 0:20] = 205  # and partly overlapping an obstacle
    unknown = (gray == 205).sum()
    data = png(gray)
    as_obstacle, info = grid_obstacles(meta(image="map.png"), data, file="map.yaml", image_name="map.png")
    as_free, info_free = grid_obstacles(
        meta(image="map.png"), data, file="map.yaml", image_name="map.png", unknown="free"
    )
    assert info == info_free
    assert info["width"] == W and info["height"] == H
    assert info["resolution"] == RES and info["origin"] == list(ORIGIN)
    assert info["unknown_cells"] == unknown
    assert info["occupied_cells"] == (mask & (gray == 0)).sum()
    area = sum(p.area for p in as_obstacle) - sum(p.area for p in as_free)
    assert area == pytest.approx(unknown * RES**2)
    truth = shapely.union_all([*shapes, cell_box(H, 30, 40, 50, 60), cell_box(H, 0, 3, 0, 20)])
    assert shapely.union_all(as_obstacle).symmetric_difference(truth).area < 1e-9


def test_grid_obstacles_negate_and_defaults(scene):
    mask, _ = scene
    inverted = np.where(mask, 255, 0).astype(np.uint8)
    polys, info = grid_obstacles(
        meta(negate=1, mode="trinary", occupied_thresh=0.65, free_thresh=0.196),
        p2(inverted),
        file="m.yaml",
        image_name="m.pgm",
    )
    plain, _ = grid_obstacles(meta(), p5(255 - inverted), file="m.yaml", image_name="m.pgm")
    assert [p.wkt for p in polys] == [p.wkt for p in plain]
    assert info["occupied_cells"] == mask.sum() and info["unknown_cells"] == 0


@pytest.mark.parametrize(
    "change,field",
    [
        ({"origin": [-1.0, 2.0, 0.3]}, "origin"),
        ({"origin": [-1.0, 2.0]}, "origin"),
        ({"origin": [-1.0, "2", 0]}, "origin"),
        ({"resolution": -0.05}, "resolution"),
        ({"resolution": 0}, "resolution"),
        ({"resolution": "0.05"}, "resolution"),
        ({"resolution": True}, "resolution"),
        ({"cell_size": 1}, "cell_size"),
        ({"mode": "foo"}, "mode"),
        ({"negate": 2}, "negate"),
        ({"negate": "yes"}, "negate"),
        ({"free_thresh": 0.9}, "free_thresh"),
        ({"image": 3}, "image"),
    ],
)
def test_grid_obstacles_rejects_bad_yaml(change, field):
    gray = np.zeros((3, 4), dtype=np.uint8)
    with pytest.raises(InvalidMapError) as err:
        grid_obstacles(meta(**change), p5(gray), file="map.yaml", image_name="map.pgm")
    assert err.value.field == field and err.value.file == "map.yaml"
    if field == "cell_size":
        assert "unknown key" in str(err.value)
    if change.get("origin", [0, 0, 0])[-1] == 0.3:
        assert "rotated" in str(err.value)


@pytest.mark.parametrize("key", ["image", "resolution", "origin"])
def test_grid_obstacles_requires_keys(key):
    spec = meta()
    del spec[key]
    with pytest.raises(InvalidMapError) as err:
        grid_obstacles(spec, p5(np.zeros((3, 4))), file="map.yaml", image_name="map.pgm")
    assert err.value.field == key


def test_grid_obstacles_bad_image_and_bad_policy():
    with pytest.raises(InvalidMapError) as err:
        grid_obstacles(meta(), b"P5\n4 3\n255\n\x00", file="map.yaml", image_name="map.pgm")
    assert err.value.field == "image" and err.value.file == "map.pgm"
    with pytest.raises(BearnavError) as err:
        grid_obstacles(meta(), p5(np.zeros((3, 4))), file="map.yaml", image_name="map.pgm", unknown="maybe")
    assert err.value.field == "unknown"


@pytest.mark.parametrize("special", ["device", "fifo", "folder"])
def test_a_grid_image_that_is_not_a_regular_file_is_one_line_naming_it(cli, tmp_path, special):
    """Issue 27 item 5: ``image: /dev/zero`` ran out of memory and a FIFO hung for ever."""
    import os

    target = {"device": "/dev/zero", "fifo": str(tmp_path / "map.pgm"), "folder": str(tmp_path / "pics")}[special]
    if special == "fifo":
        os.mkfifo(target)
    elif special == "folder":
        os.mkdir(target)
    grid = tmp_path / "grid.yaml"
    grid.write_text(
        f"image: {target}\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\n"
    )
    result = cli("map", grid, "--goal", "1,1", "-o", tmp_path / "map.json")
    assert result.exit_code == 3, result.output
    line = result.output.strip()
    assert len(line.splitlines()) == 1 and target in line and "image" in line, line
    assert not (tmp_path / "map.json").exists()
