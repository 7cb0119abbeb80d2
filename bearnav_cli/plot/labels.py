"""Label placement: short texts beside points wherever they collide with nothing, and their legend keys.

Boxes are measured in display space once the layout is settled (:func:`bearnav_cli.plot.frame.finish`),
so a label covers no other label, marker, legend or colour bar and stays in the figure.
"""

from __future__ import annotations

from typing import Any, Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib import patheffects

from bearnav_cli.datatypes import Map
from bearnav_cli.palette import PALETTE, ROLE_COLORS
from bearnav_cli.plot.style import LANDMARK_COLOR

__all__ = [
    "CENTRED",
    "CORNERS",
    "HALO",
    "label_key",
    "label_landmarks",
    "LANDMARKS_LABEL",
    "MARKER_HALF",
    "place_labels",
]


#: Legend label of the map's landmarks; their ids are written beside them where they fit.
LANDMARKS_LABEL = "landmarks (ids beside them where they fit)"
#: The white outline behind every label, so that it reads over fills, arrows and lines.
HALO = (patheffects.withStroke(linewidth=2, foreground=PALETTE["white"]),)
#: A label's places around its point: (dx, dy) offset in points, horizontal and vertical alignment.
CORNERS = (
    (3.5, 3.5, "left", "bottom"),
    (-3.5, 3.5, "right", "bottom"),
    (3.5, -3.5, "left", "top"),
    (-3.5, -3.5, "right", "top"),
)
#: Half the side of the box a marker of ``avoid`` keeps clear (points): a landmark triangle's, so that a
#: label at a corner touches its own marker but covers no other.
MARKER_HALF = 3.0
#: Centred on its point, else nudged a little up, down, right or left (a cell's index inside its region).
CENTRED = (
    (0, 0, "center", "center"),
    (0, 4, "center", "center"),
    (0, -4, "center", "center"),
    (5, 0, "center", "center"),
    (-5, 0, "center", "center"),
)


def _boxes(boxes: Sequence[Any]) -> np.ndarray:
    """Bounding boxes (matplotlib ``Bbox`` or ``(x0, y0, x1, y1)``) as an (n, 4) array."""
    rows = [(b.x0, b.y0, b.x1, b.y1) if hasattr(b, "x0") else tuple(b) for b in boxes]
    return np.array(rows, float).reshape(-1, 4)


