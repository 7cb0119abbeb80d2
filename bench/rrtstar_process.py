"""Benchmark: ``bearnav rrtstar`` against OMPL's ``RRTstar`` as whole processes (DESIGN §7, issue 26).

``bench/rrtstar.py`` times both planners in-process; here each side is a command a user would
run, timed from ``subprocess.run`` to its return, interpreter start-up, imports, reading the map
and writing the tree included:

* ours: ``bearnav rrtstar MAP_JSON -o TMP/tree.npz --iterations N --step S --seed K --clearance 0
  --force -q`` (the venv's entry point; clearance 0 is the validity OMPL checks);
* OMPL: ``python bench/ompl_rrtstar.py MAP_JSON -o TMP/ompl.npz --iterations N --step S --seed K+1``
  (json, shapely and OMPL only: the script reads ``map.json``, grows the tree, writes it to an npz);
* ``python -c pass`` (the bare interpreter), ``bearnav --help`` (bearnav's start-up) and
  ``python -c "import numpy, shapely, ompl..."`` (the OMPL script's imports) as references.

The maps are those of ``bench/rrtstar.py`` (kitchen, box500, office), written once to ``map.json``
by ``bearnav map``. Per map and iteration count, ``ROUNDS`` rounds (seed = round), in each round
every command once, the order rotating; medians. Two environments, side by side: the inherited one
(where ``PYTHONDONTWRITEBYTECODE`` may be set, so that a start reads only the byte-code ``make`` compiled at
install and compiles any ``bearnav_cli`` module changed since) and
byte-code caching on, the caches in a temporary ``PYTHONPYCACHEPREFIX`` warmed by one run of each
command. Each run's in-process planning time (our ``tree.npz`` manifest's ``elapsed_s``, the
OMPL script's ``solve_s``) is read too, so the rest (start-up, imports, map, writing) shows.

Run from the repository root::

    PYTHONPATH=. python bench/rrtstar_process.py [--quick] [--readme]

The markdown goes to stdout; ``--readme`` replaces the ``rrtstar-process`` section of
``bench/README.md``.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml
from common import (
    BENCH_DIR,
    MADE_SEED,
    README,
    REPO_DIR,
    load_line,
    load_snapshot,
    machine_line,
    markdown_table,
    quick_readme_args,
    replace_section,
)
from made_maps import KINDS

from bearnav_cli import artifacts

SECTION = "rrtstar-process"
#: (name, map file or ``made_maps.py`` kind, step), as in ``bench/rrtstar.py``.
MAPS = (
    ("kitchen", REPO_DIR / "maps" / "kitchen.yaml", 1.0),
    ("box500", BENCH_DIR / "maps" / "box500.yaml", 25.0),
    ("office", "office", 1.0),
)
ITERATIONS = (1500, 10_000)
ROUNDS = 11
#: The issue's bound on the whole-process ratio (ours / OMPL).
RATIO_TARGET = 1.2
OMPL_SCRIPT = BENCH_DIR / "ompl_rrtstar.py"
OMPL_IMPORTS = "import json, numpy, shapely; from ompl import base, geometric, util"


def log(message: str) -> None:
    """Progress on stderr, so stdout holds only the markdown."""
    print(message, file=sys.stderr, flush=True)


def bearnav() -> list[str]:
    """The ``bearnav`` entry point beside the interpreter, else ``python -m bearnav_cli``."""
    script = Path(sys.executable).parent / "bearnav"
    return [str(script)] if script.exists() else [sys.executable, "-m", "bearnav_cli"]


def run(cmd: list[str], env: dict[str, str] | None) -> tuple[float, str]:
    """Wall seconds and stdout of one subprocess run from the repository root; raises if it fails."""
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=REPO_DIR, env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited with {proc.returncode}: {proc.stderr.strip()[-2000:]}")
    return elapsed, proc.stdout


def write_map(name: str, source: Path | str, folder: Path) -> Path:
    """``map.json`` of a map file or a ``made_maps.py`` kind (seed :data:`MADE_SEED`), by ``bearnav map``."""
    if not isinstance(source, Path):
        spec = KINDS[source](MADE_SEED)
        source = folder / f"{name}.yaml"
        source.write_text(yaml.safe_dump(spec, sort_keys=False))
    out = folder / name / "map.json"
    run([*bearnav(), "map", str(source), "-o", str(out), "--force", "-q"], None)
    return out


def commands(map_json: Path, folder: Path, step: float, n: int, seed: int) -> dict[str, list[str]]:
    """The timed commands of one round, by name."""
    ours = [*bearnav(), "rrtstar", str(map_json), "-o", str(folder / "tree.npz"), "--iterations", str(n)]
    ours += ["--step", f"{step:g}", "--seed", str(seed), "--clearance", "0", "--force", "-q"]
    ompl = [sys.executable, str(OMPL_SCRIPT), str(map_json), "-o", str(folder / "ompl.npz"), "--iterations", str(n)]
    ompl += ["--step", f"{step:g}", "--seed", str(seed + 1)]  # OMPL's seed must not be 0
    return {
        "ours": ours,
        "ompl": ompl,
        "python": [sys.executable, "-c", "pass"],
        "help": [*bearnav(), "--help"],
        "ompl_imports": [sys.executable, "-c", OMPL_IMPORTS],
    }


def measure(map_json: Path, folder: Path, step: float, n: int, rounds: int, envs: dict[str, Any]) -> dict[str, Any]:
    """Median wall times per command and environment, and the in-process planning times of both sides."""
    wall: dict[str, list[float]] = {}
    inner: dict[str, list[float]] = {}
    for tag, env in envs.items():  # warm-up: byte-code caches, the page cache
        for _name, cmd in commands(map_json, folder / tag, step, n, 0).items():
            run(cmd, env)
    for r in range(rounds):
        jobs = [
            (f"{name}{'_' + tag if tag else ''}", cmd, env, tag)
            for tag, env in envs.items()
            for name, cmd in commands(map_json, folder / tag, step, n, r).items()
            if not (tag and name == "python")  # the bare interpreter compiles nothing
        ]
        k = r % len(jobs)
        for key, cmd, env, tag in jobs[k:] + jobs[:k]:
            seconds, out = run(cmd, env)
            wall.setdefault(key, []).append(seconds)
            if key.startswith("ours"):
                manifest = artifacts.read_manifest(folder / tag / "tree.npz")
                inner.setdefault(key, []).append(float(manifest["elapsed_s"]))
            elif key.startswith("ompl") and not key.startswith("ompl_imports"):
                inner.setdefault(key, []).append(float(json.loads(out)["solve_s"]))
    return {
        "wall": {key: statistics.median(t) for key, t in wall.items()},
        "inner": {key: statistics.median(t) for key, t in inner.items()},
    }


def table(results: list[tuple[str, int, dict[str, Any]]], envs: dict[str, Any]) -> str:
    """One row per map, iteration count and environment."""
    headers = [
        "map",
        "iterations",
        "environment",
        "`bearnav rrtstar` median s",
        "OMPL script median s",
        "ratio (ours/OMPL)",
        "our planning s (`elapsed_s`)",
        "OMPL planning s (`solve_s`)",
        "our rest s",
        "OMPL rest s",
        "`bearnav --help` s",
        "OMPL script's imports s",
        "`python -c pass` s",
    ]
    rows = []
    for name, n, m in results:
        w, inner = m["wall"], m["inner"]
        for tag in envs:
            s = f"_{tag}" if tag else ""
            rows.append(
                [
                    name,
                    f"{n:,}",
                    "byte-code cached" if tag else "inherited",
                    f"{w['ours' + s]:.3f}",
                    f"{w['ompl' + s]:.3f}",
                    f"{w['ours' + s] / w['ompl' + s]:.2f}",
                    f"{inner['ours' + s]:.3f}",
                    f"{inner['ompl' + s]:.3f}",
                    f"{w['ours' + s] - inner['ours' + s]:.3f}",
                    f"{w['ompl' + s] - inner['ompl' + s]:.3f}",
                    f"{w['help' + s]:.3f}",
                    f"{w['ompl_imports' + s]:.3f}",
                    f"{w['python']:.3f}",
                ]
            )
    return markdown_table(headers, rows)


def verdict(results: list[tuple[str, int, dict[str, Any]]], envs: dict[str, Any]) -> str:
    """The worst ratio per environment against :data:`RATIO_TARGET`."""
    parts = []
    for tag in envs:
        s = f"_{tag}" if tag else ""
        ratios = [(m["wall"]["ours" + s] / m["wall"]["ompl" + s], name, n) for name, n, m in results]
        worst, name, n = max(ratios)
        label = "with byte-code caches" if tag else "in the inherited environment"
        met = "met" if worst <= RATIO_TARGET else "NOT met"
        parts.append(
            f"{label} the largest ratio is {worst:.2f} ({name}, {n:,} iterations; target {RATIO_TARGET}: {met})"
        )
    return "Whole process: " + "; ".join(parts) + "."


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark, print the section and, with ``--readme``, record it."""
    args = quick_readme_args(__doc__, SECTION, "smoke test: 3 rounds, 1,500 iterations, kitchen only", argv)
    rounds = 3 if args.quick else ROUNDS
    maps = MAPS[:1] if args.quick else MAPS
    counts = ITERATIONS[:1] if args.quick else ITERATIONS

    load_before = load_snapshot()
    results = []
    with tempfile.TemporaryDirectory(prefix="bearnav-bench-rrtstar-") as tmp:
        folder = Path(tmp)
        cached = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        cached["PYTHONPYCACHEPREFIX"] = str(folder / "pycache")
        envs = {"": None, "cached": cached}
        for tag in envs:
            (folder / tag).mkdir(exist_ok=True)
        for name, source, step in maps:
            map_json = write_map(name, source, folder)
            for n in counts:
                m = measure(map_json, folder, step, n, rounds, envs)
                w = m["wall"]
                log(
                    f"{name} {n}: ours {w['ours']:.3f} s, OMPL {w['ompl']:.3f} s; cached {w['ours_cached']:.3f} s, "
                    f"{w['ompl_cached']:.3f} s"
                )
                results.append((name, n, m))
    load_after = load_snapshot()

    command = f"`bench/rrtstar_process.py{' --quick' if args.quick else ''}`"
    intro = (
        f"{command}: `bearnav rrtstar` (clearance 0) and `bench/ompl_rrtstar.py` (OMPL's `RRTstar` from Python, "
        "the validity callback of `bench/rrtstar.py`, reading `map.json` and writing its tree to an npz) as whole "
        f"processes on the same `map.json`, iterations and step; {rounds} round(s) per row (seed = round), every "
        "command once per round, the order rotating; medians. *planning*: the in-process time each side reports "
        "(our manifest's `elapsed_s`, the script's setup + solve); *rest*: whole process − planning (start-up, "
        "imports, reading the map, writing the tree)."
    )
    body = "\n\n".join(
        [
            "## RRT* as whole processes",
            intro,
            machine_line(),
            load_line(load_before, load_after),
            table(results, envs),
            verdict(results, envs),
        ]
    )
    print(body)
    if args.readme:
        replace_section(SECTION, body, README)


if __name__ == "__main__":
    main()
