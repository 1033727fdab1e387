"""The grasp executive: a LeafSystem state machine that runs the cell through one attempt. It decides
(what to try, what to remember, when to stop) and moves; what came of a move it learns from its judge
(`cell.judges`: the simulator's ground truth, or what a robot's gripper reports).

    observe: choose a candidate (failure memory, reachability threshold), plan it
    transit (around the observed objects) -> approach (straight along +z_G) -> close
      - the fingers met: "closed on nothing" is sensed at once; open, retreat along the approach line
      - else, after the trials' closing time, lift (straight up) -> hold -> judged (lifted 15 cm
        and in the hand)
    a push (VPG's other primitive, a ranked candidate marked `push`): the hand closes in transit,
      approaches the push's start, pushes 10 cm, rises -> judged (did an object move?)
    return home on a planned path (holding the object after a success; opened after a failure)
    -> attempt done

A planning failure ends the attempt before the arm moves (it counts as a failed
attempt, as in the paper). The run also ends here when no candidate is left to try:
"no objects" (an empty cloud), "nothing reachable" (no candidate's p_r reaches
`CellConfig.reach_threshold`), "nothing graspable" (the best untried candidate's predicted stability,
p_s times p_h, is under `CellConfig.grasp_threshold`), every candidate near a remembered failure, or "no grasp
candidates" (a policy with its own generator, GPD's, found none on the objects). The
episode driver (`drake_grasp.cell.episode`) reads each finished attempt, takes a
grasped object from the hand (the cell's bin) and starts the next attempt.
"""

from __future__ import annotations

import copy
import enum
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import Value
from pydrake.geometry import Meshcat
from pydrake.systems.framework import BasicVector, Context, LeafSystem
from pydrake.trajectories import PiecewisePolynomial

from drake_grasp.cell.judges import AttemptJudge, Judgement, Scene
from drake_grasp.cell.memory import FailureMemory, MemoryConfig
from drake_grasp.perception.cloud import ObjectCloud
from drake_grasp.planning.obstacles import ObservedScene
from drake_grasp.planning.planner import GraspPlan, GraspPlanner, PlanFailure
from drake_grasp.policy.drawing import draw_candidates
from drake_grasp.policy.sampling import approach_angle_deg
from drake_grasp.policy.selector import RankedGrasps
from drake_grasp.robot.collision import CollisionModel
from drake_grasp.robot.stages import stage
from drake_grasp.robot.task import (
    CLOSE_DURATION,
    EMPTY_CLOSE_CHECK,
    HOLD_DURATION,
    PUSH_LENGTH,
    SETTLE_AFTER_APPROACH,
)

UPDATE_PERIOD = 0.02  # [s]
RELEASE_DURATION = 0.3  # the hand opens before the arm moves on [s]


class Mode(enum.Enum):
    WAIT = "wait"  # objects settling, or the arm just returned home
    OBSERVE = "observe"
    TRANSIT = "transit"
    APPROACH = "approach"
    CLOSE = "close"
    LIFT = "lift"
    HOLD = "hold"
    RELEASE = "release"
    RETREAT = "retreat"
    PUSH = "push"
    RETURN = "return"
    ATTEMPT_DONE = "attempt done"
    NO_OBJECTS = "no objects left in view"
    NOTHING_REACHABLE = "nothing reachable"
    NOTHING_GRASPABLE = "nothing graspable"  # the best untried candidate's p_s * p_h is under the threshold
    NOTHING_UNTRIED = "every candidate failed before"
    NO_CANDIDATES = "no grasp candidates"  # objects in view, but the policy's own generator found none


END_MODES = (Mode.NO_OBJECTS, Mode.NOTHING_REACHABLE, Mode.NOTHING_GRASPABLE, Mode.NOTHING_UNTRIED,
             Mode.NO_CANDIDATES)
SCENE_DEPENDENT_PLAN_FAILURES = {PlanFailure.NO_PATH_AROUND_OBJECTS.value}


