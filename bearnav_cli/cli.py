"""The ``bearnav`` command line (DESIGN §5): the only place that reads YAML, prints or exits.

Exit codes: 0 success (fresh stages included), 1 the run finished but the outcome failed (no
route), 2 usage, 3 invalid input (one line naming file, field or option and the problem),
130 interrupted (SIGINT: one line ``interrupted; nothing written for STAGE``), 143 terminated
(SIGTERM, the same line).
"""

# ruff: noqa: E402 - the SIGINT handler below must be in place before the slow imports that follow
# No `from __future__ import annotations`: typer reads the annotations of every command on every start,
# and evaluating them from strings took 4 ms of it (the few names imported for type checking are quoted).

import os
import signal
import sys
import threading

# the command line is the program; Python callers use the stages, pipeline and runtime instead
__all__ = ["EXIT_INTERNAL", "EXIT_INTERRUPTED", "EXIT_INVALID", "EXIT_OUTCOME", "EXIT_TERMINATED", "app", "main"]


def _interrupted_while_starting(signum: int, frame: object) -> None:
    """SIGINT or SIGTERM while Python is still importing: nothing has been read or written yet."""
    command = next((arg for arg in sys.argv[1:] if not arg.startswith("-")), "bearnav")
    word = "interrupted" if signum == signal.SIGINT else "terminated"
    os.write(2, f"{word}; nothing written for {command}\n".encode())
    os._exit(130 if signum == signal.SIGINT else 143)


#: Whether this process is the ``bearnav`` program (not a test or a library importing the module).
_AS_PROGRAM = os.path.basename(sys.argv[0]) in ("bearnav", "__main__.py")
_STARTUP_HANDLERS: dict[int, object] = {}
if threading.current_thread() is threading.main_thread():
    for _signum in (signal.SIGINT, signal.SIGTERM):
        _STARTUP_HANDLERS[_signum] = signal.signal(_signum, _interrupted_while_starting)

import functools
import inspect
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, List, Optional

import typer
from typer.core import TyperArgument, TyperCommand, TyperGroup

from bearnav_cli import __version__
from bearnav_cli.errors import BearnavError, InternalError, InvalidMapError, InvalidParamsError

# Start-up: numpy, scipy, shapely, yaml, logging, rich (the consoles, progress bars, typer's rich help),
# the stages and the pipeline are imported by the commands that use them, so that `bearnav --help`
# and `bearnav inspect` start at once (bench/README.md "Start-up"; tests/test_cli_startup.py).
if TYPE_CHECKING:
    from rich.console import Console
    from rich.progress import Progress

    from bearnav_cli import pipeline
    from bearnav_cli.stages.map_ import GridSource, MapSource


def _usage_metavar(make_metavar: Callable) -> Callable:
    """typer writes a required argument as ``{source}`` in the usage line; write its metavar (``MAP``) as is."""

    def make(self: Any, ctx: Any, *, usage: bool = False) -> str:
        if usage and self.metavar is not None and self.required:
            return self.metavar
        return make_metavar(self, ctx, usage=usage)

    return make


TyperArgument.make_metavar = _usage_metavar(TyperArgument.make_metavar)


def _format_help_text(command: Any, ctx: Any, formatter: Any) -> None:
    """A command's docstring as help: each paragraph joined and wrapped to the terminal, except that an example
    (a line starting ``bearnav``) starts a line of its own, as typer's rich help showed them."""
    text = inspect.cleandoc(command.help or "").partition("\f")[0]
    with formatter.indentation():
        for paragraph in text.split("\n\n") if text else []:
            lines: list[str] = []
            for line in paragraph.splitlines():
                if lines and not line.startswith("bearnav "):
                    lines[-1] += " " + line
                else:
                    lines.append(line)
            formatter.write_paragraph()
            for line in lines:
                formatter.write_text(line)


class _Command(TyperCommand):
    """A command whose ``--help`` is click's plain layout (typer's rich one imports rich.markdown and
    pygments, 0.1 s of every ``--help``); usage errors keep typer's rich panel.

    The options generated from a ``Params`` (:func:`with_options`) are made when the command's
    :attr:`params` are first read (to parse its command line, print its help or complete it), so
    that a start reads the ``Params`` sources of the command it runs only.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        # typer's callback wraps the command (functools.update_wrapper): its attributes are the command's
        self._generated = getattr(self.callback, "generated_options", None)

    @property
    def params(self) -> list[Any]:
        if getattr(self, "_generated", None) is not None:
            groups, before = self._generated
            self._generated = None
            made = [_click_option(parameter) for group in groups for parameter in group()]
            at = next((i for i, param in enumerate(self._params) if param.name == before), len(self._params))
            self._params[at:at] = made
        return self._params

    @params.setter
    def params(self, value: list[Any]) -> None:
        self._params = value

    def format_help(self, ctx: Any, formatter: Any) -> None:
        super(TyperCommand, self).format_help(ctx, formatter)  # click's, not typer's rich one

    def format_help_text(self, ctx: Any, formatter: Any) -> None:
        _format_help_text(self, ctx, formatter)


class _Group(TyperGroup):
    """The ``bearnav`` group, its ``--help`` plain as :class:`_Command`'s."""

    def format_help(self, ctx: Any, formatter: Any) -> None:
        super(TyperGroup, self).format_help(ctx, formatter)

    def format_help_text(self, ctx: Any, formatter: Any) -> None:
        _format_help_text(self, ctx, formatter)

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        if not args and self.no_args_is_help and not ctx.resilient_parsing:
            # bare `bearnav`: click's error for it holds the help, and typer's rich error handler prints nothing
            # (its rich help printed itself): print the plain help here, on stdout, and exit 2, as before
            typer.echo(ctx.get_help(), color=ctx.color)
            ctx.exit(2)
        return super().parse_args(ctx, args)


class _Typer(typer.Typer):
    """typer.Typer whose commands are :class:`_Command` (plain ``--help``) unless told otherwise."""

    def command(self, name: Optional[str] = None, *, cls: Optional[type] = None, **kwargs: Any) -> Callable:
        return super().command(name, cls=cls or _Command, **kwargs)


app = _Typer(
    cls=_Group,
    add_completion=True,
    no_args_is_help=True,
    # the plain help is as wide as the terminal, up to 120 columns (click's own limit is 80)
    context_settings={"max_content_width": 120},
    help="Certified bearing-only navigation controllers from a 2-D map.\n\n"
    "Lengths are in map units; a default written '0.01 D' is 1% of D, the diagonal of the map's bounds.\n\n"
    # a pip install has no docs/ folder: the help says what a map is, and where the full description lives
    "A map is a YAML file with bounds [xmin, ymin, xmax, ymax], robot_radius, goal [x, y], starts (a list of "
    "[x, y]), obstacles (each a polygon: [[x, y], ...], a rectangle: [xmin, ymin, xmax, ymax] or a circle: "
    "{center, radius}), landmarks ([x, y] or {id, position, facing}) and optional robot: and params: sections; "
    "or a ROS map_server YAML (plan it with --goal and --landmark). `bearnav map MAP` checks one and names any "
    "field that is wrong. docs/maps.md and docs/cli.md of the bearnav source describe every key, command and "
    "word of the output.\n\n"
    "Example: bearnav plan maps/kitchen.yaml",
)


class _Console:
    """A rich Console made on first use: importing rich.console takes 20 ms that ``--help`` does not need.

    Everything but :attr:`console` (the Console itself, for rich's own classes) is the Console's.
    """

    def __init__(self, stderr: bool = False) -> None:
        self._stderr = stderr

    @functools.cached_property
    def console(self) -> "Console":
        from rich.console import Console

        return Console(stderr=self._stderr)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.console, name)


out = _Console()
err = _Console(stderr=True)

EXIT_OUTCOME, EXIT_INVALID, EXIT_INTERRUPTED, EXIT_TERMINATED = 1, 3, 130, 143
#: A bug of bearnav's own, never the user's input (EX_SOFTWARE of sysexits.h).
EXIT_INTERNAL = 70
#: Suffixes ``bearnav plot -o`` writes (matplotlib's formats that need nothing more than pillow).
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".svgz", ".eps", ".ps", ".jpg", ".jpeg", ".tif", ".tiff", ".webp")


#: What -q does, for ``bearnav -q`` and every command's own ``-q``.
QUIET_HELP = "Quiet: errors and the final result only (no stage lines, progress bars or warnings)."


class _Quiet:
    enabled = False


@functools.cache
def _warning_handler() -> type:
    """:class:`_WarningHandler`, defined on first use: logging is imported by the commands, not by ``--help``."""
    import logging

    class _WarningHandler(logging.Handler):
        """Print library warnings as one line each on stderr."""

        def emit(self, record: logging.LogRecord) -> None:
            if not _Quiet.enabled or record.levelno >= logging.ERROR:
                from rich.markup import escape

                from bearnav_cli import pipeline

                # which stage said it, of which file: a plan's five stages warn about one map
                where = pipeline.ACTIVITY.stage or ""
                if pipeline.ACTIVITY.file and where:
                    where += f" of {pipeline.ACTIVITY.file}"
                where = f"{escape(where)}: " if where else ""
                err.print(f"[yellow]warning:[/yellow] {where}{escape(record.getMessage())}", highlight=False,
                          soft_wrap=True)  # fmt: skip

    return _WarningHandler


def _setup_logging() -> None:
    import logging

    handler = _warning_handler()
    logger = logging.getLogger("bearnav_cli")
    if not any(isinstance(h, handler) for h in logger.handlers):
        logger.addHandler(handler(level=logging.WARNING))
    logger.setLevel(logging.WARNING)
    logger.propagate = False


def _plotting():
    """:mod:`bearnav_cli.plot` on matplotlib's file backend: the command line only writes files.

    The backend is chosen here, not in ``plot`` itself, so that importing ``plot`` from a notebook
    keeps the notebook's backend.
    """
    from bearnav_cli import plot

    plot.use_file_backend()
    return plot


def _fail(message: str, code: int) -> typer.Exit:
    err.print(f"[red]error:[/red] {message}".replace("\n", " "), highlight=False, soft_wrap=True, markup=True)
    return typer.Exit(code)


def _print_json(data: Any) -> None:
    """Print ``data`` as indented JSON on stdout, never wrapped: rich's print_json breaks long strings at the
    terminal's width, mid-token, and what a machine reads must parse whatever the terminal."""
    out.print(json.dumps(data, indent=2, ensure_ascii=False), markup=False, highlight=False, soft_wrap=True)


class Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an exception so that temp files are removed on the way out."""


_SIGNALLED: list[int] = []  # the signals that reached the running command, in order


def _raise_interrupt(signum: int, frame: object) -> None:
    _SIGNALLED.append(signum)
    raise KeyboardInterrupt if signum == signal.SIGINT else Terminated


def _as_interrupt(exc: BaseException) -> KeyboardInterrupt | None:
    """The interrupt behind ``exc``, when a signal reached the command while it raised.

    A signal that lands inside an extension module's import comes out as that import's
    ``ImportError: initialization failed`` (pybind11 wraps it): the user still pressed Ctrl-C.
    """
    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, KeyboardInterrupt):
            return seen
        seen = seen.__cause__ or seen.__context__
    if _SIGNALLED:
        return KeyboardInterrupt() if _SIGNALLED[-1] == signal.SIGINT else Terminated()
    return None


def _interrupt_message(command: str, exc: BaseException) -> str:
    from bearnav_cli import pipeline

    word = "terminated" if isinstance(exc, Terminated) else "interrupted"
    stage = pipeline.ACTIVITY.stage
    if stage is None:
        return f"{word}; nothing written for {command}"
    if pipeline.ACTIVITY.written:
        return f"{word}; {stage} was written, nothing after it"
    return f"{word}; nothing written for {stage}"


def _interrupted(command: str, exc: KeyboardInterrupt) -> typer.Exit:
    err.print(_interrupt_message(command, exc), highlight=False, soft_wrap=True, markup=False)
    return typer.Exit(EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED)


def handles_errors(command: Callable) -> Callable:
    """Turn every way a command can fail into one line on stderr and an exit code.

    bearnav errors exit 3 (invalid input); SIGINT exits 130 and SIGTERM 143 with ``interrupted;
    nothing written for STAGE`` (temp files are removed on the way); a broken invariant
    (:class:`InternalError`) and anything unexpected are internal errors, one line too, exit 70
    (``BEARNAV_TRACEBACK=1`` shows the traceback).
    """
    name = command.__name__.removesuffix("_command")

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from bearnav_cli import pipeline

        _setup_logging()
        pipeline.reset_activity()
        _SIGNALLED.clear()
        previous: dict[int, Any] = {}
        if threading.current_thread() is threading.main_thread():
            for signum in (signal.SIGINT, signal.SIGTERM):
                previous[signum] = signal.signal(signum, _raise_interrupt)
        try:
            return command(*args, **kwargs)
        except (typer.Exit, typer.Abort, typer.BadParameter):
            raise
        except InternalError as exc:
            raise _fail(f"internal error (a bug in bearnav, not your input): {exc}".replace("[", r"\["),
                        EXIT_INTERNAL) from None  # fmt: skip
        except BearnavError as exc:
            raise _fail(str(exc).replace("[", r"\["), EXIT_INVALID) from None
        except KeyboardInterrupt as exc:
            raise _interrupted(name, exc) from None
        except MemoryError:
            stage = pipeline.ACTIVITY.stage or name
            raise _fail(f"out of memory in {stage}; nothing written for it (ask for less)", EXIT_INVALID) from None
        except Exception as exc:  # noqa: BLE001 - the last guard: one line, never a traceback
            interrupt = _as_interrupt(exc)
            if interrupt is not None:
                raise _interrupted(name, interrupt) from None
            if os.environ.get("BEARNAV_TRACEBACK"):
                raise
            stage = pipeline.ACTIVITY.stage or name
            text = f"internal error in {stage} ({type(exc).__name__}: {exc}); nothing written for it"
            raise _fail(text.replace("[", r"\[") + " (BEARNAV_TRACEBACK=1 shows where)", EXIT_INTERNAL) from None
        finally:
            for signum, handler in previous.items():
                # the program ends now, its outcome decided: a late SIGINT must not turn it into a kill
                signal.signal(signum, signal.SIG_IGN if _AS_PROGRAM else handler)

    return wrapper


def _print_version(value: bool) -> None:
    if value:
        typer.echo(f"bearnav {__version__}")  # plain text: no rich console to import
        raise typer.Exit(0)


@app.callback()
def main(
    quiet: bool = typer.Option(False, "--quiet", "-q", help=QUIET_HELP),
    version: bool = typer.Option(
        False, "--version", help="Print the version and exit.", is_eager=True, callback=_print_version
    ),
) -> None:
    """Certified bearing-only navigation controllers from a 2-D map."""
    _Quiet.enabled = quiet


# --------------------------------------------------------------------------- reading maps


def _read_bytes(path: Path, field: str | None = None, what: str = "file") -> bytes:
    from bearnav_cli import artifacts

    return artifacts.read_input(path, InvalidMapError, what, field)


def _read_yaml(path: Path) -> tuple[Any, bytes]:
    import yaml

    data = _read_bytes(path)
    try:
        # libyaml's parser when pyyaml has it (the same documents, about 9× faster), else pyyaml's own
        return yaml.load(data, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)), data
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or "syntax error"
        raise InvalidMapError(f"not valid YAML ({problem}{where})", file=str(path)) from exc


def _grid_source(grid_yaml: Path, owner: str, field: str) -> "tuple[GridSource, list[bytes]]":
    """Read a ROS map_server YAML and its image."""
    from bearnav_cli.stages.map_ import GridSource

    if not grid_yaml.is_file():
        raise InvalidMapError(f"occupancy file {str(grid_yaml)!r} does not exist", file=owner, field=field)
    meta, meta_bytes = _read_yaml(grid_yaml)
    if not isinstance(meta, dict) or not isinstance(meta.get("image"), str):
        raise InvalidMapError("not a map_server YAML (needs an 'image' key)", file=str(grid_yaml), field="image")
    image_path = (grid_yaml.parent / meta["image"]).resolve()
    image = _read_bytes(image_path, field="image", what="image")
    return GridSource(meta, image, str(grid_yaml), str(image_path)), [meta_bytes, image]


def read_map_source(
    path: Path,
    goal: Optional[List[float]] = None,
    landmarks: Optional[List[str]] = None,
    starts: Optional[List[str]] = None,
    robot_radius: Optional[float] = None,
    lookahead: Optional[float] = None,
    robot: Optional[dict] = None,
) -> "MapSource":
    """Read a bearnav map YAML (or a bare ROS map_server YAML plus options) into a MapSource.

    ``lookahead`` (``--lookahead``, any map) overrides the map's ``robot.lookahead``, and ``robot``
    (``plan --slip`` ...: ``{key: value}`` of the ``robot:`` section) the other keys it names; like the
    bare grid's options they are part of the input hash, so another value reruns the map stage.
    """
    import hashlib

    from bearnav_cli.stages.map_ import MapSource

    spec, data = _read_yaml(path)
    if not isinstance(spec, dict):
        raise InvalidMapError("expected a mapping at the top level", file=str(path))
    if isinstance(spec.get("manifest"), dict) and "schema" in spec["manifest"]:
        raise InvalidMapError(f"is an artifact ({spec['manifest']['schema']}), not a map YAML; plan from it with "
                              f"`bearnav plan {path}`", file=str(path))  # fmt: skip
    blobs = [data]
    grid = None
    robot_given = {**(robot or {}), **({"lookahead": lookahead} if lookahead is not None else {})}
    if "image" not in spec:
        given = [name for name, value in (("--goal", goal), ("--landmark", landmarks), ("--start", starts),
                                          ("--robot-radius", robot_radius)) if value not in (None, [])]  # fmt: skip
        if given:
            raise BearnavError(f"{given[0]}: only for a bare map_server YAML; {path} is a bearnav map, "
                               "set it there (docs/maps.md)")  # fmt: skip
    if "image" in spec:  # a bare map_server YAML: the rest comes from options
        grid, extra = _grid_source(path, str(path), "image")
        blobs = extra
        spec = {"name": path.stem}
        if goal is None:
            raise InvalidMapError("a bare occupancy grid needs --goal X,Y", file=str(path), field="goal")
        spec["goal"] = list(goal)
        spec["landmarks"] = [_pair(text, "--landmark") for text in landmarks or []]
        spec["starts"] = [_pair(text, "--start") for text in starts or []]
        if robot_radius is not None:
            spec["robot_radius"] = robot_radius
        if robot_given:
            spec["robot"] = dict(robot_given)
        # the options are part of the input: other options must make the map stage rerun
        blobs.append(json.dumps(spec, sort_keys=True).encode())
    else:
        spec.setdefault("name", path.stem)
        if robot_given and isinstance(spec.get("robot") or {}, dict):  # else the map stage names it
            spec["robot"] = {**(spec.get("robot") or {}), **robot_given}
            blobs.append(json.dumps({"--" + key.replace("_", "-"): value for key, value in robot_given.items()},
                                    sort_keys=True).encode())  # fmt: skip
        if "occupancy" in spec:
            if not isinstance(spec["occupancy"], str):
                raise InvalidMapError("expected a file name", file=str(path), field="occupancy")
            grid, extra = _grid_source(path.parent / spec["occupancy"], str(path), "occupancy")
            blobs += extra
    digest = hashlib.sha256()
    for blob in blobs:
        digest.update(hashlib.sha256(blob).digest())
    return MapSource(spec=spec, file=str(path), sha256=digest.hexdigest(), grid=grid)


def _pair(text: str, option: str) -> list[float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise BearnavError(f"{option}: expected X,Y, got {text!r}") from None
    return [x, y]


# --------------------------------------------------------------------------- output helpers


def _report_line(report: "pipeline.StageReport") -> str:
    state = "ran  " if report.ran else "fresh"
    timing = f"{report.elapsed_s:6.2f} s" if report.ran else "       -"
    return f"{report.stage:<10} {state} {timing}  {report.path}  {report.summary}"


def _progress_factory(progress: "Progress") -> "Callable[[str], pipeline.Progress]":
    def make(stage: str) -> "pipeline.Progress":
        task = progress.add_task(stage, total=None)

        def update(done: int, total: int) -> None:
            progress.update(task, completed=done, total=total)

        return update

    return make


@functools.cache
def _count_column() -> type:
    """:class:`_CountColumn`, defined on first use: rich.progress is imported only by commands that show progress."""
    from rich.progress import ProgressColumn
    from rich.text import Text

    class _CountColumn(ProgressColumn):
        """``done/total``, or nothing while the stage has not said how much there is (never ``0/None``)."""

        def render(self, task: Any) -> Text:
            if task.total is None:
                return Text("")
            return Text(f"{int(task.completed)}/{int(task.total)}")

    return _CountColumn


def __getattr__(name: str) -> Any:
    if name == "_CountColumn":
        return _count_column()
    if name == "_WarningHandler":
        return _warning_handler()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class _NoProgress:
    """What :func:`_progress_bar` gives when no bar is shown (quiet, or not a terminal): it takes the
    same calls and does nothing, without importing rich.progress (about 35 ms of a plan's start)."""

    def __enter__(self) -> "_NoProgress":
        return self

    def __exit__(self, *exc: Any) -> None:
        return None

    def add_task(self, *args: Any, **kwargs: Any) -> int:
        return 0

    def update(self, *args: Any, **kwargs: Any) -> None:
        return None


def _progress_bar() -> "Progress | _NoProgress":
    if _Quiet.enabled or not err.is_terminal:
        return _NoProgress()
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn("{task.description:<10}"),
        BarColumn(),
        _count_column()(),
        TimeElapsedColumn(),
        console=err.console,
        transient=True,
    )


# --------------------------------------------------------------------------- next steps
# Every failed outcome and every perception shortfall ends with the command that addresses it, with the
# real file names, built here and only here, so that each hint runs as printed (tests/test_cli_hints.py).


def _command_text(*words: Any) -> str:
    """A command line as a user pastes it into a shell (paths with spaces quoted)."""
    import shlex

    return shlex.join(str(word) for word in words)


def _camera_words(fov: float, max_range: Optional[float] = None) -> list[str]:
    """The options naming a camera, as ``tags``, ``simulate`` and ``plan`` spell them."""
    return ["--fov", f"{fov:g}", *(["--range", f"{max_range:g}"] if max_range is not None else [])]


def _tags_output(plan_npz: Path, map_yaml: Optional[Path]) -> Path:
    """Where ``bearnav tags`` writes its map without ``-o``: NAME_tags.yaml next to ``--map`` (NAME_tags2.yaml
    for NAME_tags.yaml, NAME_tags3.yaml for NAME_tags2.yaml ...), else map_tags.yaml next to the plan."""
    import re

    if map_yaml is None:
        return plan_npz.parent / "map_tags.yaml"
    again = re.fullmatch(r"(.+)_tags(\d*)", map_yaml.stem)  # a map tags wrote: count, never NAME_tags_tags
    name = f"{again[1]}_tags{int(again[2] or 1) + 1}" if again else f"{map_yaml.stem}_tags"
    return map_yaml.with_name(f"{name}.yaml")


def _tags_map(plan_npz: Path) -> Optional[Path]:
    """The map YAML ``bearnav tags --map`` can extend for this plan: the one it was planned from, if that is a
    bearnav map (a bare map_server YAML needs the options it was planned with, so the plan's own map is used)."""
    from bearnav_cli import artifacts

    source = artifacts.map_source_of(plan_npz)
    if source is None:
        return None
    try:
        spec, _ = _read_yaml(source)
    except BearnavError:
        return None
    return source if isinstance(spec, dict) and "image" not in spec else None


def tags_step(plan_npz: Path, fov: float = 360.0, max_range: Optional[float] = None,
              plan_words: tuple[str, ...] = (), map_yaml: Optional[Path] = None,
              tags_words: tuple[str, ...] = ()) -> str:  # fmt: skip
    """The next step where a camera cannot fix itself: the ``bearnav tags`` command for this plan, the map it
    writes and the ``bearnav plan`` command that re-plans with it (``plan_words``: options to plan it with).

    Parameters
    ----------
    plan_npz : Path
        The plan, as the user named it (or as bearnav wrote it).
    fov, max_range : float
        The camera (degrees; map units, None for unlimited).
    plan_words : tuple of str
        Options of the re-planning command (the camera of ``plan --fov``).
    map_yaml : Path, optional
        The map YAML to give ``--map`` (default: the one the plan was made from, if any).
    tags_words : tuple of str
        Further options of the ``bearnav tags`` command (``--for live`` and its bound).

    Returns
    -------
    str
        ```bearnav tags PLAN --fov F --map M` writes M_tags.yaml; then `bearnav plan M_tags.yaml```.
    """
    map_yaml = map_yaml or _tags_map(plan_npz)
    tags = _command_text("bearnav", "tags", plan_npz, *_camera_words(fov, max_range), *tags_words,
                         *(["--map", map_yaml] if map_yaml is not None else []))  # fmt: skip
    written = _tags_output(plan_npz, map_yaml)
    return f"`{tags}` writes {written}; then `{_command_text('bearnav', 'plan', written, *plan_words)}`"


def _simulate_words(params: dict, **changes: Any) -> list[str]:
    """The ``bearnav simulate`` options that give the loop ``params`` (with ``changes``): those off their defaults."""
    words: list[str] = []
    for field in params_fields("simulate"):
        if field.name in PARAMS_ONLY["simulate"] or field.name not in params:
            continue
        value = changes.get(field.name, params[field.name])
        if value == field.default or value is None:
            continue
        name = _option_name("simulate", field.name)
        if field.kind is bool:
            words.append(name if value else FLAG_OFF.get(("simulate", field.name), "--no-" + name[2:]))
        else:
            words += [name, _shown(value).strip("'")]
    return words


