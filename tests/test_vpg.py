"""VPG's heightmap, its top-down grasps and the rotated fully convolutional net."""

import json
import math

import numpy as np
import pytest
import torch
from scenes import block_points

from drake_grasp.policy.baselines.vpg import (
    ROTATIONS,
    HeightmapConfig,
    MaxPool2x2,
    VpgNet,
    best_grasps,
    covering,
    executed_logits,
    grasp_cell,
    grasp_pose,
    heightmap,
    q_maps,
    rotated_logits,
    rotation_angle,
    sample_top_down,
)
from drake_grasp.policy.sampling import sample_candidates


def test_the_fast_pooling_is_torchs_value_for_value_and_trains_as_torchs():
    maps = torch.relu(torch.randn(3, 4, 16, 24, generator=torch.Generator().manual_seed(0)))  # ties at 0
    with torch.inference_mode():
        assert torch.equal(MaxPool2x2()(maps), torch.nn.functional.max_pool2d(maps, 2))
        odd = maps[..., :15, :]
        assert torch.equal(MaxPool2x2()(odd), torch.nn.functional.max_pool2d(odd, 2))
    grad = maps.clone().requires_grad_()
    MaxPool2x2()(grad).sum().backward()
    assert set(grad.grad.unique().tolist()) == {0.0, 1.0}  # one of tied maxima gets it all, as in torch's


def test_the_heightmap_holds_the_block_top_at_its_cells():
    config = HeightmapConfig()
    heights = heightmap(block_points(n=20000), config)
    assert heights.shape == (224, 224) and heights.dtype == np.float32
    i, j = np.nonzero(heights > 0.055)  # the 6 cm top face
    x = config.centre[0] - config.size / 2 + (i + 0.5) * config.resolution
    y = config.centre[1] - config.size / 2 + (j + 0.5) * config.resolution
    assert x.min() > 0.47 and x.max() < 0.53 and y.min() > -0.065 and y.max() < 0.065
    assert heights.max() <= 0.0601 and (heights >= 0).all()
    assert heights[0, 0] == 0.0  # a corner of the square sees only table


def test_a_cell_and_rotation_make_a_top_down_pose_and_back():
    heights = heightmap(block_points(n=20000))
    for i, j, k in [(112, 112, 0), (112, 100, 5), (100, 120, 15)]:
        X_WG = grasp_pose(i, j, k, heights)
        np.testing.assert_allclose(X_WG[:3, 2], [0.0, 0.0, -1.0])  # straight down
        angle = rotation_angle(k)
        np.testing.assert_allclose(X_WG[:3, 1], [math.cos(angle), math.sin(angle), 0.0], atol=1e-12)
        np.testing.assert_allclose(np.linalg.det(X_WG[:3, :3]), 1.0)
        assert grasp_cell(X_WG) == (i, j, k)
        jaw_swapped = X_WG @ np.diag([-1.0, -1.0, 1.0, 1.0])  # the same grasp, jaws swapped
        assert grasp_cell(jaw_swapped) == (i, j, k)
    assert grasp_pose(112, 112, 0, heights)[2, 3] > 0.059  # onto the block's top
    assert grasp_pose(0, 0, 0, heights)[2, 3] > 0.02  # fingertips stay above the table
    X = sample_top_down(block_points(), 30, np.random.default_rng(0))
    assert len(X) == 30 and all(heights[grasp_cell(x)[:2]] >= 0.01 for x in X)
    assert len(sample_candidates(block_points(), 5, (0.0, 90.0), "topdown", np.random.default_rng(0))[0]) == 5


