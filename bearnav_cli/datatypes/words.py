"""Counts, shares and lists of cells as every message words them (``3 cells``, ``< 0.1%``, ``3, 7, 12``)."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["cell_list", "NEGLIGIBLE_SHARE", "percent", "plural"]


def plural(count: int, word: str, many: str | None = None) -> str:
    """``"1 obstacle"``, ``"3 obstacles"``: a count and its noun, for every message that counts things.

    Parameters
    ----------
    count : int
        How many.
    word : str
        The noun in the singular.
    many : str, optional
        Its plural, when it is not ``word + "s"``.

    Returns
    -------
    str
    """
    return f"{count} {word if count == 1 else many or word + 's'}"


#: A share of an area below which a warning is not worth giving: it would read ``0.0%``, a few points of a
#: grid at a corner rather than a place a robot could be stuck in (the checks that fail a plan do not use it).
NEGLIGIBLE_SHARE = 0.0005


def percent(share: float) -> str:
    """A share as a percentage to 0.1%, never ``0.0%`` or ``100.0%`` unless it is exactly 0 or 1.

    A message that reports a sliver as ``0.0%`` says nothing (or something false): it reads
    ``< 0.1%`` instead, and ``> 99.9%`` for a share just short of all.
    """
    if 0.0 < share < NEGLIGIBLE_SHARE:
        return "< 0.1%"
    if 1.0 - NEGLIGIBLE_SHARE <= share < 1.0:
        return "> 99.9%"
    return f"{share:.1%}"


def cell_list(cells: Any, limit: int = 12) -> str:
    """``"3, 7, 12"`` for messages, cut after ``limit`` cells with the total count."""
    items = [str(int(c)) if isinstance(c, (int, np.integer)) else str(c) for c in cells]
    text = ", ".join(items[:limit])
    return text + (f" … ({len(items)} in all)" if len(items) > limit else "")
