"""The one declaration of every artifact's entries (DESIGN §3): key → dtype, symbolic shape, meaning.

Everything else reads this table: the containers of :mod:`bearnav_cli.datatypes` (dtypes and
shapes their constructors enforce, the keys of ``arrays()``), :mod:`bearnav_cli.artifacts` (the
schema names, the entries the loader requires and checks), :mod:`bearnav_cli.runtime.plan_arrays`
(:data:`RUNTIME_KEYS`, the dtypes and shapes of the run-time view) and ``tests/test_docs.py``,
which checks the tables of ``docs/artifacts.md`` against it. It lives in the runtime package, which
needs numpy only, so that a robot reading ``plan.npz`` and the planner that writes it share it.

Shapes are symbolic: each item is an int or a dimension name, optionally ``k·X`` (``"2L"``) or
``X + k`` (``"C+1"``). The names are per artifact (:data:`DIMENSIONS`). Dtypes are numpy dtype
strings (``"f8"``, ``"i8"``, ``"i1"``, ``"bool"``) or ``"str"``, a 0-d text (JSON) entry.
"""

from __future__ import annotations

import re
from typing import NamedTuple

import numpy as np

__all__ = ["DIMENSIONS", "Entry", "ENTRIES", "RETIRED_PLAN_SCHEMAS", "RUNTIME_KEYS", "SCHEMAS", "shape_text", "STAGES"]


class Entry(NamedTuple):
    """One data entry of an artifact file.

    Attributes
    ----------
    dtype : str
        ``"f8"``, ``"i8"``, ``"i1"``, ``"bool"``, or ``"str"`` (a 0-d text entry).
    shape : tuple of int or str
        Symbolic shape, ``("C", 2)``, ``("C+1",)``, ``("C", 2, "2L")``; ``()`` for a scalar.
    meaning : str
        What the entry holds (the text ``docs/artifacts.md`` shows).
    """

    dtype: str
    shape: tuple
    meaning: str

    @property
    def kind(self) -> str:
        """numpy's dtype kind the loader requires: ``"f"``, ``"i"``, ``"b"``, or ``"U"`` for a text."""
        return "U" if self.dtype == "str" else np.dtype(self.dtype).kind

    @property
    def ndim(self) -> int:
        return len(self.shape)

    @property
    def numpy_dtype(self) -> np.dtype | None:
        """The numpy dtype (None for a text entry)."""
        return None if self.dtype == "str" else np.dtype(self.dtype)

    def resolve(self, dims: dict[str, int]) -> tuple[int | None, ...]:
        """The shape with the dimensions in ``dims`` filled in; ``None`` where a dimension is not known."""
        return tuple(_dimension(item, dims) for item in self.shape)


_DIM = re.compile(r"^(?P<scale>\d*)(?P<name>[A-Z])(?:\+(?P<plus>\d+))?$")


def _dimension(item: int | str, dims: dict[str, int]) -> int | None:
    if isinstance(item, int):
        return item
    match = _DIM.match(item)
    if match is None:  # pragma: no cover - a typo in the table below (tests/test_docs.py parses every shape)
        raise ValueError(f"bad symbolic dimension {item!r}")
    value = dims.get(match["name"])
    if value is None:
        return None
    return int(match["scale"] or 1) * int(value) + int(match["plus"] or 0)


def shape_text(shape: tuple) -> str:
    """``"(C, 2)"``, ``"(C+1,)"``, ``"()"``: a symbolic shape as ``docs/artifacts.md`` writes it."""
    items = [str(item) for item in shape]
    return "(" + ", ".join(items) + ("," if len(items) == 1 else "") + ")"


#: Schema name of each artifact kind (the manifest's ``schema``).
SCHEMAS: dict[str, str] = {
    "map": "bearnav.map/1",
    "tree": "bearnav.tree/1",
    "simplified": "bearnav.simplified/1",
    "cells": "bearnav.cells/3",
    "plan": "bearnav.plan/3",
    "simulation": "bearnav.sim/2",
}

#: The stage that writes each artifact kind (the manifest's ``stage``).
STAGES: dict[str, str] = {
    "map": "map",
    "tree": "rrtstar",
    "simplified": "simplify",
    "cells": "decompose",
    "plan": "synthesize",
    "simulation": "simulate",
}

#: The plan schemas this version refuses with a "re-run" message (``artifacts.RETIRED_SCHEMAS`` has the rest).
RETIRED_PLAN_SCHEMAS = ("bearnav.plan/1", "bearnav.plan/2")

#: What the dimension names of each kind's shapes count.
DIMENSIONS: dict[str, dict[str, str]] = {
    "tree": {"N": "tree nodes", "S": "collision samples"},
    "cells": {"N": "tree nodes", "S": "collision samples", "C": "cells (C = N)", "R": "half-plane rows",
              "V": "polygon vertices (V = R)", "H": "barrier rows", "L": "landmarks"},
    "simulation": {"R": "runs", "P": "trajectory points", "N": "tree nodes", "C": "cells", "V": "polygon vertices"},
}  # fmt: skip
DIMENSIONS["simplified"] = DIMENSIONS["tree"]
DIMENSIONS["plan"] = DIMENSIONS["cells"]

