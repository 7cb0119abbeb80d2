"""What the cells and the controllers of a plan must satisfy to make sense: the one copy of those checks (DESIGN §3).

Numpy only, so that the robot's loader (:func:`bearnav_cli.runtime.plan_file.load_plan`) and the
CLI's (:func:`bearnav_cli.artifacts.load`, whose containers in :mod:`bearnav_cli.datatypes` call the
same functions) refuse the same files. Every check reads its arrays by attribute: a
:class:`~bearnav_cli.datatypes.Cells` or :class:`~bearnav_cli.datatypes.Plan`, or the robot loader's
view of a ``plan.npz`` (:class:`types.SimpleNamespace` of its entries, the embedded map as ``map``).
The map needs ``goal`` (shape (2,), map units), ``landmarks`` (shape (L, 2), map units), ``tol``
(``1e-9·D``, map units) and ``diagonal`` (D, map units).

- the **form** a loaded artifact must have before anything reads its arrays by index
  (:func:`check_cells_form`, :func:`check_plan_form`, :func:`ragged_problem`): offsets that
  rise, indices in range, finite numbers, known statuses;
- the **meaning** (:data:`CELLS_INVARIANTS`, :data:`PLAN_INVARIANTS`, run by :func:`validate`):
  a tree without cycles, counter-clockwise cells, unit normals, positive input bounds, valid
  tolerances. ``docs/artifacts.md`` lists them ("Checked on load"; a test compares the lists).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from bearnav_cli.errors import ArtifactError

__all__ = [
    "at_least",
    "cell_areas",
    "cell_polygon_problem",
    "CELLS_INVARIANTS",
    "CERTIFICATES",
    "check_cells_form",
    "check_plan_form",
    "finite_problem",
    "first",
    "in_range",
    "Invariant",
    "is_number",
    "landmarks_problem",
    "nodes_problem",
    "offsets_problem",
    "PLAN_INVARIANTS",
    "ragged_problem",
    "STATUSES",
    "tree_problem",
    "TREE_SHAPE",
    "unit_problem",
    "validate",
]


def is_number(value: Any) -> bool:
    """Whether ``value`` is a real number of Python or numpy, and not a bool (which is an int to Python)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


#: ``certificate`` values (DESIGN §3.3).
CERTIFICATES = ("funnel", "paper")
#: ``status`` values: ``CellStatus`` 0 certified, 1 relaxed, 2 not certified, 3 solver failure, 4 goal cell.
STATUSES = range(5)


@dataclass(frozen=True)
class Invariant:
    """One property an artifact must have to make sense.

    Attributes
    ----------
    field : str
        The entry (or map field) it is about, as the error message names it.
    rule : str
        What must hold, in a few words (the text docs/artifacts.md shows).
    check : callable
        ``check(artifact) -> str | None``: what is wrong, or None; or a pair ``(subfield, text)`` to name
        a part of the field (``params`` → ``params.rrtstar.seed``).
    """

    field: str
    rule: str
    check: Callable[[Any], Any]


def validate(invariants: tuple[Invariant, ...], artifact: Any, prefix: str = "") -> None:
    """Run ``invariants`` on ``artifact``; raise :class:`ArtifactError` naming the field of the first that fails.

    Parameters
    ----------
    invariants : tuple of Invariant
        The checks, run in order (``MAP_INVARIANTS``, ``INVARIANTS[kind]`` ...).
    artifact : Any
        What each ``Invariant.check`` is called with (an artifact, or the robot loader's view).
    prefix : str, default ""
        Put before the failing field's name in the error (``"map."`` when checking the map
        embedded in another artifact).

    Raises
    ------
    ArtifactError
        The first failing invariant's text, with ``field`` = ``prefix`` + its field (and
        subfield, ``params.rrtstar.seed``).
    """
    for invariant in invariants:
        problem = invariant.check(artifact)
        if problem is None:
            continue
        field = invariant.field
        if isinstance(problem, tuple):
            field, problem = f"{field}.{problem[0]}", problem[1]
        raise ArtifactError(problem, field=prefix + field)


