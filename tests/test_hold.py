"""The hold predictor: the lever of an object's weight about the jaws, learned from trials that lifted."""

import json

import numpy as np
import pytest

from drake_grasp.apps.evaluate import main as evaluate
from drake_grasp.apps.train import main as train
from drake_grasp.learning.hold import (
    HoldPredictor,
    fit_hold,
    lever_and_size,
    predict_hold,
    save_hold,
)
from drake_grasp.learning.model_cards import CHECKPOINT_SUFFIX
from drake_grasp.learning.voxels import voxelize
from drake_grasp.perception.cloud import ObjectCloud, join_end_to_end, segment_objects
from drake_grasp.policy.clearance import approach_blocked
from drake_grasp.policy.sampling import sample_grasps
from drake_grasp.policy.scorers import SelectionConfig, make_scorer
from drake_grasp.policy.selector import rank_grasps
from drake_grasp.robot.hand import default_hand, hand_record
from drake_grasp.robot.paths import REPO_ROOT
from drake_grasp.robot.specs import ROBOTS


def box_top(lo, hi, spacing=0.0025) -> np.ndarray:
    """Points 2.5 mm apart on the top face of the box [lo, hi], as a camera above sees it."""
    xs, ys = np.arange(lo[0], hi[0], spacing), np.arange(lo[1], hi[1], spacing)
    x, y = np.meshgrid(xs, ys)
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, hi[2])])


def bar_and_cube() -> np.ndarray:
    """A 24 cm bar along x at (0.5, 0) and, 10 cm away, a 4 cm cube."""
    return np.vstack([box_top([0.38, -0.02, 0.0], [0.62, 0.02, 0.04]),
                      box_top([0.48, 0.10, 0.0], [0.52, 0.14, 0.04])])


def top_grasp(x: float, y: float, closing: str) -> np.ndarray:
    """A grasp straight down at (x, y) on the 4 cm top, the jaws closing along world `closing` (x or y)."""
    X = np.eye(4)
    X[:3, :3] = np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]]) if closing == "y" else \
        np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1]])
    X[:3, 3] = [x, y, 0.04]
    return X


def test_the_lever_is_the_objects_centroid_off_the_closing_axis_and_objects_are_told_apart():
    points = bar_and_cube()
    labels = segment_objects(points)
    assert len(set(labels) - {-1}) == 2
    X_WG = np.stack([top_grasp(0.60, 0.0, "y"),   # the bar's end, jaws across it: its weight pivots it
                     top_grasp(0.60, 0.0, "x"),   # the same point, jaws along the bar: no pivot
                     top_grasp(0.50, 0.0, "y"),   # the bar's middle
                     top_grasp(0.50, 0.12, "y")])  # the cube
    lever, size = lever_and_size(points, X_WG, labels).T
    assert lever[0] == pytest.approx(0.10, abs=0.003) and lever[1] == pytest.approx(0.0, abs=0.003)
    assert lever[2] == pytest.approx(0.0, abs=0.003) and lever[3] == pytest.approx(0.0, abs=0.003)
    assert size[0] == pytest.approx(np.hypot(0.24, 0.04), abs=0.005) and size[3] < 0.06
    with pytest.raises(ValueError, match="non-empty"):
        lever_and_size(np.zeros((0, 3)), X_WG)
    # A grasp point 5 cm above a lone noise reading (nothing within 3 cm) leans on that reading alone.
    lone = np.vstack([points, [0.9, 0.3, 0.02]])
    X_above = top_grasp(0.92, 0.3, "y")
    X_above[2, 3] = 0.07
    lone_labels = segment_objects(lone)
    assert lone_labels[-1] == -1
    lever, size = lever_and_size(lone, X_above[None], lone_labels).T
    assert lever[0] == pytest.approx(0.02, abs=1e-9) and size[0] == 0.0


