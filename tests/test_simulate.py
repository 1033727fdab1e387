"""The simulate command end to end, and its answers to bad input."""

import dataclasses as dc
import json
import queue
import subprocess
import sys

import numpy as np
import pytest
from scenes import one_cube_yaml

from drake_grasp.apps.simulate import main

ONE_CUBE = one_cube_yaml(max_attempts=3)


@pytest.mark.slow
def test_a_cube_is_grasped_lifted_and_reported(tmp_path, cube_folder):
    scenario = tmp_path / "one_cube.yaml"
    scenario.write_text(ONE_CUBE)
    report = tmp_path / "report.json"
    run = subprocess.run(
        [sys.executable, "-m", "drake_grasp.simulate", "--scenario", str(scenario), "--objects",
         str(cube_folder), "--policy", "cnn_rp", "--runs", "1", "--seed", "0", "--report", str(report), "-v"],
        capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr
    data = json.loads(report.read_text())
    for key in ("grasp_success_rate", "completion_rate", "planning_success_rate"):
        assert data[key] == 1.0
    (episode,) = data["runs"]
    # A lone 50 mm cube, top-down candidates: the shipped CNN x RP picks one that lifts it first time.
    assert episode["attempts"] == episode["successes"] == 1 and episode["completion_rate"] == 1.0
    assert episode["end_reason"] == "all objects removed"
    assert episode["attempt_log"][-1]["rise"] >= 0.15
    assert 0.02 < episode["attempt_log"][-1]["grip"] < 0.026  # each jaw 25 mm from the centre, on the cube
    assert episode["sim_time_s"] > 0.6 and "aggregate over 1 runs" in run.stdout
    assert data["complete"] is True

    # The same command again resumes the report: its run is kept, nothing is simulated again.
    assert main(["--scenario", str(scenario), "--objects", str(cube_folder), "--policy", "cnn_rp",
                 "--runs", "1", "--seed", "0", "--report", str(report)]) == 0
    assert json.loads(report.read_text())["runs"] == data["runs"]
    # Another experiment in the same report file is refused with one line.
    assert main(["--scenario", str(scenario), "--objects", str(cube_folder), "--policy", "rand",
                 "--runs", "1", "--report", str(report)]) == 2
    # So is the same cell with other CNN weights (the report records the configuration whole).
    paper = tmp_path / "paper_models.yaml"
    paper.write_text("selection: {cnn_weights: models/grasp_cnn.pt}\n")
    assert main(["--config", str(paper), "--scenario", str(scenario), "--objects", str(cube_folder),
                 "--policy", "cnn_rp", "--runs", "1", "--report", str(report)]) == 2
    # And the same cell at another physics step.
    step = tmp_path / "step.yaml"
    step.write_text("time_step: 0.004\n")
    assert main(["--config", str(step), "--scenario", str(scenario), "--objects", str(cube_folder),
                 "--policy", "cnn_rp", "--runs", "1", "--report", str(report)]) == 2


@pytest.mark.parametrize("args, message", [
    (["--robot", "kuka"], "unknown robot 'kuka'"),
    (["--scenario", "nope"], "unknown scenario 'nope'"),
    (["--policy", "best"], "unknown policy 'best'"),
    (["--scenario", "single"], "scenario 'single' is for data collection"),
    (["--config", "papr"], "unknown configuration 'papr'"),
])
def test_bad_choices_exit_2_with_one_line(capsys, args, message):
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


@pytest.mark.slow
def test_empty_object_folder_exits_2_without_traceback(tmp_path):
    run = subprocess.run([sys.executable, "-m", "drake_grasp.simulate", "--objects", str(tmp_path)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert run.stderr.strip().startswith("error: object set folder")
    assert "holds no usable" in run.stderr and "Traceback" not in run.stderr


@pytest.mark.slow
def test_a_camera_that_sees_nothing_is_an_empty_cloud_error(tmp_path, cube_folder, capsys):
    scenario = tmp_path / "blind.yaml"
    looking_up = "sensing:\n  camera:\n    xyz: [0.5, 0.0, 1.3]\n    rpy_deg: [0.0, 0.0, 0.0]\n"
    scenario.write_text(ONE_CUBE + looking_up)
    assert main(["--scenario", str(scenario), "--objects", str(cube_folder), "--workers", "1"]) == 2
    assert "no finite point" in capsys.readouterr().err


@pytest.mark.slow
def test_an_object_beyond_reach_ends_the_run_with_nothing_reachable(tmp_path, cube_folder):
    """The shipped beyond_reach scenario: the near cube is grasped, the far one is not tried."""
    report = tmp_path / "report.json"
    run = subprocess.run(
        [sys.executable, "-m", "drake_grasp.simulate", "--scenario", "beyond_reach", "--objects",
         str(cube_folder), "--runs", "1", "--seed", "0", "--report", str(report)],
        capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    (episode,) = json.loads(report.read_text())["runs"]
    assert episode["end_reason"] == "nothing reachable" and episode["objects_grasped"] == 1
    far = [a for a in episode["attempt_log"] if a["grasp_point"][0] > 0.8]
    assert len(far) <= 1 and episode["attempts_saved"] > 0
    (left,) = episode["objects_left"]  # the far cube, where it lies
    assert left["object"] == "cube" and left["p_WO"][0] > 0.8


@pytest.mark.slow
def test_the_same_seed_gives_the_same_run(tmp_path, cube_folder):
    """Two runs of one seed: the same attempts, outcomes and simulated time (wall time aside)."""
    from drake_grasp.cell.episode import run_episode
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.robot.specs import ROBOTS
    from drake_grasp.simulation.objects import load_object_set
    from drake_grasp.simulation.scenario import load_scenario

    scenario_file = tmp_path / "one_cube.yaml"
    scenario_file.write_text(ONE_CUBE)
    scenario, robot = load_scenario(str(scenario_file)), ROBOTS["panda"]
    runs = [run_episode(robot=robot, scenario=scenario, scorer=make_scorer("rand", robot),
                        object_models=load_object_set(str(cube_folder)), seed=3).to_dict()
            for _ in range(2)]
    for run in runs:
        run.pop("wall_time_s")
        for entry in run["attempt_log"]:
            entry.pop("plan_seconds")
    assert runs[0] == runs[1] and runs[0]["attempts"] >= 1


@pytest.mark.slow
def test_a_run_that_diverges_starts_over_at_half_the_step():
    """The constrained scene of seed 29 blows up at its 4 ms step (a half cylinder under the stool is
    flung away while the scene settles; a pose turns NaN in the second attempt): the run starts over
    from its seed at 2 ms and runs to its end, attempt for attempt what a 2 ms configuration runs, and
    the live count takes back the first try's attempts."""
    from drake_grasp.apps.simulate import RunProgress
    from drake_grasp.evaluation.config import EvaluationConfig
    from drake_grasp.evaluation.runs import run_one

    config = EvaluationConfig(scenario="constrained", policy="rand", max_attempts=2)
    assert config.load_scenario().plant_config.time_step == 0.004
    feed = queue.Queue()
    runs = [run_one(config, 29, progress=feed), run_one(dc.replace(config, time_step=0.002), 29)]
    first = runs[0].pop("diverged_try")
    assert first["time_step"] == 0.004 and "non-finite" in first["divergence"] and first["attempts"] >= 1
    assert runs[1].pop("diverged_try") is None
    assert runs[0]["end_reason"] == "2 attempts (the scenario's limit)" and not runs[0]["divergence"]
    bar = RunProgress(1, done=0, enabled=False)
    bar.drain(feed)
    assert (bar.attempts, bar.successes) == (runs[0]["attempts"], runs[0]["successes"])
    for run in runs:
        run.pop("wall_time_s")
        for entry in run["attempt_log"]:
            entry.pop("plan_seconds")
    assert runs[0] == runs[1]


@pytest.mark.slow
@pytest.mark.parametrize("over_lcm", [False, True], ids=["station", "over_lcm"])
def test_the_gripper_judge_runs_the_cell_on_what_the_jaws_report(tmp_path, cube_folder, over_lcm):
    """The executive judged as on a robot, by the jaws' reported opening and the object cloud alone, in the
    one-cube cell: no ground truth reaches it, and its verdicts are the simulator's. Over LCM, the
    executive and perception reach the simulated robot only through the drivers' messages (a
    HardwareStation talking to the simulated station's drivers), as they would reach a robot."""
    from pydrake.math import RigidTransform, RotationMatrix

    from drake_grasp.cell.diagram import build_cell, run_attempt
    from drake_grasp.cell.judges import GripperJudge
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.robot.drivers import DriverChannels
    from drake_grasp.robot.specs import ROBOTS
    from drake_grasp.robot.task import CLOSED_ON_NOTHING_TEXT, LIFT_HEIGHT
    from drake_grasp.simulation.objects import load_object_set
    from drake_grasp.simulation.scenario import load_scenario

    yaml = tmp_path / "one_cube.yaml"
    yaml.write_text(ONE_CUBE)
    robot = ROBOTS["panda"]
    cell = build_cell(robot=robot, scenario=load_scenario(str(yaml)), scorer=make_scorer("cnn_rp", robot),
                      object_models=load_object_set(str(cube_folder)), seed=0,
                      judge=GripperJudge(robot.hand),
                      drivers=DriverChannels(lcm_url="memq://") if over_lcm else None)
    assert not cell.executive.HasInputPort("body_poses") and not cell.executive.HasInputPort("body_contacts")
    assert cell.diagram.HasSubsystemNamed("hardware_station") == over_lcm
    plant = cell.station.plant()

    def cube_z() -> float:
        context = cell.station.plant_context(cell.context)
        return plant.EvalBodyPoseInWorld(context, cell.station.object_bodies[0]).translation()[2]

    cell.advance(0.55)  # the cube at rest, just before the first look (settle_time 0.6)
    z0 = cube_z()
    # Over bare table, 15 cm beside the cube: the jaws meet, and the judge says so from them alone.
    beside = RigidTransform(RotationMatrix.MakeXRotation(np.pi), [0.5, 0.2, 0.03]).GetAsMatrix4()
    cell.executive.request_grasp(cell.context, beside)
    missed = run_attempt(cell).attempt
    assert missed.planned and missed.failure == CLOSED_ON_NOTHING_TEXT and missed.object_index is None
    assert missed.grip is None and abs(cube_z() - z0) < 1e-3
    # The policy's own choice: the jaws stay on the cube through the lift and the hold, and it is lifted.
    cell.executive.start_next_attempt(cell.context, 0.1)
    held = run_attempt(cell).attempt
    assert held.planned and held.success and held.failure is None
    assert cube_z() - z0 >= LIFT_HEIGHT


def test_a_finished_cell_is_freed(tmp_path, cube_folder):
    """pydrake keeps a diagram holding systems written in Python alive for good (0.1-0.2 GB an episode);
    a released cell's diagram, plant and scene graph go."""
    import gc
    import weakref

    from drake_grasp.cell.diagram import build_cell
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.robot.specs import ROBOTS
    from drake_grasp.simulation.lifetime import python_systems
    from drake_grasp.simulation.objects import load_object_set
    from drake_grasp.simulation.scenario import load_scenario

    yaml = tmp_path / "one_cube.yaml"
    yaml.write_text(ONE_CUBE)
    robot = ROBOTS["panda"]
    cell = build_cell(robot=robot, scenario=load_scenario(str(yaml)), scorer=make_scorer("rand", robot),
                      object_models=load_object_set(str(cube_folder)), seed=0)
    written_in_python = {type(s).__name__ for s in python_systems(cell.diagram)}
    assert {"Station", "GraspExecutive", "GraspSelector", "ObjectCloudSystem"} <= written_in_python
    alive = [weakref.ref(x) for x in (cell.diagram, cell.station.plant(), cell.station.scene_graph(),
                                      cell.simulator)]
    cell.release()
    del cell
    gc.collect()
    assert [ref() is None for ref in alive] == [True] * len(alive)
