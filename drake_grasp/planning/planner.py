"""Grasp planning: IK for the grasp, straight approach and lift lines, a collision-free transit, timing.

Whether this planner finds a complete plan for a grasp pose is the
planning-success label that trains the Reachability Predictor, so the planner is
deterministic: its searches are bounded by counts (IK solves, collision checks),
never by wall-clock time, and its random draws come from its own seeded streams.

What the planner knows about the scene: the arm, the hand (fingers open) and the
table (its own kinematic plant from the one plant assembly), and, for the transit
only, the observed objects as columns of a height map (`planning.obstacles`). The grasp, the approach
and the lift are planned without objects (observed scene structure, a shelf the objects lie under,
excepted: the grasp configuration and both lines must miss it), for two reasons. (1) The paper decouples
reachability from stability: p_r must depend on the pose and the robot only, so its
labels are collected on the robot + hand + table with no objects, and the planner
that executes grasps must answer the same way or the labels would not describe it.
(2) Collisions of the hand with the target and its neighbours during the final
approach are exactly what the stability CNN learns from its physics trials.

Per grasp X_WG: IK for the grasp (SNOPT, position + orientation of the TCP, the
180-degree-rolled twin accepted since the jaws are symmetric; a plain solve first
and a collision-constrained re-solve only if the plain solution collides). From the
grasp configuration, differential IK follows the TCP straight back along -z_G to
the pre-grasp and straight up for the lift (`planning.lines`): the arm executes the
same rigid approach and vertical lift as the grasp trials that label the CNN (with
`PlannerConfig.retreat_before_lift`, the lift first draws the object back along the
approach, out from under a shelf, and rises from there). Both lines must be
collision-free. A push (VPG's other primitive, `plan_push`) is planned the same way, its
lift replaced by the push's straight line and a rise. The transit start -> pre-grasp
tries the straight joint-space edge first and falls back to OMPL RRTConnect. Transits are timed with
rest-to-rest cubic segments, lines as one smooth motion, each joint's peak speed
within `speed_scale` of its velocity limit.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import SnoptSolver, SolverOptions
from pydrake.trajectories import PiecewisePolynomial

from drake_grasp.planning.lines import LineConfig, StraightLineIK
from drake_grasp.planning.obstacles import (
    ObservedScene,
    ObstacleConfig,
    free_voxels,
    obstacle_columns,
    structure_columns,
)
from drake_grasp.planning.timing import time_line, time_path
from drake_grasp.planning.transit import rrt_connect
from drake_grasp.robot.collision import CollisionModel
from drake_grasp.robot.plant import TCP_FRAME
from drake_grasp.robot.specs import RobotSpec
from drake_grasp.robot.stages import stage
from drake_grasp.robot.task import (
    APPROACH_DURATION,
    LIFT_DURATION,
    LIFT_TRAVEL,
    PREGRASP_DISTANCE,
    PUSH_RISE,
)

# Bumped whenever a change can flip a planning-success label: label sets of another
# version are refused (collect_reachability's manifest records it).
# 2: pre-grasp, lift and path tried for every grasp IK solution.
# 3: searches bounded by counts instead of a 2 s wall-clock budget; OMPL seeded per query.
# 4: approach and lift are straight TCP lines (differential IK), not straight joint-space edges.
PLANNER_VERSION = 4
POSITION_TOLERANCE = 0.001  # [m]
ORIENTATION_TOLERANCE = np.radians(1.0)
SNOPT_MAJOR_ITERATIONS = 100  # bounds a failing solve
X_G_FLIP = RigidTransform(RotationMatrix.MakeZRotation(np.pi))  # same grasp, jaws swapped
TRANSIT_MIN_SEGMENT_S = 0.3  # the shortest transit segment [s]


@dataclass(frozen=True)
class PlannerConfig:
    """How hard the planner searches (counts, so that its answers do not depend on machine load)."""

    ik_seeds: int = 2  # random IK seeds tried after the start configuration
    max_ik_solves: int = 24  # SNOPT solves per plan; beyond them the plan fails with BUDGET
    max_transit_checks: int = 20_000  # collision checks per RRTConnect query
    speed_scale: float = 0.8  # peak joint speed as a fraction of the limit
    # The lift first draws the grasped object this far back along the approach (out from under a shelf),
    # then rises; 0: straight up from the grasp, as the trials that label the CNN lift [m].
    retreat_before_lift: float = 0.0
    table_height: float = 0.0  # table top in the base frame (below 0: the arm on a pedestal) [m]
    line: LineConfig = field(default_factory=LineConfig)
    obstacles: ObstacleConfig = field(default_factory=ObstacleConfig)


class PlanFailure(enum.Enum):
    NO_IK_GRASP = "no IK for the grasp"
    NO_APPROACH_LINE = "no straight approach"
    NO_LIFT_LINE = "no straight lift"
    NO_PATH = "no collision-free path"
    BUDGET = "search budget exhausted"
    NO_PATH_AROUND_OBJECTS = "no path around the objects"  # the transit, with observed objects
    INTO_STRUCTURE = "into the scene structure"  # the grasp, approach or lift meets observed structure


# How far a plan got before failing (the furthest stage is reported).
STAGE_ORDER = list(PlanFailure)


@dataclass
class GraspPlan:
    q_pregrasp: np.ndarray
    q_grasp: np.ndarray
    q_lift: np.ndarray
    transit: PiecewisePolynomial  # start -> pre-grasp, joint space
    approach: PiecewisePolynomial  # pre-grasp -> grasp, the TCP on a straight line along +z_G
    lift: PiecewisePolynomial  # grasp -> lift, the TCP straight up
    approach_path: list[np.ndarray] = field(default_factory=list)  # the approach's waypoints

    def retreat(self, v_max: np.ndarray) -> PiecewisePolynomial:
        """Grasp -> pre-grasp: the approach line backwards."""
        return time_line(self.approach_path[::-1], v_max, APPROACH_DURATION)


@dataclass
class PlanResult:
    plan: GraspPlan | None
    failure: PlanFailure | None
    seconds: float  # wall time, for reports only: no decision depends on it
    ik_solves: int = 0
    observed: CollisionModel | None = None  # the world with the observed objects (until the next plan)

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
        self.world = CollisionModel(robot, table_height=self.config.table_height)
        self._observed = CollisionModel(robot, table_height=self.config.table_height)
        self._structure: CollisionModel | None = None  # robot + table + observed structure (built when seen)
        self._free: tuple[object, set] | None = None  # the last scene's rays and their free voxels
        self.checker, self.plant = self.world.checker, self.world.plant
        self._plant_context = self.world.plant_context
        self.arm, self.hand = self.world.arm, self.world.hand
        self.tcp = self.plant.GetFrameByName(TCP_FRAME, self.hand)
        self.X_GT = robot.hand.X_GT
        self._arm_slice = self.world.arm_slice
        self.q_lower, self.q_upper = robot.limits()
        self.v_max = np.asarray(robot.v_max) * self.config.speed_scale
        self.p_shoulder, flange_reach = robot.shoulder_and_reach()
        self.reach = flange_reach + robot.hand.tcp_depth
        self.lines = StraightLineIK(self.plant, self._plant_context, self.tcp, positions=self._arm_slice,
                                    full=self.world.full, q_lower=self.q_lower, q_upper=self.q_upper,
                                    config=self.config.line)
        self._solver = SnoptSolver()
        self._options = SolverOptions()
        self._options.SetOption(SnoptSolver.id(), "Major iterations limit", SNOPT_MAJOR_ITERATIONS)

    def reseed(self, seed: int | list[int]) -> None:
        """Restarts the random IK seeds and the OMPL query seeds from `seed`."""
        self.rng = np.random.default_rng(seed)
        self._transit_rng = np.random.default_rng([*np.atleast_1d(seed).tolist(), 7])

    # -- collision checking on the robot + table world --------------------------------------
    def full(self, q_arm: np.ndarray) -> np.ndarray:
        return self.world.full(q_arm)

    def is_free(self, q_arm: np.ndarray) -> bool:
        return self.world.is_free(q_arm)

    def is_edge_free(self, q1: np.ndarray, q2: np.ndarray) -> bool:
        return self.world.is_edge_free(q1, q2)

    def is_path_free(self, path: list[np.ndarray]) -> bool:
        return self.world.is_path_free(path)

    def observed_world(self, scene: ObservedScene, X_WG: np.ndarray | RigidTransform) -> CollisionModel:
        """Robot + table + the observed scene as columns, the objects clear of X_WG's approach corridor.

        One model, built with the planner: each call replaces the columns of the last, so a
        world returned here holds until the next call (the next plan).
        """
        X = X_WG.GetAsMatrix4() if isinstance(X_WG, RigidTransform) else np.asarray(X_WG)
        cfg = self.config.obstacles
        columns = obstacle_columns(scene, X, cfg, hand=self.robot.hand, table_z=self.config.table_height,
                                   free=self._free_voxels(scene))
        self._observed.set_columns(columns, cfg.cell)
        return self._observed

    def structure_world(self, scene: ObservedScene) -> CollisionModel | None:
        """Robot + table + the observed structure alone (None: the scene has none); holds until the next
        call."""
        if len(scene.structure) == 0:
            return None
        if self._structure is None:
            self._structure = CollisionModel(self.robot, table_height=self.config.table_height)
        cfg = self.config.obstacles
        columns = structure_columns(scene, cfg, table_z=self.config.table_height,
                                    free=self._free_voxels(scene))
        self._structure.set_fixed_columns(columns, cfg.cell)
        return self._structure

    def _free_voxels(self, scene: ObservedScene) -> set | None:
        """The voxels the scene's rays saw through (None: no rays), kept for the plans of one observation."""
        if scene.rays is None:
            return None
        if self._free is None or self._free[0] is not scene.rays:
            top = max(float(np.max(a[:, 2], initial=-np.inf)) for a in (scene.objects, scene.structure))
            self._free = (scene.rays, free_voxels(scene.rays, self.config.obstacles, self.config.table_height,
                                                  top + self.config.obstacles.slice))
        return self._free[1]

    def tcp_pose(self, q_arm: np.ndarray) -> RigidTransform:
        return self.lines.tcp_pose(q_arm)

    # -- IK ----------------------------------------------------------------------------
    def solve_ik(self, X_WT: RigidTransform, q_seed: np.ndarray, budget: _SolveBudget,
                 world: CollisionModel | None = None) -> np.ndarray | None:
        """Arm configuration putting the TCP at X_WT free of collisions in `world` (default robot + table;
        the observed structure's world when a scene has some), or None."""
        world = world or self.world
        if not budget.take():
            return None
        q = self.solve_ik_once(X_WT, q_seed, with_collision=False)
        if q is None:
            return None
        if world.is_free(q):
            return q
        if not budget.take():
            return None
        q = self.solve_ik_once(X_WT, q, with_collision=True, world=world)
        return q if q is not None and world.is_free(q) else None

    def solve_ik_once(self, X_WT: RigidTransform, q_seed: np.ndarray, *, with_collision: bool,
                      world: CollisionModel | None = None) -> np.ndarray | None:
        """One SNOPT solve from q_seed; `with_collision` keeps the arm off `world`'s geometry (default robot +
        table; a world whose columns are fixed geometry, as the structure's, for observed obstacles)."""
        world = world or self.world
        plant = world.plant
        tcp = plant.GetFrameByName(TCP_FRAME, world.hand)
        ik = InverseKinematics(plant, world.plant_context, with_joint_limits=True)
        q = ik.q()
        p = X_WT.translation()
        ik.AddPositionConstraint(tcp, np.zeros(3), plant.world_frame(),
                                 p - POSITION_TOLERANCE, p + POSITION_TOLERANCE)
        ik.AddOrientationConstraint(plant.world_frame(), X_WT.rotation(), tcp,
                                    RotationMatrix(), ORIENTATION_TOLERANCE)
        prog = ik.get_mutable_prog()
        prog.AddBoundingBoxConstraint(world.hand_open, world.hand_open, q[world.hand_slice])
        prog.AddQuadraticErrorCost(np.eye(len(q_seed)), q_seed, q[self._arm_slice])
        if with_collision:
            ik.AddMinimumDistanceLowerBoundConstraint(0.002, 0.02)
        try:
            result = self._solver.Solve(prog, world.full(q_seed), self._options)
        except RuntimeError:
            # FCL's GJK/EPA can throw on near-degenerate capsule-box distance queries
            # inside the collision constraint; count that solve as failed.
            return None
        if not result.is_success():
            return None
        return result.GetSolution(q)[self._arm_slice]

    def _grasp_solutions(self, X_WG: RigidTransform, q_start: np.ndarray, budget: _SolveBudget,
                         structure: CollisionModel | None = None,
                         ) -> Iterator[tuple[np.ndarray, RigidTransform]]:
        """IK solutions for the grasp or its jaw-swapped twin, from the start and random seeds (clear of the
        observed `structure` too, when there is some)."""
        if np.linalg.norm((X_WG @ self.X_GT).translation() - self.p_shoulder) > self.reach:
            return  # beyond the arm's reach: no solver call can succeed
        seeds = [q_start] + [self.rng.uniform(self.q_lower, self.q_upper)
                             for _ in range(self.config.ik_seeds)]
        for seed in seeds:
            for X in (X_WG, X_WG @ X_G_FLIP):
                q = self.solve_ik(X @ self.X_GT, seed, budget, structure)
                if q is not None:
                    yield q, X

    # -- paths -------------------------------------------------------------------------
    def rrt(self, q1: np.ndarray, q2: np.ndarray, world: CollisionModel | None = None,
            ) -> list[np.ndarray] | None:
        """An RRTConnect path q1 -> q2 (the query's seed drawn from the planner's stream)."""
        world = world or self.world
        return rrt_connect(q1, q2, is_free=world.is_free, is_edge_free=world.is_edge_free,
                           q_lower=self.q_lower, q_upper=self.q_upper,
                           max_checks=self.config.max_transit_checks,
                           seed=int(self._transit_rng.integers(2**31 - 1)))

    @stage("planning")
    def transit(self, q1: np.ndarray, q2: np.ndarray, world: CollisionModel | None = None,
                ) -> list[np.ndarray] | None:
        """A free joint path q1 -> q2 in `world` (default robot + table): straight, else RRTConnect."""
        return [q1, q2] if (world or self.world).is_edge_free(q1, q2) else self.rrt(q1, q2, world)

    @stage("planning")
    def time_transit(self, path: list[np.ndarray]) -> PiecewisePolynomial:
        return time_path(path, self.v_max, TRANSIT_MIN_SEGMENT_S)

    # -- the whole plan ----------------------------------------------------------------
    @stage("planning")
    def plan(self, X_WG: RigidTransform | np.ndarray, q_start: np.ndarray | None = None,
             observed: ObservedScene | None = None) -> PlanResult:
        """Plans the grasp X_WG from q_start (default: home).

        With an `observed` scene, the transit to the pre-grasp also avoids the objects
        outside the grasp's approach corridor and any structure, and the grasp, approach
        and lift miss the structure; the world built for the transit (once a grasp solution
        reaches it) is returned in the result, for the way home.
        """
        return self._plan(X_WG, q_start, observed, self._lift)

    def plan_push(self, X_WG: RigidTransform | np.ndarray, travel: np.ndarray,
                  q_start: np.ndarray | None = None, observed: ObservedScene | None = None) -> PlanResult:
        """Plans a push as a grasp whose lift is two TCP lines: `travel` (3,) [m] from X_WG (the push's
        start, reached by the straight approach), then straight up. The plan's `lift` is that motion;
        the push line runs into the objects by design, so only the robot, table and structure bound it."""
        travel = np.asarray(travel, dtype=float)

        def push_lines(q_push: np.ndarray, p_start: np.ndarray, X: RigidTransform):
            along = self.lines.line(q_push, p_start + travel)
            p_end = p_start + travel
            up = None if along is None else self.lines.line(along[-1], p_end + [0.0, 0.0, PUSH_RISE])
            return None if up is None else [along, up]

        return self._plan(X_WG, q_start, observed, push_lines)

    def _plan(self, X_WG: RigidTransform | np.ndarray, q_start: np.ndarray | None,
              observed: ObservedScene | None,
              moves: Callable[[np.ndarray, np.ndarray, RigidTransform], list[list[np.ndarray]] | None],
              ) -> PlanResult:
        """`plan` with the lines after the grasp made by `moves(q_grasp, p_grasp, X_WG)`."""
        t0 = time.perf_counter()
        budget = _SolveBudget(self.config.max_ik_solves)
        X_WG = X_WG if isinstance(X_WG, RigidTransform) else RigidTransform(np.asarray(X_WG))
        q_start = np.asarray(self.robot.q_home if q_start is None else q_start, dtype=float)

        built: list[CollisionModel] = []
        structure = None if observed is None else self.structure_world(observed)

        def observed_world() -> CollisionModel | None:
            if observed is None:
                return None
            if not built:
                built.append(self.observed_world(observed, X_WG))
            return built[0]

        def result(plan: GraspPlan | None, failure: PlanFailure | None) -> PlanResult:
            return PlanResult(plan, failure, time.perf_counter() - t0,
                              self.config.max_ik_solves - budget.left, built[0] if built else None)

        # Every grasp solution gets its lines and path tried: one that fails there
        # (another IK branch) does not make the grasp unreachable.
        furthest = PlanFailure.NO_IK_GRASP
        for q_grasp, X in self._grasp_solutions(X_WG, q_start, budget, structure):
            plan = self._complete(X, q_grasp, q_start, observed_world, structure, moves)
            if isinstance(plan, PlanFailure):
                furthest = max(furthest, plan, key=STAGE_ORDER.index)
                continue
            return result(plan, None)
        return result(None, PlanFailure.BUDGET if budget.refused else furthest)

    def _complete(self, X_WG: RigidTransform, q_grasp: np.ndarray, q_start: np.ndarray,
                  observed_world: Callable[[], CollisionModel | None], structure: CollisionModel | None,
                  moves: Callable[[np.ndarray, np.ndarray, RigidTransform], list[list[np.ndarray]] | None],
                  ) -> GraspPlan | PlanFailure:
        """Approach and lift lines and a free transit for one grasp solution, or a failure."""
        p_grasp = self.tcp_pose(q_grasp).translation()
        backwards = self.lines.line(q_grasp, p_grasp - PREGRASP_DISTANCE * X_WG.rotation().col(2))
        if backwards is None:
            return PlanFailure.NO_APPROACH_LINE
        lift = moves(q_grasp, p_grasp, X_WG)
        if lift is None:
            return PlanFailure.NO_LIFT_LINE
        approach = backwards[::-1]
        lift_path = [q for line in lift for q in line]
        if not (self.is_path_free(approach) and self.is_path_free(lift_path)):
            return PlanFailure.NO_PATH
        if structure is not None and not (structure.is_path_free(approach)
                                          and structure.is_path_free(lift_path)):
            return PlanFailure.INTO_STRUCTURE
        q_pre = approach[0]
        observed = observed_world()
        transit = self.transit(q_start, q_pre, observed)
        if transit is None:
            if observed is None or self.transit(q_start, q_pre) is None:
                return PlanFailure.NO_PATH
            return PlanFailure.NO_PATH_AROUND_OBJECTS
        return GraspPlan(q_pregrasp=q_pre, q_grasp=q_grasp, q_lift=lift[-1][-1],
                         transit=self.time_transit(transit),
                         approach=time_line(approach, self.v_max, APPROACH_DURATION),
                         lift=self._time_lift(lift), approach_path=approach)

    def _lift(self, q_grasp: np.ndarray, p_grasp: np.ndarray, X_WG: RigidTransform,
              ) -> list[list[np.ndarray]] | None:
        """The lift's straight TCP lines from the grasp: up, or back along the approach and then up."""
        retreat = self.config.retreat_before_lift
        if retreat <= 0.0:
            up = self.lines.line(q_grasp, p_grasp + [0.0, 0.0, LIFT_TRAVEL])
            return None if up is None else [up]
        p_out = p_grasp - retreat * X_WG.rotation().col(2)
        out = self.lines.line(q_grasp, p_out)
        up = None if out is None else self.lines.line(out[-1], p_out + [0.0, 0.0, LIFT_TRAVEL])
        return None if up is None else [out, up]

    def _time_lift(self, lines: list[list[np.ndarray]]) -> PiecewisePolynomial:
        """The lift's lines one after the other, each from rest to rest."""
        motion = time_line(lines[0], self.v_max, LIFT_DURATION)
        for line in lines[1:]:
            more = time_line(line, self.v_max, LIFT_DURATION)
            more.shiftRight(motion.end_time())
            motion.ConcatenateInTime(more)
        return motion
