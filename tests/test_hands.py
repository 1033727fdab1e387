"""The hand as a file: the Franka hand's YAML, a ROS-style URDF gripper with a mimic joint, clear errors for
bad files, and the hand's fingerprint on data and models."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix
from scenes import top_down_grasp

from drake_grasp.planning.planner import GraspPlanner
from drake_grasp.policy.config import ANY_HAND_CNN_WEIGHTS, SelectionConfig
from drake_grasp.policy.sampling import fingertip_corners_G
from drake_grasp.policy.scorers import make_scorer
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.hand import ANY_HAND, default_hand, get_hand, known_hands
from drake_grasp.robot.paths import REPO_ROOT
from drake_grasp.robot.plant import TCP_FRAME
from drake_grasp.robot.task import TrialOutcome
from drake_grasp.simulation.grasp_trial import GraspTrialScene
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import load_scenario

# A gripper as a ROS package would publish it: a URDF with its own link and joint names, the second finger
# a mimic joint, no Drake extensions; 100 mm stroke, 60 mm fingers.
GRIPPER_URDF = """<?xml version="1.0"?>
<robot name="test_gripper">
  <link name="gripper_base">
    <inertial><origin xyz="0 0 0.035"/><mass value="0.6"/>
      <inertia ixx="0.0015" ixy="0" ixz="0" iyy="0.0004" iyz="0" izz="0.0014"/></inertial>
    <visual><origin xyz="0 0 0.035"/><geometry><box size="0.05 0.16 0.07"/></geometry></visual>
    <collision><origin xyz="0 0 0.035"/><geometry><box size="0.05 0.16 0.07"/></geometry></collision>
  </link>
  <link name="finger_a">
    <inertial><origin xyz="0 0.005 0.03"/><mass value="0.02"/>
      <inertia ixx="6e-6" ixy="0" ixz="0" iyy="7e-6" iyz="0" izz="1e-6"/></inertial>
    <collision><origin xyz="0 0.005 0.03"/><geometry><box size="0.022 0.01 0.06"/></geometry></collision>
  </link>
  <link name="finger_b">
    <inertial><origin xyz="0 -0.005 0.03"/><mass value="0.02"/>
      <inertia ixx="6e-6" ixy="0" ixz="0" iyy="7e-6" iyz="0" izz="1e-6"/></inertial>
    <collision><origin xyz="0 -0.005 0.03"/><geometry><box size="0.022 0.01 0.06"/></geometry></collision>
  </link>
  <joint name="finger_a_joint" type="prismatic">
    <parent link="gripper_base"/><child link="finger_a"/><origin xyz="0 0 0.07"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="0.05" effort="60" velocity="0.2"/>
  </joint>
  <joint name="finger_b_joint" type="prismatic">
    <parent link="gripper_base"/><child link="finger_b"/><origin xyz="0 0 0.07"/><axis xyz="0 -1 0"/>
    <limit lower="0" upper="0.05" effort="60" velocity="0.2"/><mimic joint="finger_a_joint"/>
  </joint>
</robot>
"""

GRIPPER_FIELDS = {
    "name": "test_gripper", "model": "test_gripper.urdf", "base_link": "gripper_base",
    "fingers": ["finger_a", "finger_b"], "driven_joint": "finger_a_joint", "coupled_joints": [],
    "open_position": 0.05, "closed_position": 0.0, "closed_on_nothing": 0.002, "grip_force": 60.0,
    "stroke": 0.1, "tcp_depth": 0.12, "palm_depth": 0.07, "palm_size": [0.05, 0.16], "finger_length": 0.06,
    "finger_size": [0.022, 0.01], "grasp_depth": 0.01,
}


def gripper_file(folder: Path, **changes) -> Path:
    """The test gripper's URDF and its hand YAML (with `changes` to its fields) in `folder`."""
    (folder / "test_gripper.urdf").write_text(GRIPPER_URDF)
    path = folder / "test_gripper.yaml"
    path.write_text(json.dumps(GRIPPER_FIELDS | changes))  # (JSON is YAML)
    return path


def test_the_franka_hand_is_a_file_every_built_in_arm_carries_and_the_shipped_data_record_their_hands():
    hand = default_hand()
    assert (hand.name, hand.stroke, hand.max_half_opening, hand.tcp_depth) == ("franka", 0.08, 0.04, 0.1034)
    assert hand.tcp_depth_to_tip == pytest.approx(0.01) and hand.opening(0.02) == pytest.approx(0.04)
    assert get_robot("panda").hand == get_robot("ur5").hand == hand
    manifests = [*(REPO_ROOT / "data/grasps").glob("*/manifest.json"),
                 *(REPO_ROOT / "data/reachability").glob("*/manifest.json")]
    recorded = [json.loads(p.read_text())["hand"] for p in manifests]
    recorded += [json.loads(p.read_text())["hand"] for p in (REPO_ROOT / "models").glob("*.json")]
    generated = [get_hand(str(path)) for path in (REPO_ROOT / "data/hands").glob("*/*.yaml")]
    known = {(hand.name, hand.fingerprint) for hand in [*map(get_hand, known_hands()), *generated]}
    known.add((ANY_HAND["name"], ANY_HAND["fingerprint"]))  # (a CNN with a hand channel)
    assert len(recorded) > 40 and {(r["name"], r["fingerprint"]) for r in recorded} <= known
    assert sum(r["fingerprint"] == hand.fingerprint for r in recorded) > 40


