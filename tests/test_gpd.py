"""GPD's grasp images and LeNet: what the images show, that it learns, the train command, the policy."""

import dataclasses
import json

import numpy as np
import pytest
from pydrake.math import RotationMatrix
from scenes import block_points, one_cube_yaml

from drake_grasp.apps.collect_grasps import main as collect_main
from drake_grasp.apps.train import main as train_main
from drake_grasp.cell.episode import run_episode
from drake_grasp.datasets.grasp_data import load_grasp_dataset
from drake_grasp.learning.voxels import voxelize
from drake_grasp.perception.cloud import ObjectCloud
from drake_grasp.policy.baselines.gpd import GpdClassifier, GpdLeNet, grasp_images, load_model
from drake_grasp.policy.baselines.gpd_training import train_gpd
from drake_grasp.policy.baselines.gpg import (
    GpgConfig,
    estimate_normals,
    generate_candidates,
)
from drake_grasp.policy.clearance import approach_blocked
from drake_grasp.policy.scorers import GpdScorer
from drake_grasp.policy.selector import rank_grasps
from drake_grasp.robot.hand import default_hand
from drake_grasp.robot.paths import REPO_ROOT
from drake_grasp.robot.specs import ROBOTS
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import load_scenario


def test_grasp_images_show_the_closing_region_from_three_sides():
    cloud = block_points()
    normals = estimate_normals(cloud, radius=0.01, camera_positions=[(0.55, 0.0, 1.3)])
    X_WG = generate_candidates(cloud, np.random.default_rng(0), GpgConfig(num_samples=10))
    far = X_WG[:1].copy()
    far[0, :3, 3] += [0.0, 0.0, 0.5]  # half a metre above the block: nothing between the fingers
    images = grasp_images(cloud, normals, np.concatenate([X_WG, far]))
    assert images.shape == (len(X_WG) + 1, 15, 60, 60) and images.dtype == np.float32
    occupancy = images[:-1, [0, 5, 10]]
    assert (occupancy.reshape(len(X_WG), 3, -1).max(axis=2) == 1).all()  # every view sees points
    assert set(np.unique(occupancy)) <= {0.0, 1.0}
    normal_channels = images[:, [1, 2, 3, 6, 7, 8, 11, 12, 13]]
    assert np.abs(normal_channels).max() <= 1.0 + 1e-6
    depth = images[:, [4, 9, 14]]
    assert depth.min() >= 0.0 and depth.max() < 1.0
    assert not images[-1].any()
    # The 3-channel image is the three views' depth channels.
    np.testing.assert_allclose(grasp_images(cloud, normals, X_WG, channels=3), depth[:-1])
    with pytest.raises(ValueError, match="15 or 3 channels"):
        grasp_images(cloud, normals, X_WG, channels=4)


