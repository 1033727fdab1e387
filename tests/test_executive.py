"""The executive's state machine and the episode's bookkeeping, without a closed loop in physics."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import Simulator

from drake_grasp.cell.episode import ALL_REMOVED, NOTHING_REACHABLE, EpisodeLedger
from drake_grasp.cell.executive import Attempt, CellConfig, GraspExecutive, Mode
from drake_grasp.cell.judges import GripperJudge, ObjectPositions, ObservedCloud, SimulatorJudge
from drake_grasp.cell.memory import FailureMemory, MemoryConfig, successive_choices
from drake_grasp.evaluation.stats import mean_ci95
from drake_grasp.perception.cloud import ObjectCloud
from drake_grasp.policy.selector import RankedGrasps
from drake_grasp.robot.hand import default_hand
from drake_grasp.robot.specs import ROBOTS
from drake_grasp.robot.task import (
    CLOSED_ON_NOTHING_TEXT,
    LIFT_HEIGHT,
    NOT_IN_HAND_TEXT,
    NOT_LIFTED_TEXT,
    OBJECT_SLIPPED_TEXT,
    judge_grasp,
)
from drake_grasp.simulation.placement import FELL_OFF_Z

Z_OBJECT = 0.025
OBJECT, FINGERS, ROBOT = 1, [2, 3], [2, 3, 4]  # body indices of the fixed inputs
IN_HAND = frozenset({(OBJECT, FINGERS[0]), (OBJECT, FINGERS[1])})
HAND = default_hand()


def top_grasp(x: float, y: float, z: float) -> np.ndarray:
    return RigidTransform(RotationMatrix.MakeXRotation(np.pi), [x, y, z]).GetAsMatrix4()


def executive_at(planners, X_WG: np.ndarray | None, *, p_r: float = 0.9, p_s: float | None = None,
                 p_h: float | None = None, config: CellConfig | None = None):
    """The Panda's executive alone, its inputs fixed: one object (body 1) resting at Z_OBJECT.

    `X_WG` is one grasp or several, ranked in the order given. The hand state says the
    fingers stopped 2 cm open (an object between them).
    """
    spec = ROBOTS["panda"]
    judge = SimulatorJudge(object_body_indices=[OBJECT], finger_body_indices=FINGERS,
                           robot_body_indices=ROBOT, num_bodies=5, hand=spec.hand)
    executive = GraspExecutive(planners["panda"], judge=judge, settle_time=0.1,
                               config=config or CellConfig.paper())
    simulator = Simulator(executive)
    context = simulator.get_mutable_context()
    if X_WG is None:
        ranked = RankedGrasps.empty()
    else:
        X = np.asarray(X_WG).reshape(-1, 4, 4)
        ranked = RankedGrasps(X, np.linspace(0.9, 0.5, len(X)), 100, p_r=np.full(len(X), p_r),
                              p_s=None if p_s is None else np.full(len(X), p_s),
                              p_h=None if p_h is None else np.full(len(X), p_h))
    executive.GetInputPort("ranked_grasps").FixValue(context, ranked)
    executive.GetInputPort("object_cloud").FixValue(context, ObjectCloud.empty())
    set_object(executive, context, Z_OBJECT)
    executive.GetInputPort("body_contacts").FixValue(context, frozenset())
    executive.GetInputPort("arm_state").FixValue(context, np.concatenate([spec.q_home, np.zeros(7)]))
    set_fingers(executive, context, 0.02)
    return executive, simulator, context


def set_object(executive, context, z: float, x: float = 0.5) -> None:
    poses = [RigidTransform()] * 5
    poses[OBJECT] = RigidTransform([x, 0.1, z])
    executive.GetInputPort("body_poses").FixValue(context, poses)


def set_fingers(executive, context, position: float) -> None:
    executive.GetInputPort("hand_state").FixValue(context, [position, 0.0])


def advance_until(executive, simulator, context, mode: Mode, limit_s: float = 30.0) -> list[Mode]:
    """Steps until the executive is in `mode`; the modes it went through."""
    seen = [executive.get_task_state(context).mode]
    while seen[-1] is not mode:
        assert context.get_time() < limit_s, f"stuck in {seen[-1]}"
        simulator.AdvanceTo(context.get_time() + 0.02)
        if executive.get_task_state(context).mode is not seen[-1]:
            seen.append(executive.get_task_state(context).mode)
    return seen


def arm_command(executive, context) -> np.ndarray:
    return executive.GetOutputPort("arm_desired_state").Eval(context)[:7]


def test_an_attempt_runs_transit_approach_close_lift_hold_and_returns_home(planners):
    executive, simulator, context = executive_at(planners, top_grasp(0.5, 0.1, 0.04))
    advance_until(executive, simulator, context, Mode.TRANSIT)
    plan = executive.get_task_state(context).plan
    assert executive.GetOutputPort("hand_desired_state").Eval(context)[0] == HAND.open_position
    advance_until(executive, simulator, context, Mode.CLOSE)
    assert executive.GetOutputPort("hand_desired_state").Eval(context)[0] == HAND.closed_position
    np.testing.assert_allclose(arm_command(executive, context), plan.q_grasp)
    advance_until(executive, simulator, context, Mode.HOLD)
    np.testing.assert_allclose(arm_command(executive, context), plan.q_lift)
    set_object(executive, context, Z_OBJECT + LIFT_HEIGHT + 0.01)  # the object came along,
    executive.GetInputPort("body_contacts").FixValue(context, IN_HAND)  # between the fingers
    modes = advance_until(executive, simulator, context, Mode.ATTEMPT_DONE)
    assert modes == [Mode.HOLD, Mode.RETURN, Mode.ATTEMPT_DONE]  # holding it on the way home
    assert executive.GetOutputPort("hand_desired_state").Eval(context)[0] == HAND.closed_position
    np.testing.assert_allclose(arm_command(executive, context), ROBOTS["panda"].q_home, atol=1e-9)
    attempt = executive.get_task_state(context).attempt
    assert attempt.planned and attempt.success and attempt.failure is None and attempt.return_planned
    assert attempt.object_index == 0 and attempt.rise == pytest.approx(LIFT_HEIGHT + 0.01)


def test_an_object_that_rose_without_being_held_is_a_failure(planners):
    executive, simulator, context = executive_at(planners, top_grasp(0.5, 0.1, 0.04))
    advance_until(executive, simulator, context, Mode.HOLD)
    set_object(executive, context, Z_OBJECT + LIFT_HEIGHT + 0.05)  # risen, touching one finger only
    executive.GetInputPort("body_contacts").FixValue(context, frozenset({(OBJECT, FINGERS[0])}))
    modes = advance_until(executive, simulator, context, Mode.ATTEMPT_DONE)
    assert modes == [Mode.HOLD, Mode.RELEASE, Mode.RETURN, Mode.ATTEMPT_DONE]  # opened, then home
    attempt = executive.get_task_state(context).attempt
    assert not attempt.success and attempt.failure == NOT_IN_HAND_TEXT and attempt.object_index == 0


def test_a_slip_during_the_lift_opens_the_hand_and_goes_home_from_the_lift(planners):
    executive, simulator, context = executive_at(planners, top_grasp(0.5, 0.1, 0.04))
    advance_until(executive, simulator, context, Mode.LIFT)
    set_fingers(executive, context, 0.0)  # the object slipped out, the jaws met
    set_object(executive, context, Z_OBJECT + 0.05)
    modes = advance_until(executive, simulator, context, Mode.RETURN)
    assert modes == [Mode.LIFT, Mode.HOLD, Mode.RELEASE, Mode.RETURN]  # no retreat from up here
    state = executive.get_task_state(context)
    np.testing.assert_allclose(state.motion.value(0).ravel(), state.plan.q_lift, atol=1e-9)
    assert state.attempt.failure == OBJECT_SLIPPED_TEXT


def test_an_empty_close_is_sensed_and_the_hand_retreats_along_the_approach(planners):
    executive, simulator, context = executive_at(planners, top_grasp(0.5, 0.1, 0.04))
    set_fingers(executive, context, 0.0)  # the jaws meet
    advance_until(executive, simulator, context, Mode.CLOSE)
    plan = executive.get_task_state(context).plan
    modes = advance_until(executive, simulator, context, Mode.RETURN)
    assert modes == [Mode.CLOSE, Mode.RELEASE, Mode.RETREAT, Mode.RETURN]  # no lift
    np.testing.assert_allclose(executive.get_task_state(context).q_hold, plan.q_pregrasp, atol=1e-9)
    advance_until(executive, simulator, context, Mode.ATTEMPT_DONE)
    attempt = executive.get_task_state(context).attempt
    assert attempt.planned and attempt.failure == CLOSED_ON_NOTHING_TEXT and attempt.object_index == 0


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


def test_a_threshold_on_p_r_ends_the_run_with_nothing_reachable(planners):
    config = CellConfig(reach_threshold=0.2)
    executive, simulator, context = executive_at(planners, top_grasp(0.5, 0.1, 0.04), p_r=0.1, config=config)
    advance_until(executive, simulator, context, Mode.NOTHING_REACHABLE)
    assert context.get_time() < 0.2 and executive.get_task_state(context).attempt is None
    executive, simulator, context = executive_at(planners, top_grasp(0.5, 0.1, 0.04), p_r=0.3, config=config)
    advance_until(executive, simulator, context, Mode.TRANSIT)


def test_a_grasp_threshold_on_p_s_times_p_h_ends_the_run_with_nothing_graspable(planners):
    config, grasp = CellConfig(grasp_threshold=0.5), top_grasp(0.5, 0.1, 0.04)
    executive, simulator, context = executive_at(planners, grasp, p_s=0.8, p_h=0.5, config=config)
    advance_until(executive, simulator, context, Mode.NOTHING_GRASPABLE)  # 0.8 * 0.5 < 0.5
    assert executive.get_task_state(context).attempt is None
    executive, simulator, context = executive_at(planners, grasp, p_s=0.8, p_h=0.7, config=config)
    advance_until(executive, simulator, context, Mode.TRANSIT)
    executive, simulator, context = executive_at(planners, grasp, config=config)  # no p_s: never stops
    advance_until(executive, simulator, context, Mode.TRANSIT)


def empty_close_then_next(planners, config: CellConfig, *, moved: float = 0.0):
    """A grasp that closes on nothing, then the next attempt's choice between it and a second grasp."""
    grasps = np.stack([top_grasp(0.5, 0.1, 0.04), top_grasp(0.45, 0.0, 0.04)])
    executive, simulator, context = executive_at(planners, grasps, config=config)
    set_fingers(executive, context, 0.0)
    advance_until(executive, simulator, context, Mode.ATTEMPT_DONE)
    assert executive.get_task_state(context).attempt.failure == CLOSED_ON_NOTHING_TEXT
    set_object(executive, context, Z_OBJECT, x=0.5 + moved)
    executive.start_next_attempt(context, wait_s=0.0)
    advance_until(executive, simulator, context, Mode.TRANSIT)
    return executive.get_task_state(context)


