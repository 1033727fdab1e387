"""Grasp planning: IK for pre-grasp, grasp and lift, a collision-free joint path, timing.

Whether this planner finds a complete plan for a grasp pose is the
planning-success label that trains the Reachability Predictor.

What the planner knows about the scene: the arm, the hand (fingers open) and the
table, nothing else. It does not model the objects, for two reasons. (1) The
paper decouples reachability from stability: p_r must depend on the pose and the
robot only, so its labels are collected on the robot + hand + table with no
objects, and the planner that executes grasps must be that same planner or the
labels would not describe it. (2) Collisions of the hand with the target and its
neighbours during the final approach are exactly what the stability CNN learns
from its physics trials. The transit from home to the pre-grasp stays high above
the clutter in practice (the pre-grasp retreats 10 cm along the approach axis).

Per grasp X_WG: IK for the grasp (SNOPT, position + orientation of the TCP, the
180-degree-rolled twin accepted since the jaws are symmetric), then the pre-grasp
and the lift seeded from it; a plain solve first and a collision-constrained
re-solve only if the plain solution collides (DRAKE_NOTES.md). The transit
home -> pre-grasp tries the straight joint-space edge first and falls back to
OMPL RRTConnect with Drake collision checking; approach and lift must be free
straight edges. The path is timed with zero-velocity cubic segments whose peak
speed stays within `speed_scale` of each joint's velocity limit.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou
from pydrake.common import Parallelism
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.parsing import ModelDirectives, ProcessModelDirectives
from pydrake.planning import RobotDiagramBuilder, SceneGraphCollisionChecker
from pydrake.solvers import SnoptSolver, SolverOptions
from pydrake.trajectories import PiecewisePolynomial

from drake_grasp.hand import LIFT_HEIGHT, MAX_HALF_OPENING, PREGRASP_DISTANCE, TCP_DEPTH, X_GT
from drake_grasp.paths import add_package
from drake_grasp.robots import RobotSpec
from drake_grasp.station import add_hand_coupler, filter_wrist_hand_collisions, robot_directives

ou.setLogLevel(ou.LogLevel.LOG_WARN)

# Bumped whenever a change can flip a planning-success label: label sets of another
# version are refused (collect_reachability's manifest records it).
PLANNER_VERSION = 2  # 2: pre-grasp, lift and path tried for every grasp IK solution
POSITION_TOLERANCE = 0.001  # [m]
ORIENTATION_TOLERANCE = np.radians(1.0)
LIFT_EXTRA = 0.05  # the hand rises 20 cm so that a held object, even pivoting, clears LIFT_HEIGHT
X_G_FLIP = RigidTransform(RotationMatrix.MakeZRotation(np.pi))  # same grasp, jaws swapped


_ompl_seeded = False


def seed_ompl_once(seed: int) -> None:
    """OMPL has one process-wide seed that can be set only before its first sample.

    Runs that must repeat exactly (simulate's episodes) therefore each get a fresh
    worker process; later planners in the same process continue OMPL's stream.
    """
    global _ompl_seeded
    if not _ompl_seeded:
        ou.RNG.setSeed(int(seed) % (2**31 - 1) + 1)
        _ompl_seeded = True


class PlanFailure(enum.Enum):
    NO_IK_GRASP = "no IK for the grasp"
    NO_IK_PREGRASP = "no IK for the pre-grasp"
    NO_IK_LIFT = "no IK for the lift"
    NO_PATH = "no collision-free path"
    TIMEOUT = "time budget exceeded"


# How far a plan got before failing (the furthest stage is reported).
STAGE_ORDER = [PlanFailure.NO_IK_GRASP, PlanFailure.NO_IK_PREGRASP, PlanFailure.NO_IK_LIFT,
               PlanFailure.NO_PATH, PlanFailure.TIMEOUT]


@dataclass
class GraspPlan:
    q_pregrasp: np.ndarray
    q_grasp: np.ndarray
    q_lift: np.ndarray
    approach: PiecewisePolynomial  # start -> (transit) -> pre-grasp -> grasp
    lift: PiecewisePolynomial  # grasp -> lift


@dataclass
class PlanResult:
    plan: GraspPlan | None
    failure: PlanFailure | None
    seconds: float

    @property
    def success(self) -> bool:
        return self.plan is not None


class _Deadline:
    def __init__(self, budget_s: float):
        self.end = time.perf_counter() + budget_s

    def left(self) -> float:
        return self.end - time.perf_counter()


class GraspPlanner:
    """Plans home -> pre-grasp -> grasp -> lift for one arm on its own planning model.

    The arm's base is at the world origin; `table_height` moves the table top
    (0 in the station; another value models a new setup for retraining the RP).
    """

    def __init__(self, robot: RobotSpec, *, time_budget_s: float = 2.0, speed_scale: float = 0.8,
                 seed: int = 0, ik_seeds: int = 2, table_height: float = 0.0):
        self.robot = robot
        self.time_budget_s = time_budget_s
        self.speed_scale = speed_scale
        self.ik_seeds = ik_seeds
        self.rng = np.random.default_rng(seed)
        seed_ompl_once(seed)

        builder = RobotDiagramBuilder(time_step=0.0)
        plant = builder.plant()
        add_package(builder.parser().package_map())
        ProcessModelDirectives(ModelDirectives(directives=robot_directives(robot, table_height)), plant,
                               builder.parser())
        self.arm = plant.GetModelInstanceByName(robot.name)
        self.hand = plant.GetModelInstanceByName("hand")
        add_hand_coupler(plant, self.hand)
        plant.Finalize()
        filter_wrist_hand_collisions(plant, builder.scene_graph(), robot, self.arm, self.hand)
        self.checker = SceneGraphCollisionChecker(
            model=builder.Build(), robot_model_instances=[self.arm, self.hand],
            edge_step_size=0.05, env_collision_padding=0.002, self_collision_padding=0.002,
            implicit_context_parallelism=Parallelism(1),
        )
        self.plant = self.checker.plant()
        self._checker_context = self.checker.MakeStandaloneModelContext()
        self._plant_context = self._checker_context.plant_context()
        self.tcp = self.plant.GetFrameByName("tcp", self.hand)
        self._arm_slice = self._positions_slice(self.arm)
        self._q_full = self.plant.GetPositions(self._plant_context).copy()
        self._q_full[self._positions_slice(self.hand)] = MAX_HALF_OPENING
        self.q_lower, self.q_upper = robot.limits()
        self._p_shoulder, flange_reach = robot.shoulder_and_reach()
        self._reach = flange_reach + TCP_DEPTH
        self._solver = SnoptSolver()
        self._options = SolverOptions()
        self._options.SetOption(SnoptSolver.id(), "Major iterations limit", 100)

    # -- configuration helpers ----------------------------------------------------------
    def _positions_slice(self, instance) -> slice:
        start = self.plant.GetJointByName(
            self.robot.joint_names[0] if instance == self.arm else "left_finger_joint", instance
        ).position_start()
        return slice(start, start + self.plant.num_positions(instance))

    def full(self, q_arm: np.ndarray) -> np.ndarray:
        q = self._q_full.copy()
        q[self._arm_slice] = q_arm
        return q

    def is_free(self, q_arm: np.ndarray) -> bool:
        return bool(self.checker.CheckConfigCollisionFree(self.full(q_arm)))

    def is_edge_free(self, q1: np.ndarray, q2: np.ndarray) -> bool:
        return bool(self.checker.CheckEdgeCollisionFree(self.full(q1), self.full(q2)))

    def tcp_pose(self, q_arm: np.ndarray) -> RigidTransform:
        self.plant.SetPositions(self._plant_context, self.full(q_arm))
        return self.tcp.CalcPoseInWorld(self._plant_context)

    # -- IK ----------------------------------------------------------------------------
    def solve_ik(self, X_WT: RigidTransform, q_seed: np.ndarray, deadline: _Deadline,
                 ) -> np.ndarray | None:
        """Arm configuration putting the TCP at X_WT collision-free, or None."""
        q = self.solve_ik_once(X_WT, q_seed, with_collision=False)
        if q is None:
            return None
        if self.is_free(q):
            return q
        if deadline.left() <= 0:
            return None
        q = self.solve_ik_once(X_WT, q, with_collision=True)
        return q if q is not None and self.is_free(q) else None

    def solve_ik_once(self, X_WT: RigidTransform, q_seed: np.ndarray, *, with_collision: bool,
                       ) -> np.ndarray | None:
        ik = InverseKinematics(self.plant, self._plant_context, with_joint_limits=True)
        q = ik.q()
        p = X_WT.translation()
        ik.AddPositionConstraint(self.tcp, np.zeros(3), self.plant.world_frame(),
                                 p - POSITION_TOLERANCE, p + POSITION_TOLERANCE)
        ik.AddOrientationConstraint(self.plant.world_frame(), X_WT.rotation(), self.tcp,
                                    RotationMatrix(), ORIENTATION_TOLERANCE)
        hand = self._positions_slice(self.hand)
        prog = ik.get_mutable_prog()
        prog.AddBoundingBoxConstraint(MAX_HALF_OPENING, MAX_HALF_OPENING, q[hand])
        seed_full = self.full(q_seed)
        prog.AddQuadraticErrorCost(np.eye(len(q_seed)), q_seed, q[self._arm_slice])
        if with_collision:
            ik.AddMinimumDistanceLowerBoundConstraint(0.002, 0.02)
        try:
            result = self._solver.Solve(prog, seed_full, self._options)
        except RuntimeError:
            # FCL's GJK/EPA can throw on near-degenerate capsule-box distance queries
            # inside the collision constraint; count that solve as failed.
            return None
        if not result.is_success():
            return None
        return result.GetSolution(q)[self._arm_slice]

    def _grasp_solutions(self, X_WG: RigidTransform, q_start: np.ndarray, deadline: _Deadline,
                         ) -> Iterator[tuple[np.ndarray, RigidTransform]]:
        """IK solutions for the grasp or its jaw-swapped twin, from the start and random seeds."""
        if np.linalg.norm((X_WG @ X_GT).translation() - self._p_shoulder) > self._reach:
            return  # beyond the arm's reach: no solver call can succeed
        seeds = [q_start] + [self.rng.uniform(self.q_lower, self.q_upper)
                             for _ in range(self.ik_seeds)]
        for seed in seeds:
            for X in (X_WG, X_WG @ X_G_FLIP):
                if deadline.left() <= 0:
                    return
                q = self.solve_ik(X @ X_GT, seed, deadline)
                if q is not None:
                    yield q, X

    # -- paths -------------------------------------------------------------------------
    def _make_ompl(self):
        """A fresh OMPL space per query: nothing of OMPL's outlives it (no leak report at exit)."""
        n = self.robot.num_joints
        space = ob.RealVectorStateSpace(n)
        bounds = ob.RealVectorBounds(n)
        for i in range(n):
            bounds.setLow(i, float(self.q_lower[i]))
            bounds.setHigh(i, float(self.q_upper[i]))
        space.setBounds(bounds)
        si = ob.SpaceInformation(space)
        si.setStateValidityChecker(lambda s: self.is_free(np.array([s[i] for i in range(n)])))
        si.setStateValidityCheckingResolution(0.01)
        si.setup()
        return space, si

    def _rrt(self, q1: np.ndarray, q2: np.ndarray, budget_s: float) -> list[np.ndarray] | None:
        space, si = self._make_ompl()
        n = self.robot.num_joints
        start, goal = space.allocState(), space.allocState()
        for i in range(n):
            start[i], goal[i] = float(q1[i]), float(q2[i])
        pdef = ob.ProblemDefinition(si)
        pdef.setStartAndGoalStates(start, goal)
        planner = og.RRTConnect(si)
        planner.setProblemDefinition(pdef)
        planner.setup()
        solved = planner.solve(max(budget_s, 1e-3))
        if not pdef.hasExactSolution() or not bool(solved):
            return None
        path = pdef.getSolutionPath()
        og.PathSimplifier(si).reduceVertices(path)
        waypoints = [np.array([s[i] for i in range(n)]) for s in path.getStates()]
        if not all(self.is_edge_free(a, b) for a, b in zip(waypoints, waypoints[1:], strict=False)):
            return None  # OMPL's resolution missed a collision that Drake's edge check sees
        return waypoints

    def _transit(self, q1: np.ndarray, q2: np.ndarray, deadline: _Deadline) -> list[np.ndarray] | None:
        if self.is_edge_free(q1, q2):
            return [q1, q2]
        if deadline.left() <= 0:
            return None
        return self._rrt(q1, q2, deadline.left())

    # -- timing ------------------------------------------------------------------------
    def time_path(self, waypoints: list[np.ndarray], min_segment_s: float = 0.2,
                  ) -> PiecewisePolynomial:
        """Cubic segments with zero velocity at each waypoint, within the speed limits.

        A cubic from rest to rest over T has peak speed 1.5 |dq| / T.
        """
        v_max = np.asarray(self.robot.v_max) * self.speed_scale
        times = [0.0]
        for a, b in zip(waypoints, waypoints[1:], strict=False):
            times.append(times[-1] + max(min_segment_s, float(np.max(1.5 * np.abs(b - a) / v_max))))
        samples = np.column_stack(waypoints)
        return PiecewisePolynomial.CubicHermite(times, samples, np.zeros_like(samples))

    # -- the whole plan ----------------------------------------------------------------
    def plan(self, X_WG: RigidTransform | np.ndarray, q_start: np.ndarray | None = None) -> PlanResult:
        """Plans the grasp X_WG from q_start (default: home)."""
        t0 = time.perf_counter()
        deadline = _Deadline(self.time_budget_s)
        X_WG = X_WG if isinstance(X_WG, RigidTransform) else RigidTransform(np.asarray(X_WG))
        q_start = np.asarray(self.robot.q_home if q_start is None else q_start, dtype=float)

        def fail(reason: PlanFailure) -> PlanResult:
            if deadline.left() <= 0:
                reason = PlanFailure.TIMEOUT
            return PlanResult(None, reason, time.perf_counter() - t0)

        # Every grasp solution gets its pre-grasp, lift and path tried: one that
        # fails there (another IK branch) does not make the grasp unreachable.
        furthest = PlanFailure.NO_IK_GRASP
        for q_grasp, X in self._grasp_solutions(X_WG, q_start, deadline):
            waypoints = self._complete(X, q_grasp, q_start, deadline)
            if isinstance(waypoints, PlanFailure):
                furthest = max(furthest, waypoints, key=STAGE_ORDER.index)
                continue
            transit, q_pre, q_lift = waypoints
            approach = self.time_path(transit + [q_grasp], min_segment_s=0.6)
            lift = self.time_path([q_grasp, q_lift], min_segment_s=1.0)
            plan = GraspPlan(q_pregrasp=q_pre, q_grasp=q_grasp, q_lift=q_lift, approach=approach, lift=lift)
            return PlanResult(plan, None, time.perf_counter() - t0)
        return fail(furthest)

    def _complete(self, X_WG: RigidTransform, q_grasp: np.ndarray, q_start: np.ndarray, deadline: _Deadline,
                  ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray] | PlanFailure:
        """Pre-grasp, lift and a free path for one grasp solution: (transit, q_pre, q_lift) or a failure."""
        X_WT = X_WG @ X_GT
        X_WPre = X_WT @ RigidTransform([0.0, 0.0, -PREGRASP_DISTANCE])
        q_pre = self.solve_ik(X_WPre, q_grasp, deadline)
        if q_pre is None:
            return PlanFailure.NO_IK_PREGRASP
        X_WLift = RigidTransform(X_WT.rotation(), X_WT.translation() + [0, 0, LIFT_HEIGHT + LIFT_EXTRA])
        q_lift = self.solve_ik(X_WLift, q_grasp, deadline)
        if q_lift is None:
            return PlanFailure.NO_IK_LIFT
        if not (self.is_edge_free(q_pre, q_grasp) and self.is_edge_free(q_grasp, q_lift)):
            return PlanFailure.NO_PATH
        transit = self._transit(q_start, q_pre, deadline)
        if transit is None:
            return PlanFailure.NO_PATH
        return transit, q_pre, q_lift