def test_joining_end_to_end_takes_a_lying_bottles_neck_into_its_body_and_leaves_neighbours_apart():
    """The same lying bottle: its neck continues the body along its axis, narrower and lower, so
    `join_end_to_end` joins them and the neck grasp gets the whole bottle's lever. A lower object 5 mm
    beside the body, a taller one on its axis, and a neck 4 cm past its end stay apart."""
    body = box_top([0.40, -0.03, 0.0], [0.52, 0.03, 0.06])
    neck = box_top([0.521, -0.01, 0.0], [0.57, 0.01, 0.04])
    points = np.vstack([body, neck])
    labels = join_end_to_end(points, segment_objects(points))
    assert len(set(labels) - {-1}) == 1
    X_neck = top_grasp(0.547, 0.0, "y")[None]
    joined = HoldPredictor.load(join_parts=True)
    lever, _ = lever_and_size(points, X_neck, labels)[0]
    assert lever == pytest.approx(0.547 - points[:, 0].mean(), abs=0.002)
    plain = HoldPredictor.load()(points, X_neck)[0]
    assert joined(points, X_neck)[0] < plain - 0.1

    def p_h(selection):
        return make_scorer("cnn", ROBOTS["panda"], selection)(
            ObjectCloud(points), X_neck, np.random.default_rng(0)).p_h[0]

    assert p_h(SelectionConfig()) == pytest.approx(joined(points, X_neck)[0])  # the default joins
    assert p_h(SelectionConfig(hold_join_parts=False)) == pytest.approx(plain)

    def apart(other):
        cloud = np.vstack([body, other])
        plain = segment_objects(cloud)
        assert len(set(plain) - {-1}) == 2
        assert np.array_equal(join_end_to_end(cloud, plain), plain)

    apart(box_top([0.44, 0.033, 0.0], [0.48, 0.05, 0.04]))  # lower, 3 mm beside the body
    apart(box_top([0.521, -0.01, 0.0], [0.57, 0.01, 0.08]))  # taller: not a neck
    apart(box_top([0.56, -0.01, 0.0], [0.60, 0.01, 0.04]))  # on the axis, 4 cm past the end


def synthetic_trials(n=4000, seed=0):
    """Lever and size of `n` lifted grasps, slipping the more often the more the weight's lever."""
    rng = np.random.default_rng(seed)
    lever_size = np.column_stack([rng.uniform(0, 0.12, n), rng.uniform(0.04, 0.3, n)])
    p_slip = 1 / (1 + np.exp(-(-6 + 80 * lever_size[:, 0])))
    return lever_size, rng.uniform(size=n) >= p_slip


def test_a_fitted_hold_predictor_recovers_the_slip_rate_and_loads_back(tmp_path):
    lever_size, held = synthetic_trials()
    model = fit_hold(lever_size, held)
    probe = np.array([[0.0, 0.2], [0.075, 0.2], [0.12, 0.2]])
    p_h = predict_hold(model, probe)
    truth = 1 - 1 / (1 + np.exp(-(-6 + 80 * probe[:, 0])))
    np.testing.assert_allclose(p_h, truth, atol=0.08)
    assert p_h[0] > p_h[1] > p_h[2]
    save_hold(model, tmp_path / "hold.pt", card={})
    np.testing.assert_allclose(HoldPredictor.load(tmp_path / "hold.pt").model.weight.detach(),
                               model.weight.detach())
    (tmp_path / "bad.pt").write_bytes(b"not a model")
    with pytest.raises(ValueError, match="corrupt hold predictor"):
        HoldPredictor.load(tmp_path / "bad.pt")
    with pytest.raises(ValueError, match="both held and slipped"):
        fit_hold(lever_size[:3], np.ones(3, bool))