def test_failure_memory_tries_another_grasp_while_the_scene_is_unchanged(planners):
    remembered = empty_close_then_next(planners, CellConfig())
    np.testing.assert_array_equal(remembered.X_WG, top_grasp(0.45, 0.0, 0.04))
    assert not remembered.attempt.repeat
    # Without memory (the paper's loop) the same grasp comes first again: a counted repeat.
    paper = empty_close_then_next(planners, CellConfig.paper())
    np.testing.assert_array_equal(paper.X_WG, top_grasp(0.5, 0.1, 0.04))
    assert paper.attempt.repeat
    # The object moved 2 cm: the scene changed, the failed grasp may be tried again.
    moved = empty_close_then_next(planners, CellConfig(), moved=0.02)
    np.testing.assert_array_equal(moved.X_WG, top_grasp(0.5, 0.1, 0.04))
    assert not moved.attempt.repeat


def test_memory_matches_position_and_approach_and_keeps_unplannable_grasps():
    memory = FailureMemory(MemoryConfig(radius=0.02, angle_deg=20.0, scene_change=0.01))
    scene = np.array([[0.5, 0.1, 0.02], [np.nan, np.nan, np.nan]])  # the second object already left
    memory.remember(top_grasp(0.5, 0.1, 0.04), scene_dependent=True, scene=ObjectPositions(scene))
    memory.remember(top_grasp(0.9, 0.0, 0.04), scene_dependent=False, scene=ObjectPositions(scene))
    tilted = RigidTransform(RotationMatrix.MakeXRotation(np.pi - np.radians(30)), [0.5, 0.1, 0.04])
    candidates = np.stack([top_grasp(0.51, 0.1, 0.04), top_grasp(0.53, 0.1, 0.04), tilted.GetAsMatrix4(),
                           top_grasp(0.9, 0.01, 0.04)])
    np.testing.assert_array_equal(memory.excluded(candidates), [True, False, False, True])
    memory.observe(ObjectPositions(scene + [[0.005, 0, 0], [0, 0, 0]]))  # moved 5 mm: the same scene
    assert memory.excluded(candidates)[0]
    memory.observe(ObjectPositions(scene + [[0.015, 0, 0], [0, 0, 0]]))  # moved 15 mm: changed
    np.testing.assert_array_equal(memory.excluded(candidates), [False, False, False, True])


