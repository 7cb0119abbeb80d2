"""The declaration of one parameter: :func:`param` puts its range, choices, unit and option in the field's metadata.

Standard library and :mod:`bearnav_cli.errors` only. :class:`Range` is the documented range of a numeric
parameter (docs/cli.md "Option limits"); :func:`declared` reads a field's declaration back.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
from dataclasses import dataclass
from typing import Any

__all__ = [
    "AUTO",
    "check",
    "Declared",
    "MAX_RUNS",
    "MAX_STEPS_PER_RUN",
    "Range",
    "SEED",
    "declared",
    "named_option",
    "option_name",
    "param",
    "params_type",
]


@dataclass(frozen=True)
class Range:
    """The documented range of one numeric parameter (docs/cli.md "Option limits" shows :meth:`text`).

    Attributes
    ----------
    low, high : float or None
        Bounds (``None``: none); with ``per_diagonal`` they are multiples of the map's diagonal
        ``D`` and are checked once the map is known.
    low_open : bool
        ``low`` itself is excluded.
    integer : bool
        The value must be an integer.
    per_diagonal : bool
        The bounds scale with ``D`` (a length).
    high_open : bool
        ``high`` itself is excluded.
    """

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    integer: bool = False
    per_diagonal: bool = False
    high_open: bool = False

    def _bound(self, value: float | None) -> str:
        if value is None:
            return "∞"
        text = f"{value:g}" if not self.integer else str(int(value))
        if self.per_diagonal:
            return "0" if value == 0 else ("D" if value == 1 else f"{text}·D")
        return text

    def text(self) -> str:
        """``"integer in [1, 10000000]"``, ``"(0, 10·D]"`` ..."""
        left = "(" if self.low_open else "["
        right = ")" if self.high is None or self.high_open else "]"
        interval = f"{left}{self._bound(self.low)}, {self._bound(self.high)}{right}"
        return f"integer in {interval}" if self.integer else interval

    def describe(self) -> str:
        """``"an integer in [1, 10000000]"``, ``"in (0, 10·D]"``: for messages."""
        text = self.text()
        return "an " + text if self.integer else "in " + text

    def problem(self, value: Any, diagonal: float | None = None, *, high: bool = True) -> str | None:
        """What is wrong with ``value`` (None when it fits); D-relative bounds only with ``diagonal``, the high
        bound only with ``high``."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"expected a number, got {value!r}"
        if isinstance(value, float) and not math.isfinite(value):
            return f"must be finite ({self.describe()}), got {value}"
        if self.integer and not (isinstance(value, int) or float(value).is_integer()):
            return f"must be {self.describe()}, got {value!r}"
        scale = 1.0
        if self.per_diagonal or not high:
            if diagonal is None or not high:  # the map is not known yet: only what does not depend on D
                if self.low is None or value > self.low or (value == self.low and not self.low_open):
                    return None
                return f"must be {self.describe()}, got {value!r}"
            scale = diagonal
        low = None if self.low is None else self.low * scale
        high = None if self.high is None else self.high * scale
        too_low = low is not None and (value < low or (self.low_open and value == low))
        too_high = high is not None and (value > high or (self.high_open and value == high))
        if too_low or too_high:
            shown = f" (D = {diagonal:.4g})" if self.per_diagonal and diagonal is not None else ""
            return f"must be {self.describe()}{shown}, got {value!r}"
        return None


#: Seeds: any integer numpy's ``default_rng`` takes that also fits 32 bits; negatives are refused.
SEED = Range(0, 2**32 - 1, integer=True)
#: Most runs ``random:N`` / ``verify --starts`` may ask for (a memory estimate may refuse fewer).
MAX_RUNS = 1_000_000
#: Most steps one closed-loop run may be allowed (``max_steps``, explicit or from speed and dt): about 60
#: times what the example maps need at their speeds, a few minutes of one robot.
MAX_STEPS_PER_RUN = 1_000_000

#: ``option=AUTO``: the option is ``--name-with-dashes``.
AUTO = "auto"


