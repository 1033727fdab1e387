"""Grasp planning: IK for pre-grasp, grasp and lift, a collision-free joint path, timing.

Whether this planner finds a complete plan for a grasp pose is the
planning-success label that trains the Reachability Predictor, so the planner is
deterministic: its searches are bounded by counts (IK solves, collision checks),
never by wall-clock time, and its random draws come from its own seeded streams.

What the planner knows about the scene: the arm, the hand (fingers open) and the
table, nothing else (its own kinematic plant from the one plant assembly). It
does not model the objects, for two reasons. (1) The paper decouples reachability
from stability: p_r must depend on the pose and the robot only, so its labels are
collected on the robot + hand + table with no objects, and the planner that
executes grasps must be that same planner or the labels would not describe it.
(2) Collisions of the hand with the target and its neighbours during the final
approach are exactly what the stability CNN learns from its physics trials.

Per grasp X_WG: IK for the grasp (SNOPT, position + orientation of the TCP, the
180-degree-rolled twin accepted since the jaws are symmetric), then the pre-grasp
and the lift seeded from it; a plain solve first and a collision-constrained
re-solve only if the plain solution collides (a collision constraint makes failing
solves about ten times slower). The transit home -> pre-grasp tries the straight
joint-space edge first and falls back to OMPL RRTConnect; approach and lift must be
free straight edges. The path is timed with rest-to-rest cubic segments whose peak
speed stays within `speed_scale` of each joint's velocity limit.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from pydrake.common import Parallelism
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.planning import RobotDiagramBuilder, SceneGraphCollisionChecker
from pydrake.solvers import SnoptSolver, SolverOptions
from pydrake.trajectories import PiecewisePolynomial

from drake_grasp.hand import HAND_OPEN, TCP_DEPTH, X_GT
from drake_grasp.paths import add_package
from drake_grasp.planning.timing import time_path
from drake_grasp.planning.transit import rrt_connect
from drake_grasp.robots import RobotSpec
from drake_grasp.simulation.plant import add_scene, filter_hand_collisions
from drake_grasp.task import LIFT_DURATION, LIFT_TRAVEL, PREGRASP_DISTANCE

# Bumped whenever a change can flip a planning-success label: label sets of another
# version are refused (collect_reachability's manifest records it).
# 2: pre-grasp, lift and path tried for every grasp IK solution.
# 3: searches bounded by counts instead of a 2 s wall-clock budget; OMPL seeded per query.
PLANNER_VERSION = 3
POSITION_TOLERANCE = 0.001  # [m]
ORIENTATION_TOLERANCE = np.radians(1.0)
SNOPT_MAJOR_ITERATIONS = 100  # bounds a failing solve
X_G_FLIP = RigidTransform(RotationMatrix.MakeZRotation(np.pi))  # same grasp, jaws swapped
APPROACH_MIN_SECONDS = 0.6  # the shortest transit + approach segment [s]


@dataclass(frozen=True)
class PlannerConfig:
    """How hard the planner searches (counts, so that its answers do not depend on machine load)."""

    ik_seeds: int = 2  # random IK seeds tried after the start configuration
    max_ik_solves: int = 24  # SNOPT solves per plan; beyond them the plan fails with BUDGET
    max_transit_checks: int = 20_000  # collision checks per RRTConnect query
    speed_scale: float = 0.8  # peak joint speed as a fraction of the limit
    table_height: float = 0.0  # table top in the base frame (below 0: the arm on a pedestal) [m]


class PlanFailure(enum.Enum):
    NO_IK_GRASP = "no IK for the grasp"
    NO_IK_PREGRASP = "no IK for the pre-grasp"
    NO_IK_LIFT = "no IK for the lift"
    NO_PATH = "no collision-free path"
    BUDGET = "search budget exhausted"


# How far a plan got before failing (the furthest stage is reported).
STAGE_ORDER = list(PlanFailure)


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
    seconds: float  # wall time, for reports only: no decision depends on it
    ik_solves: int = 0

    @property
    def success(self) -> bool:
        return self.plan is not None


class _SolveBudget:
    def __init__(self, limit: int):
        self.left = limit
        self.refused = False  # a solve was wanted after the budget ran out

    def take(self) -> bool:
        """Whether another solve may run (and counts it)."""
        if self.left <= 0:
            self.refused = True
            return False
        self.left -= 1
        return True


class GraspPlanner:
    """Plans start -> pre-grasp -> grasp -> lift for one arm on its own planning model.

    The arm's base is at the world origin. `seed` fixes the random IK seeds and the
    OMPL queries; `reseed` restarts both streams (a data shard does, so that its
    labels depend only on its own index).
    """

    def __init__(self, robot: RobotSpec, *, seed: int = 0, config: PlannerConfig | None = None):
        self.robot = robot
        self.config = config or PlannerConfig()
        self.reseed(seed)
        builder = RobotDiagramBuilder(time_step=0.0)
        add_package(builder.parser().package_map())
        models = add_scene(builder.plant(), builder.parser(), robot=robot,
                           table_height=self.config.table_height)
        builder.plant().Finalize()
        filter_hand_collisions(builder.plant(), builder.scene_graph(), models)
        self.arm, self.hand = models.arm, models.hand
        self.checker = SceneGraphCollisionChecker(
            model=builder.Build(), robot_model_instances=[self.arm, self.hand],
            edge_step_size=0.05, env_collision_padding=0.002, self_collision_padding=0.002,
            implicit_context_parallelism=Parallelism(1),
        )
        self.plant = self.checker.plant()
        self._plant_context = self.checker.MakeStandaloneModelContext().plant_context()
        self.tcp = self.plant.GetFrameByName("tcp", self.hand)
        self._arm_slice = self._positions_slice(self.arm, robot.joint_names[0])
        self._hand_slice = self._positions_slice(self.hand, "left_finger_joint")
        self._q_full = self.plant.GetPositions(self._plant_context).copy()
        self._q_full[self._hand_slice] = HAND_OPEN
        self.q_lower, self.q_upper = robot.limits()
        self.v_max = np.asarray(robot.v_max) * self.config.speed_scale
        self.p_shoulder, flange_reach = robot.shoulder_and_reach()
        self.reach = flange_reach + TCP_DEPTH
        self._solver = SnoptSolver()
        self._options = SolverOptions()
        self._options.SetOption(SnoptSolver.id(), "Major iterations limit", SNOPT_MAJOR_ITERATIONS)

    def reseed(self, seed: int | list[int]) -> None:
        """Restarts the random IK seeds and the OMPL query seeds from `seed`."""
        self.rng = np.random.default_rng(seed)
        self._transit_rng = np.random.default_rng([*np.atleast_1d(seed).tolist(), 7])

    # -- configuration helpers ----------------------------------------------------------
    def _positions_slice(self, instance, first_joint: str) -> slice:
        start = self.plant.GetJointByName(first_joint, instance).position_start()
        return slice(start, start + self.plant.num_positions(instance))

    def full(self, q_arm: np.ndarray) -> np.ndarray:
        q = self._q_full.copy()
        q[self._arm_slice] = q_arm
        return q

    def is_free(self, q_arm: np.ndarray) -> bool:
        try:
            return bool(self.checker.CheckConfigCollisionFree(self.full(q_arm)))
        except RuntimeError:
            return False  # FCL's GJK gave up on a near-degenerate capsule pair: count it as a collision

    def is_edge_free(self, q1: np.ndarray, q2: np.ndarray) -> bool:
        try:
            return bool(self.checker.CheckEdgeCollisionFree(self.full(q1), self.full(q2)))
        except RuntimeError:
            return False

    def tcp_pose(self, q_arm: np.ndarray) -> RigidTransform:
        self.plant.SetPositions(self._plant_context, self.full(q_arm))
        return self.tcp.CalcPoseInWorld(self._plant_context)

    # -- IK ----------------------------------------------------------------------------
    def solve_ik(self, X_WT: RigidTransform, q_seed: np.ndarray, budget: _SolveBudget) -> np.ndarray | None:
        """Arm configuration putting the TCP at X_WT collision-free, or None."""
        if not budget.take():
            return None
        q = self.solve_ik_once(X_WT, q_seed, with_collision=False)
        if q is None:
            return None
        if self.is_free(q):
            return q
        if not budget.take():
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
        prog = ik.get_mutable_prog()
        prog.AddBoundingBoxConstraint(HAND_OPEN, HAND_OPEN, q[self._hand_slice])
        prog.AddQuadraticErrorCost(np.eye(len(q_seed)), q_seed, q[self._arm_slice])
        if with_collision:
            ik.AddMinimumDistanceLowerBoundConstraint(0.002, 0.02)
        try:
            result = self._solver.Solve(prog, self.full(q_seed), self._options)
        except RuntimeError:
            # FCL's GJK/EPA can throw on near-degenerate capsule-box distance queries
            # inside the collision constraint; count that solve as failed.
            return None
        if not result.is_success():
            return None
        return result.GetSolution(q)[self._arm_slice]

    def _grasp_solutions(self, X_WG: RigidTransform, q_start: np.ndarray, budget: _SolveBudget,
                         ) -> Iterator[tuple[np.ndarray, RigidTransform]]:
        """IK solutions for the grasp or its jaw-swapped twin, from the start and random seeds."""
        if np.linalg.norm((X_WG @ X_GT).translation() - self.p_shoulder) > self.reach:
            return  # beyond the arm's reach: no solver call can succeed
        seeds = [q_start] + [self.rng.uniform(self.q_lower, self.q_upper)
                             for _ in range(self.config.ik_seeds)]
        for seed in seeds:
            for X in (X_WG, X_WG @ X_G_FLIP):
                q = self.solve_ik(X @ X_GT, seed, budget)
                if q is not None:
                    yield q, X

    # -- paths -------------------------------------------------------------------------
    def rrt(self, q1: np.ndarray, q2: np.ndarray) -> list[np.ndarray] | None:
        """An RRTConnect path q1 -> q2 (the query's seed drawn from the planner's stream)."""
        return rrt_connect(q1, q2, is_free=self.is_free, is_edge_free=self.is_edge_free,
                           q_lower=self.q_lower, q_upper=self.q_upper,
                           max_checks=self.config.max_transit_checks,
                           seed=int(self._transit_rng.integers(2**31 - 1)))

    def transit(self, q1: np.ndarray, q2: np.ndarray) -> list[np.ndarray] | None:
        return [q1, q2] if self.is_edge_free(q1, q2) else self.rrt(q1, q2)

    # -- the whole plan ----------------------------------------------------------------
    def plan(self, X_WG: RigidTransform | np.ndarray, q_start: np.ndarray | None = None) -> PlanResult:
        """Plans the grasp X_WG from q_start (default: home)."""
        t0 = time.perf_counter()
        budget = _SolveBudget(self.config.max_ik_solves)
        X_WG = X_WG if isinstance(X_WG, RigidTransform) else RigidTransform(np.asarray(X_WG))
        q_start = np.asarray(self.robot.q_home if q_start is None else q_start, dtype=float)

        def result(plan: GraspPlan | None, failure: PlanFailure | None) -> PlanResult:
            return PlanResult(plan, failure, time.perf_counter() - t0,
                              self.config.max_ik_solves - budget.left)

        # Every grasp solution gets its pre-grasp, lift and path tried: one that
        # fails there (another IK branch) does not make the grasp unreachable.
        furthest = PlanFailure.NO_IK_GRASP
        for q_grasp, X in self._grasp_solutions(X_WG, q_start, budget):
            waypoints = self._complete(X, q_grasp, q_start, budget)
            if isinstance(waypoints, PlanFailure):
                furthest = max(furthest, waypoints, key=STAGE_ORDER.index)
                continue
            transit, q_pre, q_lift = waypoints
            plan = GraspPlan(q_pregrasp=q_pre, q_grasp=q_grasp, q_lift=q_lift,
                             approach=time_path(transit + [q_grasp], self.v_max, APPROACH_MIN_SECONDS),
                             lift=time_path([q_grasp, q_lift], self.v_max, LIFT_DURATION))
            return result(plan, None)
        return result(None, PlanFailure.BUDGET if budget.refused else furthest)

    def _complete(self, X_WG: RigidTransform, q_grasp: np.ndarray, q_start: np.ndarray, budget: _SolveBudget,
                  ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray] | PlanFailure:
        """Pre-grasp, lift and a free path for one grasp solution: (transit, q_pre, q_lift) or a failure."""
        X_WT = X_WG @ X_GT
        q_pre = self.solve_ik(X_WT @ RigidTransform([0.0, 0.0, -PREGRASP_DISTANCE]), q_grasp, budget)
        if q_pre is None:
            return PlanFailure.NO_IK_PREGRASP
        X_WLift = RigidTransform(X_WT.rotation(), X_WT.translation() + [0, 0, LIFT_TRAVEL])
        q_lift = self.solve_ik(X_WLift, q_grasp, budget)
        if q_lift is None:
            return PlanFailure.NO_IK_LIFT
        if not (self.is_edge_free(q_pre, q_grasp) and self.is_edge_free(q_grasp, q_lift)):
            return PlanFailure.NO_PATH
        transit = self.transit(q_start, q_pre)
        if transit is None:
            return PlanFailure.NO_PATH
        return transit, q_pre, q_lift
