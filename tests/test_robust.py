import numpy as np
import pytest

from drake_grasp.perception import ObjectCloud
from drake_grasp.policy.robust import PoseErrors, neighbour_poses, robust_stability
from drake_grasp.policy.scorers import SelectionConfig, Tier, make_scorer
from drake_grasp.policy.selector import rank_grasps
from drake_grasp.robots import ROBOTS


def test_neighbours_are_small_rigid_errors_of_the_grasp_in_its_own_frame():
    X_WG = np.eye(4)
    X_WG[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # turned 90 degrees about z_W
    X_WG[:3, 3] = [0.5, 0.1, 0.05]
    neighbours = neighbour_poses(X_WG[None])[0]
    assert neighbours.shape == (7, 4, 4)
    for X in neighbours:
        np.testing.assert_allclose(X[:3, :3] @ X[:3, :3].T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(X[:3, 2], X_WG[:3, 2], atol=1e-12)  # the approach is kept
    moved = neighbours[:, :3, 3] - X_WG[:3, 3]
    # the first shifts run along x_G, which is +y_W here; the fifth backs off along -z_G
    np.testing.assert_allclose(moved[0], [0.0, -0.005, 0.0], atol=1e-12)
    np.testing.assert_allclose(moved[4], [0.0, 0.0, -0.005], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(moved[:5], axis=1), 0.005)
    np.testing.assert_allclose(moved[5:], 0.0, atol=1e-12)  # the turns keep the grasp point
    turn = np.degrees(np.arccos(np.clip(neighbours[5, :3, 0] @ X_WG[:3, 0], -1, 1)))
    assert turn == pytest.approx(PoseErrors().turn_deg)
    np.testing.assert_allclose(robust_stability(np.array([1.0, 0.0]), np.array([[0.0] * 7, [0.8] * 7])),
                               [1 / 8, 0.7])


def test_robust_selection_ranks_its_best_candidates_first_by_the_mean_over_their_neighbours():
    """With the shipped CNN on a box's cloud: the `robust_top` best by p_g move to the robust tier, each
    scored as p_r * p_h times the mean p_s over itself and its 7 neighbours, computed here again."""
    from drake_grasp import GraspStabilityPredictor, ReachabilityPredictor
    from drake_grasp.learning.hold import HoldPredictor

    points = np.random.default_rng(0).uniform([0.45, -0.03, 0.0], [0.55, 0.03, 0.05], (1500, 3))
    cloud = ObjectCloud(points, 0.0)
    plain = rank_grasps(cloud, make_scorer("cnn_rp", ROBOTS["panda"]), num_candidates=120,
                        gamma_deg=(0, 60), rng=np.random.default_rng(3))
    robust = rank_grasps(cloud, make_scorer("cnn_rp", ROBOTS["panda"], SelectionConfig(robust_top=5)),
                         num_candidates=120, gamma_deg=(0, 60), rng=np.random.default_rng(3))
    # the same five candidates lead, each re-scored
    first = {X.tobytes() for X in plain.X_WG[:5]}
    assert {X.tobytes() for X in robust.X_WG[:5]} == first
    cnn = GraspStabilityPredictor.load()
    X5 = robust.X_WG[:5]
    p_n = cnn(points, neighbour_poses(X5).reshape(-1, 4, 4)).reshape(5, 7)
    expected = (ReachabilityPredictor.load("panda")(X5) * HoldPredictor.load()(points, X5)
                * robust_stability(cnn(points, X5), p_n))
    np.testing.assert_allclose(robust.scores[:5], expected, atol=1e-4)
    assert np.all(np.diff(robust.scores[:5]) <= 0)
    assert not np.allclose(robust.scores[:5], plain.scores[:5], atol=1e-3)  # the neighbours changed them
    np.testing.assert_allclose(robust.scores[5:], plain.scores[5:], atol=1e-5)  # the rest as before


def test_robust_selection_options_are_checked():
    with pytest.raises(ValueError, match="robust_top"):
        SelectionConfig(robust_top=-1)
    with pytest.raises(ValueError, match="hold_z_scale"):
        SelectionConfig(hold_z_scale=0.0)
    with pytest.raises(ValueError, match="cannot exceed"):
        SelectionConfig(staged=True, exact_top=5, robust_top=6)
    assert Tier.ROBUST < Tier.SCORED
