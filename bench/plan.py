"""Benchmark: the whole ``bearnav plan`` process, and decompose against F_m coverage (DESIGN §7, ALGORITHMS §11.5).

Two parts, each measured side by side in one run:

* **Whole process.** ``bearnav plan maps/kitchen.yaml -o TMP --force`` as a subprocess
  (``.venv/bin/bearnav`` beside the interpreter, else ``python -m bearnav_cli``), wall time
  from ``subprocess.run`` to its return, interpreter start-up included. It runs in two
  environments: the inherited one (which may set ``PYTHONDONTWRITEBYTECODE``, so that
  ``bearnav_cli`` is compiled at every start) and with byte-code caching on, the caches in a
  temporary ``PYTHONPYCACHEPREFIX`` (nothing is written into the repository), warmed by one
  run. In every round both run beside the start-up references ``python -c "import
  bearnav_cli.cli"`` (the CLI's imports) and ``bearnav --help`` in both environments and
  ``python -c pass`` (bare interpreter), the order rotating. After each plan run the
  per-stage ``elapsed_s`` is read from every artifact's manifest
  (``bearnav_cli.artifacts.read_manifest``); what the stages do not account for (start-up,
  imports, reading and writing artifacts, hashing) is the rest.
  Medians over the rounds, against the issue's target of 1.5 s (aim 1 s) and DESIGN §7's 2 s.
* **Decompose against coverage.** For the example maps (kitchen, storeroom: an occupancy grid,
  read by ``bearnav_cli.cli.read_map_source`` as the CLI reads it) and random maps of
  ``tests/mapgen.py`` (clutter, rooms, maze, grid; written to files and read as the CLI reads
  them), map → rrtstar → simplify run in-process once with
  the map's parameters; then ``decompose.run`` is timed with the map's decompose parameters
  in three variants, side by side in each round, the order rotating: funnel cells without
  densification (``max_added_nodes=0``), funnel cells as planned (default densification until
  ``coverage_target`` of F_m, then of F, or ``max_added_nodes``), and the papers' cells
  (``cells="paper"``). Cell counts and the coverage of F_m before and after densification
  come from ``cells.stats``. A map whose map → rrtstar → simplify fails is skipped and named,
  and the next seed of that kind is tried. ``--external PATH`` takes the random maps from
  another generator instead (a script run as ``PATH SEED --kind KIND -o FILE``, kinds clutter,
  rooms and grid), e.g. to compare with an earlier record.

Run from the repository root::

    PYTHONPATH=. python bench/plan.py [--quick] [--readme] [--external PATH]

The markdown goes to stdout; ``--readme`` replaces the ``plan`` section of ``bench/README.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from common import README, REPO_DIR, load_line, load_snapshot, machine_line, markdown_table, replace_section

from bearnav_cli import artifacts, pipeline
from bearnav_cli.cli import read_map_source
from bearnav_cli.stages import decompose
from tests import mapgen

SECTION = "plan"
PLAN_MAP = "maps/kitchen.yaml"
#: Runs of the whole process (median), after one untimed warm-up run.
PLAN_ROUNDS = 7
#: The issue's target for the whole process, its aim, and DESIGN §7's budget (s).
TARGET_S, AIM_S, DESIGN_S = 1.5, 1.0, 2.0
#: Rounds of the decompose comparison (median).
DECOMPOSE_ROUNDS = 5
#: The example maps of the decompose table.
EXAMPLE_MAPS = (REPO_DIR / "maps" / "kitchen.yaml", REPO_DIR / "maps" / "storeroom.yaml")
#: Random maps: per kind of tests/mapgen.py, the seeds tried in order; the first one that plans is used.
RANDOM_SEEDS = {kind: (1, 2, 3, 4, 5) for kind in mapgen.KINDS}
#: The kinds an ``--external`` generator is asked for.
EXTERNAL_KINDS = ("clutter", "rooms", "grid")
STAGE_FILES = tuple((stage.name, stage.filename) for stage in pipeline.STAGES)


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- whole process


def bearnav_command() -> tuple[list[str], str]:
    """The ``bearnav`` command (the venv's entry point if it is there) and how to name it."""
    script = Path(sys.executable).parent / "bearnav"
    if script.exists():
        try:
            shown = script.relative_to(REPO_DIR)
        except ValueError:
            shown = script
        return [str(script)], f"`{shown}`"
    return [sys.executable, "-m", "bearnav_cli"], "`python -m bearnav_cli`"


def wall(cmd: list[str], env: dict[str, str] | None = None) -> float:
    """Wall seconds of one subprocess run from the repository root; raises if it fails."""
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=REPO_DIR, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited with {proc.returncode}: {proc.stderr.strip()[-2000:]}")
    return elapsed


def cached_env(prefix: Path) -> dict[str, str]:
    """The inherited environment with byte-code caching on, the caches under ``prefix`` (not in the repo)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = str(prefix)
    return env


def whole_process(rounds: int) -> dict[str, Any]:
    """Median wall times of the plan runs and the start-up references, and the stages' ``elapsed_s``.

    Two environments side by side: the inherited one (where ``PYTHONDONTWRITEBYTECODE`` may
    be set, so that ``bearnav_cli`` is compiled at every start) and ``cached``: byte-code
    caching on with the caches in a temporary ``PYTHONPYCACHEPREFIX``, warmed by one run.
    """
    bearnav, shown = bearnav_command()
    with tempfile.TemporaryDirectory(prefix="bearnav-bench-plan-") as tmp:
        out = {"": Path(tmp) / "kitchen", "cached": Path(tmp) / "kitchen_cached"}
        cached = cached_env(Path(tmp) / "pycache")
        envs = {"": None, "cached": cached}
        variants = []
        for tag, env in envs.items():
            suffix = f"_{tag}" if tag else ""
            variants += [
                ("plan" + suffix, [*bearnav, "plan", PLAN_MAP, "-o", str(out[tag]), "--force"], env),
                ("help" + suffix, [*bearnav, "--help"], env),
                ("import" + suffix, [sys.executable, "-c", "import bearnav_cli.cli"], env),
            ]
        variants.append(("python", [sys.executable, "-c", "pass"], None))
        log("whole process: warm-up runs …")
        for name, cmd, env in variants:
            if name.startswith("plan"):
                wall(cmd, env)  # byte-code caches (cached), the page cache
        times: dict[str, list[float]] = {name: [] for name, _, _ in variants}
        stages = {tag: {name: [] for name, _ in STAGE_FILES} for tag in envs}
        for r in range(rounds):
            k = r % len(variants)
            for name, cmd, env in variants[k:] + variants[:k]:
                times[name].append(wall(cmd, env))
                if name.startswith("plan"):
                    tag = name.partition("_")[2]
                    for stage, filename in STAGE_FILES:
                        elapsed = artifacts.read_manifest(out[tag] / filename)["elapsed_s"]
                        stages[tag][stage].append(float(elapsed))
            log(f"  round {r + 1}/{rounds}: plan {times['plan'][-1]:.2f} s, cached {times['plan_cached'][-1]:.2f} s")
        summary = artifacts.read_manifest(out[""] / "plan.npz").get("summary", "")
        cells_summary = artifacts.read_manifest(out[""] / "cells.npz").get("summary", "")
        imports = import_times(cached)  # while the cache prefix exists
    result: dict[str, Any] = {
        "command": shown,
        "median": {name: float(np.median(t)) for name, t in times.items()},
        "min": {name: float(np.min(t)) for name, t in times.items()},
        "max": {name: float(np.max(t)) for name, t in times.items()},
        "summary": summary,
        "cells_summary": cells_summary,
        "runs": rounds,
        "no_bytecode": bool(os.environ.get("PYTHONDONTWRITEBYTECODE")),
        "imports": imports,
    }
    for tag in envs:
        suffix = f"_{tag}" if tag else ""
        per_run = np.sum([stages[tag][name] for name, _ in STAGE_FILES], axis=0)
        result["stages" + suffix] = {name: float(np.median(t)) for name, t in stages[tag].items()}
        result["stage_sum" + suffix] = float(np.median(per_run))
        result["rest" + suffix] = float(np.median(np.array(times["plan" + suffix]) - per_run))
    return result


def whole_process_text(w: dict[str, Any], rounds: int) -> str:
    med, lo, hi = w["median"], w["min"], w["max"]
    plan, cached = med["plan"], med["plan_cached"]

    def timed(key: str) -> list[str]:
        return [f"{med[key]:.3f}", f"{lo[key]:.3f} – {hi[key]:.3f}"]

    cmd = w["command"]
    rows = [
        [f"{cmd} `plan {PLAN_MAP} -o TMP --force` (whole process)", *timed("plan"), *timed("plan_cached")],
        [f"{cmd} `--help` (start-up: interpreter, imports, typer)", *timed("help"), *timed("help_cached")],
        ['`python -c "import bearnav_cli.cli"` (interpreter, imports)', *timed("import"), *timed("import_cached")],
        ["`python -c pass` (bare interpreter)", *timed("python"), "", ""],
    ]
    rows += [
        [
            f"stage `{name}` (`elapsed_s` of {filename})",
            f"{w['stages'][name]:.3f}",
            "",
            f"{w['stages_cached'][name]:.3f}",
            "",
        ]
        for name, filename in STAGE_FILES
    ]
    rows += [
        [
            "all stages (sum of `elapsed_s`, median over runs)",
            f"{w['stage_sum']:.3f}",
            "",
            f"{w['stage_sum_cached']:.3f}",
            "",
        ],
        [
            "rest: whole process − stages (start-up, imports, artifact I/O, hashing)",
            f"{w['rest']:.3f}",
            "",
            f"{w['rest_cached']:.3f}",
            "",
        ],
    ]
    inherited = "inherited environment" + (" (`PYTHONDONTWRITEBYTECODE=1`)" if w["no_bytecode"] else "")
    headers = ["what", f"{inherited}: median s", "min – max s", "byte-code cached: median s", "min – max s"]

    def verdicts(seconds: float) -> str:
        return (
            f"target {TARGET_S:g} s: {'met' if seconds < TARGET_S else 'NOT met'}; aim {AIM_S:g} s: "
            f"{'met' if seconds < AIM_S else 'not met'}; DESIGN §7 budget {DESIGN_S:g} s: "
            f"{'met' if seconds < DESIGN_S else 'NOT met'}"
        )

    st = w["stages_cached"]
    slowest = max(st, key=st.get)
    text = (
        f"Whole process, median of {w['runs']} runs: {plan:.2f} s in the inherited environment ({verdicts(plan)}), "
        f"{cached:.2f} s with byte-code caches ({verdicts(cached)}); "
        + (
            "this machine sets `PYTHONDONTWRITEBYTECODE=1`: without the cache prefix a start reads only the byte-code "
            "`make` compiled at install (`compileall`) and compiles any module changed since "
            f"({med['import'] - med['import_cached']:+.2f} s for the imports). "
            if w["no_bytecode"]
            else ""
        )
        + f"With caches, start-up (`bearnav --help`) takes {med['help_cached']:.2f} s, the stages "
        f"{w['stage_sum_cached']:.2f} s, the slowest being `{slowest}` at {st[slowest]:.2f} s "
        f"({st[slowest] / cached:.0%} of the whole), and everything outside the stages "
        f"{w['rest_cached']:.2f} s. To meet {TARGET_S:g} s the cached process must lose "
        f"{max(0.0, cached - TARGET_S):.2f} s, {max(0.0, cached - AIM_S):.2f} s for the aim."
    )
    parts = [f"Plan of the last run: {w['cells_summary']}; {w['summary']}.", markdown_table(headers, rows), text]
    imports = [(name, t) for name, t in w["imports"] if t >= 0.005 and name != "site"]
    if imports:
        parts.append(
            'Where the imports go: `python -X importtime -c "import bearnav_cli.cli"` with byte-code caches, median '
            "of 3 extra runs, cumulative time of `bearnav_cli.cli` (everything) and of each top-level module where "
            "it is first imported, from 5 ms (a module imported by another is counted in both): "
            + ", ".join(f"`{name}` {1e3 * t:.0f} ms" for name, t in imports[:10])
            + "."
        )
    return "\n\n".join(parts)


def import_times(env: dict[str, str] | None = None, runs: int = 3) -> list[tuple[str, float]]:
    """Cumulative import seconds of every top-level package ``import bearnav_cli.cli`` loads.

    From ``python -X importtime`` (median over ``runs`` extra runs, not the timed ones); a package
    counts where it is first imported, so the times of packages nested in others overlap them.
    """
    per: dict[str, list[float]] = {}
    for _ in range(runs):
        cmd = [sys.executable, "-X", "importtime", "-c", "import bearnav_cli.cli"]
        proc = subprocess.run(cmd, cwd=REPO_DIR, env=env, capture_output=True, text=True, check=True)
        for line in proc.stderr.splitlines():
            if not line.startswith("import time:") or "|" not in line:
                continue
            _, cumulative, name = (part.strip() for part in line.split("|"))
            if cumulative.isdigit() and ("." not in name or name == "bearnav_cli.cli"):
                per.setdefault(name, []).append(int(cumulative) * 1e-6)
    return sorted(((name, float(np.median(t))) for name, t in per.items()), key=lambda kv: -kv[1])


# --------------------------------------------------------------------------- decompose against coverage


@dataclasses.dataclass
class Prepared:
    """A map's simplified tree, ready for decompose."""

    label: str
    source: str
    simplified: Any
    params: decompose.Params


def prepare(path: Path) -> Any:
    """map → rrtstar → simplify of a map file in-process with its parameters (grids as the CLI reads them)."""
    return pipeline.compute(read_map_source(path), through="simplify")["simplified"]


def example_maps() -> list[Prepared]:
    out = []
    for path in EXAMPLE_MAPS:
        simplified = prepare(path)
        kind = "occupancy grid" if "occupancy" in read_map_source(path).spec else "polygons"
        out.append(
            Prepared(
                path.stem,
                f"`maps/{path.name}` ({kind})",
                simplified,
                pipeline.resolve_params("decompose", simplified.map.params),
            )
        )
    return out


def random_map(folder: Path, seed: int, kind: str, external: Path | None) -> tuple[Path, str]:
    """Write the random map ``seed`` of ``kind`` into ``folder``: its YAML and how to make it again."""
    if external is None:
        return mapgen.generate(seed, kind).write(folder), f"`python -m tests.mapgen {seed} --kind {kind}`"
    path = folder / f"{kind}_{seed}.yaml"
    subprocess.run([sys.executable, str(external), str(seed), "--kind", kind, "-o", str(path)], check=True, cwd=folder)
    return path, f"`{external.name} {seed} --kind {kind}`"


def random_maps(folder: Path, kinds: tuple[str, ...], external: Path | None = None) -> tuple[list[Prepared], list[str]]:
    """The first seed of each kind whose map plans to a simplified tree, and the skipped ones (with why)."""
    out, skipped = [], []
    for kind in kinds:
        for seed in RANDOM_SEEDS[kind]:
            path, shown = random_map(folder, seed, kind, external)
            try:
                simplified = prepare(path)
            except Exception as exc:  # noqa: BLE001 - any failure to plan the map: skip it and say why
                skipped.append(f"{shown} ({type(exc).__name__}: {exc})")
                log(f"  skipped {kind} seed {seed}: {exc}")
                continue
            out.append(
                Prepared(
                    f"random {kind} {seed}",
                    shown,
                    simplified,
                    pipeline.resolve_params("decompose", simplified.map.params),
                )
            )
            break
        else:
            skipped.append(f"no seed of kind {kind} among {RANDOM_SEEDS[kind]} planned")
    return out, skipped


def compare_decompose(m: Prepared, rounds: int) -> dict[str, dict[str, Any]]:
    """Median decompose seconds and the cells' statistics of the three variants, side by side."""
    variants = [
        ("bare", dataclasses.replace(m.params, cells="funnel", max_added_nodes=0)),
        ("dense", dataclasses.replace(m.params, cells="funnel")),
        ("paper", dataclasses.replace(m.params, cells="paper")),
    ]
    times: dict[str, list[float]] = {name: [] for name, _ in variants}
    result: dict[str, Any] = {}
    decompose.run(m.simplified, variants[0][1])  # warm-up: imports, caches
    for r in range(rounds):
        k = r % len(variants)
        for name, params in variants[k:] + variants[:k]:
            t0 = time.perf_counter()
            cells = decompose.run(m.simplified, params)
            times[name].append(time.perf_counter() - t0)
            result[name] = cells
    out = {}
    for name, _ in variants:
        cells = result[name]
        stats = cells.stats or {}
        out[name] = {
            "s": float(np.median(times[name])),
            "cells": int(cells.n_cells),
            "before": stats.get("free_coverage_before"),
            "after": stats.get("free_coverage_m"),
            "added": stats.get("added_nodes"),
        }
    return out


def pct(value: float | None) -> str:
    return "—" if value is None else f"{100 * value:.1f}%"


def decompose_text(
    maps: list[Prepared],
    skipped: list[str],
    rounds: int,
    target: float,
    limit: int,
    generator: str,
    kinds: tuple[str, ...],
) -> str:
    rows, short, ratios = [], [], []
    for m in maps:
        log(f"decompose: {m.label} ({len(m.simplified.nodes)} nodes) × {rounds} rounds …")
        d = compare_decompose(m, rounds)
        bare, dense, paper = d["bare"], d["dense"], d["paper"]
        rows.append(
            [
                m.source,
                f"{len(m.simplified.nodes)}",
                f"{bare['s']:.3f}",
                f"{bare['cells']}",
                pct(bare["after"]),
                f"{dense['s']:.3f}",
                f"{dense['cells']}",
                f"{pct(dense['before'])} → {pct(dense['after'])}",
                f"{dense['added']}",
                f"{dense['s'] / bare['s']:.2f}",
                f"{paper['s']:.3f}",
                f"{paper['cells']}",
                f"{paper['s'] / dense['s']:.2f}",
            ]
        )
        ratios.append(dense["s"] / bare["s"])
        if dense["after"] is not None and dense["after"] < target:
            short.append(f"{m.source} ({pct(dense['after'])} after {dense['added']} added nodes)")
        log(
            f"  no densification {bare['s']:.2f} s, {bare['cells']} cells, {pct(bare['after'])}; densified "
            f"{dense['s']:.2f} s, {dense['cells']} cells, {pct(dense['after'])}; paper {paper['s']:.2f} s"
        )
    headers = [
        "map",
        "simplified tree nodes",
        "funnel, `max_added_nodes=0`: median s",
        "cells",
        "F_m coverage",
        "funnel (default): median s",
        "cells",
        "F_m coverage before → after",
        "added nodes",
        "time densified / not densified",
        "paper: median s",
        "cells",
        "time paper / densified funnel",
    ]
    seeds = ", ".join(f"{kind} {', '.join(map(str, RANDOM_SEEDS[kind]))}" for kind in kinds)
    text = (
        "Decompose against coverage: map → rrtstar → simplify in-process once per map with the map's parameters "
        "(random maps have none: the defaults), then `decompose.run` with the map's decompose parameters in three "
        f"variants side by side in each round, the order rotating; medians over {rounds} round"
        f"{'s' if rounds > 1 else ''}. *funnel, `max_added_nodes=0`*: the funnel cells of the tree's own edges; "
        f"*funnel (default)*: densified until the cells cover {target:.0%} of F_m, then of F (`cover = F`: the band "
        f"along the walls; at most {limit} added leaf nodes in all), as `bearnav plan` runs it; *paper*: "
        '`cells="paper"` (ALGORITHMS §4, no coverage statistics). Coverage is `area(F_m ∩ D) / area(F_m)` from '
        "`cells.stats` (`free_coverage_before`, `free_coverage_m`, `added_nodes`; the band's cells count in F_m "
        f"too). Random maps from {generator} (seeds tried in order per kind: {seeds}; the first "
        "that plans is used)."
    )
    parts = [text, markdown_table(headers, rows)]
    if skipped:
        parts.append("Skipped: " + "; ".join(skipped) + ".")
    else:
        parts.append("No random map was skipped: the first seed of every kind planned.")
    if ratios:
        verdict = (
            f"Densification reaches the {target:.0%} target on {len(maps) - len(short)} of {len(maps)} maps"
            + (f"; short of it: {'; '.join(short)}" if short else "")
            + f". It makes decompose {min(ratios):.2f}–{max(ratios):.2f}× slower than without it "
            f"(median {float(np.median(ratios)):.2f}×)."
        )
        parts.append(verdict)
    return "\n\n".join(parts)


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark, print the section and, with ``--readme``, record it."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick", action="store_true", help="smoke test: 3 plan runs, 1 decompose round, kitchen and one clutter map"
    )
    parser.add_argument("--readme", action="store_true", help=f"replace the '{SECTION}' section of {README}")
    parser.add_argument(
        "--external", type=Path, metavar="PATH", help="random maps from this script (PATH SEED --kind KIND -o FILE)"
    )
    args = parser.parse_args(argv)
    plan_rounds = 3 if args.quick else PLAN_ROUNDS
    dec_rounds = 1 if args.quick else DECOMPOSE_ROUNDS
    # decompose warns about coverage short of the target (max_added_nodes=0 is meant to) and landmarks
    logging.getLogger("bearnav_cli").setLevel(logging.ERROR)

    load_before = load_snapshot()
    w = whole_process(plan_rounds)
    log("decompose: preparing the maps …")
    maps = example_maps()[:1] if args.quick else example_maps()
    with tempfile.TemporaryDirectory(prefix="bearnav-bench-maps-") as tmp:
        kinds = EXTERNAL_KINDS if args.external else mapgen.KINDS
        kinds = kinds[:1] if args.quick else kinds
        extra, skipped = random_maps(Path(tmp), kinds, args.external)
        generator = f"`{args.external.name}`" if args.external else "`tests/mapgen.py`"
        defaults = decompose.Params()
        dec = decompose_text(
            maps + extra, skipped, dec_rounds, defaults.coverage_target, defaults.max_added_nodes, generator, kinds
        )
    load_after = load_snapshot()

    command = f"`bench/plan.py{' --quick' if args.quick else ''}`"
    intro = (
        f"{command}: (1) the whole `bearnav plan` process on `{PLAN_MAP}` as a subprocess, interpreter start-up "
        f"included, median of {plan_rounds} runs after one warm-up, in the inherited environment and with "
        "byte-code caches in a temporary `PYTHONPYCACHEPREFIX`, side by side in each round (order rotating) "
        'with the start-up references `python -c pass`, `python -c "import bearnav_cli.cli"` and `bearnav '
        "--help` (both environments); per-stage times are the `elapsed_s` of each artifact's manifest of the "
        "same run. (2) decompose "
        "time and cell count against the coverage of F_m, before and after densification (ALGORITHMS §11.5)."
    )
    parts = [
        "## Plan",
        intro,
        machine_line(("numpy", "shapely", "highspy")),
        load_line(load_before, load_after),
        whole_process_text(w, plan_rounds),
        dec,
    ]
    body = "\n\n".join(parts)
    print(body)
    if args.readme:
        replace_section(SECTION, body, README)


if __name__ == "__main__":
    main()
