import time

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix

from drake_grasp.planning.obstacles import ObservedScene, ObstacleConfig, obstacle_columns
from drake_grasp.planning.planner import GraspPlanner, PlanFailure, PlannerConfig
from drake_grasp.planning.timing import time_path
from drake_grasp.planning.transit import rrt_connect
from drake_grasp.robot.specs import ROBOTS
from drake_grasp.robot.task import LIFT_TRAVEL, PREGRASP_DISTANCE


def top_grasp(x, y, z, roll=0.3) -> RigidTransform:
    """Approach straight down (+z_G = world -z), jaws rolled by `roll`."""
    return RigidTransform(RotationMatrix.MakeXRotation(np.pi) @ RotationMatrix.MakeZRotation(roll), [x, y, z])


def assert_within_speed_limits(trajectory, v_max):
    times = np.linspace(trajectory.start_time(), trajectory.end_time(), 400)
    v = np.abs(np.column_stack([trajectory.EvalDerivative(t, 1) for t in times]))
    assert (v <= np.asarray(v_max)[:, None] * (1 + 1e-6)).all()


def assert_straight(planner, trajectory, p_from, p_to, R, samples: int = 60) -> None:
    """The TCP moves on the segment p_from -> p_to (within 2 mm) with its orientation R (within 1.5 deg)."""
    direction = (p_to - p_from) / np.linalg.norm(p_to - p_from)
    for t in np.linspace(trajectory.start_time(), trajectory.end_time(), samples):
        X = planner.tcp_pose(trajectory.value(t).ravel())
        offset = X.translation() - p_from
        assert np.linalg.norm(offset - (offset @ direction) * direction) < 2e-3
        assert -2e-3 < offset @ direction < np.linalg.norm(p_to - p_from) + 2e-3
        assert np.trace(R.inverse().multiply(X.rotation()).matrix()) > 1 + 2 * np.cos(np.radians(1.5))


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_reachable_grasp_gives_a_timed_plan_with_straight_approach_and_lift(planners, name):
    planner, spec = planners[name], ROBOTS[name]
    X_WG = top_grasp(0.5, 0.1, 0.04)
    result = planner.plan(X_WG)
    assert result.success, result.failure
    plan = result.plan
    transit, approach, lift = plan.transit, plan.approach, plan.lift
    np.testing.assert_allclose(transit.value(0).ravel(), spec.q_home, atol=1e-9)
    np.testing.assert_allclose(transit.value(transit.end_time()).ravel(), plan.q_pregrasp, atol=1e-9)
    np.testing.assert_allclose(approach.value(0).ravel(), plan.q_pregrasp, atol=1e-9)
    np.testing.assert_allclose(approach.value(approach.end_time()).ravel(), plan.q_grasp, atol=1e-9)
    np.testing.assert_allclose(lift.value(lift.end_time()).ravel(), plan.q_lift, atol=1e-9)
    # The TCP reaches the grasp (or its jaw-swapped twin) ...
    X_WT = planner.tcp_pose(plan.q_grasp)
    target = X_WG @ ROBOTS["panda"].hand.X_GT
    np.testing.assert_allclose(X_WT.translation(), target.translation(), atol=2e-3)
    assert abs(X_WT.rotation().col(2) @ target.rotation().col(2)) > np.cos(np.radians(1.5))
    assert abs(X_WT.rotation().col(1) @ target.rotation().col(1)) > np.cos(np.radians(1.5))
    # ... on a straight line along +z_G from the pre-grasp, then lifts straight up (as the trials move).
    p_grasp = X_WT.translation()
    p_pre = p_grasp - PREGRASP_DISTANCE * target.rotation().col(2)
    np.testing.assert_allclose(planner.tcp_pose(plan.q_pregrasp).translation(), p_pre, atol=1e-3)
    assert_straight(planner, approach, p_pre, p_grasp, X_WT.rotation())
    assert_straight(planner, lift, p_grasp, p_grasp + [0, 0, LIFT_TRAVEL], X_WT.rotation())
    for q in (plan.q_pregrasp, plan.q_grasp, plan.q_lift):
        assert planner.is_free(q)
    v_max = np.asarray(spec.v_max) * planner.config.speed_scale
    for trajectory in (transit, approach, lift):
        assert_within_speed_limits(trajectory, v_max)
    # The retreat after an empty close is the approach backwards.
    retreat = plan.retreat(planner.v_max)
    np.testing.assert_allclose(retreat.value(retreat.end_time()).ravel(), plan.q_pregrasp, atol=1e-9)
    assert_straight(planner, retreat, p_pre, p_grasp, X_WT.rotation())


