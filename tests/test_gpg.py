"""GPD's candidate generator (GPG) for our hand: frames, hand search, and grasps that hold in physics."""

import numpy as np
import pytest
from scenes import block_points, write_flat_bar

from drake_grasp.learning.voxels import voxelize
from drake_grasp.policy.baselines.gpg import GpgConfig, generate_candidates, local_frame
from drake_grasp.policy.clearance import approach_blocked
from drake_grasp.policy.sampling import sample_candidates
from drake_grasp.robot.hand import default_hand
from drake_grasp.robot.task import SAMPLERS, TrialOutcome
from drake_grasp.simulation.grasp_trial import GraspTrialScene
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import load_scenario

HAND = default_hand()


def test_the_local_frame_of_a_cylinder_has_its_axis_as_curvature_axis():
    angle = np.linspace(0, np.pi / 3, 50)  # a patch of a cylinder along world y
    normals = np.stack([np.sin(angle), np.zeros_like(angle), np.cos(angle)], axis=1)
    frame = local_frame(normals, own_normal=np.array([0.3, 0.0, 0.95]))
    normal, binormal, axis = frame.T
    assert abs(axis[1]) > 0.999  # the cylinder's axis
    assert normal @ [0.3, 0.0, 0.95] > 0.9  # faces like the point's own normal
    np.testing.assert_allclose(np.cross(normal, binormal), axis, atol=1e-9)  # right-handed
    assert local_frame(normals[:2], own_normal=normal) is None


def test_candidates_clear_the_cloud_hold_points_between_the_fingers_and_stay_above_the_table():
    cloud = block_points()
    config = GpgConfig(num_samples=40)
    X_WG = generate_candidates(cloud, np.random.default_rng(0), config)
    assert len(X_WG) > 40
    R = X_WG[:, :3, :3]
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.tile(np.eye(3), (len(X_WG), 1, 1)), atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-9)
    assert (X_WG[:, 2, 2] <= 1e-9).all()  # every approach from above the horizontal
    assert not approach_blocked(voxelize(cloud, X_WG)).any()  # the swept-volume check agrees
    tip = 0.02  # fingertips past the grasp origin along +z_G
    for X in X_WG:
        p_G = (cloud - X[:3, 3]) @ X[:3, :3]
        between = (np.abs(p_G[:, 0]) <= 0.01) & (np.abs(p_G[:, 1]) < HAND.max_half_opening) & (
            p_G[:, 2] <= tip) & (p_G[:, 2] >= tip - HAND.finger_length)
        assert between.sum() >= config.min_points
        # The palm's far corners stay above the table top.
        for sx in (-1, 1):
            for sy in (-1, 1):
                corner_G = [sx * HAND.palm_size[0] / 2, sy * HAND.palm_size[1] / 2,
                            tip - HAND.finger_length - HAND.palm_depth]
                assert (X[:3, :3] @ corner_G + X[:3, 3])[2] >= 0.0
    steep = GpgConfig(num_samples=40, max_gamma_deg=30.0)
    X_steep = generate_candidates(cloud, np.random.default_rng(0), steep)
    assert 0 < len(X_steep) < len(X_WG) and (-X_steep[:, 2, 2] >= np.cos(np.radians(30.0)) - 1e-9).all()
    top = generate_candidates(cloud, np.random.default_rng(0), GpgConfig(num_samples=40, max_gamma_deg=0.0))
    assert len(top) > 0 and np.allclose(top[:, :3, 2], [0.0, 0.0, -1.0])  # straight down
    assert not approach_blocked(voxelize(cloud, top)).any()
    with pytest.raises(ValueError, match="empty"):
        generate_candidates(np.zeros((0, 3)), np.random.default_rng(0))
    with pytest.raises(ValueError, match="min_depth"):
        GpgConfig(min_depth=0.05, max_depth=0.01)


