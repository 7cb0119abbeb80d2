"""The fields of each command's ``Params``, as its options describe them: read from their declarations.

The ``Params`` of every command is declared in :mod:`bearnav_cli.params` (no numpy, shapely or scipy), so
the options of a command (:mod:`~bearnav_cli.cli.options`) are made of its imported fields: the option,
the off-switch of a flag and the choices from each field's declaration
(:func:`~bearnav_cli.params.declare.param`), the help from the class docstring's ``Attributes``.
"""

import functools
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from bearnav_cli.params import MODULES as PARAMS_MODULES

__all__ = [
    "PARAMS_ONLY",
    "ParamField",
    "params_fields",
]


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
        The allowed values the field declares (``("skip", "extend")``), or empty.
    option : str or None
        The field's option (``--starts``); ``None``: set in the map's ``params:`` only.
    off : str
        A bool's off-switch: ``--no-NAME`` unless the field declares another (``--allow-reverse``).
    """

    name: str
    kind: type
    optional: bool
    default: Any
    doc: str
    choices: tuple[str, ...] = ()
    option: str | None = None
    off: str = ""


class _ParamsOnly(Mapping):
    """``{command: fields without a command-line option}``, set in the map's ``params:`` only (docs/cli.md lists the
    stages'; ``verify.Params.dt`` follows simulate's); a command's ``Params`` is imported when first asked for."""

    def __getitem__(self, command: str) -> tuple[str, ...]:
        return tuple(field.name for field in params_fields(command) if field.option is None)

    def __iter__(self) -> Iterator[str]:
        return iter(PARAMS_MODULES)

    def __len__(self) -> int:
        return len(PARAMS_MODULES)


#: Fields without a command-line option, by command (:class:`_ParamsOnly`).
PARAMS_ONLY: Mapping[str, tuple[str, ...]] = _ParamsOnly()


def _attribute_docs(doc: str) -> dict[str, tuple[str, tuple[str, ...]]]:
    """``{field: (description, choices)}`` from the numpydoc ``Attributes`` section of a docstring."""
    import inspect as inspect_
    import re

    lines = inspect_.cleandoc(doc or "").splitlines()
    found: dict[str, tuple[str, tuple[str, ...]]] = {}
    try:
        start = (
            next(
                i
                for i, line in enumerate(lines[:-1])
                if line.strip() == "Attributes" and set(lines[i + 1].strip()) == {"-"}
            )
            + 2
        )
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
    """The fields of a command's ``Params``, from its declaration (:mod:`bearnav_cli.params`, no numpy)."""
    import dataclasses
    import typing

    from bearnav_cli.params.declare import declared, params_type

    params_type_ = params_type(command)
    hints = typing.get_type_hints(params_type_)
    docs = _attribute_docs(params_type_.__doc__ or "")
    fields = []
    for field in dataclasses.fields(params_type_):
        args = typing.get_args(hints[field.name])
        kinds = [k for k in args if k is not type(None)] or [hints[field.name]]
        declaration = declared(field)
        off = declaration.off or "--no-" + field.name.replace("_", "-")
        fields.append(
            ParamField(
                field.name,
                kinds[0],
                type(None) in args,
                field.default,
                docs.get(field.name, ("", ()))[0],
                declaration.choices,
                declaration.option,
                off,
            )
        )
    return tuple(fields)
