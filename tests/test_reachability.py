"""Reachability labels, the RP model, its training and its predictor API."""

import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from drake_grasp import ReachabilityPredictor
from drake_grasp.apps.collect_reachability import main as collect_main
from drake_grasp.apps.train import main as train_main
from drake_grasp.datasets.shards import load_shards
from drake_grasp.learning.metrics import (
    auroc,
    best_per_scene_success,
    classification_metrics,
    expected_calibration_error,
    per_group_metrics,
    top_fraction_success,
)
from drake_grasp.learning.reachability_features import reachability_determinant, reachability_features
from drake_grasp.learning.rp import calibrate_stop_threshold, predict, save_model, train_reachability
from drake_grasp.policy.sampling import approach_angle_deg, sample_workspace_poses
from drake_grasp.robot.poses import homogeneous


def test_determinant_is_position_and_approach_in_the_base_frame():
    X_WG = sample_workspace_poses(50, [0, -1, 0], [1, 1, 0.3], np.random.default_rng(0))
    a = reachability_determinant(X_WG)
    np.testing.assert_allclose(a[:, :3], X_WG[:, :3, 3])
    np.testing.assert_allclose(a[:, 3:], X_WG[:, :3, 2])
    assert approach_angle_deg(X_WG).max() <= 90 + 1e-9
    X_WB = np.eye(4)
    X_WB[:3, 3] = [0.2, 0.0, 0.1]  # base moved: positions shift, directions do not
    b = reachability_determinant(X_WG, X_WB)
    np.testing.assert_allclose(b[:, :3], a[:, :3] - [0.2, 0.0, 0.1])
    np.testing.assert_allclose(b[:, 3:], a[:, 3:])


def test_metrics_on_known_cases():
    labels = np.array([0, 0, 1, 1])
    assert auroc(labels, np.array([0.1, 0.4, 0.35, 0.8])) == pytest.approx(0.75)
    assert auroc(labels, np.array([0.1, 0.2, 0.8, 0.9])) == 1.0
    assert expected_calibration_error(labels, labels.astype(float)) == 0.0
    m = classification_metrics(labels, np.array([0.9, 0.1, 0.8, 0.7]))
    assert m["accuracy"] == 0.75 and m["precision"] == pytest.approx(2 / 3) and m["recall"] == 1.0
    ranked = np.arange(20) / 20  # the best-scored two of twenty succeed, and one more
    outcome = (np.arange(20) >= 18) | (np.arange(20) == 3)
    assert top_fraction_success(outcome, ranked, 0.1) == 1.0
    assert top_fraction_success(outcome, ranked, 0.2) == 0.5
    groups = np.array(["a"] * 10 + ["b"] * 10)
    per = per_group_metrics(outcome, ranked, groups)
    assert per["b"]["top10_success"] == 1.0 and per["a"]["top10_success"] == 0.0 and per["a"]["n"] == 10
    # Each scene's best-scored trial: scene 7's best (0.9) failed, scene 2's (0.6) succeeded, scene 5's too.
    scenes = np.array([7, 2, 7, 2, 5])
    assert best_per_scene_success([0, 1, 1, 0, 1], [0.9, 0.6, 0.8, 0.1, 0.3], scenes) == pytest.approx(2 / 3)


def test_stop_threshold_leaves_the_given_share_of_plannable_poses_below_it():
    p_r = np.linspace(0.0, 1.0, 1001)
    labels = p_r > 0.3  # every pose above 0.3 planned
    labels[[50, 120]] = True  # and two far below
    calibration = calibrate_stop_threshold(p_r, labels, max_missed=0.01)
    assert 0.3 < calibration["threshold"] < 0.32  # 1 % of the 702 plannable poses lie below it
    assert calibration["planned_below"] == 8 and calibration["unplannable_below"] == 299
    with pytest.raises(ValueError, match="no held-out pose planned"):
        calibrate_stop_threshold(p_r, np.zeros(1001, bool))