def simulation_steps(report: "pipeline.StageReport", plan_npz: Path, min_success: float) -> str:
    """Why too few simulated runs reached the goal, outcome by outcome, and the command that addresses each.

    Parameters
    ----------
    report : StageReport
        The simulate stage's report (its artifact the :class:`~bearnav_cli.datatypes.Simulation`, its
        manifest the loop's parameters).
    plan_npz : Path
        The plan simulated.
    min_success : float
        The ``--min-success`` the runs fell short of.

    Returns
    -------
    str
        One line: the outcome, then ``lost: ...; collision: ...`` and the figure that shows the runs.
    """
    params = dict((report.manifest or {}).get("params") or {})
    counts = report.artifact.counts()
    steps = []
    if counts.get("lost"):
        fov, max_range = float(params.get("fov", 360.0)), params.get("range")
        if params.get("estimator") == "set":
            eta = params.get("bearing_error_deg") or params.get("noise_bound_deg")
            words = ("--for", "live", *(["--bearing-error-deg", f"{eta:g}"] if eta else []))
            steps.append("lost: a look all around left the error bound above what the cell tolerates (the cell is "
                         "not live at these bounds); add tags until every cell is: "
                         + tags_step(plan_npz, fov, max_range, tags_words=words))  # fmt: skip
        else:
            hold = params.get("hold_time", 2.0)
            steps.append(f"lost: the camera saw fewer than two usable tags for --hold-time {hold:g} s (a {fov:g}° "
                         "camera); add tags: " + tags_step(plan_npz, fov, max_range))  # fmt: skip
    if counts.get("collision") and params.get("estimator") != "set":
        retry = _command_text("bearnav", "simulate", plan_npz, *_simulate_words(params, estimator="set"))
        steps.append("collision: the position estimate erred beyond the cell's tolerance (noise, slip, a camera or "
                     f"a unicycle outside the certificate); `{retry}` drives only where its error bound is "
                     "certified")  # fmt: skip
    elif counts.get("collision"):
        steps.append("collision: the error bounds assumed are below the errors simulated (--bearing-error-deg, "
                     "--slip); `bearnav verify " + str(plan_npz) + "` checks the certificate")  # fmt: skip
    if counts.get("stall") or counts.get("timeout"):
        steps.append("stall or timeout: the field vanished or the run made no progress (outside every cell?)")
    shown = _command_text("bearnav", "plot", report.path)
    return (f"{report.summary}, fewer than --min-success {min_success:g}: " + "; ".join(steps)
            + f"; `{shown}` draws the runs by outcome, into {_figure_default(report.path)}")  # fmt: skip


def verify_steps(report: Any, plan_npz: Path, world: Optional[Path]) -> str:
    """What to do about a plan that fails ``bearnav verify``: one line naming the real files.

    Parameters
    ----------
    report : VerifyReport
        ``verify.run``'s report (its reasons are printed above this line).
    plan_npz : Path
        The plan verified.
    world : Path, optional
        The ``--world`` map, if one was given.

    Returns
    -------
    str
    """
    import numpy as np

    from bearnav_cli import artifacts
    from bearnav_cli.datatypes import Outcome, plural

    steps = []
    if report.world_cells:
        steps.append(f"the world moved: re-plan in it with `{_command_text('bearnav', 'plan', world)}`")
    if report.uncertified:
        shown = _command_text("bearnav", "inspect", plan_npz, "--cell", report.uncertified[0])
        steps.append(f"`{shown}` shows the first cell not certified")
    composition_fails = report.composition is not None and not report.composition.ok
    breached = report.breaches is not None and bool(report.breaches.any())
    broken = bool(report.false_certificates) or composition_fails or bool(report.lookahead_problems) or breached
    if broken:  # the checks a plan bearnav wrote passes: an edited file, another version's, or a bug
        origin = artifacts.map_source_of(plan_npz)
        again = (f"`{_command_text('bearnav', 'plan', origin, '--force')}`" if origin
                 else "`bearnav plan` of the map it was made from, with --force,")  # fmt: skip
        steps.append(f"if the plan was edited or made by another version, {again} makes it again; else please "
                     "report it with the plan")  # fmt: skip
    runs = report.rollouts
    if runs is not None and len(runs) and bool(np.any(np.asarray(runs.outcome) != Outcome.SUCCESS)):
        again = _command_text("bearnav", "simulate", plan_npz, "--measurement", "displacement", "--odometry-noise", "0")
        steps.append(f"`{again}` drives runs of the same loop and writes them; `bearnav plot` of its sim.npz draws "
                     "them by outcome")  # fmt: skip
    text = f"{plan_npz} fails verification ({plural(len(report.reasons), 'problem')} above)"
    return text + (": " + "; ".join(steps) if steps else "")


def _outcome_failure(artifact: Any, path: Optional[Path] = None, camera: tuple[float, Optional[float]] = (360.0, None),
                     plan_words: tuple[str, ...] = ()) -> str | None:  # fmt: skip
    """Why a finished run's result is not usable (exit 1) and what to do next, or None.

    ``path`` is the artifact's file (the hints name it), ``camera`` the (fov, range) the tags are
    proposed for, ``plan_words`` the options of the re-planning command.
    """
    from bearnav_cli.datatypes import CellFlag, Cells, CellStatus, Plan, cell_list

    cells = getattr(artifact, "cells", artifact)  # a Plan holds its Cells
    nodes = getattr(cells, "nodes", None)
    added = getattr(cells, "node_added", None)  # leaves decompose added to cover F: not a route the tree found
    if nodes is not None and len(nodes) - (0 if added is None else sum(map(bool, added))) < 2:
        what = "no route: the tree has only its root (is the goal walled in, or did every sample fall in obstacles?)"
        return what + (f"; `{_command_text('bearnav', 'plot', path)}` draws it" if path is not None else "")
    blind = cells.flagged(CellFlag.BLIND_SPOT) if isinstance(cells, Cells) else []
    if blind:
        one = len(blind) == 1
        what = f"{'cell' if one else 'cells'} {cell_list(blind, 20)} {'has' if one else 'have'} free points that see "
        what += "fewer than 2 landmarks"
        if path is None:
            return what
        if isinstance(artifact, Plan):
            step = tags_step(path, *camera, plan_words=plan_words)
        else:  # cells.npz: tags places landmarks along a plan's fields
            plan_npz = path.with_name("plan.npz")
            step = f"`{_command_text('bearnav', 'synthesize', path, '-o', plan_npz)}`, then " + tags_step(
                plan_npz, *camera, plan_words=plan_words)  # fmt: skip
        return f"{what}: add landmarks there; {step}"
    status = getattr(artifact, "status", None)
    if status is not None:
        bad = (status == CellStatus.NOT_CERTIFIED) | (status == CellStatus.SOLVER_FAILURE)
        failed = [int(c) for c in bad.nonzero()[0]]
        if failed:
            where = f"`bearnav inspect {path} --cell {failed[0]}` shows the first" if path is not None else ""
            return f"cells {cell_list(failed, 20)} are not certified (status 2 or 3)" + (f"; {where}" if where else "")
    return None


def _finish(
    reports: "list[pipeline.StageReport]",
    as_json: bool,
    extra: Optional[dict] = None,
    camera: "tuple[float, float | None]" = (360.0, None),
    plan_words: tuple[str, ...] = (),
) -> None:
    """Print the reports' JSON rows (the last with ``extra`` fields) and exit 1 on a failed outcome."""
    if as_json:
        rows = [
            {"stage": r.stage, "ran": r.ran, "elapsed_s": r.elapsed_s, "path": str(r.path), "summary": r.summary}
            for r in reports
        ]
        if rows and extra:
            rows[-1].update(extra)
        _print_json(rows)
    problem = _outcome_failure(reports[-1].artifact, reports[-1].path, camera, plan_words) if reports else None
    if problem:
        raise _fail(problem, EXIT_OUTCOME)


# --------------------------------------------------------------------------- options from the Params


#: The folder of the ``bearnav_cli`` package, whose sources describe the options.
_PACKAGE = Path(__file__).resolve().parent
#: The module of each command's ``Params`` (the stage table's, plus ``verify``).
PARAMS_MODULES = {
    "map": "bearnav_cli.stages.map_", "rrtstar": "bearnav_cli.stages.rrtstar",
    "simplify": "bearnav_cli.stages.simplify", "decompose": "bearnav_cli.stages.decompose",
    "synthesize": "bearnav_cli.stages.synthesize", "simulate": "bearnav_cli.stages.simulate",
    "verify": "bearnav_cli.verify",
}  # fmt: skip
#: The off-switch of a flag when it is not ``--no-NAME``.
FLAG_OFF = {("synthesize", "tolerant"): "--lp-field", ("simulate", "clamp_reverse"): "--allow-reverse"}
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
    """``pipeline.OPTION_NAMES``, read from its source (importing ``pipeline`` imports every stage)."""
    import ast
    import re

    match = re.search(r"^OPTION_NAMES = (\{[^\n]*\})$", _module_source("bearnav_cli.pipeline"), re.M)
    if match is None:
        from bearnav_cli import pipeline

        return dict(pipeline.OPTION_NAMES)
    return ast.literal_eval(match.group(1))


def _option_name(command: str, name: str) -> str:
    return option_names().get((command, name), "--" + name.replace("_", "-"))


def _plain(text: str) -> str:
    """A docstring's reST as help text: ``code`` and :role:`target` plain (the help is plain text, not rich markup)."""
    import re

    text = re.sub(r":\w+:`~[\w.]*\.(\w+)`", r"\1", text)
    text = re.sub(r":\w+:`([^`]+)`", r"\1", text)
    return _user_words(text.replace("``", ""))


#: A part of a parenthesis that points into the developer documentation or the code: "ALGORITHMS
#: §11.5", "§6", "Lemma 7", "runtime.step.error_ball_pace", "bearnav_cli.world.camera.IdealCamera".
_REFERENCE = (
    r"(?:(?:ALGORITHMS|DESIGN)\s+)?§[\d.–-]+(?:\s+step\s+\d+)?|Lemma\s+\d+|issue\s+\d+(?:\.\d+)?"
    r"|(?:bearnav_cli|runtime|funnel|liveness)(?:\.\w+)+"
)


def _user_words(text: str) -> str:
    """Help text without the developer's references: the parts of a parenthesis that cite a section
    of docs/algorithms.md, a lemma, an issue or a module of the code are dropped (a parenthesis of
    nothing else goes with them). The docstrings keep them; docs/algorithms.md explains them.
    """
    import re

    def keep(match: re.Match[str]) -> str:
        parts = match.group(2).split(", ")
        kept = [part for part in parts if not re.fullmatch(_REFERENCE, part.strip())]
        if len(kept) == len(parts):
            return match.group(0)
        return f"{match.group(1)}({', '.join(kept)})" if kept else ""

    return re.sub(r"(\s*)\(([^()]*)\)", keep, text)


def _shown(value: Any) -> str:
    return repr(value) if isinstance(value, str) else f"{value:g}" if isinstance(value, float) else str(value)


def option_help(command: str, field: ParamField, *, with_default: bool = True, prefix: str = "") -> str:
    """The help text of a field's option: its docstring's first sentence and the dataclass's default.

    A default of None is described by the docstring's own words: the sentences up to the one that
    says what ``None`` means. ``with_default=False`` leaves the default to typer (``[default: 200]``).
    """
    import re

    sentences = re.split(r"(?<=\.)\s+(?=[A-Z`*(])", field.doc.strip()) if field.doc.strip() else [""]
    count = 1
    while count < len(sentences) and len(" ".join(sentences[:count])) < 40:  # "*paper* and funnel-local."
        count += 1
    if field.default is None:
        count = max(count, next((i + 1 for i, s in enumerate(sentences) if "None" in s), 1))
    text = _plain(" ".join(sentences[:count]))
    text = text[:-1] if text.endswith(".") and not text.endswith("..") else text
    notes = []
    if field.choices:
        notes.append("one of " + ", ".join(field.choices))
    if with_default and field.default is not None:
        if field.kind is bool:
            name = _option_name(command, field.name)
            shown = name if field.default else FLAG_OFF.get((command, field.name), "--no-" + name[2:])
        else:
            shown = _shown(field.default)
        notes.append(f"default: {shown}")
    return prefix + text + (f" ({'; '.join(notes)})" if notes else "") + "."


def params_options(command: str, *, skip: tuple[str, ...] = (), only: tuple[str, ...] | None = None,
                   defaults: bool = False, prefix: str = "") -> list[inspect.Parameter]:  # fmt: skip
    """The typer options of a command's ``Params`` fields, as parameters of a command's signature.

    The option is ``--field-name`` (``pipeline.OPTION_NAMES`` renames, such as ``--starts``), a
    ``--name/--no-name`` flag for a bool (:data:`FLAG_OFF` names other off-switches), of the
    field's type; the help is :func:`option_help`. A stage's options default to None, "not given",
    so that the map's ``params:`` apply; ``defaults=True`` (``verify``, which has no map layer)
    gives typer the dataclass's defaults instead. ``skip`` leaves fields without an option
    (``params:`` only), ``only`` keeps just those fields.
    """
    options = []
    for field in params_fields(command):
        if field.name in skip or (only is not None and field.name not in only):
            continue
        name = _option_name(command, field.name)
        declared = f"{name}/{FLAG_OFF.get((command, field.name), '--no-' + name[2:])}" if field.kind is bool else name
        default = field.default if defaults else None
        kind = field.kind if default is not None else Optional[field.kind]
        help_text = option_help(command, field, with_default=not defaults, prefix=prefix)
        options.append(inspect.Parameter(field.name, inspect.Parameter.KEYWORD_ONLY, annotation=kind,
                                         default=typer.Option(default, declared, help=help_text)))  # fmt: skip
    return options


def with_options(
    *groups: Callable[[], list[inspect.Parameter]], before: str = "force"
) -> Callable[[Callable], Callable]:
    """Give a command the generated options, among its own before ``before``.

    Each group is called, for its options (:func:`params_options`), when the command's click
    options are first read (:class:`_Command`), not when the program starts: typer reads the
    command's own signature, less its ``**options``, in which the command takes the generated
    ones, keyed by field name.
    """

    def decorate(command: Callable) -> Callable:
        signature = inspect.signature(command, eval_str=True)
        own = [p.replace(kind=inspect.Parameter.KEYWORD_ONLY) for p in signature.parameters.values()
               if p.kind is not inspect.Parameter.VAR_KEYWORD]  # fmt: skip
        command.__signature__ = signature.replace(parameters=own)
        command.generated_options = (groups, before)
        return command

    return decorate


