import numpy as np

from drake_grasp.apps.bench import voxelize_naive
from drake_grasp.learning.voxels import CUBE, GRID, voxelize
from drake_grasp.policy.sampling import sample_grasps


def test_a_box_of_known_size_and_pose_fills_exactly_its_voxels():
    """A solid 31 x 12.5 x 62.5 mm box, given in G at voxel centres, seen from a tilted grasp frame."""
    h = CUBE / GRID
    i, j, k = np.meshgrid(np.arange(10, 20), np.arange(12, 16), np.arange(5, 25), indexing="ij")
    p_G = (np.stack([i, j, k], -1).reshape(-1, 3) + 0.5) * h - CUBE / 2
    rng = np.random.default_rng(0)
    X_WG = sample_grasps(np.array([[0.4, -0.1, 0.2]]), 3, (20, 70), rng)
    for X in X_WG:
        p_W = p_G @ X[:3, :3].T + X[:3, 3]
        outside = np.array([[5.0, 5.0, 5.0]])  # far away: ignored
        grid = voxelize(np.vstack([p_W, outside]), X[None])[0]
        expected = np.zeros((GRID,) * 3, np.uint8)
        expected[10:20, 12:16, 5:25] = 1
        np.testing.assert_array_equal(grid, expected)


def test_batched_voxels_equal_the_naive_loop():
    rng = np.random.default_rng(1)
    points = np.vstack([rng.uniform(-0.03, 0.03, (600, 3)) + c for c in ([0.5, 0, 0.03], [0.55, 0.05, 0.02])])
    X_WG = sample_grasps(points, 12, (0, 90), rng)
    batched = voxelize(points, X_WG)
    np.testing.assert_array_equal(batched, voxelize_naive(points, X_WG))
    assert batched.shape == (12, GRID, GRID, GRID) and batched.dtype == np.uint8
    assert batched.reshape(12, -1).sum(1).min() > 0  # every grasp point sits on the cloud
    assert voxelize(np.zeros((0, 3)), X_WG).sum() == 0


def test_a_stray_far_point_or_a_bad_shape():
    """Only occupied cells are stored: a point 30 m away changes nothing and costs nothing."""
    import pytest

    rng = np.random.default_rng(2)
    points = rng.uniform(-0.03, 0.03, (400, 3)) + [0.5, 0.0, 0.03]
    X_WG = sample_grasps(points, 5, (0, 90), rng)
    np.testing.assert_array_equal(voxelize(np.vstack([points, [[20.0, -30.0, 5.0]]]), X_WG),
                                  voxelize(points, X_WG))
    with pytest.raises(ValueError, match=r"\(M, 3\)"):
        voxelize(np.zeros((10, 4)), X_WG)
    with pytest.raises(ValueError, match=r"\(N, 4, 4\)"):
        voxelize(points, X_WG[0])


def test_the_voxels_under_a_tilted_table_are_those_whose_centres_lie_under_its_plane():
    from drake_grasp.learning.voxels import below_plane, occupied_voxel_centers

    rng = np.random.default_rng(3)
    normal = np.array([0.1, -0.05, 1.0]) / np.linalg.norm([0.1, -0.05, 1.0])
    offset = -0.01  # the plane 1 cm up at the origin
    X_WG = sample_grasps(rng.uniform(-0.02, 0.04, (50, 3)) + [0.5, 0.0, 0.0], 6, (0, 80), rng)
    under = below_plane(X_WG, normal, offset)
    assert under.shape == (6, GRID, GRID, GRID) and under.dtype == np.uint8
    for grid, X in zip(under, X_WG, strict=True):
        heights_under = occupied_voxel_centers(grid, X) @ normal + offset
        heights_above = occupied_voxel_centers(1 - grid, X) @ normal + offset
        assert (heights_under < 0).all() and (heights_above >= 0).all()
    level = np.eye(4)[None].copy()
    level[0, 2, 3] = 0.02  # a grasp frame level with the world, 2 cm above a table at z = 0
    share = below_plane(level, [0.0, 0.0, 1.0], 0.0).mean()
    assert share == 10 / 32  # the bottom 10 slices: centres from -4.84 to -2.03 cm, under -2 cm
