"""Immutability: read-only dicts, and arrays copied to their declared dtype and shape and made read-only.

The containers call these in their constructors, so an artifact cannot change after it is built;
the dtypes and shapes come from the one schema declaration, :data:`bearnav_cli.runtime.schema.ENTRIES`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bearnav_cli.errors import ArtifactError
from bearnav_cli.runtime.invariants import ragged_problem
from bearnav_cli.runtime.schema import ENTRIES

__all__ = ["ArraysOnMap", "data_keys", "freeze", "freeze_fields", "FrozenDict", "frozen_array", "ragged", "thaw"]


class ArraysOnMap:
    """What every artifact but the map is (:class:`Tree`, :class:`Cells`, :class:`Plan`, :class:`Simulation`):
    arrays made on a map, its ``map`` embedded in its file beside its ``arrays()``.

    :func:`bearnav_cli.artifacts.entries_of` tells them by it, importing none of their modules.
    """

    __slots__ = ()


class FrozenDict(dict):
    """A ``dict`` that cannot change (issue 14.5): the ``stats`` and ``params`` of a frozen artifact.

    It is a ``dict`` for every reader (``json.dumps``, ``==``, ``isinstance``); every mutating
    method raises ``TypeError``. :func:`copy.copy` and :func:`copy.deepcopy` give plain, mutable
    ``dict`` copies (:func:`thaw`), so a caller that wants to edit one edits its own copy.
    """

    __slots__ = ()

    def _read_only(self, *args: Any, **kwargs: Any) -> None:
        raise TypeError("an artifact's stats and params are read-only: copy them (dict(x)) to change them")

    __setitem__ = __delitem__ = __ior__ = clear = pop = popitem = setdefault = update = _read_only  # type: ignore[assignment]

    def __copy__(self) -> dict:
        return dict(self)

    def __deepcopy__(self, memo: dict) -> Any:
        return thaw(self)

    def __reduce__(self) -> tuple:
        return (FrozenDict, (dict(self),))


def freeze(value: Any) -> Any:
    """``value`` with every dict in it (nested too) made a :class:`FrozenDict`; other values as they are.

    Parameters
    ----------
    value : Any
        A JSON-like value (dicts, lists, numbers, strings).

    Returns
    -------
    Any
        The same value, its dicts read-only (lists stay lists: they compare equal to JSON arrays).
    """
    if isinstance(value, dict):
        return (
            value
            if type(value) is FrozenDict
            and all(not isinstance(v, dict) or type(v) is FrozenDict for v in value.values())
            else FrozenDict({k: freeze(v) for k, v in value.items()})
        )
    if isinstance(value, list):
        return [freeze(v) for v in value]
    return value


def thaw(value: Any) -> Any:
    """A plain, mutable deep copy of ``value`` (every :class:`FrozenDict` in it a ``dict``).

    Parameters
    ----------
    value : Any
        A JSON-like value, possibly frozen by :func:`freeze`.

    Returns
    -------
    Any
        The copy (YAML's safe dumper, for one, writes only plain dicts).
    """
    if isinstance(value, dict):
        return {k: thaw(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [thaw(v) for v in value]
    return value


def frozen_array(value: Any, dtype: Any, shape: tuple[int | None, ...], name: str) -> np.ndarray:
    """Return a read-only copy of ``value`` as ``dtype`` after checking its shape.

    Parameters
    ----------
    value : array_like
        The data.
    dtype : numpy dtype
        Target dtype (float64 for positions, int64 for indices).
    shape : tuple of int or None
        Expected shape; ``None`` matches any length along that axis.
    name : str
        Field name used in the error message.
    """
    array = np.array(value, dtype=dtype, copy=True)
    if array.size == 0 and len(shape) > 1 and array.ndim == 1:
        array = array.reshape((0,) + tuple(s or 0 for s in shape[1:]))
    if array.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(array.shape, shape, strict=False)
    ):
        raise ArtifactError(f"expected shape {_shape_text(shape)}, got {array.shape}", field=name)
    array.setflags(write=False)
    return array


def _shape_text(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"


def freeze_fields(obj: Any, kind: str, names: tuple[str, ...], dims: dict[str, int]) -> None:
    """Replace each field of ``names`` on ``obj`` by a read-only array of the dtype and shape that
    ``ENTRIES[kind]`` declares, the dimensions in ``dims`` filled in (the others match any length).

    Parameters
    ----------
    obj : Any
        A frozen container being built (its ``__post_init__``).
    kind : str
        The artifact kind whose declaration gives each field's dtype and shape.
    names : tuple of str
        The fields to freeze.
    dims : dict of str to int
        Known sizes of the symbolic dimensions (``{"C": 12}``).
    """
    for name in names:
        entry = ENTRIES[kind][name]
        object.__setattr__(obj, name, frozen_array(getattr(obj, name), entry.numpy_dtype, entry.resolve(dims), name))


def data_keys(kind: str) -> tuple[str, ...]:
    """The data entries of ``kind`` that its container holds as fields (all but the embedded ``map``)."""
    return tuple(name for name in ENTRIES[kind] if name != "map")


def ragged(coords: Any, offsets: Any, width: int | None, name: str, count: int, dtype: Any = float):
    """Check a coords + offsets pair (DESIGN §3.1) and return both, read-only.

    Item ``c`` is ``coords[offsets[c]:offsets[c + 1]]``; ``offsets`` has ``count + 1``
    non-decreasing entries from 0 to ``len(coords)``.

    Parameters
    ----------
    coords : array_like, shape (M,) or (M, width)
        The rows of every item, concatenated (``cell_A`` rows, ``cell_vertices`` in map
        units, ...); converted to ``dtype``.
    offsets : array_like of int, shape (count + 1,)
        Where each item's rows begin in ``coords``; converted to int64.
    width : int or None
        Columns of each row (2 for points and normals); None for a 1-d ``coords``.
    name : str
        The entry's name (``"cell_A"``), as the error names it (``"cell_A offsets"`` for
        the offsets).
    count : int
        Number of items (C, the cells).
    dtype : numpy dtype, default float
        dtype of ``coords`` (float64 for coordinates, ``bool`` for flags).

    Returns
    -------
    coords, offsets : ndarray
        Read-only copies, ``coords`` of ``dtype`` and ``offsets`` of int64.

    Raises
    ------
    ArtifactError
        A wrong shape (of ``coords``, or ``offsets`` not of ``count + 1`` entries), or offsets
        that do not rise from 0 to ``len(coords)``.
    """
    shape = (None,) if width is None else (None, width)
    coords = frozen_array(coords, dtype, shape, name)
    offsets = frozen_array(offsets, np.int64, (count + 1,), f"{name} offsets")
    problem = ragged_problem(coords, offsets)
    if problem is not None:
        raise ArtifactError(problem, field=f"{name} offsets")
    return coords, offsets
