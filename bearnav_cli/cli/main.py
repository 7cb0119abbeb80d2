"""The ``bearnav`` typer app: its plain help, the group's own options (-q, --version) and its commands.

The commands are defined one module each and listed here (:data:`COMMANDS`), in the order ``bearnav
--help`` lists them. A command is made, its module imported, only when it is run, its help shown or
completed (:class:`_Commands`): ``bearnav rrtstar`` imports none of the other commands' modules.
"""

import importlib
import inspect
from collections.abc import Iterator, Mapping
from typing import Any

import typer
import typer.main
from typer.core import TyperCommand, TyperGroup
from typer.models import CommandInfo

from bearnav_cli import __version__
from bearnav_cli.cli.exits import exit_at_once
from bearnav_cli.cli.output import QUIET_HELP, Quiet
from bearnav_cli.cli.startup import AS_PROGRAM

__all__ = ["app", "main"]


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
    that a start reads the ``Params`` sources of the command it runs only. Its usage line writes a
    required argument as its metavar (``MAP``), where typer writes ``{MAP}``.
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
            made = [option for group in groups for option in group()]
            at = next((i for i, param in enumerate(self._params) if param.name == before), len(self._params))
            self._params[at:at] = made
        return self._params

    @params.setter
    def params(self, value: list[Any]) -> None:
        self._params = value

    def collect_usage_pieces(self, ctx: Any) -> list[str]:
        # click's pieces, except that a required argument is its metavar (MAP): typer's writes itself {MAP}
        pieces = [self.options_metavar] if self.options_metavar else []
        for param in self.get_params(ctx):
            named = param.param_type_name == "argument" and param.required and param.metavar is not None
            pieces.extend([param.metavar] if named else param.get_usage_pieces(ctx))
        return pieces

    def format_help(self, ctx: Any, formatter: Any) -> None:
        super(TyperCommand, self).format_help(ctx, formatter)  # click's, not typer's rich one

    def format_help_text(self, ctx: Any, formatter: Any) -> None:
        _format_help_text(self, ctx, formatter)


#: The one command table: each command's module in :mod:`bearnav_cli.cli` and its function, in the order
#: ``bearnav --help`` lists them.
COMMANDS = {
    "map": ("map_", "map_command"),
    "rrtstar": ("stage", "rrtstar_command"),
    "simplify": ("stage", "simplify_command"),
    "decompose": ("stage", "decompose_command"),
    "synthesize": ("stage", "synthesize_command"),
    "verify": ("verify", "verify_command"),
    "simulate": ("simulate", "simulate_command"),
    "plan": ("plan", "plan_command"),
    "inspect": ("inspect_", "inspect_command"),
    "tags": ("tags", "tags_command"),
    "plot": ("plot", "plot_command"),
    "sweep": ("sweep", "sweep_command"),
}


class _Commands(Mapping):
    """The group's commands by name (:data:`COMMANDS`), each a :class:`_Command` made on first use.

    Listing the names imports nothing; the command a start runs (or whose help it prints) is made as
    typer makes a registered one, from its function, so that its module, and no other command's, is
    imported.
    """

    def __init__(self) -> None:
        self._made: dict[str, Any] = {}

    def __iter__(self) -> Iterator[str]:
        return iter(COMMANDS)

    def __len__(self) -> int:
        return len(COMMANDS)

    def __getitem__(self, name: str) -> Any:
        if name not in self._made:
            module, function = COMMANDS[name]
            callback = getattr(importlib.import_module(f"bearnav_cli.cli.{module}"), function)
            self._made[name] = typer.main.get_command_from_info(
                CommandInfo(name=name, cls=_Command, callback=callback),
                pretty_exceptions_short=app.pretty_exceptions_short,
                rich_markup_mode=app.rich_markup_mode,
            )
        return self._made[name]


class _Group(TyperGroup):
    """The ``bearnav`` group, its ``--help`` plain as :class:`_Command`'s, its commands :class:`_Commands`."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.commands = _Commands()

    def list_commands(self, ctx: Any) -> list[str]:
        return list(self.commands)  # the names only: typer's reads each command (items()), making them all

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


class _Program(typer.Typer):
    """The app; run as the ``bearnav`` program, it ends without the interpreter's teardown
    (:func:`~bearnav_cli.cli.exits.exit_at_once`), called from Python (a test, a library) as typer's."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        try:
            return super().__call__(*args, **kwargs)
        except SystemExit as exc:
            if AS_PROGRAM:
                exit_at_once(exc.code)
            raise


app = _Program(
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
    Quiet.enabled = quiet