@dataclass(frozen=True)
class CellConfig:
    """How the cell behaves beyond the paper's policy. `paper()` is the paper's loop."""

    failure_memory: bool = True  # do not retry grasps that just failed on an unchanged scene
    memory: MemoryConfig = field(default_factory=MemoryConfig)
    reach_threshold: float = 0.0  # no candidate's p_r reaches it: the run ends, nothing reachable (0: off)
    grasp_threshold: float = 0.0  # the best untried candidate's p_s * p_h is under it: the run ends (0: off)
    avoid_observed_objects: bool = True  # the transit avoids the object cloud

    @staticmethod
    def paper() -> CellConfig:
        """No failure memory and no early stop: every attempt goes to the best-ranked candidate."""
        return CellConfig(failure_memory=False, reach_threshold=0.0)


@dataclass
class Attempt:
    """One grasp attempt: what was planned, how it ended."""

    planned: bool
    success: bool
    failure: str | None  # a PlanFailure value, or an execution failure mode
    plan_seconds: float
    score: float
    approach_angle_deg: float
    grasp_point: list[float] = field(default_factory=list)
    p_r: float | None = None  # the policy's predictions for the grasp (None: it made none)
    p_s: float | None = None
    p_h: float | None = None  # (with a hold predictor)
    object_index: int | None = None  # the grasped object, or for a failure the object nearest the grasp point
    rise: float = 0.0  # how much higher the object ended [m] (0 where the judge cannot tell)
    # The hand's driven joint when the close ended and the lift began (the Franka hand's: each finger's
    # travel from the centre [m]): what the jaws held (None: they met during the close, or never closed).
    # A grasp that fails later with the jaws shut lost its object in the lift ("closed on nothing"
    # after a grip).
    grip: float | None = None
    repeat: bool = False  # near a grasp that already failed on this unchanged scene (or did not plan)
    transit_contacts: int = 0  # objects the robot touched while in transit (to the pre-grasp and home)
    return_planned: bool = True  # the way home was planned collision-free
    push: bool = False  # a push (VPG's other primitive): `success` says it moved an object


def predicted_stability(p_s: float | None, p_h: float | None) -> float:
    """A candidate's predicted chance to hold: p_s, times p_h with a hold predictor (None or NaN: not
    predicted); infinite where the policy predicts no p_s (RAND, GPD, VPG: the grasp threshold never
    stops them)."""
    if p_s is None or np.isnan(p_s):
        return np.inf
    return float(p_s if p_h is None or np.isnan(p_h) else p_s * p_h)


def _prediction(value: float) -> float | None:
    return None if np.isnan(value) else float(value)


@dataclass
class ExecutiveState:
    mode: Mode = Mode.WAIT
    mode_start: float = 0.0
    wait_until: float = 0.0
    q_hold: np.ndarray = field(default_factory=lambda: np.zeros(0))
    motion: PiecewisePolynomial | None = None  # the arm's trajectory in this mode (time from mode_start)
    velocity: PiecewisePolynomial | None = None  # its derivative (the arm's output reads it every step)
    hand_closed: bool = False
    empty_close: bool = False  # the fingers met while closing at the grasp pose
    plan: GraspPlan | None = None
    X_WG: np.ndarray | None = None
    scene: Scene | None = None  # as the judge saw it when the attempt began
    observed: CollisionModel | None = None  # the planning world with the observed objects
    touched_in_transit: frozenset = frozenset()
    attempt: Attempt | None = None
    memory: FailureMemory = field(default_factory=FailureMemory)
    requested: np.ndarray | None = None  # a grasp to plan instead of the ranking's choice (request_grasp)

    def __deepcopy__(self, memo):
        # Trajectories and plans are never mutated once made: share them. The memory is copied.
        out = copy.copy(self)
        out.q_hold = self.q_hold.copy()
        out.attempt = copy.copy(self.attempt)
        out.memory = self.memory.copy()
        return out