# --------------------------------------------------------------------------- building blocks


def first(mask: np.ndarray) -> int | None:
    """Index of the first True of a bool array (flattened), or None."""
    hits = np.flatnonzero(mask)
    return int(hits[0]) if hits.size else None


def finite_problem(values: Any, allow_nan: bool = False) -> str | None:
    """What is not finite in ``values`` (any shape): NaN or infinity, or only infinity when ``allow_nan``."""
    values = np.asarray(values, float)
    bad = np.isinf(values) if allow_nan else ~np.isfinite(values)
    k = first(bad.reshape(-1))
    if k is None:
        return None
    return f"contains {'an infinity' if allow_nan else 'NaN or infinity'} (flat index {k})"


def at_least(values: Any, low: float, what: str, allow_nan: bool = False) -> str | None:
    """The first value below ``low`` (or not finite; NaN allowed when ``allow_nan``), described as ``what``.

    Parameters
    ----------
    values : array_like
        The numbers (any shape, read flat), in whatever unit ``low`` has.
    low : float
        The least value allowed.
    what : str
        What they must be, for the message (``"zero or positive"``).
    allow_nan : bool, default False
        NaN passes (infinities still fail).
    """
    values = np.asarray(values, float).reshape(-1)
    problem = finite_problem(values, allow_nan)
    if problem is not None:
        return problem
    k = first(~np.isnan(values) & (values < low)) if allow_nan else first(values < low)
    return None if k is None else f"must be {what}, got {values[k]:g} at index {k}"


def in_range(values: np.ndarray, low: int, high: int) -> str | None:
    """The first integer of ``values`` outside ``low..high`` (inclusive).

    Parameters
    ----------
    values : ndarray of int, shape (M,)
        Indices or codes.
    low, high : int
        The least and the greatest value allowed.
    """
    k = first((values < low) | (values > high))
    return None if k is None else f"must lie in {low}..{high}, got {int(values[k])} at index {k}"


def offsets_problem(offsets: np.ndarray, total: int, count: int) -> str | None:
    """``count + 1`` offsets from 0, never decreasing, to ``total`` (coords + offsets, DESIGN §3.1).

    Parameters
    ----------
    offsets : ndarray of int, shape (count + 1,)
        Where each item's rows begin.
    total : int
        The number of rows (``len(coords)``).
    count : int
        The number of items.
    """
    if len(offsets) != count + 1:
        return f"expected {count + 1} offsets, got {len(offsets)}"
    if offsets[0] != 0 or offsets[-1] != total or np.any(np.diff(offsets) < 0):
        return f"offsets must start at 0, never decrease and end at {total}"
    return None


def ragged_problem(coords: np.ndarray, offsets: np.ndarray) -> str | None:
    """Offsets (shape (C + 1,), at least one) that do not rise from 0 to ``len(coords)``."""
    if len(offsets) == 0 or offsets[0] != 0 or offsets[-1] != len(coords) or np.any(np.diff(offsets) < 0):
        return "offsets must rise from 0 to the number of rows"
    return None


def tree_problem(nodes: np.ndarray, parent: np.ndarray) -> str | None:
    """``parent == -1`` exactly at node 0, indices in range, and every chain ends at node 0 (no cycle).

    Pointer doubling: after k rounds ``up[i]`` is the ``2^k``-th ancestor of ``i`` (the root being its
    own parent), so ``ceil(log2 N) + 1`` rounds take every node of a tree to the root whatever its
    depth (< N), while a node on or above a cycle never gets there, whatever the cycle's length.
    """
    n = len(nodes)
    if n == 0 or len(parent) != n:
        return f"expected one parent per node ({n} nodes, {len(parent)} parents)"
    if parent[0] != -1 or np.count_nonzero(parent == -1) != 1:
        return "must be -1 exactly at node 0 (the root)"
    k = first((parent < -1) | (parent >= n))
    if k is not None:
        return f"node {k} has parent {int(parent[k])}, out of range 0..{n - 1}"
    up = np.array(parent, np.int64)
    up[0] = 0
    for _ in range(max(1, math.ceil(math.log2(n))) + 1):
        up = up[up]
    k = first(up != 0)
    return None if k is None else f"node {k}'s parent chain never reaches the root (a cycle)"


