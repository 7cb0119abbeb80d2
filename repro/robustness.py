"""Robustness of the bearing-only controllers: success against bearing noise and field of view, before and after tags.

For each example map the same random free starts (``random:200``, seed 0) are driven from
bearings with Gaussian bearing noise of 0, 1, 2 and 5° and a camera field of view of 360, 90,
60 and 45°, by the single integrator and by the unicycle; every other closed-loop parameter is
the map's own (``params: simulate`` of its YAML). Each configuration runs twice:

- **before**: the plan ``bearnav plan`` made from the map, with the map's own tags;
- **after**: the same plan with the tags ``bearnav tags`` proposes for a 60° camera and 1° noise
  (``tags.propose_tags(plan, tags.Params(fov_deg=60, noise_deg=1))``) added to the map. The map
  stage builds the new map from the YAML with the proposal appended
  (``tags.map_spec_with_tags``), and decompose and synthesize run again on the *same*
  simplified tree with it. The fields do not depend on the landmarks (ALGORITHMS Lemma 3), so
  the cells are those of the plan (checked: the script stops if they differ) and only the gains
  change; the starts, and which of them lie in the certified domain, are the same.

Usage::

    .venv/bin/python repro/robustness.py \\
        maps/kitchen.yaml plans/kitchen/simplified.npz plans/kitchen/plan.npz \\
        maps/storeroom.yaml plans/storeroom/simplified.npz plans/storeroom/plan.npz \\
        -o docs/figures/robustness.png

(one ``MAP.yaml SIMPLIFIED.npz PLAN.npz`` triple per map; ``--starts N`` changes the number of
random starts) writes the plot (success rate against noise, one line per field of view, solid
before and dashed after the tags, one panel per map and dynamics), ``robustness.csv`` (one row
per map, tags, dynamics, noise and field of view: the tag count, runs, success rate, the count of
each failure and, on funnel plans, the share of starts in the certified domain and the success
rate of those) and ``robustness.md`` (tables per map: noise × field of view, "before → after")
next to it.
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from common import load, sim_params
from matplotlib.lines import Line2D

from bearnav_cli import pipeline, plot, tags
from bearnav_cli.cli import read_map_source
from bearnav_cli.datatypes import replace
from bearnav_cli.stages import decompose, simulate, synthesize
from bearnav_cli.stages import map_ as map_stage

NOISES_DEG = (0.0, 1.0, 2.0, 5.0)
FOVS_DEG = (360.0, 90.0, 60.0, 45.0)
DYNAMICS = ("single", "unicycle")
DYNAMICS_NAMES = {"single": "single integrator", "unicycle": "unicycle"}
TAG_SETS = ("before", "after")
#: Random free starts per configuration (``random:N``) and their seed.
STARTS = 200
SEED = 0
#: The camera ``bearnav tags`` places the new tags for.
TAGS_FOV_DEG = 60.0
TAGS_NOISE_DEG = 1.0
FAILURES = ("collision", "stall", "timeout", "lost")
COLUMNS = ("map", "tags", "n_tags", "dynamics", "noise_deg", "fov_deg", "runs", "success_rate", *FAILURES,
           "in_domain", "success_rate_in_domain")  # fmt: skip
#: Cells the re-made plan must share with the plan (ALGORITHMS Lemma 3).
CELL_KEYS = ("cell_vertices", "cell_vertex_offsets", "cell_A", "cell_b", "cell_row_offsets", "exit_point",
             "exit_dir", "cell_rank", "cell_node")  # fmt: skip


@dataclass
class Case:
    """One map: its plan with its own tags, the proposal and the plan re-made with the proposed tags."""

    name: str
    before: object
    after: object
    proposal: tags.TagProposal


def with_proposed_tags(map_path: Path, simplified_path: Path, plan_path: Path) -> Case:
    """Propose tags for the plan and re-make it with them on the same simplified tree (decompose + synthesize)."""
    plan, _ = load(plan_path, "plan")
    simplified, _ = load(simplified_path, "simplified")
    began = time.perf_counter()
    proposal = tags.propose_tags(plan, tags.Params(fov_deg=TAGS_FOV_DEG, noise_deg=TAGS_NOISE_DEG))
    name = plan.map.name
    print(f"{name:<18} bearnav tags (fov {TAGS_FOV_DEG:g}°, noise {TAGS_NOISE_DEG:g}°): {proposal.summary()} "
          f"({time.perf_counter() - began:.1f} s)", flush=True)  # fmt: skip
    if proposal.count == 0:
        return Case(name, plan, plan, proposal)
    source = read_map_source(map_path)
    spec = tags.map_spec_with_tags(source.spec, proposal)
    with_tags = map_stage.MapSource(spec=spec, file=source.file, sha256=f"{source.sha256}+{proposal.count} tags",
                                    grid=source.grid)  # fmt: skip
    new_map = map_stage.run(with_tags, pipeline.resolve_params("map", spec.get("params")))
    if new_map.landmark_ids != proposal.landmark_ids or not np.array_equal(new_map.landmarks, proposal.landmarks):
        raise SystemExit(f"{map_path}: the map with the proposed tags does not extend {plan_path}'s landmarks "
                         "(was the plan made from this map?)")  # fmt: skip
    cells = decompose.run(replace(simplified, map=new_map), pipeline.resolve_params("decompose", new_map.params))
    for key in CELL_KEYS:
        if not np.array_equal(getattr(cells, key), getattr(plan.cells, key)):
            raise SystemExit(f"{simplified_path} with the new tags gives other cells than {plan_path} ({key}): "
                             "is it the simplified tree the plan was made from?")  # fmt: skip
    after = synthesize.run(cells, pipeline.resolve_params("synthesize", new_map.params))
    print(f"{name:<18} re-planned with {len(new_map.landmarks)} tags: {synthesize.summary(after)}", flush=True)
    return Case(name, plan, after, proposal)


def configurations() -> list[tuple[str, float, float]]:
    """Every (dynamics, field of view, noise) of the grid, in the order they run."""
    return [(d, f, n) for d in DYNAMICS for f in FOVS_DEG for n in NOISES_DEG]


def sweep(case: Case, n_starts: int, counter: list[int], total: int, began: float) -> list[dict]:
    """Every configuration on both plans of one map: one row of :data:`COLUMNS` each."""
    starts_text = f"random:{n_starts}"
    starts = simulate.resolve_starts(case.before, sim_params(case.before, starts=starts_text, seed=SEED))
    funnel = case.before.cells.certificate == "funnel"
    rows = []
    for which in TAG_SETS:
        plan = case.before if which == "before" else case.after
        if which == "after" and plan is case.before:  # the proposal added nothing: the same runs
            rows += [{**r, "tags": "after"} for r in rows]
            counter[0] += len(configurations())
            continue
        for dynamics, fov, noise in configurations():
            params = sim_params(plan, dynamics=dynamics, measurement="bearing", fov=fov, noise_deg=noise,
                                starts=starts_text, seed=SEED, record_trajectories=False)  # fmt: skip
            t0 = time.perf_counter()
            runs = simulate.rollout(plan, starts, params)
            counts = runs.counts()
            inside = runs.start_in_domain
            rows.append({
                "map": case.name, "tags": which, "n_tags": len(plan.map.landmarks), "dynamics": dynamics,
                "noise_deg": noise, "fov_deg": fov, "runs": len(runs), "success_rate": round(runs.success_rate, 4),
                **{k: counts[k] for k in FAILURES},
                "in_domain": round(float(np.mean(inside)), 4) if funnel else "",
                "success_rate_in_domain": round(runs.success_rate_of(inside), 4) if funnel and inside.any() else "",
            })  # fmt: skip
            counter[0] += 1
            print(f"[{counter[0]:>3}/{total}] {case.name:<18} {which:<6} {len(plan.map.landmarks):>2} tags "
                  f"{dynamics:<8} fov {fov:>3g}° noise {noise:g}°: {simulate.summary(runs)} "
                  f"({time.perf_counter() - t0:.1f} s, {(time.perf_counter() - began) / 60:.1f} min in all)",
                  flush=True)  # fmt: skip
    return rows


def pick(rows: list[dict], **match) -> list[dict]:
    return [r for r in rows if all(r[k] == v for k, v in match.items())]


def draw(rows: list[dict], cases: list[Case]) -> plt.Figure:
    """Success rate against noise: one panel per (map, dynamics), one colour per field of view, solid before and
    dashed after the tags."""
    colors = dict(zip(FOVS_DEG, ("#1f77b4", "#2ca02c", "#ff7f0e", "#d62728"), strict=True))
    markers = dict(zip(FOVS_DEG, "osD^", strict=True))
    fig, axes = plt.subplots(len(cases), len(DYNAMICS), figsize=(5.2 * len(DYNAMICS), 3.1 * len(cases) + 0.9),
                             sharex=True, sharey=True, squeeze=False)  # fmt: skip
    for row_axes, case in zip(axes, cases, strict=True):
        for ax, dynamics in zip(row_axes, DYNAMICS, strict=True):
            for which, style in zip(TAG_SETS, ("-", "--"), strict=True):
                for fov in FOVS_DEG:
                    line = pick(rows, map=case.name, tags=which, dynamics=dynamics, fov_deg=fov)
                    ax.plot([r["noise_deg"] for r in line], [100 * r["success_rate"] for r in line], ls=style,
                            marker=markers[fov], ms=4, lw=1.3, color=colors[fov],
                            mfc=colors[fov] if which == "before" else "white")  # fmt: skip
            n_before, n_after = len(case.before.map.landmarks), len(case.after.map.landmarks)
            ax.set_title(f"{case.name}, {DYNAMICS_NAMES[dynamics]}: {n_before} → {n_after} tags", fontsize=9)
            ax.set_xticks(NOISES_DEG)
            ax.set_ylim(0, 102)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=8)
        row_axes[0].set_ylabel("runs reaching the goal (%)", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("bearing noise σ (°)", fontsize=8)
    handles = [Line2D([], [], color=colors[f], marker=markers[f], ms=4, label=f"{f:g}° field of view")
               for f in FOVS_DEG]  # fmt: skip
    handles += [Line2D([], [], color="black", ls="-", label="the map's own tags"),
                Line2D([], [], color="black", ls="--", mfc="white", marker="o", ms=4,
                       label=f"after bearnav tags (placed for {TAGS_FOV_DEG:g}°, {TAGS_NOISE_DEG:g}°)")]  # fmt: skip
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8, frameon=False)
    runs = rows[0]["runs"]
    fig.suptitle(f"Driven by bearings: success rate of {runs} random starts against bearing noise and field of view",
                 fontsize=10)  # fmt: skip
    fig.tight_layout(rect=(0, 0.05, 1, 0.98))
    return fig


def percent(value) -> str:
    return "–" if value == "" or (isinstance(value, float) and math.isnan(value)) else f"{100 * value:.1f}%"


def cell(rows: list[dict], key: str, **match) -> str:
    """``before → after`` of ``key`` for one configuration."""
    values = [percent(pick(rows, tags=which, **match)[0][key]) for which in TAG_SETS]
    return values[0] if values[0] == values[1] else f"{values[0]} → {values[1]}"


def markdown(rows: list[dict], cases: list[Case]) -> str:
    """Per map: the tags, then per dynamics a table noise × field of view ("before → after"); then every row."""
    runs = rows[0]["runs"]
    lines = [
        "# Robustness: success by bearing noise and field of view, before and after `bearnav tags`",
        "",
        f"Generated by `repro/robustness.py` (`make reproduce`): the same {runs} random free starts per map "
        f"(`random:{runs}`, seed {SEED}) driven from bearings by the single integrator and by the unicycle, "
        "Gaussian bearing noise σ and a camera field of view as given, occlusion by the raw obstacles, the "
        "map's own `simulate` parameters otherwise. *Before*: the plan `bearnav plan` makes from the map, with "
        "the map's own tags. *After*: the tags `bearnav tags` proposes for a "
        f"{TAGS_FOV_DEG:g}° camera and {TAGS_NOISE_DEG:g}° noise (`tags.propose_tags`) added to the map, and "
        "decompose and synthesize re-run on the same simplified tree; the cells, the certified domain D and the "
        "starts are the same (ALGORITHMS Lemma 3), only the landmarks and the gains change. Each cell reads "
        "*before → after* (one number when they are equal). Every count in `robustness.csv`.",
        "",
    ]
    for case in cases:
        p = case.proposal
        lines += [f"## {case.name}", ""]
        if p.count == 0:
            lines += [f"{len(case.before.map.landmarks)} tags. They already meet the rule everywhere in D "
                      f"({TAGS_FOV_DEG:g}°, {TAGS_NOISE_DEG:g}°): `bearnav tags` adds nothing, *after* is *before*.",
                      ""]  # fmt: skip
        else:
            lines += [
                f"Tags: {len(case.before.map.landmarks)} (the map's own) → {len(case.after.map.landmarks)} "
                f"(`bearnav tags` adds {p.count}; lower bound {p.lower_bound}). The perception rule "
                f"({TAGS_FOV_DEG:g}° camera along the field, {TAGS_NOISE_DEG:g}°) holds on "
                f"{p.before.fraction_domain:.1%} → {p.after.fraction_domain:.1%} of D and "
                f"{p.before.fraction_free:.1%} → {p.after.fraction_free:.1%} of the free space"
                + (f"; {1 - p.coverable_fraction:.1%} of D cannot be covered." if p.coverable_fraction < 1 else "."),
                "",
            ]  # fmt: skip
        first = pick(rows, map=case.name, tags="before")[0]
        tables = [("success_rate", f"all {runs} starts")]
        if first["in_domain"] != "":
            n_in = round(first["in_domain"] * runs)
            lines += [f"{n_in} of the {runs} starts ({percent(first['in_domain'])}) lie in the certified domain D.", ""]
            tables.append(("success_rate_in_domain", f"the {n_in} starts in D"))
        for dynamics in DYNAMICS:
            for key, which_starts in tables:
                lines += [
                    f"{DYNAMICS_NAMES[dynamics].capitalize()}, runs reaching the goal, {which_starts}:",
                    "",
                    "| noise σ | " + " | ".join(f"{f:g}° view" for f in FOVS_DEG) + " |",
                    "| ---: | " + " | ".join("---:" for _ in FOVS_DEG) + " |",
                ]
                for noise in NOISES_DEG:
                    cells = [cell(rows, key, map=case.name, dynamics=dynamics, noise_deg=noise, fov_deg=f)
                             for f in FOVS_DEG]  # fmt: skip
                    lines.append(f"| {noise:g}° | " + " | ".join(cells) + " |")
                lines.append("")
    lines += ["## Every configuration", "", "| " + " | ".join(COLUMNS) + " |", "|" + " --- |" * len(COLUMNS)]
    lines += ["| " + " | ".join(f"{r[c]:g}" if isinstance(r[c], float) else str(r[c]) for c in COLUMNS) + " |"
              for r in rows]  # fmt: skip
    return "\n".join(lines) + "\n"


def main() -> None:
    """Propose the tags, re-plan, run the grid on every map, write the CSV, the markdown tables and the plot."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("inputs", type=Path, nargs="+",
                        help="MAP.yaml SIMPLIFIED.npz PLAN.npz for each map (one row of panels each)")  # fmt: skip
    parser.add_argument("-o", "--out", type=Path, required=True, help="Figure (.png); .csv and .md go next to it.")
    parser.add_argument("--starts", type=int, default=STARTS, help=f"Random starts per configuration ({STARTS}).")
    args = parser.parse_args()
    if len(args.inputs) % 3 or args.starts < 1:
        parser.error("give MAP.yaml SIMPLIFIED.npz PLAN.npz for each map, and --starts >= 1")
    began = time.perf_counter()
    cases = [with_proposed_tags(*args.inputs[k : k + 3]) for k in range(0, len(args.inputs), 3)]
    total = len(cases) * len(TAG_SETS) * len(configurations())
    counter = [0]
    rows = []
    for case in cases:
        rows += sweep(case, args.starts, counter, total, began)
    minutes = (time.perf_counter() - began) / 60
    with args.out.with_suffix(".csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    args.out.with_suffix(".md").write_text(markdown(rows, cases))
    plot.save_figure(draw(rows, cases), str(args.out))
    print(f"wrote {args.out}, {args.out.with_suffix('.csv')} and {args.out.with_suffix('.md')} ({minutes:.1f} min)")


if __name__ == "__main__":
    main()