@dataclass(frozen=True)
class Declared:
    """What :func:`param` declared about one field (the field's ``metadata["declared"]``).

    Attributes
    ----------
    range : Range or None
        The documented range of a numeric field.
    choices : tuple of str
        The values a string field takes (empty: any).
    unit : str
        The unit of a number ("map units", "degrees", "s"; "" for none).
    option : str or None
        The command-line option (``--starts``); ``None``: set in the map's ``params:`` only.
    off : str or None
        A bool's off-switch when it is not ``--no-NAME`` (``--allow-reverse``).
    capped : bool
        ``Params`` itself refuses a value above the range too; otherwise it checks the low bound and
        the type only, and the high bound is a limit of a request (:func:`bearnav_cli.limits.check_value`),
        which the Python API may pass.
    """

    range: Range | None
    choices: tuple[str, ...]
    unit: str
    option: str | None
    off: str | None
    capped: bool = False


def param(
    default: Any,
    *,
    range: Range | None = None,
    choices: tuple[str, ...] = (),
    unit: str = "",
    option: str | None = AUTO,
    off: str | None = None,
    capped: bool = False,
) -> Any:
    """A dataclass field with ``default`` and its declaration (:class:`Declared`) in its metadata.

    Parameters
    ----------
    default : object
        The field's default.
    range : Range, optional
        The documented range of a numeric field.
    choices : tuple of str
        The values a string field takes.
    unit : str
        The unit of a number, for the documentation.
    option : str or None
        The command-line option: :data:`AUTO` (``--name-with-dashes``, the field's name known only
        later), a name (``--starts``), or ``None`` for a field of the map's ``params:`` only.
    off : str, optional
        A bool's off-switch when it is not ``--no-NAME``.
    capped : bool
        ``Params`` itself refuses a value above the range (:attr:`Declared.capped`).
    """
    declared_ = Declared(range, tuple(choices), unit, option, off, capped)
    return dataclasses.field(default=default, metadata={"declared": declared_})


def declared(field: dataclasses.Field) -> Declared:
    """The declaration of a field (an undeclared one: no range, choices or unit; option ``--name``)."""
    found = field.metadata.get("declared")
    if found is None:
        return Declared(None, (), "", "--" + field.name.replace("_", "-"), None, False)
    if found.option == AUTO:
        return dataclasses.replace(found, option="--" + field.name.replace("_", "-"))
    return found


def check(params: Any) -> None:
    """Check a ``Params`` against its declarations: each field's choices and range, in field order.

    A range's type and low bound are checked (its high bound too when declared ``capped``; the
    pipeline checks the rest of a request, :func:`bearnav_cli.limits.check_value`); ``None`` is not
    checked. The first check of ``__post_init__`` in every ``Params``.

    Parameters
    ----------
    params : Params
        The dataclass instance just made.

    Raises
    ------
    InvalidParamsError
        For the first field outside its choices or range, naming the field.
    """
    from bearnav_cli.errors import InvalidParamsError

    for field in dataclasses.fields(params):
        declaration = declared(field)
        value = getattr(params, field.name)
        if declaration.choices and value not in declaration.choices:
            raise InvalidParamsError(
                f"must be one of {', '.join(declaration.choices)}, got {value!r}", field=field.name
            )
        if declaration.range is not None and value is not None:
            problem = declaration.range.problem(value, high=declaration.capped)
            if problem is not None:
                raise InvalidParamsError(problem, field=field.name)


def named_option(field: dataclasses.Field) -> str | None:
    """The option a field's declaration names (``--starts``), None when it is ``--name-with-dashes`` or none."""
    found = field.metadata.get("declared")
    return None if found is None or found.option in (None, AUTO) else found.option


def params_type(command: str) -> type:
    """The ``Params`` dataclass of a command (``"rrtstar"``, ``"verify"``), from :data:`bearnav_cli.params.MODULES`."""
    from bearnav_cli.params import MODULES

    return importlib.import_module(MODULES[command]).Params


def option_name(command: str, name: str) -> str:
    """The command-line option of a command's field (``--border-spacing``; ``--starts`` for verify's ``n_starts``).

    A field without an option (``params:`` only) and a name that is no field are spelled ``--name-with-dashes``.
    """
    for field in dataclasses.fields(params_type(command)):
        if field.name == name:
            return declared(field).option or "--" + name.replace("_", "-")
    return "--" + name.replace("_", "-")