def test_mlp_learns_a_reach_sphere():
    """Labels from a sphere of reach: the paper's 6-16-8-1 MLP separates them almost perfectly."""
    rng = np.random.default_rng(0)
    a = np.hstack([rng.uniform([0, -0.8, 0], [1.3, 0.8, 0.3], (4000, 3)), rng.normal(size=(4000, 3))])
    labels = (np.linalg.norm(a[:, :3] - [0, 0, 0.33], axis=1) < 0.8).astype(np.float32)
    model, info = train_reachability(a[:3000], labels[:3000], epochs=40, seed=0)
    losses = [h["train_loss"] for h in info["history"]]
    assert losses[-1] < 0.5 * losses[0]
    metrics = classification_metrics(labels[3000:], predict(model, a[3000:]))
    assert metrics["accuracy"] > 0.95 and metrics["auroc"] > 0.99


def test_an_ensemble_keeps_its_first_member_as_the_single_mlp_and_averages_the_logits(tmp_path):
    """Members train on the same fit rows from other seeds; member 0 is what one MLP of that seed is."""
    from drake_grasp.learning.rp import ReachabilityEnsemble, load_model, train_ensemble

    rng = np.random.default_rng(1)
    a = np.hstack([rng.uniform([0, -0.8, 0], [1.3, 0.8, 0.3], (3000, 3)), rng.normal(size=(3000, 3))])
    labels = (np.linalg.norm(a[:, :3] - [0, 0, 0.33], axis=1) < 0.8).astype(np.float32)
    single, _ = train_reachability(a, labels, epochs=4, seed=7)
    ensemble, info = train_ensemble(a, labels, members=3, epochs=4, seed=7)
    assert isinstance(ensemble, ReachabilityEnsemble) and len(info["members"]) == 3
    for key, value in single.state_dict().items():
        torch.testing.assert_close(ensemble.members[0].state_dict()[key], value)
    assert not torch.equal(ensemble.members[1].net[0].weight, ensemble.members[0].net[0].weight)
    x = torch.from_numpy(a[:50].astype(np.float32))
    with torch.no_grad():
        torch.testing.assert_close(ensemble(x), torch.stack([m(x) for m in ensemble.members]).mean(0))
    assert 0.8 < info["validation"]["val_accuracy"] <= 1.0
    path = tmp_path / "ensemble.pt"
    save_model(ensemble, path, robot="panda", card={})
    loaded, record = load_model(path)
    assert record["members"] == 3 and isinstance(loaded, ReachabilityEnsemble)
    np.testing.assert_allclose(predict(loaded, a), predict(ensemble, a), atol=1e-7)
    assert isinstance(train_ensemble(a, labels, members=1, epochs=1, seed=0)[0], type(single))


