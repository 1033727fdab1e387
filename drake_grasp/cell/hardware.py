"""The station on a robot: the simulated `Station`'s ports, served by the robot's drivers over LCM.

As Drake's hardware stations do, `HardwareStation` is a Diagram with the ports of the simulated
station that the cell's executive and perception use, so the same diagram runs in the simulator or on
a robot:

    inputs   arm_desired_state (positions, then velocities: the positions are sent),
             hand_desired_state (the driven finger's travel and its rate: the opening is sent)
    outputs  arm_state (measured positions, then velocities), hand_state (the driven finger's travel and
             its rate, half the gripper's opening), depth_image (32-bit float, metres), point_cloud_W
             (the image in the base frame, through the camera's pose)

The messages are Drake's driver messages (`robot.drivers`): a robot whose drivers speak them (Drake's
Franka and gripper drivers, or a bridge from ROS) plugs in; `simulation.lcm_drivers` answers them from
the simulator. The ground truth of the simulated station (body poses, contacts) has no counterpart
here: a cell on a robot judges its grasps with `cell.judges.GripperJudge`.
"""

from __future__ import annotations

import time
import zlib

import numpy as np
from drake import (
    lcmt_image,
    lcmt_image_array,
    lcmt_panda_command,
    lcmt_panda_status,
    lcmt_schunk_wsg_command,
    lcmt_schunk_wsg_status,
)
from pydrake.common.value import AbstractValue, Value
from pydrake.lcm import DrakeLcmInterface
from pydrake.manipulation import (
    PandaCommandSender,
    PandaControlMode,
    PandaStatusReceiver,
    SchunkWsgCommandSender,
    SchunkWsgStatusReceiver,
)
from pydrake.perception import BaseField, DepthImageToPointCloud
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import ConstantValueSource, Demultiplexer, MatrixGain, Multiplexer
from pydrake.systems.sensors import ImageDepth32F, PixelType

from drake_grasp.perception.camera import CameraConfig, CameraError
from drake_grasp.robot.drivers import DriverChannels
from drake_grasp.robot.specs import RobotSpec
from drake_grasp.simulation.station import camera_info

DEPTH_CHANNELS = {lcmt_image.CHANNEL_TYPE_FLOAT32: (np.float32, 1.0),  # metres
                  lcmt_image.CHANNEL_TYPE_UINT16: (np.uint16, 1e-3)}  # millimetres (0: no reading)


class DriversSilentError(RuntimeError):
    """No message came on a driver's channel in time."""


class HardwareStation(Diagram):
    """The cell's station on a robot (see the module): `robot`'s arm and a parallel gripper over LCM,
    and a fixed depth camera `camera` (its pose is the image's place in the base frame)."""

    def __init__(self, robot: RobotSpec, camera: CameraConfig, channels: DriverChannels | None = None,
                 lcm: DrakeLcmInterface | None = None):
        super().__init__()
        self.set_name("hardware_station")
        self.robot, self.camera = robot, camera
        self.channels = channels = channels or DriverChannels()
        channels.check_hand(robot.hand)
        self.lcm = lcm = lcm or channels.make_lcm()
        n = robot.num_joints
        builder = DiagramBuilder()
        builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))

        def publisher(name: str, lcm_type):
            return builder.AddNamedSystem(f"{name}_publisher", LcmPublisherSystem.Make(
                getattr(channels, name), lcm_type, lcm, publish_period=channels.command_period,
                use_cpp_serializer=True))

        def subscriber(name: str, lcm_type):
            return builder.AddNamedSystem(f"{name}_subscriber", LcmSubscriberSystem.Make(
                getattr(channels, name), lcm_type, lcm, use_cpp_serializer=True))

        # The arm
        desired = builder.AddNamedSystem("arm_desired_split", Demultiplexer([n, n]))
        builder.ExportInput(desired.get_input_port(), "arm_desired_state")
        command = builder.AddNamedSystem("arm_command_sender",
                                         PandaCommandSender(n, PandaControlMode.kPosition))
        builder.Connect(desired.get_output_port(0), command.GetInputPort("position"))
        builder.Connect(command.get_output_port(),
                        publisher("arm_command", lcmt_panda_command).get_input_port())
        status = builder.AddNamedSystem("arm_status_receiver", PandaStatusReceiver(n))
        builder.Connect(subscriber("arm_status", lcmt_panda_status).get_output_port(),
                        status.GetInputPort("lcmt_panda_status"))
        state = builder.AddNamedSystem("arm_state_join", Multiplexer([n, n]))
        builder.Connect(status.GetOutputPort("position_measured"), state.get_input_port(0))
        builder.Connect(status.GetOutputPort("velocity_measured"), state.get_input_port(1))
        builder.ExportOutput(state.get_output_port(), "arm_state")

        # The gripper: the opening is both fingers' travel
        to_opening = builder.AddNamedSystem("finger_to_opening", MatrixGain(np.array([[2.0, 0.0]])))
        builder.ExportInput(to_opening.get_input_port(), "hand_desired_state")
        hand_command = builder.AddNamedSystem("hand_command_sender", SchunkWsgCommandSender(
            default_force_limit=channels.grip_force))
        builder.Connect(to_opening.get_output_port(), hand_command.GetInputPort("position"))
        builder.Connect(hand_command.get_output_port(),
                        publisher("hand_command", lcmt_schunk_wsg_command).get_input_port())
        hand_status = builder.AddNamedSystem("hand_status_receiver", SchunkWsgStatusReceiver())
        builder.Connect(subscriber("hand_status", lcmt_schunk_wsg_status).get_output_port(),
                        hand_status.get_input_port())
        to_finger = builder.AddNamedSystem("opening_to_finger", MatrixGain(0.5 * np.eye(2)))
        builder.Connect(hand_status.GetOutputPort("state"), to_finger.get_input_port())
        builder.ExportOutput(to_finger.get_output_port(), "hand_state")

        # The camera
        images_subscriber = builder.AddNamedSystem("images_subscriber", LcmSubscriberSystem.Make(
            channels.images, lcmt_image_array, lcm))  # (Python's message: DepthImageFromLcm decodes it)
        images = builder.AddNamedSystem("depth_from_lcm", DepthImageFromLcm(camera))
        builder.Connect(images_subscriber.get_output_port(), images.get_input_port())
        depth = images.get_output_port()
        builder.ExportOutput(depth, "depth_image")
        to_cloud = builder.AddNamedSystem("depth_to_cloud", DepthImageToPointCloud(
            camera_info(camera), PixelType.kDepth32F, 1.0, BaseField.kXYZs))
        pose = builder.AddNamedSystem("camera_pose", ConstantValueSource(AbstractValue.Make(camera.X_BC)))
        builder.Connect(depth, to_cloud.depth_image_input_port())
        builder.Connect(pose.get_output_port(), to_cloud.camera_pose_input_port())
        builder.ExportOutput(to_cloud.point_cloud_output_port(), "point_cloud_W")
        builder.BuildInto(self)
        self._heard = dict.fromkeys((channels.arm_status, channels.hand_status, channels.images), 0)
        for channel in self._heard:  # counted as LCM hands them out (to the subscribers above too)
            lcm.Subscribe(channel, lambda _, channel=channel: self._hear(channel))

    def _hear(self, channel: str) -> None:
        self._heard[channel] += 1

    def wait_for_drivers(self, timeout_s: float = 5.0) -> None:
        """Handles LCM until the arm, the gripper and the camera have each sent a message; DriversSilentError
        names the channels that stayed silent for `timeout_s`."""
        deadline = time.monotonic() + timeout_s
        while True:
            silent = [channel for channel, count in self._heard.items() if count == 0]
            if not silent:
                return
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DriversSilentError(f"no message on {', '.join(silent)} in {timeout_s:g} s (LCM "
                                    f"'{self.channels.lcm_url or 'default'}'): are the drivers running?")
            self.lcm.HandleSubscriptions(int(min(remaining, 0.1) * 1000))