def test_successive_choices_skip_the_grasps_near_those_tried_before():
    """The candidates a policy tries one after another in an unchanged scene if each fails: the best, then
    the best not near it (point within 2 cm and approach within 20 degrees), and so on."""
    tilted = RigidTransform(RotationMatrix.MakeXRotation(np.pi - np.radians(30)), [0.5, 0.1, 0.04])
    candidates = np.stack([top_grasp(0.5, 0.1, 0.04), top_grasp(0.51, 0.1, 0.04), tilted.GetAsMatrix4(),
                           top_grasp(0.7, 0.0, 0.04), top_grasp(0.71, 0.0, 0.04)])
    order = np.argsort(-np.array([0.9, 0.95, 0.5, 0.8, 0.6]))  # best first
    np.testing.assert_array_equal(successive_choices(candidates, order, 3), [1, 3, 2])
    np.testing.assert_array_equal(successive_choices(candidates, order, 9), [1, 3, 2])  # no more to try
    np.testing.assert_array_equal(successive_choices(candidates, order, 3, MemoryConfig(radius=0.005)),
                                  [1, 0, 3])


@pytest.mark.parametrize("rise, finger, in_hand, expected", [
    (LIFT_HEIGHT, 0.02, True, None),
    (LIFT_HEIGHT + 0.05, 0.02, False, NOT_IN_HAND_TEXT),
    (LIFT_HEIGHT, HAND.closed_on_nothing / 2, True, NOT_IN_HAND_TEXT),  # the jaws met: nothing between them
    (0.05, 0.02, True, OBJECT_SLIPPED_TEXT),
    (0.0, HAND.closed_on_nothing / 2, False, CLOSED_ON_NOTHING_TEXT),
    (0.0, 0.02, False, NOT_LIFTED_TEXT),
])
def test_the_success_rule(rise, finger, in_hand, expected):
    assert judge_grasp(rise, HAND.jaws_met(finger), in_hand) == expected


