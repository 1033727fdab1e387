"""Staged selection: the hand's swept volume in the voxel grid, and the CNN spent where it matters."""


import numpy as np
import pytest
from pydrake.geometry import Box, SceneGraph
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from scenes import block_points

from drake_grasp.learning.voxels import voxelize
from drake_grasp.perception.cloud import ObjectCloud
from drake_grasp.policy.clearance import approach_blocked, hand_sweep_mask
from drake_grasp.policy.sampling import sample_grasps
from drake_grasp.policy.scorers import SelectionConfig, Tier, make_scorer
from drake_grasp.policy.selector import rank_grasps
from drake_grasp.robot.hand import default_hand
from drake_grasp.robot.paths import SDF_DIR
from drake_grasp.robot.specs import ROBOTS


def test_the_franka_hand_files_boxes_are_its_models_collision_boxes():
    scene_graph, plant = SceneGraph(), MultibodyPlant(0.0)
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    Parser(plant).AddModels(str(SDF_DIR / "hand.sdf"))
    plant.Finalize()
    inspector = scene_graph.model_inspector()
    sizes = {}
    for body in ("hand", "left_finger", "right_finger"):
        (geometry,) = plant.GetCollisionGeometriesForBody(plant.GetBodyByName(body))
        shape = inspector.GetShape(geometry)
        assert isinstance(shape, Box)
        sizes[body] = (shape.width(), shape.depth(), shape.height())
    hand = default_hand()
    np.testing.assert_allclose(sizes["hand"], (*hand.palm_size, hand.palm_depth))
    np.testing.assert_allclose(sizes["left_finger"], (*hand.finger_size, hand.finger_length))
    np.testing.assert_allclose(sizes["right_finger"], (*hand.finger_size, hand.finger_length))


def grid_of(points_G: np.ndarray) -> np.ndarray:
    """The (1, 32, 32, 32) grid of grasp-frame points at a grasp at the world origin."""
    return voxelize(np.asarray(points_G, float), np.eye(4)[None])


def slab(x, y, z, step=0.002) -> np.ndarray:
    """Points filling the box x[0]..x[1], y[0]..y[1], z[0]..z[1] (grasp frame)."""
    axes = [np.arange(lo, hi + 1e-9, step) for lo, hi in (x, y, z)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def test_what_lies_in_the_open_hands_way_blocks_it_and_what_lies_between_the_fingers_does_not():
    block_between_fingers = slab((-0.02, 0.02), (-0.03, 0.03), (0.0, 0.04))  # 6 cm wide, under the stroke
    too_wide = slab((-0.02, 0.02), (-0.049, 0.049), (0.0, 0.04))  # 9.8 cm: the fingers land on it
    wall_behind = slab((-0.049, 0.049), (-0.049, 0.049), (-0.045, -0.04))  # where the palm passes
    beside = slab((0.03, 0.049), (-0.03, 0.03), (0.0, 0.04))  # off to the side of the fingers' columns
    grids = np.concatenate([grid_of(p) for p in (block_between_fingers, too_wide, wall_behind, beside)])
    assert approach_blocked(grids).tolist() == [False, True, True, False]
    mask = hand_sweep_mask()
    assert mask.shape == (32, 32, 32) and 0.05 < mask.mean() < 0.3
    assert not mask[:, :, -1].any()  # past the fingertips nothing is swept
    with pytest.raises(ValueError, match="occupancy grids"):
        approach_blocked(np.zeros((2, 32, 32)))


def test_staged_selection_keeps_the_top_ranks_of_scoring_everything_with_fewer_cnn_calls():
    robot, cloud = ROBOTS["panda"], ObjectCloud(block_points())
    full = make_scorer("cnn_rp", robot, SelectionConfig(staged=False))
    staged = make_scorer("cnn_rp", robot, SelectionConfig(staged=True, exact_top=10, batch_size=32))
    rank = {name: rank_grasps(cloud, scorer, num_candidates=400, gamma_deg=(0, 90),
                              rng=np.random.default_rng(3))
            for name, scorer in (("full", full), ("staged", staged))}
    assert np.isfinite(rank["full"].p_s).all()
    scored = np.isfinite(rank["staged"].p_s)
    assert scored.sum() < 0.6 * len(scored)  # the CNN ran on a fraction of the candidates
    blocked_staged = approach_blocked(voxelize(cloud.points, rank["staged"].X_WG))
    assert (~scored & ~blocked_staged).any()  # p_r cut some unblocked candidates too
    # Scoring everything, the best unblocked candidates are the staged ranking's top 10, in order.
    blocked = approach_blocked(voxelize(cloud.points, rank["full"].X_WG))
    np.testing.assert_array_equal(rank["staged"].X_WG[:10], rank["full"].X_WG[~blocked][:10])
    np.testing.assert_allclose(rank["staged"].p_s[:10], rank["full"].p_s[~blocked][:10])
    # Scored candidates come first, best first; the unscored ones have no score.
    k = scored.sum()
    assert scored[:k].all() and not scored[k:].any()
    assert np.all(np.diff(rank["staged"].scores[:k]) <= 0) and np.isnan(rank["staged"].scores[k:]).all()


def test_staged_cnn_policy_skips_blocked_candidates_and_ranks_them_last():
    cloud = ObjectCloud(block_points(seed=1, n=3000))
    X_WG = sample_grasps(cloud.points, 200, (0, 90), np.random.default_rng(0))
    scorer = make_scorer("cnn", ROBOTS["panda"], SelectionConfig(staged=True))
    scored = scorer(cloud, X_WG, np.random.default_rng(0))
    blocked = approach_blocked(voxelize(cloud.points, X_WG))
    assert 0 < blocked.sum() < len(X_WG)
    np.testing.assert_array_equal(scored.tier == Tier.BLOCKED, blocked)
    assert np.isnan(scored.p_s[blocked]).all() and np.isfinite(scored.p_s[~blocked]).all()
    with pytest.raises(ValueError, match="blocking_voxels"):
        SelectionConfig(staged=True, blocking_voxels=0)