def test_rotated_logits_turn_the_map_so_the_jaws_close_along_the_rows():
    """A net that answers with its input shows the turn: rotation k's output is the map itself."""

    class Identity(VpgNet):
        def forward(self, heights):
            return heights[:, 0]

    n = 64
    heights = torch.zeros(ROTATIONS, n, n)
    heights[:, 20:44, 30:34] = 1.0
    heights[:, 1:4, 1:12] = 1.0  # in a corner, which a turn by 45 degrees takes out of the frame
    out = rotated_logits(Identity(), heights, torch.arange(ROTATIONS))
    assert out.shape == (ROTATIONS, n, n)
    for k in range(ROTATIONS):  # turned and turned back: both bars are where they were
        for rows, cols in [(slice(20, 44), slice(30, 34)), (slice(1, 4), slice(1, 12))]:
            assert float(out[k, rows, cols].mean()) > 0.7, (k, rows)
    maps = q_maps(VpgNet(), heightmap(block_points()))
    assert maps.shape == (ROTATIONS, 224, 224) and ((maps >= 0) & (maps <= 1)).all()


def test_the_square_grows_to_hold_objects_beyond_vpg_workspace():
    default = HeightmapConfig()
    assert covering(block_points()) == default  # the block lies well inside VPG's 0.448 m square
    far = block_points(n=20000) + [0.0, 0.3, 0.0]  # rolled 30 cm aside: out of that square
    assert not heightmap(far, default).any()
    config = covering(far)
    assert config.centre == default.centre and config.size > default.size
    assert config.cells % 8 == 0 and config.cells * config.resolution == pytest.approx(config.size)
    heights = heightmap(far, config)
    i, j = np.nonzero(heights > 0.055)  # the top face, where it lies
    y = config.centre[1] - config.size / 2 + (j + 0.5) * config.resolution
    assert len(i) > 0 and y.min() > 0.235 and y.max() < 0.365
    with pytest.raises(ValueError, match="empty"):
        covering(np.zeros((0, 3)))


def test_spaced_candidates_span_every_object_not_just_the_best_spot():
    """Two blocks, the net's q peaked on one: the 20 best cell-rotations all lie on that spot; one a spot
    1 cm apart, the list reaches the other block, best first and never two within the spacing."""
    config = HeightmapConfig()
    heights = heightmap(np.concatenate([block_points(n=20000), block_points(n=20000) + [0.0, 0.15, 0.0]]))
    rows, cols = np.indices(heights.shape)
    peak = np.exp(-((rows - 112) ** 2 + (cols - 112) ** 2) / 2000.0)
    q = peak[None] * np.linspace(0.5, 1.0, ROTATIONS)[:, None, None]
    packed = best_grasps(heights, q, 20, config)
    assert np.ptp(packed[:, 1, 3]) < 0.01  # a single spot, every rotation of a few cells
    spaced = best_grasps(heights, q, 20, config, spacing=5)
    cells = np.array([grasp_cell(X, config) for X in spaced])
    assert (cells[:, 2] == ROTATIONS - 1).all()  # each spot's best rotation
    scores = q[cells[:, 2], cells[:, 0], cells[:, 1]]
    assert (np.diff(scores) <= 0).all()
    gaps = np.abs(cells[:, None, :2] - cells[None, :, :2]).max(axis=2) + 5 * np.eye(len(cells), dtype=int)
    assert gaps.min() >= 5
    spread = best_grasps(heights, q, 2000, config, spacing=5)
    assert (spread[:, 1, 3] > 0.1).any() and len(spread) < 2000  # the other block too; then no spot is left


def test_training_reads_the_executed_cells_logit_from_a_window_as_from_the_whole_map():
    torch.manual_seed(0)
    net = VpgNet()
    with torch.no_grad():  # larger weights: logits that differ from cell to cell
        for parameter in net.parameters():
            parameter.mul_(3.0)
    generator = torch.Generator().manual_seed(1)
    heights = torch.zeros(8, 224, 224)
    heights[:, 60:170, 60:170] = 0.1 * torch.rand(110, 110, generator=generator)
    cells = torch.cat([torch.randint(70, 160, (8, 2), generator=generator),
                       torch.arange(0, ROTATIONS, 2)[:, None]], 1)  # (i, j, k) rows
    with torch.no_grad():
        whole = rotated_logits(net, heights, cells[:, 2])[torch.arange(8), cells[:, 0], cells[:, 1]]
        window = executed_logits(net, heights, cells)
    assert float(whole.std()) > 0.3  # the cells' logits differ
    torch.testing.assert_close(window, whole, atol=1e-4, rtol=1e-4)


