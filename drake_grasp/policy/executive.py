"""The grasp executive: a LeafSystem state machine that plans and executes one attempt.

observe (take the best ranked grasp, plan it) -> approach -> close -> lift -> hold
-> attempt done. A planning failure ends the attempt at once (it counts as a
failed attempt, as in the paper). The task state lives in the system's abstract
state; the episode driver (`drake_grasp.policy.episode`) reads the finished
attempt, removes a grasped object, sends the arm home and starts the next one.
"""

from __future__ import annotations

import copy
import enum
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue, Value
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from drake_grasp.hand import HAND_CLOSED, HAND_OPEN
from drake_grasp.planning.planner import GraspPlan, GraspPlanner
from drake_grasp.policy.drawing import draw_candidates
from drake_grasp.policy.sampling import approach_angle_deg
from drake_grasp.policy.selector import RankedGrasps
from drake_grasp.task import CLOSE_DURATION, HOLD_DURATION, SETTLE_AFTER_APPROACH, judge_lift

UPDATE_PERIOD = 0.02  # [s]


class Mode(enum.Enum):
    WAIT = "wait"  # objects settling, or the arm just returned home
    OBSERVE = "observe"
    APPROACH = "approach"
    CLOSE = "close"
    LIFT = "lift"
    HOLD = "hold"
    ATTEMPT_DONE = "attempt done"
    NO_OBJECTS = "no objects"


@dataclass
class Attempt:
    """One grasp attempt: what was planned, how it ended."""

    planned: bool
    success: bool
    failure: str | None  # a PlanFailure value, or an execution failure mode
    plan_seconds: float
    score: float
    approach_angle_deg: float
    object_index: int | None = None
    rise: float = 0.0


@dataclass
class ExecutiveState:
    mode: Mode = Mode.WAIT
    mode_start: float = 0.0
    wait_until: float = 0.0
    q_hold: np.ndarray = field(default_factory=lambda: np.zeros(0))
    hand_closed: bool = False
    plan: GraspPlan | None = None
    z_before: np.ndarray = field(default_factory=lambda: np.zeros(0))
    attempt: Attempt | None = None

    def __deepcopy__(self, memo):
        # Trajectories and plans are never mutated once made: share them.
        out = copy.copy(self)
        out.q_hold = self.q_hold.copy()
        out.z_before = self.z_before.copy()
        return out


