"""The offline models: kinematics against the published DH chains, parsing, collision, rendering."""

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator

from drake_grasp.perception.cloud import extract_object_cloud
from drake_grasp.robot.hand import default_hand
from drake_grasp.robot.paths import SDF_DIR, make_parser
from drake_grasp.robot.specs import ROBOTS
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.placement import place_objects
from drake_grasp.simulation.scenario import load_scenario
from drake_grasp.simulation.station import Station


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])


def _t(x=0.0, z=0.0):
    T = np.eye(4)
    T[0, 3], T[2, 3] = x, z
    return T


def dh_forward_kinematics(dh, q) -> np.ndarray:
    """Flange pose from a DH table, written independently of the model generator."""
    T = np.eye(4)
    for i, qi in enumerate(q):
        if dh.modified:
            T = T @ _rx(dh.alpha[i]) @ _t(x=dh.a[i]) @ _rz(qi) @ _t(z=dh.d[i])
        else:
            T = T @ _rz(qi) @ _t(z=dh.d[i]) @ _t(x=dh.a[i]) @ _rx(dh.alpha[i])
    return T @ _t(z=dh.flange_d)


def arm_plant(spec) -> MultibodyPlant:
    """The arm alone, its base welded at the world origin."""
    plant = MultibodyPlant(0.0)
    make_parser(plant).AddModels(url=spec.model_url)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(spec.base_link))
    plant.Finalize()
    return plant


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_forward_kinematics_matches_published_dh(name):
    spec = ROBOTS[name]
    plant = arm_plant(spec)
    context = plant.CreateDefaultContext()
    flange = plant.GetFrameByName(spec.flange_link)
    rng = np.random.default_rng(7)
    for _ in range(100):
        q = rng.uniform(spec.q_lower, spec.q_upper)
        plant.SetPositions(context, q)
        X = flange.CalcPoseInWorld(context).GetAsMatrix4()
        np.testing.assert_allclose(X, dh_forward_kinematics(spec.dh, q), atol=1e-6)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_joint_limits_match_the_spec(name):
    spec = ROBOTS[name]
    plant = arm_plant(spec)
    np.testing.assert_allclose(plant.GetPositionLowerLimits(), spec.q_lower)
    np.testing.assert_allclose(plant.GetPositionUpperLimits(), spec.q_upper)
    np.testing.assert_allclose(plant.GetVelocityUpperLimits(), spec.v_max)
    np.testing.assert_allclose(plant.GetEffortUpperLimits(), spec.effort_max)


def test_every_model_parses_with_positive_mass():
    files = sorted(SDF_DIR.rglob("*.sdf"))
    assert len(files) >= 4 + 8 + 5
    for path in files:
        plant = MultibodyPlant(0.0)
        make_parser(plant).AddModels(str(path))
        plant.Finalize()
        context = plant.CreateDefaultContext()
        assert plant.CalcTotalMass(context) > 0, path


def test_object_sets():
    assert {m.name for m in load_object_set("primitives")} == {
        "triangular_prism", "arch", "square_slab", "brick", "cube", "tall_block", "half_cylinder",
        "cylinder"}
    assert len(load_object_set("novel")) >= 5
    assert not {m.name for m in load_object_set("novel")} & {m.name for m in load_object_set("primitives")}


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_home_is_collision_free_and_collisions_are_detected(planners, name):
    planner, spec = planners[name], ROBOTS[name]
    q_home = np.asarray(spec.q_home)
    assert planner.is_free(q_home)
    # Shoulder pitched down hard: the arm goes through the table.
    q_down = q_home.copy()
    q_down[1] = spec.q_upper[1] if name == "panda" else 0.6
    q_down[2] = 0.0
    assert not planner.is_free(q_down)


def test_camera_renders_the_objects_on_the_table():
    scenario = load_scenario("single")
    robot = ROBOTS["panda"]
    cube = [m for m in load_object_set("primitives") if m.name == "cube"]
    station = Station(scenario=scenario, robot=robot, objects=cube)
    simulator = Simulator(station)
    context = simulator.get_mutable_context()
    plant, plant_context = station.plant(), station.plant_context(context)
    place_objects(plant, plant_context, station.scene_graph().model_inspector(), station.object_bodies,
                  scenario, np.random.default_rng(3))
    station.set_home(context)
    station.GetInputPort("arm_desired_state").FixValue(
        context, np.concatenate([robot.q_home, np.zeros(robot.num_joints)]))
    station.GetInputPort("hand_desired_state").FixValue(context, [default_hand().open_position, 0])
    simulator.AdvanceTo(0.8)
    p_cube = plant.EvalBodyPoseInWorld(plant_context, station.object_bodies[0]).translation()
    assert p_cube[2] == pytest.approx(0.025, abs=0.004)  # settled on a face: half its 50 mm size
    # The exported ports: the arm held at home, the cube among the body poses, a depth image.
    np.testing.assert_allclose(station.GetOutputPort("arm_state").Eval(context)[:robot.num_joints],
                               robot.q_home, atol=2e-3)
    poses = station.GetOutputPort("body_poses").Eval(context)
    np.testing.assert_allclose(poses[int(station.object_bodies[0].index())].translation(), p_cube)
    depth = station.GetOutputPort("depth_image").Eval(context)
    camera = scenario.sensing.camera
    assert (depth.width(), depth.height()) == (camera.width, camera.height)
    cloud = station.GetOutputPort("point_cloud_W").Eval(context)
    box = scenario.sensing.workspace
    objects = extract_object_cloud(cloud.xyzs().T, lower=box.lower, upper=box.upper)
    assert len(objects) > 100
    # Every object point lies on the cube, within a voxel or two of its 50 mm extent.
    assert np.abs(objects.points[:, :2] - p_cube[:2]).max() < 0.025 * np.sqrt(2) + 0.006
    assert objects.points[:, 2].max() == pytest.approx(0.05, abs=0.004)
