"""What ``bearnav verify`` found: :class:`VerifyReport`, its verdict, reasons, notes, summary and JSON.

:func:`bearnav_cli.verify.run` fills it from the checks of :mod:`bearnav_cli.verify_checks` and the
closed loop; :attr:`VerifyReport.failed` is the exit decision.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from bearnav_cli.composition import Composition
from bearnav_cli.datatypes import CLAIMS_CERTIFICATE, CellStatus, Outcome, Simulation, cell_list, plural
from bearnav_cli.liveness import Liveness
from bearnav_cli.routes import MAX_ROUTE_VERTICES
from bearnav_cli.verify_checks import Certificates, Geometry, Unreached

__all__ = ["VerifyReport", "duration_text"]

# --------------------------------------------------------------------------- the report


def _finite_or_none(values: np.ndarray) -> list:
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, float)]


def _mean_or_nan(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(values.mean()) if len(values) else math.nan


@dataclass(frozen=True, eq=False)
class VerifyReport:
    """Everything ``bearnav verify`` found; :attr:`failed` decides the exit code.

    Attributes
    ----------
    status : ndarray of int8, shape (C,)
        Stored :class:`CellStatus` of each cell.
    certificates : Certificates
        Recomputed values per cell.
    false_certificates : dict of int to str
        Cells with status 0, 1 or 4 whose certificate the recomputation refutes.
    c_h_tilde, c_v_tilde, c_h_over_s_max : ndarray, shape (C,)
        Bearing constants ``c_h/s_min``, ``c_v/s_max`` and ``c_h/s_max`` (ALGORITHMS §5.5).
    flagged : dict of str to list of int
        Cells flagged by decomposition, by flag name.
    geometry : Geometry
        The geometric checks (:func:`check_geometry`).
    starts : ndarray, shape (R, 2)
        Monte-Carlo starts.
    rollouts : Simulation or None
        Their closed-loop runs (None when skipped).
    straight : ndarray, shape (R,)
        ``‖x₀ − g‖``. The path ratios (:attr:`ratio_straight`, :attr:`ratio_route`) are means
        over the successful runs of (path length + ``‖x_end − g‖``) / reference.
    route : ndarray, shape (R,)
        Shortest collision-free route length from each start.
    min_success : float or None
        The success rate below which the plan fails (``Params.min_success``; None: never on that ground).
    skipped : str or None
        Why the Monte-Carlo check did not run.
    goal : ndarray, shape (2,)
        The map's goal (map units), the reference of :attr:`straight`.
    composition : Composition or None
        The composed certificate's checks of a funnel plan (:func:`bearnav_cli.composition.check`);
        None for paper plans.
    world_cells : list of int or None
        Cells that no longer hold (C1) in the ``world`` map given to :func:`run`; None without one.
    unreached : Unreached or None
        The free regions the tree never reached (:func:`unreached_regions`): no start is drawn there.
    breaches : ndarray of bool, shape (R,), or None
        Runs from ``D`` that breached the certificate (:class:`Params` ``dynamics`` defines it).
    lookahead_problems : tuple of str
        What :func:`check_lookahead` found wrong (the plan's ``λ`` against its map's, the obstacles
        against the raw ones inflated by ``ρ + λ``); each fails verify.
    uncovered_dynamics : str or None
        Why the closed loop's robot is outside the certificate (the unicycle on a plan without a
        look-ahead), a note; None when it is inside.
    liveness : Liveness or None
        The liveness measurement of ALGORITHMS §12.5 (:func:`bearnav_cli.liveness.measure`) when
        :class:`Params` ``live_fov`` asks for it; a note, never a failure.
    liveness_note : str or None
        Why liveness was asked for but not measured (a paper plan), a note.
    """

    status: np.ndarray
    certificates: Certificates
    false_certificates: dict[int, str]
    c_h_tilde: np.ndarray
    c_v_tilde: np.ndarray
    c_h_over_s_max: np.ndarray
    flagged: dict[str, list[int]]
    geometry: Geometry
    starts: np.ndarray
    rollouts: Simulation | None
    straight: np.ndarray
    route: np.ndarray
    min_success: float | None
    skipped: str | None
    goal: np.ndarray
    composition: Composition | None = None
    world_cells: list[int] | None = None
    unreached: Unreached | None = None
    breaches: np.ndarray | None = None
    lookahead_problems: tuple[str, ...] = ()
    uncovered_dynamics: str | None = None
    liveness: Liveness | None = None
    liveness_note: str | None = None

    # ------------------------------------------------------------- the composed certificate (§11)
    @property
    def in_domain(self) -> np.ndarray:
        """Runs that started in the certified domain ``D``, shape (R,)."""
        if self.rollouts is None:
            return np.zeros(0, bool)
        return self.rollouts.start_in_domain

    @property
    def success_in_domain(self) -> float:
        """Success rate of the runs from ``D`` (the theorem says 1); NaN without such runs."""
        return self.rollouts.success_rate_of(self.in_domain) if self.rollouts is not None else math.nan

    @property
    def success_outside_domain(self) -> float:
        """Success rate of the runs from ``F \\ D`` (uncertified: straight approach first)."""
        return self.rollouts.success_rate_of(~self.in_domain) if self.rollouts is not None else math.nan

    # ------------------------------------------------------------- Monte-Carlo figures
    @property
    def success_rate(self) -> float:
        return self.rollouts.success_rate if self.rollouts is not None else math.nan

    @property
    def outcome_counts(self) -> dict[str, int]:
        return self.rollouts.counts() if self.rollouts is not None else {}

    @property
    def left_cell_total(self) -> int:
        return int(self.rollouts.left_cell.sum()) if self.rollouts is not None else 0

    @property
    def left_cell_fraction(self) -> float:
        """Fraction of runs with at least one relocation."""
        if self.rollouts is None or not len(self.rollouts):
            return math.nan
        return float(np.mean(self.rollouts.left_cell > 0))

    @property
    def approach_fraction(self) -> float:
        """Fraction of runs that drove straight to a tree node at least once (outside every safe set)."""
        if self.rollouts is None or not len(self.rollouts):
            return math.nan
        return float(np.mean(self.rollouts.approach_steps > 0))

    def _ratio(self, reference: np.ndarray) -> float:
        """Mean of (path length + the last ``‖x_end − g‖``) / reference over the successful runs.

        A run stops within ``goal_tolerance`` of the goal; adding the remaining straight bit
        makes a straight run score exactly 1 against the straight distance.
        """
        if self.rollouts is None:
            return math.nan
        r = self.rollouts
        ok = (r.outcome == Outcome.SUCCESS) & (reference > 0)
        rest = np.hypot(*(r.final_position[ok] - self.goal).T)
        return _mean_or_nan((r.path_length[ok] + rest) / reference[ok])

    @property
    def ratio_straight(self) -> float:
        return self._ratio(self.straight)

    @property
    def ratio_route(self) -> float:
        return self._ratio(self.route)

    # ------------------------------------------------------------- decision
    @property
    def uncertified(self) -> list[int]:
        """Cells with status 2 (not certified) or 3 (solver failure)."""
        bad = (CellStatus.NOT_CERTIFIED, CellStatus.SOLVER_FAILURE)
        return np.flatnonzero(np.isin(self.status, bad)).tolist()

    @property
    def reasons(self) -> list[str]:
        """Why the plan fails verification (empty when it passes)."""
        out = []
        if self.uncertified:
            out.append(
                f"{plural(len(self.uncertified), 'cell')} not certified (status 2 or 3): {cell_list(self.uncertified)}"
            )
        if self.false_certificates:
            items = [f"{c} ({why})" for c, why in sorted(self.false_certificates.items())]
            out.append(f"{len(items)} certified cells fail the recomputation: {cell_list(items)}")
        g = self.geometry
        if not g.coverage_ok:
            out.append(f"cells leave {g.uncovered_area:.3g} map units² of the bounds uncovered")
        for cells, what in (
            (g.cells_outside_bounds, "cells reach outside the bounds"),
            (g.edges_outside_cell, "cells do not contain their edge"),
            (g.bad_barriers, "cells have a barrier row that is not unit-norm or not positive at x_j"),
            (
                g.rows_not_polygon,
                "cells have half-plane rows that are not their polygon (the runtime reads the rows, "
                "the certificate was checked on the polygon)",
            ),
            (g.blocked_edges, "tree edges (by child node) are not free"),
        ):
            if cells:
                out.append(f"{len(cells)} {what}: {cell_list(cells)}")
        if g.samples_unchanged is False:
            out.append("collision samples differ from tree.npz")
        if self.skipped is not None and self.skipped.startswith("malformed"):
            out.append(self.skipped)
        if self.composition is not None:
            out.extend(self.composition.problems)
            if self.rollouts is not None and self.in_domain.any() and self.success_in_domain < 1.0:
                bad = np.flatnonzero(self.in_domain & (self.rollouts.outcome != Outcome.SUCCESS))
                out.append(
                    f"{len(bad)} runs from the certified domain did not reach the goal (the theorem says "
                    f"every one does: a bug): starts {cell_list(bad)}"
                )
        if self.rollouts is not None and len(self.rollouts):
            hit = np.flatnonzero(self._collided(certified=True))
            if hit.size:
                whence = " from the certified domain" if self.composition is not None else ""
                out.append(
                    f"{hit.size} of {len(self.rollouts)} closed-loop runs{whence} collided (any collision "
                    f"fails, whatever --min-success says): starts {cell_list(hit)}"
                )
        if self.breaches is not None and self.breaches.any():
            bad = np.flatnonzero(self.breaches)
            out.append(
                f"{bad.size} runs from the certified domain breached it (a step not certified, or a true "
                f"position outside every cell): starts {cell_list(bad)}"
            )
        out.extend(self.lookahead_problems)
        if self.world_cells:
            out.append(
                f"{len(self.world_cells)} cells no longer hold in the world (C1: they leave B_r or meet an "
                f"obstacle): {cell_list(self.world_cells)}"
            )
        if self.min_success is not None and not self.success_rate >= self.min_success:
            out.append(f"success rate {self.success_rate:.1%} below --min-success {self.min_success:.1%}")
        return out

    def _collided(self, certified: bool) -> np.ndarray:
        """The runs that collided, shape (R,) bool: from D (``certified``) or from outside it.

        A funnel plan's theorem covers the starts in ``D``, so a collision from there fails verify;
        a run from outside ``D`` drives on uncertified rules, and its collision is measured (a note).
        A paper plan certifies no domain: every collision fails.
        """
        hit = self.rollouts.outcome == Outcome.COLLISION
        if self.composition is None:
            return hit if certified else np.zeros_like(hit)
        return hit & (self.in_domain if certified else ~self.in_domain)

    @property
    def notes(self) -> list[str]:
        """What the report adds without failing: the robot outside the certificate, liveness, unreached regions."""
        out = [] if self.uncovered_dynamics is None else [self.uncovered_dynamics]
        if self.rollouts is not None and len(self.rollouts):
            outside = np.flatnonzero(self._collided(certified=False))
            if outside.size:
                out.append(
                    f"{outside.size} of {len(self.rollouts)} closed-loop runs from outside the certified "
                    f"domain collided (measured, not certified: those starts lie in the sliver of free "
                    f"space no cell covers, by an obstacle or a wall): starts {cell_list(outside)}"
                )
        if len(self.route) and np.isnan(self.route).all():
            out.append(
                f"the shortest-route ratio was not computed: the free space has more than "
                f"{MAX_ROUTE_VERTICES:,} corners (the straight-line ratio is given)"
            )
        if self.liveness is not None:
            out.append(self.liveness.summary())
        if self.liveness_note is not None:
            out.append(self.liveness_note)
        u = self.unreached
        if u is None or not u.parts:
            return out
        where = "; ".join(f"({x:.3g}, {y:.3g}) {area:.3g}" for x, y, area in u.parts[:5])
        more = f" … ({len(u.parts)} in all)" if len(u.parts) > 5 else ""
        share = f" ({u.area / u.free_area:.1%} of the free space)" if u.free_area > 0 else ""
        regions = "1 free region" if len(u.parts) == 1 else f"{len(u.parts)} free regions"
        return out + [
            f"{regions} the tree never reached, {u.area:.3g} map units²{share}, at (x, y) "
            f"area: {where}{more}; no start was drawn there, the plan says nothing about them"
        ]

    @property
    def failed(self) -> bool:
        """The exit decision: True means exit code 1."""
        return bool(self.reasons)

    def summary(self) -> str:
        """One line for the CLI."""
        n = len(self.status)
        certified = int(np.count_nonzero(np.isin(self.status, CLAIMS_CERTIFICATE))) - len(self.false_certificates)
        comp = self.composition
        if comp is not None:
            tau = comp.usable_by_area
            text = (
                f"{certified}/{n} funnel cells certified, composition {'proved' if comp.ok else 'FAILS'}, "
                f"{100 * comp.coverage_free:.1f}% of the free space covered ({100 * comp.coverage:.1f}% of it "
                f"away from the walls), a position error of {comp.plan_tolerance:.3g} tolerated everywhere "
                f"({tau['median']:.3g} at the median point, under {tau['p10']:.3g} on 10% of the area), "
                f"worst-case time to goal {duration_text(comp.time_bound)}"
            )
            if self.rollouts is not None and len(self.rollouts):
                d = self.in_domain
                ok = self.rollouts.outcome == Outcome.SUCCESS
                text += f"; from the certified area {int(ok[d].sum())}/{int(d.sum())} reached the goal"
                text += f", from outside it (uncertified) {int(ok[~d].sum())}/{int((~d).sum())}"
                if self.breaches is not None:
                    text += f", {int(self.breaches.sum())} left the certified area"
            return text + self._unreached_text() + ("; FAILED" if self.failed else "")
        text = f"{certified}/{n} cells certified, coverage {'ok' if self.geometry.coverage_ok else 'FAILS'}"
        if self.rollouts is not None:
            counts = self.outcome_counts
            others = ", ".join(f"{k} {v}" for k, v in counts.items() if k != "success" and v)
            text += f", {counts['success']}/{len(self.rollouts)} runs reached the goal"
            text += f" ({others})" if others else ""
            if len(self.rollouts) and self.approach_fraction > 0:
                text += f"; {self.approach_fraction:.0%} started or relocated outside every safe set"
        return text + self._unreached_text() + ("; FAILED" if self.failed else "")

    def _unreached_text(self) -> str:
        u = self.unreached
        if u is None or not u.parts or u.free_area <= 0:
            return ""
        return f"; {u.area / u.free_area:.1%} of the free space never reached by the tree (no starts there)"

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (non-finite numbers become ``null``)."""
        cert = self.certificates
        status_counts = {s.name.lower(): int(np.count_nonzero(self.status == s)) for s in CellStatus}
        g = self.geometry
        out: dict[str, Any] = {
            "failed": self.failed,
            "reasons": self.reasons,
            "summary": self.summary(),
            "cells": {
                "count": len(self.status),
                "status_counts": status_counts,
                "uncertified": self.uncertified,
                "false_certificates": {str(c): why for c, why in sorted(self.false_certificates.items())},
                "max_violation_certified": _finite_or_none(
                    [np.max(cert.violation[np.isin(self.status, CLAIMS_CERTIFICATE)], initial=0.0)]
                )[0],
                "flagged": self.flagged,
                "per_cell": {
                    "status": self.status.tolist(),
                    "cbf_value": _finite_or_none(cert.value_h),
                    "clf_value": _finite_or_none(cert.value_v),
                    "input_value": _finite_or_none(cert.value_u),
                    "violation": _finite_or_none(cert.violation),
                    "margin_error": _finite_or_none(cert.margin_error),
                    "c_h_tilde": _finite_or_none(self.c_h_tilde),
                    "c_v_tilde": _finite_or_none(self.c_v_tilde),
                    "c_h_over_s_max": _finite_or_none(self.c_h_over_s_max),
                },
            },
            "geometry": {
                "uncovered_area": g.uncovered_area,
                "coverage_ok": g.coverage_ok,
                "cells_outside_bounds": list(g.cells_outside_bounds),
                "edges_outside_cell": list(g.edges_outside_cell),
                "bad_barriers": list(g.bad_barriers),
                "rows_not_polygon": list(g.rows_not_polygon),
                "blocked_edges": list(g.blocked_edges),
                "samples_unchanged": g.samples_unchanged,
            },
        }
        mc: dict[str, Any] = {"n_starts": len(self.starts), "skipped": self.skipped}
        if self.rollouts is not None:
            mc.update(
                success_rate=_finite_or_none([self.success_rate])[0],
                outcomes=self.outcome_counts,
                left_cell_events=self.left_cell_total,
                left_cell_run_fraction=_finite_or_none([self.left_cell_fraction])[0],
                approach_run_fraction=_finite_or_none([self.approach_fraction])[0],
                path_over_straight=_finite_or_none([self.ratio_straight])[0],
                path_over_route=_finite_or_none([self.ratio_route])[0],
                dt=self.rollouts.dt,
                speed=self.rollouts.speed,
                min_success=self.min_success,
            )
        if self.rollouts is not None:
            mc.update(
                runs_from_domain=int(self.in_domain.sum()),
                success_rate_in_domain=_finite_or_none([self.success_in_domain])[0],
                success_rate_outside_domain=_finite_or_none([self.success_outside_domain])[0],
                certified_step_fraction=self.rollouts.certified_fraction,
                breaches=None if self.breaches is None else int(self.breaches.sum()),
            )
        out["monte_carlo"] = mc
        if self.composition is not None:
            comp = self.composition
            out["composition"] = {
                "proved": comp.ok,
                "failures": comp.failures,
                "problems": comp.problems,
                "coverage": comp.coverage,
                "coverage_free": comp.coverage_free,
                "stored_coverage": comp.stored_coverage,
                "plan_tolerance": _finite_or_none([comp.plan_tolerance])[0],
                "usable_tolerance_by_area": comp.usable_by_area,
                "time_bound_s": _finite_or_none([comp.time_bound])[0],
                "speed": comp.speed,
            }
        if self.world_cells is not None:
            out["world_cells"] = self.world_cells
        if self.unreached is not None:
            u = self.unreached
            out["unreached"] = {
                "area": u.area,
                "free_area": u.free_area,
                "parts": [{"point": [x, y], "area": a} for x, y, a in u.parts],
            }
        if self.liveness is not None:
            out["liveness"] = self.liveness.to_json()
        out["notes"] = self.notes
        return out


def duration_text(seconds: float) -> str:
    """``"≤ 1.387e+04 s (3.9 h)"``: a time bound in seconds, and in minutes or hours when it is long."""
    if not math.isfinite(seconds):
        return "unbounded"
    text = f"≤ {seconds:.4g} s"
    if seconds >= 3600:
        return text + f" ({seconds / 3600:.2g} h)"
    if seconds >= 120:
        return text + f" ({seconds / 60:.2g} min)"
    return text