class GraspExecutive(LeafSystem):
    """Ranked grasps, body poses and the arm and hand states in; arm and hand desired states out.

    `object_body_indices` are the plant body indices of the objects (in the
    `body_poses` input), `num_bodies` the plant's body count.
    """

    def __init__(self, planner: GraspPlanner, *, object_body_indices: Sequence[int], num_bodies: int,
                 settle_time: float, meshcat: Meshcat | None = None):
        super().__init__()
        self._planner = planner
        self._meshcat = meshcat
        robot = planner.robot
        self._q_home = np.asarray(robot.q_home, dtype=float)
        self._object_body_indices = [int(i) for i in object_body_indices]
        self._grasps_port = self.DeclareAbstractInputPort("ranked_grasps", Value(RankedGrasps.empty()))
        self._poses_port = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()] * num_bodies))
        self._arm_state_port = self.DeclareVectorInputPort("arm_state", 2 * robot.num_joints)
        self._hand_state_port = self.DeclareVectorInputPort("hand_state", 4)
        self._state_index = self.DeclareAbstractState(
            Value(ExecutiveState(q_hold=self._q_home.copy(), wait_until=settle_time)))
        self.DeclareVectorOutputPort("arm_desired_state", 2 * robot.num_joints, self._calc_arm,
                                     {self.all_state_ticket(), self.time_ticket()})
        self.DeclareVectorOutputPort("hand_desired_state", 2, self._calc_hand, {self.all_state_ticket()})
        self.DeclarePeriodicUnrestrictedUpdateEvent(UPDATE_PERIOD, 0.0, self._update)

    # -- state access for the episode driver ----------------------------------------------
    def get_task_state(self, context: Context) -> ExecutiveState:
        return self.GetMyContextFromRoot(context).get_abstract_state(self._state_index).get_value()

    def start_next_attempt(self, root_context: Context, wait_s: float) -> None:
        """Arm back home (the driver has set the plant), observe again after `wait_s`."""
        context = self.GetMyMutableContextFromRoot(root_context)
        t = context.get_time()
        state = ExecutiveState(q_hold=self._q_home.copy(), wait_until=t + wait_s, mode_start=t)
        context.SetAbstractState(self._state_index, state)

    # -- outputs --------------------------------------------------------------------------
    def _active_trajectory(self, s: ExecutiveState):
        if s.plan is None:
            return None
        if s.mode is Mode.APPROACH:
            return s.plan.approach
        if s.mode is Mode.LIFT:
            return s.plan.lift
        return None

    def _calc_arm(self, context: Context, output: BasicVector) -> None:
        s = context.get_abstract_state(self._state_index).get_value()
        traj = self._active_trajectory(s)
        if traj is None:
            q, v = s.q_hold, np.zeros_like(s.q_hold)
        else:
            t = np.clip(context.get_time() - s.mode_start, traj.start_time(), traj.end_time())
            q, v = traj.value(t).ravel(), traj.EvalDerivative(t, 1).ravel()
        output.SetFromVector(np.concatenate([q, v]))

    def _calc_hand(self, context: Context, output: BasicVector) -> None:
        s = context.get_abstract_state(self._state_index).get_value()
        output.SetFromVector([HAND_CLOSED if s.hand_closed else HAND_OPEN, 0.0])

    # -- the state machine ----------------------------------------------------------------
    def _object_heights(self, context: Context) -> np.ndarray:
        poses = self._poses_port.Eval(context)
        return np.array([poses[i].translation()[2] for i in self._object_body_indices])

    def _update(self, context: Context, state) -> None:
        s = copy.deepcopy(context.get_abstract_state(self._state_index).get_value())
        t = context.get_time()
        elapsed = t - s.mode_start

        def go(mode: Mode) -> None:
            s.mode, s.mode_start = mode, t

        if s.mode is Mode.WAIT and t >= s.wait_until:
            go(Mode.OBSERVE)
        elif s.mode is Mode.OBSERVE:
            self._observe_and_plan(context, s)
            s.mode_start = t
        elif s.mode is Mode.APPROACH and elapsed >= s.plan.approach.end_time() + SETTLE_AFTER_APPROACH:
            s.hand_closed, s.q_hold = True, s.plan.q_grasp
            go(Mode.CLOSE)
        elif s.mode is Mode.CLOSE and elapsed >= CLOSE_DURATION:
            go(Mode.LIFT)
        elif s.mode is Mode.LIFT and elapsed >= s.plan.lift.end_time():
            s.q_hold = s.plan.q_lift
            go(Mode.HOLD)
        elif s.mode is Mode.HOLD and elapsed >= HOLD_DURATION:
            self._judge(context, s)
            go(Mode.ATTEMPT_DONE)
        state.get_mutable_abstract_state(self._state_index).set_value(s)

    def _observe_and_plan(self, context: Context, s: ExecutiveState) -> None:
        ranked = self._grasps_port.Eval(context)
        if len(ranked.X_WG) == 0:
            s.mode = Mode.NO_OBJECTS
            return
        s.z_before = self._object_heights(context)
        X_WG = ranked.X_WG[0]
        q_now = self._arm_state_port.Eval(context)[: len(self._q_home)]
        result = self._planner.plan(X_WG, q_start=q_now)
        s.attempt = Attempt(
            planned=result.success, success=False,
            failure=None if result.success else result.failure.value,
            plan_seconds=result.seconds, score=float(ranked.scores[0]),
            approach_angle_deg=float(approach_angle_deg(X_WG)),
        )
        if self._meshcat is not None:
            draw_candidates(self._meshcat, ranked, planned=result.success)
        if result.success:
            s.plan = result.plan
            s.mode = Mode.APPROACH
        else:
            s.mode = Mode.ATTEMPT_DONE

    def _judge(self, context: Context, s: ExecutiveState) -> None:
        """The task's success rule on the object that rose most during the attempt."""
        rise = self._object_heights(context) - s.z_before
        k = int(np.argmax(rise))
        a = s.attempt
        a.rise, a.object_index = float(rise[k]), k
        a.failure = judge_lift(float(rise[k]), float(self._hand_state_port.Eval(context)[0]))
        a.success = a.failure is None
