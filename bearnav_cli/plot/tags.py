"""Perception and tags (issue 11): where the perception rule fails, where to glue new tags, the tags figure.

The coverages and proposals are duck-typed (``perception.PerceptionCoverage``,
``tags.TagProposal``): this package computes nothing and imports neither.
"""

from __future__ import annotations

import math
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

from bearnav_cli.datatypes import Map
from bearnav_cli.palette import ROLE_COLORS
from bearnav_cli.plot.frame import figure_title, finish, legend_below, map_frame
from bearnav_cli.plot.labels import CORNERS, place_labels
from bearnav_cli.plot.style import LANDMARK_COLOR, axis_labels

__all__ = [
    "EXISTING_TAG_COLOR",
    "EXISTING_TAGS_LABEL",
    "label_tags",
    "PERCEPTION_FAIL_COLOR",
    "PERCEPTION_FAIL_FREE_COLOR",
    "plot_perception",
    "plot_tags",
    "PROPOSED_TAG_COLOR",
    "PROPOSED_TAGS_LABEL",
    "tags_figure",
]


PERCEPTION_FAIL_COLOR = ROLE_COLORS["perception fail"]
PERCEPTION_FAIL_FREE_COLOR = ROLE_COLORS["perception fail outside"]
EXISTING_TAG_COLOR = LANDMARK_COLOR
PROPOSED_TAG_COLOR = ROLE_COLORS["proposed tag"]


def _existing_tags(ax: plt.Axes, landmarks: Any, gid: str, label: str) -> None:
    """The tags a map already has, as vermillion triangles labelled ``label``."""
    lm = np.asarray(landmarks, float).reshape(-1, 2)
    ax.scatter(
        lm[:, 0],
        lm[:, 1],
        marker="^",
        s=40,
        color=EXISTING_TAG_COLOR,
        edgecolor=ROLE_COLORS["edge"],
        linewidths=0.5,
        zorder=6,
        gid=gid,
        label=label,
    )


def plot_perception(
    ax: plt.Axes, coverage: Any, *, free: bool = True, landmarks: bool = True, legend: bool = True
) -> plt.Axes:
    """Where the perception rule fails: small marks over the plan (issue 11; compute with ``perception``).

    Draw it over :func:`figure_for` of the plan (or :func:`plot_map` with ``landmarks=False``).

    Parameters
    ----------
    ax : Axes
        The axes to draw into (map units on both axes).
    coverage : PerceptionCoverage
        :func:`bearnav_cli.perception.perception_coverage` (duck-typed: ``failing_domain`` and
        ``failing_free`` (n, 2), ``fraction_domain``, ``fraction_free``, ``error_target``,
        ``landmarks`` (L, 2), ``fov_deg``, ``noise_deg``), so this module does not import it.
    free : bool
        Also mark the failing points of the free space outside ``D`` (orange dots).
    landmarks : bool
        Draw the landmarks the rule was evaluated with (triangles).
    legend : bool
        Label the axes (map units) and draw the legend (every labelled artist of the axes, once).

    Returns
    -------
    Axes
        Artists carry the gids ``perception-fail-domain``, ``perception-fail-free`` and ``perception-tags``.
    """
    bad = coverage.failing_domain  # what perception computed, not a second selection of it
    share = 1.0 - coverage.fraction_domain
    target = coverage.error_target
    what = "fewer than 2 usable tags in view" if target is None else f"no fix within {target:g} in view"
    label = f"{what}, in D ({share:.1%} of D; {coverage.fov_deg:g}° camera)"
    ax.scatter(
        bad[:, 0],
        bad[:, 1],
        marker="x",
        s=8,
        lw=0.7,
        color=PERCEPTION_FAIL_COLOR,
        zorder=5.5,
        gid="perception-fail-domain",
        label=label,
    )
    if free:
        out = coverage.failing_free
        ax.scatter(
            out[:, 0],
            out[:, 1],
            marker=".",
            s=5,
            lw=0,
            color=PERCEPTION_FAIL_FREE_COLOR,
            zorder=5.4,
            gid="perception-fail-free",
            label="the same, in F outside D",
        )
    if landmarks:
        _existing_tags(ax, coverage.landmarks, "perception-tags", f"tags ({len(coverage.landmarks)})")
    if legend:
        axis_labels(ax)
        legend_below(ax)
    return ax