@pytest.mark.parametrize("rise, finger, in_hand, expected", [
    (0.05, 0.02, True, None),  # held, hanging below the hand: the field's success
    (LIFT_HEIGHT, 0.02, True, None),
    (0.05, 0.02, False, OBJECT_SLIPPED_TEXT),  # rose, then left the fingers
    (0.05, HAND.closed_on_nothing / 2, True, OBJECT_SLIPPED_TEXT),  # the jaws met
    (0.01, 0.02, True, NOT_LIFTED_TEXT),  # pinched but not off the table
    (LIFT_HEIGHT + 0.05, 0.02, False, NOT_IN_HAND_TEXT),
])
def test_the_fields_success_rule(rise, finger, in_hand, expected):
    assert judge_grasp(rise, HAND.jaws_met(finger), in_hand, "held") == expected


def test_an_unknown_success_rule_is_refused():
    with pytest.raises(ValueError, match="unknown success rule 'gripped'"):
        judge_grasp(0.2, False, True, "gripped")


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


def test_the_benchmark_ledger_ends_at_a_failed_grasp_not_at_a_failed_plan():
    ledger = EpisodeLedger(seed=0, object_names=["cube", "brick"], max_consecutive_failures=1,
                           max_consecutive_plan_failures=3)
    for _ in range(2):
        ledger.record(attempt(False, planned=False, k=None), t=1.0)  # nothing executed: try the next
        assert ledger.end_reason() is None
    ledger.record(attempt(True), t=2.0)  # an executed grasp resets the failed plans
    for _ in range(2):
        ledger.record(attempt(False, planned=False, k=None), t=3.0)
    assert ledger.end_reason() is None
    ledger.record(attempt(False, planned=False, k=None), t=4.0)
    assert ledger.end_reason() == "3 failed plans in a row"
    grasp_failed = EpisodeLedger(seed=0, object_names=["cube"], max_consecutive_failures=1,
                                 max_consecutive_plan_failures=3)
    grasp_failed.record(attempt(False, planned=False, k=None), t=1.0)
    grasp_failed.record(attempt(False), t=2.0)
    assert grasp_failed.end_reason() == "1 consecutive failures"


