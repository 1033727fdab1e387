import dataclasses
import functools
import pickle
from pathlib import Path

import numpy as np
import pytest
import torch

from drake_grasp.learning.cnn import GraspCNN
from drake_grasp.learning.voxels import voxelize
from drake_grasp.policy.sampling import sample_grasps


def test_architecture_sizes():
    assert GraspCNN(first_stride=2)(torch.zeros(3, 32, 32, 32)).shape == (3,)
    assert GraspCNN(first_stride=1)(torch.zeros(2, 32, 32, 32)).shape == (2,)
    params = sum(p.numel() for p in GraspCNN(first_stride=2).parameters())
    assert 0.8e6 < params < 1.0e6  # the VoxNet-style variant


def test_loss_falls_on_a_small_dataset_the_test_makes():
    """Blocks narrower than the 80 mm jaw opening (label 1) against wider ones (label 0)."""
    rng = np.random.default_rng(0)
    grids, labels = [], []
    for _ in range(64):
        width = rng.uniform(0.02, 0.12)
        u = rng.uniform(-0.5, 0.5, (1500, 3)) * [0.05, width, 0.04]
        points = u + [0.5, 0.0, 0.02]
        X = sample_grasps(points[points[:, 2] > 0.035], 1, (0, 0), rng)
        X[0, :3, :3] = np.diag([1.0, -1.0, -1.0])  # close across the block's width
        grids.append(voxelize(points, X)[0])
        labels.append(float(width < 0.08))
    x, y = torch.from_numpy(np.stack(grids)), torch.tensor(labels)
    torch.manual_seed(0)
    model = GraspCNN()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    loss_fn = torch.nn.BCEWithLogitsLoss()
    losses = []
    for _ in range(15):
        optimizer.zero_grad()
        loss = loss_fn(model(x), y)
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.6 * losses[0]


def test_flips_keep_the_grid_and_predictor_loads_what_training_saved(tmp_path):
    import pytest

    from drake_grasp.learning.cnn import GraspStabilityPredictor, save_model
    from drake_grasp.learning.stability_training import (
        StabilityConfig,
        pack,
        random_flips,
        train_stability,
        unpack,
    )

    rng = np.random.default_rng(0)
    grids = (rng.random((8, 32, 32, 32)) < 0.05).astype(np.uint8)
    np.testing.assert_array_equal(unpack(pack(grids)), grids)
    flipped = random_flips(grids, np.random.default_rng(1))
    which = [[(f == variant).all() for variant in (g, g[::-1], g[:, ::-1], g[::-1, ::-1])]
             for f, g in zip(flipped, grids, strict=True)]
    assert all(sum(w) == 1 for w in which)  # each grid is exactly one of its four x/y flips
    assert len({w.index(True) for w in which}) > 1  # and the flips are drawn at random
    model, info = train_stability(pack(grids), np.array([0, 1] * 4), val_packed=pack(grids[:2]),
                                  val_labels=np.array([0, 1]), config=StabilityConfig(epochs=2, width=8))
    assert len(info["history"]) == 2 and 1 <= info["best_epoch"] <= 2
    assert model.features[0].out_channels == 8  # a narrower variant, saved and loaded as such

    path = tmp_path / "cnn.pt"
    save_model(model, path, card={"note": "test"})
    cnn = GraspStabilityPredictor.load(path)
    points = rng.uniform(-0.03, 0.03, (500, 3)) + [0.5, 0.0, 0.03]
    X_WG = sample_grasps(points, 7, (0, 90), rng)
    p = cnn(points, X_WG)
    assert p.shape == (7,) and ((p >= 0) & (p <= 1)).all()
    with torch.inference_mode():
        expected = torch.sigmoid(model(torch.from_numpy(voxelize(points, X_WG)))).numpy()
    np.testing.assert_allclose(p, expected, atol=1e-6)  # (the frozen inference module against eager)
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(cnn))(points, X_WG), p)  # to worker processes
    with pytest.raises(ValueError, match="empty"):
        cnn(np.zeros((0, 3)), X_WG)
    with pytest.raises(ValueError, match="NaN"):
        cnn(np.full((5, 3), np.nan), X_WG)
    with pytest.raises(ValueError, match=r"\(N, 4, 4\)"):
        cnn(points, np.zeros((3, 6)))
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not torch")
    with pytest.raises(ValueError, match="corrupt grasp CNN weights"):
        GraspStabilityPredictor.load(bad)
    with pytest.raises(ValueError, match="not found"):
        GraspStabilityPredictor.load(tmp_path / "missing.pt")
    torch.save({"arch": "reachability_mlp"}, tmp_path / "rp.pt")
    with pytest.raises(ValueError, match="not grasp CNN weights"):
        GraspStabilityPredictor.load(tmp_path / "rp.pt")


