"""Settled scenes shared between runs of the same scene: a run that sets the kept state is the run that
settled it, attempt for attempt, and the key tells scenes apart."""

import dataclasses as dc

import numpy as np
import pytest

from drake_grasp.cell.diagram import build_cell
from drake_grasp.cell.episode import run_episode
from drake_grasp.perception.config import SamplingConfig
from drake_grasp.policy.scorers import make_scorer
from drake_grasp.robot.arms import get_robot
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import Scenario, load_scenario
from drake_grasp.simulation.settled import SettledScenes, scene_key

# Four objects dropped close together, strays dropped again: a settle worth keeping, one attempt.
PILE = """
name: pile
clusters:
  - centre: [0.5, 0.0]
    radius: 0.05
    count: 4
settle_time: 0.5
settle_within: 0.3
sampling: {num_candidates: 50}
max_attempts: 1
plant_config: {time_step: 0.004}
object_sleep: {enabled: true}
"""


@pytest.fixture(scope="module")
def pile(tmp_path_factory):
    path = tmp_path_factory.mktemp("pile") / "pile.yaml"
    path.write_text(PILE)
    return get_robot("panda"), load_scenario(str(path)), load_object_set("primitives")


def test_a_run_on_a_kept_scene_is_the_run_that_settled_it(pile, tmp_path):
    robot, scenario, models = pile
    settled = SettledScenes(tmp_path / "settled")

    def run(scene: Scenario, kept: SettledScenes | None) -> dict:
        result = run_episode(robot=robot, scenario=scene, scorer=make_scorer("rand", robot),
                             object_models=models, seed=3, settled=kept).to_dict()
        result["attempt_log"] = [{k: v for k, v in a.items() if k != "plan_seconds"}
                                 for a in result["attempt_log"]]
        return {k: v for k, v in result.items() if k != "wall_time_s"}  # (wall-clock times aside)

    plain = run(scenario, None)
    settling = run(scenario, settled)  # settles the scene and keeps it
    assert len(list((tmp_path / "settled").glob("*.npz"))) == 1
    from_kept = run(scenario, settled)  # sets the kept state
    assert plain["attempts"] == 1 and plain["objects_left"]
    assert settling == plain and from_kept == plain
    # Another policy's view of the same drop (a second camera, top grasps only) starts from it too.
    seen_otherwise = scenario.with_second_camera().with_gamma_deg([0.0, 0.0])
    assert run(seen_otherwise, settled) == run(seen_otherwise, None)
    assert len(list((tmp_path / "settled").glob("*.npz"))) == 1

    cell = build_cell(robot=robot, scenario=scenario, scorer=make_scorer("rand", robot), object_models=models,
                      seed=3, settled=settled)
    assert cell.simulator.get_num_steps_taken() == 0  # nothing simulated to get there
    assert cell.context.get_time() >= scenario.settle_time


def test_the_key_tells_scenes_apart(pile):
    robot, scenario, models = pile
    key = scene_key(robot, scenario, models[:4], 3)
    seen_otherwise = dc.replace(scenario.with_second_camera(), sampling=SamplingConfig(num_candidates=9))
    assert key == scene_key(robot, seen_otherwise, models[:4], 3)
    others = [scene_key(robot, scenario, models[:4], 4),
              scene_key(robot, scenario.with_time_step(0.002), models[:4], 3),
              scene_key(robot, dc.replace(scenario, settle_time=0.6), models[:4], 3),
              scene_key(robot, scenario, models[1:5], 3),
              scene_key(get_robot("ur5"), scenario, models[:4], 3)]
    assert len({key, *others}) == 6


def test_a_missing_or_foreign_state_is_not_used(pile, tmp_path):
    robot, scenario, models = pile
    settled = SettledScenes(tmp_path)
    assert settled.load("nothing-here") is None
    state = settled.load(_settle_once(robot, scenario, models, settled))
    assert state is not None and np.all(np.isfinite(state.discrete[0]))
    context = build_cell(robot=robot, scenario=scenario, scorer=make_scorer("rand", robot),
                         object_models=models, seed=5).context
    for foreign in (state.discrete * 2, (state.discrete[0][:-13],)):  # more state groups, fewer bodies
        with pytest.raises(ValueError, match="another diagram"):
            dc.replace(state, discrete=foreign).apply(context)


def _settle_once(robot, scenario, models, settled: SettledScenes) -> str:
    """Builds seed 3's cell with `settled` and returns the key its scene is kept under."""
    build_cell(robot=robot, scenario=scenario, scorer=make_scorer("rand", robot), object_models=models,
               seed=3, settled=settled)
    (path,) = settled.folder.glob("*.npz")
    return path.stem