_MAP = Entry("str", (), "the normalised map JSON")

_TREE = {
    "map": _MAP,
    "nodes": Entry("f8", ("N", 2), "node positions; node 0 is the goal"),
    "parent": Entry("i8", ("N",), "parent index; -1 exactly at the root"),
    "cost": Entry("f8", ("N",), "length of the tree route to the root"),
    "collision_samples": Entry("f8", ("S", 2), "samples inside obstacles, then border pseudo-samples (ALGORITHMS "
                               "§2); simplify keeps every one"),
}  # fmt: skip

_CELLS = {
    "map": _MAP,
    "nodes": Entry("f8", ("N", 2), "simplified tree nodes; node 0 is the goal"),
    "parent": Entry("i8", ("N",), "parent index; -1 exactly at the root"),
    "collision_samples": Entry("f8", ("S", 2), "every collision sample"),
    "cell_node": Entry("i8", ("C",), "node owning each cell"),
    "cell_A": Entry("f8", ("R", 2), "outward unit normals; cell = {x : A x ≤ b}"),
    "cell_b": Entry("f8", ("R",), "offsets"),
    "cell_row_offsets": Entry("i8", ("C+1",), "rows of each cell"),
    "cell_vertices": Entry("f8", ("V", 2), "CCW vertices; row q is the normal of edge v_q → v_q+1"),
    "cell_vertex_offsets": Entry("i8", ("C+1",), "vertices of each cell"),
    "exit_point": Entry("f8", ("C", 2), "x_j, the parent node; zeros for the goal cell"),
    "exit_dir": Entry("f8", ("C", 2), "unit z from the exit face into the cell: V(x) = z·(x − x_j) ≥ 0 in the cell; "
                      "zeros for the goal cell"),
    "cbf_A": Entry("f8", ("H", 2), "barrier normals; h(x) = A x + b, safe where h ≥ 0"),
    "cbf_b": Entry("f8", ("H",), "barrier offsets"),
    "cbf_offsets": Entry("i8", ("C+1",), "barrier rows of each cell"),
    "cell_landmarks": Entry("bool", ("C", "L"), "landmarks each cell's controller uses"),
    "fixed_landmark": Entry("i8", ("C",), "landmark f that rescales bearings (ALGORITHMS §5.5)"),
    "s_min": Entry("f8", ("C",), "exact distance from l_f to the cell (0 if inside)"),
    "s_max": Entry("f8", ("C",), "largest distance from l_f to the cell"),
    "cell_flags": Entry("i8", ("C",), "bits: 1 few landmarks (topped up), 2 degenerate rescaling risk, 4 fixed "
                        "landmark inside, 8 sample on the edge line, 16 blind spot (a free point sees < 2 landmarks)"),
    "certificate": Entry("str", (), "`funnel` (ALGORITHMS §11: every cell is obstacle-free and its exit face lies in "
                         "its parent cell, so the certificates compose) or `paper` (§4 cells, per-cell certificates "
                         "only)"),
    "cell_exit_row": Entry("i8", ("C",), "index of the exit row among the cell's own rows (local, 0-based); -1 for "
                           "the goal cell"),
    "cell_rank": Entry("f8", ("C",), "rank of the switching policy: the cost-to-go of the cell's node (0 for the goal "
                       "cell); every exit lands in a cell of smaller rank"),
    "exit_inset": Entry("f8", ("C",), "δ_e,c: cell c's exit face lies in its parent cell eroded by δ_e,c (ALGORITHMS "
                        "§12.3; 0 for `paper`); NaN for the goal cell"),
    "node_added": Entry("bool", ("N",), "nodes added by densification (ALGORITHMS §11.5), not by the tree stages"),
    "free_coverage": Entry("f8", (), "area(D)/area(F) of the reached part of F as built (ALGORITHMS §12.7; `verify` "
                           "recomputes it and that of F_m); NaN for `paper`"),
    "lookahead": Entry("f8", (), "λ the cells were built for (ALGORITHMS §12.6): the obstacles and walls were inflated "
                       "by ρ + λ; 0: the robot is its own reference point"),
}  # fmt: skip

