"""Each parameter declared once (issue 24 item 1): the ``Params`` of every command in :mod:`bearnav_cli.params`.

Every numeric field declares a range; ``limits.LIMITS`` and the command line's options are made of the
declarations; a declaration's choices are its docstring's; the declaring modules import no numpy.
"""

from __future__ import annotations

import dataclasses
import importlib
import subprocess
import sys
import typing

import pytest

from bearnav_cli import limits, params
from bearnav_cli.cli import fields as cli_fields
from bearnav_cli.params.declare import Range, declared, params_type

from .conftest import REPO


def _numeric(params_class: type, field: dataclasses.Field) -> bool:
    kinds = set(typing.get_args(typing.get_type_hints(params_class)[field.name])) or {
        typing.get_type_hints(params_class)[field.name]
    }
    return bool(kinds & {int, float}) and bool not in kinds


def unranged(params_class: type) -> list[str]:
    """The numeric fields of ``params_class`` without a declared range."""
    return [f.name for f in dataclasses.fields(params_class) if _numeric(params_class, f) and declared(f).range is None]


@pytest.mark.parametrize("command", sorted(params.MODULES))
def test_every_numeric_field_has_a_range(command):
    assert unranged(params_type(command)) == [], command


def test_a_field_without_a_range_fails_the_check():
    @dataclasses.dataclass(frozen=True)
    class Params:
        ranged: float = params.declare.param(1.0, range=Range(0, 2))
        bare: float = 1.0

    assert unranged(Params) == ["bare"]


def test_limits_are_the_declarations():
    for command in params.MODULES:
        ranges = {
            f.name: declared(f).range for f in dataclasses.fields(params_type(command)) if declared(f).range is not None
        }
        assert limits.LIMITS[command] == ranges, command


def test_each_stage_uses_the_declared_params():
    for command in params.MODULES:
        name = {"verify": "bearnav_cli.verify", "map": "bearnav_cli.stages.map_"}.get(command)
        stage = importlib.import_module(name or f"bearnav_cli.stages.{command}")
        assert issubclass(stage.Params, params_type(command)), command
        assert dataclasses.fields(stage.Params) == dataclasses.fields(params_type(command)), command


def test_the_docstring_choices_are_the_declared_ones():
    for command in params.MODULES:
        docs = cli_fields._attribute_docs(params_type(command).__doc__)
        for field in dataclasses.fields(params_type(command)):
            assert docs[field.name][1] == declared(field).choices, (command, field.name)


def test_the_declarations_import_no_numpy():
    code = (
        "import sys, importlib; from bearnav_cli import params\n"
        "for m in params.MODULES.values(): importlib.import_module(m)\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy', 'shapely', 'scipy')))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    assert done.stdout.strip() == "[]", done.stdout


def _ros_settings() -> type:
    """``Settings`` of contrib/ros2/bearnav_ros.py (numpy and the runtime only)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("bearnav_ros_defaults", REPO / "contrib" / "ros2" / "bearnav_ros.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module.Settings


def test_the_loop_defaults_have_one_source():
    """simulate's ``Params``, ``ControlSettings`` and the ROS node's ``Settings`` take each shared default from
    ``runtime.defaults.LOOP_DEFAULTS`` (the node's ``dynamics`` aside: a real base is a unicycle)."""
    from bearnav_cli.runtime.defaults import LOOP_DEFAULTS
    from bearnav_cli.runtime.settings import ControlSettings

    simulate = {f.name: f.default for f in dataclasses.fields(params_type("simulate"))}
    control = {f.name: f.default for f in dataclasses.fields(ControlSettings)}
    node = {f.name: f.default for f in dataclasses.fields(_ros_settings())}
    for name, default in LOOP_DEFAULTS.items():
        assert simulate[name] == default, name
        assert control[name] in (default, dataclasses.MISSING), name  # speed: ControlSettings.for_plan's SPEED
        if name in node and name != "dynamics":
            assert node[name] == default, name
    assert node["clamp_reverse"] is False


@pytest.mark.parametrize("command", sorted(set(params.MODULES) - {"map"}))  # map_.Params: the pipeline checks
def test_params_refuse_a_value_below_the_declared_range(command):
    """``__post_init__`` checks every declared choice and range (:func:`bearnav_cli.params.declare.check`)."""
    from bearnav_cli.errors import InvalidParamsError

    for field in dataclasses.fields(params_type(command)):
        declaration = declared(field)
        rng = declaration.range
        if rng is not None and rng.low is not None:
            with pytest.raises(InvalidParamsError) as caught:
                params_type(command)(**{field.name: rng.low if rng.low_open else rng.low - 1})
            assert caught.value.field == field.name, (command, field.name)
        if declaration.choices:
            with pytest.raises(InvalidParamsError) as caught:
                params_type(command)(**{field.name: "no-such-choice"})
            assert caught.value.field == field.name, (command, field.name)
