"""Files as users bring them: Gazebo SDF and ROS URDF objects, ROS-style URDF arms (a `world` link,
transmissions, `package://` STL meshes without a package.xml), camera files; a simulation that diverges."""

from pathlib import Path

import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.systems.framework import DiagramBuilder
from ros_files import (
    write_arm_yaml,
    write_gazebo_model_folders,
    write_gazebo_sdf_set,
    write_ros_arm,
    write_ros_urdf_set,
)
from scenes import one_cube_yaml, simulate_one_cube, top_down_grasp

from drake_grasp.planning.planner import GraspPlanner
from drake_grasp.policy.sampling import grasp_poses
from drake_grasp.robot import log
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.config import default_plant_config
from drake_grasp.robot.contact_model import OBJECT_CONTACT
from drake_grasp.robot.paths import make_parser
from drake_grasp.robot.plant import add_scene
from drake_grasp.robot.task import TrialOutcome
from drake_grasp.simulation.grasp_trial import GraspTrialScene
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import load_scenario


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DRAKE_GRASP_CACHE", str(tmp_path / "cache"))


def _object_plant(models):
    """A plant of the objects (and the loose hand and table), not finalized, with its scene graph."""
    plant, scene_graph = AddMultibodyPlant(default_plant_config(), DiagramBuilder())
    scene = add_scene(plant, make_parser(plant), robot=None, objects=models)
    return plant, scene_graph, scene


def blow_up(plant, context) -> None:
    """Velocities that are not finite, as a step that blew up leaves them (SetVelocities refuses NaN)."""
    state = context.get_mutable_discrete_state_vector()
    for i in range(plant.num_positions(), plant.num_positions() + plant.num_velocities()):
        state.SetAtIndex(i, np.nan)


def _properties(plant, scene_graph, body):
    inspector = scene_graph.model_inspector()
    return [inspector.GetProximityProperties(g) for g in plant.GetCollisionGeometriesForBody(body)]


# -- objects ---------------------------------------------------------------------------------------
def test_plain_sdf_and_urdf_objects_get_the_contact_model_and_keep_their_friction(tmp_path):
    models = load_object_set(str(write_gazebo_sdf_set(tmp_path / "sdf")))
    models += load_object_set(str(write_ros_urdf_set(tmp_path / "urdf")))
    assert sorted(m.name for m in models) == ["ball", "block", "box", "can", "pebble", "prism", "tin"]
    plant, scene_graph, scene = _object_plant(models)
    assert sorted(scene.filled_contact) == sorted(m.name for m in models)
    for name, body in zip(scene.object_names, scene.object_bodies, strict=True):
        for props in _properties(plant, scene_graph, body):
            modulus = props.GetProperty("hydroelastic", "hydroelastic_modulus")
            assert modulus == OBJECT_CONTACT.hydroelastic_modulus
            mu = props.GetProperty("material", "coulomb_friction").static_friction()
            gazebo = name in ("box", "can", "ball", "prism")
            assert mu == pytest.approx(0.9 if gazebo else OBJECT_CONTACT.friction)  # <ode><mu> is kept


def test_objects_that_bring_their_own_properties_keep_them():
    models = load_object_set("primitives")
    plant, scene_graph, scene = _object_plant(models)
    assert scene.filled_contact == []
    for body in scene.object_bodies:
        for props in _properties(plant, scene_graph, body):
            assert props.GetProperty("hydroelastic", "resolution_hint") == 0.01


@pytest.mark.parametrize("folder, name", [("sdf", "box"), ("urdf", "block"), ("shipped", "cube")])
def test_a_plain_cube_is_grasped_as_the_projects_own(tmp_path, folder, name):
    if folder == "shipped":
        models = load_object_set("primitives")
    else:
        write = write_gazebo_sdf_set if folder == "sdf" else write_ros_urdf_set
        models = load_object_set(str(write(tmp_path / folder)))
    scene = GraspTrialScene(load_scenario("single"), next(m for m in models if m.name == name))
    scene.settle(np.random.default_rng(0))
    result = scene.run(top_down_grasp(scene, close_along=0))
    assert result.outcome is TrialOutcome.SUCCESS and result.rise > 0.15


