"""Issue 11's done-when: bearings on maps nobody tuned, with the map's own tags and after `bearnav tags`.

For every map: ``bearnav plan`` with the map's own tags, ``bearnav tags PLAN.npz --fov 60
--noise-deg 1`` (the tags it proposes, within its budget), ``bearnav plan`` of the map with them;
then, on both plans, ``--starts`` starts drawn uniformly in the certified domain ``D`` (the union
of the funnel cells, area-weighted) driven by :func:`bearnav_cli.stages.simulate.rollout` with a
60° unicycle, 1° and 2° bearing noise and the simulator's default wheel slip. The target of the
issue is at least 99% (1°) and 97% (2°) of the starts reaching the goal with 0 collisions.

The maps: the example maps, the three made by ``bench/made_maps.py`` (office, maze, clutter), and
``kitchen_12``, the kitchen with only its original twelve tags, given the budget of the sixteen
placed by hand (``--max-tags 16``).
Not a timing benchmark.

Run from the repository root (about 10 minutes on 2 cores)::

    PYTHONPATH=.:bench .venv/bin/python bench/perception.py [--starts 1000] [--readme]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import made_maps
import numpy as np
import shapely
import yaml
from common import REPO_DIR, machine_line, markdown_table, replace_section

from bearnav_cli import artifacts, pipeline
from bearnav_cli.stages import simulate

BEARNAV = [sys.executable, "-m", "bearnav_cli"]
EXAMPLES = ["kitchen", "paper_sim_circles", "paper_b_circles", "storeroom"]
NOISES = (1.0, 2.0)
FOV = 60.0


def sample_in_domain(cells, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points of ``D``: a cell by area, then a uniform point of it (rejection in its box)."""
    polys = [shapely.Polygon(cells.vertices(c)) for c in range(cells.n_cells)]
    area = np.array([p.area for p in polys])
    out = []
    for c in rng.choice(len(polys), size=n, p=area / area.sum()):
        v = cells.vertices(int(c))
        A, b = cells.rows(int(c))
        while True:
            p = rng.uniform(v.min(axis=0), v.max(axis=0))
            if np.all(A @ p <= b):
                out.append(p)
                break
    return np.array(out)


def plan(map_yaml: Path, out: Path) -> tuple[int, object]:
    """``bearnav plan``; its exit code (1: blind spots or uncertified cells) and the plan."""
    done = subprocess.run([*BEARNAV, "plan", str(map_yaml), "-o", str(out), "--quiet"], capture_output=True, text=True)
    if done.returncode not in (0, 1):
        raise RuntimeError(f"bearnav plan {map_yaml}: {done.stderr.strip()}")
    return done.returncode, artifacts.load(out / "plan.npz", "plan").artifact


def closed_loop(plan_obj, starts: np.ndarray, noise: float) -> dict:
    """The closed loop as ``bearnav simulate`` runs it: the map's own ``params: simulate:`` (paper B's
    α = 1, say) under the bench's camera, noise and dynamics."""
    overrides = {"dynamics": "unicycle", "fov": FOV, "noise_deg": noise, "record_trajectories": False, "seed": 0}
    params = pipeline.resolve_params("simulate", plan_obj.map.params, overrides)
    sim = simulate.rollout(plan_obj, starts, params)
    counts = sim.counts()
    return {
        "success": float(np.mean(sim.outcome == 0)),
        "collision": counts["collision"],
        "lost": counts["lost"],
        "other": len(starts) - counts["success"] - counts["collision"] - counts["lost"],
    }


#: The kitchen as it was first drawn: its first twelve tags (``tag0``–``tag11``); the other sixteen
#: were placed by hand for a 60° camera. ``bearnav tags`` gets the same budget (issue 11's done-when).
ORIGINAL_KITCHEN_TAGS, HAND_PLACED = 12, 16


def original_kitchen(work: Path) -> Path:
    """``maps/kitchen.yaml`` with only its original twelve tags, written into ``work``."""
    spec = yaml.safe_load((REPO_DIR / "maps" / "kitchen.yaml").read_text())
    spec["landmarks"] = spec["landmarks"][:ORIGINAL_KITCHEN_TAGS]
    spec["name"] = "kitchen_12"
    path = work / "kitchen_12.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def measure(name: str, map_yaml: Path, work: Path, n_starts: int, max_tags: int | None = None) -> dict:
    started = time.perf_counter()
    code, own = plan(map_yaml, work / name)
    n_own = len(own.map.landmarks)
    tagged = work / f"{name}_tags.yaml"
    budget = [] if max_tags is None else ["--max-tags", str(max_tags)]
    proposal = subprocess.run(
        [
            *BEARNAV,
            "tags",
            str(work / name / "plan.npz"),
            "--fov",
            str(FOV),
            "--noise-deg",
            "1",
            *budget,
            "-o",
            str(tagged),
            "--json",
        ],
        capture_output=True,
        text=True,
    )
    if proposal.returncode not in (0, 1) or not tagged.exists():
        raise RuntimeError(f"bearnav tags {name}: {proposal.stderr.strip()}")
    report = json.loads(proposal.stdout) if proposal.stdout.strip().startswith("{") else {}
    code_tags, with_tags = plan(tagged, work / f"{name}_tags")
    row = {
        "map": name,
        "own_tags": n_own,
        "plan_exit": code,
        "tags_after": len(with_tags.map.landmarks),
        "tags_exit": proposal.returncode,
        "lower_bound": report.get("lower_bound"),
        "plan_exit_after": code_tags,
    }
    for label, p in (("own", own), ("after", with_tags)):
        starts = sample_in_domain(p.cells, n_starts, np.random.default_rng(0))
        for noise in NOISES:
            row[f"{label}_{noise:g}"] = closed_loop(p, starts, noise)
    row["seconds"] = time.perf_counter() - started
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=1000)
    parser.add_argument("--maps", nargs="*", default=None, help="Only these (example names or office/maze/clutter).")
    parser.add_argument("--readme", action="store_true", help="Write the table into bench/README.md.")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        maps = {name: REPO_DIR / "maps" / f"{name}.yaml" for name in EXAMPLES}
        for kind, make in made_maps.KINDS.items():
            spec = make(0)
            path = work / f"{spec['name']}.yaml"
            path.write_text(yaml.safe_dump(spec, sort_keys=False))
            maps[kind] = path
        maps["kitchen_12"] = original_kitchen(work)
        for name, path in maps.items():
            if args.maps and name not in args.maps:
                continue
            rows.append(measure(name, path, work, args.starts, HAND_PLACED if name == "kitchen_12" else None))
            print(json.dumps(rows[-1]), flush=True)

    def cell(result: dict) -> str:
        other = f", {result['other']} stalled or late" if result["other"] else ""
        return f"{100 * result['success']:.1f}% ({result['collision']} coll., {result['lost']} lost{other})"

    table = markdown_table(
        ["map", "tags (own → after)", "own 1°", "own 2°", "after tags 1°", "after tags 2°"],
        [
            [
                r["map"],
                f"{r['own_tags']} → {r['tags_after']}",
                cell(r["own_1"]),
                cell(r["own_2"]),
                cell(r["after_1"]),
                cell(r["after_2"]),
            ]
            for r in rows
        ],
    )
    text = (
        f"{machine_line()} {args.starts} starts in D per plan, 60° unicycle, default wheel slip, "
        "each map's own `params: simulate:`; "
        f"`PYTHONPATH=.:bench python bench/perception.py`\n\n{table}"
    )
    print(text)
    if args.readme:
        replace_section("Perception", text)


if __name__ == "__main__":
    main()
