"""Objects under scene structure: perception keeps the structure apart, planning sees it as the cameras
did (free where a camera saw through), the hand never goes into it, and the constrained scenario
renders a stool that the cell recognizes."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix

from drake_grasp.perception.cloud import camera_rays, extract_object_cloud, split_structure
from drake_grasp.planning.obstacles import ObservedScene, ObstacleConfig, free_voxels, obstacle_columns
from drake_grasp.planning.planner import GraspPlanner, PlanFailure, PlannerConfig
from drake_grasp.policy.clearance import corridor_blocked, thinned
from drake_grasp.robot.specs import ROBOTS
from drake_grasp.robot.task import LIFT_TRAVEL

SEAT = ((0.45, 0.81), (-0.2, 0.2), 0.28)  # x range, y range, underside z of a stool's seat [m]


def grid(x, y, z):
    """Points on the axis-aligned patch spanned by the ranges (a float is a plane), 5 mm apart."""
    axes = [np.arange(a[0], a[1] + 1e-9, 0.005) if isinstance(a, tuple) else np.array([a])
            for a in (x, y, z)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def stool_cloud() -> np.ndarray:
    (x0, x1), (y0, y1), under = SEAT
    seat = np.vstack([grid((x0, x1), (y0, y1), under + 0.02), grid((x0, x1), (y0, y1), under)])
    legs = [grid(x, (y, y + 0.03), (0.005, under)) for x in (x0, x1 - 0.03) for y in (y0, y1 - 0.03)]
    # A leg's side, seen apart from the leg (2 cm from its front): it belongs to the structure as well.
    side = grid(x0 + 0.02, (y0, y0 + 0.03), (0.005, 0.2))
    return np.vstack([seat, *legs, side])


def cube(centre, size=0.05) -> np.ndarray:
    c = np.asarray(centre)
    h = size / 2
    return np.vstack([grid((c[0] - h, c[0] + h), (c[1] - h, c[1] + h), c[2] + size),
                      grid(c[0] - h, (c[1] - h, c[1] + h), (c[2], c[2] + size))])


def test_structure_is_split_from_the_objects_and_takes_what_lies_against_it():
    under_the_seat, beside = cube([0.6, 0.0, 0.0]), cube([0.3, -0.3, 0.0])
    objects, structure = split_structure(np.vstack([stool_cloud(), under_the_seat, beside]), extent=0.3)
    assert len(objects) == len(under_the_seat) + len(beside)
    expected = np.vstack([under_the_seat, beside])
    np.testing.assert_array_equal(np.sort(objects, axis=0), np.sort(expected, axis=0))
    assert len(structure) == len(stool_cloud())
    # Without a structure extent every point above the table is an object, as in every other scene.
    table = grid((0.2, 1.0), (-0.4, 0.4), 0.0)
    cloud = extract_object_cloud(np.vstack([table, stool_cloud(), under_the_seat]), lower=[0, -1, -0.02],
                                 upper=[1.2, 1, 0.34])
    assert len(cloud.structure) == 0 and cloud.rays is None


def test_camera_rays_follow_the_clouds_order_and_refuse_a_cloud_of_another_size():
    a, b = np.full((4, 3), 0.1), np.full((6, 3), 0.2)
    b[0] = np.nan
    origins, ends = camera_rays(np.vstack([a, b]), [(np.zeros(3), 4), (np.ones(3), 6)], [0, 0, 0], [1, 1, 1])
    assert len(ends) == 9
    np.testing.assert_array_equal(origins[:4], 0.0)
    np.testing.assert_array_equal(origins[4:], 1.0)
    with pytest.raises(ValueError, match="the cloud has 10 points, the cameras' images 9"):
        camera_rays(np.vstack([a, b]), [(np.zeros(3), 4), (np.ones(3), 5)], [0, 0, 0], [1, 1, 1])


def seen_rays(points: np.ndarray, camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.tile(camera, (len(points), 1)), points


def test_a_seat_seen_from_the_side_is_a_board_over_free_space():
    config = ObstacleConfig()
    (x0, x1), (y0, y1), under = SEAT
    seat_top = grid((x0, x1), (y0, y1), under + 0.02)
    seat_under = grid((x0, x1), (y0, y1), under)
    table_under_it = grid((x0, x1), (y0, y1), 0.0)
    X_far = np.eye(4)
    X_far[:3, 3] = [2.0, 2.0, 0.0]  # a grasp elsewhere: its corridor cuts nothing
    # From above alone: the seat is a block down to the table (nothing says what lies under it).
    above = obstacle_columns(ObservedScene(np.zeros((0, 3)), seat_top), X_far, config, free=None)
    assert np.all(above[:, 2] == -np.inf) and np.allclose(above[:, 3], under + 0.02)
    # A camera from the side sees the underside and the table beneath: the space between is free.
    side = np.array([0.63, -0.75, 0.12])
    rays = seen_rays(np.vstack([seat_under, table_under_it]), side)
    free = free_voxels(rays, config, table_z=0.0, top_z=under + 0.04)
    seat = ObservedScene(np.zeros((0, 3)), np.vstack([seat_top, seat_under]))
    columns = obstacle_columns(seat, X_far, config, free=free)
    inside = (columns[:, 0] > x0 + 0.03) & (columns[:, 0] < x1 - 0.03) & (np.abs(columns[:, 1]) < y1 - 0.03)
    assert inside.sum() > 50
    assert np.all(columns[inside, 2] >= under - config.slice - 1e-9)  # a board, not a block
    # With free voxels but no rays through a cell, its column still reaches the table.
    alone = obstacle_columns(ObservedScene(np.zeros((0, 3)), cube([0.2, 0.5, 0.0])), X_far, config, free=free)
    assert np.all(alone[:, 2] == -np.inf)


def top_grasp(p) -> np.ndarray:
    X = RigidTransform(RotationMatrix.MakeXRotation(np.pi), p).GetAsMatrix4()
    return X


def test_the_approach_corridor_ignores_objects_but_never_structure():
    config = ObstacleConfig()
    target = cube([0.6, 0.0, 0.0])
    X = top_grasp([0.6, 0.0, 0.03])
    assert len(obstacle_columns(ObservedScene(target), X, config)) == 0
    assert len(obstacle_columns(ObservedScene(np.zeros((0, 3)), target), X, config)) > 0
    # Selection ranks last a top grasp under the seat, not one from the open side.
    seat = grid(SEAT[0], SEAT[1], SEAT[2])
    X_side = RigidTransform(RotationMatrix.MakeXRotation(np.pi / 2), [0.6, -0.12, 0.03]).GetAsMatrix4()
    blocked = corridor_blocked(thinned(seat), np.stack([X, X_side]), config.corridor_margin)
    assert blocked.tolist() == [True, False]
    assert corridor_blocked(np.zeros((0, 3)), X[None], config.corridor_margin).tolist() == [False]


@pytest.fixture(scope="module")
def planner():
    return GraspPlanner(ROBOTS["panda"], seed=0, config=PlannerConfig(retreat_before_lift=0.2))


def test_a_grasp_into_the_structure_fails_and_the_lift_can_draw_the_object_out_first(planner):
    X = top_grasp([0.5, 0.25, 0.03])
    free = planner.plan(X)
    assert free.success
    p_grasp = planner.tcp_pose(free.plan.q_grasp).translation()
    # The lift goes back along the approach (up, for a top grasp) and then up.
    lift = free.plan.lift
    end = planner.tcp_pose(lift.value(lift.end_time()).ravel()).translation()
    np.testing.assert_allclose(end, p_grasp + [0, 0, 0.2 + LIFT_TRAVEL], atol=2e-3)
    # A board over the grasp, seen from above and from the side (its underside and the table beneath).
    def board_at(z):
        under = grid((0.35, 0.65), (0.1, 0.4), z)
        seen = np.vstack([under, grid((0.35, 0.65), (0.1, 0.4), 0.0)])
        return np.vstack([under, under + [0, 0, 0.02]]), seen_rays(seen, [0.5, -0.6, 0.2])

    # 20 cm up, the arm at the grasp would pass through it: the IK, kept off the structure, finds none.
    board, rays = board_at(0.23)
    low = planner.plan(X, observed=ObservedScene(np.zeros((0, 3)), board, rays))
    assert low.failure is PlanFailure.NO_IK_GRASP
    # 35 cm up, the grasp is free but the lift (40 cm: out along the approach, then up) goes into it.
    board, rays = board_at(0.38)
    high = planner.plan(X, observed=ObservedScene(np.zeros((0, 3)), board, rays))
    assert high.failure is PlanFailure.INTO_STRUCTURE
    # The same board far from the grasp changes nothing.
    away = ObservedScene(np.zeros((0, 3)), board + [0.0, -0.7, 0.0])
    assert planner.plan(X, observed=away).success


def test_the_constrained_scene_puts_objects_under_a_stool_that_the_cell_sees_as_structure():
    from drake_grasp.cell.diagram import build_cell
    from drake_grasp.policy.scorers import random_scorer
    from drake_grasp.simulation.objects import load_object_set
    from drake_grasp.simulation.scenario import load_scenario

    scenario = load_scenario("constrained")
    cell = build_cell(robot=ROBOTS["panda"], scenario=scenario, scorer=random_scorer,
                      object_models=load_object_set("primitives"), seed=3)
    cell.advance(scenario.settle_time)
    perception_context = cell.perception.GetMyContextFromRoot(cell.context)
    cloud = cell.perception.GetOutputPort("object_cloud").Eval(perception_context)
    assert len(cloud.structure) > 10_000 and cloud.rays is not None
    # The objects lie under the seat (its underside 0.28 m up), seen by the camera from the side.
    plant, plant_context = cell.station.plant(), cell.station.plant_context(cell.context)
    for body in cell.station.object_bodies:
        x, y, z = plant.EvalBodyPoseInWorld(plant_context, body).translation()
        assert 0.45 < x < 0.84 and abs(y) < 0.2 and z < 0.2
    assert len(cloud) > 500 and cloud.points[:, 2].max() < 0.27
    # Planning sees the seat as a board over free space, the legs as posts.
    planner = GraspPlanner(ROBOTS["panda"], seed=0)
    world = planner.structure_world(ObservedScene(cloud.points, cloud.structure, cloud.rays))
    columns = np.array(sorted(world._built_with | set(world._column_groups)))[:, :4]
    seat = (columns[:, 0] > 0.53) & (columns[:, 0] < 0.79) & (np.abs(columns[:, 1]) < 0.15)
    assert seat.sum() > 50 and np.all(columns[seat, 2] > 0.2)


def test_a_fixture_written_as_a_plain_urdf_stands_in_the_station(tmp_path):
    import dataclasses as dc

    from drake_grasp.simulation.scenario import Fixture, load_scenario
    from drake_grasp.simulation.station import Station

    shelf = tmp_path / "shelf.urdf"  # as a ROS description writes it: no Drake tags, a box per part
    parts = {"board": ("0 0 0.25", "0.3 0.5 0.02"), "left": ("0 0.24 0.12", "0.3 0.02 0.24"),
             "right": ("0 -0.24 0.12", "0.3 0.02 0.24")}
    shapes = {n: f"<origin xyz='{xyz}'/><geometry><box size='{size}'/></geometry>"
              for n, (xyz, size) in parts.items()}
    links = "".join(f"<collision name='{n}'>{shape}</collision><visual>{shape}</visual>"
                    for n, shape in shapes.items())
    inertia = "<inertia ixx='1' iyy='1' izz='1' ixy='0' ixz='0' iyz='0'/>"
    shelf.write_text(f"<robot name='shelf'><link name='base'><inertial><mass value='5'/>{inertia}</inertial>"
                     f"{links}</link></robot>")
    fixture = Fixture(model=str(shelf), xyz=[0.6, 0.0, 0.0])
    scenario = dc.replace(load_scenario("standard"), fixtures=[fixture])
    station = Station(scenario=scenario, robot=ROBOTS["panda"], objects=[])
    plant = station.plant()
    body = plant.GetBodyByName("base", plant.GetModelInstanceByName("fixture_0"))
    assert len(plant.GetCollisionGeometriesForBody(body)) == 3
    X_WB = plant.EvalBodyPoseInWorld(plant.CreateDefaultContext(), body)
    np.testing.assert_allclose(X_WB.translation(), [0.6, 0.0, 0.0])