def test_gazebo_model_folders_with_model_uris_and_stl_meshes_are_objects_that_lift(tmp_path):
    models = load_object_set(str(write_gazebo_model_folders(tmp_path / "models")))
    assert [m.name for m in models] == ["block_description", "soup_can"]  # each named after its folder
    for model in models:
        text = Path(model.url.removeprefix("file://")).read_text()
        assert ".stl" not in text and "://" not in text.replace("http://", "")  # absolute OBJ meshes
    plant, _, scene = _object_plant(models)
    assert sorted(scene.filled_contact) == ["block_description", "soup_can"]
    scene = GraspTrialScene(load_scenario("single"), models[0])  # the block
    scene.settle(np.random.default_rng(0))
    assert scene.run(top_down_grasp(scene, close_along=0)).outcome is TrialOutcome.SUCCESS


def test_a_static_object_is_a_one_line_error(tmp_path, capsys):
    from drake_grasp.apps.simulate import main

    folder = write_gazebo_sdf_set(tmp_path / "sdf")
    box = folder / "box.sdf"
    box.write_text(box.read_text().replace('<model name="box">', '<model name="box"><static>true</static>'))
    assert main(["--objects", str(folder), "--runs", "1"]) == 2
    err = capsys.readouterr().err
    assert "object 'box' is fixed in place by its file" in err and err.count("\n") == 1


def test_a_diverging_trial_is_a_failure_named_so_and_the_next_trial_runs(tmp_path):
    models = load_object_set(str(write_gazebo_sdf_set(tmp_path / "sdf")))
    scene = GraspTrialScene(load_scenario("single"), next(m for m in models if m.name == "box"))
    scene.settle(np.random.default_rng(0))
    X_WG = top_down_grasp(scene, close_along=0)
    settled = scene.plant.GetMyMutableContextFromRoot(scene._settled)
    velocities = scene.plant.GetVelocities(settled)
    blow_up(scene.plant, settled)
    result = scene.run(X_WG)
    assert result.outcome is TrialOutcome.DIVERGED and not result.success
    scene.plant.SetVelocities(settled, velocities)
    assert scene.run(X_WG).success


def test_a_run_that_diverges_at_half_the_step_too_ends_with_its_reason_and_keeps_the_attempt(
        tmp_path, monkeypatch):
    from drake_grasp.cell import diagram as cell_module
    from drake_grasp.cell import episode
    from drake_grasp.cell.executive import Mode
    from drake_grasp.evaluation.runs import format_run, summarize
    from drake_grasp.policy.scorers import make_scorer

    real_update = cell_module.GraspCell.update_sleep

    def blow_up_while_closing(self):
        real_update(self)
        if self.task_state().mode is Mode.CLOSE:
            blow_up(self.station.plant(), self.station.plant_context(self.context))

    monkeypatch.setattr(cell_module.GraspCell, "update_sleep", blow_up_while_closing)
    scenario_file = tmp_path / "one_cube.yaml"
    scenario_file.write_text(one_cube_yaml(max_attempts=3))
    robot = get_robot("panda")
    result = episode.run_episode(robot=robot, scenario=load_scenario(str(scenario_file)),
                                 scorer=make_scorer("cnn", robot),
                                 object_models=load_object_set("primitives"), seed=0)
    assert result.end_reason == "simulation diverged" and "NaN" in result.divergence
    assert result.attempts == 1 and result.failures == {"simulation diverged": 1}
    assert result.diverged_try["attempts"] == 1 and "NaN" in result.diverged_try["divergence"]
    run = result.to_dict()
    summary = summarize([run])
    assert summary["ended_diverged"] == summary["ran_at_half_step"] == 1
    assert "simulation diverged: " in format_run(run)
    assert format_run(run).endswith("[ran at 1 ms after diverging at 2 ms]")  # (the scene steps 2 ms)


# -- arms ------------------------------------------------------------------------------------------
def test_a_ros_urdf_arm_with_a_world_link_loads_as_written(tmp_path, capsys):
    urdf = write_ros_arm(tmp_path)
    robot = get_robot(str(write_arm_yaml(tmp_path, urdf)))  # no base_link, no package.xml
    assert robot.base_link == "base_link" and len(robot.joint_names) == 6
    assert robot.q_upper[-1] == pytest.approx(2 * np.pi)  # the continuous wrist
    assert robot.effort_max == (150.0,) * 6  # each joint's URDF effort limit
    prepared = Path(robot.model_url.removeprefix("file://"))
    text = prepared.read_text()
    assert "<transmission" not in text and 'name="world"' not in text and ".stl" not in text
    assert text.count("\n") == urdf.read_text().count("\n")  # line for line with the user's file
    notes = capsys.readouterr().err
    assert "finger_joint, finger_mimic_joint" in notes and "wrist_3_joint limited" in notes
    planner = GraspPlanner(robot, seed=0)
    down = np.array([[0.0, 0.0, -1.0]])
    assert planner.plan(grasp_poses(np.array([[0.5, 0.0, 0.05]]), down, np.array([0.0]))[0]).success


