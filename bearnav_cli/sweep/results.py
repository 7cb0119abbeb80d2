"""A sweep's results: the tidy table of its jobs (CSV, Parquet) and the success figure's data and numbers."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from bearnav_cli import artifacts
from bearnav_cli.datatypes import Outcome
from bearnav_cli.sweep.grid import Job

__all__ = [
    "COLUMNS",
    "DETERMINISTIC_COLUMNS",
    "markdown",
    "OUTCOMES",
    "Panel",
    "success_curves",
    "table",
    "write_results",
]


#: Outcome names, in the enum's order (the table's count columns).
OUTCOMES = tuple(o.name.lower() for o in Outcome)
#: Columns of the table whose values do not depend on the machine or the schedule.
DETERMINISTIC_COLUMNS = (
    "map", "map_file", "seed", "tags", "n_tags", "fov", "noise_deg", "noise_bound_deg", "dynamics", "estimator",
    "starts", "sim_seed", "status", "error", "runs", *OUTCOMES, "success_rate", "certified_step_fraction",
    "in_domain_fraction", "success_rate_in_domain", "plan_tolerance", "plan_cells", "plan_key", "job_key",
)  # fmt: skip
#: Every column of the table: the deterministic ones, then the times (seconds of wall time).
COLUMNS = (*DETERMINISTIC_COLUMNS, "plan_s", "sim_s")


def table(jobs: Sequence[Job], found: dict[str, dict]) -> list[dict]:
    """One row of :data:`COLUMNS` per job of the grid that has a file in the store, in grid order.

    A failed job has its grid values, ``status`` ``failed`` and its ``error``; its counts are None.
    """
    rows = []
    for job in jobs:
        record = found.get(job.key)
        if record is None:
            continue
        result = record.get("result") or {}
        plan = record.get("plan") or {}
        times = record.get("times") or {}
        row = {
            **record["grid"],
            "status": record["status"],
            "error": record.get("error"),
            "n_tags": plan.get("n_tags"),
            "plan_tolerance": plan.get("tolerance"),
            "plan_cells": plan.get("cells"),
            "plan_key": job.plan_key[:24],
            "job_key": job.key[:24],
            "plan_s": times.get("plan_s"),
            "sim_s": times.get("sim_s"),
        }
        for name in (
            "runs",
            *OUTCOMES,
            "success_rate",
            "certified_step_fraction",
            "in_domain_fraction",
            "success_rate_in_domain",
        ):
            row[name] = result.get(name)
        rows.append({column: row.get(column) for column in COLUMNS})
    return rows


def write_results(store: str | os.PathLike, rows: Sequence[dict]) -> list[Path]:
    """``results.csv`` and, when pyarrow is installed, ``results.parquet`` in the store; the files written."""
    store = Path(store)
    written = [artifacts.write_table(store / "results.csv", COLUMNS, rows)]
    parquet = artifacts.write_parquet(store / "results.parquet", COLUMNS, rows)
    return written + ([parquet] if parquet is not None else [])


@dataclass(frozen=True)
class Panel:
    """One panel of the success figure: one map and dynamics, success against noise, a line per curve.

    Attributes
    ----------
    map, dynamics : str
        What the panel shows.
    lines : tuple of dict
        Each ``{"fov": float, "variant": str, "variant_index": int, "noise": list of float,
        "success": list of float}``: success rates (0–1) against the noise (degrees: ``noise_deg``, or
        ``noise_bound_deg`` for a bounded noise), sorted by noise; ``variant`` names the values of the
        other axes that vary in the sweep (``tags=own``), ``""`` when none does.
    tags : str
        The tag counts of the panel's plans (``"6 → 9 tags"``).
    """

    map: str
    dynamics: str
    lines: tuple
    tags: str


#: Axes that tell lines of one panel and field of view apart.
_VARIANT_AXES = ("tags", "estimator", "seed", "sim_seed", "starts", "noise_kind")


def success_curves(rows: Sequence[dict]) -> list[Panel]:
    """The success figure's data (drawn by :func:`bearnav_cli.plot.sweep_plot`): a panel per map and dynamics.

    Parameters
    ----------
    rows : sequence of dict
        Rows of :func:`table`; failed jobs are left out.
    """
    done = [
        dict(r, noise_kind="bounded" if r["noise_bound_deg"] is not None else "gaussian")
        for r in rows
        if r["status"] == "done" and r["success_rate"] is not None
    ]
    varying = [axis for axis in _VARIANT_AXES if len({r[axis] for r in done}) > 1]
    variants: list[tuple] = []
    panels = []
    for map_name, dynamics in dict.fromkeys((r["map"], r["dynamics"]) for r in done):
        here = [r for r in done if (r["map"], r["dynamics"]) == (map_name, dynamics)]
        lines = []
        for fov, variant in dict.fromkeys((r["fov"], tuple(r[a] for a in varying)) for r in here):
            points = sorted(
                (_noise(r), r["success_rate"])
                for r in here
                if r["fov"] == fov and tuple(r[a] for a in varying) == variant
            )
            if variant not in variants:
                variants.append(variant)
            label = ", ".join(f"{axis}={value}" for axis, value in zip(varying, variant, strict=True))
            lines.append(
                {
                    "fov": fov,
                    "variant": label,
                    "variant_index": variants.index(variant),
                    "noise": [p[0] for p in points],
                    "success": [p[1] for p in points],
                }
            )
        counts = sorted({r["n_tags"] for r in here if r["n_tags"] is not None})
        panels.append(Panel(map_name, dynamics, tuple(lines), " → ".join(map(str, counts)) + " tags" if counts else ""))
    return panels


def _noise(row: dict) -> float:
    return row["noise_bound_deg"] if row["noise_bound_deg"] is not None else row["noise_deg"]


def markdown(panels: Sequence[Panel], title: str) -> str:
    """The figure's numbers as tables: per panel, noise × field of view, variants as ``a → b``."""
    lines = [f"# {title}", "", "Success rate of the runs (`results.csv` has every count).", ""]
    for panel in panels:
        fovs = list(dict.fromkeys(line["fov"] for line in panel.lines))
        noises = sorted({n for line in panel.lines for n in line["noise"]})
        variants = list(dict.fromkeys(line["variant"] for line in panel.lines))
        heading = f"## {panel.map}, {panel.dynamics}" + (f" ({panel.tags})" if panel.tags else "")
        note = " → ".join(variants) if variants != [""] else ""
        lines += [heading, ""] + ([f"Each cell: {note}.", ""] if note else [])
        lines += [
            "| noise | " + " | ".join(f"{f:g}° view" for f in fovs) + " |",
            "| ---: | " + " | ".join("---:" for _ in fovs) + " |",
        ]
        for noise in noises:
            cells = []
            for fov in fovs:
                values = []
                for variant in variants:
                    line = next((x for x in panel.lines if x["fov"] == fov and x["variant"] == variant), None)
                    value = dict(zip(line["noise"], line["success"], strict=True)).get(noise) if line else None
                    values.append("–" if value is None else f"{100 * value:.1f}%")
                cells.append(values[0] if len(set(values)) == 1 else " → ".join(values))
            lines.append(f"| {noise:g}° | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)