def test_a_half_turn_about_the_approach_is_the_grid_flipped_as_training_flips_it():
    """Turned half a turn about its approach axis, a grasp is the same grasp (the fingers swapped): its
    grid is the grid flipped along x and y, one of the flips training draws (`random_flips`)."""
    rng = np.random.default_rng(2)
    bar = rng.uniform(-0.5, 0.5, (1500, 3)) * [0.12, 0.02, 0.02] + [0.5, 0.0, 0.01]
    post = rng.uniform(-0.5, 0.5, (800, 3)) * [0.02, 0.02, 0.06] + [0.55, 0.0, 0.03]
    points = np.vstack([bar, post])  # an L: no symmetry of its own
    X_WG = sample_grasps(points, 20, (0, 60), rng)
    X_WG[:, :3, 3] += rng.uniform(-1e-5, 1e-5, (20, 3))  # (off the cloud: no point on a voxel boundary)
    half_turn = X_WG @ np.diag([-1.0, -1.0, 1.0, 1.0])
    grids = voxelize(points, X_WG)
    assert grids.any()
    np.testing.assert_array_equal(voxelize(points, half_turn), grids[:, ::-1, ::-1])


def test_an_interrupted_training_resumes_from_its_checkpoint_to_the_same_model(tmp_path, monkeypatch):
    from drake_grasp.learning import stability_training
    from drake_grasp.learning.stability_training import StabilityConfig, pack, train_stability

    rng = np.random.default_rng(1)
    grids = (rng.random((40, 32, 32, 32)) < 0.05).astype(np.uint8)
    labels = rng.integers(0, 2, 40)
    config = StabilityConfig(epochs=3, batch_size=8, seed=0, width=4)
    args = dict(val_packed=pack(grids[:8]), val_labels=labels[:8], config=config)
    reference, reference_info = train_stability(pack(grids), labels, **args)

    # Interrupted during epoch 2 (after its second batch), with the state saved after every batch.
    monkeypatch.setattr(stability_training, "Checkpoint",
                        functools.partial(stability_training.Checkpoint, every_seconds=0.0))
    calls = {"n": 0}
    real_flips = stability_training.random_flips

    def interrupting_flips(g, r):
        calls["n"] += 1
        if calls["n"] == 5 + 2 + 1:  # epoch 1 has 5 batches
            raise KeyboardInterrupt
        return real_flips(g, r)

    checkpoint = tmp_path / "cnn.checkpoint.pt"
    monkeypatch.setattr(stability_training, "random_flips", interrupting_flips)
    with pytest.raises(KeyboardInterrupt):
        train_stability(pack(grids), labels, checkpoint=checkpoint, **args)
    assert checkpoint.exists()
    monkeypatch.setattr(stability_training, "random_flips", real_flips)
    resumed, info = train_stability(pack(grids), labels, checkpoint=checkpoint, **args)
    assert info["fit_seconds"] > 0  # both sessions' training time
    assert {**info, "fit_seconds": 0} == {**reference_info, "fit_seconds": 0}
    for name, tensor in reference.state_dict().items():
        assert torch.equal(tensor, resumed.state_dict()[name]), name

    # A finished training goes on for more epochs from its checkpoint (here the uninterrupted one's).
    _, longer = train_stability(pack(grids), labels, checkpoint=checkpoint,
                                **{**args, "config": dataclasses.replace(config, epochs=4)})
    assert longer["history"][:3] == reference_info["history"] and len(longer["history"]) == 4
    assert longer["fit_seconds"] > info["fit_seconds"]

    with pytest.raises(ValueError, match="another training run"):  # other labels, same file
        train_stability(pack(grids), 1 - labels, checkpoint=checkpoint, **args)


