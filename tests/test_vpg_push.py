"""VPG with pushing: the push primitive, its Q maps, the executive's pushes, the ledger and the training."""

import json

import numpy as np
import pytest
import torch
from scenes import block_points, one_cube_yaml

from drake_grasp.cell.episode import EpisodeLedger
from drake_grasp.cell.executive import Attempt
from drake_grasp.evaluation.vpg_push_training import transitions
from drake_grasp.policy.baselines.vpg import HeightmapConfig, covering, grasp_cell, grasp_pose, heightmap
from drake_grasp.policy.baselines.vpg_push import (
    PUSH_DIRECTIONS,
    PUSH_REACH,
    VpgPushGraspNet,
    best_actions,
    common_square,
    push_cell,
    push_direction,
    push_pose,
    scene_changed,
)
from drake_grasp.policy.scorers import VpgObservation
from drake_grasp.robot.hand import default_hand

CONFIG = HeightmapConfig()


def cell_of(x: float, y: float) -> tuple[int, int]:
    lo = np.asarray(CONFIG.centre) - CONFIG.size / 2
    return int((x - lo[0]) / CONFIG.resolution), int((y - lo[1]) / CONFIG.resolution)


def test_a_push_starts_above_what_stands_there_and_travels_along_x_G():
    heights = heightmap(block_points(n=20000), CONFIG)  # the block spans x 0.475-0.525, 6 cm tall
    free, on_block, beside = cell_of(0.44, 0.0), cell_of(0.50, 0.0), cell_of(0.470, 0.0)
    for k in range(PUSH_DIRECTIONS):
        X = push_pose(*free, k, heights, CONFIG)
        assert push_cell(X, CONFIG) == (*free, k)
        np.testing.assert_allclose(X[:3, 0], push_direction(k), atol=1e-12)
        np.testing.assert_allclose(X[:3, 2], [0.0, 0.0, -1.0])
        np.testing.assert_allclose(X[:3, :3].T @ X[:3, :3], np.eye(3), atol=1e-12)
    tip = lambda cell: push_pose(*cell, 0, heights, CONFIG)[2, 3] - default_hand().tip_beyond_grasp  # noqa: E731
    assert tip(free) == pytest.approx(CONFIG.tip_clearance)
    assert tip(on_block) == pytest.approx(0.06, abs=1e-3)
    assert tip(beside) == pytest.approx(0.06, abs=1e-3)  # 5 mm from the block: within a finger's width
    np.testing.assert_allclose(push_direction(4), [0.0, 1.0, 0.0], atol=1e-12)  # a quarter turn


def test_a_moved_block_changes_the_scene_a_redrawn_one_does_not():
    before = heightmap(block_points(), CONFIG)
    assert not scene_changed(before, heightmap(block_points(seed=1), CONFIG))  # the same block, other points
    assert scene_changed(before, heightmap(block_points() + [0.03, 0.0, 0.0], CONFIG))
    # A map grown about the same centre holds the first one at its centre.
    far = np.vstack([block_points(), block_points() + [0.0, 0.3, 0.0]])
    grown = covering(far, CONFIG)
    assert grown.cells > CONFIG.cells
    np.testing.assert_array_equal(common_square(heightmap(far, grown), CONFIG.cells)[:, :150],
                                  heightmap(far, CONFIG)[:, :150])


def test_executed_q_reads_the_full_maps_at_the_executed_actions():
    torch.manual_seed(0)
    net = VpgPushGraspNet().eval()
    heights = heightmap(block_points(), CONFIG)
    q_push, q_grasp = net.q_maps(heights)
    assert q_push.shape == q_grasp.shape == (16, CONFIG.cells, CONFIG.cells)
    assert (q_push >= 0).all() and (q_push <= 2).all()
    cells = torch.tensor([[100, 112, 3], [120, 90, 12], [112, 112, 0], [90, 130, 7]])
    push = torch.tensor([True, True, False, False])
    with torch.no_grad():
        q = net.executed_q(torch.from_numpy(heights)[None].expand(4, -1, -1), cells, push)
    expected = [(q_push if p else q_grasp)[k, i, j] for (i, j, k), p in zip(cells.tolist(), push.tolist(),
                                                                             strict=True)]
    np.testing.assert_allclose(q.numpy(), expected, atol=1e-4)


