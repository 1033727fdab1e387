import numpy as np
import pytest
from pydrake.multibody.plant import ContactModel, DiscreteContactApproximation

from drake_grasp.perception.camera import points_in_base
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.specs import ROBOTS
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.placement import PARKING_Z, choose_objects, park_object, place_objects
from drake_grasp.simulation.scenario import load_scenario, scenario_names
from drake_grasp.simulation.station import Station


def test_shipped_scenarios_load():
    assert {"standard", "challenging", "ablation", "single"} <= set(scenario_names())
    assert load_scenario("standard").num_objects == 10
    assert load_scenario("challenging").num_objects == 30
    ablation = load_scenario("ablation")
    assert len(ablation.clusters) == 2 and ablation.max_attempts == 5
    assert load_scenario("single").num_objects == 1


def test_unknown_and_malformed_scenarios_are_named(tmp_path):
    with pytest.raises(ValueError, match="unknown scenario 'nope'.*standard"):
        load_scenario("nope")
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nnot_a_field: 3\n")
    with pytest.raises(ValueError, match="invalid scenario file"):
        load_scenario(str(bad))


def test_unknown_robot_is_named():
    with pytest.raises(ValueError, match="unknown robot 'kuka'; choose one of: panda, ur5"):
        get_robot("kuka")


def test_dropped_objects_start_without_overlap():
    scenario = load_scenario("challenging")
    rng = np.random.default_rng(0)
    objects = choose_objects(load_object_set("primitives"), scenario.num_objects, rng)
    station = Station(scenario=scenario, robot=ROBOTS["panda"], objects=objects)
    context = station.CreateDefaultContext()
    plant, plant_context = station.plant(), station.plant_context(context)
    inspector = station.scene_graph().model_inspector()
    place_objects(plant, plant_context, inspector, station.object_bodies, scenario, rng)
    query = station.GetOutputPort("query_object").Eval(context)
    object_geometries = {g for b in station.object_bodies for g in plant.GetCollisionGeometriesForBody(b)}
    overlaps = [p for p in query.ComputeSignedDistancePairwiseClosestPoints(0.0)
                if p.id_A in object_geometries and p.id_B in object_geometries
                and inspector.GetFrameId(p.id_A) != inspector.GetFrameId(p.id_B)]
    assert overlaps == []
    # The closed-loop scenes step 4 ms (the grasp trials 2 ms), the YAML naming only the step: SAP and
    # hydroelastic stay.
    assert plant.time_step() == 0.004 == load_scenario("standard").plant_config.time_step
    assert load_scenario("single").plant_config.time_step == 0.002
    assert plant.get_discrete_contact_approximation() == DiscreteContactApproximation.kSap
    assert plant.get_contact_model() == ContactModel.kHydroelasticWithFallback
    heights = [plant.EvalBodyPoseInWorld(plant_context, b).translation()[2]
               for b in station.object_bodies]
    assert min(heights) > scenario.drop_height
    # A removed object is parked at rest far below the table, out of every other object's way.
    park_object(plant, plant_context, station.object_bodies[3], 3)
    body = station.object_bodies[3]
    assert plant.EvalBodyPoseInWorld(plant_context, body).translation()[2] == PARKING_Z
    assert not plant.EvalBodySpatialVelocityInWorld(plant_context, body).get_coeffs().any()


def test_object_folder_with_meshes_and_bad_folders(tmp_path):
    cube = tmp_path / "cube.obj"
    corners = [(x, y, z) for x in (-0.02, 0.02) for y in (-0.02, 0.02) for z in (-0.02, 0.02)]
    faces = ["1 2 4 3", "5 7 8 6", "1 5 6 2", "3 4 8 7", "1 3 7 5", "2 6 8 4"]
    cube.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in corners) + "".join(f"f {f}\n" for f in faces))
    (tmp_path / "notes.txt").write_text("not a model")
    models = load_object_set(str(tmp_path))
    assert [m.name for m in models] == ["cube"]
    station = Station(scenario=load_scenario("single"), robot=ROBOTS["ur5"], objects=models)
    assert len(station.object_bodies) == 1
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="holds no usable"):
        load_object_set(str(empty))
    with pytest.raises(ValueError, match="unknown object set"):
        load_object_set("no_such_set")


