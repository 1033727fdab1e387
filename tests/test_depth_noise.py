"""The depth camera's noise model: its statistics, edges, units and determinism, and in the station."""

import dataclasses as dc

import numpy as np
import pytest

from drake_grasp.cell.diagram import build_cell
from drake_grasp.policy.scorers import make_scorer
from drake_grasp.robot.arms import get_robot
from drake_grasp.simulation.depth_noise import DepthNoiseConfig, add_depth_noise
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import load_scenario


def test_noise_grows_with_range_is_quantized_and_keeps_missing_pixels_missing():
    config = DepthNoiseConfig(enabled=True, edge_dropout=0.0, random_dropout=0.0)
    near, far = np.full((200, 200), 0.5, np.float32), np.full((200, 200), 2.0, np.float32)
    rng = np.random.default_rng(0)
    sigma_near, sigma_far = (np.std(add_depth_noise(d, config, rng) - d) for d in (near, far))
    assert sigma_near == pytest.approx(0.0005 + 0.0006 * 0.25, rel=0.25)  # quantization adds ~0.3 mm
    assert sigma_far == pytest.approx(0.0005 + 0.0006 * 4.0, rel=0.1) and sigma_far > 3 * sigma_near
    noisy = add_depth_noise(far, config, rng)
    np.testing.assert_allclose(noisy * 1000, np.round(noisy * 1000), atol=1e-3)  # whole millimetres
    holes = far.copy()
    holes[:10], holes[10:20] = 0.0, np.inf
    assert (add_depth_noise(holes, config, rng)[:20] == 0).all()


def test_pixels_at_a_depth_step_drop_out_and_the_same_generator_gives_the_same_image():
    step = np.full((100, 100), 1.3, np.float32)
    step[:, 50:] = 1.2  # an object's edge 10 cm above the table
    config = DepthNoiseConfig(enabled=True, edge_dropout=1.0, random_dropout=0.0)
    noisy = add_depth_noise(step, config, np.random.default_rng(1))
    assert (noisy[:, 49:51] == 0).all() and (noisy[:, :48] > 0).all() and (noisy[:, 52:] > 0).all()
    again = add_depth_noise(step, config, np.random.default_rng(1))
    np.testing.assert_array_equal(noisy, again)


def test_the_station_sees_through_the_noise_model_when_the_scenario_enables_it():
    robot = get_robot("panda")
    # (no re-drop: the images are taken 0.3 s into the drop, before the first attempt)
    scenario = dc.replace(load_scenario("standard").shrunk(objects_per_cluster=2), settle_within=0.0)
    images = {}
    for name, noisy in (("clean", False), ("noisy", True), ("again", True)):
        cell = build_cell(robot=robot, scenario=scenario.with_depth_noise(noisy),
                          scorer=make_scorer("rand", robot), object_models=load_object_set("primitives"),
                          seed=0)
        cell.advance(0.3)
        images[name] = cell.depth_image()
    clean, noisy = images["clean"], images["noisy"]
    np.testing.assert_array_equal(images["again"], noisy)  # the same seed: the same noisy image
    seen = np.isfinite(clean) & (clean > 0) & (noisy > 0)
    difference = np.abs(noisy[seen] - clean[seen])
    assert 0.0005 < np.mean(difference) < 0.005  # about a millimetre at 1.3 m
    assert (noisy == 0).mean() > (~np.isfinite(clean) | (clean == 0)).mean()  # edge pixels lost
