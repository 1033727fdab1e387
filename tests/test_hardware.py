"""The station on a robot (`cell.hardware.HardwareStation`): the simulated station's ports over Drake's LCM
driver messages, tested against the simulated station behind the same messages."""

import zlib

import numpy as np
import pytest
from drake import lcmt_image, lcmt_image_array
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource
from scenes import one_cube_yaml

from drake_grasp.cell.hardware import DriversSilentError, HardwareStation, decode_depth
from drake_grasp.perception.camera import CameraError
from drake_grasp.robot.drivers import DriverChannels
from drake_grasp.robot.specs import ROBOTS
from drake_grasp.simulation.lcm_drivers import add_lcm_drivers
from drake_grasp.simulation.scenario import load_scenario
from drake_grasp.simulation.station import Station


@pytest.mark.parametrize("arm", ["panda", "ur5"])
def test_the_hardware_station_drives_the_simulated_robot_and_reports_what_it_measures(arm):
    robot, scenario = ROBOTS[arm], load_scenario("standard")
    channels = DriverChannels(lcm_url="memq://")
    lcm = DrakeLcm(channels.lcm_url)
    builder = DiagramBuilder()
    station = builder.AddSystem(Station(scenario=scenario, robot=robot, objects=[]))
    add_lcm_drivers(builder, station, lcm, channels)
    hardware = builder.AddSystem(HardwareStation(robot, scenario.sensing.camera, channels, lcm))
    q_target = np.asarray(robot.q_home) + 0.1
    arm_command = builder.AddSystem(ConstantVectorSource(np.r_[q_target, np.zeros(robot.num_joints)]))
    builder.Connect(arm_command.get_output_port(), hardware.GetInputPort("arm_desired_state"))
    hand_command = builder.AddSystem(ConstantVectorSource([0.01, 0.0]))  # each finger 1 cm from the centre
    builder.Connect(hand_command.get_output_port(), hardware.GetInputPort("hand_desired_state"))
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    station.set_home(context)
    with pytest.raises(DriversSilentError, match="PANDA_STATUS, SCHUNK_WSG_STATUS, DRAKE_RGBD_CAMERA_IMAGES"):
        hardware.wait_for_drivers(timeout_s=0.2)  # nothing has been published yet
    simulator.AdvanceTo(1.5)
    hardware.wait_for_drivers(timeout_s=0.2)

    plant, plant_context = station.plant(), station.plant_context(context)
    q = plant.GetPositions(plant_context, station.models.arm)
    np.testing.assert_allclose(q, q_target, atol=1e-4)  # the simulated arm went where it was sent
    hardware_context = hardware.GetMyContextFromRoot(context)
    station_context = station.GetMyContextFromRoot(context)
    arm_state = hardware.GetOutputPort("arm_state").Eval(hardware_context)
    np.testing.assert_allclose(arm_state[:robot.num_joints], q, atol=1e-6)  # and the station reports it
    np.testing.assert_allclose(plant.GetPositions(plant_context, station.models.hand), [0.01, 0.01],
                               atol=1e-4)
    hand_state = hardware.GetOutputPort("hand_state").Eval(hardware_context)
    np.testing.assert_allclose(hand_state[0], 0.01, atol=1e-4)
    # The camera's image came through whole (the last one sent, up to image_period old: the arm still
    # creeps by microns), and its cloud is the simulated station's
    sent = np.array(station.GetOutputPort("depth_image").Eval(station_context).data)
    received = np.array(hardware.GetOutputPort("depth_image").Eval(hardware_context).data)
    assert received.shape == sent.shape == (480, 640, 1) and np.isfinite(received).mean() > 0.8
    np.testing.assert_allclose(received, sent, rtol=0, atol=1e-4)
    cloud = hardware.GetOutputPort("point_cloud_W").Eval(hardware_context).xyzs()
    np.testing.assert_allclose(cloud, station.GetOutputPort("point_cloud_W").Eval(station_context).xyzs(),
                               rtol=0, atol=1e-4)


def depth_message(pixels: np.ndarray, channel_type: int, *, compress: bool = False, width: int | None = None):
    image = lcmt_image()
    image.height, image.width = pixels.shape
    image.width = width or image.width
    image.row_stride = pixels.shape[1] * pixels.itemsize
    image.pixel_format, image.channel_type = lcmt_image.PIXEL_FORMAT_DEPTH, channel_type
    image.bigendian = False
    data = pixels.astype(pixels.dtype.newbyteorder("<")).tobytes()
    image.compression_method = (lcmt_image.COMPRESSION_METHOD_ZLIB if compress
                                else lcmt_image.COMPRESSION_METHOD_NOT_COMPRESSED)
    image.data = zlib.compress(data) if compress else data
    image.size = len(image.data)
    message = lcmt_image_array()
    message.images, message.num_images = [image], 1
    return message


