"""ROS ``map_server`` occupancy grids turned into obstacle polygons.

Pure functions: the caller reads the YAML and the image file and passes their content in.
The pipeline is :func:`decode_image` (bytes to a gray array), :func:`classify` (gray to
occupied / free / unknown, with the ROS ``map_server`` / nav2 ``map_io`` semantics) and
:func:`vectorize` (a boolean pixel mask to the exact union of its pixels, in world
coordinates); :func:`grid_obstacles` chains them from a parsed map YAML.
"""

from __future__ import annotations

import io
import math
import numbers
import re

import numpy as np
import shapely

from bearnav_cli.errors import InvalidMapError, InvalidParamsError

__all__ = [
    "classify",
    "decode_image",
    "FREE",
    "grid_obstacles",
    "MODES",
    "OCCUPIED",
    "UNKNOWN",
    "vectorize",
]

OCCUPIED, FREE, UNKNOWN = 1, 0, -1
MODES = ("trinary", "scale", "raw")
_DEFAULTS = {"negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196, "mode": "trinary"}
_KEYS = ("image", "resolution", "origin", *_DEFAULTS)
_SEP = rb"(?:\s|#[^\r\n]*)+"
_PGM_HEADER = re.compile(rb"\AP([25])" + (_SEP + rb"(\d+)") * 3 + rb"\s")


def decode_image(data: bytes, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Decode an occupancy grid image.

    PGM (binary ``P5`` and ASCII ``P2``, 8 or 16 bit) is parsed here; anything else
    (PNG, ...) goes through Pillow. The gray level of a colour pixel is the mean of its
    colour channels, as ROS ``map_server`` computes it.

    Parameters
    ----------
    data : bytes
        The content of the image file.
    name : str
        The image file name, used in error messages.

    Returns
    -------
    gray : numpy.ndarray
        float64, shape (H, W), values in [0, 255]; row 0 is the top row of the image.
    alpha : numpy.ndarray or None
        float64, shape (H, W), values in [0, 255] (255 = opaque), or None if the image
        has no alpha channel.

    Raises
    ------
    InvalidMapError
        ``field="image"``: the data is not a readable, non-empty image.
    """
    match = _PGM_HEADER.match(data)
    if match is not None:
        gray, alpha = _decode_pgm(data, match, name), None
    else:
        gray, alpha = _decode_pillow(data, name)
    if gray.size == 0:
        raise InvalidMapError("unreadable image (empty)", file=name, field="image")
    return gray, alpha


def _decode_pgm(data: bytes, match: re.Match, name: str) -> np.ndarray:
    def fail(reason: str) -> InvalidMapError:
        return InvalidMapError(f"unreadable image ({reason})", file=name, field="image")

    kind, width, height, maxval = match.group(1), *(int(g) for g in match.groups()[1:])
    if not 0 < maxval < 65536:
        raise fail(f"PGM maxval {maxval} not in 1..65535")
    count, body = width * height, data[match.end() :]
    if kind == b"5":
        dtype = np.dtype(">u2") if maxval > 255 else np.dtype("u1")
        if len(body) < count * dtype.itemsize:
            raise fail("truncated PGM")
        values = np.frombuffer(body, dtype=dtype, count=count)
    else:
        tokens = re.sub(rb"#[^\r\n]*", b"", body).split()
        if len(tokens) < count:
            raise fail("truncated PGM")
        if not all(token.isdigit() for token in tokens[:count]):
            raise fail("non-numeric PGM sample")
        values = np.array(tokens[:count]).astype(np.int64)
    if values.size and values.max() > maxval:
        raise fail("PGM sample above maxval")
    return values.reshape(height, width).astype(np.float64) * 255.0 / maxval


def _decode_pillow(data: bytes, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as img:
            img.load()
            if img.mode in ("I;16", "I;16B", "I;16L", "I"):
                raw = np.asarray(img).astype(np.float64)
                return np.clip(raw, 0, 65535) * 255.0 / 65535.0, None
            if img.mode not in ("L", "LA", "RGB", "RGBA") or "transparency" in img.info:
                has_alpha = "A" in img.getbands() or "transparency" in img.info
                img = img.convert("RGBA" if has_alpha else "RGB")
            pixels, mode = np.asarray(img, dtype=np.float64), img.mode
    except Exception as exc:  # Pillow raises many types on corrupt data
        reason = (str(exc).splitlines() or [type(exc).__name__])[0][:80]
        if isinstance(exc, UnidentifiedImageError):
            reason = "not PGM nor a format Pillow knows"
        raise InvalidMapError(f"unreadable image ({reason})", file=name, field="image") from exc
    if pixels.ndim == 2:
        return pixels, None
    if mode == "LA":
        return pixels[..., 0], pixels[..., 1]
    gray = pixels[..., :3].mean(axis=2)
    return gray, (pixels[..., 3] if mode == "RGBA" else None)


def classify(
    gray: np.ndarray,
    alpha: np.ndarray | None,
    *,
    negate: bool,
    occupied_thresh: float,
    free_thresh: float,
    mode: str,
    file: str | None = None,
) -> np.ndarray:
    """Classify the pixels of an occupancy image as ROS ``map_server`` does.

    In ``trinary`` and ``scale`` modes the occupancy of a pixel of gray level ``p`` is
    ``occ = p / 255`` if ``negate`` else ``(255 - p) / 255``; ``occ > occupied_thresh`` is
    occupied, ``occ < free_thresh`` free, anything else unknown. In ``scale`` mode ROS keeps
    the in-between values as a partial occupancy; we have no use for probabilities, so they
    are unknown too (the caller's unknown policy decides), and a pixel with ``alpha < 255``
    is unknown. Unlike ROS, alpha is not averaged into the gray level in ``trinary`` mode.
    In ``raw`` mode the value ``v = round(p)`` is the occupancy in percent (``negate`` is
    ignored): 0 is free, 100 occupied, 1..99 compared with the thresholds as ``v / 100``,
    and anything above 100 (e.g. 255) unknown.

    Parameters
    ----------
    gray : numpy.ndarray
        Shape (H, W), gray levels in [0, 255].
    alpha : numpy.ndarray or None
        Shape (H, W), alpha in [0, 255] (255 = opaque), or None.
    negate : bool
        Whether white means occupied.
    occupied_thresh, free_thresh : float
        Thresholds on the occupancy, ``0 <= free_thresh < occupied_thresh <= 1``.
    mode : str
        ``"trinary"``, ``"scale"`` or ``"raw"``.
    file : str, optional
        The file named in error messages.

    Returns
    -------
    numpy.ndarray
        int8, shape (H, W): 1 occupied, 0 free, -1 unknown.

    Raises
    ------
    InvalidMapError
        ``field`` is ``mode``, ``free_thresh`` or ``occupied_thresh``.
    """
    if mode not in MODES:
        raise InvalidMapError(f"must be one of {', '.join(MODES)}, got {mode!r}", file=file, field="mode")
    free = _number(free_thresh, "free_thresh", file)
    occupied = _number(occupied_thresh, "occupied_thresh", file)
    for value, field in ((free, "free_thresh"), (occupied, "occupied_thresh")):
        if not 0.0 <= value <= 1.0:
            raise InvalidMapError(f"must be in [0, 1], got {value}", file=file, field=field)
    if free >= occupied:
        raise InvalidMapError(
            f"must be less than occupied_thresh ({occupied}), got {free}",
            file=file,
            field="free_thresh",
        )
    gray = np.asarray(gray, dtype=np.float64)
    if alpha is not None and np.shape(alpha) != gray.shape:
        raise InvalidMapError("alpha and gray shapes differ", file=file, field="image")
    out = np.full(gray.shape, UNKNOWN, dtype=np.int8)
    if mode == "raw":
        value = np.rint(gray)
        occ = value / 100.0
        partial = (value > 0) & (value < 100)
        out[(value == 0) | (partial & (occ < free))] = FREE
        out[(value == 100) | (partial & (occ > occupied))] = OCCUPIED
        return out
    occ = gray / 255.0 if negate else (255.0 - gray) / 255.0
    out[occ < free] = FREE
    out[occ > occupied] = OCCUPIED
    if mode == "scale" and alpha is not None:
        out[np.asarray(alpha) < 255] = UNKNOWN
    return out


def vectorize(blocked: np.ndarray, resolution: float, origin: tuple[float, float]) -> list[shapely.Polygon]:
    """Turn a pixel mask into the exact union of its pixels, in world coordinates.

    Pixel (row ``r``, column ``c``) of an (H, W) mask covers
    ``x in [ox + c * res, ox + (c + 1) * res]`` and
    ``y in [oy + (H - 1 - r) * res, oy + (H - r) * res]``: row 0 is the top of the map and
    the origin is the lower-left corner of the lower-left pixel (ROS convention).
    The boundary of the mask is traced into rings in integer pixel coordinates (corners
    only, so no collinear vertices), holes are given to the smallest shell around them and
    the polygons are only then scaled to the world: the result is exact. Pixels touching at
    a corner only are kept in separate polygons, or as a hole touching its shell.

    Parameters
    ----------
    blocked : numpy.ndarray
        bool, shape (H, W).
    resolution : float
        Size of a pixel side, in metres.
    origin : tuple of float
        ``(ox, oy)``, world position of the lower-left corner of the grid, in metres.

    Returns
    -------
    list of shapely.Polygon
        Valid pixel-aligned polygons (possibly with holes), normalized, sorted by
        ``(minx, miny, maxx, maxy, area)``; an empty list for an empty mask.
    """
    mask = np.asarray(blocked, dtype=bool)
    if not mask.any():
        return []
    sx, sy, ex, ey, step = _boundary(mask)
    ring, walk, first, pinched = _trace(sx, sy, ex, ey, step, mask.shape[1])
    area = np.bincount(ring, weights=sx * ey - ex * sy)  # twice the area, > 0 for shells (CCW)
    shell = area > 0
    res, (ox, oy) = float(resolution), (float(origin[0]), float(origin[1]))
    # Rounding to 1e-12 m makes 3 * 0.05 read 0.15, as the map author wrote it.
    coords = np.round(np.column_stack([sx[walk] * res + ox, sy[walk] * res + oy]), 12)
    rings = shapely.linearrings(coords, indices=ring[walk])
    # a hole goes to the smallest shell around the blocked pixel left of its first segment
    dx, dy = np.sign(ex - sx)[first] * 0.5, np.sign(ey - sy)[first] * 0.5
    inside = shapely.points((sx[first] + dx - dy) * res + ox, (sy[first] + dy + dx) * res + oy)
    shells = np.flatnonzero(shell)
    hole, cand = shapely.STRtree(shapely.polygons(rings[shells])).query(inside[~shell], predicate="within")
    pick = np.lexsort((area[shells][cand], hole))
    keep = pick[np.unique(hole[pick], return_index=True)[1]]
    owner = np.empty(area.size, dtype=np.int64)
    owner[shells] = np.arange(shells.size)
    owner[np.flatnonzero(~shell)[hole[keep]]] = cand[keep]
    order = np.lexsort((~shell, owner))
    polys = shapely.polygons(rings[order], indices=owner[order])
    # a ring through a corner touching pixels may touch itself there: make it valid
    suspect = np.zeros(shells.size, dtype=bool)
    suspect[owner[pinched]] = True
    suspect[suspect] = ~shapely.is_valid(polys[suspect])
    if suspect.any():
        fixed = shapely.get_parts(shapely.make_valid(polys[suspect], method="structure"))
        polys = np.concatenate([polys[~suspect], fixed])
    polys = shapely.normalize(polys)
    order = np.lexsort((shapely.area(polys), *shapely.bounds(polys).T[::-1]))
    return list(polys[order])


def _boundary(mask: np.ndarray) -> tuple[np.ndarray, ...]:
    """Directed boundary segments of a (H, W) mask, blocked pixels on their left.

    Returns start x, start y, end x, end y (pixel units, y up, origin at the lower-left
    corner) and the direction (0 east, 1 north, 2 west, 3 south), each of shape (N,).
    Segments are maximal: they end exactly at the corners of the boundary.
    """
    height = mask.shape[0]
    cells = np.zeros((mask.shape[0] + 2, mask.shape[1] + 2), dtype=np.int8)
    cells[1:-1, 1:-1] = mask
    above, below = cells[:-1, 1:-1], cells[1:, 1:-1]
    left, right = cells[1:-1, :-1], cells[1:-1, 1:]
    # code 2: blocked above (east) / on the left (north); 1: below (west) / on the right (south)
    line, x0, x1, code = _runs(np.where(above != below, above + 1, 0))
    east, hy = code == 2, height - line
    col, r0, r1, code = _runs(np.where(left != right, left + 1, 0).T)
    north = code == 2
    sx = np.concatenate([np.where(east, x0, x1), col])
    ex = np.concatenate([np.where(east, x1, x0), col])
    sy = np.concatenate([hy, height - np.where(north, r1, r0)])
    ey = np.concatenate([hy, height - np.where(north, r0, r1)])
    step = np.concatenate([np.where(east, 0, 2), np.where(north, 1, 3)])
    return sx, sy, ex, ey, step


def _runs(code: np.ndarray) -> tuple[np.ndarray, ...]:
    """Maximal runs of one non-zero value along the rows of ``code`` (L, N).

    Returns the row, start column, end column (exclusive) and value of each run.
    """
    width = code.shape[1] + 2
    flat = np.zeros((code.shape[0], width), dtype=np.int8)
    flat[:, 1:-1] = code
    flat = flat.ravel()
    cuts = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    start, end = cuts[:-1], cuts[1:]
    start, end = start[flat[start] != 0], end[flat[start] != 0]
    row = start // width
    return row, start - row * width - 1, end - row * width - 1, flat[start]


def _trace(sx, sy, ex, ey, step, width) -> tuple[np.ndarray, ...]:
    """Chain the (N,) boundary segments into rings.

    Each segment is followed by the one starting at its end, turning left where two start
    there (at a corner where pixels touch diagonally). Returns the ring of each segment,
    numbered 0..R-1, the segment indices in ring order (ring by ring), the first segment
    of each ring and whether each ring passes through such a corner.
    """
    vertex = (sy * (width + 1) + sx) * 4
    order = np.argsort(vertex + step)
    key = (vertex + step)[order]
    stop = (ey * (width + 1) + ex) * 4
    pos = np.searchsorted(key, stop)  # the first segment starting at the end of each one
    two = np.minimum(pos + 1, key.size - 1)
    two = (key[two] < stop + 4) & (two > pos)
    turn = two & (key[pos] != stop + (step + 1) % 4)
    nxt = order[pos + turn]
    # pointer jumping: the leader of a ring is its smallest segment ...
    idx = np.arange(key.size)
    leader, jump = idx, nxt
    while True:
        new = np.minimum(leader, leader[jump])
        if np.array_equal(new, leader):
            break
        leader, jump = new, jump[jump]
    # ... and list ranking gives the distance from every segment on to it
    dist = (idx != leader).astype(np.int64)
    jump = np.where(dist > 0, nxt, idx)
    while not np.array_equal(jump[jump], jump):
        dist += dist[jump]
        jump = jump[jump]
    is_leader = dist == 0
    ring = (np.cumsum(is_leader) - 1)[leader]
    length = np.bincount(ring)
    start = np.cumsum(length) - length
    walk = np.empty_like(idx)
    walk[start[ring] + (length[ring] - dist) % length[ring]] = idx
    pinched = np.zeros(length.size, dtype=bool)
    pinched[ring[two]] = True
    return ring, walk, np.flatnonzero(is_leader), pinched


def grid_obstacles(
    meta: dict, image: bytes, *, file: str, image_name: str, unknown: str = "obstacle"
) -> tuple[list[shapely.Polygon], dict]:
    """Obstacle polygons of a ROS ``map_server`` map.

    Parameters
    ----------
    meta : dict
        The parsed map YAML: ``image`` (str), ``resolution`` (m per pixel, > 0),
        ``origin`` (``[x, y, yaw]``, m and rad, yaw must be 0) are required; ``negate``
        (0/1, default 0), ``occupied_thresh`` (default 0.65), ``free_thresh`` (default
        0.196) and ``mode`` (default ``"trinary"``) are optional.
    image : bytes
        The content of the image file.
    file : str
        The YAML file name, used in error messages.
    image_name : str
        The image file name, used in error messages.
    unknown : str
        ``"obstacle"`` (default) or ``"free"``: what unknown cells become.

    Returns
    -------
    polygons : list of shapely.Polygon
        The blocked cells, as from :func:`vectorize`, in metres.
    info : dict
        ``width``, ``height`` (pixels), ``resolution`` (m), ``origin`` (``[x, y]``, m),
        ``occupied_cells``, ``unknown_cells`` (counts) and ``extent``
        (``[xmin, ymin, xmax, ymax]`` of the whole grid, m).

    Raises
    ------
    InvalidMapError
        The YAML or the image is malformed; ``field`` names the culprit.
    InvalidParamsError
        ``unknown`` is neither ``"obstacle"`` nor ``"free"``.
    """
    if unknown not in ("obstacle", "free"):
        raise InvalidParamsError(f"must be 'obstacle' or 'free', got {unknown!r}", field="unknown")
    if not isinstance(meta, dict):
        raise InvalidMapError("must be a mapping", file=file)
    extra = sorted(set(meta) - set(_KEYS), key=str)
    if extra:
        raise InvalidMapError("unknown key", file=file, field=str(extra[0]))
    for key in ("image", "resolution", "origin"):
        if key not in meta:
            raise InvalidMapError("missing required key", file=file, field=key)
    meta = {**_DEFAULTS, **meta}
    if not isinstance(meta["image"], str) or not meta["image"]:
        raise InvalidMapError("must be a non-empty string", file=file, field="image")
    res = _number(meta["resolution"], "resolution", file)
    if res <= 0:
        raise InvalidMapError(f"must be > 0, got {res}", file=file, field="resolution")
    origin = meta["origin"]
    if not isinstance(origin, (list, tuple)) or len(origin) != 3:
        raise InvalidMapError("must be [x, y, yaw]", file=file, field="origin")
    ox, oy, yaw = (_number(v, "origin", file) for v in origin)
    if yaw != 0:
        raise InvalidMapError("rotated grids (yaw != 0) are not supported", file=file, field="origin")
    negate = meta["negate"]
    if not isinstance(negate, int) or negate not in (0, 1):
        raise InvalidMapError(f"must be 0 or 1, got {negate!r}", file=file, field="negate")
    gray, alpha = decode_image(image, image_name)
    cells = classify(
        gray,
        alpha,
        negate=bool(negate),
        occupied_thresh=meta["occupied_thresh"],
        free_thresh=meta["free_thresh"],
        mode=meta["mode"],
        file=file,
    )
    blocked = cells == OCCUPIED
    if unknown == "obstacle":
        blocked |= cells == UNKNOWN
    height, width = cells.shape
    info = {
        "width": width,
        "height": height,
        "resolution": res,
        "origin": [ox, oy],
        "occupied_cells": int(np.count_nonzero(cells == OCCUPIED)),
        "unknown_cells": int(np.count_nonzero(cells == UNKNOWN)),
        "extent": [ox, oy, ox + width * res, oy + height * res],
    }
    return vectorize(blocked, res, (ox, oy)), info


def _number(value: object, field: str, file: str | None) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InvalidMapError(f"must be a number, got {value!r}", file=file, field=field)
    if not math.isfinite(value):
        raise InvalidMapError(f"must be finite, got {value!r}", file=file, field=field)
    return float(value)
