"""``bearnav-runtime`` (``tools/build_runtime.py``): the robot's wheel holds the runtime only and runs on numpy only."""

from __future__ import annotations

import base64
import copy
import email.parser
import hashlib
import json
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np

import bearnav_cli
from bearnav_cli import pipeline
from bearnav_cli.stages import map_

from .conftest import REPO, SMALL_MAP
from .handmade import write_plan

#: Runs in ``python -I -S``: no site-packages, no ``.pth`` (so not the editable install), no current folder;
#: ``sys.path`` is the stdlib, the installed wheel and a folder holding numpy alone.
_ROBOT = """
import importlib.util, json, sys
site, numpy_only, plan = sys.argv[1:4]
sys.path[:0] = [site, numpy_only]
for name in ("scipy", "shapely", "matplotlib", "highspy", "typer", "yaml", "rich", "PIL"):
    assert importlib.util.find_spec(name) is None, name
import numpy as np
from bearnav_cli.runtime import Controller
import bearnav_cli
assert bearnav_cli.__file__.startswith(site), bearnav_cli.__file__
ctl = Controller.from_plan(plan)
landmarks = np.array([lm["position"] for lm in json.loads(str(np.load(plan)["map"]))["landmarks"]], float)
start = np.array(json.loads(sys.argv[4]))
bearings = (landmarks - start) / np.linalg.norm(landmarks - start, axis=1, keepdims=True)
u = ctl.command(bearings, np.ones(len(landmarks), bool))
stdlib = set(sys.stdlib_module_names)
foreign = sorted(m for m in sys.modules if m.split(".")[0] not in stdlib | {"__main__", "numpy", "bearnav_cli"})
print(json.dumps({"u": u.tolist(), "cell": ctl.cell, "lost": ctl.lost, "foreign": foreign}))
"""


def _build(out: Path) -> Path:
    done = subprocess.run(
        [sys.executable, str(REPO / "tools" / "build_runtime.py"), "-o", str(out)],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    )
    wheel = Path(done.stdout.strip())
    assert wheel == out / f"bearnav_runtime-{bearnav_cli.__version__}-py3-none-any.whl" and wheel.is_file()
    return wheel


def test_the_wheel_holds_the_runtime_only_and_asks_for_numpy_only(tmp_path):
    wheel = _build(tmp_path)
    info = f"bearnav_runtime-{bearnav_cli.__version__}.dist-info"
    sources = ["bearnav_cli/__init__.py", "bearnav_cli/errors.py"]
    sources += sorted(p.relative_to(REPO).as_posix() for p in (REPO / "bearnav_cli" / "runtime").rglob("*.py"))
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        assert sorted(names) == sorted(sources + [f"{info}/{f}" for f in ("METADATA", "WHEEL", "RECORD")])
        for name in sources:  # the checkout's files, not copies
            assert archive.read(name) == (REPO / name).read_bytes(), name
        meta = email.parser.Parser().parsestr(archive.read(f"{info}/METADATA").decode())
        record = archive.read(f"{info}/RECORD").decode().splitlines()
        for row in record:  # every file hashed, as pip and installers check
            name, digest, size = row.rsplit(",", 2)
            if name == f"{info}/RECORD":
                assert digest == size == ""
                continue
            data = archive.read(name)
            want = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
            assert (digest, int(size)) == (f"sha256={want}", len(data)), name
        assert sorted(row.rsplit(",", 2)[0] for row in record) == sorted(names)
        wheel_file = archive.read(f"{info}/WHEEL").decode()
    assert meta["Name"] == "bearnav-runtime" and meta["Version"] == bearnav_cli.__version__
    assert meta.get_all("Requires-Dist") == ["numpy>=1.24"] and not meta.get_all("Provides-Extra")
    assert "Root-Is-Purelib: true" in wheel_file and "Tag: py3-none-any" in wheel_file
    # the same numpy and Python floor as the full distribution
    pyproject = (REPO / "pyproject.toml").read_text()
    assert '"numpy>=1.24"' in pyproject and re.search(r'^requires-python = "(.*)"$', pyproject, re.M)[1] == ">=3.10"
    assert meta["Requires-Python"] == ">=3.10"
    # reproducible: the same sources give the same bytes
    assert _build(tmp_path / "again").read_bytes() == wheel.read_bytes()


def test_a_robot_runs_a_plan_from_the_wheel_with_numpy_alone(tmp_path):
    """pip installs the wheel (offline), and its Controller runs a plan with only the stdlib and numpy importable."""
    wheel = _build(tmp_path / "dist")
    site = tmp_path / "site"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--isolated",
            "--no-index",
            "--no-deps",
            "--quiet",
            "--target",
            str(site),
            str(wheel),
        ],
        check=True,
        timeout=120,
    )
    info = f"bearnav_runtime-{bearnav_cli.__version__}.dist-info"
    assert sorted(p.name for p in site.iterdir()) == ["bearnav_cli", info]
    numpy_only = tmp_path / "numpy_only"  # numpy (and its bundled libraries) without the rest of site-packages
    numpy_only.mkdir()
    numpy_dir = Path(np.__file__).parent
    for entry in numpy_dir.parent.iterdir():
        if entry.name == "numpy" or entry.name.startswith("numpy.libs"):
            (numpy_only / entry.name).symlink_to(entry, target_is_directory=entry.is_dir())

    spec = copy.deepcopy(SMALL_MAP)
    made = pipeline.compute(
        map_.MapSource(spec=spec, file="small.yaml", sha256="0"), overrides={"rrtstar": {"iterations": 150}}
    )
    plan = made["plan"]
    plan_path = write_plan(tmp_path / "plan.npz", plan)
    start = SMALL_MAP["starts"][0]

    done = subprocess.run(
        [sys.executable, "-I", "-S", "-c", _ROBOT, str(site), str(numpy_only), str(plan_path), json.dumps(start)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out["foreign"] == [], out["foreign"]
    assert not out["lost"] and out["cell"] >= 0
    assert abs(np.linalg.norm(out["u"]) - 0.1) < 1e-9, out["u"]  # a single integrator at the default speed