def test_gpg_grasps_on_a_settled_cube_lift_it_in_physics():
    cube = next(m for m in load_object_set("primitives") if m.name == "cube")
    scene = GraspTrialScene(load_scenario("single"), cube)
    scene.settle(np.random.default_rng(0))
    cloud = scene.observe().points
    X_WG, made_by = sample_candidates(cloud, 6, (0.0, 30.0), "gpg", np.random.default_rng(1))
    assert len(X_WG) == 6 and (made_by == SAMPLERS.index("gpg")).all()
    outcomes = [scene.run(X).outcome for X in X_WG]
    # The cube is always between the fingers; a tilted hand may meet a side the camera did not see.
    assert outcomes.count(TrialOutcome.SUCCESS) >= 2, outcomes
    assert set(outcomes) <= {TrialOutcome.SUCCESS, TrialOutcome.COLLIDES_ON_APPROACH}, outcomes
    mixed, made_by = sample_candidates(cloud, 10, (0.0, 30.0), "mixed", np.random.default_rng(1))
    assert len(mixed) == 10 and not approach_blocked(voxelize(cloud, mixed[:5])).any()
    # Each candidate says which sampler made it: GPG's first (its five are the gpg run's first five).
    np.testing.assert_array_equal(made_by, [SAMPLERS.index("gpg")] * 5 + [SAMPLERS.index("uniform")] * 5)
    np.testing.assert_allclose(mixed[:5], sample_candidates(cloud, 5, (0.0, 30.0), "gpg",
                                                           np.random.default_rng(1))[0])
    with pytest.raises(ValueError, match="unknown sampler 'best'"):
        sample_candidates(cloud, 4, (0.0, 90.0), "best", np.random.default_rng(1))


def test_evaluate_splits_the_metrics_by_the_sampler_that_made_each_candidate(tmp_path):
    """A mixed job's trials (the household packed validation: half GPG, half uniform) scored per sampler:
    GPG's placements, made to fit the hand around the cloud, lift far more often."""
    import json

    from drake_grasp.apps.evaluate import main as evaluate
    from drake_grasp.robot.paths import REPO_ROOT

    out = tmp_path / "eval.json"
    assert evaluate(["cnn", "--data", str(REPO_ROOT / "data/grasps/household_validation_packed"),
                     "--per-sampler", "--threads", "1", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    per_sampler = result["per_sampler"]
    assert set(per_sampler) == {"gpg", "uniform"}
    assert sum(m["n"] for m in per_sampler.values()) == result["all"]["n"] == 1200
    assert per_sampler["gpg"]["positive_rate"] > 5 * per_sampler["uniform"]["positive_rate"]


def test_a_hand_stopped_at_the_table_grasps_a_flat_bar_that_a_dropped_hand_misses(tmp_path):
    write_flat_bar(tmp_path)  # 1.8 cm tall
    scene = GraspTrialScene(load_scenario("single"), load_object_set(str(tmp_path))[0])
    scene.settle(np.random.default_rng(0))
    cloud = scene.observe().points
    dropped = generate_candidates(cloud, np.random.default_rng(1), GpgConfig(max_gamma_deg=60.0))
    stopped = generate_candidates(cloud, np.random.default_rng(1), GpgConfig(max_gamma_deg=60.0,
                                                                             stop_at_table=True))
    # Pushed 1-3 cm past the bar's top, a hand dropped at the table finds almost no placement
    assert len(dropped) <= 5 < 50 <= len(stopped)
    tips = stopped[:, :3, 3] + default_hand().tip_beyond_grasp * stopped[:, :3, 2]  # the fingertips' centres
    assert (tips[:, 2] >= 0.002 - 1e-6).all()  # above the table by the margin at least
    down = stopped[:, 2, 2] < -0.99  # straight down: fingertips at least min_depth (1 cm) into the bar
    assert down.sum() >= 5 and (tips[down, 2] <= 0.018 - 0.01 + 1e-6).all()
    tried = stopped[np.random.default_rng(2).permutation(len(stopped))[:12]]
    outcomes = [scene.run(X).outcome for X in tried]
    # Those whose fingers miss the bar's hidden side lift it
    assert outcomes.count(TrialOutcome.SUCCESS) >= 3, outcomes