def test_transit_goes_around_observed_objects_but_not_the_target():
    """A pile of points between home and the pre-grasp: the transit avoids it; the target does not count."""
    planner = GraspPlanner(ROBOTS["panda"], seed=0)
    home = np.asarray(ROBOTS["panda"].q_home)
    X_WG = top_grasp(0.55, -0.25, 0.04)
    rng = np.random.default_rng(0)
    target = rng.uniform([0.53, -0.27, 0.0], [0.57, -0.23, 0.04], (300, 3))  # the grasped object
    in_corridor = obstacle_columns(ObservedScene(target), X_WG.GetAsMatrix4(), ObstacleConfig())
    assert len(in_corridor) == 0
    free = planner.plan(X_WG, observed=ObservedScene(target))
    assert free.success and free.observed.num_columns == 0
    assert free.plan.transit.get_number_of_segments() == 1  # the straight edge
    pile = rng.uniform([0.35, -0.06, 0.0], [0.41, 0.0, 0.5], (2000, 3))  # in the way, 50 cm tall
    around = planner.plan(X_WG, observed=ObservedScene(np.vstack([target, pile])))
    assert around.success and around.observed.num_columns > 0
    assert not around.observed.is_edge_free(home, around.plan.q_pregrasp)  # the straight edge is blocked
    transit = around.plan.transit
    path = [transit.value(t).ravel() for t in transit.get_segment_times()]
    assert len(path) > 2 and around.observed.is_path_free(path)
    assert planner.is_edge_free(home, around.plan.q_pregrasp)  # the planner's own world has no objects
    # One observed world serves every plan: the next plan's columns replace these.
    again = planner.plan(X_WG, observed=ObservedScene(target))
    assert again.observed is around.observed and again.observed.num_columns == 0
    assert again.observed.is_edge_free(home, around.plan.q_pregrasp)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_unreachable_grasps_fail_with_a_reason(planners, name):
    planner = planners[name]
    far = planner.plan(top_grasp(1.6, 0.0, 0.05))
    assert not far.success and far.failure is PlanFailure.NO_IK_GRASP
    # Fingertips would have to go 25 mm into the table.
    into_table = planner.plan(top_grasp(0.5, 0.0, -0.005))
    assert not into_table.success and into_table.failure is PlanFailure.NO_IK_GRASP


def test_plans_repeat_for_the_same_seed():
    spec = ROBOTS["panda"]
    a = GraspPlanner(spec, seed=5).plan(top_grasp(0.6, -0.2, 0.05, roll=2.0))
    b = GraspPlanner(spec, seed=5).plan(top_grasp(0.6, -0.2, 0.05, roll=2.0))
    assert a.success and b.success
    np.testing.assert_array_equal(a.plan.q_grasp, b.plan.q_grasp)


def test_transit_around_an_obstacle_uses_rrt(planners):
    """The straight joint-space edge from home to this goal hits the arm or the table; OMPL goes round."""
    planner, spec = planners["panda"], ROBOTS["panda"]
    q1 = np.asarray(spec.q_home)
    q2 = np.array([2.17, -0.29, -2.42, -0.29, 0.71, 0.42, -2.24])
    assert planner.is_free(q2) and not planner.is_edge_free(q1, q2)
    path = planner.rrt(q1, q2)
    assert path is not None and len(path) >= 3
    np.testing.assert_allclose(path[0], q1)
    np.testing.assert_allclose(path[-1], q2)
    assert all(planner.is_edge_free(a, b) for a, b in zip(path, path[1:], strict=False))


