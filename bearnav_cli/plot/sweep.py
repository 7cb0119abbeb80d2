"""The success figure of ``bearnav sweep``: success against bearing noise, a panel per map and dynamics."""

from __future__ import annotations

from typing import Any, Sequence

import matplotlib.pyplot as plt
from matplotlib.lines import Line2D

from bearnav_cli.palette import PALETTE

__all__ = ["sweep_plot"]


#: Colours and markers of the success figure's fields of view, in the order they first appear.
#: One colour per field of view, the palette's Okabe–Ito colours in a fixed order.
_SWEEP_COLORS = tuple(
    PALETTE[name]
    for name in ("blue", "orange", "bluish green", "vermillion", "reddish purple", "sky blue", "yellow", "black")
)
_SWEEP_MARKERS = "osD^vP*X"
_SWEEP_STYLES = ("-", "--", ":", "-.")


def sweep_plot(panels: Sequence[Any], title: str | None = None) -> plt.Figure:
    """Success against bearing noise: a panel per map and dynamics, a colour per field of view.

    Draws the data of :func:`bearnav_cli.sweep.success_curves` and computes nothing. Lines of one
    field of view that differ in another axis of the sweep (the tags, the estimator ...) differ
    in style: solid with filled markers for the first variant, dashed with open ones for the next.

    Parameters
    ----------
    panels : sequence of Panel
        Each with ``map``, ``dynamics``, ``tags`` (a caption) and ``lines`` (dicts with ``fov``,
        ``variant``, ``variant_index``, ``noise`` in degrees and ``success`` in [0, 1]).
    title : str, optional
        The figure's title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    maps = list(dict.fromkeys(p.map for p in panels)) or [""]
    dynamics = list(dict.fromkeys(p.dynamics for p in panels)) or [""]
    fovs = list(dict.fromkeys(line["fov"] for p in panels for line in p.lines))
    color = {f: _SWEEP_COLORS[i % len(_SWEEP_COLORS)] for i, f in enumerate(fovs)}
    marker = {f: _SWEEP_MARKERS[i % len(_SWEEP_MARKERS)] for i, f in enumerate(fovs)}
    ncol = 2 if len(dynamics) == 1 else 4
    n_handles = len(fovs) + len({line["variant_index"] for p in panels for line in p.lines if line["variant"]})
    legend_rows = -(-n_handles // ncol)
    height = 3.1 * len(maps) + 0.6 + 0.22 * legend_rows
    fig, axes = plt.subplots(
        len(maps),
        len(dynamics),
        figsize=(max(6.4, 5.2 * len(dynamics)), height),
        sharex=True,
        sharey=True,
        squeeze=False,
    )
    variants: dict[int, str] = {}
    noises: set[float] = set()
    for panel in panels:
        ax = axes[maps.index(panel.map), dynamics.index(panel.dynamics)]
        for line in panel.lines:
            k = line["variant_index"]
            variants.setdefault(k, line["variant"])
            noises.update(line["noise"])
            ax.plot(
                line["noise"],
                [100 * v for v in line["success"]],
                ls=_SWEEP_STYLES[k % len(_SWEEP_STYLES)],
                marker=marker[line["fov"]],
                ms=4,
                lw=1.3,
                color=color[line["fov"]],
                mfc=color[line["fov"]] if k == 0 else "white",
            )
        caption = f"{panel.map}, {panel.dynamics}" + (f": {panel.tags}" if panel.tags else "")
        ax.set_title(caption, fontsize=9)
    for ax in axes.flat:
        ax.set_ylim(0, 102)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=8)
        if noises:
            ax.set_xticks(sorted(noises))
    for ax in axes[:, 0]:
        ax.set_ylabel("runs reaching the goal (%)", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("bearing noise (°; σ, or the bound of a bounded noise)", fontsize=8)
    handles = [Line2D([], [], color=color[f], marker=marker[f], ms=4, label=f"{f:g}° field of view") for f in fovs]
    handles += [
        Line2D(
            [],
            [],
            color="black",
            ls=_SWEEP_STYLES[k % len(_SWEEP_STYLES)],
            marker="o",
            ms=4,
            mfc="black" if k == 0 else "white",
            label=label,
        )
        for k, label in sorted(variants.items())
        if label
    ]
    if handles:
        fig.legend(handles=handles, loc="lower center", ncol=min(ncol, len(handles)), fontsize=8, frameon=False)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, (0.22 * legend_rows + 0.1) / height, 1, 1 - 0.3 / height))
    return fig
