import numpy as np
import pytest
from pydrake.geometry import StartMeshcat

from drake_grasp.perception.cloud import ObjectCloud
from drake_grasp.policy.config import SelectionConfig
from drake_grasp.policy.drawing import draw_candidates, hand_outline
from drake_grasp.policy.scorers import make_scorer
from drake_grasp.policy.selector import GraspSelector, rank_grasps
from drake_grasp.robot.specs import ROBOTS


def cloud(n=200, seed=0) -> ObjectCloud:
    rng = np.random.default_rng(seed)
    points = rng.uniform([0.45, -0.05, 0.0], [0.55, 0.05, 0.05], (n, 3))
    return ObjectCloud(points)


def test_ranking_orders_candidates_by_a_pluggable_scorer():
    def prefer_top_grasps(c, X_WG, rng):
        return -X_WG[:, 2, 2]  # +z_G straight down scores 1

    ranked = rank_grasps(cloud(), prefer_top_grasps, num_candidates=300, gamma_deg=(0, 90),
                         rng=np.random.default_rng(1))
    assert len(ranked.X_WG) == 300 and ranked.num_object_points == 200
    assert np.all(np.diff(ranked.scores) <= 0)
    np.testing.assert_allclose(ranked.scores, -ranked.X_WG[:, 2, 2])
    assert ranked.scores[0] > 0.99
    assert np.isnan(ranked.p_r).all() and np.isnan(ranked.p_s).all()  # this scorer predicts neither


def test_rand_policy_is_seeded_and_empty_clouds_give_no_grasps():
    scorer = make_scorer("rand", ROBOTS["panda"])
    a = rank_grasps(cloud(), scorer, num_candidates=50, gamma_deg=(0, 90), rng=np.random.default_rng(4))
    b = rank_grasps(cloud(), scorer, num_candidates=50, gamma_deg=(0, 90), rng=np.random.default_rng(4))
    np.testing.assert_array_equal(a.X_WG, b.X_WG)
    empty = ObjectCloud.empty()
    assert len(rank_grasps(empty, scorer, num_candidates=50, gamma_deg=(0, 90),
                           rng=np.random.default_rng(0)).X_WG) == 0
    with pytest.raises(ValueError, match="unknown policy 'best'"):
        make_scorer("best", ROBOTS["panda"])


def test_grasp_selector_system_outputs_ranked_grasps():
    def prefer_low_grasp_points(c, X_WG, rng):
        return -X_WG[:, 2, 3]

    selector = GraspSelector(prefer_low_grasp_points, num_candidates=20, gamma_deg=(10, 20))
    context = selector.CreateDefaultContext()
    selector.GetInputPort("object_cloud").FixValue(context, cloud())
    ranked = selector.GetOutputPort("ranked_grasps").Eval(context)
    angles = np.degrees(np.arccos(-ranked.X_WG[:, 2, 2]))
    assert len(ranked.X_WG) == 20 and angles.min() >= 10 - 1e-6 and angles.max() <= 20 + 1e-6
    assert np.all(np.diff(ranked.X_WG[:, 2, 3]) >= 0)  # best first: the lowest grasp point leads


def test_hand_outline_spans_the_open_jaws_at_the_grasp():
    X_WG = np.eye(4)
    X_WG[:3, 3] = [0.5, 0.0, 0.1]
    start, end = hand_outline(X_WG)
    tips = start[:, :2].T
    np.testing.assert_allclose(np.abs(tips[:, 1]), 0.04)  # 80 mm apart
    np.testing.assert_allclose(tips[:, 2], 0.1 + 0.02)  # 20 mm past the grasp point


def test_meshcat_shows_candidates_and_the_chosen_grasp():
    meshcat = StartMeshcat()
    ranked = rank_grasps(cloud(), make_scorer("rand", ROBOTS["panda"]), num_candidates=30,
                         gamma_deg=(0, 90), rng=np.random.default_rng(0))
    draw_candidates(meshcat, ranked, planned=True)
    for path in ("grasps/candidates", "grasps/chosen"):
        assert meshcat.HasPath(path)
    meshcat.Delete("grasps")
    assert not meshcat.HasPath("grasps/chosen")


