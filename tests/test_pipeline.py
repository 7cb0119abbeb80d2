"""Issue 24.3: stages own their checks and verdicts, and the pipeline reaches them through its table.

A stage module may define ``check_resources(input, params, given)`` and ``problems(result)``; the
pipeline calls them through :class:`~bearnav_cli.pipeline.Stage` (a default where a stage has none), which
turns the parameter a stage's error names into the option or map field that set it
(:class:`~bearnav_cli.pipeline.Origins`).
"""

from __future__ import annotations

import dataclasses
import functools
import inspect

import numpy as np
import pytest

from bearnav_cli import pipeline, verdicts
from bearnav_cli.datatypes import CellStatus
from bearnav_cli.errors import InvalidParamsError, ResourceLimitError
from bearnav_cli.pipeline import params as pipeline_params
from bearnav_cli.pipeline.table import CHAIN, HOOKS, REQUIRED
from bearnav_cli.stages import rrtstar, simulate

from .conftest import SMALL_MAP, build_map


@functools.cache
def _made() -> dict:
    return pipeline.compute(build_map(SMALL_MAP), through="synthesize")


def test_every_stage_module_defines_what_the_table_needs_and_its_hooks_as_documented():
    """The hooks a stage defines take the documented parameters and are in its ``__all__`` (a misspelt hook
    would be a silent default); the stages the docs name define them."""
    defined = {}
    for stage in CHAIN:
        module = stage.module
        assert all(hasattr(module, name) for name in REQUIRED), stage.module_name
        for hook, names in HOOKS.items():
            function = getattr(module, hook, None)
            if function is None:
                continue
            defined.setdefault(hook, []).append(stage.name)
            assert hook in module.__all__, (stage.module_name, hook)
            parameters = list(inspect.signature(function).parameters)
            assert len(parameters) == len(names), (stage.module_name, hook, parameters)
        public = {name for name in module.__all__ if callable(getattr(module, name, None))}
        assert not {name for name in public if "check" in name or "problem" in name} - set(HOOKS), stage.module_name
    assert defined == {
        "check_resources": ["rrtstar", "simulate"],
        "problems": ["rrtstar", "simplify", "decompose", "synthesize"],
    }


def test_stages_name_their_own_parameter_and_the_table_the_field_that_set_it():
    made = _made()
    params = rrtstar.Params(step=1e-5)
    with pytest.raises(ResourceLimitError) as raised:
        rrtstar.check_resources(made["map"], params, frozenset({"step"}))
    assert raised.value.field == "step" and "neighbour grid" in raised.value.reason
    for overrides, field in (({"step": 1e-5}, "--step"), (None, "params.rrtstar.step")):
        map_ = dataclasses.replace(made["map"], params={"rrtstar": {"step": 1e-5}} if overrides is None else {})
        with pytest.raises(ResourceLimitError) as raised:
            pipeline_params.stage_params("rrtstar", map_, overrides)
        assert raised.value.field == field, raised.value


def test_a_derived_border_spacing_is_blamed_on_the_step():
    """The ``_explicit`` string of old is :attr:`Origins.given`: a spacing left at step/10 names ``step``."""
    thin = build_map(
        {
            "name": "thin",
            "bounds": [0, 0, 100, 0.1],
            "robot_radius": 0.001,
            "goal": [0.05, 0.05],
            "starts": [[99, 0.05]],
            "obstacles": [],
            "landmarks": [[0, 0], [100, 0.1]],
        }
    )
    cases = (
        ({"step": 0.005}, "--step", "(step/10 = 0.0005)"),
        ({"step": 0.005, "border_spacing": 0.0005}, "--border-spacing", "0.0005 would"),
    )
    for overrides, field, words in cases:
        with pytest.raises(ResourceLimitError) as raised:
            pipeline_params.stage_params("rrtstar", thin, overrides)
        assert raised.value.field == field and words in raised.value.reason, raised.value


def test_origins_record_where_each_value_came_from():
    made = _made()
    map_ = dataclasses.replace(made["map"], params={"simulate": {"dt": 0.05}})
    params, origins = pipeline_params.resolve("simulate", map_.params, {"speed": 0.2}, map_.diagonal)
    assert origins.given == frozenset({"dt", "speed"})
    assert origins.field("dt") == "params.simulate.dt" and origins.field("speed") == "--speed"
    assert origins.field("fov") == "params.simulate.fov" and origins.field(None) is None
    assert (params.dt, params.speed) == (0.05, 0.2)


def test_the_closed_loop_estimate_names_dt_only_when_given():
    plan = _made()["plan"]
    slow = simulate.Params(dt=1e-6)
    for given, field in ((frozenset(), "speed"), (frozenset({"dt"}), "dt")):
        with pytest.raises(ResourceLimitError) as raised:
            simulate.check_resources(plan, slow, given)
        assert raised.value.field == field
    with pytest.raises(InvalidParamsError) as raised:
        pipeline.SIMULATE.check_resources(
            plan, simulate.Params(starts="random:2000000"), pipeline.Origins({"starts": "--starts"})
        )
    assert raised.value.field == "--starts" and "at most 1,000,000 runs" in raised.value.reason


def test_problems_are_the_stages_verdicts_worst_first():
    made = _made()
    for stage in CHAIN[:-1]:
        assert stage.problems(made[stage.output_kind]) == [], stage.name
    plan = made["plan"]
    status = np.array(plan.status)
    status[[3, 5]] = CellStatus.NOT_CERTIFIED
    found = pipeline.STAGE_BY_NAME["synthesize"].problems(dataclasses.replace(plan, status=status))
    assert [(p.kind, p.cells) for p in found] == [(verdicts.NOT_CERTIFIED, (3, 5))]
    assert found[0].text == "cells 3, 5 are not certified (status 2 or 3)"
    root = dataclasses.replace(
        made["tree"], nodes=made["tree"].nodes[:1], parent=made["tree"].parent[:1], cost=made["tree"].cost[:1]
    )
    assert [p.kind for p in pipeline.STAGE_BY_NAME["rrtstar"].problems(root)] == [verdicts.NO_ROUTE]