@pytest.mark.slow
def test_collect_resume_train_and_predict(tmp_path):
    data = tmp_path / "labels"
    args = ["--robot", "panda", "--shard-size", "8", "--workers", "1", "--seed", "3", "--out", str(data)]
    assert collect_main(["--samples", "12", *args]) == 0
    first = load_shards(data)
    assert len(first["label"]) == 12
    assert collect_main(["--samples", "24", *args]) == 0  # extends: shard 1 was short, is redone
    both = load_shards(data)
    assert len(both["label"]) == 24
    np.testing.assert_array_equal(both["X_WG"][:8], first["X_WG"][:8])
    np.testing.assert_array_equal(both["label"][:8], first["label"][:8])
    assert set(np.unique(both["failure"][both["label"] == 1])) == {0}
    assert (both["failure"][both["label"] == 0] > 0).all()
    assert (both["plan_seconds"] > 0).all()
    # A machine computing only shard 2 of the job writes the same shard.
    part = tmp_path / "part"
    assert collect_main(["--samples", "24", *args[:-2], "--out", str(part), "--shards", "2:3"]) == 0
    assert sorted(p.name for p in part.glob("shard_*")) == ["shard_00002.npz"]
    np.testing.assert_array_equal(load_shards(part)["label"], both["label"][16:])
    np.testing.assert_array_equal(load_shards(part)["X_WG"], both["X_WG"][16:])
    # Changing what the labels mean is refused.
    assert collect_main(["--samples", "24", *args[:-4], "--seed", "4", "--out", str(data)]) == 2

    held_out = tmp_path / "held_out"
    assert collect_main(["--robot", "panda", "--samples", "10", "--workers", "1", "--seed", "4",
                         "--out", str(held_out)]) == 0
    weights = tmp_path / "rp.pt"
    assert train_main(["reachability", "--robot", "panda", "--data", str(data), "--out", str(weights),
                       "--test", str(held_out), "--epochs", "3"]) == 0
    card = json.loads(weights.with_suffix(".json").read_text())
    assert card["data"]["labels"] == 24 and card["seed"] == 0
    assert set(card["validation"]) == {"val_loss", "val_accuracy"}
    assert 0 <= card["validation"]["val_accuracy"] <= 1
    assert card["test_metrics"]["n"] == 10 and card["test_data"] == str(held_out)
    assert train_main(["reachability", "--robot", "ur5", "--data", str(data), "--out", str(weights)]) == 2
    pair = tmp_path / "rp_pair.pt"
    assert train_main(["reachability", "--robot", "panda", "--data", str(data), "--out", str(pair),
                       "--epochs", "2", "--members", "2"]) == 0
    pair_card = json.loads(pair.with_suffix(".json").read_text())
    assert pair_card["model"].startswith("Reachability Predictor, 2 x MLP 6-16-8-1, mean logit")
    assert len(pair_card["best_epoch"]) == 2
    assert ReachabilityPredictor.load(str(pair))(both["a"][:3]).shape == (3,)

    rp = ReachabilityPredictor.load(str(weights))
    p = rp(homogeneous(both["X_WG"][:5]))
    assert p.shape == (5,) and ((p >= 0) & (p <= 1)).all()
    np.testing.assert_allclose(p, rp(both["a"][:5]), atol=1e-6)


def test_roll_feature_sees_the_jaw_axis_and_ignores_the_jaw_swap():
    X_WG = sample_workspace_poses(20, [0, -1, 0], [1, 1, 0.3], np.random.default_rng(5))
    swapped = X_WG.copy()
    swapped[:, :3, :2] *= -1  # rotate 180 degrees about the approach axis
    f, g = reachability_features(X_WG, "roll"), reachability_features(swapped, "roll")
    np.testing.assert_allclose(f, g)
    np.testing.assert_allclose(f[:, 6], np.abs(X_WG[:, 2, 1]))
    jaw = reachability_features(X_WG, "jaw")
    np.testing.assert_allclose(jaw, reachability_features(swapped, "jaw"))
    y = X_WG[:, :3, 1]
    np.testing.assert_allclose(jaw[:, 6:], np.stack([y[:, 0] ** 2, y[:, 0] * y[:, 1], y[:, 0] * y[:, 2],
                                                     y[:, 1] ** 2, y[:, 1] * y[:, 2], y[:, 2] ** 2], 1))
    # In the base frame: a base turned 90 degrees about z sees the jaw axis turned back.
    X_WB = np.eye(4)
    X_WB[:2, :2] = [[0.0, -1.0], [1.0, 0.0]]
    y_B = np.stack([y[:, 1], -y[:, 0], y[:, 2]], 1)
    np.testing.assert_allclose(reachability_features(X_WG, "jaw", X_WB)[:, 6:9],
                               np.stack([y_B[:, 0] ** 2, y_B[:, 0] * y_B[:, 1], y_B[:, 0] * y_B[:, 2]], 1),
                               atol=1e-12)
    with pytest.raises(ValueError, match="unknown RP features"):
        reachability_features(X_WG, "colour")


