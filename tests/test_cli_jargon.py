"""No developer jargon at the surface: ``--help`` speaks the user's words (issue 23, item 4).

Section numbers, lemma and condition labels, issue numbers and internal module names belong to
docs/algorithms.md and the docstrings; the help of every command (and of ``bearnav`` itself)
must not show them.
"""

from __future__ import annotations

import re

import pytest
from typer.testing import CliRunner

from bearnav_cli.cli import app

from .test_docs_cli import ANSI, command_names

JARGON = re.compile(
    r"§|\bALGORITHMS\b|\bDESIGN\b|\bLemma\b|(?<![\w/])(?:bearnav_cli|runtime|funnel)\.\w|\([CL]\d\)|\bissue \d"
    r"|δ\*|x̂"  # the old plan-wide tolerance and the estimate's symbol: "the position error ...", "the estimate"
)


@pytest.mark.parametrize("command", ["", *command_names()])
def test_help_has_no_jargon(command: str) -> None:
    args = [command, "--help"] if command else ["--help"]
    result = CliRunner().invoke(app, args, env={"COLUMNS": "200", "TERMINAL_WIDTH": "200"})
    assert result.exit_code == 0, result.output
    text = ANSI.sub("", result.output)
    found = [line.strip() for line in text.splitlines() if JARGON.search(line)]
    assert not found, f"bearnav {command} --help shows developer jargon:\n" + "\n".join(found)


def test_a_plans_stage_lines_have_no_jargon(tmp_path_factory) -> None:
    """The summaries ``bearnav plan`` prints, one per stage, speak the user's words too (no section signs,
    lemma or condition labels, internal module names)."""
    from bearnav_cli import artifacts, pipeline

    from .conftest import planned_small_map

    folder = planned_small_map(tmp_path_factory, "jargon").parent
    for stage in pipeline.STAGES:
        loaded = artifacts.load(folder / stage.filename)
        line = stage.module.summary(loaded.artifact)
        assert not JARGON.search(line), f"{stage.name}: {line}"