def nodes_problem(artifact: Any) -> str | None:
    """Finite node positions, node 0 at the goal of the artifact's map (within ``10·tol``)."""
    nodes, map_ = artifact.nodes, artifact.map
    problem = finite_problem(nodes)
    if problem is None and len(nodes) and not np.all(np.abs(nodes[0] - map_.goal) <= 10 * map_.tol):
        problem = f"node 0 {nodes[0].tolist()} is not the goal {np.asarray(map_.goal).tolist()}"
    return problem


def cell_areas(cells: Any) -> np.ndarray:
    """The signed (shoelace) area of every cell polygon, shape (C,), map units² (positive when CCW).

    ``cells`` is anything with ``cell_vertices`` (shape (V, 2)) and ``cell_vertex_offsets`` (shape
    (C + 1,)): Cells, Plan's cells, :class:`~bearnav_cli.runtime.plan_arrays.PlanArrays`. Every cell
    needs at least one vertex (:func:`cell_polygon_problem` asks for three).
    """
    offsets, verts = cells.cell_vertex_offsets, cells.cell_vertices
    if not len(verts):
        return np.zeros(len(offsets) - 1)
    following = np.arange(len(verts)) + 1
    following[offsets[1:] - 1] = offsets[:-1]
    x, y = verts[:, 0], verts[:, 1]
    return np.add.reduceat(x * y[following] - x[following] * y, offsets[:-1]) / 2


def cell_polygon_problem(cells: Any) -> str | None:
    """Each cell a counter-clockwise polygon of 3 or more vertices with positive area (shoelace)."""
    counts = np.diff(cells.cell_vertex_offsets)
    k = first(counts < 3)
    if k is not None:
        return f"cell {k} has {int(counts[k])} vertices (at least 3 are needed)"
    if not len(cells.cell_vertices):
        return None
    area = cell_areas(cells)
    k = first(~(area > 0))
    return None if k is None else f"cell {k} is not a counter-clockwise polygon of positive area (area {area[k]:.3g})"


def unit_problem(vectors: np.ndarray, rows: np.ndarray | None = None) -> str | None:
    """The first row of ``vectors`` (shape (M, 2)) whose norm is not 1 (within 1e-6), among ``rows`` (bool, (M,))."""
    norms = np.hypot(vectors[:, 0], vectors[:, 1])
    bad = ~(np.abs(norms - 1.0) <= 1e-6)
    if rows is not None:
        bad &= rows
    k = first(bad)
    return None if k is None else f"row {k} has norm {norms[k]:.6g}, expected 1"


def landmarks_problem(landmarks: np.ndarray, map_landmarks: np.ndarray) -> str | None:
    """``plan.npz``'s ``landmarks`` (shape (L, 2)) must be the embedded map's, exactly."""
    if np.shape(landmarks) == np.shape(map_landmarks) and np.array_equal(landmarks, map_landmarks):
        return None
    return "landmarks differ from the embedded map's"


def _s_problem(cells: Any) -> str | None:
    problem = at_least(cells.s_min, 0.0, "zero or positive")
    if problem is not None:
        return problem
    k = first(cells.s_min > cells.s_max * (1 + 1e-9) + cells.map.tol)
    return None if k is None else f"cell {k}: s_min {cells.s_min[k]:g} exceeds s_max {cells.s_max[k]:g}"


def _coverage_problem(value: float) -> str | None:
    if math.isnan(value) or 0.0 <= value <= 1.0:
        return None
    return f"must lie in [0, 1] (or be NaN), got {value:g}"


def _goal_tolerance_problem(plan: Any) -> str | None:
    value, diagonal = float(plan.goal_tolerance), float(plan.map.diagonal)
    if math.isfinite(value) and 0 < value < diagonal:
        return None
    return f"must be finite, positive and below the map's diagonal {diagonal:g}, got {value:g}"


