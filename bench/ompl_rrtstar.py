"""OMPL's ``RRTstar`` on a bearnav ``map.json``, as a whole process: the other side of ``bench/rrtstar_process.py``.

What a user of OMPL from Python would write to do what ``bearnav rrtstar`` does: read the map,
grow the tree rooted at the goal for a fixed number of iterations, write the tree to a file.
It reads ``map.json`` with :mod:`json` (the obstacles there are already inflated by the robot
radius), gives OMPL the state-validity callback of ``bench/rrtstar.py`` (one prepared shapely
point query against the union of the obstacles), range = ``--step``, other OMPL settings
default, and writes the tree's vertices and parent indices to an uncompressed npz. It imports
neither bearnav nor anything of ``bench/``, so its start-up is OMPL's, numpy's and shapely's only.

Run::

    python bench/ompl_rrtstar.py plans/kitchen/map.json -o /tmp/ompl.npz --iterations 1500 --step 1 --seed 1

One JSON line on stdout: ``solve_s`` (setup and solve, timed as ``bench/rrtstar.py`` times
OMPL), ``vertices`` and ``iterations``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
import shapely
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

#: OMPL's goal region radius, as a fraction of the step (as in ``bench/rrtstar.py``).
GOAL_THRESHOLD = 0.01


def obstacles_of(document: dict) -> shapely.Geometry:
    """The prepared union of the map's (inflated) obstacle polygons."""
    polygons = [shapely.Polygon(o["exterior"], o.get("holes") or None) for o in document["obstacles"]]
    union = shapely.union_all(polygons)
    shapely.prepare(union)
    return union


def main(argv: list[str] | None = None) -> None:
    """Read the map, run RRTstar for exactly ``--iterations`` iterations, write the tree, print the timing."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("map_json")
    parser.add_argument("-o", "--out", required=True, help="npz written with the tree (vertices, parent)")
    parser.add_argument("--iterations", type=int, required=True)
    parser.add_argument("--step", type=float, required=True, help="OMPL's range (map units)")
    parser.add_argument("--seed", type=int, default=1, help="OMPL's global seed (set before the first sampler)")
    args = parser.parse_args(argv)

    ou.setLogLevel(ou.LOG_WARN)
    ou.RNG.setSeed(args.seed)
    with open(args.map_json) as handle:
        document = json.load(handle)
    obstacles = obstacles_of(document)
    intersects_xy = shapely.intersects_xy

    def valid(state: object) -> bool:
        return not intersects_xy(obstacles, state[0], state[1])

    t0 = time.perf_counter()
    xmin, ymin, xmax, ymax = (float(v) for v in document["bounds"])
    space = ob.RealVectorStateSpace(2)
    bounds = ob.RealVectorBounds(2)
    for k, (low, high) in enumerate(((xmin, xmax), (ymin, ymax))):
        bounds.setLow(k, low)
        bounds.setHigh(k, high)
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    si.setStateValidityChecker(valid)
    si.setup()
    start, goal = si.allocState(), si.allocState()
    for k in range(2):
        start[k] = float(document["goal"][k])
        goal[k] = float(document["starts"][0][k])
    problem = ob.ProblemDefinition(si)
    problem.setStartAndGoalStates(start, goal, GOAL_THRESHOLD * args.step)
    planner = og.RRTstar(si)
    planner.setRange(args.step)
    planner.setProblemDefinition(problem)
    planner.setup()
    planner.solve(ob.PlannerTerminationCondition(lambda: planner.numIterations() >= args.iterations))
    solve_s = time.perf_counter() - t0

    data = ob.PlannerData(si)
    planner.getPlannerData(data)
    n = data.numVertices()
    vertices = np.array([[data.getVertex(i).getState()[k] for k in range(2)] for i in range(n)])
    parent = np.full(n, -1, np.int64)
    for i in range(n):  # RRT*'s planner data keeps one edge per vertex: parent -> child
        for child in data.getEdges(i):
            parent[child] = i
    np.savez(args.out, vertices=vertices, parent=parent)
    json.dump({"solve_s": solve_s, "vertices": n, "iterations": planner.numIterations()}, sys.stdout)
    print()


if __name__ == "__main__":
    main()
