"""The grasping cell as one Drake diagram, ready to simulate: what `run_episode` and the notebooks drive.

The diagram: station (plant, scene graph, depth camera, point cloud) ->
ObjectCloudSystem -> GraspSelector (a policy's scorer) -> GraspExecutive (plan and
execute, home included) -> the station's desired-state inputs; optionally a
MeshcatVisualizer. `build_cell` places the seeded scene's objects and puts the arm
home; `run_attempt` advances the simulator until the executive has finished one
attempt (or found nothing worth trying). `add_controller` wires the controller (perception,
selector, executive) to a station's ports; `build_robot_cell` puts it on a robot's
`HardwareStation` alone.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context, Diagram, DiagramBuilder

from drake_grasp.cell.executive import END_MODES, CellConfig, ExecutiveState, GraspExecutive, Mode
from drake_grasp.cell.hardware import HardwareStation
from drake_grasp.cell.judges import AttemptJudge, GripperJudge, SimulatorJudge
from drake_grasp.perception.cloud import ObjectCloud, ObjectCloudSystem
from drake_grasp.planning.planner import GraspPlanner, PlannerConfig
from drake_grasp.policy.scorers import Scorer
from drake_grasp.policy.selector import GraspSelector, RankedGrasps
from drake_grasp.robot.drivers import DriverChannels
from drake_grasp.robot.specs import RobotSpec
from drake_grasp.robot.stages import stage
from drake_grasp.simulation.lcm_drivers import add_lcm_drivers
from drake_grasp.simulation.lifetime import release_python_systems
from drake_grasp.simulation.objects import ObjectModel
from drake_grasp.simulation.placement import choose_objects, place_objects, settle_in_clusters
from drake_grasp.simulation.scenario import Scenario
from drake_grasp.simulation.settled import SettledScenes, SettledState, scene_key
from drake_grasp.simulation.sleep import ObjectSleep
from drake_grasp.simulation.station import Station

POLL_S = 0.1  # how often a driver looks at the executive (and objects fall asleep or wake) [simulated s]
# While the executive is in these modes, the grasp point is where the action is (objects near it stay awake).
AT_THE_GRASP = (Mode.TRANSIT, Mode.APPROACH, Mode.CLOSE, Mode.LIFT, Mode.HOLD, Mode.RELEASE, Mode.RETREAT)
ATTEMPT_TIMEOUT_S = 60.0  # simulated seconds; guards against a stuck state machine


@dataclass
class GraspCell:
    """A built cell: the diagram, its simulator and the systems a driver or a notebook looks at."""

    diagram: Diagram
    simulator: Simulator
    station: Station
    perception: ObjectCloudSystem
    selector: GraspSelector
    executive: GraspExecutive
    objects: list[ObjectModel]
    sleep: ObjectSleep
    visualizer: MeshcatVisualizer | None = None

    @property
    def context(self) -> Context:
        return self.simulator.get_mutable_context()

    def advance(self, seconds: float) -> None:
        """Simulates `seconds` more (a scenario with `settle_within` has already settled once in
        `build_cell`, so the clock does not start at zero)."""
        self.simulator.AdvanceTo(self.context.get_time() + seconds)

    def advance_to_next_look(self) -> None:
        """Simulates until the executive next looks at the scene (no time when that is now), so the
        camera, cloud and ranking read here are those it decides on. (`advance(settle_time)` after
        `build_cell` of a scene that re-drops strays overshoots: the first attempt is under way.)"""
        self.simulator.AdvanceTo(max(self.context.get_time(), self.task_state().wait_until))

    def depth_image(self) -> np.ndarray:
        """The camera's depth image [m], (height, width)."""
        image = self.station.GetOutputPort("depth_image").Eval(self._station_context())
        return np.array(image.data, copy=True).squeeze(-1)

    def point_cloud_W(self) -> np.ndarray:
        """The camera's whole point cloud in the world frame, (N, 3), invalid pixels dropped."""
        points = self.station.GetOutputPort("point_cloud_W").Eval(self._station_context()).xyzs().T
        return points[np.isfinite(points).all(axis=1)]

    def object_cloud(self) -> ObjectCloud:
        """The segmented object cloud the policy sees."""
        return self.perception.GetOutputPort("object_cloud").Eval(
            self.perception.GetMyContextFromRoot(self.context))

    def ranked_grasps(self) -> RankedGrasps:
        """The policy's ranked candidates for the current image."""
        return self.selector.GetOutputPort("ranked_grasps").Eval(
            self.selector.GetMyContextFromRoot(self.context))

    def task_state(self) -> ExecutiveState:
        return self.executive.get_task_state(self.context)

    @stage("bookkeeping")
    def update_sleep(self) -> None:
        """Objects at rest away from the hand and the grasp in progress sleep; the others wake."""
        if not self.sleep.config.enabled:
            return
        station_context = self._station_context()
        focus = list(self.station.finger_positions(self.context))
        state = self.task_state()
        if state.mode in AT_THE_GRASP and state.X_WG is not None:
            focus.append(np.asarray(state.X_WG)[:3, 3])
        contacts = self.station.GetOutputPort("body_contacts").Eval(station_context)
        self.sleep.update(self.context, np.array(focus), contacts)

    def release(self) -> None:
        """Frees the cell's diagram once its run is over (`simulation.lifetime`); the cell cannot be
        simulated or looked at afterwards."""
        release_python_systems(self.diagram)

    def _station_context(self) -> Context:
        return self.station.GetMyContextFromRoot(self.context)


