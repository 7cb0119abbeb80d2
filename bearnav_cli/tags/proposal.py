"""What a tag proposal is: its :class:`Params`, the :class:`TagProposal` itself, new ids, the rule with added tags."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bearnav_cli import perception
from bearnav_cli.datatypes import percent, plural
from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.perception import EvaluationGrid, PerceptionCoverage
from bearnav_cli.runtime.invariants import is_number
from bearnav_cli.tags.candidates import Candidates

__all__ = ["coverage_with", "new_tag_ids", "Params", "TAG_WIDTH_FRACTION", "TagProposal", "TARGETS"]


#: Default tag width as a fraction of the bounds' diagonal D: 0.19 m on the kitchen (D = 12.8 m), the
#: size of a printed AprilTag; in map units, so it scales with maps drawn in other units.
TAG_WIDTH_FRACTION = 0.015


#: What the tags are for: a usable fix where the robot looks (``fix``), or every cell live (``live``).
TARGETS = ("fix", "live")


@dataclass(frozen=True)
class Params:
    """Parameters of :func:`propose_tags` (deterministic: no seed).

    Attributes
    ----------
    fov_deg : float
        Camera field of view (degrees), in ``(0, 360]``.
    max_range : float
        Sensing range (map units), ``> 0``; ``inf`` for unlimited.
    noise_deg : float
        Bearing noise σ (degrees, ``≥ 0``): the predicted error ``3σ`` of a fix scales with it.
    error_target : float or None
        ``E`` (map units): the rule also needs predicted error ``≤ E``; ``None``: no error target.
    max_tags : int or None
        At most this many new tags (``≥ 0``); ``None``: as many as the target needs.
    tag_width : float or None
        Spacing of the candidates and least distance between tags (map units, ``> 0``); ``None``:
        ``TAG_WIDTH_FRACTION·D``.
    spacing : float or None
        Spacing of the evaluation grid (map units, ``> 0``); ``None``: ``D/100``.
    min_spread_deg : float
        ``θ_min`` of a usable fix (degrees, ALGORITHMS §6.2), the runtime's 2° by default.
    prune : bool
        After the greedy, drop every chosen tag (the last chosen first) whose removal keeps the rule
        wherever it holds; ``False`` gives the plain greedy.
    target : str
        ``fix``: the perception rule above (:func:`propose_tags`); ``live``: every cell live
        (ALGORITHMS §12.5, :func:`propose_live_tags`).
    bearing_error_deg, slip, resolution : float or None
        For ``live``: the bearing error bound ``η`` (degrees), the slip ``κ`` and the grid spacing
        (map units) of :func:`bearnav_cli.liveness.grid`; ``None``: its defaults (the map's robot).
    """

    fov_deg: float = 60.0
    max_range: float = math.inf
    noise_deg: float = 1.0
    error_target: float | None = None
    max_tags: int | None = None
    tag_width: float | None = None
    spacing: float | None = None
    min_spread_deg: float = 2.0
    prune: bool = True
    target: str = "fix"
    bearing_error_deg: float | None = None
    slip: float | None = None
    resolution: float | None = None

    def __post_init__(self) -> None:
        perception.check_params(
            self.fov_deg, self.noise_deg, self.max_range, self.error_target, self.min_spread_deg, self.spacing
        )
        if self.target not in TARGETS:
            raise InvalidParamsError(f"must be one of {', '.join(TARGETS)}, got {self.target!r}", field="target")
        m = self.max_tags
        if m is not None and (isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 0):
            raise InvalidParamsError(f"must be an integer >= 0, got {m!r}", field="max_tags")
        w = self.tag_width
        if w is not None and (not is_number(w) or not (w > 0 and math.isfinite(w))):
            raise InvalidParamsError(f"must be positive, got {w!r}", field="tag_width")

    def width(self, diagonal: float) -> float:
        """The tag width in map units for a map of diagonal ``diagonal``."""
        return TAG_WIDTH_FRACTION * diagonal if self.tag_width is None else float(self.tag_width)


@dataclass(frozen=True, eq=False)
class TagProposal:
    """New tags for a plan's map and what they achieve; ``K`` new tags, ``C`` candidates.

    Attributes
    ----------
    ids : tuple of str, length K
        New tag ids, none equal to an existing one (``tagN`` continuing the map's numbering, or
        integers when every existing id is one).
    positions : ndarray, shape (K, 2)
        Where to glue them (map units), on a raw obstacle's boundary or a wall, in the order chosen.
    normals : ndarray, shape (K, 2)
        Unit normal of each tag's surface, toward the free side it faces.
    gains : ndarray of int64, shape (K,)
        Grid points of ``D`` where the rule comes to hold as each new tag is added in turn, in the
        order of ``ids`` (the rule in the greedy's closed form).
    before, after : PerceptionCoverage
        The rule with the map's tags, and with the new ones added (fractions of ``D`` and ``F``).
    lower_bound : int
        ``ceil`` of the LP optimum: no placement among the candidates reaching the target uses fewer
        new tags.
    lp_objective : float
        The LP optimum itself (NaN if the LP did not solve).
    uncoverable : ndarray, shape (U, 2)
        Points of ``D`` where the rule fails even with every candidate added (map units).
    coverable_fraction : float
        Share of the points of ``D`` where some placement makes the rule hold.
    target_reached : bool
        The rule holds, after, at every coverable point of ``D`` (false when ``max_tags`` stopped it).
    candidates : Candidates
        Every candidate considered.
    params : Params
        The parameters the proposal was made with.
    tag_width : float
        The tag width used (map units).
    stats : dict
        Counts of the search: ``candidates`` (candidates seen from some evaluation point),
        ``domain_points`` (grid points of ``D``), ``pairs`` (visible point × candidate pairs) and
        ``greedy`` (tags the greedy chose before pruning). Not compared by ``==``.
    live_before, live_after : Liveness or None
        For ``target = live``: the liveness with the map's tags and with the new ones added
        (:func:`bearnav_cli.liveness.evaluate`); ``lower_bound`` is then 0 and ``lp_objective`` NaN
        (no bound is computed), ``gains`` counts liveness grid points, ``uncoverable`` the grid points
        no candidate makes live, and ``coverable_fraction`` is a share of the liveness grid.
    """

    ids: tuple
    positions: np.ndarray
    normals: np.ndarray
    gains: np.ndarray
    before: PerceptionCoverage
    after: PerceptionCoverage
    lower_bound: int
    lp_objective: float
    uncoverable: np.ndarray
    coverable_fraction: float
    target_reached: bool
    candidates: Candidates
    params: Params
    tag_width: float
    stats: dict = field(default_factory=dict, compare=False)
    live_before: Any = None
    live_after: Any = None

    @property
    def count(self) -> int:
        """Number of new tags ``K``."""
        return len(self.ids)

    @property
    def landmarks(self) -> np.ndarray:
        """Existing and new tag positions, shape (L + K, 2): the landmarks of the map with the tags."""
        return self.after.landmarks

    @property
    def landmark_ids(self) -> tuple:
        """Existing and new ids, length L + K."""
        return self.after.landmark_ids

    def summary(self) -> str:
        """One line: tags added against the lower bound, and the coverage of ``D`` and ``F`` before and after."""
        reached = "target reached" if self.target_reached else "target NOT reached"
        uncovered = 1.0 - self.coverable_fraction
        if self.live_after is not None:
            b, a = self.live_before, self.live_after
            return (
                f"{plural(self.count, 'new tag')} to the {len(self.before.landmarks)} of the map, {reached}: "
                f"live on {percent(b.live_fraction)} → {percent(a.live_fraction)} of the certified area at η = "
                f"{math.degrees(a.grid.eta):.3g}° ({b.n_live} → {a.n_live} of {len(a.live)} cells); certified bearing "
                f"error η* {math.degrees(b.eta_star):.3g}° → {math.degrees(a.eta_star):.3g}°"
                + (f"; {percent(uncovered)} of the grid cannot be made live by any tag" if uncovered > 0 else "")
            )
        return (
            f"{plural(self.count, 'new tag')} (lower bound {self.lower_bound}) to the "
            f"{len(self.before.landmarks)} of the map, {reached}: two usable tags in view on "
            f"{percent(self.before.fraction_domain)} → {percent(self.after.fraction_domain)} of the certified area "
            f"and {percent(self.before.fraction_free)} → {percent(self.after.fraction_free)} of the free space"
            + (f"; {percent(uncovered)} of the certified area cannot be covered" if uncovered > 0 else "")
        )


def new_tag_ids(existing: Any, count: int) -> tuple[str, ...]:
    """``count`` ids that clash with none of ``existing``.

    Every existing id an integer: the next integers. Otherwise ``tagN`` with ``N`` after the largest
    existing ``tagN`` (``tag0`` without one), skipping any id already taken.
    """
    taken = {str(i) for i in existing}
    if taken and all(re.fullmatch(r"\d+", i) for i in taken):
        prefix, start = "", max(int(i) for i in taken) + 1
    else:
        numbers = [int(m.group(1)) for i in taken if (m := re.fullmatch(r"tag(\d+)", i))]
        prefix, start = "tag", max(numbers, default=-1) + 1
    out: list[str] = []
    n = start
    while len(out) < count:
        name = f"{prefix}{n}"
        if name not in taken:
            out.append(name)
        n += 1
    return tuple(out)


def coverage_with(
    grid: EvaluationGrid,
    map_: Any,
    params: Params,
    sight: list,
    positions: np.ndarray | None = None,
    ids: tuple = (),
    new_sight: list | None = None,
) -> PerceptionCoverage:
    """The perception rule at ``params``' camera with the map's tags (their ``sight``) and new ones at ``positions``.

    Parameters
    ----------
    grid : EvaluationGrid
        Where the rule is evaluated (``perception.evaluation_grid``).
    map_ : Map
        The map whose tags are there already.
    params : Params
        The camera: field of view, noise, range, error target, ``θ_min``.
    sight : list of shapely geometry
        The visibility region of each of the map's tags.
    positions : ndarray, shape (K, 2), optional
        New tags (map units); none by default.
    ids : tuple of str
        Their ids.
    new_sight : list of shapely geometry, optional
        Their visibility regions (with ``positions``).
    """
    camera = dict(
        fov_deg=params.fov_deg,
        noise_deg=params.noise_deg,
        max_range=params.max_range,
        error_target=params.error_target,
        min_spread_deg=params.min_spread_deg,
    )
    if positions is None or not len(positions):
        landmarks, landmark_ids, seen = map_.landmarks, map_.landmark_ids, sight
    else:
        landmarks = np.vstack([map_.landmarks, positions])
        landmark_ids, seen = (*map_.landmark_ids, *ids), sight + list(new_sight)
    return perception.evaluate(grid, landmarks, landmark_ids, sight=seen, **camera)