@pytest.mark.slow
def test_train_hold_fits_the_lifted_trials_and_writes_a_card(tmp_path, capsys):
    data = REPO_ROOT / "data" / "grasps"
    out = tmp_path / "hold.pt"
    assert train(["hold", "--data", str(data / "validation"), "--validation", str(data / "novel"),
                  "--out", str(out)]) == 0
    card = json.loads(out.with_suffix(".json").read_text())
    lifted = card["train_metrics"]["n"]
    assert 100 < lifted < 2000  # of the 2,000 trials, those that lifted their object
    assert card["coefficients"]["lever"] != 0 and card["validation_slip_by_lever"]
    assert card["data"]["read"] == {str(data / "validation"): {"shards": "0-24", "trials": 2000}}
    assert HoldPredictor.load(out)(bar_and_cube(), top_grasp(0.5, 0.0, "y")[None]).shape == (1,)
    empty = ["hold", "--data", str(tmp_path), "--validation", str(data / "novel"), "--out", str(out)]
    assert train(empty) == 2  # not a collect_grasps folder
    # evaluate cnn ranks by p_s and by p_s * p_h.
    metrics = tmp_path / "eval.json"
    assert evaluate(["cnn", "--data", str(data / "novel"), "--hold-weights", str(out),
                     "--json", str(metrics)]) == 0
    evaluated = json.loads(metrics.read_text())
    with_hold = evaluated["with_hold"]["all"]
    assert with_hold["n"] == evaluated["all"]["n"] and with_hold["auroc"] != evaluated["all"]["auroc"]
    assert 0 < with_hold["top10_success"] <= 1


def test_with_a_hold_predictor_cnn_rp_ranks_by_p_r_p_s_p_h_and_staged_selection_stays_exact(tmp_path):
    save_hold(fit_hold(*synthetic_trials()), tmp_path / "hold.pt", card={"hand": hand_record(default_hand())})
    robot, cloud = ROBOTS["panda"], ObjectCloud(bar_and_cube(), 0.0)
    hold = SelectionConfig(staged=False, hold_weights=str(tmp_path / "hold.pt"))
    X_WG = sample_grasps(cloud.points, 300, (0, 60), np.random.default_rng(0), table_z=0.0)
    scores = make_scorer("cnn_rp", robot, hold)(cloud, X_WG, np.random.default_rng(0))
    np.testing.assert_allclose(scores.score, scores.p_r * scores.p_s * scores.p_h, atol=1e-4)
    far = lever_and_size(cloud.points, X_WG)[:, 0] > 0.07
    assert far.any() and scores.p_h[far].max() < scores.p_h[~far].min() + 1e-9
    full = rank_grasps(cloud, make_scorer("cnn_rp", robot, hold), num_candidates=300, gamma_deg=(0, 60),
                       rng=np.random.default_rng(1))
    staged = rank_grasps(cloud, make_scorer("cnn_rp", robot, SelectionConfig(
        staged=True, hold_weights=hold.hold_weights)), num_candidates=300, gamma_deg=(0, 60),
        rng=np.random.default_rng(1))
    assert np.isfinite(staged.p_s).sum() < len(staged)
    blocked = approach_blocked(voxelize(cloud.points, full.X_WG))
    np.testing.assert_array_equal(staged.X_WG[:10], full.X_WG[~blocked][:10])
    with pytest.raises(ValueError, match="not found"):
        make_scorer("cnn_rp", robot, SelectionConfig(hold_weights=str(tmp_path / "missing.pt")))


def test_every_shipped_model_has_a_card_naming_its_data_command_and_seed():
    shipped = sorted(p for p in (REPO_ROOT / "models").glob("*.pt")
                     if not p.name.endswith(CHECKPOINT_SUFFIX))  # (a training in progress)
    assert any(p.stem == "grasp_hold" for p in shipped)
    for weights in shipped:
        card = json.loads(weights.with_suffix(".json").read_text())
        assert card["command"].startswith("python -m drake_grasp train ") and card["data"], weights.name
        assert "seed" in card and any(k.endswith("_metrics") for k in card), weights.name
    hold = HoldPredictor.load(REPO_ROOT / "models" / "grasp_hold.pt")
    p_h = hold(bar_and_cube(), np.stack([top_grasp(0.50, 0.0, "y"), top_grasp(0.60, 0.0, "y")]))
    assert p_h[0] > 0.9 > p_h[1]  # the bar's middle holds; taken at its end, 10 cm off, it often pivots