def test_pushes_start_near_objects_and_grasps_stand_on_them():
    heights = heightmap(block_points(), CONFIG)
    rng = np.random.default_rng(0)
    q_push, q_grasp = rng.uniform(size=(2, 16, CONFIG.cells, CONFIG.cells))
    X_WG, push, q = best_actions(heights, q_push, q_grasp, 10, CONFIG, spacing=5)
    assert push.sum() == 10 and (~push).sum() == 10 and len(q) == 20
    block = np.array([0.5, 0.0])
    for X, p, value in zip(X_WG, push, q, strict=True):
        gap = np.maximum(np.abs(X[:2, 3] - block) - [0.025, 0.06], 0.0)  # to the block's footprint
        if p:  # within reach of the block along each axis, at the best direction of its cell
            assert gap.max() <= PUSH_REACH + 0.003
            i, j, k = push_cell(X, CONFIG)
            assert value == pytest.approx(q_push[k, i, j]) and q_push[k, i, j] == q_push[:, i, j].max()
        else:
            assert np.linalg.norm(gap) <= 0.003
            i, j, k = grasp_cell(X, CONFIG)
            assert value == pytest.approx(q_grasp[k, i, j])


def attempt(*, push: bool, success: bool, planned: bool = True) -> Attempt:
    failure = None if success else ("pushed nothing" if push else "not lifted")
    return Attempt(planned=planned, success=success, failure=failure, plan_seconds=0.1, score=1.0,
                   approach_angle_deg=0.0, grasp_point=[0.5, 0.0, 0.05], object_index=0, push=push)


def test_the_ledger_counts_pushes_apart_from_grasp_attempts():
    ledger = EpisodeLedger(seed=0, object_names=["a", "b"], max_consecutive_failures=3, max_attempts=5)
    entry = ledger.record(attempt(push=True, success=True), 1.0)
    assert entry["push"] is True and ledger.result.attempts == 0 and ledger.result.pushes_moved == 1
    assert "push" not in ledger.record(attempt(push=False, success=False), 2.0)
    ledger.record(attempt(push=True, success=False), 3.0)  # moved nothing: a failure in a row
    assert ledger.consecutive_failures == 2 and ledger.end_reason() is None
    ledger.record(attempt(push=False, success=True), 4.0)
    r = ledger.result
    assert (r.attempts, r.successes, r.pushes, r.pushes_moved, r.grasp_success_rate) == (2, 1, 2, 1, 0.5)
    ledger.record(attempt(push=True, success=True), 5.0)
    assert ledger.end_reason() == "2 attempts and 3 pushes (the scenario's limit)"


def test_transitions_reward_a_push_that_changed_the_heightmap_and_label_by_the_next_value():
    before, after = block_points(), block_points() + [0.03, 0.0, 0.0]
    X_push = push_pose(*cell_of(0.44, 0.0), 0, heightmap(before, CONFIG), CONFIG)
    X_grasp = grasp_pose(*cell_of(0.53, 0.0), 0, heightmap(after, CONFIG), CONFIG)
    first = VpgObservation(CONFIG, heightmap(before, CONFIG), np.stack([X_grasp, X_push]),
                           np.array([False, True]), best_q=0.8)
    grown = covering(np.vstack([after, after + [0.0, 0.3, 0.0]]), CONFIG)  # the next map is larger
    second = VpgObservation(grown, heightmap(after, grown), X_grasp[None], np.array([False]), best_q=1.2)
    entries = [{"grasp_point": np.round(X_push[:3, 3], 4).tolist(), "push": True, "success": True},
               {"grasp_point": np.round(X_grasp[:3, 3], 4).tolist(), "success": True}]
    out = transitions([first, second], entries)
    assert out["heights"].shape == (2, grown.cells, grown.cells)
    np.testing.assert_allclose(out["reward"], [0.5, 1.0])
    np.testing.assert_allclose(out["label"], [0.5 + 0.5 * 1.2, 1.0])  # the last action has no next state
    pad = (grown.cells - CONFIG.cells) // 2
    assert out["actions"][0].tolist() == [1, cell_of(0.44, 0.0)[0] + pad, cell_of(0.44, 0.0)[1] + pad, 0]
    assert out["actions"][1, 0] == 0
    with pytest.raises(ValueError, match="matches no candidate"):
        transitions([first], [{"grasp_point": [0.1, 0.1, 0.1], "success": False}])


def test_the_planner_plans_a_push_along_the_table_and_refuses_one_into_it():
    from drake_grasp.planning.planner import PUSH_RISE, GraspPlanner
    from drake_grasp.robot.specs import ROBOTS

    planner = GraspPlanner(ROBOTS["panda"], seed=0)
    X = push_pose(*cell_of(0.42, 0.05), 0, np.zeros((CONFIG.cells, CONFIG.cells)), CONFIG)
    result = planner.plan_push(X, 0.1 * X[:3, 0])
    assert result.success
    plan = result.plan
    end = planner.tcp_pose(plan.lift.value(plan.lift.end_time()).ravel()).translation()
    start = planner.tcp_pose(plan.q_grasp).translation()
    np.testing.assert_allclose(end - start, [0.1, 0.0, PUSH_RISE], atol=2e-3)
    down = planner.plan_push(X, [0.0, 0.0, -0.05])  # the fingertips 5 mm over the table, pushed into it
    assert not down.success