def test_rp_policy_ranks_reachable_grasps_first():
    """The shipped Panda RP puts a top grasp in front of the arm ahead of one beyond its reach."""
    scorer = make_scorer("rp", ROBOTS["panda"])
    X_WG = np.tile(np.diag([1.0, -1.0, -1.0, 1.0]), (2, 1, 1))  # straight down
    X_WG[0, :3, 3] = [0.5, 0.0, 0.05]
    X_WG[1, :3, 3] = [1.2, 0.0, 0.05]
    scored = scorer(cloud(), X_WG, np.random.default_rng(0))
    assert scored.score[0] > 0.9 and scored.score[1] < 0.1
    np.testing.assert_allclose(scored.score, scored.p_r, atol=1e-5)
    assert scored.p_s is None


def test_cnn_policies_score_with_the_shipped_cnn_hold_predictor_and_rp():
    """By default CNN ranks by p_s * p_h (models/grasp_cnn_all.pt, models/grasp_hold.pt), CNN_RP by
    p_r * p_s * p_h; with the paper's CNN (the 8 blocks) and no hold predictor, by the paper's p_r * p_s."""
    from drake_grasp import GraspStabilityPredictor, ReachabilityPredictor
    from drake_grasp.learning.cnn import PAPER_WEIGHTS
    from drake_grasp.learning.hold import DEFAULT_WEIGHTS as HOLD_WEIGHTS
    from drake_grasp.learning.hold import HoldPredictor
    from drake_grasp.policy.sampling import sample_grasps

    c = cloud(n=2000)
    X_WG = sample_grasps(c.points, 60, (0, 90), np.random.default_rng(2))
    p_s = GraspStabilityPredictor.load()(c.points, X_WG)
    p_h = HoldPredictor.load(HOLD_WEIGHTS)(c.points, X_WG)
    p_r = ReachabilityPredictor.load("panda")(X_WG)
    assert np.ptp(p_s) > 0.1  # the trained CNN tells these grasps apart
    rng = np.random.default_rng(0)
    every = SelectionConfig(staged=False)  # the CNN on every candidate
    np.testing.assert_allclose(make_scorer("cnn", ROBOTS["panda"], every)(c, X_WG, rng).score, p_s * p_h,
                               atol=1e-5)
    default = make_scorer("cnn_rp", ROBOTS["panda"], every)(c, X_WG, rng)
    np.testing.assert_allclose(default.score, p_r * p_s * p_h, atol=1e-5)
    np.testing.assert_allclose(default.p_r, p_r, atol=1e-6)
    np.testing.assert_allclose(default.p_s, p_s, atol=1e-6)
    paper_models = SelectionConfig(staged=False, cnn_weights="models/grasp_cnn.pt", hold_weights=None)
    paper = make_scorer("cnn_rp", ROBOTS["panda"], paper_models)(c, X_WG, rng)
    p_s_paper = GraspStabilityPredictor.load(PAPER_WEIGHTS)(c.points, X_WG)
    np.testing.assert_allclose(paper.score, p_r * p_s_paper, atol=1e-5)
    assert paper.p_h is None


def test_the_sampling_chooses_the_sampler_gpg_candidates_clear_the_cloud():
    from scenes import block_points

    from drake_grasp.learning.voxels import voxelize
    from drake_grasp.perception.config import SamplingConfig
    from drake_grasp.policy.clearance import approach_blocked

    block = ObjectCloud(block_points(), table_z=0.0)
    camera = [(0.5, 0.0, 0.9)]
    gpg = rank_grasps(block, make_scorer("rand", ROBOTS["panda"]), num_candidates=60, gamma_deg=(0, 90),
                      rng=np.random.default_rng(0), sampler="gpg", camera_positions=camera)
    uniform = rank_grasps(block, make_scorer("rand", ROBOTS["panda"]), num_candidates=60, gamma_deg=(0, 90),
                          rng=np.random.default_rng(0))
    assert 0 < len(gpg) <= 60 and len(uniform) == 60
    # GPG's hands are placed clear of the cloud; most of the paper's uniform candidates are not.
    assert not approach_blocked(voxelize(block.points, gpg.X_WG)).any()
    assert approach_blocked(voxelize(block.points, uniform.X_WG)).mean() > 0.3
    selector = GraspSelector(make_scorer("rand", ROBOTS["panda"]), num_candidates=60, sampler="gpg",
                             camera_positions=camera)
    context = selector.CreateDefaultContext()
    selector.GetInputPort("object_cloud").FixValue(context, block)
    assert not approach_blocked(voxelize(block.points, selector.GetOutputPort("ranked_grasps").Eval(
        context).X_WG)).any()
    with pytest.raises(ValueError, match="unknown sampler 'best'"):
        SamplingConfig(sampler="best")
