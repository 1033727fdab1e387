import numpy as np
import pytest

from drake_grasp.policy.sampling import (
    MAX_BACK_OFF,
    TABLE_CLEARANCE,
    approach_angle_deg,
    back_off_from_table,
    fingertip_corners_G,
    sample_grasps,
)


def test_candidates_follow_the_papers_sampling():
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.05, 0.05, (300, 3))
    X = sample_grasps(points, 2000, (30.0, 60.0), rng)
    assert X.shape == (2000, 4, 4)
    R = X[:, :3, :3]
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape), atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-9)
    gamma = approach_angle_deg(X)
    assert gamma.min() >= 30 - 1e-6 and gamma.max() <= 60 + 1e-6
    assert abs(np.mean(gamma) - 45) < 1.5  # uniform in the angle
    # Grasp points are points of the cloud, drawn uniformly.
    assert all(np.any(np.all(points == p, axis=1)) for p in X[:50, :3, 3])
    # Wrist roll is uniform: the closing axis projected on the table spans all directions.
    y = X[:, :3, 1]
    angles = np.arctan2(y[:, 1], y[:, 0])
    hist, _ = np.histogram(angles, bins=8, range=(-np.pi, np.pi))
    assert hist.min() > 0.6 * hist.mean()


def test_top_grasps_point_straight_down_and_seeds_repeat():
    points = np.array([[0.5, 0.0, 0.02]])
    X = sample_grasps(points, 10, (0.0, 0.0), np.random.default_rng(3))
    np.testing.assert_allclose(X[:, :3, 2], np.tile([0, 0, -1.0], (10, 1)), atol=1e-12)
    np.testing.assert_array_equal(X, sample_grasps(points, 10, (0.0, 0.0), np.random.default_rng(3)))


def test_bad_requests_raise():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="empty"):
        sample_grasps(np.zeros((0, 3)), 5, (0, 90), rng)
    with pytest.raises(ValueError, match="gamma"):
        sample_grasps(np.zeros((4, 3)), 5, (60, 30), rng)


def test_candidates_that_would_hit_the_table_back_off_just_enough():
    rng = np.random.default_rng(4)
    points = rng.uniform([-0.03, -0.03, 0.0], [0.03, 0.03, 0.08], (400, 3))
    X = sample_grasps(points, 600, (0.0, 90.0), np.random.default_rng(5))
    backed = back_off_from_table(X, table_z=0.0)
    # The sampler given the table's height draws the same candidates and backs them off.
    aware = sample_grasps(points, 600, (0.0, 90.0), np.random.default_rng(5), table_z=0.0)
    np.testing.assert_array_equal(aware, backed)
    corners_G = fingertip_corners_G()
    lowest = lambda Y: Y[:, 2, 3] + (corners_G @ Y[:, 2, :3].T).min(axis=0)  # noqa: E731
    moved = np.linalg.norm(backed[:, :3, 3] - X[:, :3, 3], axis=1) > 1e-12
    assert 0 < moved.sum() < len(X)
    np.testing.assert_allclose(backed[:, :3, :3], X[:, :3, :3])  # orientations untouched
    # Moved ones: back along the approach, the fingertips exactly at the clearance, at most MAX_BACK_OFF.
    shift = backed[moved, :3, 3] - X[moved, :3, 3]
    along = np.einsum("ij,ij->i", shift, -X[moved, :3, 2])
    np.testing.assert_allclose(shift, -along[:, None] * X[moved, :3, 2], atol=1e-12)
    assert (along > 0).all() and (along <= MAX_BACK_OFF + 1e-12).all()
    np.testing.assert_allclose(lowest(backed[moved]), TABLE_CLEARANCE, atol=1e-9)
    # Kept ones: clear already, or beyond help (near-horizontal, or too deep).
    kept = ~moved
    clear = lowest(X[kept]) >= TABLE_CLEARANCE
    assert clear.any() and (~clear).any()
    # A top-down grasp on a 1 cm slab's top: fingertips 2 cm past it, backed off to 3 mm above the table.
    top = np.eye(4)
    top[:3, :3] = np.diag([1.0, -1.0, -1.0])
    top[:3, 3] = [0.5, 0.0, 0.01]
    np.testing.assert_allclose(back_off_from_table(top[None], 0.0)[0, :3, 3], [0.5, 0.0, 0.023])
    np.testing.assert_allclose(back_off_from_table(top[None], 0.2)[0], top)  # 21 cm under: beyond help