def test_ledger_counts_wasted_attempts_and_what_an_early_end_saved():
    ledger = EpisodeLedger(seed=0, object_names=["cube", "brick"], max_consecutive_failures=10,
                           max_attempts=6)
    ledger.record(attempt(False, planned=False, k=None), t=1.0)  # a failed plan
    ledger.record(attempt(False), t=2.0)
    repeat = attempt(False)
    repeat.repeat, repeat.transit_contacts = True, 2
    ledger.record(repeat, t=3.0)  # the same grasp again, on the same scene
    r = ledger.result
    assert r.wasted_attempts == 2 and r.repeated_failures == 1 and r.transit_contacts == 2
    ledger.end_early(NOTHING_REACHABLE)
    assert r.end_reason == "nothing reachable" and r.attempts_saved == 3  # the attempt limit left 3
    assert r.to_dict()["wasted_attempts"] == 2


def test_rates_over_runs_come_with_a_t_interval():
    mean, half = mean_ci95([0.8, 1.0, 0.9, 0.7])
    assert mean == pytest.approx(0.85)
    assert half == pytest.approx(3.182 * np.std([0.8, 1.0, 0.9, 0.7], ddof=1) / 2)
    assert np.isnan(mean_ci95([0.5])[1]) and mean_ci95([1.0] * 40) == (1.0, 0.0)


def test_an_observed_cloud_changes_when_an_object_moves_not_with_sensor_noise():
    rng = np.random.default_rng(0)
    box = rng.uniform([0.45, 0.0, 0.0], [0.5, 0.05, 0.05], (2000, 3))
    ball = rng.uniform([0.6, -0.1, 0.0], [0.64, -0.06, 0.04], (1500, 3))
    before = ObservedCloud(np.vstack([box, ball]))
    noisy = ObservedCloud(before.points + rng.normal(0, 0.001, before.points.shape))
    assert not noisy.changed_since(before, 0.01)
    assert not ObservedCloud(np.vstack([box + [0.004, 0, 0], ball])).changed_since(before, 0.01)
    assert ObservedCloud(np.vstack([box + [0.03, 0, 0], ball])).changed_since(before, 0.01)
    assert ObservedCloud(box).changed_since(before, 0.01)  # the ball went
    assert ObservedCloud(np.zeros((0, 3))).changed_since(before, 0.01)
    assert before.nearest_object(np.array([0.5, 0.0, 0.0])) is None  # a cloud knows no objects


def test_the_gripper_judge_reads_the_jaws_alone():
    judge, scene = GripperJudge(HAND), ObservedCloud(np.zeros((0, 3)))
    X = top_grasp(0.5, 0.1, 0.04)
    held = judge.grasp(None, scene, X, finger=0.0245, grip=0.025)
    assert held.success and held.failure is None and held.object_index is None and np.isnan(held.rise)
    assert judge.grasp(None, scene, X, finger=0.004, grip=0.012).success  # a held object settles in the pads
    assert judge.grasp(None, scene, X, finger=0.0005, grip=0.025).failure == OBJECT_SLIPPED_TEXT  # lost it
    assert judge.grasp(None, scene, X, finger=0.0005, grip=None).failure == CLOSED_ON_NOTHING_TEXT
    with pytest.raises(ValueError, match="judges grasps only"):
        judge.push(None, scene, X)