@pytest.mark.slow
def test_collect_topdown_trials_train_vpg_and_grasp_with_it(tmp_path):
    from scenes import one_cube_yaml

    from drake_grasp.apps.collect_grasps import main as collect_main
    from drake_grasp.apps.train import main as train_main
    from drake_grasp.cell.episode import run_episode
    from drake_grasp.datasets.grasp_data import load_grasp_dataset
    from drake_grasp.perception.cloud import ObjectCloud
    from drake_grasp.policy.baselines.vpg import load_model
    from drake_grasp.policy.scorers import VpgScorer
    from drake_grasp.robot.specs import ROBOTS
    from drake_grasp.simulation.objects import load_object_set
    from drake_grasp.simulation.scenario import load_scenario

    out = tmp_path / "topdown"
    assert collect_main(["--sampler", "topdown", "--trials", "12", "--per-scene", "4",
                         "--scenes-per-shard", "3", "--workers", "1", "--seed", "2", "--out", str(out)]) == 0
    data = load_grasp_dataset(out)
    assert data.manifest["sampler"] == "topdown" and np.allclose(data.X_WG[:, :3, 2], [0.0, 0.0, -1.0])
    weights = tmp_path / "vpg.pt"
    assert train_main(["vpg", "--data", str(out), "--out", str(weights), "--epochs", "1",
                       "--test-fraction", "0.3", "--heldout", str(out)]) == 0
    card = json.loads(weights.with_suffix(".json").read_text())
    assert card["trials"]["fit"] > 0 and "test_metrics" in card
    assert card["heldout_metrics"]["n"] == card["heldout"]["trials"] == len(data)  # every trial measured
    assert load_model(weights)[1]["arch"] == "vpg_fcn"
    # As a policy: its best cells, straight down, in the closed loop on one cube.
    scenario = tmp_path / "one_cube.yaml"
    scenario.write_text(one_cube_yaml(max_attempts=1))
    cube = [m for m in load_object_set("primitives") if m.name == "cube"]
    run = run_episode(robot=ROBOTS["panda"], scenario=load_scenario(str(scenario)), scorer=VpgScorer(weights),
                      object_models=cube, seed=0)
    assert run.attempts == 1 and run.attempt_log[0]["approach_angle_deg"] < 1e-6
    # Heights count from the table perception measured: the same block on a table 10 cm higher gets
    # the same cells and angles, 10 cm higher (without the measured table, other heights, other grasps).
    scorer, rng = VpgScorer(weights), np.random.default_rng(0)
    on_floor = scorer.candidates(block_points(), 5, (0.0, 0.0), rng, table_z=0.0)
    raised, up = block_points() + [0.0, 0.0, 0.1], np.zeros((4, 4))
    up[2, 3] = 0.1
    np.testing.assert_allclose(scorer.candidates(raised, 5, (0.0, 0.0), rng, table_z=0.1), on_floor + up,
                               atol=1e-9)
    assert not np.allclose(scorer.candidates(block_points() + [0.0, 0.0, 0.1], 5, (0.0, 0.0), rng)[:, 2, 3],
                           on_floor[:, 2, 3] + 0.1)
    # A block out of VPG's 0.448 m square (rolled 30 cm aside) is still grasped where it lies, and the
    # scores are read at the grown map's cells.
    aside = block_points() + [0.0, 0.3, 0.0]
    X_WG = scorer.candidates(aside, 5, (0.0, 0.0), rng, table_z=0.0)
    assert len(X_WG) == 5
    assert (np.abs(X_WG[:, 1, 3] - 0.3) < 0.07).all() and (np.abs(X_WG[:, 0, 3] - 0.5) < 0.04).all()
    cloud = ObjectCloud(points=aside, table_z=0.0)
    scores = scorer(cloud, X_WG, rng).score
    assert (np.diff(scores) <= 1e-5).all()  # the candidates come best first