@pytest.mark.slow
def test_a_push_beside_a_cube_moves_it_and_vpg_push_trains_and_resumes(tmp_path):
    from drake_grasp.apps.train import main as train_main
    from drake_grasp.cell.episode import run_episode
    from drake_grasp.policy.baselines.vpg_push import load_model
    from drake_grasp.policy.scorers import GraspScores, VpgPushScorer
    from drake_grasp.robot.specs import ROBOTS
    from drake_grasp.simulation.objects import load_object_set
    from drake_grasp.simulation.scenario import load_scenario

    scenario = tmp_path / "one_cube.yaml"
    scenario.write_text(one_cube_yaml(max_attempts=1))
    cube = [m for m in load_object_set("primitives") if m.name == "cube"]

    class PushTheCube:  # one push from 8 cm in front of the cube at (0.5, 0.05), towards +x
        def candidates(self, points_W, count, gamma_deg, rng, table_z=None):
            return push_pose(*cell_of(0.42, 0.05), 0, heightmap(points_W, CONFIG), CONFIG)[None]

        def __call__(self, cloud, X_WG, rng):
            return GraspScores(np.ones(1), push=np.ones(1, bool))

    run = run_episode(robot=ROBOTS["panda"], scenario=load_scenario(str(scenario)), scorer=PushTheCube(),
                      object_models=cube, seed=0)
    assert (run.attempts, run.pushes, run.pushes_planned, run.pushes_moved) == (0, 1, 1, 1)
    assert run.attempt_log[0]["push"] and run.attempt_log[0]["success"]
    assert run.objects_left[0]["p_WO"][0] > 0.52  # pushed along +x from 0.5

    data, weights = tmp_path / "training", tmp_path / "vpg_push.pt"
    command = ["vpg-push", "--data", str(data), "--out", str(weights), "--rounds", "1", "--scenario",
               str(scenario), "--objects", "primitives", "--episodes-per-round", "1", "--max-actions", "2",
               "--steps-per-round", "2", "--workers", "1"]
    assert train_main(command) == 0
    card = json.loads(weights.with_suffix(".json").read_text())
    assert card["rounds"] == 1 and card["data"]["actions"] == card["history"][0]["actions"] >= 1
    assert weights.with_suffix(".png").exists() and (data / "episodes" / "shard_00000.npz").exists()
    first = load_model(weights)[0].state_dict()
    written = {f: f.stat().st_mtime_ns for f in data.rglob("*") if f.is_file()}
    assert train_main(command) == 0  # resumed: nothing played or learnt again, the same nets
    assert {f: f.stat().st_mtime_ns for f in written} == written
    assert all(torch.equal(first[k], v) for k, v in load_model(weights)[0].state_dict().items())
    assert train_main([*command[:-4], "--steps-per-round", "3"]) == 2  # other settings: refused
    scorer = VpgPushScorer(weights)
    X_WG = scorer.candidates(block_points(), 5, (0.0, 0.0), np.random.default_rng(0), table_z=0.0)
    assert len(X_WG) == 10


def test_the_push_q_turns_with_the_scene_as_the_push_directions_do():
    """A scene turned a quarter turn about the map's centre turns every push Q map with it and moves it
    to the direction a quarter turn on (`push_direction(k + 4)` is `push_direction(k)` turned): the net's
    directions and the push poses' agree."""
    torch.manual_seed(0)
    net = VpgPushGraspNet(8).eval()
    points = block_points(n=20000) + [0.03, 0.05, 0.0]
    centre = np.asarray(CONFIG.centre)[:2]
    quarter = np.array([[0.0, -1.0], [1.0, 0.0]])
    turned = points.copy()
    turned[:, :2] = (points[:, :2] - centre) @ quarter.T + centre
    q, _ = net.q_maps(heightmap(points, CONFIG))
    q_turned, _ = net.q_maps(heightmap(turned, CONFIG))
    for k in range(PUSH_DIRECTIONS):
        np.testing.assert_allclose(q_turned[(k + 4) % PUSH_DIRECTIONS], np.rot90(q[k]), atol=1e-5)
        np.testing.assert_allclose(push_direction(k + 4)[:2], quarter @ push_direction(k)[:2], atol=1e-12)
    assert np.abs(q_turned[12] - np.rot90(q[0])).max() > 1e-4  # (directions turning the other way do not fit)
