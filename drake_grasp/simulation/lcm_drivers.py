"""The simulated station behind a robot's driver messages: what `cell.hardware.HardwareStation` talks to
when there is no robot.

`add_lcm_drivers` answers the messages of `robot.drivers` from a `Station` in the same diagram: the arm
follows the joint positions of `lcmt_panda_command` (holding where it is until the first command), the
hand the opening of `lcmt_schunk_wsg_command` (its grip is the scenario's), and the station publishes
`lcmt_panda_status`, `lcmt_schunk_wsg_status` and its depth camera's `lcmt_image_array`, as a robot's
drivers and camera would. A robot stack (or the cell's own `HardwareStation`) is tested against the
simulator this way before it meets the robot.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from drake import (
    lcmt_image_array,
    lcmt_panda_command,
    lcmt_panda_status,
    lcmt_schunk_wsg_command,
    lcmt_schunk_wsg_status,
)
from pydrake.lcm import DrakeLcmInterface
from pydrake.manipulation import (
    PandaCommandReceiver,
    PandaControlMode,
    PandaStatusSender,
    SchunkWsgCommandReceiver,
    SchunkWsgStatusSender,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import ConstantVectorSource, Demultiplexer, MatrixGain, Multiplexer
from pydrake.systems.sensors import ImageToLcmImageArrayT, PixelType

from drake_grasp.robot.drivers import DriverChannels
from drake_grasp.robot.specs import RobotSpec
from drake_grasp.simulation.objects import ObjectModel
from drake_grasp.simulation.placement import choose_objects, place_objects, settle_in_clusters
from drake_grasp.simulation.scenario import Scenario
from drake_grasp.simulation.station import Station


@dataclass
class SimulatedRobot:
    """The simulated station behind the drivers' messages, in its own diagram and simulator: a robot
    for a controller in another diagram (or process) to drive."""

    diagram: Diagram
    simulator: Simulator
    station: Station

    @property
    def context(self) -> Context:
        return self.simulator.get_mutable_context()


def build_simulated_robot(*, robot: RobotSpec, scenario: Scenario, object_models: Sequence[ObjectModel],
                          seed: int, channels: DriverChannels, lcm: DrakeLcmInterface | None = None,
                          realtime_rate: float = 0.0) -> SimulatedRobot:
    """`robot` in the seeded scene (its objects chosen, placed and settled as the cell's are), at home,
    answering `channels`' messages on `lcm`; simulated at `realtime_rate` (0: as fast as it computes)."""
    rng = np.random.default_rng(seed)
    objects = choose_objects(list(object_models), scenario.num_objects, rng, scenario.object_scale)
    builder = DiagramBuilder()
    station = builder.AddSystem(Station(scenario=scenario, robot=robot, objects=objects, noise_seed=seed))
    lcm = lcm or channels.make_lcm()
    builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
    add_lcm_drivers(builder, station, lcm, channels)
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    plant, inspector = station.plant(), station.scene_graph().model_inspector()
    place_objects(plant, station.plant_context(context), inspector, station.object_bodies, scenario, rng)
    station.set_home(context)
    simulator.Initialize()
    settle_in_clusters(simulator, plant, station.plant_context(context), inspector, station.object_bodies,
                       scenario, rng)
    simulator.set_target_realtime_rate(realtime_rate)
    return SimulatedRobot(simulator.get_system(), simulator, station)


def add_lcm_drivers(builder: DiagramBuilder, station: Station, lcm: DrakeLcmInterface,
                    channels: DriverChannels | None = None) -> None:
    """Connects `station` (already in `builder`, with an arm) to the driver messages on `lcm`; its
    arm_desired_state and hand_desired_state inputs are then taken."""
    channels = channels or DriverChannels()
    if station.robot is None:
        raise ValueError("the LCM drivers drive an arm; this station mounts a floating hand")
    channels.check_hand(station.robot.hand)
    n = station.robot.num_joints

    def publisher(name: str, lcm_type, period: float):
        return builder.AddNamedSystem(f"{name}_publisher", LcmPublisherSystem.Make(
            getattr(channels, name), lcm_type, lcm, publish_period=period, use_cpp_serializer=True))

    def subscriber(name: str, lcm_type):
        return builder.AddNamedSystem(f"{name}_subscriber", LcmSubscriberSystem.Make(
            getattr(channels, name), lcm_type, lcm, use_cpp_serializer=True))

    # The arm: commanded positions in (held at the measured ones until the first command), status out
    arm_state = builder.AddNamedSystem("arm_state_split", Demultiplexer([n, n]))
    builder.Connect(station.GetOutputPort("arm_state"), arm_state.get_input_port())
    command = builder.AddNamedSystem("arm_command_receiver",
                                     PandaCommandReceiver(n, PandaControlMode.kPosition))
    builder.Connect(subscriber("arm_command", lcmt_panda_command).get_output_port(),
                    command.GetInputPort("lcmt_panda_command"))
    builder.Connect(arm_state.get_output_port(0), command.GetInputPort("position_measured"))
    zeros = builder.AddNamedSystem("zero_joint_values", ConstantVectorSource(np.zeros(n)))
    desired = builder.AddNamedSystem("arm_desired_join", Multiplexer([n, n]))
    builder.Connect(command.GetOutputPort("position"), desired.get_input_port(0))
    builder.Connect(zeros.get_output_port(), desired.get_input_port(1))
    builder.Connect(desired.get_output_port(), station.GetInputPort("arm_desired_state"))
    status = builder.AddNamedSystem("arm_status_sender", PandaStatusSender(n))
    measured = {"position_commanded": command.GetOutputPort("position"),
                "position_measured": arm_state.get_output_port(0),
                "velocity_measured": arm_state.get_output_port(1)}
    for k in range(status.num_input_ports()):
        port = status.get_input_port(k)
        builder.Connect(measured.get(port.get_name(), zeros.get_output_port()), port)
    builder.Connect(status.get_output_port(), publisher("arm_status", lcmt_panda_status,
                                                       channels.command_period).get_input_port())

    # The hand: the commanded opening in (each finger half of it), the opening and its rate out
    hand_command = builder.AddNamedSystem("hand_command_receiver", SchunkWsgCommandReceiver(
        initial_position=station.models.hand_spec.stroke, initial_force=channels.grip_force))
    builder.Connect(subscriber("hand_command", lcmt_schunk_wsg_command).get_output_port(),
                    hand_command.GetInputPort("command_message"))
    to_finger = builder.AddNamedSystem("opening_to_finger", MatrixGain(np.array([[0.5], [0.0]])))
    builder.Connect(hand_command.GetOutputPort("position"), to_finger.get_input_port())
    builder.Connect(to_finger.get_output_port(), station.GetInputPort("hand_desired_state"))
    to_opening = builder.AddNamedSystem("finger_to_opening", MatrixGain(2.0 * np.eye(2)))  # (both fingers')
    builder.Connect(station.GetOutputPort("hand_state"), to_opening.get_input_port())
    hand_status = builder.AddNamedSystem("hand_status_sender", SchunkWsgStatusSender())
    builder.Connect(to_opening.get_output_port(), hand_status.get_input_port(0))
    no_force = builder.AddNamedSystem("hand_force_unmeasured", ConstantVectorSource(np.zeros(1)))
    builder.Connect(no_force.get_output_port(), hand_status.get_input_port(1))
    builder.Connect(hand_status.get_output_port(), publisher("hand_status", lcmt_schunk_wsg_status,
                                                             channels.command_period).get_input_port())

    # The camera: its depth image, in metres
    images = builder.AddNamedSystem("image_to_lcm", ImageToLcmImageArrayT(do_compress=False))
    depth_port = images.DeclareImageInputPort[PixelType.kDepth32F]("depth")
    builder.Connect(station.GetOutputPort("depth_image"), depth_port)
    builder.Connect(images.get_output_port(), publisher("images", lcmt_image_array,
                                                        channels.image_period).get_input_port())
