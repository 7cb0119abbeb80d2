"""Build ``bearnav-runtime``, the robot's numpy-only distribution, as a wheel (``make runtime-wheel``).

The wheel holds ``bearnav_cli/__init__.py``, ``bearnav_cli/errors.py`` and the package
``bearnav_cli/runtime/``, read from this checkout (no copies are kept), and depends on numpy only;
``docs/runtime.md`` says how a robot installs it. It is written directly in the wheel format
(packaging.python.org, "Binary distribution format": the files, ``METADATA``, ``WHEEL`` and a
``RECORD`` of hashes) with the standard library only, so the build needs no build backend, no
network and no ``pip``: setuptools cannot package files outside its project folder, and building
from a staged copy would need the ``wheel`` package or a newer setuptools than the venv has. The
wheel is reproducible: the same sources give the same bytes (dates are ``SOURCE_DATE_EPOCH`` or
1980-01-01).

Usage: ``python tools/build_runtime.py [-o dist]``; prints the wheel's path.
"""

from __future__ import annotations

import argparse
import ast
import base64
import hashlib
import os
import re
import time
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
NAME = "bearnav-runtime"
#: The runtime's one dependency; ``pyproject.toml`` asks the same of the full distribution (a test checks).
NUMPY = "numpy>=1.24"
REQUIRES_PYTHON = ">=3.10"
SUMMARY = "The robot side of bearnav: runs a plan.npz on bearings, numpy only."


def version() -> str:
    """``bearnav_cli.__version__``, read without importing the package."""
    tree = ast.parse((REPO / "bearnav_cli" / "__init__.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__version__" for t in node.targets):
            return ast.literal_eval(node.value)
    raise SystemExit("bearnav_cli/__init__.py sets no __version__")


def sources() -> list[Path]:
    """The files the wheel installs, relative to the checkout, in a fixed order."""
    package = REPO / "bearnav_cli"
    found = [package / "__init__.py", package / "errors.py", *sorted((package / "runtime").rglob("*.py"))]
    return [path.relative_to(REPO) for path in found]


def metadata(ver: str) -> str:
    """The ``METADATA`` file (core metadata 2.1: what pip of 2020 and later reads)."""
    return (
        "Metadata-Version: 2.1\n"
        f"Name: {NAME}\n"
        f"Version: {ver}\n"
        f"Summary: {SUMMARY}\n"
        "License: MIT\n"
        f"Requires-Python: {REQUIRES_PYTHON}\n"
        f"Requires-Dist: {NUMPY}\n"
        "Description-Content-Type: text/markdown\n"
        "\n"
        '`from bearnav_cli.runtime import Controller`; `Controller.from_plan("plan.npz")` turns one camera\n'
        "frame of landmark bearings into a velocity command (bearnav's docs/runtime.md). Install it alone:\n"
        "it and the full `bearnav` distribution both provide `bearnav_cli/__init__.py` and `errors.py`.\n"
    )


def _record_row(name: str, data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def build(out_dir: str | os.PathLike = REPO / "dist") -> Path:
    """Write ``bearnav_runtime-VERSION-py3-none-any.whl`` into ``out_dir`` (created if missing) and return its path."""
    ver = version()
    if not re.fullmatch(r"[0-9]+(\.[0-9]+)*([a-z]+[0-9]+)?(\.(post|dev)[0-9]+)?", ver):
        raise SystemExit(f"version {ver!r} is not a plain PEP 440 version")
    dist = f"{NAME.replace('-', '_')}-{ver}"
    info = f"{dist}.dist-info"
    files = [(path.as_posix(), (REPO / path).read_bytes()) for path in sources()]
    files.append((f"{info}/METADATA", metadata(ver).encode()))
    wheel = "Wheel-Version: 1.0\nGenerator: bearnav tools/build_runtime.py\nRoot-Is-Purelib: true\nTag: py3-none-any\n"
    files.append((f"{info}/WHEEL", wheel.encode()))
    record = "".join(_record_row(name, data) + "\n" for name, data in files) + f"{info}/RECORD,,\n"
    files.append((f"{info}/RECORD", record.encode()))

    epoch = max(int(os.environ.get("SOURCE_DATE_EPOCH", "315532800")), 315532800)  # zip dates start in 1980
    stamp = time.gmtime(epoch)[:6]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"{dist}-py3-none-any.whl"
    partial = target.with_name(target.name + ".part")
    with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in files:
            entry = zipfile.ZipInfo(name, date_time=stamp)
            entry.external_attr = 0o644 << 16
            entry.compress_type = zipfile.ZIP_DEFLATED
            archive.writestr(entry, data)
    partial.replace(target)  # a failed build leaves no wheel under the name
    return target


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--out-dir", default=str(REPO / "dist"), help="where to write the wheel (default: dist/)")
    print(build(parser.parse_args(argv).out_dir))


if __name__ == "__main__":
    main()