def test_time_path_respects_velocity_limits(planners):
    planner, spec = planners["ur5"], ROBOTS["ur5"]
    rng = np.random.default_rng(0)
    waypoints = [rng.uniform(-1, 1, spec.num_joints) for _ in range(5)]
    trajectory = time_path(waypoints, planner.v_max)
    assert_within_speed_limits(trajectory, np.asarray(spec.v_max) * planner.config.speed_scale)
    np.testing.assert_allclose(trajectory.EvalDerivative(trajectory.end_time(), 1).ravel(), 0, atol=1e-9)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_reach_bound_holds_at_random_configurations(planners, name):
    """No configuration puts the TCP beyond the bound the planner uses to skip hopeless IK."""
    planner, spec = planners[name], ROBOTS[name]
    rng = np.random.default_rng(2)
    distances = [np.linalg.norm(planner.tcp_pose(rng.uniform(spec.q_lower, spec.q_upper)).translation()
                                - planner.p_shoulder) for _ in range(2000)]
    assert max(distances) <= planner.reach
    assert max(distances) > 0.8 * planner.reach  # and it is not a loose bound


def test_a_lowered_table_changes_what_is_reachable():
    """The arm on a 10 cm pedestal: grasps just above the lowered table top plan, those below do not."""
    lowered = GraspPlanner(ROBOTS["panda"], config=PlannerConfig(table_height=-0.1))
    assert lowered.plan(top_grasp(0.5, 0.1, -0.06)).success
    below_top = lowered.plan(top_grasp(0.5, 0.1, -0.11))
    assert not below_top.success and below_top.failure is PlanFailure.NO_IK_GRASP


def test_the_furthest_stage_is_reported_after_every_grasp_solution_failed():
    """At the edge of the Panda's reach the grasp has IK solutions but the lift, 20 cm higher, has none."""
    planner = GraspPlanner(ROBOTS["panda"], seed=0)
    at_edge = planner.plan(top_grasp(0.76, 0.0, 0.25))
    assert not at_edge.success and at_edge.failure is PlanFailure.NO_LIFT_LINE
    assert planner.plan(top_grasp(0.70, 0.0, 0.25)).success


def test_rrt_queries_repeat_whatever_ran_before():
    """OMPL's process-wide generator is reseeded per query: the same seed, the same path, in any order."""
    planner, spec = GraspPlanner(ROBOTS["panda"], seed=3), ROBOTS["panda"]
    q1 = np.asarray(spec.q_home)
    q2 = np.array([2.17, -0.29, -2.42, -0.29, 0.71, 0.42, -2.24])

    def query(seed: int) -> list[np.ndarray]:
        return rrt_connect(q1, q2, is_free=planner.is_free, is_edge_free=planner.is_edge_free,
                           q_lower=planner.q_lower, q_upper=planner.q_upper, max_checks=20_000, seed=seed)

    first = query(1)
    others = [query(seed) for seed in (2, 3)]
    again = query(1)
    assert len(first) == len(again)
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)
    assert any(len(o) != len(first) or not np.allclose(o[1], first[1]) for o in others)


def test_rrt_ends_past_a_joint_limit_by_rounding_are_planned_and_kept():
    """A goal 1e-13 rad past a limit (a line's last step, met in the closed loop) once made OMPL wait for
    a valid goal forever; it is planned from the limit and kept as given. Further out: no path, at once."""
    planner, spec = GraspPlanner(ROBOTS["panda"], seed=3), ROBOTS["panda"]
    q1 = np.asarray(spec.q_home)
    q2 = np.array([2.17, -0.29, -2.42, -0.29, 0.71, 0.42, -2.24])

    def query(q_upper: np.ndarray) -> list[np.ndarray] | None:
        return rrt_connect(q1, q2, is_free=planner.is_free, is_edge_free=planner.is_edge_free,
                           q_lower=planner.q_lower, q_upper=q_upper, max_checks=20_000, seed=1)

    rounded, beyond = planner.q_upper.copy(), planner.q_upper.copy()
    rounded[0], beyond[0] = q2[0] - 1e-13, q2[0] - 1e-3
    path = query(rounded)
    assert path is not None and len(path) > 2
    np.testing.assert_array_equal(path[0], q1)
    np.testing.assert_array_equal(path[-1], q2)
    assert query(beyond) is None