def test_the_default_weights_are_found_by_their_repository_name_from_any_working_directory(tmp_path,
                                                                                         monkeypatch):
    from drake_grasp.learning.cnn import DEFAULT_WEIGHTS, load_model
    from drake_grasp.policy.scorers import SelectionConfig
    from drake_grasp.robot.paths import model_path

    monkeypatch.chdir(tmp_path)
    name = SelectionConfig().cnn_weights
    assert model_path(name) == DEFAULT_WEIGHTS
    _, record = load_model(model_path(name))
    folders = record["card"]["data"]["folders"]  # the default learned from the generated corpora too
    assert {"data/grasps/primitives", "data/grasps/generated", "data/grasps/generated_long"} <= set(folders)
    own = tmp_path / name
    own.parent.mkdir(parents=True)
    own.write_bytes(b"")
    assert model_path(name) == Path(name)  # a file of that name where the user runs comes first
    assert model_path(own) == own


def test_a_table_channel_starts_as_the_network_it_extends_and_is_saved_and_fed_as_such(tmp_path):
    """`with_channels` adds an input whose weights are zero: the same p_s until training; a table
    network trains on two-channel grids (flips and packing keep the channels together), is saved and
    loaded with it, and the predictor feeds it the cloud's table plane."""
    from drake_grasp.learning.cnn import GraspStabilityPredictor, save_model
    from drake_grasp.learning.stability_training import (
        StabilityConfig,
        pack,
        random_flips,
        train_stability,
        unpack,
    )
    from drake_grasp.learning.voxels import below_plane

    rng = np.random.default_rng(4)
    torch.manual_seed(0)
    plain = GraspCNN(width=8).eval()
    table_net = plain.with_channels(table_channel=True, hand_channel=False).eval()
    assert table_net.input_shape == (2, 32, 32, 32)
    points = rng.uniform(-0.03, 0.03, (500, 3)) + [0.5, 0.0, 0.03]
    X_WG = sample_grasps(points, 9, (0, 80), rng)
    occupancy, under = voxelize(points, X_WG), below_plane(X_WG, [0.0, 0.0, 1.0], 0.0)
    assert under.any() and not under.all()
    with torch.inference_mode():
        np.testing.assert_allclose(table_net(torch.from_numpy(np.stack([occupancy, under], 1))).numpy(),
                                   plain(torch.from_numpy(occupancy)).numpy(), rtol=1e-5, atol=1e-6)

    grids = np.stack([occupancy, under], 1)
    np.testing.assert_array_equal(unpack(pack(grids), (2, 32, 32, 32)), grids)
    flipped = random_flips(grids, np.random.default_rng(1))
    for f, g in zip(flipped, grids, strict=True):  # both channels flipped alike
        assert any((f == v).all() for v in (g, g[:, ::-1], g[:, :, ::-1], g[:, ::-1, ::-1]))
    labels = np.arange(9) % 2
    model, _ = train_stability(pack(grids), labels, val_packed=pack(grids[:2]), val_labels=labels[:2],
                               config=StabilityConfig(epochs=1, width=8, table_channel=True), init=plain)
    assert model.table_channel
    path = tmp_path / "table.pt"
    save_model(model, path, card={"note": "test"})
    cnn = GraspStabilityPredictor.load(path)
    assert cnn.model.table_channel
    table = (np.array([0.0, 0.0, 1.0]), 0.0)
    assert cnn.voxelize(points, X_WG, table).shape == (9, 2, 32, 32, 32)
    with torch.inference_mode():
        expected = torch.sigmoid(model(torch.from_numpy(grids))).numpy()
    np.testing.assert_allclose(cnn(points, X_WG, table), expected, atol=1e-6)
    far_below = cnn(points, X_WG, (np.array([0.0, 0.0, 1.0]), 1.0))  # a table a metre down: none in view
    np.testing.assert_allclose(far_below, cnn(points, X_WG, None), atol=1e-6)
    with pytest.raises(ValueError, match="table channel"):
        train_stability(pack(occupancy), labels, val_packed=pack(occupancy[:2]), val_labels=labels[:2],
                        config=StabilityConfig(epochs=1, width=8), init=model)