#: Legend labels of the tags figure's two kinds of tag (their ids are written beside them where they fit).
PROPOSED_TAGS_LABEL = "proposed tags ({}): glue one at each, ids beside them"
EXISTING_TAGS_LABEL = "existing tags ({}), ids beside them where they fit"


def plot_tags(
    ax: plt.Axes,
    proposal: Any,
    *,
    failures: bool = True,
    labels: bool = True,
    uncoverable: bool = True,
    legend: bool = True,
) -> plt.Axes:
    """Where to glue the proposed tags: existing tags, new ones with the side they face, what still fails.

    Draw it over :func:`figure_for` of the plan (or :func:`plot_map` with ``landmarks=False``).

    Parameters
    ----------
    ax : Axes
        The axes to draw into (map units on both axes).
    proposal : TagProposal
        :func:`bearnav_cli.tags.propose_tags` (duck-typed: ``ids``, ``positions`` (K, 2),
        ``normals`` (K, 2), ``uncoverable`` (U, 2), ``before`` and ``after`` coverages as
        :func:`plot_perception` reads them).
    failures : bool
        Mark where the rule still fails with the new tags (:func:`plot_perception` of ``after``).
    labels : bool
        Write the tags' ids beside them, in the layout as it stands (:func:`label_tags`).
    uncoverable : bool
        Mark the points of ``D`` no placement can cover (grey).
    legend : bool
        Label the axes (map units) and draw the legend.

    Returns
    -------
    Axes
        Artists carry the gids ``existing-tags``, ``proposed-tags``, ``proposed-tag-facing`` and
        ``uncoverable``, the labels ``proposed-tag-label`` and ``existing-tag-label``, besides those of
        :func:`plot_perception`.
    """
    if failures:
        plot_perception(ax, proposal.after, landmarks=False, legend=False)
    before = proposal.before
    _existing_tags(ax, before.landmarks, "existing-tags", EXISTING_TAGS_LABEL.format(len(before.landmarks)))
    new = np.asarray(proposal.positions, float).reshape(-1, 2)
    normals = np.asarray(proposal.normals, float).reshape(-1, 2)
    ax.scatter(
        new[:, 0],
        new[:, 1],
        marker="D",
        s=34,
        color=PROPOSED_TAG_COLOR,
        edgecolor=ROLE_COLORS["edge"],
        linewidths=0.6,
        zorder=6.5,
        gid="proposed-tags",
        label=PROPOSED_TAGS_LABEL.format(len(new)),
    )
    if len(new):
        xmin, xmax = ax.get_xlim()
        scale = 0.02 * abs(xmax - xmin) if xmax != xmin else 0.1
        tips = new + scale * normals
        ax.add_collection(
            LineCollection(
                np.stack([new, tips], axis=1),
                colors=PROPOSED_TAG_COLOR,
                linewidths=1.0,
                zorder=6.4,
                gid="proposed-tag-facing",
                label="the free side a proposed tag faces",
            )
        )
    stuck = np.asarray(proposal.uncoverable, float).reshape(-1, 2)
    if uncoverable and len(stuck):
        ax.scatter(
            stuck[:, 0],
            stuck[:, 1],
            marker="s",
            s=5,
            lw=0,
            color=ROLE_COLORS["uncoverable"],
            zorder=5.6,
            gid="uncoverable",
            label=f"no placement covers ({len(stuck)} points)",
        )
    if legend:
        axis_labels(ax)
        legend_below(ax)
    if labels:
        label_tags(ax, proposal)
    return ax


