import numpy as np
import pytest

from drake_grasp.policy.sampling import approach_angle_deg, sample_grasps


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