class GraspExecutive(LeafSystem):
    """Ranked grasps, the object cloud, arm and hand states (and what the `judge` reads) in; desired states
    out."""

    def __init__(self, planner: GraspPlanner, *, judge: AttemptJudge, settle_time: float,
                 config: CellConfig | None = None, meshcat: Meshcat | None = None):
        super().__init__()
        self._planner = planner
        self._judge = judge
        self._meshcat = meshcat
        self.config = config or CellConfig()
        robot = planner.robot
        self._hand = robot.hand
        self._q_home = np.asarray(robot.q_home, dtype=float)
        self._grasps_port = self.DeclareAbstractInputPort("ranked_grasps", Value(RankedGrasps.empty()))
        self._cloud_port = self.DeclareAbstractInputPort("object_cloud", Value(ObjectCloud.empty()))
        judge.declare_inputs(self)
        self._arm_state_port = self.DeclareVectorInputPort("arm_state", 2 * robot.num_joints)
        self._hand_state_port = self.DeclareVectorInputPort("hand_state", 2)  # the driven joint's q, v
        memory = FailureMemory(self.config.memory)
        self._state_index = self.DeclareAbstractState(
            Value(ExecutiveState(q_hold=self._q_home.copy(), wait_until=settle_time, memory=memory)))
        self.DeclareVectorOutputPort("arm_desired_state", 2 * robot.num_joints, self._calc_arm,
                                     {self.all_state_ticket(), self.time_ticket()})
        self.DeclareVectorOutputPort("hand_desired_state", 2, self._calc_hand, {self.all_state_ticket()})
        self.DeclarePeriodicUnrestrictedUpdateEvent(UPDATE_PERIOD, 0.0, self._update)

    # -- state access for the episode driver ----------------------------------------------
    def get_task_state(self, context: Context) -> ExecutiveState:
        return self.GetMyContextFromRoot(context).get_abstract_state(self._state_index).get_value()

    def start_next_attempt(self, root_context: Context, wait_s: float) -> None:
        """Hand open at home, observe again after `wait_s` (the failure memory is kept)."""
        context = self.GetMyMutableContextFromRoot(root_context)
        t = context.get_time()
        old = context.get_abstract_state(self._state_index).get_value()
        state = ExecutiveState(q_hold=self._q_home.copy(), wait_until=t + wait_s, mode_start=t,
                               memory=old.memory.copy())
        context.SetAbstractState(self._state_index, state)

    def wait_until(self, root_context: Context, t: float) -> None:
        """The coming attempt observes no earlier than time `t` (while the dropped scene settles)."""
        self._set_before_observing(root_context, "wait", wait_until=t)

    def request_grasp(self, root_context: Context, X_WG: np.ndarray) -> None:
        """The coming attempt plans and executes X_WG (from another detector, say) instead of choosing
        from the ranking; everything after the choice is the same. Call before it observes."""
        self._set_before_observing(root_context, "request a grasp",
                                   requested=np.asarray(X_WG, dtype=float).copy())

    def _set_before_observing(self, root_context: Context, what: str, **fields) -> None:
        """Sets `fields` of the state while it still waits to observe; RuntimeError once it has begun."""
        context = self.GetMyMutableContextFromRoot(root_context)
        state = copy.deepcopy(context.get_abstract_state(self._state_index).get_value())
        if state.mode is not Mode.WAIT:
            raise RuntimeError(f"{what} before the attempt observes (mode is {state.mode.value})")
        for name, value in fields.items():
            setattr(state, name, value)
        context.SetAbstractState(self._state_index, state)

    # -- outputs --------------------------------------------------------------------------
    @stage("bookkeeping")
    def _calc_arm(self, context: Context, output: BasicVector) -> None:
        s = context.get_abstract_state(self._state_index).get_value()
        if s.motion is None:
            q, v = s.q_hold, np.zeros_like(s.q_hold)
        else:
            t = min(max(context.get_time() - s.mode_start, s.motion.start_time()), s.motion.end_time())
            q, v = s.motion.value(t).ravel(), s.velocity.value(t).ravel()
        output.SetFromVector(np.concatenate([q, v]))

    @stage("bookkeeping")
    def _calc_hand(self, context: Context, output: BasicVector) -> None:
        s = context.get_abstract_state(self._state_index).get_value()
        hand = self._hand
        output.SetFromVector([hand.closed_position if s.hand_closed else hand.open_position, 0.0])

    # -- the state machine ----------------------------------------------------------------
    @stage("bookkeeping")
    def _update(self, context: Context, state) -> None:
        s = copy.deepcopy(context.get_abstract_state(self._state_index).get_value())
        t = context.get_time()
        elapsed = t - s.mode_start

        def go(mode: Mode, motion: PiecewisePolynomial | None = None) -> None:
            if s.motion is not None:  # hold where the last motion ended
                s.q_hold = s.motion.value(s.motion.end_time()).ravel()
            s.mode, s.mode_start, s.motion = mode, t, motion
            s.velocity = None if motion is None else motion.derivative(1)

        def motion_done(settle: float = 0.0) -> bool:
            return elapsed >= s.motion.end_time() + settle

        if s.mode in (Mode.TRANSIT, Mode.RETURN):
            touched = self._judge.touched_by_robot(context)
            if s.attempt.success:
                touched.discard(s.attempt.object_index)  # the object in the hand
            s.touched_in_transit = s.touched_in_transit | touched

        if s.mode is Mode.WAIT and t >= s.wait_until:
            go(Mode.OBSERVE)
        elif s.mode is Mode.OBSERVE:
            self._observe_and_plan(context, s)
            if s.attempt is not None and s.attempt.planned:
                go(Mode.TRANSIT, s.plan.transit)
            else:
                s.mode_start = t
        elif s.mode is Mode.TRANSIT and motion_done():
            go(Mode.APPROACH, s.plan.approach)
        elif s.mode is Mode.APPROACH and s.attempt.push and motion_done():
            go(Mode.PUSH, s.plan.lift)
        elif s.mode is Mode.APPROACH and motion_done(SETTLE_AFTER_APPROACH):
            s.hand_closed = True
            go(Mode.CLOSE)
        elif s.mode is Mode.PUSH and motion_done():
            self._apply(s, self._judge.push(context, s.scene, s.X_WG))
            s.hand_closed = False
            go(Mode.RETURN, self._way_home(s))
        elif s.mode is Mode.CLOSE:
            if elapsed >= EMPTY_CLOSE_CHECK and self._hand.jaws_met(self._hand_state_port.Eval(context)[0]):
                self._apply(s, self._judge.empty_close(s.scene, s.X_WG))  # sensed: the jaws met
                s.hand_closed, s.empty_close = False, True
                go(Mode.RELEASE)
            elif elapsed >= CLOSE_DURATION:  # the grip the trials that label the CNN build
                s.attempt.grip = round(float(self._hand_state_port.Eval(context)[0]), 4)
                go(Mode.LIFT, s.plan.lift)
        elif s.mode is Mode.LIFT and motion_done():
            go(Mode.HOLD)
        elif s.mode is Mode.HOLD and elapsed >= HOLD_DURATION:
            finger = float(self._hand_state_port.Eval(context)[0])
            self._apply(s, self._judge.grasp(context, s.scene, s.X_WG, finger, s.attempt.grip))
            if s.attempt.success:
                go(Mode.RETURN, self._way_home(s))
            else:
                s.hand_closed = False
                go(Mode.RELEASE)
        elif s.mode is Mode.RELEASE and elapsed >= RELEASE_DURATION:
            if s.empty_close:  # still at the grasp pose: back out along the approach line
                go(Mode.RETREAT, s.plan.retreat(self._planner.v_max))
            else:
                go(Mode.RETURN, self._way_home(s))
        elif s.mode is Mode.RETREAT and motion_done():
            go(Mode.RETURN, self._way_home(s))
        elif s.mode is Mode.RETURN and motion_done():
            s.attempt.transit_contacts = len(s.touched_in_transit)
            self._remember(s)
            go(Mode.ATTEMPT_DONE)
        state.get_mutable_abstract_state(self._state_index).set_value(s)

    def _choose(self, ranked: RankedGrasps, s: ExecutiveState) -> tuple[int | None, Mode | None]:
        """The candidate to try (its index in the ranking), or the mode that ends the run."""
        allowed = np.ones(len(ranked), bool)
        if self.config.failure_memory:
            allowed &= ~s.memory.excluded(ranked.X_WG)
        if not allowed.any():
            return None, Mode.NOTHING_UNTRIED
        threshold = self.config.reach_threshold
        if threshold > 0 and not np.isnan(ranked.p_r).all() and not (ranked.p_r[allowed] >= threshold).any():
            return None, Mode.NOTHING_REACHABLE
        k = int(np.argmax(allowed))  # the best untried candidate (the ranking is best first)
        threshold = self.config.grasp_threshold
        if threshold > 0 and predicted_stability(ranked.p_s[k], ranked.p_h[k]) < threshold:
            return None, Mode.NOTHING_GRASPABLE
        return k, None

    def _observe_and_plan(self, context: Context, s: ExecutiveState) -> None:
        ranked = self._grasps_port.Eval(context)
        s.attempt = None
        if len(ranked) == 0:
            s.mode = Mode.NO_CANDIDATES if ranked.num_object_points > 0 else Mode.NO_OBJECTS
            return
        s.scene = self._judge.scene(context, self._cloud_port.Eval(context))
        s.memory.observe(s.scene)
        if s.requested is not None:  # an outside choice: no ranking, no prediction
            ranked, k, end = RankedGrasps(s.requested[None], np.array([np.nan]), len(ranked)), 0, None
        else:
            k, end = self._choose(ranked, s)
        if end is not None:
            s.mode = end
            return
        s.X_WG = ranked.X_WG[k]
        push = bool(ranked.push[k])
        if push and not self._judge.judges_pushes:
            raise ValueError(f"the policy pushes, and {type(self._judge).__name__} judges grasps only")
        q_now = self._arm_state_port.Eval(context)[: len(self._q_home)]
        if push:
            result = self._planner.plan_push(s.X_WG, PUSH_LENGTH * s.X_WG[:3, 0], q_start=q_now,
                                             observed=self._observed_scene(context))
        else:
            result = self._planner.plan(s.X_WG, q_start=q_now, observed=self._observed_scene(context))
        s.observed = result.observed
        s.attempt = Attempt(
            planned=result.success, success=False,
            failure=None if result.success else result.failure.value,
            plan_seconds=result.seconds, score=float(ranked.scores[k]),
            approach_angle_deg=float(approach_angle_deg(s.X_WG)),
            grasp_point=[round(float(x), 4) for x in s.X_WG[:3, 3]],
            p_r=_prediction(ranked.p_r[k]), p_s=_prediction(ranked.p_s[k]), p_h=_prediction(ranked.p_h[k]),
            repeat=bool(s.memory.excluded(s.X_WG)[0]), push=push,
        )
        if self._meshcat is not None:
            draw_candidates(self._meshcat, ranked, planned=result.success, chosen=k, hand=self._hand)
        if result.success:
            s.plan = result.plan
            s.hand_closed = push  # a push is made with the hand closed
        else:
            s.attempt.object_index = s.scene.nearest_object(s.X_WG[:3, 3])
            self._remember(s)
            s.mode = Mode.ATTEMPT_DONE

    def _observed_scene(self, context: Context) -> ObservedScene | None:
        """What the planner avoids: the object cloud (unless `avoid_observed_objects` is off) and any
        scene structure, with the cameras' rays when the cloud has them."""
        cloud = self._cloud_port.Eval(context)
        if not self.config.avoid_observed_objects:
            if len(cloud.structure) == 0:
                return None
            return ObservedScene(np.zeros((0, 3)), cloud.structure, cloud.rays)
        return ObservedScene(cloud.points, cloud.structure, cloud.rays)

    def _remember(self, s: ExecutiveState) -> None:
        a = s.attempt
        if a.success:
            return
        scene_dependent = a.planned or a.failure in SCENE_DEPENDENT_PLAN_FAILURES
        s.memory.remember(s.X_WG, scene_dependent=scene_dependent, scene=s.scene)

    @staticmethod
    def _apply(s: ExecutiveState, judgement: Judgement) -> None:
        """The judge's verdict on the attempt in flight."""
        a = s.attempt
        a.success, a.failure, a.object_index = judgement.success, judgement.failure, judgement.object_index
        if not np.isnan(judgement.rise):
            a.rise = judgement.rise

    def _way_home(self, s: ExecutiveState) -> PiecewisePolynomial:
        """A planned path home from where the arm holds now (around the objects, if it can)."""
        planner, q_from = self._planner, s.motion.value(s.motion.end_time()).ravel() if s.motion else s.q_hold
        path = planner.transit(q_from, self._q_home, s.observed)
        if path is None and s.observed is not None:
            path = planner.transit(q_from, self._q_home)
        if path is None:
            s.attempt.return_planned = False
            path = [q_from, self._q_home]
        return planner.time_transit(path)
