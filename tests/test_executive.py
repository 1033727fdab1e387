"""The executive's state machine and the episode's bookkeeping, without a closed loop in physics."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import Simulator

from drake_grasp.hand import HAND_CLOSED, HAND_OPEN
from drake_grasp.policy.episode import ALL_REMOVED, FELL_OFF_Z, EpisodeLedger
from drake_grasp.policy.executive import Attempt, GraspExecutive, Mode
from drake_grasp.policy.selector import RankedGrasps
from drake_grasp.robots import ROBOTS
from drake_grasp.task import (
    CLOSED_ON_NOTHING,
    CLOSED_ON_NOTHING_TEXT,
    LIFT_HEIGHT,
    NOT_LIFTED_TEXT,
    OBJECT_SLIPPED_TEXT,
    judge_lift,
)

Z_OBJECT = 0.025


def top_grasp(x: float, y: float, z: float) -> np.ndarray:
    return RigidTransform(RotationMatrix.MakeXRotation(np.pi), [x, y, z]).GetAsMatrix4()


def executive_at(planners, X_WG: np.ndarray | None):
    """The Panda's executive alone, its inputs fixed: one object (body 1) resting at Z_OBJECT."""
    spec = ROBOTS["panda"]
    executive = GraspExecutive(planners["panda"], object_body_indices=[1], num_bodies=2, settle_time=0.1)
    simulator = Simulator(executive)
    context = simulator.get_mutable_context()
    ranked = RankedGrasps.empty() if X_WG is None else RankedGrasps(X_WG[None], np.array([0.9]), 100)
    executive.GetInputPort("ranked_grasps").FixValue(context, ranked)
    set_object_height(executive, context, Z_OBJECT)
    executive.GetInputPort("arm_state").FixValue(context, np.concatenate([spec.q_home, np.zeros(7)]))
    executive.GetInputPort("hand_state").FixValue(context, np.zeros(4))  # fingers met: closed on nothing
    return executive, simulator, context


def set_object_height(executive, context, z: float) -> None:
    executive.GetInputPort("body_poses").FixValue(context, [RigidTransform(), RigidTransform([0.5, 0.1, z])])


def advance_until(executive, simulator, context, mode: Mode, limit_s: float = 20.0) -> None:
    while executive.get_task_state(context).mode is not mode:
        assert context.get_time() < limit_s, f"stuck in {executive.get_task_state(context).mode}"
        simulator.AdvanceTo(context.get_time() + 0.02)


def test_an_attempt_runs_approach_close_lift_hold_and_is_judged(planners):
    executive, simulator, context = executive_at(planners, top_grasp(0.5, 0.1, 0.04))
    advance_until(executive, simulator, context, Mode.APPROACH)
    plan = executive.get_task_state(context).plan
    assert executive.GetOutputPort("hand_desired_state").Eval(context)[0] == HAND_OPEN
    advance_until(executive, simulator, context, Mode.CLOSE)
    assert executive.GetOutputPort("hand_desired_state").Eval(context)[0] == HAND_CLOSED
    np.testing.assert_allclose(executive.GetOutputPort("arm_desired_state").Eval(context)[:7], plan.q_grasp)
    advance_until(executive, simulator, context, Mode.HOLD)
    np.testing.assert_allclose(executive.GetOutputPort("arm_desired_state").Eval(context)[:7], plan.q_lift)
    set_object_height(executive, context, Z_OBJECT + LIFT_HEIGHT + 0.01)  # the object came along
    advance_until(executive, simulator, context, Mode.ATTEMPT_DONE)
    attempt = executive.get_task_state(context).attempt
    assert attempt.planned and attempt.success and attempt.failure is None
    assert attempt.object_index == 0 and attempt.rise == pytest.approx(LIFT_HEIGHT + 0.01)


def test_an_object_left_behind_is_a_failed_attempt(planners):
    executive, simulator, context = executive_at(planners, top_grasp(0.5, 0.1, 0.04))
    advance_until(executive, simulator, context, Mode.ATTEMPT_DONE)
    attempt = executive.get_task_state(context).attempt
    assert attempt.planned and not attempt.success and attempt.failure == CLOSED_ON_NOTHING_TEXT


def test_an_unreachable_grasp_ends_the_attempt_at_once(planners):
    executive, simulator, context = executive_at(planners, top_grasp(1.6, 0.0, 0.05))
    advance_until(executive, simulator, context, Mode.ATTEMPT_DONE)
    attempt = executive.get_task_state(context).attempt
    assert not attempt.planned and attempt.failure == "no IK for the grasp"
    assert context.get_time() < 0.2  # no motion was simulated
    executive.start_next_attempt(context, wait_s=0.3)
    assert executive.get_task_state(context).mode is Mode.WAIT


def test_no_candidates_means_no_objects(planners):
    executive, simulator, context = executive_at(planners, None)
    advance_until(executive, simulator, context, Mode.NO_OBJECTS)


@pytest.mark.parametrize("rise, finger, expected", [
    (LIFT_HEIGHT, 0.0, None),
    (0.05, 0.02, OBJECT_SLIPPED_TEXT),
    (0.0, CLOSED_ON_NOTHING / 2, CLOSED_ON_NOTHING_TEXT),
    (0.0, 0.02, NOT_LIFTED_TEXT),
])
def test_the_success_rule(rise, finger, expected):
    assert judge_lift(rise, finger) == expected


def attempt(success: bool, *, planned: bool = True, k: int | None = 0) -> Attempt:
    return Attempt(planned=planned, success=success, failure=None if success else "closed on nothing",
                   plan_seconds=0.01, score=0.5, approach_angle_deg=10.0, object_index=k)


def test_ledger_counts_and_ends_when_every_object_is_gone():
    ledger = EpisodeLedger(seed=0, object_names=["cube", "brick", "arch"], max_consecutive_failures=5)
    entry = ledger.record(attempt(True, k=1), t=3.0)
    assert entry["object"] == "brick" and entry["t"] == 3.0
    assert list(ledger.present) == [True, False, True] and ledger.end_reason() is None
    ledger.remove_fallen([0.02, -50.0, FELL_OFF_Z - 0.1])  # brick parked (not counted), arch fell
    assert list(ledger.present) == [True, False, False] and ledger.result.objects_fell_off == 1
    ledger.record(attempt(True, k=0), t=6.0)
    assert ledger.end_reason() == ALL_REMOVED
    r = ledger.result
    assert (r.attempts, r.successes, r.objects_grasped, r.completion_rate) == (2, 2, 2, pytest.approx(2 / 3))


def test_ledger_stops_after_consecutive_failures_and_the_attempt_limit():
    ledger = EpisodeLedger(seed=0, object_names=["cube", "brick"], max_consecutive_failures=3)
    ledger.record(attempt(False), t=1.0)
    ledger.record(attempt(False, planned=False, k=None), t=1.0)
    ledger.record(attempt(True), t=2.0)  # a success resets the count
    for _ in range(2):
        ledger.record(attempt(False), t=3.0)
        assert ledger.end_reason() is None
    ledger.record(attempt(False), t=4.0)
    assert ledger.end_reason() == "3 consecutive failures"
    r = ledger.result
    assert r.failures == {"closed on nothing": 5} and r.plans_tried == 6 and r.plans_succeeded == 5
    limited = EpisodeLedger(seed=0, object_names=["cube", "brick"], max_consecutive_failures=10,
                            max_attempts=2)
    limited.record(attempt(False), t=1.0)
    limited.record(attempt(False), t=2.0)
    assert limited.end_reason() == "2 attempts (the scenario's limit)"
