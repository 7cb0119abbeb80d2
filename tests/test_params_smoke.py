"""Every enumerated or bool value of every ``Params`` field, end to end on one small map (issue 14, item 7).

The cases are discovered, not listed: for each stage's ``Params`` (map … simulate) and
``verify.Params``, every field whose docstring type is an enumeration (``{"a", "b"}``, read by
:func:`bearnav_cli.cli.fields.params_fields`, the reader the command-line options come from) and every bool
field, each value once, plus the named non-enum cases of the issue (:data:`EXTRA`). One test id per
(stage, field, value): the stages before the case's come from a module-wide baseline chain, its own
stage and the ones after it run again with the value. Each artifact made is written and loaded back
(its type's invariants, the content hash, the manifest's ``params`` holding the value); a plan's cells
are re-checked (``verify.check_geometry``, ``composition.check`` for a funnel plan); a simulation's
outcomes are valid codes and its trajectories lie in the map's bounds. A field that acts only with
another setting runs every value with it (:data:`WITH`).
"""

from __future__ import annotations

import copy
import functools

import numpy as np
import pytest

from bearnav_cli import artifacts, composition, pipeline, runtime, verify
from bearnav_cli.cli import fields
from bearnav_cli.datatypes import CLAIMS_CERTIFICATE, Outcome, Plan, Simulation
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.params import decompose, rrtstar, simplify, synthesize
from bearnav_cli.params.simulate import CAMERAS
from bearnav_cli.pipeline import chain, table
from bearnav_cli.pipeline import params as params_of
from bearnav_cli.runtime import bearing
from bearnav_cli.stages import map_, simulate

from .conftest import SMALL_MAP

#: The small map, planned with few RRT* samples; its closed loop runs fast and coarse (a smoke test).
SPEC = {
    **copy.deepcopy(SMALL_MAP),
    "params": {
        "rrtstar": {"iterations": 150, "step": 1.0, "seed": 0},
        "simulate": {"speed": 0.5, "alpha": 0.5, "dt": 0.5},
    },
}
#: verify's closed loop: a few starts, the same coarse step.
VERIFY = {"n_starts": 4, "dt": 0.5}
#: The stages in chain order and the artifact kind each writes.
CHAIN = [(stage.name, stage.output_kind) for stage in table.CHAIN]

#: Values that are neither an enumeration nor a bool but have an option no other test runs end to end.
EXTRA = {("simulate", "max_fix_error"): (1.0,)}
#: Settings a field's cases run with (every value of it), so that the field has an effect at all.
WITH = {
    # the paper's options act on the paper cells only (funnel cells come out identical); cbf_* shape the wedge
    ("decompose", "bisector_rule"): {"cells": "paper"},
    ("decompose", "barrier"): {"cells": "paper"},
    **{("decompose", name): {"cells": "paper", "barrier": "wedge"} for name in ("cbf_apex", "cbf_filter")},
    ("simulate", "max_fix_error"): {"noise_deg": 1.0},  # no fix is refused without bearing noise
    **{("simulate", name): {"dynamics": "unicycle"} for name in ("clamp_reverse", "turn_first", "certified_heading")},
    ("simulate", "look_on_purpose"): {"fov": 120.0},  # with a full view every heading sees the pair
}
#: ``camera="render"`` draws frames and detects tags with OpenCV, seconds per run: it has its own tests,
#: tests/test_render.py (test_the_controller_reaches_the_goal_from_rendered_frames) and tests/test_world.py.
SKIPPED = {("simulate", "camera", "render")}
#: The tuple of allowed values each enumerated field is checked against (the docstring must list them all).
TUPLES = {
    ("map", "unknown"): None,  # no module tuple: map_.run checks the literal pair (it only acts on a grid)
    ("rrtstar", "collision_policy"): rrtstar.POLICIES,
    ("simplify", "ctl"): simplify.CTL_MODES,
    ("decompose", "cells"): decompose.CELL_MODES,
    ("decompose", "cover"): decompose.COVER_DOMAINS,
    ("decompose", "bisector_rule"): decompose.BISECTOR_RULES,
    ("decompose", "cbf_apex"): decompose.CBF_APEXES,
    ("decompose", "cbf_filter"): decompose.CBF_FILTERS,
    ("decompose", "barrier"): decompose.BARRIERS,
    ("synthesize", "gain_structure"): synthesize.GAIN_STRUCTURES,
    ("synthesize", "lp_form"): synthesize.LP_FORMS,
    ("simulate", "dynamics"): runtime.DYNAMICS,
    ("simulate", "measurement"): runtime.MEASUREMENTS,
    ("simulate", "reconstruction"): bearing.METHODS,
    ("simulate", "camera"): CAMERAS,
    ("simulate", "estimator"): runtime.ESTIMATORS,
    ("verify", "dynamics"): runtime.DYNAMICS,
}


