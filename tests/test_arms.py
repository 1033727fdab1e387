"""Any arm from a YAML description: the third-party KUKA iiwa model, planned and simulated; bad arm files."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scenes import drawn_fraction, one_cube_yaml, simulate_one_cube

from drake_grasp.planning.planner import GraspPlanner, PlanFailure
from drake_grasp.policy.sampling import grasp_poses
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.paths import REPO_ROOT, SDF_DIR

IIWA = SDF_DIR / "third_party" / "kuka_iiwa" / "iiwa.yaml"
MODEL = IIWA.parent / "model.urdf"


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DRAKE_GRASP_CACHE", str(tmp_path / "cache"))


def test_the_iiwa_yaml_gives_a_seven_joint_arm_with_collidable_meshes():
    robot = get_robot(str(IIWA))
    assert robot.name == "iiwa" and robot.joint_names == tuple(f"lbr_iiwa_joint_{i}" for i in range(1, 8))
    assert robot.v_max[0] == pytest.approx(np.radians(85), abs=1e-3)  # the YAML's datasheet override
    prepared = robot.model_url.removeprefix("file://")
    text = Path(prepared).read_text()
    assert ".stl" not in text and "collision_filter_group" in text  # STL hulls became OBJ files
    assert 1.0 < robot.reach < 1.3 and robot.shoulder[2] == pytest.approx(0.1575)


@pytest.mark.slow
def test_the_planner_plans_the_iiwa_near_and_refuses_it_far():
    planner = GraspPlanner(get_robot(str(IIWA)), seed=0)
    down = np.array([[0.0, 0.0, -1.0]])
    near = grasp_poses(np.array([[0.55, 0.0, 0.05]]), down, np.array([0.0]))[0]
    far = grasp_poses(np.array([[1.6, 0.0, 0.05]]), down, np.array([0.0]))[0]
    assert planner.plan(near).success
    assert planner.plan(far).failure is PlanFailure.NO_IK_GRASP


def _shipped_iiwa(tmp_path, weights: Path) -> Path:
    """The shipped iiwa description, copied to tmp_path with its RP weights at `weights`."""
    arm = tmp_path / "iiwa.yaml"
    text = IIWA.read_text().replace("model: model.urdf", f"model: {MODEL}")
    arm.write_text(text.replace("../../../models/reachability_iiwa.pt", str(weights)))
    return arm


def _arm_file(tmp_path, **changes) -> str:
    fields = {"name": "iiwa", "model": str(MODEL), "base_link": "lbr_iiwa_link_0",
              "flange": "lbr_iiwa_link_7", "q_home": [0.0, 0.6, 0.0, -1.6, 0.0, 0.9, 0.0]} | changes
    path = tmp_path / "arm.yaml"
    path.write_text("".join(f"{k}: {json.dumps(v)}\n" for k, v in fields.items()))
    return str(path)


@pytest.mark.parametrize("changes, message", [
    ({"base_link": "nope"}, "has no link 'nope'"),
    ({"flange": "tool0"}, "has no frame 'tool0'"),
    ({"q_home": [0.0, 0.6, 0.0]}, "q_home has 3 values but the arm has 7 joints"),
    ({"q_home": []}, "q_home needs 7 values"),
    ({"q_home": [0.0, 3.0, 0.0, -1.6, 0.0, 0.9, 0.0]}, "outside the joint limits at joint(s) [2]"),
    ({"q_home": [0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0]}, "in collision"),
    ({"v_max": [1.0, 2.0]}, "v_max has 2 values but the arm has 7 joints"),
])
def test_a_bad_arm_file_is_one_clear_error(tmp_path, changes, message):
    with pytest.raises(ValueError) as error:
        get_robot(_arm_file(tmp_path, **changes))
    assert message in str(error.value) and "\n" not in str(error.value)


def test_an_arm_model_that_does_not_parse_is_named(tmp_path):
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot name='x'><link name='a'></robot>")
    with pytest.raises(ValueError, match="could not parse the arm model"):
        get_robot(_arm_file(tmp_path, model=str(broken)))


@pytest.mark.slow
def test_simulate_runs_the_iiwa_and_refuses_an_rp_policy_without_its_rp(tmp_path):
    scenario = tmp_path / "one_cube.yaml"
    scenario.write_text(one_cube_yaml(max_attempts=2))
    arm = _shipped_iiwa(tmp_path, tmp_path / "not_trained.pt")  # an RP not trained yet
    command = [sys.executable, "-m", "drake_grasp.simulate", "--robot", str(arm), "--scenario",
               str(scenario), "--runs", "1", "--report", str(tmp_path / "report.json")]
    run = subprocess.run([*command, "--policy", "cnn"], capture_output=True, text=True, timeout=600,
                         cwd=REPO_ROOT)
    assert run.returncode == 0, run.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["robot_name"] == "iiwa" and report["runs"][0]["plans_succeeded"] >= 1
    missing = subprocess.run([*command, "--policy", "cnn_rp"], capture_output=True, text=True, timeout=600,
                             cwd=REPO_ROOT)
    assert missing.returncode == 2 and "no reachability predictor for arm 'iiwa'" in missing.stderr


@pytest.mark.slow
def test_collect_train_map_and_simulate_the_iiwa_with_its_own_rp(tmp_path):
    """The README's pipeline for a new arm, small: labels, an RP trained on them, its map, a CNN x RP run."""
    from drake_grasp.apps.collect_reachability import main as collect
    from drake_grasp.apps.reachability_map import main as draw_map
    from drake_grasp.apps.train import main as train

    arm = _shipped_iiwa(tmp_path, tmp_path / "rp.pt")
    assert collect(["--robot", str(arm), "--samples", "120", "--shard-size", "60", "--seed", "0",
                    "--out", str(tmp_path / "labels"), "--workers", "2"]) == 0
    manifest = json.loads((tmp_path / "labels" / "manifest.json").read_text())
    assert manifest["robot"] == "iiwa" and manifest["robot_source"] == str(arm.resolve())
    assert train(["reachability", "--robot", str(arm), "--data", str(tmp_path / "labels"), "--epochs", "3",
                  "--out", str(tmp_path / "rp.pt")]) == 0
    assert draw_map(["--robot", str(arm), "--out", str(tmp_path / "map.png"), "--planner-grid", "3",
                     "--workers", "1"]) == 0
    assert drawn_fraction(tmp_path / "map.png") > 0.05
    report, _ = simulate_one_cube(arm, tmp_path)
    assert report["runs"][0]["attempt_log"][0]["p_r"] is not None
