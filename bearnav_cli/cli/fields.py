"""The fields of each command's ``Params``, read from the module's source without importing it.

Importing a stage imports numpy, shapely and scipy, which ``bearnav --help`` must not wait for;
the options of a command (:mod:`~bearnav_cli.cli.options`) are made of these fields.
"""

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = [
    "FLAG_OFF",
    "PARAMS_MODULES",
    "PARAMS_ONLY",
    "ParamField",
    "imported_params_fields",
    "option_name",
    "option_names",
    "params_fields",
]


#: The folder of the ``bearnav_cli`` package, whose sources describe the options.
_PACKAGE = Path(__file__).resolve().parents[1]
#: The module of each command's ``Params`` (the stage table's, plus ``verify``).
PARAMS_MODULES = {
    "map": "bearnav_cli.stages.map_", "rrtstar": "bearnav_cli.stages.rrtstar",
    "simplify": "bearnav_cli.stages.simplify", "decompose": "bearnav_cli.stages.decompose",
    "synthesize": "bearnav_cli.stages.synthesize", "simulate": "bearnav_cli.stages.simulate",
    "verify": "bearnav_cli.verify",
}  # fmt: skip
#: The off-switch of a flag when it is not ``--no-NAME``.
FLAG_OFF = {("synthesize", "tolerant"): "--lp-field", ("simulate", "clamp_reverse"): "--allow-reverse"}
#: Fields without a command-line option, set in the map's ``params:`` only (docs/cli.md lists the
#: stages'; ``verify.Params.dt`` follows simulate's).
PARAMS_ONLY: dict[str, tuple[str, ...]] = {
    "map": ("coverage_cells",), "rrtstar": (), "simplify": (), "decompose": (),
    "synthesize": ("w_h", "w_v", "clf_margin"),
    "simulate": ("min_spread_deg", "turn_first", "certified_heading", "look_on_purpose", "initial_heading",
                 "max_fix_error", "goal_tolerance", "max_steps", "record_trajectories"),
    "verify": ("dt",),
}  # fmt: skip
_TYPES = {"int": int, "float": float, "str": str, "bool": bool}


@dataclass(frozen=True)
class ParamField:
    """One field of a ``Params`` dataclass, as an option describes it.

    Attributes
    ----------
    name : str
    kind : type
        int, float, str or bool (``None`` allowed when ``optional``).
    optional : bool
        The annotation is ``X | None``.
    default : object
        The dataclass's default.
    doc : str
        The field's entry under ``Attributes`` of the class docstring ("" when it has none).
    choices : tuple of str
        The allowed values the docstring's type declares (``{"skip", "extend"}``), or empty.
    """

    name: str
    kind: type
    optional: bool
    default: Any
    doc: str
    choices: tuple[str, ...] = ()


class _NotLiteral(Exception):
    """A declaration the source reader cannot evaluate: the module is imported instead."""


@functools.cache  # one read per module: each constant default would read its module again
def _module_source(module: str) -> str:
    parts = module.split(".")[1:]
    path = _PACKAGE.joinpath(*parts).with_suffix(".py")
    if not path.is_file():
        path = _PACKAGE.joinpath(*parts, "__init__.py")
    try:
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise _NotLiteral(module) from exc


def _constant(module: str, name: str, depth: int = 0) -> Any:
    """A module-level ``NAME = literal`` of ``module``, or of the bearnav module it imports NAME from."""
    import ast
    import re

    source = _module_source(module)
    match = re.search(rf"^{name}(?:[ \t]*:[^=\n]+)?[ \t]*=[ \t]*([^\n]+)$", source, re.M)
    if match:
        try:
            return ast.literal_eval(match.group(1).split("  #")[0].strip())
        except (ValueError, SyntaxError) as exc:
            raise _NotLiteral(f"{module}.{name}") from exc
    for origin, names in re.findall(r"^from (bearnav_cli[\w.]*) import (\([^)]*\)|[^\n]*)", source, re.M):
        if depth < 3 and name in {n.strip() for n in names.strip("()").replace("\n", " ").split(",")}:
            return _constant(origin, name, depth + 1)
    raise _NotLiteral(f"{module}.{name}")


def _annotation(text: str) -> tuple[type, bool]:
    parts = [part.strip() for part in text.replace("Optional[", "").rstrip("]").split("|")]
    optional = "None" in parts or text.startswith("Optional[")
    kinds = [part for part in parts if part != "None"]
    if len(kinds) != 1 or kinds[0] not in _TYPES:
        raise _NotLiteral(text)
    return _TYPES[kinds[0]], optional


