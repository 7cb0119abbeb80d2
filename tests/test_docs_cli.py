"""docs/cli.md and the typer app must agree: every command documented with an example, no stale options.

Each ``## `bearnav NAME` `` section of docs/cli.md documents one command. Every command of the app
needs a section with at least one example line (in a fenced block) that starts with
``bearnav NAME``, and every ``--option`` a section mentions must appear in that command's
``--help``. An option inside a ``bearnav OTHER ...`` example line or inline code span is checked
against ``OTHER``. The ``params:`` table lists parameters without a command-line option: each must
be a field of its stage's ``Params`` and must not have become an option.
"""

from __future__ import annotations

import dataclasses
import functools
import re

from typer.main import get_command
from typer.testing import CliRunner

from bearnav_cli import pipeline
from bearnav_cli.cli import app

from .conftest import REPO

DOC = REPO / "docs" / "cli.md"
OPTION = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")
COMMAND_LINE = re.compile(r"^(?:\$\s*)?bearnav\s+([a-z][a-z0-9-]*)(?=\s|$)")
INLINE_CODE = re.compile(r"`([^`]+)`")
PARAM_ROW = re.compile(r"^\| `([a-z_]+)\.([a-z_]+)` \|", re.M)


def command_names() -> list[str]:
    """Names of the commands of the app's group, as the command line spells them."""
    return list(get_command(app).commands)


@functools.cache
def help_options(name: str) -> frozenset[str]:
    """Every ``--option`` printed by ``bearnav NAME --help`` (wide terminal: rich does not wrap names)."""
    result = CliRunner().invoke(app, [name, "--help"], env={"COLUMNS": "200", "TERMINAL_WIDTH": "200"})
    assert result.exit_code == 0, f"bearnav {name} --help failed: {result.output}"
    found = frozenset(OPTION.findall(ANSI.sub("", result.output)))
    assert "--help" in found, f"could not read the options of bearnav {name} --help"
    return found


def command_sections(text: str) -> dict[str, str]:
    """``{command: section body}`` for every ``## `bearnav NAME` `` heading."""
    sections = {}
    for chunk in re.split(r"^## ", text, flags=re.M)[1:]:
        heading, _, body = chunk.partition("\n")
        match = re.fullmatch(r"`bearnav ([a-z][a-z0-9-]*)`\s*", heading)
        if match:
            sections[match.group(1)] = body
    return sections


def mentioned_options(section: str, owner: str) -> list[tuple[str, str]]:
    """``(command, option)`` pairs a section mentions; example lines and code spans name their own command."""
    pairs: list[tuple[str, str]] = []
    fenced = False
    for line in section.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced:
            match = COMMAND_LINE.match(line.strip())
            pairs += [(match.group(1) if match else owner, opt) for opt in OPTION.findall(line)]
            continue
        rest = line
        for span in INLINE_CODE.findall(line):
            match = COMMAND_LINE.match(span.strip())
            if match:
                pairs += [(match.group(1), opt) for opt in OPTION.findall(span)]
                rest = rest.replace(f"`{span}`", "")
        pairs += [(owner, opt) for opt in OPTION.findall(rest)]
    return pairs


def example_lines(section: str, name: str) -> list[str]:
    """Lines inside fenced blocks of the section that start with ``bearnav NAME``."""
    lines, fenced = [], False
    for line in section.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        match = COMMAND_LINE.match(line.strip())
        if fenced and match and match.group(1) == name:
            lines.append(line.strip())
    return lines


def problems(text: str) -> list[str]:
    """Everything in a cli.md text that disagrees with the app (empty when they agree)."""
    found = []
    names = command_names()
    sections = command_sections(text)
    for name in names:
        if name not in sections:
            found.append(f"no section '## `bearnav {name}`'")
        elif not example_lines(sections[name], name):
            found.append(f"section of {name} has no example line starting with 'bearnav {name}'")
    for name in sections:
        if name not in names:
            found.append(f"section for unknown command {name!r}")
    for owner, body in sections.items():
        for command, option in mentioned_options(body, owner):
            if command not in names:
                found.append(f"section {owner}: example of unknown command {command!r}")
            elif option not in help_options(command):
                found.append(f"section {owner}: {option} is not an option of bearnav {command}")
    for stage, field in PARAM_ROW.findall(text):
        if stage not in pipeline.STAGE_BY_NAME:
            found.append(f"params table: unknown stage {stage!r}")
            continue
        fields = {f.name for f in dataclasses.fields(pipeline.STAGE_BY_NAME[stage].module.Params)}
        if field not in fields:
            found.append(f"params table: {stage}.{field} is not a field of {stage}.Params")
        elif "--" + field.replace("_", "-") in help_options(stage):
            found.append(f"params table: {stage}.{field} has an option now (--{field.replace('_', '-')})")
    return found