def test_depth_images_come_in_metres_from_float_metres_or_millimetres_raw_or_compressed():
    metres = np.array([[0.5, 0.75, np.nan], [1.0, 1.25, 1.5]], dtype=np.float32)
    np.testing.assert_array_equal(decode_depth(depth_message(metres, lcmt_image.CHANNEL_TYPE_FLOAT32), 3, 2),
                                  metres)
    millimetres = np.array([[500, 750, 0], [1000, 1250, 1500]], dtype=np.uint16)  # 0: no reading
    for compress in (False, True):
        message = depth_message(millimetres, lcmt_image.CHANNEL_TYPE_UINT16, compress=compress)
        np.testing.assert_allclose(decode_depth(message, 3, 2), metres, rtol=1e-6)
    with pytest.raises(CameraError, match="is 4 x 2 but the camera's intrinsics are for 3 x 2"):
        decode_depth(depth_message(metres, lcmt_image.CHANNEL_TYPE_FLOAT32, width=4), 3, 2)
    with pytest.raises(CameraError, match="channel type 1"):
        decode_depth(depth_message(millimetres.astype(np.uint8), lcmt_image.CHANNEL_TYPE_UINT8), 3, 2)
    empty = lcmt_image_array()
    empty.num_images, empty.images = 1, [lcmt_image()]
    with pytest.raises(CameraError, match="holds no depth image"):
        decode_depth(empty, 3, 2)


def test_driver_channels_are_checked():
    with pytest.raises(ValueError, match="distinct, non-empty"):
        DriverChannels(arm_status="PANDA_COMMAND")
    with pytest.raises(ValueError, match="command_period"):
        DriverChannels(command_period=0.0)


@pytest.mark.slow
def test_a_cell_on_a_robot_grasps_with_a_simulated_robot_in_another_diagram(tmp_path, cube_folder):
    """The controller alone (`build_robot_cell`: HardwareStation, perception, policy, executive judged by the
    jaws) and the simulated robot alone (`build_simulated_robot`), two diagrams with two clocks that share
    nothing but the LCM messages, stepped in turn: the cube is grasped and lifted."""
    from drake_grasp.cell.diagram import build_robot_cell
    from drake_grasp.cell.executive import END_MODES, Mode
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.robot.task import LIFT_HEIGHT
    from drake_grasp.simulation.lcm_drivers import build_simulated_robot
    from drake_grasp.simulation.objects import load_object_set

    yaml = tmp_path / "one_cube.yaml"
    yaml.write_text(one_cube_yaml(max_attempts=1))
    robot, scenario = ROBOTS["panda"], load_scenario(str(yaml))
    channels = DriverChannels(lcm_url="memq://")
    lcm = channels.make_lcm()
    simulated = build_simulated_robot(robot=robot, scenario=scenario, seed=0, channels=channels, lcm=lcm,
                                      object_models=load_object_set(str(cube_folder)))
    cell = build_robot_cell(robot=robot, scenario=scenario, scorer=make_scorer("cnn_rp", robot),
                            channels=channels, lcm=lcm, realtime_rate=0.0)
    plant = simulated.station.plant()

    def cube_z() -> float:
        context = simulated.station.plant_context(simulated.context)
        return plant.EvalBodyPoseInWorld(context, simulated.station.object_bodies[0]).translation()[2]

    def step(seconds: float = 0.01) -> None:
        for simulator in (simulated.simulator, cell.simulator):
            simulator.AdvanceTo(simulator.get_context().get_time() + seconds)

    step(channels.image_period + 0.01)  # (the camera's first image comes with its period)
    cell.hardware.wait_for_drivers(timeout_s=1.0)
    while cell.context.get_time() < scenario.settle_time - 0.05:
        step()
    z0 = cube_z()
    start = cell.context.get_time()
    while cell.task_state().mode not in (Mode.ATTEMPT_DONE, *END_MODES):
        assert cell.context.get_time() - start < 30.0, "no attempt in 30 simulated seconds"
        step()
    attempt = cell.task_state().attempt
    assert attempt.planned and attempt.success and attempt.failure is None, attempt
    assert attempt.object_index is None  # the jaws' judgement: no object identities
    assert cube_z() - z0 >= LIFT_HEIGHT  # and the simulated robot did lift it


def test_the_robot_programs_name_silent_drivers_and_run_a_simulated_robot(capsys, cube_folder, tmp_path):
    from drake_grasp.apps import robot_cell, sim_robot

    # No driver publishes on this in-process network: one line naming the silent channels, exit 2
    assert robot_cell.main(["--lcm-url", "memq://", "--wait", "0.2"]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("error: no message on PANDA_STATUS, SCHUNK_WSG_STATUS, DRAKE_RGBD_CAMERA_IMAGES")
    assert "\n" not in error
    assert robot_cell.main(["--lcm-url", "memq://", "--robot", "kuka"]) == 2
    assert "kuka" in capsys.readouterr().err
    yaml = tmp_path / "one_cube.yaml"
    yaml.write_text(one_cube_yaml(max_attempts=1))
    assert sim_robot.main(["--lcm-url", "memq://", "--scenario", str(yaml), "--objects", str(cube_folder),
                           "--duration", "0.2", "--realtime-rate", "0"]) == 0
    assert "stopped after 0.20 simulated s" in capsys.readouterr().out
    assert sim_robot.main(["--lcm-url", "memq://", "--duration", "0"]) == 2