def test_the_policy_feeds_a_table_network_the_table_its_perception_found(tmp_path):
    """The CNN policies hand a table network the cloud's table plane (the fitted one, else the level plane
    at `table_z`): its p_s are the network's on that table, and change with where the table is."""
    from drake_grasp.learning.cnn import GraspStabilityPredictor, save_model
    from drake_grasp.perception.cloud import ObjectCloud
    from drake_grasp.policy.config import SelectionConfig
    from drake_grasp.policy.scorers import stability_scorer
    from drake_grasp.robot.specs import ROBOTS

    torch.manual_seed(1)
    model = GraspCNN(width=8).with_channels(table_channel=True, hand_channel=False)
    with torch.no_grad():
        model.features[0].weight[:, 1].normal_(0.0, 0.5)  # a network that reads the table
    path = tmp_path / "table.pt"
    save_model(model, path, card={"note": "test"})
    scorer = stability_scorer(ROBOTS["panda"], SelectionConfig(cnn_weights=str(path), hold_weights=None,
                                                               staged=False))
    rng = np.random.default_rng(5)
    points = rng.uniform(-0.03, 0.03, (400, 3)) + [0.5, 0.0, 0.035]
    X_WG = sample_grasps(points, 12, (0, 80), rng)
    cnn = GraspStabilityPredictor.load(path)
    level = np.array([0.0, 0.0, 1.0])
    on_table = scorer(ObjectCloud(points, table_z=0.0), X_WG, np.random.default_rng(0)).p_s
    np.testing.assert_allclose(on_table, cnn(points, X_WG, (level, 0.0)), atol=1e-6)
    raised = scorer(ObjectCloud(points, table_z=0.02), X_WG, np.random.default_rng(0)).p_s
    np.testing.assert_allclose(raised, cnn(points, X_WG, (level, -0.02)), atol=1e-6)
    assert np.abs(raised - on_table).max() > 1e-3
    unseen = scorer(ObjectCloud(points), X_WG, np.random.default_rng(0)).p_s
    np.testing.assert_allclose(unseen, cnn(points, X_WG, None), atol=1e-6)


def test_bfloat16_gives_the_float32_network_s_p_s_to_a_few_thousandths_and_its_ranking():
    """The shipped CNN on 400 grasp trials of the validation objects: bfloat16 (after the first layer)
    moves p_s by under 0.01 and keeps the ten best; "auto" is one of the two; bad names are refused."""
    from drake_grasp.datasets.grasp_data import load_grasp_dataset
    from drake_grasp.learning.cnn import GraspStabilityPredictor, resolve_precision
    from drake_grasp.learning.stability_training import packed_voxels, unpack
    from drake_grasp.policy.config import SelectionConfig
    from drake_grasp.robot.paths import REPO_ROOT

    data = load_grasp_dataset(REPO_ROOT / "data/grasps/validation")
    exact = GraspStabilityPredictor.load()
    grids = unpack(packed_voxels(data, np.arange(400)), exact.model.input_shape)
    p_32 = exact.predict(grids)
    p_16 = GraspStabilityPredictor.load(precision="bfloat16").predict(grids)
    assert 0 < np.abs(p_16 - p_32).max() < 0.01  # another arithmetic, the same network
    assert set(np.argsort(p_16)[-10:]) == set(np.argsort(p_32)[-10:])
    assert resolve_precision("auto") in ("float32", "bfloat16")
    with pytest.raises(ValueError, match="precision must be one of"):
        GraspStabilityPredictor.load(precision="half")
    with pytest.raises(ValueError, match="cnn_precision must be one of"):
        SelectionConfig(cnn_precision="half")