def label_tags(ax: plt.Axes, proposal: Any) -> list:
    """The ids of the proposed tags, then of the existing ones, where they fit (:func:`place_labels`).

    A proposed tag's id goes on the side it faces first (the free side, away from the wall); every
    proposed id is written (``every``: the reader must find each tag to glue), an existing one only
    where it collides with nothing. Call it once the layout is settled.

    Parameters
    ----------
    ax : Axes
        The axes of :func:`plot_tags`.
    proposal : TagProposal
        The proposal drawn (``ids``, ``positions``, ``normals``, ``before.landmarks`` and
        ``before.landmark_ids``).

    Returns
    -------
    list of matplotlib.text.Annotation
        The texts written (gids ``proposed-tag-label`` and ``existing-tag-label``).
    """
    for t in [t for t in ax.texts if t.get_gid() in ("proposed-tag-label", "existing-tag-label")]:
        t.remove()
    new = np.asarray(proposal.positions, float).reshape(-1, 2)
    normals = np.asarray(proposal.normals, float).reshape(-1, 2)
    old = np.asarray(proposal.before.landmarks, float).reshape(-1, 2)
    marks = np.vstack([new, old])
    label = PROPOSED_TAGS_LABEL.format(len(new))
    texts = []
    for name, point, n in zip(proposal.ids, new, normals, strict=True):
        # the corner toward the free side first: there the label covers no wall
        facing = sorted(CORNERS, key=lambda o: -(np.sign(o[0]) * n[0] + np.sign(o[1]) * n[1]))
        texts += place_labels(
            ax,
            [str(name)],
            point[None],
            gid="proposed-tag-label",
            label=label,
            avoid=marks,
            offsets=facing,
            every=True,
            replace=False,
            color=PROPOSED_TAG_COLOR,
        )
    texts += place_labels(
        ax,
        proposal.before.landmark_ids,
        old,
        gid="existing-tag-label",
        avoid=marks,
        label=EXISTING_TAGS_LABEL.format(len(old)),
        color=EXISTING_TAG_COLOR,
    )
    return texts


def _tags_title(proposal: Any, map_: Map) -> str:
    before, after = proposal.before, proposal.after
    live = getattr(proposal, "live_after", None)
    if live is not None:
        config = (
            f"every cell live at η = {math.degrees(live.grid.eta):.3g}°: "
            f"{proposal.live_before.live_fraction:.1%} → {live.live_fraction:.1%} of D"
        )
        return figure_title(map_.name, "tags", f"where to glue {len(proposal.ids)} new tags", config)
    target = before.error_target
    rule = "2 usable tags in view" if target is None else f"a fix within {target:g} in view"
    config = (
        f"{before.fov_deg:g}° camera, {before.noise_deg:g}° noise: {rule} on {before.fraction_domain:.1%} "
        f"→ {after.fraction_domain:.1%} of D"
    )
    return figure_title(map_.name, "tags", f"where to glue {len(proposal.ids)} new tags", config)


def tags_figure(proposal: Any, map_: Map, title: str | None = None) -> plt.Figure:
    """Where to glue the proposed tags on the map (:func:`plot_map` without its tags, then :func:`plot_tags`).

    Parameters
    ----------
    proposal : TagProposal
        The proposal of :func:`bearnav_cli.tags.propose_tags` (its ``ids`` and placements).
    map_ : Map
        The map the tags are proposed for, drawn underneath.
    title : str, optional
        Figure title; default :func:`figure_title` with the camera, the noise and the share of ``D``
        where the rule holds before and after.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = map_frame(map_, title or _tags_title(proposal, map_), landmarks=False)
    # for liveness the perception rule's failures are beside the point: the grey marks say where no tag helps
    plot_tags(ax, proposal, failures=getattr(proposal, "live_after", None) is None, labels=False, legend=False)
    finish(fig, ax)
    label_tags(ax, proposal)
    return fig