def test_cli_doc_matches_the_app():
    assert not problems(DOC.read_text()), "\n".join(problems(DOC.read_text()))


def test_cli_doc_documents_exit_codes_and_params():
    text = DOC.read_text()
    assert re.search(r"^## Exit codes", text, re.M)
    for code in "0123":
        assert re.search(rf"^\| {code} \|", text, re.M), f"exit code {code} missing"
    assert PARAM_ROW.search(text), "the params: table is missing"


def test_the_check_can_fail():
    """A section removed, an option invented or an example lost is reported (on a copy of the text)."""
    text = DOC.read_text()
    sections = command_sections(text)
    assert set(sections) == set(command_names())
    without = re.sub(r"^## `bearnav verify`\n.*?(?=^## )", "", text, flags=re.M | re.S)
    assert "no section '## `bearnav verify`'" in problems(without)
    invented = text.replace("## `bearnav rrtstar`\n", "## `bearnav rrtstar`\n\nAlso `--no-such-option`.\n", 1)
    assert "section rrtstar: --no-such-option is not an option of bearnav rrtstar" in problems(invented)
    example = "bearnav simplify plans/kitchen/tree.npz"
    foreign = text.replace(example, example + " --fov 60")
    assert "section simplify: --fov is not an option of bearnav simplify" in problems(foreign)
    no_example = re.sub(r"(## `bearnav inspect`\n.*?)```console\n.*?```\n", r"\1", text, flags=re.S)
    assert "section of inspect has no example line starting with 'bearnav inspect'" in problems(no_example)
    stale = text.replace("| `simulate.min_spread_deg` |", "| `simulate.speed` |")
    assert any("simulate.speed has an option now" in p for p in problems(stale))


# --------------------------------------------------------------------------- the tables and the declarations

LIMIT_ROW = re.compile(r"^\| ([a-z]+) `([a-z_]+)` \| [^|]+ \| ([^|]+) \|", re.M)
DEFAULT_ROW = re.compile(r"^\| `([a-z_]+)\.([a-z_]+)` \| ([^|]+) \|", re.M)


def _shown(value: object) -> str:
    """A default as the ``params:`` table writes it: ``none``, ``true``, ``100``, ``1.0``."""
    return "none" if value is None else str(value).lower() if isinstance(value, bool) else repr(value)


def declaration_problems(text: str) -> list[str]:
    """Where docs/cli.md's "Option limits" and ``params:`` tables disagree with the ``Params`` declarations: a
    row's option (or ``params.STAGE.NAME`` only) and unit, the ``params:``-only fields and their defaults."""
    from bearnav_cli.params import MODULES
    from bearnav_cli.params.declare import declared, params_type

    found = []
    for stage, name, column in LIMIT_ROW.findall(text):
        field = {f.name: f for f in dataclasses.fields(params_type(stage))}[name]
        declaration = declared(field)
        # a field without an option: the map's params: section sets it, except verify's (no map: the Python API)
        only = f"`verify.Params.{name}` only" if stage == "verify" else f"`params.{stage}.{name}` only"
        where = only if declaration.option is None else f"`{declaration.option}`"
        if not column.strip().replace("`verify ", "`").startswith(where):  # verify's rows: `verify --starts`
            found.append(f"option limits: {stage} `{name}` should name {where}")
        if declaration.unit and f", {declaration.unit}" not in column:
            found.append(f"option limits: {stage} `{name}` should give its unit, {declaration.unit}")
    rows = {(stage, name): default.strip() for stage, name, default in DEFAULT_ROW.findall(text)}
    params_only = {
        (stage, f.name): _shown(f.default)
        for stage in MODULES
        if stage != "verify"
        for f in dataclasses.fields(params_type(stage))
        if declared(f).option is None
    }
    if set(rows) != set(params_only):
        found.append(f"params table: rows {sorted(set(rows) ^ set(params_only))} differ from the declarations")
    found += [
        f"params table: {s}.{n} default {rows[s, n]}, declared {d}"
        for (s, n), d in params_only.items()
        if (s, n) in rows and rows[s, n] != d
    ]
    return found


def test_the_tables_are_the_declarations():
    assert not declaration_problems(DOC.read_text()), "\n".join(declaration_problems(DOC.read_text()))


def test_the_declaration_check_can_fail():
    text = DOC.read_text()
    assert "params table: map.coverage_cells default 10, declared 100" in declaration_problems(
        text.replace("| `map.coverage_cells` | 100 |", "| `map.coverage_cells` | 10 |")
    )
    assert "option limits: simulate `fov` should give its unit, degrees" in declaration_problems(
        text.replace("| `--fov`, degrees |", "| `--fov` |")
    )
    assert "option limits: rrtstar `step` should name `--step`" in declaration_problems(
        text.replace("| `--step` (also on `plan`)", "| `--stride` (also on `plan`)")
    )