@stage("set-up")
def build_cell(*, robot: RobotSpec, scenario: Scenario, scorer: Scorer, object_models: Sequence[ObjectModel],
               seed: int, cell: CellConfig | None = None, meshcat: Meshcat | None = None,
               settled: SettledScenes | None = None, judge: AttemptJudge | None = None,
               drivers: DriverChannels | None = None) -> GraspCell:
    """The cell for one seeded scene: objects chosen and dropped by rng(seed), the arm home, initialized.

    With `settled`, a scene settled before (by a run of another policy) is set from there instead of
    simulated again, and a scene settled here is kept there. `judge`: how the executive tells what its
    attempts did (default: the simulator's ground truth; `GripperJudge`: what a robot would know).
    With `drivers`, the executive and perception reach the simulated robot only through a
    `HardwareStation` and the drivers' LCM messages (`simulation.lcm_drivers`), as they would reach a
    robot: one camera, and a judge that reads the arm and the jaws (`GripperJudge`)."""
    rng = np.random.default_rng(seed)
    objects = choose_objects(list(object_models), scenario.num_objects, rng, scenario.object_scale)
    builder = DiagramBuilder()
    station = builder.AddSystem(Station(scenario=scenario, robot=robot, objects=objects, noise_seed=seed))
    plant = station.plant()
    sensing = scenario.sensing
    controlled = station  # the ports the executive and perception use: the station's, or over LCM
    if drivers is not None:
        if len(sensing.cameras) > 1:
            raise ValueError("a cell over the drivers' messages has one camera; the scenario has "
                             f"{len(sensing.cameras)}")
        lcm = drivers.make_lcm()
        add_lcm_drivers(builder, station, lcm, drivers)
        controlled = builder.AddSystem(HardwareStation(robot, sensing.camera, drivers, lcm))
    judge = judge or SimulatorJudge(object_body_indices=[b.index() for b in station.object_bodies],
                                    finger_body_indices=station.finger_bodies,
                                    robot_body_indices=station.robot_bodies, num_bodies=plant.num_bodies(),
                                    hand=robot.hand, success_rule=scenario.success_rule)
    perception, selector, executive = add_controller(
        builder, controlled, robot=robot, scenario=scenario, scorer=scorer, judge=judge, seed=seed, cell=cell,
        meshcat=meshcat)
    visualizer = None
    if meshcat is not None:
        visualizer = MeshcatVisualizer.AddToBuilder(builder, station.GetOutputPort("query_object"), meshcat,
                                                    MeshcatVisualizerParams(role=Role.kIllustration))
    diagram = builder.Build()

    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    place_objects(plant, station.plant_context(context), station.scene_graph().model_inspector(),
                  station.object_bodies, scenario, rng)
    station.set_home(context)
    key = None if settled is None else scene_key(robot, scenario, objects, seed)
    kept = None if settled is None else settled.load(key)
    if kept is not None:
        kept.apply(context)
    simulator.Initialize()
    if kept is None:
        # No attempt starts while the scene settles and strays are dropped again: the first looks at the
        # scene at rest, once the last settle is over (at settle_time when nothing is re-dropped).
        executive.wait_until(context, math.inf)
        settle_in_clusters(simulator, plant, station.plant_context(context),
                           station.scene_graph().model_inspector(), station.object_bodies, scenario, rng)
        if settled is not None:
            settled.save(key, SettledState.of(context))
    executive.wait_until(context, max(scenario.settle_time, context.get_time()))
    if meshcat is not None:
        meshcat.Delete("grasps")
    sleep = ObjectSleep(plant, station.scene_graph(), station.object_bodies, station.robot_bodies,
                        scenario.object_sleep)
    return GraspCell(diagram, simulator, station, perception, selector, executive, objects, sleep, visualizer)


def run_attempt(cell: GraspCell, *, record: bool = False) -> ExecutiveState:
    """Simulates until the executive has finished its attempt or ended the run; returns its state.

    With `record`, the attempt is recorded in the cell's Meshcat and published as an
    animation (Meshcat's "animation" controls replay it).
    """
    if record and cell.visualizer is None:
        raise ValueError("build the cell with a Meshcat to record an attempt")
    if record:
        cell.visualizer.DeleteRecording()
        cell.visualizer.StartRecording()
    context = cell.context
    start = context.get_time()
    while cell.task_state().mode not in (Mode.ATTEMPT_DONE, *END_MODES):
        if context.get_time() - start > ATTEMPT_TIMEOUT_S:
            raise RuntimeError("the grasp executive did not finish an attempt in time")
        cell.simulator.AdvanceTo(context.get_time() + POLL_S)
        cell.update_sleep()
    if record:
        cell.visualizer.StopRecording()
        cell.visualizer.PublishRecording()
    return cell.task_state()