def test_a_ros_urdf_gripper_with_a_mimic_joint_loads_and_lifts_a_cube_in_physics(tmp_path):
    hand = get_hand(str(gripper_file(tmp_path)))
    assert hand.mimics == (("finger_b_joint", 1.0, 0.0),)
    assert hand.fingerprint != default_hand().fingerprint
    assert hand.joint_positions(0.05) == {"finger_a_joint": 0.05, "finger_b_joint": 0.05}
    corners = fingertip_corners_G(hand)  # the policy's box model is this hand's: 100 mm stroke, tips 2 cm in
    assert np.abs(corners[:, 1]).max() == pytest.approx(0.06) and corners[0, 2] == pytest.approx(0.02)

    cube = next(m for m in load_object_set("primitives") if m.name == "cube")
    scene = GraspTrialScene(load_scenario("single"), cube, hand=hand)
    assert scene.station.models.hand_spec == hand
    scene.settle(np.random.default_rng(0))
    on_top = top_down_grasp(scene, close_along=0)
    assert scene.run(on_top).outcome is TrialOutcome.SUCCESS
    # Its file names no Drake contact: its three boxes are made rigid hydroelastic (and fingerprinted), so
    # both fingers hold the compliant cube in hydroelastic contact, not in point contact that sinks in.
    assert hand.contact_filled == 3 and default_hand().contact_filled == 0
    contacts = scene.plant.get_contact_results_output_port().Eval(scene.plant_context)
    assert (contacts.num_hydroelastic_contacts(), contacts.num_point_pair_contacts()) == (2, 0)
    far_above = on_top @ RigidTransform([0.0, 0.0, -0.08])
    assert scene.run(far_above).outcome is TrialOutcome.CLOSED_ON_NOTHING  # both fingers closed: they met


@pytest.mark.parametrize("changes, message", [
    ({"model": "missing.urdf"}, "model not found"),
    ({"base_link": "palm"}, "the model has no link 'palm'"),
    ({"fingers": ["finger_a"]}, "'fingers' names the two finger links"),
    ({"driven_joint": "finger_c_joint"}, "the model has no joint 'finger_c_joint'"),
    ({"open_position": 0.08}, "open_position 0.08 is outside the driven joint's limits [0, 0.05]"),
    ({"closed_on_nothing": 0.2}, "closed_on_nothing must lie between"),
    ({"stroke": -0.1}, "stroke must be positive"),
    ({"palm_size": [0.05]}, "'palm_size' needs two sizes"),
])
def test_a_bad_hand_file_is_one_clear_error(tmp_path, changes, message):
    with pytest.raises(ValueError) as error:
        get_hand(str(gripper_file(tmp_path, **changes)))
    assert message in str(error.value) and "\n" not in str(error.value)
    with pytest.raises(ValueError, match="unknown hand 'robotiq'"):
        get_hand("robotiq")


def test_models_and_trials_of_another_hand_are_refused(tmp_path):
    other = get_robot("panda", str(gripper_file(tmp_path)))
    with pytest.raises(ValueError, match=r"grasp_cnn_household.pt .*: made with the .franka. hand"):
        make_scorer("cnn", other, SelectionConfig(cnn_weights="models/grasp_cnn_household.pt"))
    with pytest.raises(ValueError, match=r"grasp_hold_robotiq_2f_85.pt .*: made with the 'robotiq_2f_85'"):
        make_scorer("cnn", other, SelectionConfig(cnn_weights=ANY_HAND_CNN_WEIGHTS,
                                                  hold_weights="models/grasp_hold_robotiq_2f_85.pt"))
    # A hand without models of its own gets the CNN for any hand and no hold predictor.
    assert SelectionConfig().for_hand(other.hand) == SelectionConfig(cnn_weights=ANY_HAND_CNN_WEIGHTS,
                                                                     hold_weights=None)
    assert make_scorer("cnn", other) is not None
    with pytest.raises(ValueError, match="no reachability predictor for arm 'panda' with the 'test_gripper'"):
        make_scorer("cnn_rp", other)
    assert make_scorer("rand", other) is not None  # no models: any hand
    assert make_scorer("cnn", other, SelectionConfig(any_hand=True)) is not None  # a transfer, on purpose
    arm = tmp_path / "arm.yaml"
    arm.write_text((REPO_ROOT / "sdf/third_party/kuka_iiwa/iiwa.yaml").read_text().replace(
        "model: ", f"hand: {tmp_path / 'test_gripper.yaml'}\nmodel: ", 1))
    for item in (REPO_ROOT / "sdf/third_party/kuka_iiwa").iterdir():  # (its model, relative to the arm file)
        (tmp_path / item.name).symlink_to(item)
    assert get_robot(str(arm)).hand.name == "test_gripper"

    train = [sys.executable, "-m", "drake_grasp", "train", "stability", "--data",
             str(REPO_ROOT / "data/grasps/novel"), "--hand", str(tmp_path / "test_gripper.yaml"),
             "--epochs", "1", "--out", str(tmp_path / "cnn.pt")]
    refused = subprocess.run(train, capture_output=True, text=True, timeout=300, cwd=REPO_ROOT)
    assert refused.returncode == 2 and "the training trials: made with the 'franka' hand" in refused.stderr


