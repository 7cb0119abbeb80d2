"""Benchmark: ``bearnav sweep`` of the robustness figure on one process, two, and a 2-worker Dask LocalCluster.

The sweep file is ``repro/robustness.yaml`` (``make reproduce``'s robustness figure: 4 maps × 2 tag
sets × 4 fields of view × 4 noises × 2 dynamics, 200 random starts). By default a reduced grid of
it runs (``--full`` runs all of it: 30 min with ``--jobs 1``, 17 min on two processes): the same file with
``fov: [360, 60]``, ``noise_deg: [0, 1]``, ``dynamics: [single]`` and ``starts: random:100``, 32 jobs of
100 starts on every map with both tag sets; the section says which ran.

Each configuration is the whole ``bearnav sweep`` command in a subprocess, into an empty store
(plans included: every run makes its own 8 plans), timed by its wall clock: ``--jobs 1``,
``--jobs 2`` and ``--scheduler`` on a ``distributed.LocalCluster`` of 2 single-threaded worker
processes started just before its own sweep and closed after it (its start-up is not timed; an idle
cluster beside the other two sweeps took 8% of a core from them). The three tables must be the same
(every column but the times). The order of the configurations rotates between rounds; times are
medians. The machine is shared: the load line says how busy it was.

Run from the repository root::

    PYTHONPATH=. python bench/sweep.py [--full] [--rounds N] [--readme]

The markdown goes to stdout; ``--readme`` replaces the ``sweep`` section of ``bench/README.md``.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml
from common import README, REPO_DIR, load_line, load_snapshot, machine_line, markdown_table, replace_section

from bearnav_cli import sweep

SECTION = "sweep"
SWEEP_FILE = REPO_DIR / "repro" / "robustness.yaml"
#: The reduced grid (the default): these axes of the robustness sweep file replaced.
REDUCED = {"fov": [360, 60], "noise_deg": [0, 1], "dynamics": ["single"], "starts": "random:100"}
TARGET = 1.8


def run_sweep(sweep_yaml: Path, store: Path, args: list[str]) -> float:
    """Wall time (s) of ``bearnav sweep SWEEP -o STORE ARGS`` in a subprocess from the repository root."""
    command = [sys.executable, "-m", "bearnav_cli", "-q", "sweep", str(sweep_yaml), "-o", str(store), *args]
    began = time.perf_counter()
    done = subprocess.run(command, cwd=REPO_DIR, capture_output=True, text=True)
    elapsed = time.perf_counter() - began
    if done.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(command)} failed ({done.returncode}): {done.stderr.strip()}")
    return elapsed


def table(store: Path) -> list[dict]:
    with (store / "results.csv").open() as handle:
        return [{c: row[c] for c in sweep.DETERMINISTIC_COLUMNS} for row in csv.DictReader(handle)]


def priority_note() -> str:
    """A sentence on the benchmark's scheduling priority when it was raised (empty when it was not)."""
    niceness = os.getpriority(os.PRIO_PROCESS, 0)
    if niceness >= 0:
        return ""
    return (
        f" The benchmark and its sweeps ran at niceness {niceness}, so the other work on the machine "
        "ran on what the sweep left idle (the second core during `--jobs 1`)."
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="the whole robustness sweep (256 jobs)")
    parser.add_argument("--rounds", type=int, default=1, help="rounds (default 1)")
    parser.add_argument("--readme", action="store_true", help=f"replace the '{SECTION}' section of {README}")
    parser.add_argument(
        "--keep",
        type=Path,
        help="copy the `--jobs 1` store here (a new folder), e.g. "
        "sweeps/robustness, so that `make reproduce` draws the figure from it without running a job",
    )
    args = parser.parse_args()
    from distributed import LocalCluster

    spec = yaml.safe_load(SWEEP_FILE.read_text())
    if not args.full:
        spec.update(REDUCED)
    n_jobs = len(spec["maps"]) * len(spec["tags"]) * len(spec["fov"]) * len(spec["noise_deg"]) * len(spec["dynamics"])
    env_note = f"PYTHONPATH={os.environ.get('PYTHONPATH', '')}"
    before = load_snapshot()
    times: dict[str, list[float]] = {"--jobs 1": [], "--jobs 2": [], "LocalCluster, 2 workers": []}
    tables: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory(prefix="bench-sweep-") as tmp:
        sweep_yaml = Path(tmp) / "robustness.yaml"
        sweep_yaml.write_text(yaml.safe_dump(spec, sort_keys=False))
        configs = {"--jobs 1": ["--jobs", "1"], "--jobs 2": ["--jobs", "2"], "LocalCluster, 2 workers": None}
        names = list(configs)
        for r in range(args.rounds):
            for name in names[r % len(names) :] + names[: r % len(names)]:
                store = Path(tmp) / f"store-{r}-{names.index(name)}"
                if configs[name] is not None:
                    seconds = run_sweep(sweep_yaml, store, configs[name])
                else:
                    # the cluster lives only for its own sweep: idle, its scheduler (in this process) and its two
                    # workers took 8% of a core, which a `--jobs 2` sweep beside them lost
                    with LocalCluster(
                        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
                    ) as cluster:
                        seconds = run_sweep(sweep_yaml, store, ["--scheduler", cluster.scheduler_address])
                times[name].append(seconds)
                tables[name] = table(store)
                print(f"round {r + 1}: {name}: {seconds:.1f} s", file=sys.stderr, flush=True)
        if args.keep is not None:
            shutil.copytree(Path(tmp) / "store-0-0", args.keep)
    after = load_snapshot()
    same = all(t == tables["--jobs 1"] for t in tables.values())
    one = statistics.median(times["--jobs 1"])
    rows = [[name, f"{statistics.median(t):.1f}", f"{one / statistics.median(t):.2f}"] for name, t in times.items()]
    reduced = "; ".join(f"{k}: {v}" for k, v in REDUCED.items())
    grid = "the whole sweep" if args.full else f"a REDUCED grid, not the full 256 jobs of 200 starts ({reduced})"
    sample = tables["--jobs 1"]
    failed = sum(1 for row in sample if row["status"] != "done")
    two = one / statistics.median(times["--jobs 2"])
    body = "\n\n".join(
        [
            "## Sweep",
            "`bench/sweep.py`: `bearnav sweep` of `repro/robustness.yaml` (the robustness figure of "
            f"`make reproduce`), {grid}: {n_jobs} jobs of {spec['starts'].split(':')[1]} random starts on "
            f"{len(spec['maps'])} maps, both tag sets, dynamics {', '.join(spec['dynamics'])}. Each configuration "
            "is the whole command in a subprocess "
            "into an empty store (its 8 plans included, interpreter start-up included), by wall clock: `--jobs 1`, "
            "`--jobs 2`, and `--scheduler` on a `distributed.LocalCluster` of 2 single-threaded worker processes "
            "started just before its own sweep and closed after it (its start-up not timed; idle beside the "
            "others it took 8% of a core). "
            f"Medians over {args.rounds} round(s), the order rotating. Speed-up = time of `--jobs 1` / time.",
            machine_line(("numpy", "shapely", "distributed")),
            load_line(before, after) + priority_note(),
            markdown_table(["configuration", "wall s", "speed-up"], rows),
            f"The three tables are {'identical' if same else 'NOT identical'} (every column but the times; "
            f"{failed} failed jobs). Speed-up with 2 processes: {two:.2f}× (target ≥ {TARGET}× on 2 cores: "
            f"{'met' if two >= TARGET else 'NOT met'}).",
        ]
    )
    print(body)
    print(env_note, file=sys.stderr)
    if args.readme:
        replace_section(SECTION, body, README)


if __name__ == "__main__":
    main()