def discovered() -> list[tuple[str, str, object]]:
    """(stage, field, value) for every enumerated value and both values of every bool field, plus :data:`EXTRA`."""
    found = []
    for stage in fields.PARAMS_MODULES:
        for field in fields.params_fields(stage):
            values = field.choices or ((False, True) if field.kind is bool else ())
            found += [(stage, field.name, value) for value in (*values, *EXTRA.get((stage, field.name), ()))]
    return found


def _param(case: tuple[str, str, object]):
    if case in SKIPPED:
        return pytest.param(*case, marks=pytest.mark.skip(reason="camera=render: see tests/test_render.py"))
    return pytest.param(*case)


CASES = discovered()


def test_the_cases_cover_the_issue_and_the_module_tuples():
    """The issue's named options are among the cases; every enumerated field lists its module's tuple."""
    named = {
        ("decompose", "bisector_rule", "crossing"),
        ("decompose", "barrier", "wedge"),
        ("simulate", "odometry", False),
        ("simulate", "turn_first", False),
        ("simulate", "max_fix_error", 1.0),
        *(("decompose", "cbf_filter", v) for v in decompose.CBF_FILTERS),
    }
    assert named <= set(CASES)
    enumerated = {
        (stage, f.name): f.choices for stage in fields.PARAMS_MODULES for f in fields.params_fields(stage) if f.choices
    }
    for key, values in TUPLES.items():
        if values is not None:
            assert enumerated[key] == tuple(values), key
    assert set(enumerated) == set(TUPLES)


# --------------------------------------------------------------------------- the chain, cached per worker


def _run(stage: str, upstream: dict, overrides: dict | None, base: tuple | None = None) -> tuple[dict, dict]:
    """``(artifacts by kind, Params by stage)``: ``upstream``'s artifacts, then ``stage`` with ``overrides`` and the
    stages after it with the map's settings, as :func:`bearnav_cli.pipeline.compute` runs them (its steps).
    When ``stage``'s resolved ``Params`` equal those of ``base`` (a value that is the default), ``base``."""
    made, params = dict(upstream), {}
    for name, kind in CHAIN[[name for name, _ in CHAIN].index(stage) :]:
        step, mine = pipeline.STAGE_BY_NAME[name], overrides if name == stage else None
        if name == "map":
            payload = map_.MapSource(spec=copy.deepcopy(SPEC), file="smoke.yaml", sha256="0")
            params[name] = params_of.map_stage_params(payload, mine)
        else:
            payload = made[step.input_kind]
            params[name] = params_of.stage_params(name, payload, mine)
        if base is not None and name == stage and params[name] == base[1][name]:
            return base
        made[kind] = chain.execute(step, payload, params[name], None, name)
    return made, params


@functools.cache
def baseline() -> tuple[dict, dict]:
    """The whole chain with the map's settings, from the map to the simulation."""
    return _run("map", {}, None)


@functools.cache
def _made(stage: str, overrides: tuple) -> tuple[dict, dict]:
    base = baseline()
    names = [name for name, _ in CHAIN]
    upstream = {kind: base[0][kind] for _, kind in CHAIN[: names.index(stage)]}
    return _run(stage, upstream, dict(overrides), base)


def run_case(stage: str, overrides: dict) -> tuple[dict, dict]:
    """The chain of one case: cached per worker, so a value and its neighbours share the stages before theirs."""
    return _made(stage, tuple(sorted(overrides.items())))