def _click_option(parameter: inspect.Parameter) -> Any:
    """The click option typer makes of a generated option (:func:`params_options`), as of a signature's."""
    from typer.main import get_click_param
    from typer.models import ParamMeta

    option, convertor = get_click_param(ParamMeta(name=parameter.name, default=parameter.default,
                                                  annotation=parameter.annotation))  # fmt: skip
    if convertor is not None:  # typer converts paths and enums after parsing; a field is an int, float, str or bool
        raise TypeError(f"option {parameter.name}: a {parameter.annotation} needs typer's conversion")
    return option


# --------------------------------------------------------------------------- commands

#: Fields without a command-line option, set in the map's ``params:`` only (docs/cli.md lists the
#: stages'; ``verify.Params.dt`` follows simulate's).
PARAMS_ONLY: dict[str, tuple[str, ...]] = {
    "map": ("coverage_cells",), "rrtstar": (), "simplify": (), "decompose": (),
    "synthesize": ("w_h", "w_v", "clf_margin"),
    "simulate": ("min_spread_deg", "turn_first", "certified_heading", "look_on_purpose", "initial_heading",
                 "max_fix_error", "goal_tolerance", "max_steps", "record_trajectories"),
    "verify": ("dt",),
}  # fmt: skip

#: Where the words of the verify and simulate output are defined.
WORDS_NOTE = 'lost, stall, left-cell events, approach, hold, certified, D, F_m: docs/cli.md "Words in the output"'

MAP_ARG = typer.Argument(..., metavar="MAP", help="Map YAML (bearnav format, or a ROS map_server YAML).")
FORCE = typer.Option(False, "--force", help="Rerun even if the output is fresh.")
QUIET = typer.Option(False, "--quiet", "-q", help=QUIET_HELP)
JSON = typer.Option(False, "--json", help="Print machine-readable JSON.")
LOOKAHEAD = typer.Option(
    None, metavar="λ", help="Look-ahead λ, map units (any map; overrides the map's robot.lookahead): plan for the "
    "point λ ahead of a unicycle's axle, obstacles inflated by the radius plus λ (docs/maps.md)."
)  # fmt: skip


#: The option of each field a camera check names (``perception.check_params``, ``bearing.check_camera``).
#: The range and noise of the camera a ``--fov`` names (map, plan, plot): one declaration each.
CAMERA_RANGE = typer.Option(None, "--range", help="That camera's range, map units (default: unlimited).")
CAMERA_NOISE = typer.Option(
    None, "--noise-deg", help="Bearing noise (1σ, degrees) of that camera's predicted fix error (default 1)."
)
CAMERA_OPTIONS = {"fov": "--fov", "fov_deg": "--fov", "noise_deg": "--noise-deg", "range": "--range",
                  "max_range": "--range"}  # fmt: skip


def _check_camera(fov: float, noise_deg: float = 0.0, max_range: Optional[float] = None) -> None:
    """``perception.check_params`` of a command's camera options; an error names the option (one line, exit 3)."""
    from bearnav_cli import perception

    try:
        perception.check_params(fov, noise_deg, float("inf") if max_range is None else max_range)
    except InvalidParamsError as exc:  # name the option the user typed
        raise _fail(f"{CAMERA_OPTIONS.get(exc.field or '', exc.field)}: {exc.reason}", EXIT_INVALID) from None