_PLAN = {
    **_CELLS,
    "gain": Entry("f8", ("C", 2, "2L"), "u(x) = gain[c] @ (landmarks − x).ravel(); unused landmarks' columns are "
                  "zero"),
    "c_h": Entry("f8", ("C",), "barrier constant (NaN without barrier rows)"),
    "c_v": Entry("f8", ("C",), "Lyapunov constant"),
    "u_max": Entry("f8", ("C",), "input box |u_k| ≤ u_max"),
    "margin_h": Entry("f8", ("C",), "worst CBF slack over the cell (≤ 0 holds; NaN without rows)"),
    "margin_v": Entry("f8", ("C",), "worst CLF slack (NaN for the goal cell)"),
    "status": Entry("i1", ("C",), "0 certified, 1 certified after relaxing constants, 2 not certified, 3 solver "
                    "failure, 4 goal cell"),
    "goal_tolerance": Entry("f8", (), "success radius around the goal"),
    "tolerance": Entry("f8", ("C",), "δ_c, the position error each cell's certificate tolerates (ALGORITHMS §11.4); "
                       "+inf where the field is constant (M = 0); NaN where none"),
    "usable_tolerance": Entry("f8", ("C",), "τ_c = min(δ_c, δ_e,c/2) (δ_c for the goal cell): the error radius under "
                              "which the runtime may move in cell c (ALGORITHMS §12.3); NaN for `paper`"),
    "plan_tolerance": Entry("f8", (), "min_c τ_c (NaN for `paper`)"),
    "landmarks": Entry("f8", ("L", 2), "landmark positions (the embedded map's)"),
}  # fmt: skip

_SIMULATION = {
    "map": _MAP,
    "starts": Entry("f8", ("R", 2), "start of each run (a look-ahead unicycle's point p, ALGORITHMS §12.6)"),
    "outcome": Entry("i1", ("R",), "0 success, 1 collision, 2 stall, 3 timeout, 4 lost"),
    "steps": Entry("i8", ("R",), "Euler steps"),
    "time": Entry("f8", ("R",), "seconds"),
    "path_length": Entry("f8", ("R",), "length of the trajectory"),
    "route_length": Entry("f8", ("R",), "tree route from the start: ‖x₀ − x_n‖ + cost(n), n the nearest node"),
    "left_cell": Entry("i8", ("R",), "relocations after leaving a cell through a side face"),
    "approach_steps": Entry("i8", ("R",), "steps driven straight to a tree node from outside every safe set"),
    "hold_steps": Entry("i8", ("R",), "steps without a usable bearing reconstruction"),
    "certified_steps": Entry("i8", ("R",), "steps covered by the composed certificate (ALGORITHMS §11.4; 0 for "
                             "`paper` plans)"),
    "start_in_domain": Entry("bool", ("R",), "the start lies in the certified domain D (some funnel cell holds it)"),
    "min_clearance": Entry("f8", ("R",), "smallest distance of the body from the inflated obstacles and the walls"),
    "final_position": Entry("f8", ("R", 2), "where each run ended (p for a look-ahead unicycle)"),
    "final_cell": Entry("i8", ("R",), "active cell at the end; -1 if the start was not free or never had a fix"),
    "max_steps": Entry("i8", ("R",), "step limit of the run"),
    "trajectory_coords": Entry("f8", ("P", 2), "every run's positions (p for a look-ahead unicycle: the axle is p − "
                               "λ·(cos, sin)(heading)), run r at offsets[r]:offsets[r+1] (start first; empty when not "
                               "recorded)"),
    "trajectory_cells": Entry("i8", ("P",), "active cell at each point"),
    "trajectory_heading": Entry("f8", ("P",), "camera heading at each point (rad)"),
    "trajectory_offsets": Entry("i8", ("R+1",), "where each run's points begin"),
    "nodes": Entry("f8", ("N", 2), "the plan's tree"),
    "parent": Entry("i8", ("N",), "parent index; -1 exactly at the root"),
    "cell_vertices": Entry("f8", ("V", 2), "the plan's cells, CCW"),
    "cell_vertex_offsets": Entry("i8", ("C+1",), "vertices of each cell"),
    "cell_status": Entry("i1", ("C",), "the cells' synthesis status"),
    "speed": Entry("f8", (), "the speed `dt` and `eps_sw` are scaled by: `v_ref`, or `α` for the unicycle (map "
                   "units/s)"),
    "dt": Entry("f8", (), "Euler step (s)"),
    "eps_sw": Entry("f8", (), "switching radius `2·speed·dt` around the exit point (map units)"),
    "goal_tolerance": Entry("f8", (), "success radius (map units)"),
}  # fmt: skip

#: The data entries of every artifact kind, in file order (``manifest`` aside). ``map.json``'s one
#: entry is its document (the normalised map); every later artifact embeds the same JSON as ``map``.
ENTRIES: dict[str, dict[str, Entry]] = {
    "map": {"map": _MAP},
    "tree": _TREE,
    "simplified": _TREE,
    "cells": _CELLS,
    "plan": _PLAN,
    "simulation": _SIMULATION,
}

#: ``plan.npz`` entries a robot needs (DESIGN §3.2; :class:`~bearnav_cli.runtime.plan_arrays.PlanArrays`).
RUNTIME_KEYS: tuple[str, ...] = (
    "landmarks", "nodes", "parent", "cell_node", "cell_A", "cell_b", "cell_row_offsets", "exit_point",
    "exit_dir", "gain", "u_max", "goal_tolerance", "cell_landmarks", "fixed_landmark", "status",
    "cbf_A", "cbf_b", "cbf_offsets", "certificate", "cell_rank", "tolerance", "plan_tolerance", "exit_inset",
    "usable_tolerance", "lookahead",
    "cell_vertices", "cell_vertex_offsets", "c_h", "c_v",
)  # fmt: skip