@functools.cache
def verify_report(dynamics: str) -> verify.VerifyReport:
    return verify.run(baseline()[0]["plan"], verify.Params(dynamics=dynamics, **VERIFY))


# --------------------------------------------------------------------------- the invariants


#: The checks already run in this worker, by ``id`` of the artifact (the caches above keep every one alive).
_CHECKED: dict[int, object] = {}


def round_trip(tmp_path, stage: str, kind: str, artifact, params) -> dict:
    """Write ``artifact`` as ``plan`` would and load it back: its invariants and hash hold; the loaded manifest."""
    if id(artifact) in _CHECKED:
        return _CHECKED[id(artifact)]
    version = pipeline.STAGE_BY_NAME[stage].module.VERSION
    manifest = artifacts.make_manifest(
        kind,
        artifact,
        stage=stage,
        stage_version=version,
        params=artifacts.params_dict(params),
        input_path=None,
        input_hash="0",
        summary="",
        elapsed_s=0.0,
        stats=getattr(artifact, "stats", None),
    )
    path = artifacts.save(tmp_path / artifacts.KINDS[kind].filename, artifact, manifest)
    loaded = artifacts.load(path, expect=kind)
    assert type(loaded.artifact) is type(artifact)
    assert artifacts.content_hash(artifacts.entries_of(loaded.artifact), kind) == manifest["content_sha256"]
    _CHECKED[id(artifact)] = loaded.manifest
    return loaded.manifest


def check_plan(plan: Plan) -> None:
    """Every certified cell re-checked: the geometry of §8, and the composed certificate of a funnel plan."""
    if ("plan", id(plan)) in _CHECKED:
        return
    space = FreeSpace.from_map(plan.map)
    geometry = verify.check_geometry(plan, space)
    assert geometry.ok, geometry
    assert np.isin(plan.status, CLAIMS_CERTIFICATE).any()
    if plan.cells.is_funnel:
        comp = composition.check(plan, simulate.Params().speed, space)
        assert comp.ok, comp.problems
    _CHECKED["plan", id(plan)] = True


def check_simulation(sim: Simulation) -> None:
    assert len(sim) > 0
    assert np.isin(sim.outcome, [int(o) for o in Outcome]).all(), sim.outcome
    low, high = np.asarray(sim.map.bounds[:2], float), np.asarray(sim.map.bounds[2:], float)
    for points in (sim.trajectory_coords, sim.final_position, sim.starts):
        assert ((points >= low - 1e-9) & (points <= high + 1e-9)).all()


#: Visible effects of a value beyond the manifest: (stage, field) -> check(value, artifacts).
EFFECTS = {
    ("decompose", "cells"): lambda v, made: made["cells"].certificate == ("paper" if v == "paper" else "funnel"),
    ("simulate", "record_trajectories"): lambda v, made: (len(made["simulation"].trajectory_coords) > 0) == v,
}


@pytest.mark.parametrize(("stage", "field", "value"), [_param(case) for case in CASES if case[0] != "verify"])
def test_every_option_value_runs_end_to_end(tmp_path, stage, field, value):
    overrides = {**WITH.get((stage, field), {}), field: value}
    made, params = run_case(stage, overrides)
    assert getattr(params[stage], field) == value
    names = [name for name, _ in CHAIN]
    for name, kind in CHAIN[names.index(stage) :]:
        manifest = round_trip(tmp_path, name, kind, made[kind], params[name])
        if name == stage:
            assert manifest["params"][field] == value, "the value did not reach the artifact's manifest"
    check_plan(made["plan"])
    check_simulation(made["simulation"])
    effect = EFFECTS.get((stage, field))
    if effect is not None:
        assert effect(value, made)


@pytest.mark.parametrize(("stage", "field", "value"), [_param(case) for case in CASES if case[0] == "verify"])
def test_every_verify_value_runs(stage, field, value):
    report = verify_report(value) if field == "dynamics" else None
    assert report is not None, f"no runner for verify.{field}"
    assert not report.failed, report.reasons
    check_simulation(report.rollouts)
    # the value reached the loop: the two robots drive differently from the same starts
    other = next(v for v in runtime.DYNAMICS if v != value)
    assert not np.array_equal(report.rollouts.steps, verify_report(other).rollouts.steps)
