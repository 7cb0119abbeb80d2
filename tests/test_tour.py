"""The README's tour runs top to bottom with exit 0 at every line, writing only under plans/ (issue 13)."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

from .conftest import REPO


def tour_commands(readme: str) -> list[str]:
    """Every ``bearnav ...`` line of the README's fenced code blocks, in order (comments dropped)."""
    commands = []
    for block in re.findall(r"^```[a-z]*\n(.*?)^```", readme, flags=re.M | re.S):
        for line in block.replace("\\\n", " ").splitlines():
            words = shlex.split(line, comments=True)
            if words and words[0] == "bearnav":
                commands.append(line)
    return commands


def maps_used(commands: list[str]) -> set[str]:
    """The files under maps/ the commands name, with the files they reference (grid images)."""
    named = {m for line in commands for m in re.findall(r"maps/[\w.]+\.yaml", line)}
    files = set(named)
    for name in named:
        text = (REPO / name).read_text()
        files |= {f"maps/{ref}" for ref in re.findall(r"^(?:occupancy|image):\s*(\S+)", text, flags=re.M)}
    return files


def test_the_tour_parses_and_avoids_the_repo_root():
    commands = tour_commands((REPO / "README.md").read_text())
    assert len(commands) >= 10, commands
    assert commands[0].startswith("bearnav map maps/kitchen.yaml")
    for line in commands:
        words = shlex.split(line, comments=True)
        for option, value in zip(words[:-1], words[1:], strict=True):
            if option in ("-o", "--out", "--gif", "--figure"):
                assert value.startswith("plans/"), f"{line}: writes outside plans/"
    outputs = [shlex.split(line, comments=True) for line in commands if " simulate " in f" {line} "]
    targets = [w[w.index("-o") + 1] if "-o" in w else "plans/kitchen/sim.npz" for w in outputs]
    assert len(set(targets)) == len(targets), f"two tour simulations write the same file: {targets}"


def test_the_tour_runs_with_exit_0_at_every_line(tmp_path):
    commands = tour_commands((REPO / "README.md").read_text())
    for name in maps_used(commands):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / name, tmp_path / name)
    bearnav = Path(sys.executable).with_name("bearnav")
    env = {**os.environ, "PATH": f"{bearnav.parent}{os.pathsep}{os.environ.get('PATH', '')}", "COLUMNS": "200"}
    before = set(os.listdir(tmp_path))
    started = time.perf_counter()
    for line in commands:
        words = shlex.split(line, comments=True)
        result = subprocess.run([str(bearnav), *words[1:]], cwd=tmp_path, env=env, capture_output=True, text=True)
        assert result.returncode == 0, f"{line}\nexit {result.returncode}\n{result.stdout}\n{result.stderr}"
        assert "Traceback" not in result.stderr, line
    assert set(os.listdir(tmp_path)) - before <= {"plans"}, "the tour wrote outside plans/"
    for figure in ("simplified.png", "plan.png", "sim_unicycle.png", "sim.npz", "sim_unicycle.npz"):
        assert (tmp_path / "plans" / "kitchen" / figure).is_file(), figure
    assert time.perf_counter() - started < 120