def _tolerance_problem(values: Any, allow_inf: bool = False) -> str | None:
    values = np.asarray(values, float)
    if allow_inf:  # +inf is a constant field's δ_c; −inf is never a tolerance
        values = np.where(values == np.inf, 0.0, values)
    return at_least(values, 0.0, "zero or positive (or NaN)", allow_nan=True)


# --------------------------------------------------------------------------- form


def _fail(problem: str | None, field: str) -> None:
    if problem is not None:
        raise ArtifactError(problem, field=field)


def check_cells_form(cells: Any) -> None:
    """Raise :class:`ArtifactError` unless the cells' arrays can be indexed as their layout says.

    What :class:`~bearnav_cli.datatypes.Cells` checks once its arrays have their dtypes and shapes,
    and what the robot's loader checks of a ``plan.npz``: the coords + offsets pairs, the root at
    node 0, every index in range (nodes, landmarks of ``cells.map``, local exit rows), finite
    coordinates, a known ``certificate``, the exit insets and ``lookahead``.

    Parameters
    ----------
    cells : Cells or the robot loader's view
        The arrays of ``ENTRIES["cells"]`` as attributes, with dtypes and shapes checked, and ``map``.

    Raises
    ------
    ArtifactError
        Naming the field and what is wrong.
    """
    for coords, offsets in (
        ("cell_A", "cell_row_offsets"),
        ("cbf_A", "cbf_offsets"),
        ("cell_vertices", "cell_vertex_offsets"),
    ):
        _fail(ragged_problem(getattr(cells, coords), getattr(cells, offsets)), f"{coords} offsets")
    n, n_lm, parent = len(cells.nodes), len(cells.map.landmarks), cells.parent
    if n == 0 or parent[0] != -1 or np.count_nonzero(parent == -1) != 1:
        raise ArtifactError("parent must be -1 exactly at node 0", field="parent")
    if np.any((cells.cell_node < 0) | (cells.cell_node >= n)):
        raise ArtifactError("cell_node index out of range", field="cell_node")
    if np.any((cells.fixed_landmark < 0) | (cells.fixed_landmark >= n_lm)):
        raise ArtifactError("landmark index out of range", field="fixed_landmark")
    if not np.array_equal(np.diff(cells.cell_row_offsets), np.diff(cells.cell_vertex_offsets)):
        raise ArtifactError("one row per polygon edge expected", field="cell_row_offsets")
    for name in (
        "nodes",
        "collision_samples",
        "cell_A",
        "cell_b",
        "cell_vertices",
        "exit_point",
        "exit_dir",
        "cbf_A",
        "cbf_b",
        "s_min",
        "s_max",
    ):
        if not np.all(np.isfinite(getattr(cells, name))):
            raise ArtifactError("contains NaN or infinity", field=name)
    if cells.certificate not in CERTIFICATES:
        raise ArtifactError(f"must be one of {', '.join(CERTIFICATES)}, got {cells.certificate!r}", field="certificate")
    counts = np.diff(cells.cell_row_offsets)
    goal = parent[cells.cell_node] == -1
    exit_row = cells.cell_exit_row
    if np.any(exit_row[goal] != -1) or np.any((exit_row[~goal] < 0) | (exit_row[~goal] >= counts[~goal])):
        raise ArtifactError("must index one of the cell's rows (-1 exactly for the goal cell)", field="cell_exit_row")
    if not np.all(np.isfinite(cells.cell_rank)):
        raise ArtifactError("contains NaN or infinity", field="cell_rank")
    inset = cells.exit_inset
    if not (np.all(np.isnan(inset[goal])) and np.all(np.isfinite(inset[~goal]) & (inset[~goal] >= 0))):
        raise ArtifactError(
            "must be finite and zero or positive in every edge cell and NaN in the goal cell", field="exit_inset"
        )
    lookahead = float(cells.lookahead)
    if not (math.isfinite(lookahead) and lookahead >= 0):
        raise ArtifactError(f"must be finite and zero or positive, got {lookahead:g}", field="lookahead")


