"""The stage table: each stage's name, module, input and output, and the hooks the pipeline calls on it.

The pipeline reaches a stage only through its row here: the module is named by a string and imported on
first use (:attr:`Stage.module`), so that loading an artifact (``bearnav inspect``) imports only the stages
whose parameters its map's ``params:`` sets, and so that no pipeline module imports a stage by name
(tests/test_layering.py).

Every stage module exposes ``VERSION``, a frozen ``Params``, ``run(input, params, progress=None)`` and
``summary(result)`` (:data:`REQUIRED`), and may define the two hooks :meth:`Stage.check_resources` and
:meth:`Stage.problems` call (:data:`HOOKS`):

- ``check_resources(input, params, given)``: refuse a request too big to finish before the stage runs,
  raising :class:`~bearnav_cli.errors.ResourceLimitError` (or ``InvalidParamsError``) whose field is the
  parameter's name; ``given`` holds the parameters set by the map or an option (``rrtstar``, ``simulate``);
- ``problems(result)``: why the result is not usable, a list of :class:`~bearnav_cli.verdicts.Problem`
  worst first (``rrtstar``, ``simplify``, ``decompose``, ``synthesize``).

A stage without one gets the table's default: nothing to check, no problems. The default is the table's,
not a no-op in every module, because most stages have nothing to estimate (their work is bounded by
their input, which the stages before bounded) and nothing to judge (a map that cannot be planned is an
error, a simulation's failed runs are outcomes its command weighs): a documented no-op in each would be
boilerplate. tests/test_pipeline.py checks the hooks a stage defines against these signatures.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any, Callable, Mapping

from bearnav_cli import artifacts
from bearnav_cli.errors import InvalidParamsError

if TYPE_CHECKING:
    from bearnav_cli.verdicts import Problem

__all__ = ["CHAIN", "HOOKS", "Origins", "Progress", "REQUIRED", "SIMULATE", "Stage", "STAGE_BY_NAME", "STAGES"]

#: ``progress(done, total)``, called by long stages.
Progress = Callable[[int, int], None]

#: What every stage module defines.
REQUIRED = ("VERSION", "Params", "run", "summary")
#: What a stage module may define, with its parameters: without it, the table's default (:class:`Stage`).
HOOKS = {"check_resources": ("input", "params", "given"), "problems": ("result",)}


@dataclass(frozen=True)
class Origins:
    """Where each parameter of one stage got its value (what the hooks' errors name).

    Attributes
    ----------
    fields : mapping of str to str
        Parameter name to the field an error about it names: the option that set it (``--seed``), else
        the map field that did or would (``params.rrtstar.seed``).
    given : frozenset of str
        The names set by the map's ``params:`` or an option, not left at their default.
    """

    fields: Mapping[str, str]
    given: frozenset[str] = frozenset()

    def field(self, name: str | None) -> str | None:
        """The field of parameter ``name`` (a name without one, or None, as it is)."""
        return self.fields.get(name or "", name)


@dataclass(frozen=True)
class Stage:
    """One row of the stage table.

    Attributes
    ----------
    name : str
        The stage's name (``"rrtstar"``), as the CLI, the manifests and ``params:`` name it.
    module_name : str
        Its module in :mod:`bearnav_cli.stages` (``"bearnav_cli.stages.rrtstar"``).
    input_kind : str or None
        The artifact kind it reads (a key of :data:`bearnav_cli.artifacts.KINDS`); None for
        ``map``, which reads a map description.
    output_kind : str
        The artifact kind it writes.
    module : ModuleType
        The module itself, imported on first use (:data:`REQUIRED`, and those of :data:`HOOKS` it defines).
    filename : str
        The conventional file name of its output (``"tree.npz"``).
    """

    name: str
    module_name: str
    input_kind: str | None
    output_kind: str

    @property
    def module(self) -> ModuleType:
        return importlib.import_module(self.module_name)

    @property
    def filename(self) -> str:
        return artifacts.KINDS[self.output_kind].filename

    def check_resources(self, artifact: Any, params: Any, origins: Origins) -> None:
        """The stage's estimates on its input, before it runs (its ``check_resources``; none without one).

        Parameters
        ----------
        artifact : Any
            The stage's input (the map for ``rrtstar``, the plan for ``simulate``).
        params : Params
            Its resolved parameters.
        origins : Origins
            Where each parameter came from: the stage is told which were given, and the field of its
            error, a parameter's name, becomes the option or map field that set it (``--step``,
            ``params.rrtstar.step``).

        Raises
        ------
        ResourceLimitError, InvalidParamsError
            A request over a limit or the memory budget, naming the option to change.
        """
        check = getattr(self.module, "check_resources", None)
        if check is None:
            return
        try:
            check(artifact, params, origins.given)
        except InvalidParamsError as exc:  # ResourceLimitError too: the same class, the field translated
            raise type(exc)(exc.reason, field=origins.field(exc.field)) from None

    def problems(self, result: Any) -> list[Problem]:
        """Why the stage's ``result`` is not usable, worst first (its ``problems``); empty when it is, or
        when the stage judges nothing."""
        judge = getattr(self.module, "problems", None)
        return [] if judge is None else list(judge(result))

    def summary(self, result: Any, payload: Any) -> str:
        """The one line of the manifest: the stage's ``summary(result)``; the map stage's also says how many
        obstacles its description (``payload``) listed."""
        if self.input_kind is None:
            return self.module.summary(result, self.module.listed_obstacles(payload))
        return self.module.summary(result)


STAGES: tuple[Stage, ...] = (
    Stage("map", "bearnav_cli.stages.map_", None, "map"),
    Stage("rrtstar", "bearnav_cli.stages.rrtstar", "map", "tree"),
    Stage("simplify", "bearnav_cli.stages.simplify", "tree", "simplified"),
    Stage("decompose", "bearnav_cli.stages.decompose", "simplified", "cells"),
    Stage("synthesize", "bearnav_cli.stages.synthesize", "cells", "plan"),
)
#: Not part of ``plan``: run on a plan by ``bearnav simulate`` (maps may still set its ``params:``).
SIMULATE = Stage("simulate", "bearnav_cli.stages.simulate", "plan", "simulation")
STAGE_BY_NAME = {stage.name: stage for stage in (*STAGES, SIMULATE)}
#: The stages :func:`~bearnav_cli.pipeline.compute` can run, in order: ``plan``'s, then ``simulate``.
CHAIN: tuple[Stage, ...] = (*STAGES, SIMULATE)
