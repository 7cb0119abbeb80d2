"""``bearnav inspect``: check an artifact and print its manifest, a table of its cells or one cell."""

import json
from pathlib import Path
from typing import Any, Optional

import typer

from bearnav_cli.cli.exits import EXIT_INVALID, fail, handles_errors
from bearnav_cli.cli.options import JSON, QUIET
from bearnav_cli.cli.output import Quiet, out, print_json

__all__ = ["inspect_command"]


@handles_errors
def inspect_command(
    artifact: Path = typer.Argument(..., metavar="ARTIFACT", help="Any bearnav artifact (map.json, *.npz)."),
    cells: bool = typer.Option(
        False, "--cells", help="Also print a table of the cells (one row each, with units); with --json, its rows."
    ),
    cell: Optional[int] = typer.Option(
        None, "--cell", metavar="N", help="Print one cell of cells.npz or plan.npz: rows, vertices, status, tolerance."
    ),
    quiet: bool = QUIET,
    as_json: bool = JSON,
) -> None:
    """Check an artifact and print a short summary of its manifest (per-cell detail with --cells).

    Examples: bearnav inspect plans/kitchen/plan.npz;
    bearnav inspect plans/kitchen/plan.npz --cell 12
    """
    from bearnav_cli import pipeline

    Quiet.enabled |= quiet
    loaded = pipeline.load(artifact)
    manifest = loaded.manifest
    if cell is not None:
        _inspect_cell(artifact, loaded.artifact, cell, as_json)
        return
    table = _cell_table(loaded.artifact, manifest.get("stats") or {}) if cells else None
    if as_json:
        units = {key: unit.replace("u", "map unit") if unit else None for key, _, unit in table[0]} if table else None
        print_json(manifest if table is None else {"units": units, "cells": table[1]})
        return
    stage = f"stage {manifest['stage']} v{manifest['stage_version']}"
    out.print(f"[bold]{artifact}[/bold]  {manifest['schema']}  ({stage})")
    # soft_wrap: a line as long as it is (a terminal folds it; rich would cut the JSON mid-token at 80 columns)
    out.print(f"summary   {manifest.get('summary', '')}", highlight=False, markup=False, soft_wrap=True)
    out.print(
        f"params    {json.dumps(manifest.get('params', {}), sort_keys=True)}",
        highlight=False,
        markup=False,
        soft_wrap=True,
    )
    inp = manifest.get("input", {})
    out.print(f"input     {inp.get('path')}  sha256 {str(inp.get('content_sha256'))[:16]}…", highlight=False)
    out.print(f"content   sha256 {manifest['content_sha256'][:16]}…  key {manifest['key'][:16]}…", highlight=False)
    stats = manifest.get("stats") or {}
    if stats:
        out.print(
            f"stats     {json.dumps(_short_stats(stats), sort_keys=True)}",
            highlight=False,
            markup=False,
            soft_wrap=True,
        )
    software = ", ".join(f"{k} {v}" for k, v in manifest.get("software", {}).items())
    out.print(f"software  {software}  elapsed {manifest.get('elapsed_s', 0):.3f} s", highlight=False, soft_wrap=True)
    per_cell = sorted(key for key, value in stats.items() if isinstance(value, list) and value)
    if cells:
        from bearnav_cli.datatypes import cell_list

        if table is not None:
            _print_cell_table(*table)
        shown = {_STATS_KEY.get(key, key) for key, _, _ in table[0]} if table is not None else set()
        lists = {key: value for key, value in stats.items() if isinstance(value, list) and value and key not in shown}
        for key, value in sorted(lists.items()):  # lists of cells (or of rounds), not a column each
            out.print(f"{key}: {cell_list(value, 40)}", highlight=False, markup=False, soft_wrap=True)
    elif per_cell:
        out.print(
            f"(--cells adds a table of the cells and the lists {', '.join(per_cell)}; --cell N shows one cell)",
            highlight=False,
            markup=False,
            soft_wrap=True,
        )


#: The per-cell lists of a plan's statistics that ``inspect --cells`` shows as columns: (key, heading, unit).
_PLAN_STATS_COLUMNS = (
    ("lp_solves", "LP", ""),
    ("c_tilde_h", "c̃_h", "1/(s·u)"),
    ("c_tilde_v", "c̃_v", "1/(s·u)"),
    ("c_h_over_s_max", "c_h/s_max", "1/(s·u)"),
)
#: Where a column's numbers come from in the statistics, when not its key (``attempts``: the LP solves of a cell).
_STATS_KEY = {"lp_solves": "attempts"}


