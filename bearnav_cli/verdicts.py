"""Why a stage's result is not usable: the :class:`Problem` a stage's ``problems(result)`` returns.

A result with a problem is an outcome, not an error (DESIGN §1.4): the stage writes it, and the command
line exits 1 with the first problem and the command that addresses it (:mod:`bearnav_cli.cli.hints`).
Several stages judge the same thing (every stage after ``rrtstar`` carries the tree; ``synthesize``
carries the cells), so the judgements are here, one each, and each stage's ``problems`` lists those
that apply to what it made.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bearnav_cli.datatypes import cell_list

__all__ = [
    "blind_spots",
    "BLIND_SPOT",
    "cell_problems",
    "no_route",
    "NO_ROUTE",
    "not_certified",
    "NOT_CERTIFIED",
    "Problem",
]

#: The kinds of :class:`Problem`.
NO_ROUTE, BLIND_SPOT, NOT_CERTIFIED = "no route", "blind spot", "not certified"


@dataclass(frozen=True)
class Problem:
    """One reason a stage's result is not usable.

    Attributes
    ----------
    kind : str
        :data:`NO_ROUTE`, :data:`BLIND_SPOT` or :data:`NOT_CERTIFIED`: what the next step is.
    text : str
        What is wrong, in words (no command: the command line adds the one that addresses it).
    cells : tuple of int
        The cells concerned, in order (empty when the problem is not about cells).
    """

    kind: str
    text: str
    cells: tuple[int, ...] = ()


def no_route(nodes: Any, added: Any = None) -> list[Problem]:
    """The tree is only its root: no node but the goal, leaving out the ``added`` ones (decompose's, not the tree's).

    Parameters
    ----------
    nodes : array_like, shape (N, 2)
        The tree's nodes.
    added : array_like of bool, shape (N,), optional
        Nodes ``decompose`` added to cover the free space (not a route the tree found).
    """
    found = len(nodes) - (0 if added is None else sum(map(bool, added)))
    if found >= 2:
        return []
    return [
        Problem(
            NO_ROUTE,
            "no route: the tree has only its root (is the goal walled in, or did every sample fall in obstacles?)",
        )
    ]


def blind_spots(cells: Any) -> list[Problem]:
    """Cells with free points that see fewer than 2 landmarks (:attr:`~bearnav_cli.datatypes.CellFlag.BLIND_SPOT`)."""
    from bearnav_cli.datatypes.cells import CellFlag  # here: judging a tree (no_route) needs no cells

    blind = cells.flagged(CellFlag.BLIND_SPOT)
    if not blind:
        return []
    one = len(blind) == 1
    text = f"{'cell' if one else 'cells'} {cell_list(blind, 20)} {'has' if one else 'have'} free points that see "
    return [Problem(BLIND_SPOT, text + "fewer than 2 landmarks", tuple(int(c) for c in blind))]


def cell_problems(cells: Any) -> list[Problem]:
    """The problems of a set of cells, worst first: no route (the tree is only its root, the nodes added to cover
    the free space left out), then blind-spot cells (what ``decompose`` judges, and ``synthesize`` before its own)."""
    return no_route(cells.nodes, cells.node_added) + blind_spots(cells)


def not_certified(status: Any) -> list[Problem]:
    """Cells whose synthesis failed: not certified or a solver failure (status 2 or 3)."""
    from bearnav_cli.datatypes.cells import CellStatus  # here: judging a tree (no_route) needs no cells

    bad = (status == CellStatus.NOT_CERTIFIED) | (status == CellStatus.SOLVER_FAILURE)
    failed = [int(c) for c in bad.nonzero()[0]]
    if not failed:
        return []
    return [Problem(NOT_CERTIFIED, f"cells {cell_list(failed, 20)} are not certified (status 2 or 3)", tuple(failed))]
