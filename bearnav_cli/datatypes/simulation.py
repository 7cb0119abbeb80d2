"""The closed-loop runs of ``sim.npz``: :class:`Simulation`, the run :class:`Outcome` and their invariants."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from bearnav_cli.datatypes.frozen import ArraysOnMap, data_keys, freeze, freeze_fields
from bearnav_cli.datatypes.map_ import Map
from bearnav_cli.errors import ArtifactError
from bearnav_cli.runtime.invariants import Invariant
from bearnav_cli.runtime.invariants import at_least as _at_least
from bearnav_cli.runtime.invariants import finite_problem as _finite_problem
from bearnav_cli.runtime.invariants import in_range as _in_range
from bearnav_cli.runtime.invariants import nodes_problem as _nodes_problem
from bearnav_cli.runtime.invariants import offsets_problem as _offsets_problem
from bearnav_cli.runtime.invariants import tree_problem as _tree_problem
from bearnav_cli.runtime.schema import ENTRIES

__all__ = ["Outcome", "Simulation", "SIMULATION_INVARIANTS", "SIMULATION_KEYS"]


class Outcome(enum.IntEnum):
    """How a run of ``bearnav simulate`` ended (``sim.npz`` ``outcome``, ALGORITHMS §7.4)."""

    SUCCESS = 0  # within goal_tolerance of the goal
    COLLISION = 1  # a step segment met the inflated obstacles or left the bounds (or the start was not free)
    STALL = 2  # field below 1e-6·u_max, or no net progress over the progress window with a fix
    TIMEOUT = 3  # more than max_steps steps
    LOST = 4  # fewer than two usable landmarks for longer than hold_time


#: Data keys of ``sim.npz`` besides ``map`` and ``manifest`` (DESIGN §3; ``ENTRIES["simulation"]``).
SIMULATION_KEYS = data_keys("simulation")


@dataclass(frozen=True, eq=False)  # arrays inside: identity equality, a hash that works
class Simulation(ArraysOnMap):
    """The closed-loop runs of ``bearnav simulate`` (``sim.npz``; metrics in ``sim.json``), R runs.

    What :func:`bearnav_cli.stages.simulate.rollout` returns (``stats`` empty) and what
    :func:`~bearnav_cli.stages.simulate.run` saves (``stats`` the metrics).

    Attributes
    ----------
    map : Map
        The plan's map (the world the robots drove in may differ: ``rollout(world=...)``).
    starts, final_position : ndarray, shape (R, 2)
        Where each run began and ended (map units).
    outcome : ndarray of int8, shape (R,)
        :class:`Outcome` values: 0 success, 1 collision, 2 stall, 3 timeout, 4 lost (ALGORITHMS §7.4).
    steps, left_cell, approach_steps, hold_steps, certified_steps : ndarray of int64, shape (R,)
        Euler steps; relocations through a side face (§7.3); steps driven straight to a tree node from
        outside every safe set; steps without a usable reconstruction (§7.5); steps covered by the
        composed certificate (§11.4; 0 for ``paper`` plans).
    start_in_domain : ndarray of bool, shape (R,)
        The start lies in the certified domain ``D`` (a funnel plan's cells, ALGORITHMS §11.3).
    final_cell, max_steps : ndarray of int64, shape (R,)
        Active cell at the end (``-1`` if the start was not free or never had a fix); step limit of the run.
    time, path_length, route_length, min_clearance : ndarray, shape (R,)
        Seconds (``steps · dt``); path length; the tree route from the start (``‖x₀ − x_n‖ +
        cost(n)``); the smallest distance from the inflated obstacles and the walls (map units).
    trajectory_coords, trajectory_cells, trajectory_heading, trajectory_offsets : ndarray
        Shapes (P, 2), (P,), (P,), (R + 1,): run ``r`` is ``coords[o[r]:o[r + 1]]`` (start first,
        ``steps + 1`` points) with the cell whose field moved the robot on from each point (the active
        cell at the end for the last point) and the camera heading (rad); empty when not recorded.
    nodes, parent : ndarray, shapes (N, 2), (N,)
        The simplified tree the plan was built on.
    cell_vertices, cell_vertex_offsets, cell_status : ndarray, shapes (V, 2), (C + 1,), (C,)
        The plan's cells and their synthesis status (for plots).
    speed, dt, eps_sw, goal_tolerance : float
        The loop constants used: the speed ``dt`` and ``eps_sw`` are scaled by (map units / s), the
        Euler step (s), the switching radius and the success radius (map units).
    stats : dict
        The metrics of ``sim.json`` (empty from ``rollout``).
    """

    map: Map
    starts: np.ndarray
    outcome: np.ndarray
    steps: np.ndarray
    time: np.ndarray
    path_length: np.ndarray
    route_length: np.ndarray
    left_cell: np.ndarray
    approach_steps: np.ndarray
    hold_steps: np.ndarray
    certified_steps: np.ndarray
    start_in_domain: np.ndarray
    min_clearance: np.ndarray
    final_position: np.ndarray
    final_cell: np.ndarray
    max_steps: np.ndarray
    trajectory_coords: np.ndarray
    trajectory_cells: np.ndarray
    trajectory_heading: np.ndarray
    trajectory_offsets: np.ndarray
    nodes: np.ndarray
    parent: np.ndarray
    cell_vertices: np.ndarray
    cell_vertex_offsets: np.ndarray
    cell_status: np.ndarray
    speed: float
    dt: float
    eps_sw: float
    goal_tolerance: float
    stats: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stats", freeze(dict(self.stats)))
        arrays = tuple(name for name in SIMULATION_KEYS if ENTRIES["simulation"][name].ndim)
        for name in SIMULATION_KEYS:
            if name not in arrays:
                object.__setattr__(self, name, float(getattr(self, name)))
        freeze_fields(self, "simulation", arrays, {"R": len(np.asarray(self.outcome))})
        points = len(self.trajectory_coords)
        if len(self.trajectory_cells) != points or len(self.trajectory_heading) != points:
            raise ArtifactError("trajectory arrays differ in length", field="trajectory_cells")
        if points and (self.trajectory_offsets[0] != 0 or self.trajectory_offsets[-1] != points):
            raise ArtifactError("offsets do not span the trajectory points", field="trajectory_offsets")

    def __len__(self) -> int:
        return len(self.outcome)

    def trajectory(self, r: int) -> np.ndarray:
        """Positions of run ``r``, shape (steps + 1, 2) (empty when not recorded)."""
        o = self.trajectory_offsets
        return self.trajectory_coords[o[r] : o[r + 1]]

    def cells_along(self, r: int) -> np.ndarray:
        """Cells along run ``r``, aligned with :meth:`trajectory`."""
        o = self.trajectory_offsets
        return self.trajectory_cells[o[r] : o[r + 1]]

    def counts(self) -> dict[str, int]:
        """Number of runs per outcome name (every outcome listed)."""
        return {o.name.lower(): int(np.count_nonzero(self.outcome == o)) for o in Outcome}

    @property
    def success_rate(self) -> float:
        """Fraction of successful runs (NaN without runs)."""
        return float(np.mean(self.outcome == Outcome.SUCCESS)) if len(self) else math.nan

    def success_rate_of(self, runs: np.ndarray) -> float:
        """Fraction of successful runs among ``runs`` (bool mask, shape (R,)); NaN when it selects none."""
        done = self.outcome[runs] == Outcome.SUCCESS
        return float(np.mean(done)) if len(done) else math.nan

    @property
    def certified_fraction(self) -> float:
        """Steps covered by the composed certificate over all steps (ALGORITHMS §11.4; 0 without steps)."""
        return float(self.certified_steps.sum() / max(1, self.steps.sum()))

    def arrays(self) -> dict[str, np.ndarray]:
        """The data entries of ``sim.npz`` (without ``manifest`` and ``map``)."""
        return {name: np.asarray(getattr(self, name)) for name in SIMULATION_KEYS}


def _sim_cells_problem(sim: Simulation) -> str | None:
    return _offsets_problem(sim.cell_vertex_offsets, len(sim.cell_vertices), len(sim.cell_status)) or (
        _finite_problem(sim.cell_vertices)
    )


def _sim_trajectory_problem(sim: Simulation) -> str | None:
    return _offsets_problem(sim.trajectory_offsets, len(sim.trajectory_coords), len(sim.outcome))


#: What ``sim.npz`` must satisfy (besides its map's invariants).
SIMULATION_INVARIANTS: tuple[Invariant, ...] = (
    Invariant("parent", "-1 exactly at node 0, indices in range, every chain ends at node 0 (no cycle)",
              lambda s: _tree_problem(s.nodes, s.parent)),
    Invariant("nodes", "finite; node 0 is the goal", lambda s: _nodes_problem(s)),
    Invariant("outcome", "0 to 4", lambda s: _in_range(s.outcome, 0, 4)),
    Invariant("steps", "zero or positive", lambda s: _in_range(s.steps, 0, np.iinfo(np.int64).max)),
    Invariant("starts", "finite", lambda s: _finite_problem(s.starts)),
    Invariant("final_position", "finite", lambda s: _finite_problem(s.final_position)),
    Invariant("time", "finite, zero or positive", lambda s: _at_least(s.time, 0.0, "zero or positive")),
    Invariant("path_length", "finite, zero or positive", lambda s: _at_least(s.path_length, 0.0, "zero or positive")),
    Invariant("min_clearance", "not NaN", lambda s: None if not np.isnan(s.min_clearance).any() else "contains NaN"),
    Invariant("trajectory_offsets", "R + 1 offsets from 0, never decreasing, to the number of points",
              _sim_trajectory_problem),
    Invariant("trajectory_coords", "finite", lambda s: _finite_problem(s.trajectory_coords)),
    Invariant("trajectory_heading", "finite", lambda s: _finite_problem(s.trajectory_heading)),
    Invariant("trajectory_cells", "-1 (no cell) or a cell index",
              lambda s: _in_range(s.trajectory_cells, -1, len(s.cell_status) - 1)),
    Invariant("cell_status", "0 to 4", lambda s: _in_range(s.cell_status, 0, 4)),
    Invariant("cell_vertex_offsets", "C + 1 offsets from 0, never decreasing, to the number of vertices; finite "
              "vertices", _sim_cells_problem),
    Invariant("certified_steps", "zero or positive, at most steps",
              lambda s: _in_range(s.certified_steps, 0, np.iinfo(np.int64).max)
              or (None if (s.certified_steps <= s.steps).all() else "more than steps")),
    Invariant("final_cell", "-1 (no cell) or a cell index",
              lambda s: _in_range(s.final_cell, -1, len(s.cell_status) - 1)),
    Invariant("dt", "finite and positive", lambda s: _positive_scalar(s.dt)),
    Invariant("speed", "finite and positive", lambda s: _positive_scalar(s.speed)),
    Invariant("eps_sw", "finite and positive", lambda s: _positive_scalar(s.eps_sw)),
    Invariant("goal_tolerance", "finite and positive", lambda s: _positive_scalar(s.goal_tolerance)),
)  # fmt: skip


def _positive_scalar(value: float) -> str | None:
    return None if math.isfinite(value) and value > 0 else f"got {value:g}"