def test_the_shipped_robotiq_2f_85_lifts_a_cube_and_rides_on_the_shipped_ur5e():
    hand = get_hand("robotiq_2f_85")
    assert len(hand.mimics) == 5 and hand.closed_position > hand.open_position  # a linkage, closing upward
    assert hand.jaws_met(0.79) and not hand.jaws_met(0.5)
    cube = next(m for m in load_object_set("primitives") if m.name == "cube")
    scene = GraspTrialScene(load_scenario("single"), cube, hand=hand)
    scene.settle(np.random.default_rng(0))
    on_top = top_down_grasp(scene, close_along=0)
    result = scene.run(on_top)
    assert result.outcome is TrialOutcome.SUCCESS and 0.3 < scene._finger() < 0.6  # the pads 5 cm apart

    ur5e = get_robot(str(REPO_ROOT / "sdf/third_party/airo_models/ur5e.yaml"))
    assert ur5e.hand == hand and len(ur5e.joint_names) == 6
    planner = GraspPlanner(ur5e, seed=0)
    X_WG = RigidTransform(RotationMatrix.MakeXRotation(np.pi), [0.5, 0.0, 0.1])  # straight down
    result = planner.plan(X_WG)
    assert result.success, result.failure
    world = planner.world
    world.plant.SetPositions(world.plant_context, world.full(result.plan.q_grasp))
    X_WT = world.plant.GetFrameByName(TCP_FRAME, world.hand).CalcPoseInWorld(world.plant_context)
    np.testing.assert_allclose(X_WT.translation(), (X_WG @ hand.X_GT).translation(), atol=2e-3)


def test_a_hand_that_names_its_models_gets_them_where_the_selection_names_the_defaults(tmp_path):
    hand = get_hand(str(gripper_file(tmp_path, cnn_weights="cnn.pt", hold_weights="none")))
    assert hand.cnn_weights == str(tmp_path / "cnn.pt") and hand.hold_weights == "none"
    assert hand.fingerprint == get_hand(str(gripper_file(tmp_path))).fingerprint  # (models are not the hand)
    default = SelectionConfig().for_hand(hand)
    assert (default.cnn_weights, default.hold_weights) == (str(tmp_path / "cnn.pt"), None)
    chosen = SelectionConfig(cnn_weights="mine.pt", hold_weights="hold.pt").for_hand(hand)
    assert (chosen.cnn_weights, chosen.hold_weights) == ("mine.pt", "hold.pt")
    assert SelectionConfig().for_hand(default_hand()) == SelectionConfig()


def test_make_hands_writes_hand_files_that_load_and_the_franka_hand_is_made_the_same_way(tmp_path):
    from pydrake.common.yaml import yaml_load_typed

    from drake_grasp.robot.hand import HANDS_DIR, HandConfig
    from drake_grasp.robot.parallel_jaw import STROKES, parallel_jaw_sdf

    out = subprocess.run([sys.executable, "-m", "drake_grasp", "make_hands", "--count", "3", "--seed", "4",
                          "--out", str(tmp_path)], capture_output=True, text=True, cwd=REPO_ROOT)
    assert out.returncode == 0, out.stderr
    hands = [get_hand(str(p)) for p in sorted(tmp_path.glob("*.yaml"))]
    assert len(hands) == 3 and len({h.fingerprint for h in hands}) == 3
    for hand in hands:
        assert STROKES[0] <= hand.stroke <= STROKES[1]
        assert hand.open_position == pytest.approx(hand.stroke / 2)
        assert f"{hand.name}: stroke {hand.stroke * 1000:.0f} mm" in out.stdout
    franka = yaml_load_typed(schema=HandConfig, filename=str(HANDS_DIR / "franka.yaml"))
    assert parallel_jaw_sdf(franka) == (REPO_ROOT / "sdf" / "hand.sdf").read_text()