def _cell_table(artifact: Any, stats: dict) -> "tuple[list[tuple[str, str, str]], list[dict]] | None":
    """``inspect --cells``: the columns as (key, heading, unit) and one row per cell, or None without cells.

    The rows hold numbers keyed by column (None where there is none: the goal cell's exit inset, a
    cell without a tolerance), so that ``--json`` prints them as they are and the table formats them.
    Lengths are in map units (``u``).
    """
    import math

    import numpy as np

    from bearnav_cli.datatypes import CellFlag, Cells, CellStatus, Plan

    plan = artifact if isinstance(artifact, Plan) else None
    cells = plan.cells if plan is not None else artifact
    if not isinstance(cells, Cells):
        return None

    def number(value: Any) -> Any:
        value = float(value)
        return None if math.isnan(value) else value

    columns = [
        ("cell", "cell", ""),
        ("rank", "rank", "u"),
        ("vertices", "vertices", ""),
        ("barrier_rows", "barriers", ""),
        ("exit_inset", "exit inset", "u"),
        ("landmarks", "landmarks", ""),
    ]
    if plan is not None:
        columns[1:1] = [("status", "status", ""), ("delta_c", "δ_c", "u"), ("tau_c", "τ_c", "u")]
        columns += [c for c in _PLAN_STATS_COLUMNS if len(stats.get(_STATS_KEY.get(c[0], c[0])) or []) == cells.n_cells]
    columns.append(("flags", "flags", ""))
    barrier_rows = np.diff(cells.cbf_offsets)
    rows = []
    for c in range(cells.n_cells):
        row: dict[str, Any] = {
            "cell": c,
            "rank": number(cells.cell_rank[c]),
            "vertices": len(cells.vertices(c)),
            "barrier_rows": int(barrier_rows[c]),
            "exit_inset": number(cells.exit_inset[c]),
            "landmarks": int(np.count_nonzero(cells.cell_landmarks[c])),
            "flags": ",".join(f.name.lower() for f in CellFlag if f and int(cells.cell_flags[c]) & f),
        }
        if plan is not None:
            row.update(
                status=CellStatus(int(plan.status[c])).name.lower(),
                delta_c=number(plan.tolerance[c]),
                tau_c=number(plan.usable_tolerance[c]),
            )
            for key, _, _ in columns:
                if key in dict((k, h) for k, h, _ in _PLAN_STATS_COLUMNS):
                    row[key] = stats[_STATS_KEY.get(key, key)][c]
        rows.append({key: row[key] for key, _, _ in columns})
    return columns, rows


def _print_cell_table(columns: "list[tuple[str, str, str]]", rows: list[dict]) -> None:
    """The rows of :func:`_cell_table` as plain aligned text (as wide as it needs: never wrapped or cut),
    the units under the headings, numbers to 4 digits, "-" where there is none."""

    def text(value: Any) -> str:
        return "-" if value is None else f"{value:.4g}" if isinstance(value, float) else str(value)

    cells = [[text(row[key]) for key, _, _ in columns] for row in rows]
    widths = [
        max([len(heading), len(unit) + 2, *(len(line[k]) for line in cells)])
        for k, (_, heading, unit) in enumerate(columns)
    ]
    left = {"status", "flags"}

    def line(items: list[str]) -> str:
        return "  ".join(
            item.ljust(w) if key in left else item.rjust(w)
            for item, w, (key, _, _) in zip(items, widths, columns, strict=True)
        ).rstrip()

    for items in ([h for _, h, _ in columns], [f"[{u}]" if u else "" for _, _, u in columns], *cells):
        out.print(line(items), highlight=False, markup=False, soft_wrap=True)
    out.print("u: map units; s: seconds", highlight=False, markup=False, soft_wrap=True)


def _short_stats(stats: dict) -> dict:
    """The manifest's statistics for the default ``inspect``: per-cell lists left out (``--cells``
    shows them), lists of cells inside a mapping counted, zero counts dropped, floats to 4 digits."""

    def short(value: Any) -> Any:
        if isinstance(value, float):
            return float(f"{value:.4g}")
        if isinstance(value, list):
            return len(value)
        if isinstance(value, dict):
            return {k: short(v) for k, v in value.items() if v not in (0, [], None, {})}
        return value

    return {
        key: short(value) for key, value in stats.items() if not isinstance(value, list) and value not in ({}, None)
    }


