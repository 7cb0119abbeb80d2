"""A package whose names are imported on first use (PEP 562): its ``__getattr__`` and ``__dir__``, made once.

Standard library only, as everything under ``runtime/`` is at most numpy: ``bearnav_cli.runtime`` and
``bearnav_cli.datatypes`` resolve their names with it, so that importing either imports no submodule
until one of its names is used.
"""

import importlib
from typing import Any, Callable

__all__ = ["lazy_names"]


def lazy_names(
    package: str, namespace: dict[str, Any], origin: dict[str, str], submodules: tuple[str, ...]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The ``__getattr__`` and ``__dir__`` of ``package`` whose names come from its submodules on first use.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    namespace : dict
        Its ``globals()``: a name once imported is stored there, so the next use does not ask again.
    origin : dict of str to str
        The submodule each name is defined in.
    submodules : tuple of str
        The submodules, attributes of the package too.
    """

    def __getattr__(name: str) -> Any:
        if name in submodules:
            return importlib.import_module(f"{package}.{name}")
        if name in origin:
            value = getattr(importlib.import_module(f"{package}.{origin[name]}"), name)
            namespace[name] = value
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted({*namespace, *namespace.get("__all__", ()), *submodules})

    return __getattr__, __dir__