def test_drakes_warnings_about_an_arm_are_one_line_once_and_mesh_conversion_is_silent(tmp_path, capfd,
                                                                                     monkeypatch):
    monkeypatch.setattr(log, "_summarised", set())
    monkeypatch.setattr(log, "_reported", set())
    urdf = write_ros_arm(tmp_path)
    # One link's inertia breaks the triangle inequality, as the xArm6's published URDF does.
    urdf.write_text(urdf.read_text().replace("ixx='0.004'", "ixx='0.1'", 1))
    robot = get_robot(str(write_arm_yaml(tmp_path, urdf)))
    plant, _ = AddMultibodyPlant(default_plant_config(), DiagramBuilder())
    add_scene(plant, make_parser(plant), robot=robot)  # parses the arm again, with the hand and table
    err = capfd.readouterr().err
    notes = [line for line in err.splitlines() if "parser warned" in line]
    assert len(notes) == 1 and "warned 1 time(s) about arm 'ur_like'" in notes[0]
    assert "ur5.urdf:" in notes[0] and "inertia matrix" in notes[0]  # the user's file and line
    assert "Open3D" not in err  # (the STL meshes became OBJ files)


def test_an_error_in_a_ros_urdf_names_the_users_file_and_line(tmp_path):
    urdf = write_ros_arm(tmp_path)
    lines = urdf.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if 'name="elbow_joint"' in line)
    lines[k] = lines[k].replace('type="revolute"', 'type="hinge"')
    urdf.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError) as error:
        get_robot(str(write_arm_yaml(tmp_path, urdf)))
    message = str(error.value)
    assert f"{urdf}:{k + 1}:" in message and "cache" not in message and "\n" not in message


def test_package_paths_resolve_through_package_path_or_fail_naming_the_arm_file(tmp_path):
    urdf = write_ros_arm(tmp_path / "src")
    elsewhere = tmp_path / "robots" / "ur5.urdf"  # not inside its package any more
    elsewhere.parent.mkdir()
    elsewhere.write_text(urdf.read_text())
    arm = write_arm_yaml(tmp_path, elsewhere)
    with pytest.raises(ValueError, match=f"set package_path .* in {arm}"):
        get_robot(str(arm))
    arm = write_arm_yaml(tmp_path, elsewhere, package_path=[str(tmp_path / "src")])
    assert get_robot(str(arm)).num_joints == 6


@pytest.mark.slow
def test_the_ros_arm_collects_trains_and_simulates(tmp_path):
    """collect_reachability, train reachability and a CNN x RP run of the ROS-style arm, small."""
    from drake_grasp.apps.collect_reachability import main as collect
    from drake_grasp.apps.train import main as train

    arm = write_arm_yaml(tmp_path, write_ros_arm(tmp_path), reachability_weights=str(tmp_path / "rp.pt"))
    assert collect(["--robot", str(arm), "--samples", "90", "--shard-size", "60", "--seed", "0",
                    "--out", str(tmp_path / "labels"), "--workers", "2"]) == 0
    assert train(["reachability", "--robot", str(arm), "--data", str(tmp_path / "labels"), "--epochs", "3",
                  "--out", str(tmp_path / "rp.pt")]) == 0
    report, stderr = simulate_one_cube(arm, tmp_path)
    assert report["robot_name"] == "ur_like" and report["runs"][0]["attempt_log"][0]["p_r"] is not None
    assert "Traceback" not in stderr


def test_collect_reachability_refuses_an_out_that_is_a_file(tmp_path, capsys):
    from drake_grasp.apps.collect_reachability import main as collect

    (tmp_path / "labels").write_text("not a folder")
    with pytest.raises(SystemExit) as exit_:
        collect(["--robot", "panda", "--samples", "10", "--out", str(tmp_path / "labels")])
    assert exit_.value.code == 2 and "is a file; give a folder" in capsys.readouterr().err