def test_predictor_rejects_bad_input_and_bad_files(tmp_path):
    from drake_grasp.learning.rp import ReachabilityMLP

    path = tmp_path / "rp.pt"
    save_model(ReachabilityMLP(), path, robot="panda", card={})
    save_model(ReachabilityMLP(features="roll"), tmp_path / "roll.pt", robot="panda", card={})
    with pytest.raises(ValueError, match="pass \\(N, 4, 4\\) grasp poses"):
        ReachabilityPredictor.load(str(tmp_path / "roll.pt"))(np.zeros((2, 6)))
    rp = ReachabilityPredictor.load(str(path))
    with pytest.raises(ValueError, match="expected"):
        rp(np.zeros((3, 5)))
    with pytest.raises(ValueError, match="NaN"):
        rp(np.full((2, 6), np.nan))
    corrupt = tmp_path / "bad.pt"
    corrupt.write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match="corrupt reachability weights"):
        ReachabilityPredictor.load(str(corrupt))
    with pytest.raises(ValueError, match="not found"):
        ReachabilityPredictor.load(str(tmp_path / "missing.pt"))
    torch.save({"arch": "something_else"}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not reachability weights"):
        ReachabilityPredictor.load(str(tmp_path / "other.pt"))


@pytest.mark.slow
def test_collection_runs_on_a_local_ray_instance(tmp_path):
    data = tmp_path / "ray_labels"
    assert collect_main(["--robot", "ur5", "--samples", "6", "--shard-size", "3", "--out", str(data),
                         "--ray-address", "local"]) == 0
    assert len(load_shards(data)["label"]) == 6


@pytest.mark.slow
def test_reachability_map_draws_rp_beside_planner_labels(tmp_path):
    import matplotlib.pyplot as plt

    from drake_grasp.apps.reachability_map import main as map_main
    from drake_grasp.evaluation.reachability_labels import grid_poses
    from drake_grasp.learning.rp import ReachabilityMLP

    poses = grid_poses(np.array([0.3, 0.6]), np.array([-0.2, 0.2]), 0.05, 45.0, seed=0)
    gamma = approach_angle_deg(poses)
    np.testing.assert_allclose(gamma, 45.0, atol=1e-9)
    # Tilted toward the robot: the approach's horizontal part points at the base.
    horizontal = poses[:, :2, 2]
    assert (np.sum(horizontal * poses[:, :2, 3], axis=1) < 0).all()
    weights = tmp_path / "rp.pt"
    save_model(ReachabilityMLP(), weights, robot="panda", card={})
    out = tmp_path / "map.png"
    assert map_main(["--robot", "panda", "--weights", str(weights), "--out", str(out),
                     "--planner-grid", "3", "--workers", "1"]) == 0
    height, width, _ = plt.imread(out).shape
    assert (width, height) == (1100, 990)  # 10 x 9 inches at 110 dpi
    # The shipped Panda RP agrees with the planner on nearly every cell of both maps.
    assert map_main(["--robot", "panda", "--out", str(out), "--planner-grid", "4", "--workers", "1"]) == 0
    rows = json.loads(out.with_suffix(".json").read_text())["rows"]
    assert [r["tilt_deg"] for r in rows] == [0.0, 45.0]
    assert all(r["cells"] == 12 and r["agreement"] >= 0.75 for r in rows)
    assert any(0 < r["reachable"] < 1 for r in rows)  # the grid spans reachable and unreachable cells
    assert map_main(["--robot", "kuka", "--out", str(out)]) == 2


@pytest.mark.slow
def test_labels_do_not_depend_on_machine_load_or_worker_history(tmp_path):
    """The same command, once on one worker and once on two beside three busy processes: the same shards."""
    args = ["--robot", "ur5", "--samples", "30", "--shard-size", "10", "--seed", "11"]
    assert collect_main([*args, "--workers", "1", "--out", str(tmp_path / "calm")]) == 0
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(3)]
    try:
        assert collect_main([*args, "--workers", "2", "--out", str(tmp_path / "loaded")]) == 0
    finally:
        for burner in burners:
            burner.kill()
    calm, loaded = load_shards(tmp_path / "calm"), load_shards(tmp_path / "loaded")
    for key in ("X_WG", "a", "label", "failure"):
        np.testing.assert_array_equal(calm[key], loaded[key])
