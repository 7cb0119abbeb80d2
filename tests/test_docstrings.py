"""Numpydoc docstrings on the public callables of every module (issue 14 item 9).

In the style of python-control's ``control/tests/docstrings_test.py``: pure introspection, no
numpydoc dependency, one test id per module of ``bearnav_cli`` (``__main__`` and ``cli`` aside,
the CLI is checked against docs/cli.md by ``test_docs_cli.py``). The public callables of a module are the
functions and classes named in its ``__all__`` and defined in it (``obj.__module__`` is the
module), so a re-export is checked once, where it is defined. The rules:

1. Every public callable has its own docstring. A class does not inherit one, and the signature
   text ``Name(a: int, ...)`` that ``dataclass`` and ``NamedTuple`` write when the class has none
   does not count.
2. Counted parameters are the signature's parameters other than ``self``, ``cls``, ``*args`` and
   ``**kwargs``. A function with 3 or more of them has a ``Parameters`` section. A class is
   checked on its ``__init__`` (its ``Parameters`` section lives in the class docstring or in
   ``__init__``'s), except a dataclass or ``NamedTuple``: its fields are its parameters, and with
   3 or more fields it has an ``Attributes`` section. ``Enum`` classes need only rule 1.
3. A section, when present, documents exactly the parameters: the entry lines of a section are
   its non-blank lines at the indentation of its header (``name : type``, ``a, b : type`` or a
   bare ``name``), the names before the colon; every counted parameter is documented (none
   missing) and every documented name is a parameter (none stale). ``*args`` and ``**kwargs``
   may be left out; when documented, an entry starting with ``*`` (``*points``) stands for the
   ``*args`` parameter and one starting with ``**`` (``**options``) for ``**kwargs``, whatever
   the name after the stars, and is stale if the signature has no such parameter. An
   ``Attributes`` section of a dataclass or ``NamedTuple`` lists every field and may also list
   other attributes of the class (properties, class constants), but no name the class lacks.
4. Every entry of a checked section has a description: the line after it is indented deeper
   (a type alone, ``params : Params``, says what a value is, not what it is for).

A failure names the module and lists every offending callable with what is missing or stale.
"""

from __future__ import annotations

import dataclasses
import enum
import importlib
import inspect
import pkgutil
import re

import pytest

import bearnav_cli

#: Modules not checked here: the entry point and the Typer app (the ``cli`` package and its modules: a command's
#: docstring is its ``--help``, checked against docs/cli.md by ``test_docs_cli.py``).
SKIP = {"bearnav_cli.__main__", "bearnav_cli.cli"}

#: Fewest counted parameters that make a ``Parameters`` (or ``Attributes``) section compulsory.
MIN_DOCUMENTED = 3

_HEADER_RULE = re.compile(r"^\s*-{3,}\s*$")
_NAME = re.compile(r"^\*{0,2}[A-Za-z_]\w*$")
_VARIADIC = (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)


def _module_names() -> list[str]:
    names = [bearnav_cli.__name__]
    for info in pkgutil.walk_packages(bearnav_cli.__path__, prefix=f"{bearnav_cli.__name__}."):
        names.append(info.name)
    return sorted(name for name in names if name not in SKIP and not name.startswith("bearnav_cli.cli."))


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _sections(doc: str) -> dict[str, list[tuple[str, bool]]]:
    """Numpydoc sections of a cleaned docstring: header -> its entry lines (at the header's
    indentation), each with whether a description (the next line, indented deeper) follows it."""
    lines = doc.splitlines()
    headers = [i for i in range(len(lines) - 1) if lines[i].strip() and _HEADER_RULE.match(lines[i + 1])]
    sections = {}
    for k, start in enumerate(headers):
        end = headers[k + 1] if k + 1 < len(headers) else len(lines)
        indent = _indent(lines[start])
        sections[lines[start].strip()] = [
            (lines[i].strip(), i + 1 < end and bool(lines[i + 1].strip()) and _indent(lines[i + 1]) > indent)
            for i in range(start + 2, end)
            if lines[i].strip() and _indent(lines[i]) == indent
        ]
    return sections


def _documented(entries: list[str]) -> tuple[list[str], list[str]]:
    """Names documented by a section's entry lines, and the entry lines that name nothing."""
    names, malformed = [], []
    for entry in entries:
        parts = [part.strip() for part in entry.split(" :", 1)[0].rstrip(":").split(",")]
        if all(_NAME.match(part) for part in parts):
            names.extend(parts)
        else:
            malformed.append(entry)
    return names, malformed