def check_plan_form(plan: Any) -> None:
    """Raise :class:`ArtifactError` unless the controllers' arrays of a plan can be used as they are.

    What :class:`~bearnav_cli.datatypes.Plan` checks once its arrays have their dtypes and shapes,
    and the robot's loader of a ``plan.npz``: finite gains and constants, known statuses.

    Parameters
    ----------
    plan : Plan or the robot loader's view
        ``gain`` (C, 2, 2L), ``c_v``, ``u_max`` and ``status`` (C,) as attributes.

    Raises
    ------
    ArtifactError
        Naming the field and what is wrong.
    """
    for name in ("gain", "c_v", "u_max"):
        if not np.all(np.isfinite(getattr(plan, name))):
            raise ArtifactError("contains NaN or infinity", field=name)
    if np.any((plan.status < STATUSES.start) | (plan.status >= STATUSES.stop)):
        raise ArtifactError(f"status must be {STATUSES.start}..{STATUSES.stop - 1}", field="status")


# --------------------------------------------------------------------------- meaning

#: The tree every tree-carrying artifact holds (trees, and the cells' nodes and parents).
TREE_SHAPE: tuple[Invariant, ...] = (
    Invariant("parent", "-1 exactly at node 0, indices in range, every chain ends at node 0 (no cycle)",
              lambda t: tree_problem(t.nodes, t.parent)),
    Invariant("nodes", "finite; node 0 is the goal", nodes_problem),
)  # fmt: skip

#: What ``cells.npz`` (and the cells of ``plan.npz``) must satisfy (besides their map's invariants).
CELLS_INVARIANTS: tuple[Invariant, ...] = (
    *TREE_SHAPE,
    Invariant("cell_node", "distinct node indices in range",
              lambda c: None if len(np.unique(c.cell_node)) == len(c.cell_node) else "two cells share a node"),
    Invariant("cell_vertices", "each cell a counter-clockwise polygon of 3 or more vertices with positive area",
              cell_polygon_problem),
    Invariant("cell_A", "unit-norm rows", lambda c: unit_problem(c.cell_A)),
    Invariant("exit_dir", "a unit vector in every cell but the goal cell",
              lambda c: unit_problem(c.exit_dir, c.parent[c.cell_node] >= 0)),
    Invariant("s_min", "0 <= s_min <= s_max", _s_problem),
    Invariant("cell_flags", "only the known flag bits (0 to 31)", lambda c: in_range(c.cell_flags, 0, 31)),
    Invariant("cell_rank", "zero or positive", lambda c: at_least(c.cell_rank, 0.0, "zero or positive")),
    Invariant("free_coverage", "in [0, 1], or NaN", lambda c: _coverage_problem(float(c.free_coverage))),
)  # fmt: skip

#: What ``plan.npz`` adds to the cells' invariants (checked on ``plan.cells`` too).
PLAN_INVARIANTS: tuple[Invariant, ...] = (
    Invariant("goal_tolerance", "finite, positive and below the map's diagonal", _goal_tolerance_problem),
    Invariant("u_max", "positive", lambda p: at_least(p.u_max, np.nextafter(0.0, 1.0), "positive")),
    Invariant("c_v", "zero or positive", lambda p: at_least(p.c_v, 0.0, "zero or positive")),
    Invariant("c_h", "zero or positive, or NaN (no barrier rows)", lambda p: _tolerance_problem(p.c_h)),
    Invariant("margin_h", "finite or NaN", lambda p: finite_problem(p.margin_h, allow_nan=True)),
    Invariant("margin_v", "finite or NaN", lambda p: finite_problem(p.margin_v, allow_nan=True)),
    Invariant("tolerance", "zero or positive (+inf for a constant field), or NaN",
              lambda p: _tolerance_problem(p.tolerance, allow_inf=True)),
    Invariant("usable_tolerance", "finite and zero or positive, or NaN",
              lambda p: _tolerance_problem(p.usable_tolerance)),
    Invariant("plan_tolerance", "finite and zero or positive, or NaN",
              lambda p: _tolerance_problem([p.plan_tolerance])),
)  # fmt: skip