class DepthImageFromLcm(LeafSystem):
    """`lcmt_image_array` in, its depth image out as an ImageDepth32F in metres (32-bit float metres or
    16-bit millimetres, raw or zlib-compressed); an empty image until the first message. A message
    without a depth image, or one of another size than the camera's, is a CameraError naming it."""

    def __init__(self, camera: CameraConfig):
        super().__init__()
        self._width, self._height = camera.width, camera.height
        self.DeclareAbstractInputPort("image_array", AbstractValue.Make(lcmt_image_array()))
        self.DeclareAbstractOutputPort("depth_image", lambda: Value(ImageDepth32F()), self._calc)

    def _calc(self, context, output) -> None:
        message = self.get_input_port().Eval(context)
        if message.num_images == 0:  # (no message yet)
            output.set_value(ImageDepth32F())
            return
        depth = decode_depth(message, self._width, self._height)
        image = ImageDepth32F(self._width, self._height)
        image.mutable_data[:] = depth[:, :, None]
        output.set_value(image)


def decode_depth(message: lcmt_image_array, width: int, height: int) -> np.ndarray:
    """The (height, width) depth image [m] of an `lcmt_image_array` (NaN: no reading)."""
    depth = [im for im in message.images if im.pixel_format == lcmt_image.PIXEL_FORMAT_DEPTH]
    if not depth:
        raise CameraError("the camera's image array holds no depth image")
    image = depth[0]
    if (image.width, image.height) != (width, height):
        raise CameraError(f"the depth image is {image.width} x {image.height} but the camera's intrinsics "
                          f"are for {width} x {height}")
    if image.channel_type not in DEPTH_CHANNELS:
        raise CameraError(f"depth pixels of channel type {image.channel_type}: 32-bit float metres or 16-bit "
                          "millimetres expected")
    dtype, scale = DEPTH_CHANNELS[image.channel_type]
    if image.compression_method == lcmt_image.COMPRESSION_METHOD_ZLIB:
        data = zlib.decompress(bytes(image.data))
    elif image.compression_method == lcmt_image.COMPRESSION_METHOD_NOT_COMPRESSED:
        data = bytes(image.data)
    else:
        raise CameraError(f"depth image compression {image.compression_method}: raw or zlib expected")
    itemsize = np.dtype(dtype).itemsize
    if image.row_stride < width * itemsize or len(data) < image.row_stride * height:
        raise CameraError(f"a depth image of {len(data)} bytes, row stride {image.row_stride}, is too short "
                          f"for {width} x {height} pixels")
    rows = np.frombuffer(data, dtype=np.uint8)[:image.row_stride * height].reshape(height, image.row_stride)
    order = ">" if image.bigendian else "<"
    pixels = rows[:, :width * itemsize].copy().view(np.dtype(dtype).newbyteorder(order))
    metres = pixels.astype(np.float32) * np.float32(scale)
    if image.channel_type == lcmt_image.CHANNEL_TYPE_UINT16:
        metres[pixels == 0] = np.nan
    return metres