def _own_doc(obj) -> str | None:
    doc = obj.__doc__
    if not doc or not doc.strip():
        return None
    if inspect.isclass(obj) and doc.startswith(f"{obj.__name__}("):  # written by dataclass / NamedTuple
        return None
    return inspect.cleandoc(doc)


def _signature_names(func) -> tuple[list[str], list[inspect.Parameter]]:
    """Counted parameter names of a callable, and its ``*args``/``**kwargs`` parameters."""
    params = list(inspect.signature(func).parameters.values())
    counted = [p.name for p in params if p.kind not in _VARIADIC and p.name not in ("self", "cls")]
    return counted, [p for p in params if p.kind in _VARIADIC]


def _compare(section: str, documented: list[str], counted: list[str], variadic, extra_ok=()) -> list[str]:
    problems = []
    missing = [name for name in counted if name not in documented]
    if missing:
        problems.append(f"{section} misses {', '.join(missing)}")
    kinds = {p.kind for p in variadic}
    stale = []
    for name in documented:
        if name.startswith("**"):
            ok = inspect.Parameter.VAR_KEYWORD in kinds
        elif name.startswith("*"):
            ok = inspect.Parameter.VAR_POSITIONAL in kinds
        else:
            ok = name in counted or name in extra_ok
        if not ok:
            stale.append(name)
    if stale:
        absent = "not fields or attributes of the class" if section == "Attributes" else "not in the signature"
        problems.append(f"{section} documents {', '.join(stale)}, {absent}")
    duplicated = sorted({name for name in documented if documented.count(name) > 1})
    if duplicated:
        problems.append(f"{section} documents {', '.join(duplicated)} twice")
    return problems


def _check_section(doc: str, section: str, counted, variadic, extra_ok=()) -> list[str]:
    entries = _sections(doc).get(section)
    if entries is None:
        if len(counted) >= MIN_DOCUMENTED:
            return [f"no {section} section for {len(counted)} parameters ({', '.join(counted)})"]
        return []
    documented, malformed = _documented([line for line, _ in entries])
    problems = [f"{section} entry {line!r} is not 'name : type'" for line in malformed]
    problems += [f"{section} entry {line!r} has no description" for line, described in entries if not described]
    return problems + _compare(section, documented, counted, variadic, extra_ok)


def _problems(obj) -> list[str]:
    doc = _own_doc(obj)
    if doc is None:
        return ["no docstring"]
    if not inspect.isclass(obj):
        counted, variadic = _signature_names(obj)
        return _check_section(doc, "Parameters", counted, variadic)
    if issubclass(obj, enum.Enum):
        return []
    if dataclasses.is_dataclass(obj) or (issubclass(obj, tuple) and hasattr(obj, "_fields")):
        fields = [f.name for f in dataclasses.fields(obj)] if dataclasses.is_dataclass(obj) else list(obj._fields)
        extra = [name for name in dir(obj) if name not in fields]
        return _check_section(doc, "Attributes", fields, [], extra_ok=extra)
    init = obj.__dict__.get("__init__")
    if init is None:
        return []
    counted, variadic = _signature_names(init)
    init_doc = _own_doc(init) or ""
    where = doc if "Parameters" in _sections(doc) or "Parameters" not in _sections(init_doc) else init_doc
    return _check_section(where, "Parameters", counted, variadic)


def _public(module) -> list[tuple[str, object]]:
    found = []
    for name in getattr(module, "__all__", ()):
        obj = getattr(module, name)
        if (inspect.isclass(obj) or inspect.isroutine(inspect.unwrap(obj))) and obj.__module__ == module.__name__:
            found.append((name, obj))
    return found


def test_modules_found():
    """The walk sees the stages and the runtime, so an empty parametrisation cannot pass silently."""
    names = _module_names()
    assert "bearnav_cli.stages.rrtstar" in names and "bearnav_cli.runtime.bearing" in names
    assert not SKIP & set(names)


@pytest.mark.parametrize("module_name", _module_names())
def test_docstrings(module_name):
    module = importlib.import_module(module_name)
    report = []
    for name, obj in _public(module):
        problems = _problems(obj)
        if problems:
            report.append(f"  {name}: " + "; ".join(problems))
    assert not report, f"{module_name}: {len(report)} callables with docstring problems\n" + "\n".join(report)