def add_controller(builder: DiagramBuilder, controlled: Diagram, *, robot: RobotSpec, scenario: Scenario,
                   scorer: Scorer, judge: AttemptJudge, seed: int, cell: CellConfig | None = None,
                   meshcat: Meshcat | None = None) -> tuple[ObjectCloudSystem, GraspSelector, GraspExecutive]:
    """The cell's controller in `builder`: perception, the policy's selector and the executive, connected to
    the ports of `controlled` (a `Station` or a `HardwareStation`: point_cloud_W, the states the judge
    reads, the desired-state inputs), as `scenario`'s sensing and sampling say."""
    sensing, sampling = scenario.sensing, scenario.sampling
    cameras = [(np.asarray(c.xyz, dtype=float), c.width * c.height) for c in sensing.cameras]
    perception = builder.AddNamedSystem("object_cloud", ObjectCloudSystem(
        lower=sensing.workspace.lower, upper=sensing.workspace.upper, config=sensing.perception,
        cameras=cameras))
    selector = builder.AddNamedSystem("grasp_selector", GraspSelector(
        scorer, num_candidates=sampling.num_candidates, gamma_deg=tuple(sampling.gamma_deg), seed=seed,
        sampler=sampling.sampler, camera_positions=sensing.camera_positions,
        gpg_stop_at_table=sampling.gpg_stop_at_table, hand=robot.hand))
    executive = builder.AddNamedSystem("executive", GraspExecutive(
        GraspPlanner(robot, seed=seed,
                     config=PlannerConfig(retreat_before_lift=scenario.retreat_before_lift)),
        judge=judge, settle_time=scenario.settle_time, config=cell, meshcat=meshcat))
    builder.Connect(controlled.GetOutputPort("point_cloud_W"), perception.GetInputPort("point_cloud_W"))
    builder.Connect(perception.GetOutputPort("object_cloud"), selector.GetInputPort("object_cloud"))
    builder.Connect(perception.GetOutputPort("object_cloud"), executive.GetInputPort("object_cloud"))
    builder.Connect(selector.GetOutputPort("ranked_grasps"), executive.GetInputPort("ranked_grasps"))
    for port in ("body_poses", "body_contacts", "arm_state", "hand_state"):  # (those the judge reads)
        if executive.HasInputPort(port):
            if not controlled.HasOutputPort(port):
                raise ValueError(f"the judge reads the simulator's {port}, which a robot's drivers do not "
                                 "send: judge a cell over the drivers with GripperJudge")
            builder.Connect(controlled.GetOutputPort(port), executive.GetInputPort(port))
    for port in ("arm_desired_state", "hand_desired_state"):
        builder.Connect(executive.GetOutputPort(port), controlled.GetInputPort(port))
    return perception, selector, executive


@dataclass
class RobotCell:
    """A cell on a robot: the controller and the `HardwareStation` it drives, and their simulator (the
    clock of the controller's decisions, kept to wall time)."""

    diagram: Diagram
    simulator: Simulator
    hardware: HardwareStation
    perception: ObjectCloudSystem
    selector: GraspSelector
    executive: GraspExecutive

    @property
    def context(self) -> Context:
        return self.simulator.get_mutable_context()

    def task_state(self) -> ExecutiveState:
        return self.executive.get_task_state(self.context)


def build_robot_cell(*, robot: RobotSpec, scenario: Scenario, scorer: Scorer, channels: DriverChannels,
                     seed: int = 0, cell: CellConfig | None = None, lcm: DrakeLcmInterface | None = None,
                     realtime_rate: float = 1.0) -> RobotCell:
    """The cell's controller on a robot whose drivers speak `channels`' messages (`HardwareStation`),
    judged by the jaws (`GripperJudge`); `scenario` gives the camera, the workspace, the sampling and
    the executive's timing (its world is the robot's). The simulator runs at `realtime_rate` (1: wall
    time; 0: as fast as it computes, for lockstep with a simulated robot)."""
    sensing = scenario.sensing
    if len(sensing.cameras) > 1:
        raise ValueError(f"a cell on a robot has one camera; the scenario has {len(sensing.cameras)}")
    builder = DiagramBuilder()
    hardware = builder.AddSystem(HardwareStation(robot, sensing.camera, channels, lcm))
    perception, selector, executive = add_controller(
        builder, hardware, robot=robot, scenario=scenario, scorer=scorer,
        judge=GripperJudge(robot.hand), seed=seed, cell=cell)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.set_target_realtime_rate(realtime_rate)
    simulator.Initialize()
    return RobotCell(diagram, simulator, hardware, perception, selector, executive)
