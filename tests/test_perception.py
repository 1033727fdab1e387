import numpy as np
import pytest

from drake_grasp.perception import PerceptionError, crop, extract_object_cloud

LOWER, UPPER = [0.0, -0.5, -0.02], [1.0, 0.5, 0.3]


def table_and_box(rng, noise=0.001):
    xs, ys = np.meshgrid(np.linspace(0.1, 0.9, 120), np.linspace(-0.4, 0.4, 120))
    table = np.column_stack([xs.ravel(), ys.ravel(), rng.normal(0, noise, xs.size)])
    # The top and two sides of a 60 x 40 x 50 mm box centred at (0.5, 0.1).
    u, v = rng.uniform(-0.5, 0.5, (2, 800))
    top = np.column_stack([0.5 + 0.06 * u, 0.1 + 0.04 * v, np.full(800, 0.05)])
    side = np.column_stack([np.full(400, 0.47), 0.1 + 0.04 * v[:400], 0.005 + 0.045 * (u[:400] + 0.5)])
    far = np.array([[3.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])  # outside the workspace, and invalid depth
    return np.vstack([table, top, side, far]), np.vstack([top, side])


def test_table_is_removed_and_the_box_kept():
    rng = np.random.default_rng(0)
    points, box = table_and_box(rng)
    cloud = extract_object_cloud(points, lower=LOWER, upper=UPPER)
    assert len(cloud) >= 0.95 * len(box)
    assert cloud.points[:, 2].min() > 0.004  # no table point survives
    assert np.abs(cloud.points[:, 0] - 0.5).max() <= 0.031
    # The same points and seed give the same cloud (open3d's RANSAC is seeded on every call).
    again = extract_object_cloud(points, lower=LOWER, upper=UPPER)
    np.testing.assert_array_equal(cloud.points, again.points)


def test_the_table_top_is_measured_where_it_lies():
    rng = np.random.default_rng(2)
    points, _ = table_and_box(rng)
    for height in (0.0, 0.12):
        raised = points + [0.0, 0.0, height]
        cloud = extract_object_cloud(raised, lower=LOWER, upper=np.add(UPPER, [0, 0, height]))
        assert cloud.table_z == pytest.approx(height, abs=0.002)
    assert extract_object_cloud(points[points[:, 2] > 0.004], lower=LOWER, upper=UPPER).table_z is None


def test_only_table_gives_an_empty_object_cloud():
    rng = np.random.default_rng(1)
    points, _ = table_and_box(rng)
    table_only = points[points[:, 2] < 0.004]
    assert len(extract_object_cloud(table_only, lower=LOWER, upper=UPPER)) == 0


def test_crop_keeps_only_finite_points_inside_the_box():
    points = np.array([[0.5, 0, 0.1], [1.5, 0, 0.1], [np.nan, 0, 0], [0.5, 0, np.inf], [0.0, -0.5, -0.02]])
    np.testing.assert_array_equal(crop(points, LOWER, UPPER), points[[0, 4]])


@pytest.mark.parametrize("points, message", [
    (np.zeros((0, 3)), "empty"),
    (np.full((50, 3), np.nan), "no finite point"),
])
def test_bad_clouds_are_named(points, message):
    with pytest.raises(PerceptionError, match=message):
        extract_object_cloud(points, lower=LOWER, upper=UPPER)