def _attribute_docs(doc: str) -> dict[str, tuple[str, tuple[str, ...]]]:
    """``{field: (description, choices)}`` from the numpydoc ``Attributes`` section of a docstring."""
    import inspect as inspect_
    import re

    lines = inspect_.cleandoc(doc or "").splitlines()
    found: dict[str, tuple[str, tuple[str, ...]]] = {}
    try:
        start = next(i for i, line in enumerate(lines[:-1]) if line.strip() == "Attributes"
                     and set(lines[i + 1].strip()) == {"-"}) + 2  # fmt: skip
    except StopIteration:
        return found
    names: list[str] = []
    text: list[str] = []
    choices: tuple[str, ...] = ()

    def close() -> None:
        for one in names:
            found[one] = (" ".join(text), choices)

    for line in lines[start:]:
        head = re.fullmatch(r"(\w+(?:, \w+)*)(?: : (.*))?", line)
        if head and not line.startswith(" "):
            close()
            names, text = head.group(1).split(", "), []
            kind = head.group(2) or ""
            choices = tuple(re.findall(r'"([^"]+)"', kind)) if kind.startswith("{") else ()
        elif line.startswith(" ") and names:
            text.append(line.strip())
        elif line.strip() and not line.startswith(" "):  # the next section
            break
    close()
    return found


@functools.cache
def params_fields(command: str) -> tuple[ParamField, ...]:
    """The fields of a command's ``Params``, read from its module's source without importing it.

    Importing a stage imports numpy, shapely and scipy, which ``bearnav --help`` must not wait
    for; the source says the same (``tests/test_cli_options.py`` compares the two). A declaration
    the reader cannot evaluate (a default that is not a literal or a constant) falls back to
    importing the module.
    """
    import ast
    import re

    module = PARAMS_MODULES[command]
    try:
        source = _module_source(module)
        block = re.search(r"^class Params\b[^\n]*\n(?:[ \t]+[^\n]*\n|[ \t]*\n)*", source, re.M)
        if block is None:
            raise _NotLiteral(module)
        (node,) = ast.parse(block.group(0)).body
        docs = _attribute_docs(ast.get_docstring(node) or "")
        fields = []
        for item in node.body:
            if not (isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name)):
                continue
            if item.value is None:
                raise _NotLiteral(f"{module}.Params.{item.target.id}: no default")
            if isinstance(item.value, ast.Name):
                default = _constant(module, item.value.id)
            else:
                try:
                    default = ast.literal_eval(item.value)
                except ValueError as exc:
                    raise _NotLiteral(f"{module}.Params.{item.target.id}") from exc
            kind, optional = _annotation(ast.unparse(item.annotation))
            doc, choices = docs.get(item.target.id, ("", ()))
            fields.append(ParamField(item.target.id, kind, optional, default, doc, choices))
        return tuple(fields)
    except (_NotLiteral, SyntaxError, ValueError):
        return imported_params_fields(command)


def imported_params_fields(command: str) -> tuple[ParamField, ...]:
    """:func:`params_fields` from the imported dataclass (the slow way, and the check of the fast one)."""
    import dataclasses as dataclasses_
    import importlib
    import typing

    params_type = importlib.import_module(PARAMS_MODULES[command]).Params
    hints = typing.get_type_hints(params_type)
    docs = _attribute_docs(params_type.__doc__ or "")
    fields = []
    for field in dataclasses_.fields(params_type):
        kinds = [k for k in typing.get_args(hints[field.name]) if k is not type(None)] or [hints[field.name]]
        doc, choices = docs.get(field.name, ("", ()))
        fields.append(ParamField(field.name, kinds[0], type(None) in typing.get_args(hints[field.name]),
                                 field.default, doc, choices))  # fmt: skip
    return tuple(fields)


@functools.cache
def option_names() -> dict[tuple[str, str], str]:
    """``limits.OPTION_NAMES``, read from its source (importing ``limits`` imports numpy)."""
    import ast
    import re

    match = re.search(r"^OPTION_NAMES = (\{[^\n]*\})$", _module_source("bearnav_cli.limits"), re.M)
    if match is None:
        from bearnav_cli import limits

        return dict(limits.OPTION_NAMES)
    return ast.literal_eval(match.group(1))


def option_name(command: str, name: str) -> str:
    """The option of a command's field: ``--field-name`` unless :func:`option_names` renames it."""
    return option_names().get((command, name), "--" + name.replace("_", "-"))