def test_a_point_in_the_closing_region_lands_on_its_pixel_in_each_view_with_its_normal_and_depth():
    from drake_grasp.policy.baselines.gpd import VIEWS, closing_region

    region = closing_region(default_hand())

    X_WG = np.eye(4)
    X_WG[:3, :3] = RotationMatrix.MakeZRotation(0.3).matrix()
    X_WG[:3, 3] = [0.5, 0.1, 0.2]
    t = (np.array([[15, 36, 54], [42, 6, 24]]) + 0.5) / 60  # two points at pixel centres (region fractions)
    p_G = region[:, 0] + t * (region[:, 1] - region[:, 0])
    cloud = np.vstack([p_G @ X_WG[:3, :3].T + X_WG[:3, 3], [[3.0, 3.0, 3.0]]])  # (and one far away)
    n_G = np.array([[0.0, 0.6, 0.8], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    images = grasp_images(cloud, n_G @ X_WG[:3, :3].T, X_WG[None])[0]
    for v, (along, row, col) in enumerate(VIEWS):
        for point in range(2):
            i, j = (t[point, [row, col]] * 60).astype(int)
            np.testing.assert_allclose(images[5 * v:5 * v + 5, i, j], [1.0, *n_G[point], t[point, along]],
                                       atol=1e-6)
        assert images[5 * v].sum() == 2  # two pixels hit


@pytest.mark.slow
def test_lenet_learns_the_trials_of_a_few_scenes():
    data = load_grasp_dataset(REPO_ROOT / "data" / "grasps" / "primitives")
    few = data.subset(np.flatnonzero(data.trial_scene < 6))
    model, result = train_gpd(few, channels=3, epochs=4, seed=0)
    assert isinstance(model, GpdLeNet) and result["trials"]["fit"] > 0
    assert result["train_metrics"]["auroc"] > 0.75  # it fits what it saw


@pytest.mark.slow
def test_collect_gpg_trials_train_gpd_and_score_candidates(tmp_path, capsys):
    out = tmp_path / "gpg_trials"
    assert collect_main(["--sampler", "gpg", "--trials", "12", "--per-scene", "4", "--scenes-per-shard", "3",
                         "--workers", "1", "--seed", "3", "--out", str(out)]) == 0
    data = load_grasp_dataset(out)
    assert data.manifest["sampler"] == "gpg" and len(data) > 0
    weights = tmp_path / "gpd.pt"
    assert train_main(["gpd", "--data", str(out), "--out", str(weights), "--epochs", "1", "--channels", "3",
                       "--test-fraction", "0.3", "--heldout", str(out)]) == 0
    card = json.loads(weights.with_suffix(".json").read_text())
    assert card["heldout_metrics"]["n"] == card["heldout"]["trials"] == len(data)  # every trial measured
    assert card["data"]["collection"]["sampler"] == "gpg" and "test_metrics" in card
    assert "--sampler" not in capsys.readouterr().err  # no note: these are GPG trials
    gpd = GpdClassifier.load(weights)
    cloud = block_points()
    X_WG = generate_candidates(cloud, np.random.default_rng(0), GpgConfig(num_samples=5))
    scores = gpd(cloud, X_WG)
    assert scores.shape == (len(X_WG),) and ((scores >= 0) & (scores <= 1)).all()
    # As a policy: GPG's candidates ranked by the classifier, in the closed loop on one cube.
    scorer = GpdScorer(weights)
    ranked = rank_grasps(ObjectCloud(cloud), scorer, num_candidates=40, gamma_deg=(0.0, 60.0),
                         rng=np.random.default_rng(0))
    assert 0 < len(ranked) <= 40 and np.all(np.diff(ranked.scores) <= 0)
    assert (-ranked.X_WG[:, 2, 2] >= np.cos(np.radians(60.0)) - 1e-9).all()
    assert not approach_blocked(voxelize(cloud, ranked.X_WG)).any()
    # GPG keeps the hand above the table perception measured (without one: its default, z = 0).
    def tips_z(table_z: float | None) -> np.ndarray:
        X = rank_grasps(ObjectCloud(cloud, table_z), scorer, num_candidates=40, gamma_deg=(0.0, 60.0),
                        rng=np.random.default_rng(0)).X_WG
        return (X[:, :3, 3] + default_hand().tip_beyond_grasp * X[:, :3, 2])[:, 2]

    unaware, aware = tips_z(None), tips_z(0.02)  # a table 2 cm up the block's sides
    assert 0 < len(aware) < len(unaware) and aware.min() >= 0.02
    scenario_file = tmp_path / "one_cube.yaml"
    scenario_file.write_text(one_cube_yaml(max_attempts=1).replace("[0.0, 0.0]", "[0.0, 60.0]"))
    cube = [m for m in load_object_set("primitives") if m.name == "cube"]
    robot = ROBOTS["panda"]

    def run_on_cube():
        return run_episode(robot=robot, scenario=load_scenario(str(scenario_file)), scorer=scorer,
                           object_models=cube, seed=0)

    run = run_on_cube()
    assert run.attempts == 1 and run.attempt_log[0]["planned"]
    # When GPG finds no candidate on the cube, the run says so instead of "no objects".
    scorer.gpg = dataclasses.replace(scorer.gpg, min_points=100_000)
    run = run_on_cube()
    assert run.attempts == 0 and run.end_reason == "no grasp candidates"
    weights.write_bytes(b"not a model")
    with pytest.raises(ValueError, match="corrupt GPD classifier weights"):
        load_model(weights)
    with pytest.raises(ValueError, match="train gpd"):
        GpdScorer(tmp_path / "missing.pt")


def test_a_fused_clouds_side_faces_get_normals_facing_the_side_camera():
    cloud = block_points()
    side = np.isclose(cloud[:, 1], -0.06) & (cloud[:, 2] < 0.055)  # the face looking along -y
    top_camera, side_camera = (0.55, 0.0, 1.3), (0.5, -0.8, 0.6)
    both = estimate_normals(cloud, radius=0.01, camera_positions=[top_camera, side_camera])
    assert (both[side] @ [0.0, -1.0, 0.0] > 0.9).mean() > 0.9  # outward
    top_only = estimate_normals(cloud, radius=0.01, camera_positions=[top_camera])
    assert (top_only[side] @ [0.0, 1.0, 0.0] > 0.9).mean() > 0.9  # turned toward the one camera: inward


@pytest.mark.slow
def test_gpd_sees_the_scene_through_a_second_camera(tmp_path, capsys):
    from drake_grasp.apps.bench import settled_scene
    from drake_grasp.apps.detect import main as detect_main
    from drake_grasp.evaluation.config import EvaluationConfig
    from drake_grasp.perception.cloud import extract_object_cloud

    assert len(EvaluationConfig(policy="gpd").load_scenario().sensing.extra_cameras) == 1
    assert EvaluationConfig(policy="gpd1c").load_scenario().sensing.extra_cameras == []
    counts = []
    for policy in ("gpd1c", "gpd"):
        seen = EvaluationConfig(policy=policy).load_scenario()
        seen = seen.shrunk(objects_per_cluster=3)
        _, context, station, simulator, scenario = settled_scene("panda", "standard", 0, scenario=seen)
        simulator.AdvanceTo(scenario.settle_time)
        points = station.GetOutputPort("point_cloud_W").Eval(station.GetMyContextFromRoot(context)).xyzs().T
        box = scenario.sensing.workspace
        objects = extract_object_cloud(points, lower=box.lower, upper=box.upper)
        counts.append((len(points), len(objects)))
    (pixels_1, objects_1), (pixels_2, objects_2) = counts
    assert pixels_2 == 2 * pixels_1 and objects_2 > 1.5 * objects_1
    assert detect_main(["--depth", "x.png", "--camera", "x.yaml", "--policy", "gpd", "--out",
                        str(tmp_path / "g.json")]) == 2
    assert "fuses two cameras" in capsys.readouterr().err
    # Each policy scores with the classifier trained on what it sees: one camera's trials, or fused ones.
    from drake_grasp.policy.baselines.gpd import DEFAULT_WEIGHTS, TWO_CAMERA_WEIGHTS
    from drake_grasp.policy.scorers import make_scorer, policy_weights
    from drake_grasp.robot.specs import ROBOTS

    panda = ROBOTS["panda"]
    assert policy_weights("gpd", panda) == [TWO_CAMERA_WEIGHTS]
    assert policy_weights("gpd1c", panda) == [DEFAULT_WEIGHTS]
    two, one = make_scorer("gpd", panda), make_scorer("gpd1c", panda)
    assert len(two.gpg.camera_positions) == 2 and len(one.gpg.camera_positions) == 1
    first = [next(scorer.classifier.model.parameters()) for scorer in (two, one)]
    assert first[0].shape == first[1].shape and not bool((first[0] == first[1]).all())


@pytest.mark.slow
def test_a_mixed_job_records_each_trials_sampler_and_gpd_trains_on_its_own(tmp_path, capsys):
    from drake_grasp.robot.task import SAMPLERS

    out = tmp_path / "mixed"
    assert collect_main(["--sampler", "mixed", "--trials", "16", "--per-scene", "4",
                         "--scenes-per-shard", "2", "--workers", "1", "--seed", "3", "--out", str(out)]) == 0
    data = load_grasp_dataset(out)
    gpg, uniform = data.made_by("gpg"), data.made_by("uniform")
    assert len(gpg) and len(uniform) and len(gpg) + len(uniform) == len(data)
    assert data.statistics()["samplers"]["gpg"]["trials"] == len(gpg)
    assert train_main(["gpd", "--data", str(out), "--out", str(tmp_path / "gpd.pt"), "--epochs", "1",
                       "--channels", "3", "--test-fraction", "0.3"]) == 0
    assert f"training on the {len(gpg)} of {len(data)} trials" in capsys.readouterr().err
    card = json.loads((tmp_path / "gpd.json").read_text())
    assert card["data"]["statistics"]["trials"] == len(gpg)
    assert not (tmp_path / "gpd.checkpoint.pt").exists()  # gone once the weights are saved
    assert set(data.trial_sampler) <= {SAMPLERS.index("gpg"), SAMPLERS.index("uniform")}


@pytest.mark.slow
def test_trials_seen_by_two_cameras_record_them_and_gpd_is_measured_on_them(tmp_path, capsys):
    from drake_grasp.apps.evaluate import main as evaluate_main
    from drake_grasp.policy.baselines.gpd import DEFAULT_WEIGHTS
    from drake_grasp.policy.baselines.gpd_training import ImageSource
    from drake_grasp.policy.baselines.gpg import config_normals

    one, two = tmp_path / "one_camera", tmp_path / "two_cameras"
    job = ["--sampler", "gpg", "--trials", "8", "--per-scene", "4", "--scenes-per-shard", "2",
           "--workers", "1", "--seed", "3"]
    assert collect_main([*job, "--out", str(one)]) == 0
    assert collect_main([*job, "--second-camera", "--out", str(two)]) == 0
    assert collect_main([*job, "--second-camera", "--out", str(two)]) == 0  # the same job: resumed, done
    seen_once, seen_twice = load_grasp_dataset(one), load_grasp_dataset(two)
    assert seen_twice.manifest["second_camera"] is True and seen_once.manifest["second_camera"] is False
    scenes = sorted(seen_twice.clouds)
    assert scenes == sorted(seen_once.clouds) and len(seen_twice) > 0
    assert seen_once.camera_positions(scenes[0]) is None
    both = load_scenario("single").with_second_camera().sensing.camera_positions
    assert seen_twice.camera_positions(scenes[0]) == both and len(both) == 2
    # The same drops (a scene is a function of the seed and its id): the side camera adds their sides.
    assert sum(map(len, seen_twice.clouds.values())) > 1.2 * sum(map(len, seen_once.clouds.values()))
    # GPD's images of the fused cloud turn the normals of what only the side camera sees outward.
    fused = seen_twice.clouds[scenes[0]]
    facing_both = ImageSource(seen_twice, 15).normals(scenes[0])
    facing_top = config_normals(fused, GpgConfig())
    assert (np.sum(facing_both * facing_top, axis=1) < 0).any()

    report = tmp_path / "gpd_metrics.json"
    assert evaluate_main(["gpd", "--weights", str(DEFAULT_WEIGHTS), "--data", str(one), str(two),
                          "--threads", "1", "--json", str(report)]) == 0
    printed = capsys.readouterr().out
    assert "AUROC" in printed and "best of each scene" in printed and "outcomes: " in printed
    per_folder = json.loads(report.read_text())["per_folder"]
    assert per_folder[str(one)]["n"] == len(seen_once) and per_folder[str(two)]["n"] == len(seen_twice)
    assert evaluate_main(["gpd", "--weights", str(tmp_path / "missing.pt"), "--data", str(one)]) == 2
    assert "not found" in capsys.readouterr().err