@pytest.mark.slow
def test_objects_that_roll_out_of_their_cluster_are_dropped_again(tmp_path):
    import dataclasses as dc

    from drake_grasp.cell.diagram import build_cell
    from drake_grasp.cell.executive import Mode
    from drake_grasp.policy.scorers import random_scorer
    from drake_grasp.simulation.placement import strays

    novel = load_object_set("novel")
    assert load_scenario("standard").settle_within == 0.4
    plain = dc.replace(load_scenario("standard"), settle_within=0.0)
    yaml = tmp_path / "settled.yaml"
    yaml.write_text("name: settled\nclusters:\n  - centre: [0.5, 0.0]\n    radius: 0.12\n    count: 10\n"
                    "settle_within: 0.3\n")
    settled = load_scenario(str(yaml))
    assert settled.settle_within == 0.3
    cells = {}  # (a scenario that keeps objects where they lie leaves the settle to the executive's wait)
    for name, scenario in (("plain", plain), ("settled", settled)):
        cell = build_cell(robot=ROBOTS["panda"], scenario=scenario, scorer=random_scorer, object_models=novel,
                          seed=0)
        if name == "settled":  # the first attempt waits for the scene: it looks once the last settle is over
            state = cell.executive.get_task_state(cell.context)
            assert state.mode is Mode.WAIT and state.attempt is None
            assert state.wait_until == cell.context.get_time() >= 2 * settled.settle_time
        cell.advance_to_next_look()
        state = cell.task_state()  # the executive looks now (or at its next update): nothing moved yet
        assert state.mode in (Mode.WAIT, Mode.OBSERVE) and state.attempt is None
        assert cell.context.get_time() == state.wait_until
        cells[name] = cell
    plant, bodies = cells["plain"].station.plant(), cells["plain"].station.object_bodies
    context = cells["plain"].station.plant_context(cells["plain"].context)
    # Seed 0 drops a bottle of the novel set that rolls out of the camera's workspace, behind the arm.
    assert len(strays(plant, context, bodies, dc.replace(plain, settle_within=0.3))) >= 1
    cell = cells["settled"]
    context = cell.station.plant_context(cell.context)
    assert len(strays(cell.station.plant(), context, cell.station.object_bodies, settled)) == 0
    assert cell.context.get_time() >= 2 * settled.settle_time  # it settled again after the drop


D435 = ("sensing:\n  camera:\n    width: 848\n    height: 480\n    fx: 421.0\n    fy: 420.0\n    cx: 430.5\n"
        "    cy: 236.0\n    xyz: [0.5, 0.1, 0.9]\n    rpy_deg: [-160.0, 0.0, 10.0]\n")


def test_a_scenario_camera_is_detects_camera(tmp_path):
    """A scenario's camera is the camera YAML `detect` reads: rendered with its own intrinsics and pose, its
    image back-projects through `points_in_base` to the simulator's own cloud (of the bare table, z = 0)."""
    yaml = tmp_path / "d435.yaml"
    yaml.write_text("name: d435\nclusters: []\n" + D435)
    scenario = load_scenario(str(yaml))
    camera = scenario.sensing.camera
    station = Station(scenario=scenario, robot=None, objects=[])
    context = station.CreateDefaultContext()
    depth = station.GetOutputPort("depth_image").Eval(context).data.squeeze(-1)
    assert depth.shape == (480, 848)
    points_B = points_in_base(depth, camera)
    cloud = station.GetOutputPort("point_cloud_W").Eval(context).xyzs().T
    cloud = cloud[np.isfinite(cloud).all(axis=1)]
    assert len(points_B) == len(cloud) > 100_000
    assert np.mean(np.abs(points_B[:, 2]) < 1e-3) > 0.95  # the table top (and the floating hand above it)
    np.testing.assert_allclose(np.sort(points_B, axis=0), np.sort(cloud, axis=0), atol=1e-4)


def test_a_scenario_with_an_impossible_workspace_or_sampling_is_named(tmp_path):
    for text, problem in (("sensing:\n  workspace:\n    upper: [1.0, 0.5, -0.1]\n", "lower < upper"),
                          ("sampling: {gamma_deg: [30.0, 10.0]}\n", "gamma_deg needs"),
                          ("sensing:\n  camera: {fx: -1.0}\n", "focal lengths must be positive")):
        yaml = tmp_path / "bad.yaml"
        yaml.write_text("name: bad\n" + text)
        with pytest.raises(ValueError, match=problem):
            load_scenario(str(yaml))
