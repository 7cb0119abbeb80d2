"""The options the commands share (the map, --force, -q, --json, --lookahead, the camera's) and those made of a
``Params``.

A stage's fields become its command's options here, with help from the field's docstring and the
default of the dataclass (:func:`params_options`); they are made when a command's options are first
read (:func:`with_options`), so that a start reads the ``Params`` sources of the command it runs only.
They are ``typer.core.TyperOption`` objects, the class of typer's own options, made directly: no private
typer function turns them into click options.
"""

import functools
import inspect
from typing import Any, Callable, Optional

import typer
from typer.core import TyperOption

from bearnav_cli.cli.exits import EXIT_INVALID, fail
from bearnav_cli.cli.fields import ParamField, params_fields
from bearnav_cli.cli.output import QUIET_HELP
from bearnav_cli.errors import InvalidParamsError

__all__ = [
    "CAMERA_NOISE",
    "CAMERA_OPTIONS",
    "CAMERA_RANGE",
    "FORCE",
    "JSON",
    "LOOKAHEAD",
    "MAP_ARG",
    "QUIET",
    "check_camera",
    "option_help",
    "params_options",
    "shown_value",
    "with_options",
]


MAP_ARG = typer.Argument(..., metavar="MAP", help="Map YAML (bearnav format, or a ROS map_server YAML).")
FORCE = typer.Option(False, "--force", help="Rerun even if the output is fresh.")
QUIET = typer.Option(False, "--quiet", "-q", help=QUIET_HELP)
JSON = typer.Option(False, "--json", help="Print machine-readable JSON.")
LOOKAHEAD = typer.Option(
    None,
    metavar="λ",
    help="Look-ahead λ, map units (any map; overrides the map's robot.lookahead): plan for the "
    "point λ ahead of a unicycle's axle, obstacles inflated by the radius plus λ (docs/maps.md).",
)


#: The range and noise of the camera a ``--fov`` names (map, plan, plot): one declaration each.
CAMERA_RANGE = typer.Option(None, "--range", help="That camera's range, map units (default: unlimited).")
CAMERA_NOISE = typer.Option(
    None, "--noise-deg", help="Bearing noise (1σ, degrees) of that camera's predicted fix error (default 1)."
)
#: The option of each field a camera check names (``perception.check_params``, ``bearing.check_camera``).
CAMERA_OPTIONS = {
    "fov": "--fov",
    "fov_deg": "--fov",
    "noise_deg": "--noise-deg",
    "range": "--range",
    "max_range": "--range",
}


def check_camera(fov: float, noise_deg: float = 0.0, max_range: Optional[float] = None) -> None:
    """``perception.check_params`` of a command's camera options; an error names the option (one line, exit 3)."""
    from bearnav_cli import perception

    try:
        perception.check_params(fov, noise_deg, float("inf") if max_range is None else max_range)
    except InvalidParamsError as exc:  # name the option the user typed
        raise fail(f"{CAMERA_OPTIONS.get(exc.field or '', exc.field)}: {exc.reason}", EXIT_INVALID) from None


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


def shown_value(value: Any) -> str:
    """A value as the help and the hints write it: a string quoted, a float as ``%g``."""
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
            shown = field.option if field.default else field.off
        else:
            shown = shown_value(field.default)
        notes.append(f"default: {shown}")
    return prefix + text + (f" ({'; '.join(notes)})" if notes else "") + "."


class _ParamOption(TyperOption):
    """A generated option whose help text (:func:`option_help`) is made when something first reads it (the
    help, a completion, the documentation), not on every start: making the help of a stage's options
    compiles and runs a dozen regular expressions (2-3 ms of a ``bearnav rrtstar`` process that shows none)."""

    _make_help: Optional[Callable[[], str]] = None

    @property
    def help(self) -> Optional[str]:
        if self._make_help is not None:
            make, self._make_help = self._make_help, None
            text = make()
            self._help = inspect.cleandoc(text) if text else text  # as TyperOption does with a help it is given
        return self._help

    @help.setter
    def help(self, value: Optional[str]) -> None:
        self._help = value
        self._make_help = None


def params_options(
    command: str, *, only: tuple[str, ...] | None = None, defaults: bool = False, prefix: str = ""
) -> list[Any]:
    """The click options of a command's ``Params`` fields (``typer.core.TyperOption``, as typer makes its own).

    The option is the field's declared one (``--field-name``, or a name such as ``--starts``), a
    ``--name/--no-name`` flag for a bool (or the off-switch it declares), of the field's type; the
    help is :func:`option_help`. A stage's options default to None, "not given", so that the map's
    ``params:`` apply; ``defaults=True`` (``verify``, which has no map layer) gives the dataclass's
    defaults instead, shown in the help as typer shows a default (``[default: 200]``). Fields declared
    without an option (``params:`` only) are left out; ``only`` keeps just those fields.
    """
    options = []
    for field in params_fields(command):
        if (field.option is None and only is None) or (only is not None and field.name not in only):
            continue
        if field.kind not in (int, float, str, bool):  # click converts these by itself; typer would convert others
            raise TypeError(f"option {field.name}: a {field.kind} needs typer's conversion")
        name = field.option or "--" + field.name.replace("_", "-")
        flag = field.kind is bool
        # what typer.Option(default, declared, help=...) in a signature makes: a bool is a flag with its
        # off-switch (click's own bool type), any other kind click's type of that Python type
        option = _ParamOption(
            param_decls=[field.name, f"{name}/{field.off}" if flag else name],
            type=None if flag else field.kind,
            is_flag=flag or None,
            default=field.default if defaults else None,
            show_default=True,
        )
        option._make_help = functools.partial(option_help, command, field, with_default=not defaults, prefix=prefix)
        options.append(option)
    return options


def with_options(*groups: Callable[[], list[Any]], before: str = "force") -> Callable[[Callable], Callable]:
    """Give a command the generated options, among its own before ``before``.

    Each group is called, for its click options (:func:`params_options`), when the command's
    options are first read (:class:`_Command`), not when the program starts: typer reads the
    command's own signature, less its ``**options``, in which the command takes the generated
    ones, keyed by field name.
    """

    def decorate(command: Callable) -> Callable:
        signature = inspect.signature(command, eval_str=True)
        own = [
            p.replace(kind=inspect.Parameter.KEYWORD_ONLY)
            for p in signature.parameters.values()
            if p.kind is not inspect.Parameter.VAR_KEYWORD
        ]
        command.__signature__ = signature.replace(parameters=own)
        command.generated_options = (groups, before)
        return command

    return decorate