def test_a_hand_channel_tells_one_network_which_hand_grasps(tmp_path):
    """A hand network starts as the one it extends (zero weights on the new channel), sees each hand's
    palm and closing space, trains on trials of two hands at once, is fed its robot's hand by the
    predictor, and goes with any hand where a Franka hand's network is refused for another hand."""
    from drake_grasp.learning.cnn import GraspStabilityPredictor, save_model
    from drake_grasp.learning.stability_training import StabilityConfig, pack, train_stability
    from drake_grasp.learning.voxels import hand_grid
    from drake_grasp.policy.config import SelectionConfig
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.robot.arms import get_robot
    from drake_grasp.robot.hand import ANY_HAND, default_hand, get_hand
    from drake_grasp.robot.parallel_jaw import random_hand, write_hand

    franka = default_hand()
    narrow = dataclasses.replace(random_hand(0, 0), stroke=0.04, open_position=0.02, name="narrow")
    other = get_hand(str(write_hand(narrow, tmp_path / "hands")))
    grids = {h.name: hand_grid(h) for h in (franka, other)}
    # At the grasp point the closing space is as wide as the stroke, along y (32 voxels span 10 cm).
    y_span = {name: int(np.any(g[:, :, 16], axis=0).sum()) for name, g in grids.items()}
    assert y_span["franka"] == 26 and y_span["narrow"] == 12
    assert grids["franka"][:, :, 25:].sum() == 0  # nothing past the fingertips

    rng = np.random.default_rng(2)
    torch.manual_seed(0)
    plain = GraspCNN(width=8).eval()
    hand_net = plain.with_channels(table_channel=False, hand_channel=True).eval()
    assert hand_net.input_shape == (2, 32, 32, 32)
    points = rng.uniform(-0.03, 0.03, (500, 3)) + [0.5, 0.0, 0.03]
    X_WG = sample_grasps(points, 8, (0, 80), rng)
    occupancy = voxelize(points, X_WG)
    with_franka = np.stack([occupancy, np.broadcast_to(grids["franka"], occupancy.shape)], 1)
    with torch.inference_mode():
        np.testing.assert_allclose(hand_net(torch.from_numpy(with_franka)).numpy(),
                                   plain(torch.from_numpy(occupancy)).numpy(), rtol=1e-5, atol=1e-6)

    # Trials of two hands in one training; the predictor feeds the hand it is given.
    both = np.concatenate([with_franka, np.stack([occupancy, np.broadcast_to(grids["narrow"],
                                                                             occupancy.shape)], 1)])
    labels = np.r_[np.ones(8), np.zeros(8)]
    model, _ = train_stability(pack(both), labels, val_packed=pack(both), val_labels=labels,
                               config=StabilityConfig(epochs=30, width=8, hand_channel=True, augment=False),
                               init=plain)
    path = tmp_path / "any_hand.pt"
    save_model(model, path, card={"hand": ANY_HAND})
    p_franka = GraspStabilityPredictor.load(path)(points, X_WG)  # (no hand given: the Franka hand's)
    p_narrow = GraspStabilityPredictor.load(path, hand=other)(points, X_WG)
    assert p_franka.mean() > 0.7 > 0.3 > p_narrow.mean()

    robot = get_robot("panda", str(tmp_path / "hands" / "narrow.yaml"))
    make_scorer("cnn", robot, SelectionConfig(cnn_weights=str(path), hold_weights=None))
    with pytest.raises(ValueError, match="made with the 'franka' hand"):
        make_scorer("cnn", robot, SelectionConfig(cnn_weights="models/grasp_cnn_household.pt",
                                                  hold_weights=None))
