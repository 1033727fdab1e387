"""One closed-loop grasping run (an episode) and its metrics.

The diagram: station (plant, scene graph, depth camera, point cloud) ->
ObjectCloudSystem -> GraspSelector (pluggable scorer) -> GraspExecutive (plan and
execute) -> the plant's PD actuators. The driver here advances the simulator
attempt by attempt: it removes a grasped object, sends the arm home, and ends
the run when no object is left, after `max_consecutive_failures` failures in a
row (planning failures included), or after `max_attempts`.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_grasp.executive import GraspExecutive, Mode
from drake_grasp.objects import ObjectModel
from drake_grasp.perception import ObjectCloudSystem
from drake_grasp.planner import GraspPlanner
from drake_grasp.robots import RobotSpec
from drake_grasp.scenario import Scenario
from drake_grasp.selector import GraspSelector, Scorer
from drake_grasp.station import HAND_OPEN, build_station, choose_objects, park_object, place_objects

POLL_S = 0.1  # how often the driver looks at the executive [simulated s]
RESETTLE_S = 0.3  # physics after the arm returns home, before the next image [s]
FELL_OFF_Z = -0.2  # an object this far below the table top has left the table [m]
ATTEMPT_TIMEOUT_S = 30.0  # simulated seconds; guards against a stuck state machine


@dataclass
class EpisodeResult:
    seed: int
    num_objects: int
    attempts: int = 0
    successes: int = 0
    plans_tried: int = 0
    plans_succeeded: int = 0
    objects_grasped: int = 0
    objects_fell_off: int = 0
    end_reason: str = ""
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    failures: dict[str, int] = field(default_factory=dict)
    attempt_log: list[dict] = field(default_factory=list)

    @property
    def grasp_success_rate(self) -> float:
        return self.successes / self.attempts if self.attempts else 0.0

    @property
    def completion_rate(self) -> float:
        return self.objects_grasped / self.num_objects if self.num_objects else 0.0

    @property
    def planning_success_rate(self) -> float:
        return self.plans_succeeded / self.plans_tried if self.plans_tried else 0.0

    def to_dict(self) -> dict:
        out = asdict(self)
        out.update(grasp_success_rate=self.grasp_success_rate, completion_rate=self.completion_rate,
                   planning_success_rate=self.planning_success_rate)
        return out


def run_episode(*, robot: RobotSpec, scenario: Scenario, scorer: Scorer, object_models: list[ObjectModel],
                seed: int, meshcat: Meshcat | None = None,
                on_attempt: Callable[[int, dict], None] | None = None) -> EpisodeResult:
    """Builds the diagram for one seeded scene and grasps until the run ends."""
    wall_start = time.perf_counter()
    rng = np.random.default_rng(seed)
    objects = choose_objects(object_models, scenario.num_objects, rng)
    builder = DiagramBuilder()
    station = build_station(builder, robot=robot, scenario=scenario, objects=objects, meshcat=meshcat)
    plant = station.plant
    perception = builder.AddNamedSystem("object_cloud", ObjectCloudSystem(
        lower=scenario.workspace_min, upper=scenario.workspace_max,
        camera_position=station.X_WC.translation(),
    ))
    selector = builder.AddNamedSystem("grasp_selector", GraspSelector(
        scorer, num_candidates=scenario.num_candidates, gamma_deg=tuple(scenario.gamma_deg), seed=seed,
    ))
    planner = GraspPlanner(robot, seed=seed)
    executive = builder.AddNamedSystem("executive", GraspExecutive(
        planner, station, settle_time=scenario.settle_time, meshcat=meshcat,
    ))
    builder.Connect(station.cloud.point_cloud_output_port(), perception.GetInputPort("point_cloud_W"))
    builder.Connect(perception.GetOutputPort("object_cloud"), selector.GetInputPort("object_cloud"))
    builder.Connect(selector.GetOutputPort("ranked_grasps"), executive.GetInputPort("ranked_grasps"))
    builder.Connect(plant.get_body_poses_output_port(), executive.GetInputPort("body_poses"))
    builder.Connect(plant.get_state_output_port(station.arm), executive.GetInputPort("arm_state"))
    builder.Connect(plant.get_state_output_port(station.hand), executive.GetInputPort("hand_state"))
    builder.Connect(executive.GetOutputPort("arm_desired_state"),
                    plant.get_desired_state_input_port(station.arm))
    builder.Connect(executive.GetOutputPort("hand_desired_state"),
                    plant.get_desired_state_input_port(station.hand))
    diagram = builder.Build()

    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    place_objects(station, plant_context, scenario, rng)

    def send_arm_home() -> None:
        plant.SetPositions(plant_context, station.arm, robot.q_home)
        plant.SetVelocities(plant_context, station.arm, np.zeros(robot.num_joints))
        plant.SetPositions(plant_context, station.hand, [HAND_OPEN, HAND_OPEN])
        plant.SetVelocities(plant_context, station.hand, np.zeros(2))

    send_arm_home()
    simulator.Initialize()
    if meshcat is not None:
        meshcat.Delete("grasps")

    result = EpisodeResult(seed=seed, num_objects=len(objects))
    present = np.ones(len(objects), dtype=bool)
    consecutive_failures = 0
    failures: Counter[str] = Counter()
    while True:
        attempt_start = context.get_time()
        while executive.get_task_state(context).mode not in (Mode.ATTEMPT_DONE, Mode.NO_OBJECTS):
            if context.get_time() - attempt_start > ATTEMPT_TIMEOUT_S:
                raise RuntimeError("the grasp executive did not finish an attempt in time")
            simulator.AdvanceTo(context.get_time() + POLL_S)
        task = executive.get_task_state(context)
        if task.mode is Mode.NO_OBJECTS:
            result.end_reason = "no objects left in view"
            break
        attempt = task.attempt
        result.attempts += 1
        result.plans_tried += 1
        result.plans_succeeded += attempt.planned
        if attempt.success:
            result.successes += 1
            result.objects_grasped += 1
            present[attempt.object_index] = False
            consecutive_failures = 0
        else:
            failures[attempt.failure] += 1
            consecutive_failures += 1
        entry = asdict(attempt) | {"t": round(context.get_time(), 3)}
        if attempt.object_index is not None:
            entry["object"] = objects[attempt.object_index].name
        result.attempt_log.append(entry)
        if on_attempt is not None:
            on_attempt(result.attempts, entry)
        # Take grasped and fallen objects out of the scene, then send the arm home.
        for k, body in enumerate(station.object_bodies):
            if present[k] and plant.EvalBodyPoseInWorld(plant_context, body).translation()[2] < FELL_OFF_Z:
                present[k] = False
                result.objects_fell_off += 1
            if not present[k]:
                park_object(station, plant_context, k)
        send_arm_home()
        if not present.any():
            result.end_reason = "all objects removed"
            break
        if consecutive_failures >= scenario.max_consecutive_failures:
            result.end_reason = f"{consecutive_failures} consecutive failures"
            break
        if scenario.max_attempts and result.attempts >= scenario.max_attempts:
            result.end_reason = f"{result.attempts} attempts (the scenario's limit)"
            break
        executive.start_next_attempt(context, RESETTLE_S if attempt.planned else 0.0)
    result.failures = dict(failures)
    result.sim_time_s = context.get_time()
    result.wall_time_s = time.perf_counter() - wall_start
    return result