def _inspect_cell(path: Path, artifact: Any, c: int, as_json: bool) -> None:
    """``inspect --cell N``: one cell of a cells.npz or plan.npz, everything a user needs to find it."""
    import numpy as np

    from bearnav_cli.datatypes import CellFlag, Cells, CellStatus, Plan

    plan = artifact if isinstance(artifact, Plan) else None
    cells = plan.cells if plan is not None else artifact
    if not isinstance(cells, Cells):
        raise fail(f"--cell: {path} holds no cells (give cells.npz or plan.npz)", EXIT_INVALID)
    if not 0 <= c < cells.n_cells:
        raise fail(f"--cell: {path} has cells 0 to {cells.n_cells - 1}, got {c}", EXIT_INVALID)
    A, b = cells.rows(c)
    vertices = cells.vertices(c)
    node = int(cells.cell_node[c])
    parent = int(cells.parent[node])
    ids = [str(cells.map.landmark_ids[k]) for k in np.flatnonzero(cells.cell_landmarks[c])]
    flags = [flag.name.lower() for flag in CellFlag if flag and int(cells.cell_flags[c]) & flag]
    info: dict[str, Any] = {
        "cell": c,
        "node": node,
        "node_position": [float(v) for v in cells.nodes[node]],
        "parent_cell": parent,
        "rank": float(cells.cell_rank[c]),
        "exit_row": int(cells.cell_exit_row[c]),
        "vertices": [[float(v) for v in p] for p in vertices],
        "rows": [{"a": [float(v) for v in a], "b": float(bb)} for a, bb in zip(A, b, strict=True)],
        "landmarks": ids,
        "fixed_landmark": str(cells.map.landmark_ids[int(cells.fixed_landmark[c])]),
        "flags": flags,
        "added_by_densification": bool(cells.node_added[node]),
    }
    if plan is not None:
        status = CellStatus(int(plan.status[c]))
        tol = float(plan.tolerance[c])
        usable, inset = float(plan.usable_tolerance[c]), float(cells.exit_inset[c])
        info.update(
            status=status.name.lower(),
            status_code=int(status),
            tolerance=None if np.isnan(tol) else tol,
            usable_tolerance=None if np.isnan(usable) else usable,
            exit_inset=None if np.isnan(inset) else inset,
            margin_h=float(plan.margin_h[c]),
            margin_v=float(plan.margin_v[c]),
        )
        if status == CellStatus.NOT_CERTIFIED:  # why: the judgement synthesize and verify make of the rows
            from bearnav_cli.runtime.certificate import barrier_fault

            info["barrier_fault"] = barrier_fault(*cells.barrier(c), cells.nodes[parent] if parent >= 0 else None)
    if as_json:
        print_json(info)
        return

    def point(p: Any) -> str:
        return f"({p[0]:.4g}, {p[1]:.4g})"

    lines = [f"cell {c} of {path} ({cells.n_cells} cells)"]
    lines.append(
        f"node      {node} at {point(cells.nodes[node])}, "
        + (f"parent cell {parent}" if parent >= 0 else "the goal cell")
        + (" (added by densification)" if info["added_by_densification"] else "")
        + f"; rank {info['rank']:.4g} (cost-to-go, map units)"
    )
    if plan is not None:
        tol_text = "none" if info["tolerance"] is None else f"{info['tolerance']:.4g} map units"
        lines.append(f"status    {info['status_code']} {info['status']}; δ_c (position error tolerated) {tol_text}")
        if info.get("barrier_fault"):
            lines.append(f"why       {info['barrier_fault']} (its barrier rows cannot carry a certificate)")
        elif status == CellStatus.NOT_CERTIFIED:
            lines.append(
                f"why       no κ made the LP feasible (least-violation margins: barrier "
                f"{info['margin_h']:.3g}, progress {info['margin_v']:.3g})"
            )
        if info["usable_tolerance"] is not None:
            inset = info["exit_inset"]
            inset_text = "no exit (goal cell)" if inset is None else f"exit inset δ_e,c {inset:.4g}"
            lines.append(
                f"tolerance τ_c = min(δ_c, δ_e,c/2) = {info['usable_tolerance']:.4g} map units, the error "
                f"under which the robot may move here; {inset_text}"
            )
    lines.append(f"vertices  {len(vertices)}, CCW: " + " ".join(point(p) for p in vertices))
    lines.append(
        f"rows      {len(A)}, the cell is {{x : a·x ≤ b}}; the exit row is {info['exit_row']}"
        + (" (none: goal cell)" if info["exit_row"] < 0 else "")
    )
    for k, (a, bb) in enumerate(zip(A, b, strict=True)):
        mark = "  <- exit" if k == info["exit_row"] else ""
        lines.append(f"  {k:>3}  a = ({a[0]: .4f}, {a[1]: .4f})  b = {bb: .5g}{mark}")
    lines.append(f"landmarks {', '.join(ids) or 'none'} (fixed: {info['fixed_landmark']})")
    lines.append(f"flags     {', '.join(flags) or 'none'}")
    for line in lines:
        out.print(line, highlight=False, markup=False, soft_wrap=True)