def test_plans_do_not_depend_on_wall_clock_time(monkeypatch):
    """A plan is the same when every clock reading jumps 10 s, as on a machine slowed to a crawl."""
    X_WG = top_grasp(0.6, -0.2, 0.05, roll=2.0)
    calm = GraspPlanner(ROBOTS["ur5"], seed=5).plan(X_WG)
    clock = iter(range(0, 10**6, 10))
    monkeypatch.setattr(time, "perf_counter", lambda: float(next(clock)))
    slowed = GraspPlanner(ROBOTS["ur5"], seed=5).plan(X_WG)
    assert calm.success and slowed.success
    np.testing.assert_array_equal(calm.plan.q_grasp, slowed.plan.q_grasp)
    np.testing.assert_array_equal(calm.plan.q_pregrasp, slowed.plan.q_pregrasp)


def test_a_configuration_fcl_cannot_decide_counts_as_a_collision(planners):
    """This UR5 configuration makes FCL's GJK throw on a near-degenerate capsule pair (a label shard
    once died of it inside an OMPL query); the planner treats it as a collision instead."""
    planner = planners["ur5"]
    q = np.array([2.2827641502164666, -1.4365040894548915, 2.967226389165062, -0.9105789618486196,
                  6.097521770804584, -1.7819393530535446])
    with pytest.raises(RuntimeError, match="Error with configuration"):
        planner.checker.CheckConfigCollisionFree(planner.full(q))
    assert not planner.is_free(q)
    assert not planner.is_edge_free(np.asarray(ROBOTS["ur5"].q_home), q)


def test_observed_columns_that_stay_are_kept_and_the_world_answers_as_one_made_anew():
    from drake_grasp.robot.collision import CollisionModel

    robot = ROBOTS["panda"]
    rng = np.random.default_rng(4)
    first = np.column_stack([rng.uniform(0.3, 0.6, (40, 2)), np.full(40, -np.inf),
                             rng.uniform(0.05, 0.5, 40)])
    new = np.column_stack([rng.uniform(0.3, 0.6, (10, 2)), np.full(10, -np.inf),
                           rng.uniform(0.05, 0.5, 10)])
    second = np.vstack([first[:25], new])
    reused, fresh, old = (CollisionModel(robot, table_height=0.0) for _ in range(3))
    reused.set_columns(first, 0.03)
    reused.set_columns(second, 0.03)
    fresh.set_columns(second, 0.03)
    old.set_columns(first, 0.03)
    assert reused.num_columns == fresh.num_columns == 35
    lower, upper = robot.limits()
    configurations = rng.uniform(lower, upper, (300, len(lower)))
    answers = np.array([(reused.is_free(q), fresh.is_free(q), old.is_free(q)) for q in configurations])
    assert (answers[:, 0] != answers[:, 2]).any()  # the columns changed where the arm goes
    np.testing.assert_array_equal(answers[:, 0], answers[:, 1])


def test_many_new_columns_get_a_new_checker_that_answers_as_added_ones(monkeypatch):
    import drake_grasp.robot.collision as collision

    robot = ROBOTS["panda"]
    rng = np.random.default_rng(5)
    many = np.column_stack([rng.uniform(0.25, 0.7, (90, 2)), np.full(90, -np.inf),
                            rng.uniform(0.05, 0.5, 90)])
    built = collision.CollisionModel(robot, table_height=0.0)
    built.set_columns(many, 0.03)  # more than MAX_ADDED_COLUMNS: a new checker
    monkeypatch.setattr(collision, "MAX_ADDED_COLUMNS", 1000)
    added = collision.CollisionModel(robot, table_height=0.0)
    added.set_columns(many, 0.03)
    assert built.num_columns == added.num_columns == 90
    lower, upper = robot.limits()
    configurations = rng.uniform(lower, upper, (300, len(lower)))
    answers = np.array([(built.is_free(q), added.is_free(q)) for q in configurations])
    np.testing.assert_array_equal(answers[:, 0], answers[:, 1])
    assert 0 < answers[:, 0].sum() < len(answers)
    built.set_columns(many[:10], 0.03)  # back to a few: they are added to a checker without the others
    assert built.num_columns == 10 and built.is_free(robot.q_home)