@app.command("map")
@handles_errors
@with_options(functools.partial(params_options, "map", skip=PARAMS_ONLY["map"]), before="goal")
def map_command(
    source: Path = MAP_ARG,
    out_path: Optional[Path] = typer.Option(None, "-o", "--out", help="Output (default plans/<name>/map.json)."),
    goal: Optional[str] = typer.Option(None, help="Goal X,Y (bare occupancy grids only)."),
    landmark: Optional[List[str]] = typer.Option(None, help="Landmark X,Y, repeatable (bare grids only)."),
    start: Optional[List[str]] = typer.Option(None, help="Start X,Y, repeatable (bare grids only)."),
    robot_radius: Optional[float] = typer.Option(None, help="Robot radius (bare grids only)."),
    lookahead: Optional[float] = LOOKAHEAD,
    fov: Optional[float] = typer.Option(
        None, "--fov", help="Also report where a camera of this field of view (degrees, (0, 360]) can fix itself."
    ),
    max_range: Optional[float] = CAMERA_RANGE,
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Validate a map and write map.json.

    Example: bearnav map maps/kitchen.yaml -o /tmp/kitchen/map.json --fov 60
    """
    from bearnav_cli import pipeline

    _Quiet.enabled |= quiet
    if fov is None and max_range is not None:
        raise _fail("--range: only with --fov (the camera it belongs to)", EXIT_INVALID)
    if fov is not None:  # checked before anything is written
        _check_camera(fov, 0.0, max_range)
    goal_xy = _pair(goal, "--goal") if goal else None
    src = read_map_source(source, goal_xy, landmark, start, robot_radius, lookahead)
    target = out_path or Path("plans") / str(src.spec.get("name", source.stem)) / "map.json"
    report = pipeline.run_map(src, target, options, force)
    seeing = None
    if fov is not None:  # the map artifact is written already, without it
        from bearnav_cli import perception

        seeing = perception.heading_coverage(report.artifact, fov, float("inf") if max_range is None else max_range)
    extra = None
    if seeing is not None:
        extra = {"perception": {"fov_deg": seeing.fov_deg, "range": max_range, "grid_points": len(seeing.points),
                                "fraction_some_heading": seeing.fraction_some,
                                "fraction_every_heading": seeing.fraction_every,
                                "blind_points": len(seeing.blind)}}  # fmt: skip
    if not as_json:
        out.print(_report_line(report), highlight=False, soft_wrap=True)
        if seeing is not None:
            # the plan `bearnav plan` makes of this map.json lands next to it; of the YAML, in plans/NAME/
            default = target == Path("plans") / str(src.spec.get("name", source.stem)) / "map.json"
            planning = _command_text("bearnav", "plan", source if default else target)
            bearnav_map = source if src.grid is None or "occupancy" in src.spec else None  # a bare grid needs options
            step = tags_step(target.parent / "plan.npz", fov, max_range, map_yaml=bearnav_map)
            hint = f"; to place tags where it fails, `{planning}`, then {step}"
            out.print(f"  perception: {seeing.summary()}{hint if seeing.fraction_some < 1.0 else ''}",
                      highlight=False, markup=False, soft_wrap=True)  # fmt: skip
    _finish([report], as_json, extra)


@app.command("rrtstar")
@handles_errors
@with_options(functools.partial(params_options, "rrtstar", skip=PARAMS_ONLY["rrtstar"]))
def rrtstar_command(
    map_json: Path = typer.Argument(..., metavar="MAP_JSON", help="map.json from `bearnav map`."),
    out_path: Optional[Path] = typer.Option(None, "-o", "--out", help="Output (default tree.npz next to the input)."),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Grow an RRT* tree rooted at the goal, keeping the collision samples.

    Example: bearnav rrtstar plans/kitchen/map.json --iterations 3000 --seed 1
    """
    _Quiet.enabled |= quiet
    _run_one("rrtstar", map_json, out_path, options, force, as_json)


@app.command("simplify")
@handles_errors
@with_options(functools.partial(params_options, "simplify", skip=PARAMS_ONLY["simplify"]))
def simplify_command(
    tree_npz: Path = typer.Argument(..., metavar="TREE_NPZ", help="tree.npz from `bearnav rrtstar`."),
    out_path: Optional[Path] = typer.Option(
        None, "-o", "--out", help="Output (default simplified.npz next to the input)."
    ),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Simplify the tree: shortcuts, leaf cutting and crossing removal to a fixed point.

    Example: bearnav simplify plans/kitchen/tree.npz
    """
    _Quiet.enabled |= quiet
    _run_one("simplify", tree_npz, out_path, options, force, as_json)


@app.command("decompose")
@handles_errors
@with_options(functools.partial(params_options, "decompose", skip=PARAMS_ONLY["decompose"]))
def decompose_command(
    tree_npz: Path = typer.Argument(..., metavar="SIMPLIFIED_NPZ", help="simplified.npz from `bearnav simplify`."),
    out_path: Optional[Path] = typer.Option(None, "-o", "--out", help="Output (default cells.npz next to the input)."),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Cut the free space into one convex cell per tree node: funnel cells that compose (default).

    Example: bearnav decompose plans/kitchen/simplified.npz --cells paper
    """
    _Quiet.enabled |= quiet
    _run_one("decompose", tree_npz, out_path, options, force, as_json)


@app.command("synthesize")
@handles_errors
@with_options(functools.partial(params_options, "synthesize", skip=PARAMS_ONLY["synthesize"]))
def synthesize_command(
    cells_npz: Path = typer.Argument(..., metavar="CELLS_NPZ", help="cells.npz from `bearnav decompose`."),
    out_path: Optional[Path] = typer.Option(None, "-o", "--out", help="Output (default plan.npz next to the input)."),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Synthesise a certified linear controller per cell (one robust LP each, HiGHS).

    Example: bearnav synthesize plans/kitchen/cells.npz --lp-form dual
    """
    _Quiet.enabled |= quiet
    _run_one("synthesize", cells_npz, out_path, options, force, as_json)


@app.command("verify")
@handles_errors
@with_options(functools.partial(params_options, "verify", skip=PARAMS_ONLY["verify"], defaults=True), before="tree")
def verify_command(
    plan_npz: Path = typer.Argument(..., metavar="PLAN_NPZ", help="plan.npz from `bearnav synthesize`."),
    tree: Optional[Path] = typer.Option(None, help="tree.npz whose collision samples the plan must keep."),
    world: Optional[Path] = typer.Option(
        None, help="Another map YAML in the same frame: list the cells that are no longer obstacle-free there."
    ),
    fov: Optional[float] = typer.Option(
        None, "--fov", help="Also report perception coverage for a camera of this field of view, degrees (0, 360]."
    ),
    noise_deg: float = typer.Option(1.0, "--noise-deg", help="Bearing noise (1σ, degrees) of that report."),
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Prove the plan's certificate from the plan alone (no solver): every cell, coverage, tolerance, the loop.

    Example: bearnav verify plans/kitchen/plan.npz --starts 500 --min-success 0.99
    """
    from bearnav_cli import pipeline, verify  # scipy.sparse and the closed loop: only for this command

    _Quiet.enabled |= quiet
    for name, value in options.items():
        pipeline.check_value("verify", name, value, pipeline.option_name("verify", name))
    try:
        params = verify.Params(**options)
    except InvalidParamsError as exc:  # name the option the user typed
        raise _fail(f"{pipeline.option_name('verify', exc.field or '')}: {exc.reason}", EXIT_INVALID) from None
    starts = params.n_starts
    pipeline.ACTIVITY.stage = "verify"
    loaded = pipeline.load(plan_npz, "plan")
    samples = pipeline.load(tree, ("tree", "simplified")).artifact.collision_samples if tree else None
    plan = loaded.artifact
    where_speed = "--speed" if params.speed is not None else "params.simulate.speed"
    speed = verify.loop_speed(plan, params)  # the speed verify.run drives at (the map's, else simulate's)
    pipeline.check_value("verify", "speed", speed, where_speed, plan.map.diagonal)
    if starts:
        loop = pipeline.resolve_params("simulate", {}, {"speed": speed, "measurement": "displacement",
                                                       "record_trajectories": False})  # fmt: skip
        pipeline.check_closed_loop(plan, loop, starts, "--starts", where_speed, record=False)
        pipeline.check_verify_starts(plan, starts)
    world_map = _load_world(world) if world is not None else None
    seeing = None
    if fov is not None:  # checked before the closed loop runs
        from bearnav_cli import perception

        _check_camera(fov, noise_deg)
    with _progress_bar() as progress:
        track = _progress_factory(progress)("verify")
        try:
            report = verify.run(plan, params, tree_samples=samples, progress=track, world=world_map)
        except InvalidParamsError as exc:  # a liveness option only the map refuses (--live-resolution against D)
            if exc.field not in options:
                raise
            raise _fail(f"{pipeline.option_name('verify', exc.field)}: {exc.reason}", EXIT_INVALID) from None
    if fov is not None:
        seeing = perception.perception_coverage(plan, fov, noise_deg)
    if as_json:
        data = report.to_json()
        if seeing is not None:
            data["perception"] = {"fov_deg": fov, "noise_deg": noise_deg, "fraction_domain": seeing.fraction_domain,
                                  "fraction_free": seeing.fraction_free,
                                  "median_predicted_error": seeing.median_error_domain,
                                  "fraction_within_tolerance": seeing.fraction_within_tolerance}  # fmt: skip
        _print_json(data)
    else:
        out.print(f"verify    {plan_npz}  {report.summary()}", highlight=False, soft_wrap=True)
        for reason in report.reasons:
            out.print(f"  - {reason}", highlight=False, soft_wrap=True)
        for note in [] if _Quiet.enabled else getattr(report, "notes", []):
            out.print(f"  note: {note}", highlight=False, soft_wrap=True)
        if seeing is not None:
            out.print(f"  perception: {seeing.summary()} (the rule: `bearnav tags` places tags where it fails)",
                      highlight=False, soft_wrap=True)  # fmt: skip
        if not _Quiet.enabled:  # what the certificate says, in words, whatever else was printed
            out.print(f"  {verify.guarantee(plan, report)}", highlight=False, markup=False, soft_wrap=True)
        if starts and not _Quiet.enabled:
            out.print(f"  the {starts} runs drive with displacements (exact positions) and a full view, at speed "
                      f"{speed:g} map units/s: `bearnav simulate` adds bearings, a camera and noise; {WORDS_NOTE}",
                      highlight=False, markup=False, soft_wrap=True)  # fmt: skip
    if report.failed:
        raise _fail(verify_steps(report, plan_npz, world), EXIT_OUTCOME)


def _load_world(path: Path):
    """The normalised map of a ``--world`` YAML (validated like any map)."""
    from bearnav_cli.stages import map_

    return map_.run(read_map_source(path))


def _run_one(stage: str, source: Path, out_path: Optional[Path], overrides: dict, force: bool, as_json: bool) -> None:
    from bearnav_cli import pipeline

    with _progress_bar() as progress:
        report = pipeline.run_stage(stage, source, out_path, overrides, force, _progress_factory(progress)(stage))
    if not as_json:
        out.print(_report_line(report), highlight=False, soft_wrap=True)
    _finish([report], as_json)
    if stage == "synthesize" and not as_json and not _Quiet.enabled:  # the plan: what it certifies, in words
        out.print(f"  {plan_guarantee(report.artifact, report.path)}", highlight=False, markup=False, soft_wrap=True)


@app.command("simulate")
@handles_errors
@with_options(functools.partial(params_options, "simulate", skip=PARAMS_ONLY["simulate"]), before="min_success")
def simulate_command(
    plan_npz: Path = typer.Argument(
        ..., metavar="PLAN_NPZ", help="plan.npz from `bearnav synthesize` or `bearnav plan`."
    ),
    out_path: Optional[Path] = typer.Option(None, "-o", "--out", help="Output (default sim.npz next to the plan)."),
    min_success: float = typer.Option(1.0, help="Exit 1 when fewer runs than this fraction reach the goal."),
    gif: Optional[Path] = typer.Option(None, help="Also write an animation of the runs (.gif)."),
    bag: Optional[Path] = typer.Option(
        None, help="Also write the runs as a ROS 2 bag: NAME.mcap (one MCAP file) or NAME (a bag folder)."
    ),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Drive robots with the plan's controllers from bearings: field of view, noise, unicycle.

    Example: bearnav simulate plans/kitchen/plan.npz --fov 60 --dynamics unicycle --starts random:200
    """
    from bearnav_cli import artifacts, pipeline

    _Quiet.enabled |= quiet
    if not 0.0 <= min_success <= 1.0:
        raise _fail(f"--min-success: must lie in [0, 1], got {min_success}", EXIT_INVALID)
    overrides = options
    sim_npz = out_path or plan_npz.with_name(pipeline.STAGE_BY_NAME["simulate"].filename)
    # -o's own form first (a sim.json given as -o is a wrong extension, not a clash with its metrics),
    # then every output against every other before any work: a bag folder around sim.npz would replace it
    artifacts.check_output_file(sim_npz, (artifacts.KINDS["simulation"].suffix,), inputs=(plan_npz,))
    artifacts.check_distinct(
        {"-o/--out": sim_npz, "sim.json": artifacts.metrics_path(sim_npz), "--gif": gif, "--bag": bag}
    )
    if gif is not None:  # before any work, like every output path
        artifacts.check_output_file(gif, (".gif",), "--gif", inputs=(plan_npz,))
    if bag is not None:  # before any work too: suffix, folder, what is there, rosbags installed
        from bearnav_cli import bag as ros_bag

        ros_bag.check_path(bag, "--bag", force=force)
    with _progress_bar() as progress:
        report = pipeline.run_stage("simulate", plan_npz, out_path, overrides, force,
                                    _progress_factory(progress)("simulate"))  # fmt: skip
    sim = report.artifact
    metrics = sim.stats
    if bag is not None:
        pipeline.ACTIVITY.stage, pipeline.ACTIVITY.written = f"{bag} (sim.npz and sim.json were written)", False
        if not _Quiet.enabled and not as_json and len(sim.trajectory_coords) > 50_000:  # about a second each
            err.print(f"writing {bag} ({len(sim.trajectory_coords)} poses) ...", highlight=False, markup=False)
        ros_bag.write(bag, sim, option="--bag", force=force)
    if as_json:
        shown = {"sim": str(report.path), "ran": report.ran, "metrics": metrics}
        _print_json(shown if bag is None else dict(shown, bag=str(bag)))
    elif _Quiet.enabled:  # -q: the result's one line (and, on stderr, what failed)
        out.print(_report_line(report), highlight=False, soft_wrap=True)
    else:
        from rich.table import Table

        out.print(_report_line(report), highlight=False, soft_wrap=True)
        table = Table(title=None, box=None, show_header=True, header_style="bold")
        table.add_column("metric")
        table.add_column("value", justify="right")
        for name, value in _metric_rows(metrics):
            table.add_row(name, value)
        out.print(table)
        out.print(WORDS_NOTE, highlight=False, markup=False, soft_wrap=True)
        if bag is not None:
            out.print(f"wrote {bag}", highlight=False)
    if gif is not None:
        plot = _plotting()  # matplotlib only when asked

        pipeline.ACTIVITY.stage, pipeline.ACTIVITY.written = f"{gif} (sim.npz and sim.json were written)", False
        if not _Quiet.enabled and not as_json:  # a GIF takes seconds: say what is happening
            err.print(f"writing {gif} (80 frames) ...", highlight=False, markup=False)
        with artifacts.atomic_output(gif) as tmp:
            plot.save_animation(sim, str(tmp), params=(report.manifest or {}).get("params"))
        if not as_json:
            out.print(f"wrote {gif}", highlight=False)
    rate = metrics.get("success_rate")
    if rate is None or rate < min_success:
        raise _fail(simulation_steps(report, plan_npz, min_success), EXIT_OUTCOME)


def _metric_rows(metrics: dict) -> list[tuple[str, str]]:
    """The metrics table of ``bearnav simulate``: (name, formatted value) rows."""

    def num(value: Any, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    rows = [
        ("runs", str(metrics["runs"])),
        ("success rate", num(metrics["success_rate"], ".1%")),
    ]
    rows += [(f"  {name}", str(n)) for name, n in metrics["outcomes"].items() if n]
    rows += [
        ("mean time (s)", num(metrics["time_mean_s"], ".1f")),
        ("mean path length (map units)", num(metrics["path_length_mean"], ".2f")),
        ("path / tree route", num(metrics["path_over_tree_route_mean"], ".3f")),
        ("min clearance (map units)", num(metrics["min_clearance"], ".3f")),
        ("left-cell events", str(metrics["left_cell_events"])),
        ("runs with an approach", str(metrics["runs_with_approach"])),
        ("hold time total (s)", num(metrics["hold_time_total_s"], ".1f")),
        ("certified moving steps", num(metrics.get("certified_step_fraction"), ".1%")),
    ]
    if metrics.get("estimator") == "set":  # ALGORITHMS §12.8: how the bounded-error robot spent its time
        rows += [
            ("success from D", num(metrics.get("success_rate_in_domain"), ".1%")),
            ("looks per run", num(metrics.get("looks_per_run"), ".1f")),
            ("mean look (s)", num(metrics.get("look_time_mean_s"), ".2f")),
            ("truth outside its set (steps)", str(metrics.get("containment_violations"))),
            ("empty sets (broken bounds)", str(metrics.get("inconsistencies"))),
            ("error bound e_t, mean (map units)", num(metrics.get("error_bound_mean"), ".3g")),
            ("true error, mean (map units)", num(metrics.get("true_error_mean"), ".3g")),
            ("largest true error / e_t", num(metrics.get("error_used_max"), ".2f")),
        ]
    return rows


#: The options ``bearnav plan`` takes of each stage (to change the others for a whole plan: ``params:``).
PLAN_OPTIONS = {
    "map": ("unknown", "circle_segments"), "rrtstar": ("iterations", "step", "seed"), "decompose": ("cells",),
}  # fmt: skip


@app.command("plan")
@handles_errors
@with_options(
    *(
        functools.partial(params_options, stage, only=names, prefix=f"{stage}: ")
        for stage, names in PLAN_OPTIONS.items()
    )
)
def plan_command(
    source: Path = typer.Argument(
        ..., metavar="MAP", help="Map YAML (bearnav format, or a bare ROS map_server YAML with --goal), or a map.json."
    ),
    out_dir: Optional[Path] = typer.Option(
        None, "-o", "--out", help="Output folder (default plans/<name>/; for a map.json, its folder)."
    ),
    goal: Optional[str] = typer.Option(None, help="Goal X,Y, map units (bare occupancy grids only)."),
    landmark: Optional[List[str]] = typer.Option(
        None, metavar="X,Y", help="Landmark X,Y, map units, repeatable (bare grids only)."
    ),
    start: Optional[List[str]] = typer.Option(
        None, metavar="X,Y", help="Start X,Y, map units, repeatable (bare grids only)."
    ),
    robot_radius: Optional[float] = typer.Option(None, help="Robot radius, map units (bare grids only; 0)."),
    lookahead: Optional[float] = LOOKAHEAD,
    fov: Optional[float] = typer.Option(
        None,
        "--fov",
        help="Check the plan for a camera of this field of view (degrees, (0, 360]): exit 1 where "
        "it sees no usable pair of tags along the field, with the `bearnav tags` command that adds them.",
    ),
    max_range: Optional[float] = CAMERA_RANGE,
    noise_deg: Optional[float] = CAMERA_NOISE,
    bearing_error_deg: Optional[float] = typer.Option(
        None, "--bearing-error-deg", help="Overrides the map's robot.bearing_error_deg (degrees)."
    ),
    compass_error_deg: Optional[float] = typer.Option(
        None, "--compass-error-deg", help="Overrides the map's robot.compass_error_deg (degrees)."
    ),
    slip: Optional[float] = typer.Option(None, "--slip", help="Overrides the map's robot.slip."),
    slip_floor: Optional[float] = typer.Option(
        None, "--slip-floor", help="Overrides the map's robot.slip_floor (map units per step)."
    ),
    force: bool = FORCE,
    quiet: bool = QUIET,
    as_json: bool = JSON,
    **options: Any,
) -> None:
    """Run every stage from the map to the last one, skipping fresh stages.

    Takes the same map options as `bearnav map`; a map.json from `bearnav map` starts at rrtstar.
    The error bounds (--bearing-error-deg ...) go into the plan's robot section, which simulate
    --estimator set and verify read; with --fov the plan is also checked for that camera.

    Examples: bearnav plan maps/kitchen.yaml --seed 3;
    bearnav plan lab.yaml --goal 1,1 --landmark 0,2 --landmark 4,0 (a bare map_server YAML)
    """
    from bearnav_cli import pipeline

    _Quiet.enabled |= quiet
    cells = options["cells"]
    if cells is not None and cells not in CELL_KINDS:  # before any stage runs
        raise _fail(f"--cells: must be one of {', '.join(CELL_KINDS)}, got {cells!r}", EXIT_INVALID)
    map_options = {"--goal": goal, "--landmark": landmark, "--start": start, "--robot-radius": robot_radius,
                   "--lookahead": lookahead,
                   **{_option_name("map", name): options[name] for name in PLAN_OPTIONS["map"]}}  # fmt: skip
    overrides = {stage: {name: options[name] for name in names} for stage, names in PLAN_OPTIONS.items()}
    robot = {key: value for key, value in (("bearing_error_deg", bearing_error_deg), ("compass_error_deg",
             compass_error_deg), ("slip", slip), ("slip_floor", slip_floor)) if value is not None}  # fmt: skip
    map_options.update({"--" + key.replace("_", "-"): value for key, value in robot.items()})
    if fov is None and (max_range is not None or noise_deg is not None):
        given = "--range" if max_range is not None else "--noise-deg"
        raise _fail(f"{given}: only with --fov (the camera it belongs to)", EXIT_INVALID)
    if fov is not None:  # checked before any stage runs
        _check_camera(fov, 1.0 if noise_deg is None else noise_deg, max_range)
    if source.is_dir():
        inside = source / "map.json"
        hint = f"; did you mean {inside}?" if inside.is_file() else " (give a map YAML or a map.json)"
        raise _fail(f"{source}: is a folder{hint}", EXIT_INVALID)
    if _is_map_artifact(source):
        given = [name for name, value in map_options.items() if value not in (None, [])]
        if given:
            raise _fail(f"{given[0]}: {source} is a map.json, built already; give the map YAML to change "
                        "its map options", EXIT_INVALID)  # fmt: skip
        src: Any = source
        target = out_dir or source.parent
    else:
        goal_xy = _pair(goal, "--goal") if goal else None
        src = read_map_source(source, goal_xy, landmark, start, robot_radius, lookahead, robot)
        target = out_dir or Path("plans") / str(src.spec.get("name", source.stem))

    def show(report: pipeline.StageReport) -> None:
        if not as_json and (not _Quiet.enabled or report.stage == pipeline.STAGES[-1].name):
            out.print(_report_line(report), highlight=False, soft_wrap=True)

    with _progress_bar() as progress:
        try:
            reports = pipeline.plan(src, target, overrides, force, _progress_factory(progress), show)
        except InvalidMapError as exc:  # a robot bound only the option gave: name the option
            key = (exc.field or "").removeprefix("robot.")
            if key not in robot:
                raise
            raise _fail(f"--{key.replace('_', '-')}: {exc.reason}", EXIT_INVALID) from None
    plan_words = tuple(_camera_words(fov, max_range)) if fov is not None else ()
    plan_words += tuple(word for key, value in robot.items() for word in (f"--{key.replace('_', '-')}", f"{value:g}"))
    seeing, extra = None, None
    plan = reports[-1].artifact
    if fov is not None and _outcome_failure(plan) is None:  # the camera's check, on a plan that passed the others
        from bearnav_cli import perception

        seeing = perception.perception_coverage(plan, fov, 1.0 if noise_deg is None else noise_deg,
                                                float("inf") if max_range is None else max_range)  # fmt: skip
        extra = {
            "perception": {
                "fov_deg": fov,
                "range": max_range,
                "noise_deg": seeing.noise_deg,
                "fraction_domain": seeing.fraction_domain,
                "fraction_free": seeing.fraction_free,
            }
        }
        if not as_json:
            out.print(f"  perception: {seeing.summary()}", highlight=False, markup=False, soft_wrap=True)
    _finish(reports, as_json, extra, camera=(360.0 if fov is None else fov, max_range), plan_words=plan_words)
    if not as_json and not _Quiet.enabled and (seeing is None or seeing.fraction_domain >= 1.0):
        out.print(f"  {plan_guarantee(plan, reports[-1].path, fov)}", highlight=False, markup=False, soft_wrap=True)
    if seeing is not None and seeing.fraction_domain < 1.0:
        from bearnav_cli.datatypes import percent

        raise _fail(f"a {fov:g}° camera looking along the field sees no usable pair of tags from "
                    f"{percent(1.0 - seeing.fraction_domain)} of D: add tags there; "
                    + tags_step(reports[-1].path, fov, max_range, plan_words), EXIT_OUTCOME)  # fmt: skip


def plan_guarantee(plan: Any, path: Path, fov: Optional[float] = None) -> str:
    """The sentence ``plan`` ends with: what the synthesis certified, for which robot, and what proves it.

    Parameters
    ----------
    plan : Plan
        The plan just made (every check of ``plan`` passed).
    path : Path
        Its ``plan.npz``, for the ``bearnav verify`` command the sentence names.
    fov : float, optional
        The camera ``plan --fov`` checked, if any.
    """
    from bearnav_cli import composition
    from bearnav_cli.datatypes import percent

    check = f"`{_command_text('bearnav', 'verify', path)}` proves it from the file alone"
    camera = (f"a {fov:g}° camera sees a usable pair of tags along the field everywhere in that area (measured on a "
              "grid)" if fov is not None else "the camera is not checked (add --fov)")  # fmt: skip
    if not plan.cells.is_funnel:
        return f"guarantee: {composition.PAPER_CLAIM}; {camera}"
    by_area = composition.tolerance_by_area(plan.cells, plan.usable_tolerance)
    robot = composition.robot_words(plan.map)
    where = f"the certified area ({percent(plan.cells.free_coverage)} of the free space)"
    known = f"{plan.plan_tolerance:.3g} map units (median {by_area['median']:.3g} by area)"
    return (f"guarantee (by construction): {robot} that starts in {where} and knows its position to within "
            f"{known} reaches the goal without touching an obstacle or a wall; {check}; {camera}")  # fmt: skip


#: ``decompose --cells`` (and ``plan --cells``) choices.
CELL_KINDS = ("funnel", "funnel-local", "paper")


def _is_map_artifact(path: Path) -> bool:
    """A ``map.json`` written by the map stage (told by its suffix: map YAMLs end in .yaml or .yml)."""
    return path.suffix.lower() == ".json"


@app.command("inspect")
@handles_errors
def inspect_command(
    artifact: Path = typer.Argument(..., metavar="ARTIFACT", help="Any bearnav artifact (map.json, *.npz)."),
    cells: bool = typer.Option(
        False, "--cells", help="Also print a table of the cells (one row each, with units); with --json, its rows."
    ),
    cell: Optional[int] = typer.Option(
        None, "--cell", metavar="N", help="Print one cell of cells.npz or plan.npz: rows, vertices, status, tolerance."
    ),
    quiet: bool = QUIET,
    as_json: bool = JSON,
) -> None:
    """Check an artifact and print a short summary of its manifest (per-cell detail with --cells).

    Examples: bearnav inspect plans/kitchen/plan.npz;
    bearnav inspect plans/kitchen/plan.npz --cell 12
    """
    from bearnav_cli import pipeline

    _Quiet.enabled |= quiet
    loaded = pipeline.load(artifact)
    manifest = loaded.manifest
    if cell is not None:
        _inspect_cell(artifact, loaded.artifact, cell, as_json)
        return
    table = _cell_table(loaded.artifact, manifest.get("stats") or {}) if cells else None
    if as_json:
        units = {key: unit.replace("u", "map unit") if unit else None for key, _, unit in table[0]} if table else None
        _print_json(manifest if table is None else {"units": units, "cells": table[1]})
        return
    stage = f"stage {manifest['stage']} v{manifest['stage_version']}"
    out.print(f"[bold]{artifact}[/bold]  {manifest['schema']}  ({stage})")
    # soft_wrap: a line as long as it is (a terminal folds it; rich would cut the JSON mid-token at 80 columns)
    out.print(f"summary   {manifest.get('summary', '')}", highlight=False, markup=False, soft_wrap=True)
    out.print(f"params    {json.dumps(manifest.get('params', {}), sort_keys=True)}", highlight=False, markup=False,
              soft_wrap=True)  # fmt: skip
    inp = manifest.get("input", {})
    out.print(f"input     {inp.get('path')}  sha256 {str(inp.get('content_sha256'))[:16]}…", highlight=False)
    out.print(f"content   sha256 {manifest['content_sha256'][:16]}…  key {manifest['key'][:16]}…", highlight=False)
    stats = manifest.get("stats") or {}
    if stats:
        out.print(f"stats     {json.dumps(_short_stats(stats), sort_keys=True)}", highlight=False, markup=False,
                  soft_wrap=True)  # fmt: skip
    software = ", ".join(f"{k} {v}" for k, v in manifest.get("software", {}).items())
    out.print(f"software  {software}  elapsed {manifest.get('elapsed_s', 0):.3f} s", highlight=False, soft_wrap=True)
    per_cell = sorted(key for key, value in stats.items() if isinstance(value, list) and value)
    if cells:
        from bearnav_cli.datatypes import cell_list

        if table is not None:
            _print_cell_table(*table)
        shown = {_STATS_KEY.get(key, key) for key, _, _ in table[0]} if table is not None else set()
        lists = {key: value for key, value in stats.items() if isinstance(value, list) and value and key not in shown}
        for key, value in sorted(lists.items()):  # lists of cells (or of rounds), not a column each
            out.print(f"{key}: {cell_list(value, 40)}", highlight=False, markup=False, soft_wrap=True)
    elif per_cell:
        out.print(f"(--cells adds a table of the cells and the lists {', '.join(per_cell)}; --cell N shows one cell)",
                  highlight=False, markup=False, soft_wrap=True)  # fmt: skip


#: The per-cell lists of a plan's statistics that ``inspect --cells`` shows as columns: (key, heading, unit).
_PLAN_STATS_COLUMNS = (("lp_solves", "LP", ""), ("c_tilde_h", "c̃_h", "1/(s·u)"), ("c_tilde_v", "c̃_v", "1/(s·u)"),
                       ("c_h_over_s_max", "c_h/s_max", "1/(s·u)"))  # fmt: skip
#: Where a column's numbers come from in the statistics, when not its key (``attempts``: the LP solves of a cell).
_STATS_KEY = {"lp_solves": "attempts"}


def _cell_table(artifact: Any, stats: dict) -> "tuple[list[tuple[str, str, str]], list[dict]] | None":
    """``inspect --cells``: the columns as (key, heading, unit) and one row per cell, or None without cells.

    The rows hold numbers keyed by column (None where there is none: the goal cell's exit inset, a
    cell without a tolerance), so that ``--json`` prints them as they are and the table formats them.
    Lengths are in map units (``u``).
    """
    import math

    import numpy as np

    from bearnav_cli.datatypes import CellFlag, Cells, CellStatus, Plan

    plan = artifact if isinstance(artifact, Plan) else None
    cells = plan.cells if plan is not None else artifact
    if not isinstance(cells, Cells):
        return None

    def number(value: Any) -> Any:
        value = float(value)
        return None if math.isnan(value) else value

    columns = [("cell", "cell", ""), ("rank", "rank", "u"), ("vertices", "vertices", ""),
               ("barrier_rows", "barriers", ""), ("exit_inset", "exit inset", "u"),
               ("landmarks", "landmarks", "")]  # fmt: skip
    if plan is not None:
        columns[1:1] = [("status", "status", ""), ("delta_c", "δ_c", "u"), ("tau_c", "τ_c", "u")]
        columns += [c for c in _PLAN_STATS_COLUMNS if len(stats.get(_STATS_KEY.get(c[0], c[0])) or []) == cells.n_cells]
    columns.append(("flags", "flags", ""))
    barrier_rows = np.diff(cells.cbf_offsets)
    rows = []
    for c in range(cells.n_cells):
        row: dict[str, Any] = {"cell": c, "rank": number(cells.cell_rank[c]), "vertices": len(cells.vertices(c)),
                               "barrier_rows": int(barrier_rows[c]), "exit_inset": number(cells.exit_inset[c]),
                               "landmarks": int(np.count_nonzero(cells.cell_landmarks[c])),
                               "flags": ",".join(f.name.lower() for f in CellFlag
                                                 if f and int(cells.cell_flags[c]) & f)}  # fmt: skip
        if plan is not None:
            row.update(status=CellStatus(int(plan.status[c])).name.lower(), delta_c=number(plan.tolerance[c]),
                       tau_c=number(plan.usable_tolerance[c]))  # fmt: skip
            for key, _, _ in columns:
                if key in dict((k, h) for k, h, _ in _PLAN_STATS_COLUMNS):
                    row[key] = stats[_STATS_KEY.get(key, key)][c]
        rows.append({key: row[key] for key, _, _ in columns})
    return columns, rows


def _print_cell_table(columns: "list[tuple[str, str, str]]", rows: list[dict]) -> None:
    """The rows of :func:`_cell_table` as plain aligned text (as wide as it needs: never wrapped or cut),
    the units under the headings, numbers to 4 digits, "-" where there is none."""

    def text(value: Any) -> str:
        return "-" if value is None else f"{value:.4g}" if isinstance(value, float) else str(value)

    cells = [[text(row[key]) for key, _, _ in columns] for row in rows]
    widths = [max([len(heading), len(unit) + 2, *(len(line[k]) for line in cells)])
              for k, (_, heading, unit) in enumerate(columns)]  # fmt: skip
    left = {"status", "flags"}

    def line(items: list[str]) -> str:
        return "  ".join(item.ljust(w) if key in left else item.rjust(w)
                         for item, w, (key, _, _) in zip(items, widths, columns, strict=True)).rstrip()  # fmt: skip

    for items in ([h for _, h, _ in columns], [f"[{u}]" if u else "" for _, _, u in columns], *cells):
        out.print(line(items), highlight=False, markup=False, soft_wrap=True)
    out.print("u: map units; s: seconds", highlight=False, markup=False, soft_wrap=True)


def _short_stats(stats: dict) -> dict:
    """The manifest's statistics for the default ``inspect``: per-cell lists left out (``--cells``
    shows them), lists of cells inside a mapping counted, zero counts dropped, floats to 4 digits."""

    def short(value: Any) -> Any:
        if isinstance(value, float):
            return float(f"{value:.4g}")
        if isinstance(value, list):
            return len(value)
        if isinstance(value, dict):
            return {k: short(v) for k, v in value.items() if v not in (0, [], None, {})}
        return value

    return {key: short(value) for key, value in stats.items()
            if not isinstance(value, list) and value not in ({}, None)}  # fmt: skip


def _inspect_cell(path: Path, artifact: Any, c: int, as_json: bool) -> None:
    """``inspect --cell N``: one cell of a cells.npz or plan.npz, everything a user needs to find it."""
    import numpy as np

    from bearnav_cli.datatypes import CellFlag, Cells, CellStatus, Plan

    plan = artifact if isinstance(artifact, Plan) else None
    cells = plan.cells if plan is not None else artifact
    if not isinstance(cells, Cells):
        raise _fail(f"--cell: {path} holds no cells (give cells.npz or plan.npz)", EXIT_INVALID)
    if not 0 <= c < cells.n_cells:
        raise _fail(f"--cell: {path} has cells 0 to {cells.n_cells - 1}, got {c}", EXIT_INVALID)
    A, b = cells.rows(c)
    vertices = cells.vertices(c)
    node = int(cells.cell_node[c])
    parent = int(cells.parent[node])
    ids = [str(cells.map.landmark_ids[k]) for k in np.flatnonzero(cells.cell_landmarks[c])]
    flags = [flag.name.lower() for flag in CellFlag if flag and int(cells.cell_flags[c]) & flag]
    info: dict[str, Any] = {
        "cell": c, "node": node, "node_position": [float(v) for v in cells.nodes[node]],
        "parent_cell": parent, "rank": float(cells.cell_rank[c]), "exit_row": int(cells.cell_exit_row[c]),
        "vertices": [[float(v) for v in p] for p in vertices],
        "rows": [{"a": [float(v) for v in a], "b": float(bb)} for a, bb in zip(A, b, strict=True)],
        "landmarks": ids, "fixed_landmark": str(cells.map.landmark_ids[int(cells.fixed_landmark[c])]),
        "flags": flags, "added_by_densification": bool(cells.node_added[node]),
    }  # fmt: skip
    if plan is not None:
        status = CellStatus(int(plan.status[c]))
        tol = float(plan.tolerance[c])
        usable, inset = float(plan.usable_tolerance[c]), float(cells.exit_inset[c])
        info.update(status=status.name.lower(), status_code=int(status), tolerance=None if np.isnan(tol) else tol,
                    usable_tolerance=None if np.isnan(usable) else usable,
                    exit_inset=None if np.isnan(inset) else inset,
                    margin_h=float(plan.margin_h[c]), margin_v=float(plan.margin_v[c]))  # fmt: skip
    if as_json:
        _print_json(info)
        return

    def point(p: Any) -> str:
        return f"({p[0]:.4g}, {p[1]:.4g})"

    lines = [f"cell {c} of {path} ({cells.n_cells} cells)"]
    lines.append(f"node      {node} at {point(cells.nodes[node])}, "
                 + (f"parent cell {parent}" if parent >= 0 else "the goal cell")
                 + (" (added by densification)" if info["added_by_densification"] else "")
                 + f"; rank {info['rank']:.4g} (cost-to-go, map units)")  # fmt: skip
    if plan is not None:
        tol_text = "none" if info["tolerance"] is None else f"{info['tolerance']:.4g} map units"
        lines.append(f"status    {info['status_code']} {info['status']}; δ_c (position error tolerated) {tol_text}")
        if info["usable_tolerance"] is not None:
            inset = info["exit_inset"]
            inset_text = "no exit (goal cell)" if inset is None else f"exit inset δ_e,c {inset:.4g}"
            lines.append(f"tolerance τ_c = min(δ_c, δ_e,c/2) = {info['usable_tolerance']:.4g} map units, the error "
                         f"under which the robot may move here; {inset_text}")  # fmt: skip
    lines.append(f"vertices  {len(vertices)}, CCW: " + " ".join(point(p) for p in vertices))
    lines.append(f"rows      {len(A)}, the cell is {{x : a·x ≤ b}}; the exit row is {info['exit_row']}"
                 + (" (none: goal cell)" if info["exit_row"] < 0 else ""))  # fmt: skip
    for k, (a, bb) in enumerate(zip(A, b, strict=True)):
        mark = "  <- exit" if k == info["exit_row"] else ""
        lines.append(f"  {k:>3}  a = ({a[0]: .4f}, {a[1]: .4f})  b = {bb: .5g}{mark}")
    lines.append(f"landmarks {', '.join(ids) or 'none'} (fixed: {info['fixed_landmark']})")
    lines.append(f"flags     {', '.join(flags) or 'none'}")
    for line in lines:
        out.print(line, highlight=False, markup=False, soft_wrap=True)


@app.command("tags")
@handles_errors
def tags_command(
    plan_npz: Path = typer.Argument(..., metavar="PLAN_NPZ", help="plan.npz from `bearnav plan`."),
    fov: float = typer.Option(60.0, "--fov", help="Camera field of view, degrees, in (0, 360]."),
    max_range: Optional[float] = typer.Option(None, "--range", help="Camera range, map units (default: unlimited)."),
    noise_deg: float = typer.Option(1.0, "--noise-deg", help="Bearing noise (1σ, degrees) of the predicted fix error."),
    error_target: Optional[float] = typer.Option(
        None, "--error-target", help="Also require a predicted fix error (3σ) of at most this, map units."
    ),
    max_tags: Optional[int] = typer.Option(
        None, "--max-tags", help="At most this many new tags (exit 1 if the rule then still fails somewhere)."
    ),
    map_yaml: Optional[Path] = typer.Option(
        None, "--map", help="The map YAML to add the tags to (default: the plan's map, written as polygons)."
    ),
    out_path: Optional[Path] = typer.Option(
        None,
        "-o",
        "--out",
        help="Map YAML with the new tags, a new file (default: NAME_tags.yaml next to the --map "
        "YAML, else map_tags.yaml next to the plan).",
    ),
    figure: Optional[Path] = typer.Option(
        None, "--figure", help="Where to glue them, a figure (default: the map YAML's name with .png)."
    ),
    force: bool = typer.Option(False, "--force", help="Replace an -o file that is not a map bearnav tags wrote."),
    target: str = typer.Option(
        "fix",
        "--for",
        help="fix: a usable pair in view where the robot drives; live: every cell live, so that a "
        "look all around always lets the robot move on, at --bearing-error-deg and --slip (one of fix, live).",
    ),
    bearing_error_deg: Optional[float] = typer.Option(
        None,
        "--bearing-error-deg",
        help="With --for live: the bound on every world-frame bearing error (degrees, "
        "in (0, 45)); None means the map's robot: bearing_error_deg plus compass_error_deg.",
    ),
    slip: Optional[float] = typer.Option(
        None,
        "--slip",
        help="With --for live: the odometry error bound, a fraction of each step (in [0, 1)); None "
        "means the map's robot: slip.",
    ),
    live_resolution: Optional[float] = typer.Option(
        None,
        "--live-resolution",
        help="With --for live: grid spacing of the liveness measurement (map units, > 0); "
        "None means about 25 points in the median cell, at most 0.01·D.",
    ),
    quiet: bool = QUIET,
    as_json: bool = JSON,
) -> None:
    """Propose tag positions so that a camera looking along the fields sees a usable pair in the certified area.

    With --for live, so that every cell is live instead: a look all around brings the set
    estimator's error bound below what the cell tolerates (the fix rule is the default).

    The tags go on obstacle and wall boundaries, facing the free side, a tag's width apart; the
    existing tags stay. Writes the map with the new tags and a figure of where to glue them; the
    cells do not depend on the tags, so re-planning with the new map only changes the gains.

    Example: bearnav tags plans/kitchen/plan.npz --fov 60 --noise-deg 1 -o kitchen_tags.yaml
    """
    import yaml

    from bearnav_cli import artifacts, composition, pipeline, tags
    from bearnav_cli.stages import map_

    _Quiet.enabled |= quiet
    if out_path is None:  # a new file: the map given stays as it is
        out_path = _tags_output(plan_npz, map_yaml)
    artifacts.check_output_file(out_path, (".yaml", ".yml"), "-o/--out", inputs=tuple(p for p in (plan_npz, map_yaml)
                                                                                        if p is not None))  # fmt: skip
    artifacts.check_overwrite(out_path, "tags", force=force)
    figure = figure or out_path.with_suffix(".png")
    artifacts.check_output_file(figure, FIGURE_SUFFIXES, "--figure")
    artifacts.check_distinct({"-o/--out": out_path, "--figure": figure})
    options = {**CAMERA_OPTIONS, "error_target": "--error-target", "max_tags": "--max-tags", "target": "--for",
               "eta_deg": "--bearing-error-deg", "kappa": "--slip", "resolution": "--live-resolution"}  # fmt: skip
    if target != "live" and (bearing_error_deg is not None or slip is not None or live_resolution is not None):
        raise _fail("--bearing-error-deg, --slip and --live-resolution are for --for live", EXIT_INVALID)
    try:
        params = tags.Params(fov_deg=fov, max_range=float("inf") if max_range is None else max_range,
                             noise_deg=noise_deg, error_target=error_target, max_tags=max_tags, target=target,
                             bearing_error_deg=bearing_error_deg, slip=slip, resolution=live_resolution)  # fmt: skip
    except InvalidParamsError as exc:  # name the option the user typed
        raise _fail(f"{options.get(exc.field, exc.field)}: {exc.reason}", EXIT_INVALID) from None
    pipeline.ACTIVITY.stage = "tags"
    plan = pipeline.load(plan_npz, "plan").artifact
    spec = map_.spec_of(plan.map)
    original = None  # the YAML text the user wrote, kept as it is in the new map
    grid = None  # the occupancy grid the new map names, when it keeps the map's own text
    if map_yaml is not None:
        source = read_map_source(map_yaml)
        problem = composition.map_frame_problem(plan.map, map_.run(source))
        if problem:
            raise _fail(f"{map_yaml}: {problem}: not the plan's map", EXIT_INVALID)
        grid_elsewhere = "occupancy" in source.spec and map_yaml.resolve().parent != out_path.resolve().parent
        spec = spec if grid_elsewhere else source.spec  # an occupancy image path is relative to its YAML
        grid = None if grid_elsewhere else source.grid
        bare_grid = source.grid is not None and "occupancy" not in source.spec  # its spec comes from options
        if not grid_elsewhere and not bare_grid:
            original = _read_bytes(map_yaml).decode("utf-8", errors="replace")
    try:
        proposal = tags.propose(plan, params)
    except InvalidParamsError as exc:  # liveness's own checks: η, the slip, a paper plan
        where = "" if exc.field == "plan" else f"{options.get(exc.field, exc.field)}: "
        raise _fail(f"{plan_npz}: {where}{exc.reason}", EXIT_INVALID) from None
    name = tags.tagged_name(str(spec.get("name", plan.map.name)))  # another name: re-planning it makes its own folder
    new_spec = tags.map_spec_with_tags(spec, proposal)
    new_spec = {"name": name, **{key: value for key, value in new_spec.items() if key != "name"}}
    map_.run(map_.MapSource(spec=new_spec, file=str(out_path), sha256="", grid=grid))  # the map stage accepts it
    header = (f"{artifacts.TAGS_MARKER} {proposal.count} new tags for a {fov:g}° camera, from {plan_npz} "
              f"(and {map_yaml or 'its map'}); plan it with `bearnav plan {out_path}`")  # fmt: skip
    text = tags.map_text_with_tags(original, proposal, name, header) if original is not None else None
    if text is not None:
        try:
            kept = yaml.safe_load(text)
        except yaml.YAMLError:
            kept = None
        meant = dict(yaml.safe_load(original), name=name, landmarks=new_spec["landmarks"])
        if kept != meant:
            text = None  # a layout the text edit got wrong: the map is written afresh (its comments are lost)
    if text is None:
        if original is not None and not _Quiet.enabled:
            err.print(f"[yellow]warning:[/yellow] {out_path}: bearnav cannot extend the landmarks of {map_yaml} "
                      "where they are; the map is written afresh, without its comments", highlight=False,
                      soft_wrap=True)  # fmt: skip
        text = header + "\n" + yaml.safe_dump(new_spec, sort_keys=False, default_flow_style=None)
    artifacts.atomic_write(out_path, lambda f: f.write(text.encode()))
    plot = _plotting()  # matplotlib is slow to import: only here

    fig = plot.tags_figure(proposal, plan.map)  # its title states the camera, the noise and the coverage
    with artifacts.atomic_output(figure) as tmp:
        plot.save_figure(fig, str(tmp))
    if as_json:
        _print_json({
            "map": str(out_path), "figure": str(figure), "new_tags": proposal.count,
            "lower_bound": proposal.lower_bound, "ids": list(proposal.ids),
            "positions": [[float(v) for v in p] for p in proposal.positions],
            "target_reached": proposal.target_reached,
            "domain_before": proposal.before.fraction_domain, "domain_after": proposal.after.fraction_domain,
            "free_before": proposal.before.fraction_free, "free_after": proposal.after.fraction_free,
            "for": target,
            **({"live_before": proposal.live_before.live_fraction, "live_after": proposal.live_after.live_fraction,
                "eta_deg": math.degrees(proposal.live_after.grid.eta),
                "eta_star_deg_before": math.degrees(proposal.live_before.eta_star),
                "eta_star_deg_after": math.degrees(proposal.live_after.eta_star)}
               if proposal.live_after is not None else {}),
        })  # fmt: skip
    else:
        out.print(f"tags      {out_path}  {proposal.summary()}", highlight=False, soft_wrap=True)
        if not _Quiet.enabled:
            out.print(f"wrote {out_path} and {figure}; re-plan with `{_command_text('bearnav', 'plan', out_path)}`",
                      highlight=False, soft_wrap=True)  # fmt: skip
    if not proposal.target_reached and proposal.live_after is not None:
        from bearnav_cli.datatypes import percent

        live = proposal.live_after
        why = (f"--max-tags {max_tags} allowed too few" if max_tags is not None and proposal.count >= max_tags else
               "no tag makes the grey points live: their cells tolerate less than any look gives (a smaller "
               "--bearing-error-deg, the heading from the bearings, or a plan with larger tolerances)")  # fmt: skip
        raise _fail(f"{len(live.live) - live.n_live} cells are still not live ({percent(1.0 - live.live_fraction)} of "
                    f"the certified area): {why}; {out_path} has the tags placed", EXIT_OUTCOME)  # fmt: skip
    if not proposal.target_reached:
        from bearnav_cli.datatypes import percent

        short = 1.0 - proposal.after.fraction_domain
        if max_tags is not None and proposal.count >= max_tags:
            again = _command_text("bearnav", "tags", plan_npz, *_camera_words(fov, max_range),
                                  *(["--noise-deg", f"{noise_deg:g}"] if noise_deg != 1.0 else []),
                                  *(["--error-target", f"{error_target:g}"] if error_target is not None else []),
                                  *(["--map", map_yaml] if map_yaml is not None else []), "-o", out_path)  # fmt: skip
            fix = (f"--max-tags {max_tags} allowed too few (at least {proposal.lower_bound} are needed); "
                   f"`{again}` places as many as the rule needs")  # fmt: skip
        else:
            fix = ("the rest sees no wall or obstacle a tag could go on in view: a wider --fov, a longer "
                   "--range or a lower --error-target")  # fmt: skip
        raise _fail(f"two usable tags are still not in view on {percent(short)} of the certified area: {fix}; "
                    f"{out_path} has the tags placed",
                    EXIT_OUTCOME)  # fmt: skip


def _figure_default(artifact: Path) -> Path:
    """Where ``bearnav plot`` draws an artifact without ``-o``: next to it, its name with .png (plan.npz: plan.png)."""
    return artifact.with_suffix(".png")


@app.command("plot")
@handles_errors
def plot_command(
    artifact: Path = typer.Argument(..., metavar="ARTIFACT", help="Any bearnav artifact (map.json, *.npz)."),
    out_path: Optional[Path] = typer.Option(
        None, "-o", "--out", help="Figure file (.png, .pdf, .svg; default: the artifact's name with .png, next to it)."
    ),
    also: Optional[List[Path]] = typer.Option(None, "--also", help="Tree artifact drawn faintly underneath."),
    title: Optional[str] = typer.Option(None, help="Figure title."),
    color_by: Optional[str] = typer.Option(
        None,
        "--color-by",
        help="Cell fill: rank, tolerance (the position error the cell tolerates), status, or live "
        "(red where a cell is not live) (default: rank; status for paper plans).",
    ),
    barriers: bool = typer.Option(False, "--barriers", help="Also draw every barrier line h = 0."),
    labels: Optional[bool] = typer.Option(
        None, "--labels/--no-labels", help="Landmark ids: all, or none (default: those that do not collide)."
    ),
    cell_numbers: bool = typer.Option(False, "--cell-numbers", help="Write each cell's index where it is active."),
    fov: Optional[float] = typer.Option(
        None, "--fov", help="Mark where a camera of this field of view (degrees, (0, 360]) fails along a plan's field."
    ),
    noise_deg: Optional[float] = CAMERA_NOISE,
    max_range: Optional[float] = CAMERA_RANGE,
    live_fov: Optional[float] = typer.Option(
        None, "--live-fov", help="With --color-by live: the camera's field of view, degrees, (0, 360] (default 60)."
    ),
    bearing_error_deg: Optional[float] = typer.Option(
        None,
        "--bearing-error-deg",
        help="With --color-by live: the bearing error bound η, degrees, (0, 45) "
        "(default: the map's robot.bearing_error_deg plus compass_error_deg).",
    ),  # fmt: skip
    quiet: bool = QUIET,
) -> None:
    """Draw an artifact: map, tree, collision samples, cells, the plan's field, simulated runs.

    Example: bearnav plot plans/kitchen/plan.npz -o plan.png --color-by tolerance --cell-numbers
    """
    from bearnav_cli import artifacts, pipeline
    from bearnav_cli.datatypes import Cells, Plan

    _Quiet.enabled |= quiet
    out_path = out_path or _figure_default(artifact)
    artifacts.check_output_file(out_path, FIGURE_SUFFIXES, "-o/--out", inputs=(artifact, *(also or [])))
    if fov is None and (noise_deg is not None or max_range is not None):
        given = "--noise-deg" if noise_deg is not None else "--range"
        raise _fail(f"{given}: only with --fov (the camera it belongs to)", EXIT_INVALID)
    noise_deg = 1.0 if noise_deg is None else noise_deg
    if fov is not None:
        _check_camera(fov, noise_deg, max_range)
    # matplotlib is slow to import: only here
    from bearnav_cli import composition

    plot = _plotting()

    if color_by is not None and color_by not in plot.COLOR_BY:
        raise _fail(f"--color-by: must be one of {', '.join(plot.COLOR_BY)}, got {color_by!r}", EXIT_INVALID)

    pipeline.ACTIVITY.stage = str(out_path)
    loaded = pipeline.load(artifact)
    background = [pipeline.load(p, ("tree", "simplified")).artifact for p in also or []]
    shown = loaded.artifact
    seeing = None
    if fov is not None:
        if not isinstance(shown, Plan):
            schema = loaded.manifest.get("schema", "not a plan")
            raise _fail(f"--fov: {artifact} is {schema}, not a plan (bearnav.plan/2): the camera looks along "
                        "the plan's field", EXIT_INVALID)  # fmt: skip
        from bearnav_cli import perception

        seeing = perception.perception_coverage(shown, fov, noise_deg, float("inf") if max_range is None else max_range)
    live = None
    if color_by == "live" or live_fov is not None or bearing_error_deg is not None:
        if color_by != "live":
            given = "--live-fov" if live_fov is not None else "--bearing-error-deg"
            raise _fail(f"{given}: only with --color-by live (the liveness it measures)", EXIT_INVALID)
        if not isinstance(shown, Plan) or not shown.cells.is_funnel:
            schema = loaded.manifest.get("schema", "not a plan")
            raise _fail(f"--color-by live: {artifact} is {schema}, not a funnel plan: liveness needs its usable "
                        "tolerances τ_c", EXIT_INVALID)  # fmt: skip
        from bearnav_cli import liveness

        names = {"eta_deg": "--bearing-error-deg", "fov_deg": "--live-fov"}
        try:
            live = liveness.measure(shown, bearing_error_deg, 60.0 if live_fov is None else live_fov)
        except InvalidParamsError as exc:
            raise _fail(f"{names.get(exc.field or '', exc.field)}: {exc.reason}", EXIT_INVALID) from None
    cells = shown.cells if isinstance(shown, Plan) else shown if isinstance(shown, Cells) else None
    # plan/3 covers F (ALGORITHMS §12.7): hatch what of F no cell covers
    coverage = composition.coverage_regions(cells, margin=0.0) if cells is not None and cells.is_funnel else None
    fig = plot.figure_for(shown, background=background, title=title, color_by=color_by, barriers=barriers,
                          labels=labels, cell_numbers=cell_numbers, coverage=coverage, perception=seeing,
                          liveness=live, params=loaded.manifest.get("params"))  # fmt: skip
    with artifacts.atomic_output(out_path) as tmp:
        plot.save_figure(fig, str(tmp))
    if seeing is not None:
        out.print(f"perception: {seeing.summary()}", highlight=False, markup=False, soft_wrap=True)
    if live is not None:
        out.print(live.summary(), highlight=False, markup=False, soft_wrap=True)
    out.print(f"wrote {out_path}", highlight=False)


# --------------------------------------------------------------------------- bearnav sweep (issue 25)


def _sweep_progress() -> "Progress":
    """The sweep's bar: jobs done, failed and left, and the time left (rich's estimate from the pace so far)."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    return Progress(
        TextColumn("{task.description:<10}"),
        BarColumn(),
        _count_column()(),
        TextColumn("{task.fields[failed]} failed, {task.fields[left]} left"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=err.console,
        transient=True,
        disable=_Quiet.enabled or not err.is_terminal,
    )


@app.command("sweep")
@handles_errors
def sweep_command(
    sweep_yaml: Path = typer.Argument(..., metavar="SWEEP", help="Sweep file (docs/sweeps.md)."),
    out_dir: Optional[Path] = typer.Option(None, "-o", "--out", help="The store folder (default sweeps/NAME/)."),
    jobs: Optional[int] = typer.Option(None, "--jobs", "-j", help="Local worker processes (default: every CPU)."),
    scheduler: Optional[str] = typer.Option(
        None,
        "--scheduler",
        metavar="ADDRESS",
        help="Run the jobs on this Dask scheduler (tcp://HOST:PORT; needs bearnav[dask]), not in local processes.",
    ),
    report: bool = typer.Option(False, "--report", help="Only redraw the table and figure from the store."),
    figure: Optional[Path] = typer.Option(None, "--figure", help="The figure (default STORE/success.png)."),
    quiet: bool = QUIET,
    as_json: bool = JSON,
) -> None:
    """Run a grid of plans and closed-loop runs (maps × seeds × fov × noise × ...), each job once, into a store.

    Each job's result is a small file of the store: an interrupted or repeated sweep runs only what is
    missing. Writes results.csv (and .parquet with pyarrow), results.md and a figure of success against
    noise. Exit 1 when a job failed (its error is in the table).

    Examples: bearnav sweep repro/robustness.yaml --jobs 2;
    bearnav sweep small.yaml --scheduler tcp://10.0.0.5:8786;
    bearnav sweep small.yaml --report
    """
    from bearnav_cli import artifacts, sweep

    _Quiet.enabled |= quiet
    if jobs is not None and jobs < 1:
        raise _fail(f"--jobs: must be at least 1, got {jobs}", EXIT_INVALID)
    if jobs is not None and scheduler is not None:
        raise _fail("--jobs: not with --scheduler (the cluster's workers run the jobs)", EXIT_INVALID)
    if figure is not None:
        artifacts.check_output_file(figure, FIGURE_SUFFIXES, "--figure", inputs=(sweep_yaml,))
    spec, _ = _read_yaml(sweep_yaml)
    grid = sweep.read_sweep(spec, str(sweep_yaml))
    sources = [read_map_source(path) for path in sweep.expand_maps(grid)]
    job_list, left_out = sweep.expand(grid, sources)
    store = out_dir or Path("sweeps") / grid.name
    artifacts.check_output_folder(store)
    figure = figure or store / "success.png"
    if report and not store.is_dir():
        raise _fail(f"--report: {store} holds no sweep yet (run `bearnav sweep {sweep_yaml}` first)", EXIT_INVALID)
    outcome = None
    if not report:
        close = None
        if scheduler is not None:
            executor, close = sweep.connect_scheduler(scheduler)
        else:
            executor = sweep.local_executor(jobs or os.cpu_count() or 1)
        interrupted = True
        try:
            with _sweep_progress() as progress:
                plans = progress.add_task("plans", total=None, failed=0, left="")
                task = progress.add_task("jobs", total=len(job_list), failed=0, left=len(job_list))

                def on_job(done: int, failed: int, total: int) -> None:
                    progress.update(task, completed=done, failed=failed, left=total - done)

                def on_plans(done: int, total: int) -> None:
                    progress.update(plans, completed=done, total=total, left=total - done)

                outcome = sweep.run(job_list, store, executor, on_job, on_plans)
            interrupted = False
        except KeyboardInterrupt as exc:
            done = len([r for r in sweep.records(store, job_list).values() if r.get("status") == "done"])
            word = "terminated" if isinstance(exc, Terminated) else "interrupted"
            err.print(f"{word}; {done} of {len(job_list)} jobs are in {store}, the next `bearnav sweep` runs the "
                      "others", highlight=False, soft_wrap=True, markup=False)  # fmt: skip
            raise typer.Exit(EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED) from None
        finally:
            if close is not None:
                close()
            else:
                sweep.stop_local(executor, interrupted)
    found = sweep.records(store, job_list)
    rows = sweep.table(job_list, found)
    written = sweep.write_results(store, rows)
    panels = sweep.success_curves(rows)
    runs = sorted({r["runs"] for r in rows if r["runs"] is not None})
    title = f"{grid.name}: success against bearing noise" + (f" ({'/'.join(map(str, runs))} runs each)" if runs else "")
    markdown = store / "results.md"
    artifacts.atomic_write(markdown, lambda f: f.write(sweep.markdown(panels, title).encode()))
    plot = _plotting()
    with artifacts.atomic_output(figure) as tmp:
        plot.save_figure(plot.sweep_plot(panels, title), str(tmp))
    failed = [r for r in rows if r["status"] != "done"]
    summary = {"store": str(store), "jobs": len(job_list), "in_store": len(rows), "failed": len(failed),
               "left_out": left_out, "files": [str(p) for p in (*written, markdown, figure)]}  # fmt: skip
    if outcome is not None:
        summary.update(ran=outcome.ran, from_store=outcome.stored, plans_made=outcome.plans_made,
                       elapsed_s=round(outcome.elapsed_s, 3))  # fmt: skip
    if as_json:
        out.print_json(json.dumps(summary))
    else:
        if outcome is not None:
            out.print(f"sweep      {store}: {len(job_list)} jobs, {outcome.ran} ran, {outcome.stored} from the store, "
                      f"{len(failed)} failed ({outcome.plans_made} plans made, {outcome.elapsed_s:.1f} s)",
                      highlight=False, soft_wrap=True)  # fmt: skip
        else:
            out.print(f"report     {store}: {len(rows)} of {len(job_list)} jobs in the store, {len(failed)} failed",
                      highlight=False, soft_wrap=True)  # fmt: skip
        if left_out:
            out.print(f"left out {left_out} cells with both noise_deg and noise_bound_deg (simulate takes one)",
                      highlight=False, soft_wrap=True)  # fmt: skip
        for row in failed[:5]:
            out.print(f"failed     {row['map']} fov {row['fov']:g} noise {row['noise_deg']:g}: {row['error']}",
                      highlight=False, markup=False, soft_wrap=True)  # fmt: skip
        out.print("wrote " + ", ".join(summary["files"]), highlight=False, soft_wrap=True)
    if failed:
        raise typer.Exit(EXIT_OUTCOME)


if not _AS_PROGRAM:  # a test or a library imported the app: give SIGINT and SIGTERM back
    for _signum, _handler in _STARTUP_HANDLERS.items():
        signal.signal(_signum, _handler)
