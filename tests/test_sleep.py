"""Sleeping objects: at rest and away from the hand they are locked; near the action or touched they wake."""

import numpy as np
import pytest

from drake_grasp.cell.diagram import POLL_S, build_cell
from drake_grasp.policy.scorers import make_scorer
from drake_grasp.robot.arms import get_robot
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import load_scenario
from drake_grasp.simulation.sleep import ObjectSleepConfig, bounding_radius

TWO_CUBES = """name: two_cubes
clusters:
  - centre: [0.45, -0.3]
    radius: 0.0
    count: 1
  - centre: [0.6, 0.3]
    radius: 0.0
    count: 1
settle_time: 60.0
object_sleep: {enabled: true}
"""  # the executive waits for 60 s of settling: the arm stays home through the tests


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    path = tmp_path_factory.mktemp("sleep") / "two_cubes.yaml"
    path.write_text(TWO_CUBES)
    scenario = load_scenario(str(path))
    robot = get_robot("panda")
    cube = [m for m in load_object_set("primitives") if m.name == "cube"]
    built = build_cell(robot=robot, scenario=scenario, scorer=make_scorer("rand", robot), object_models=cube,
                       seed=0)
    for _ in range(10):  # 1 s: the cubes land and rest, far from the arm at home
        built.simulator.AdvanceTo(built.context.get_time() + POLL_S)
        built.update_sleep()
    return built


def _positions(cell) -> np.ndarray:
    plant, plant_context = cell.station.plant(), cell.station.plant_context(cell.context)
    return np.array([plant.EvalBodyPoseInWorld(plant_context, b).translation()
                     for b in cell.station.object_bodies])


def _contacts_found(cell) -> int:
    """Contact pairs the geometry query finds (what the solver would get), sleeping objects' included."""
    from pydrake.geometry import HydroelasticContactRepresentation

    plant = cell.station.plant()
    query = plant.get_geometry_query_input_port().Eval(cell.station.plant_context(cell.context))
    surfaces, pairs = query.ComputeContactSurfacesWithFallback(HydroelasticContactRepresentation.kPolygon)
    return len(surfaces) + len(pairs)


def test_the_scenario_turns_sleep_on_and_it_is_off_by_default():
    assert not ObjectSleepConfig().enabled and not load_scenario("single").object_sleep.enabled
    assert all(load_scenario(name).object_sleep.enabled for name in ("standard", "challenging", "ablation"))


def test_a_bounding_radius_holds_the_cube(cell):
    plant, inspector = cell.station.plant(), cell.station.scene_graph().model_inspector()
    radius = bounding_radius(inspector, plant, cell.station.object_bodies[0])
    assert radius == pytest.approx(0.5 * np.sqrt(3) * 0.05, rel=0.05)  # the 5 cm cube's half diagonal


def test_objects_at_rest_far_from_the_hand_sleep_and_stay_put(cell):
    plant_context = cell.station.plant_context(cell.context)
    assert cell.sleep.asleep(plant_context).all()
    assert _contacts_found(cell) == 0  # sleeping cubes on the table: filtered out of the queries
    before = _positions(cell)
    cell.simulator.AdvanceTo(cell.context.get_time() + 0.5)
    np.testing.assert_allclose(_positions(cell), before, atol=1e-9)


def test_an_object_wakes_when_the_action_comes_near_or_the_robot_touches_it(cell):
    plant_context = cell.station.plant_context(cell.context)
    near, far = _positions(cell)
    cell.sleep.update(cell.context, near[None, :] + [0.0, 0.0, 0.05], frozenset())
    assert cell.sleep.asleep(plant_context).tolist() == [False, True]
    assert _contacts_found(cell) == 1  # the awake cube rests on the table again
    far_index = int(cell.station.object_bodies[1].index())
    robot_link = cell.station.robot_bodies[0]
    cell.sleep.update(cell.context, near[None, :], frozenset({(min(far_index, robot_link),
                                                                 max(far_index, robot_link))}))
    assert not cell.sleep.asleep(plant_context).any()
    # awake and still at rest: asleep again once the action has left for rest_s
    for _ in range(5):
        cell.simulator.AdvanceTo(cell.context.get_time() + POLL_S)
        cell.sleep.update(cell.context, np.zeros((0, 3)), frozenset())
    assert cell.sleep.asleep(plant_context).all()