def place_labels(
    ax: plt.Axes,
    texts: Sequence[str],
    points: Any,
    *,
    gid: str,
    label: str | None = None,
    avoid: Any = None,
    offsets: Sequence[tuple] = CORNERS,
    every: bool = False,
    replace: bool = True,
    **style: Any,
) -> list:
    """Write short texts beside points, leaving out those that would collide: every figure's one label placement.

    Each text tries ``offsets`` in turn and takes the first place whose box meets no visible text
    of the axes (an earlier call's labels too, so what is labelled first wins), no marker around
    ``avoid``, no legend or other axes (a colour bar) and stays in the figure. Boxes are the
    renderer's window extents as the figure stands now: call it after the layout is settled
    (:func:`figure_for` does).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to write into (map units on both axes).
    texts : sequence of str
        The labels, in order of priority.
    points : array_like, shape (n, 2)
        Where each label belongs (map units).
    gid : str
        The gid of every text written (what a later call with this gid replaces).
    label : str, optional
        The legend label each text carries (:func:`label_key` draws its legend entry).
    avoid : array_like, shape (m, 2), optional
        Marker positions (map units) no label may cover (a box of :data:`MARKER_HALF` points around each).
    offsets : sequence of (dx, dy, ha, va)
        The places to try: offsets in points from the point and the text's alignment
        (:data:`CORNERS` beside a marker, :data:`CENTRED` on a spot).
    every : bool
        Keep a text that fits nowhere, at its first place (labels may then collide).
    replace : bool
        Remove the texts an earlier call wrote with this ``gid`` first (a redraw after the layout
        changed); False adds to them.
    **style
        Text properties (default 6.5 pt, black, with a white :data:`HALO`).

    Returns
    -------
    list of matplotlib.text.Annotation
        The texts written (those that fit, or all with ``every``).
    """
    for text in [t for t in ax.texts if replace and t.get_gid() == gid]:
        text.remove()
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    ax.apply_aspect()
    style = {"fontsize": 6.5, "color": ROLE_COLORS["text"], "zorder": 8, "path_effects": list(HALO)} | style
    taken = [t.get_window_extent(renderer) for t in ax.texts if t.get_visible() and t.get_text()]
    taken += [other.get_window_extent(renderer) for other in fig.axes if other is not ax]
    if ax.get_legend() is not None:
        taken.append(ax.get_legend().get_window_extent(renderer))
    r = MARKER_HALF * fig.dpi / 72
    marks = ax.transData.transform(np.asarray(avoid, float).reshape(-1, 2)) if avoid is not None else np.zeros((0, 2))
    boxes = np.vstack([_boxes(taken), np.column_stack([marks - r, marks + r])])
    page = fig.bbox
    placed = []
    for name, point in zip(texts, np.asarray(points, float).reshape(-1, 2), strict=True):
        text = ax.annotate(
            str(name),
            point,
            xytext=offsets[0][:2],
            textcoords="offset points",
            gid=gid,
            label=label or "_label",
            ha=offsets[0][2],
            va=offsets[0][3],
            **style,
        )
        for dx, dy, ha, va in offsets:
            text.xyann = (dx, dy)
            text.set(ha=ha, va=va)
            b = text.get_window_extent(renderer)
            inside = page.x0 <= b.x0 and b.x1 <= page.x1 and page.y0 <= b.y0 and b.y1 <= page.y1
            if inside and not np.any(
                (b.x0 < boxes[:, 2]) & (boxes[:, 0] < b.x1) & (b.y0 < boxes[:, 3]) & (boxes[:, 1] < b.y1)
            ):
                break
        else:
            if not every:
                text.remove()
                continue
            text.xyann = offsets[0][:2]
            text.set(ha=offsets[0][2], va=offsets[0][3])
            b = text.get_window_extent(renderer)
        boxes = np.vstack([boxes, [[b.x0, b.y0, b.x1, b.y1]]])
        placed.append(text)
    return placed


def label_key(ax: plt.Axes, sample: str, label: str, **style: Any) -> None:
    """A legend entry for labels: ``sample`` drawn as text in the labels' ``style`` (colour, font style).

    An empty line whose marker is the text, so that :func:`figure_for`'s legend shows it like any
    other mark; a second call with the same ``label`` adds nothing.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes whose legend gets the entry.
    sample : str
        The text the key shows (e.g. ``"12"`` for cell indices).
    label : str
        The entry's text (the label :func:`place_labels` gives the texts it stands for).
    **style
        ``color`` and ``fontstyle`` (``"italic"``) of those texts.
    """
    if label in [h.get_label() for h in ax.lines]:
        return
    weight = r"\mathit" if style.get("fontstyle") == "italic" else r"\mathrm"
    ax.plot(
        [],
        [],
        ls="none",
        marker=f"${weight}{{{sample}}}$",
        markersize=9 if len(sample) < 3 else 12,
        color=style.get("color", ROLE_COLORS["text"]),
        label=label,
        gid="label-key",
    )


def label_landmarks(ax: plt.Axes, map_: Map, *, every: bool = False) -> list:
    """Write landmark ids beside their markers (:func:`place_labels`); unless ``every``, skip those that would collide.

    Each label tries the four corners around its landmark and takes the first whose text box meets no
    earlier label and no landmark marker. Call it after the layout is settled.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (map units on both axes).
    map_ : Map
        The map whose ``landmark_ids`` are written at its ``landmarks``.
    every : bool
        Label every landmark, at its first corner, even where labels collide.

    Returns
    -------
    list of matplotlib.text.Annotation
        The label artists (gid ``landmark-label``, legend label :data:`LANDMARKS_LABEL`).
    """
    return place_labels(
        ax,
        map_.landmark_ids,
        map_.landmarks,
        gid="landmark-label",
        label=LANDMARKS_LABEL,
        avoid=map_.landmarks,
        every=every,
        color=LANDMARK_COLOR,
    )
