"""Helpers shared by the benchmarks: maps, timing, markdown tables and README sections.

Each benchmark script writes its results between its own pair of markers in
``bench/README.md`` (``<!-- name:begin -->`` … ``<!-- name:end -->``) and leaves
every other section alone, so several benchmarks can share the file.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import time
from importlib import metadata
from pathlib import Path
from typing import Any, Callable, Sequence

from bearnav_cli import pipeline
from bearnav_cli.datatypes import Map
from bearnav_cli.stages import map_

#: Directory of the benchmark scripts.
BENCH_DIR = Path(__file__).resolve().parent
#: Root of the repository (``maps/`` lives there).
REPO_DIR = BENCH_DIR.parent
#: The results file the benchmarks update.
README = BENCH_DIR / "README.md"


#: The example maps every map-by-map benchmark measures, and the seed of the maps made for the bearings work.
EXAMPLES = ("kitchen", "paper_sim_circles", "paper_b_circles", "storeroom")
MADE_SEED = 0


def measured_maps() -> dict[str, map_.MapSource]:
    """The example maps and the three ``made_maps.py`` makes (seed :data:`MADE_SEED`), as the CLI reads them."""
    from made_maps import KINDS

    from bearnav_cli.cli import read_map_source

    out = {name: read_map_source(REPO_DIR / "maps" / f"{name}.yaml") for name in EXAMPLES}
    for make in KINDS.values():
        spec = make(MADE_SEED)
        out[spec["name"]] = map_.MapSource(spec=spec, file=f"{spec['name']}.yaml", sha256="bench")
    return out


def load_map(path: Path) -> Map:
    """Build a normalised :class:`Map` from a bearnav map YAML, read as the CLI reads it.

    Parameters
    ----------
    path : Path
        The map file.

    Returns
    -------
    Map
    """
    from bearnav_cli.cli import read_map_source

    return pipeline.compute(read_map_source(path), through="map")["map"]


def run_stages(map_obj: Map, stages: Sequence[str]) -> Any:
    """The output of the last of ``stages`` (the chain after ``map``, in order: ``("rrtstar", "simplify")``).

    A shorthand for :func:`bearnav_cli.pipeline.compute` (``plan``'s parameter resolution, in memory),
    which new code calls directly.
    """
    chain = [stage.name for stage in (*pipeline.STAGES[1:], pipeline.SIMULATE)]
    if not stages or list(stages) != chain[: len(stages)]:
        raise ValueError(f"expected the stages {', '.join(chain)} from the first, got {list(stages)}")
    return list(pipeline.compute(map_obj, through=stages[-1]).values())[-1]


def timed(fn: Callable[..., Any], *args: Any, **kwargs: Any) -> tuple[float, Any]:
    """Call ``fn(*args, **kwargs)`` once.

    Returns
    -------
    seconds : float
        Wall time of the call (``time.perf_counter``).
    result : object
        What ``fn`` returned.
    """
    t0 = time.perf_counter()
    result = fn(*args, **kwargs)
    return time.perf_counter() - t0, result


def version(package: str) -> str:
    """Installed version of a distribution, or ``"not installed"``."""
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "not installed"


def machine_line(packages: Sequence[str] = ("numpy", "shapely", "ompl")) -> str:
    """One line naming the machine, the interpreter, package versions and today's date."""
    parts = [
        f"{platform.system()} {platform.machine()}",
        f"{os.cpu_count()} CPUs",
        f"Python {platform.python_version()}",
    ]
    parts += [f"{name} {version(name)}" for name in packages]
    return f"Machine: {', '.join(parts)}; run on {datetime.date.today().isoformat()}."


def _busy_cpu_seconds() -> float | None:
    """CPU seconds all processes have used since boot (``/proc/stat``), or None where it is missing."""
    try:
        fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()
    except OSError:
        return None
    if not fields or fields[0] != "cpu":
        return None
    user, nice, system, _idle, _iowait, irq, softirq, steal = (int(x) for x in fields[1:9])
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


def load_snapshot() -> dict[str, Any]:
    """What :func:`load_line` compares: load averages, busy CPU time of the machine and of this process."""
    t = os.times()
    return {
        "loadavg": os.getloadavg(),
        "busy": _busy_cpu_seconds(),
        "own": t.user + t.system + t.children_user + t.children_system,
        "wall": time.monotonic(),
    }


def load_line(before: dict[str, Any], after: dict[str, Any]) -> str:
    """One line on how loaded the machine was between two :func:`load_snapshot` calls.

    The load averages (1, 5, 15 min) before and after, and the CPU time that other processes
    used meanwhile: all busy CPU time (``/proc/stat``) minus this process's and its waited-for
    children's, per second of wall time (1.0 = one whole CPU busy with other work). The machine
    is shared: side-by-side ratios are meant to absorb such load, absolute times are not.
    """

    def fmt(load: Sequence[float]) -> str:
        return " / ".join(f"{x:.2f}" for x in load)

    text = (
        f"Load average (1 / 5 / 15 min, {os.cpu_count()} CPUs): {fmt(before['loadavg'])} before the run, "
        f"{fmt(after['loadavg'])} after"
    )
    wall = after["wall"] - before["wall"]
    if before["busy"] is not None and after["busy"] is not None and wall > 0:
        others = max(0.0, (after["busy"] - before["busy"]) - (after["own"] - before["own"])) / wall
        text += (
            f"; other processes used {others:.2f} CPUs on average during the {wall:.0f} s run "
            f"(of {os.cpu_count()}; busy time from /proc/stat minus the benchmark's own)"
        )
    return text + "."


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A GitHub markdown table; cells are converted with ``str``."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines)


def replace_section(name: str, body: str, readme: Path = README) -> None:
    """Replace the text between ``<!-- name:begin -->`` and ``<!-- name:end -->``.

    The file is created with a title and a machine line if it does not exist, and the
    markers are appended if they are missing. Everything outside the markers is kept.

    Parameters
    ----------
    name : str
        Section name used in the markers.
    body : str
        New markdown between the markers.
    readme : Path
        The results file.
    """
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    text = readme.read_text() if readme.exists() else f"# Benchmarks\n\n{machine_line()}\n"
    block = f"{begin}\n{body.strip()}\n{end}"
    head, found, rest = text.partition(begin)
    if found and end in rest:
        text = head + block + rest.partition(end)[2]
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    readme.write_text(text)


def quick_readme_args(doc: str, section: str, quick_help: str, argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The options every benchmark takes: ``--quick`` (a smoke test, ``quick_help`` says what it runs) and
    ``--readme`` (replace ``section`` of :data:`README`); the description is ``doc``'s first line."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help=quick_help)
    parser.add_argument("--readme", action="store_true", help=f"replace the '{section}' section of {README}")
    return parser.parse_args(argv)
