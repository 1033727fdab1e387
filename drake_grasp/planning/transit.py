"""Collision-free joint-space transit: OMPL RRTConnect with Drake collision checking, deterministic.

OMPL draws from a process-wide seed generator. Every query here reseeds it first
and ends after a fixed number of collision checks (not a wall-clock budget), so a
query's answer depends only on its inputs and its seed: not on the machine's load,
nor on the queries that ran before it in the same process.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

ou.setLogLevel(ou.LogLevel.LOG_WARN)

CHECK_RESOLUTION = 0.01  # OMPL's edge check step, as a fraction of the space's extent
LIMIT_TOLERANCE = 1e-6  # [rad] an end this far past a joint limit is rounding (seen: 1e-13): moved onto it


def seed_ompl(seed: int) -> None:
    """Reseeds OMPL's seed generator: the samplers made after this call repeat for the same seed.

    OMPL logs an error when this happens after its first sample (it assumes nobody
    reseeds mid-process); its generator is reseeded all the same, which the tests check.
    """
    ou.setLogLevel(ou.LogLevel.LOG_NONE)
    try:
        ou.RNG.setSeed(int(seed) % (2**31 - 2) + 1)
    finally:
        ou.setLogLevel(ou.LogLevel.LOG_WARN)


def rrt_connect(q_start: np.ndarray, q_goal: np.ndarray, *, is_free: Callable[[np.ndarray], bool],
                is_edge_free: Callable[[np.ndarray, np.ndarray], bool], q_lower: np.ndarray,
                q_upper: np.ndarray, max_checks: int, seed: int) -> list[np.ndarray] | None:
    """Waypoints from q_start to q_goal whose straight edges are all collision-free, or None.

    The search stops after `max_checks` state validity checks. The path's vertices
    are reduced by OMPL's simplifier, and every edge is confirmed with Drake's own
    edge check (OMPL's resolution could miss a thin collision). The path starts at
    `q_start` and ends at `q_goal` as given; an end past a joint limit by at most
    `LIMIT_TOLERANCE` is searched from the limit, one further out has no path.
    """
    ends = [within_limits(q, q_lower, q_upper) for q in (q_start, q_goal)]
    if any(q is None or not is_free(q) for q in ends):
        return None  # OMPL would wait for a valid goal forever: its termination counts checks only
    seed_ompl(seed)
    n = len(q_start)
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for i in range(n):
        bounds.setLow(i, float(q_lower[i]))
        bounds.setHigh(i, float(q_upper[i]))
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    checks = [0]

    def valid(state) -> bool:
        checks[0] += 1
        return is_free(np.array([state[i] for i in range(n)]))

    si.setStateValidityChecker(valid)
    si.setStateValidityCheckingResolution(CHECK_RESOLUTION)
    si.setup()
    start, goal = space.allocState(), space.allocState()
    for i in range(n):
        start[i], goal[i] = float(ends[0][i]), float(ends[1][i])
    problem = ob.ProblemDefinition(si)
    problem.setStartAndGoalStates(start, goal)
    planner = og.RRTConnect(si)
    planner.setProblemDefinition(problem)
    planner.setup()
    planner.solve(ob.PlannerTerminationCondition(lambda: checks[0] >= max_checks))
    if not problem.hasExactSolution():
        return None
    path = problem.getSolutionPath()
    og.PathSimplifier(si).reduceVertices(path)
    waypoints = [np.array([s[i] for i in range(n)]) for s in path.getStates()]
    waypoints[0], waypoints[-1] = np.array(q_start, dtype=float), np.array(q_goal, dtype=float)
    if not all(is_edge_free(a, b) for a, b in zip(waypoints, waypoints[1:], strict=False)):
        return None
    return waypoints


def within_limits(q: np.ndarray, q_lower: np.ndarray, q_upper: np.ndarray) -> np.ndarray | None:
    """q moved onto the joint limits it passes by at most `LIMIT_TOLERANCE`; None if it passes one further."""
    q = np.asarray(q, dtype=float)
    if np.any(q < q_lower - LIMIT_TOLERANCE) or np.any(q > q_upper + LIMIT_TOLERANCE):
        return None
    return np.clip(q, q_lower, q_upper)
