"""The import rules of DESIGN §2, checked by parsing every module's imports."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "bearnav_cli"

#: Layer of each internal module; a module may import only strictly lower layers,
#: except the pairs listed in SAME_LAYER_OK.
LAYERS = {
    "errors": 0,
    # the numpy-only package a robot installs: its modules import each other and errors only (checked below), so
    # it sits just above errors; datatypes and artifacts read the one artifact schema from runtime/schema.py
    "runtime": 0.5,
    "params": 0.6,  # each Params declared once (no numpy): the stages, limits and the command line read them
    "limits": 0.7,  # parameter ranges and the memory budget: the stages' checks and the pipeline's use them
    "datatypes": 1,
    "palette": 1.2,  # the figures' and bags' colours, plain data on datatypes' enums
    "verdicts": 1.3,  # why a result is not usable: the stages' problems(), on datatypes
    "crossings": 1.5,  # RC, the crossing edges of a tree (numpy and shapely only); simplify runs it
    "geometry": 2,
    "lp": 2,
    "occupancy": 2,
    "cell_lp": 2.5,
    "routes": 2.5,
    "barriers": 2.5,
    "cell_landmarks": 2.5,  # the landmarks of each cell (§5.4–§5.5), on geometry and datatypes
    "funnel": 2.5,  # build on lp and geometry
    "cell_fields": 2.6,  # synthesize's LP-free parts of a cell's field, on cell_lp, funnel and runtime
    "composition": 2.7,  # the §11.6 checks, on funnel and geometry; verify builds on it
    "perception": 2.8,
    "liveness": 2.8,  # ALGORITHMS §12.5 on runtime and datatypes; verify reports it, cli passes it to plot
    "verify_checks": 2.85,  # verify's exact checks of a plan's data, on composition, funnel, geometry and routes
    "tags": 2.9,  # issue 11 analyses on runtime, geometry and composition (tags also on lp)
    "verify_report": 2.9,  # what verify found, on verify_checks, composition and liveness
    "world": 2.95,  # the simulated world (camera, motion, rendering) the simulate stage drives robots in
    "stages": 3,
    "verify": 3,
    "artifacts": 4,
    "bag": 4.5,
    "pipeline": 5,
    "sweep": 5.5,  # bearnav sweep: grids of pipeline plans and simulate runs, its store through artifacts
    "cli": 6,
}
EXTERNAL_ONLY_IN = {
    "highspy": {"lp"},
    "matplotlib": {"plot"},
    "yaml": {"cli"},
    "typer": {"cli"},
    "rich": {"cli"},
    "cv2": {"world"},
    "rosbags": {"bag"},
}


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).with_suffix("")
        parts = rel.parts
        if parts[-1] == "__init__":
            continue
        name = parts[0]  # stages/* and runtime/* are one layer each
        yield name, ".".join(parts), ast.parse(path.read_text())


def _imports(tree):
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name
        elif isinstance(node, ast.ImportFrom) and node.module:
            if node.module.startswith("bearnav_cli"):
                for alias in node.names:
                    yield f"{node.module}.{alias.name}"
            else:
                yield node.module


def _internal(target: str) -> str | None:
    """The internal module a dotted import target belongs to (None for third-party imports)."""
    return target.split(".")[1] if target.startswith("bearnav_cli.") else None


def test_imports_flow_one_way():
    problems = []
    for layer_name, dotted, tree in _modules():
        for target in _imports(tree):
            top = target.split(".")[0]
            allowed = EXTERNAL_ONLY_IN.get(top)
            if allowed is not None and layer_name not in allowed:
                problems.append(f"{dotted} imports {target} (only {sorted(allowed)} may)")
            dep = _internal(target)
            if dep is None or dep == "__version__":
                continue
            if layer_name == "plot":  # DESIGN §2: fields come from runtime; plot/* import each other
                if dep not in ("datatypes", "errors", "palette", "plot", "runtime"):
                    problems.append(f"plot imports {target} (plot depends on datatypes, palette and runtime only)")
                continue
            if layer_name == "runtime":
                if dep not in ("runtime", "errors"):
                    problems.append(f"{dotted} imports {target} (runtime depends on numpy and errors only)")
                continue
            if dep == "plot" and layer_name != "cli":
                problems.append(f"{dotted} imports plot")
            if layer_name == "stages" and dep == "stages" and target.count(".") >= 2:
                problems.append(f"{dotted} imports another stage {target}")
            elif dep == layer_name and "." in dotted:  # a package's modules (world/*, cli/*, ...) build on each other
                continue
            # stages may import stages (one stage at most, checked above), verify may use simulate
            stage_ok = dep == "stages" and LAYERS.get(layer_name, 0) >= LAYERS["stages"]
            if dep in LAYERS and layer_name in LAYERS and not stage_ok and LAYERS[dep] >= LAYERS[layer_name]:
                problems.append(f"{dotted} ({layer_name}) imports {target} against the layering")
    assert not problems, "\n".join(problems)


#: The command line's modules that are not a command: the commands build on them, and they import no command.
CLI_SHARED = {"startup", "output", "exits", "fields", "options", "mapfile", "hints"}


def test_cli_commands_share_helpers_not_each_other():
    """One module per command (issue 24.2): a command imports the shared modules of ``cli`` only, never another
    command, and only ``cli.main`` (the app) imports the commands."""
    problems = []
    for layer_name, dotted, tree in _modules():
        if layer_name != "cli" or dotted == "cli.main":
            continue
        for target in _imports(tree):
            parts = target.split(".")
            if parts[:2] == ["bearnav_cli", "cli"] and len(parts) > 2 and parts[2] not in CLI_SHARED:
                problems.append(f"{dotted} imports {target} (only cli.main imports the commands)")
    assert not problems, "\n".join(problems)


def _all_imports(tree):
    """Every import target, as :func:`_imports` gives them, plus the package of ``from bearnav_cli import x``."""
    yield from _imports(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            yield node.module


def test_the_pipeline_imports_no_stage_by_name():
    """Issue 24.3: the pipeline reaches a stage through its table only (a module path string, imported on use):
    no module of the pipeline package, its ``__init__`` included, imports ``bearnav_cli.stages`` or a stage,
    not even for type checking."""
    problems = []
    for path in sorted((PACKAGE / "pipeline").rglob("*.py")):
        tree = ast.parse(path.read_text())
        for target in _all_imports(tree):
            if target == "bearnav_cli.stages" or target.startswith("bearnav_cli.stages."):
                problems.append(f"{path.relative_to(PACKAGE)} imports {target}")
        if path.name == "table.py":  # the one place that names the stage modules
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and str(node.value).startswith("bearnav_cli.stages."):
                problems.append(f"{path.relative_to(PACKAGE)} names the module {node.value} (only the table may)")
    assert not problems, "\n".join(problems)


def test_only_cli_prints():
    offenders = []
    for layer_name, dotted, tree in _modules():
        if layer_name == "cli":
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                offenders.append(dotted)
    assert not offenders


FILE_METHODS = {
    "read_text",
    "read_bytes",
    "write_text",
    "write_bytes",
    "savez",
    "savez_compressed",
    "ZipFile",
    "write_array",
    "savefig",
    "mkdir",
    "unlink",
}


def test_stages_do_no_file_io():
    offenders = []
    for layer_name, dotted, tree in _modules():
        if layer_name not in ("stages", "geometry", "occupancy", "datatypes"):
            continue
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call):
                continue
            func = node.func
            if isinstance(func, ast.Name) and func.id == "open":  # the builtin (Image.open on bytes is fine)
                offenders.append(f"{dotted}: open")
            if isinstance(func, ast.Attribute) and func.attr in FILE_METHODS:
                offenders.append(f"{dotted}: {func.attr}")
    assert not offenders, offenders


def _defined(tree) -> set[str]:
    """Top-level names a module defines itself (functions, classes, assignments), not imports."""
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            for target in node.targets:
                for name in ast.walk(target):
                    if isinstance(name, ast.Name):
                        names.add(name.id)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names


def _declared(tree) -> list[str] | None:
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets):
            return [ast.literal_eval(e) for e in node.value.elts]
    return None


def test_every_module_declares_its_own_names():
    """Issue 14.4: every module has an ``__all__`` and it names only what the module defines (the
    package ``__init__`` files, the robot's one import, are the only re-exporters)."""
    problems = []
    for _, dotted, tree in _modules():
        if dotted == "__main__":  # `python -m bearnav_cli`: nothing to import from it
            continue
        declared = _declared(tree)
        if declared is None:
            problems.append(f"{dotted}: no __all__")
            continue
        defined = _defined(tree)
        problems += [f"{dotted}: __all__ names {name}, defined elsewhere" for name in declared if name not in defined]
    assert not problems, "\n".join(problems)
