"""The station: a Diagram of the plant (arm or floating hand, table, objects), scene graph and depth camera.

As Drake's `MakeHardwareStation` does, the station is one Diagram whose ports are
its interface; consumers connect ports and never wire plant internals:

    inputs   arm_desired_state (or mount_desired_state), hand_desired_state
    outputs  arm_state (or mount_state), hand_state (the hand's driven joint: position, velocity),
             body_poses, query_object, contact_results, body_contacts (touching body index pairs),
             depth_image, point_cloud_W

The arm and the hand track their desired states with the plant's implicit PD
actuators (`ControlConfig`'s gains). The camera is a VTK depth camera fixed in the
world; `point_cloud_W` is its image as a world-frame point cloud, joined by the
clouds of the scenario's `extra_cameras` if it has any (`depth_image` stays the first's).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pydrake.geometry import (
    ClippingRange,
    DepthRange,
    DepthRenderCamera,
    MakeRenderEngineVtk,
    RenderCameraCore,
    RenderEngineVtkParams,
    SceneGraph,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant
from pydrake.multibody.tree import BodyIndex
from pydrake.perception import BaseField, DepthImageToPointCloud
from pydrake.systems.framework import Context, Diagram, DiagramBuilder, OutputPort
from pydrake.systems.primitives import MatrixGain
from pydrake.systems.sensors import CameraInfo, PixelType, RgbdSensor

from drake_grasp.perception.camera import CameraConfig
from drake_grasp.perception.cloud import PointCloudFusion
from drake_grasp.robot.hand import HandSpec
from drake_grasp.robot.paths import make_parser
from drake_grasp.robot.plant import SceneModels, add_scene, filter_hand_collisions, set_hand_joints
from drake_grasp.robot.specs import RobotSpec
from drake_grasp.simulation.contacts import BodyContacts
from drake_grasp.simulation.depth_noise import DepthNoiseSystem
from drake_grasp.simulation.objects import ObjectModel
from drake_grasp.simulation.scenario import Scenario


def driven_joint_selection(plant: MultibodyPlant, models: SceneModels) -> np.ndarray:
    """(2, 2 n) the hand's driven joint's position and velocity out of its model instance's state."""
    joints = [plant.get_joint(i) for i in plant.GetJointIndices(models.hand)]
    first_q = min(j.position_start() for j in joints if j.num_positions())
    first_v = min(j.velocity_start() for j in joints if j.num_velocities())
    driven = plant.GetJointByName(models.hand_spec.driven_joint, models.hand)
    nq, nv = plant.num_positions(models.hand), plant.num_velocities(models.hand)
    select = np.zeros((2, nq + nv))
    select[0, driven.position_start() - first_q] = 1.0
    select[1, nq + driven.velocity_start() - first_v] = 1.0
    return select


def camera_info(camera: CameraConfig) -> CameraInfo:
    """Drake's intrinsics of `camera`."""
    return CameraInfo(width=camera.width, height=camera.height, focal_x=camera.fx, focal_y=camera.fy,
                      center_x=camera.cx, center_y=camera.cy)


class Station(Diagram):
    """The simulated cell of one scenario. `robot=None` mounts `hand` (default: the Franka hand) on a
    floating mount; an arm carries its own hand."""

    def __init__(self, *, scenario: Scenario, robot: RobotSpec | None, objects: Sequence[ObjectModel],
                 noise_seed: int = 0, hand: HandSpec | None = None):
        super().__init__()
        self.set_name("station")
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlant(scenario.plant_config, builder)
        models = add_scene(plant, make_parser(plant), robot=robot, hand=hand, objects=objects,
                           control=scenario.control,
                           fixtures=[f.to_model() for f in scenario.fixtures])
        plant.Finalize()
        filter_hand_collisions(plant, scene_graph, models)
        self.scenario, self.robot, self.models = scenario, robot, models
        self.camera_info = camera_info(scenario.sensing.camera)
        self.X_WC = scenario.sensing.camera.X_BC  # the base frame is the world frame

        driven = ("arm", models.arm) if models.arm is not None else ("mount", models.mount)
        for name, instance in (driven, ("hand", models.hand)):
            builder.ExportInput(plant.get_desired_state_input_port(instance), f"{name}_desired_state")
        name, instance = driven
        builder.ExportOutput(plant.get_state_output_port(instance), f"{name}_state")
        driven_joint = builder.AddNamedSystem("hand_driven_joint",
                                              MatrixGain(driven_joint_selection(plant, models)))
        builder.Connect(plant.get_state_output_port(models.hand), driven_joint.get_input_port())
        builder.ExportOutput(driven_joint.get_output_port(), "hand_state")
        builder.ExportOutput(plant.get_body_poses_output_port(), "body_poses")
        builder.ExportOutput(plant.get_contact_results_output_port(), "contact_results")
        contacts = builder.AddNamedSystem("body_contacts", BodyContacts(plant))
        builder.Connect(plant.get_contact_results_output_port(), contacts.GetInputPort("contact_results"))
        builder.ExportOutput(contacts.GetOutputPort("body_contacts"), "body_contacts")
        builder.ExportOutput(scene_graph.get_query_output_port(), "query_object")
        scene_graph.AddRenderer("vtk", MakeRenderEngineVtk(RenderEngineVtkParams()))
        cameras = scenario.sensing.cameras
        outputs = [self._add_depth_camera(builder, scene_graph, spec, k, noise_seed + k)
                   for k, spec in enumerate(cameras)]
        builder.ExportOutput(outputs[0][0], "depth_image")
        if len(cameras) == 1:
            builder.ExportOutput(outputs[0][1], "point_cloud_W")
        else:  # one world-frame cloud of every camera's points
            fusion = builder.AddNamedSystem("cloud_fusion", PointCloudFusion(len(cameras)))
            for k, (_, cloud) in enumerate(outputs):
                builder.Connect(cloud, fusion.GetInputPort(f"cloud_{k}"))
            builder.ExportOutput(fusion.GetOutputPort("point_cloud_W"), "point_cloud_W")
        builder.BuildInto(self)
        self._plant, self._scene_graph = plant, scene_graph

    def _add_depth_camera(self, builder: DiagramBuilder, scene_graph: SceneGraph, spec: CameraConfig, k: int,
                          noise_seed: int) -> tuple[OutputPort, OutputPort]:
        """Camera k ("camera", then "camera_1", ...): its depth image and world-frame cloud output ports."""
        suffix = f"_{k}" if k else ""
        info = camera_info(spec)
        near, far = spec.depth_range
        depth_camera = DepthRenderCamera(
            RenderCameraCore("vtk", info, ClippingRange(near * 0.5, far * 1.5), RigidTransform()),
            DepthRange(near, far),
        )
        sensor = RgbdSensor(scene_graph.world_frame_id(), spec.X_BC, depth_camera, False)
        camera = builder.AddNamedSystem(f"camera{suffix}", sensor)
        builder.Connect(scene_graph.get_query_output_port(), camera.query_object_input_port())
        to_cloud = builder.AddNamedSystem(f"depth_to_cloud{suffix}", DepthImageToPointCloud(
            info, PixelType.kDepth32F, 1.0, BaseField.kXYZs))
        depth = camera.depth_image_32F_output_port()
        if self.scenario.depth_noise.enabled:  # the camera's image through the sensor noise model
            noise = builder.AddNamedSystem(f"depth_noise{suffix}", DepthNoiseSystem(
                self.scenario.depth_noise, width=info.width(), height=info.height(), seed=noise_seed))
            builder.Connect(depth, noise.get_input_port())
            depth = noise.get_output_port()
        builder.Connect(depth, to_cloud.depth_image_input_port())
        builder.Connect(camera.body_pose_in_world_output_port(), to_cloud.camera_pose_input_port())
        return depth, to_cloud.point_cloud_output_port()

    # -- access for drivers that set state (placing objects, resets) -------------------------
    def plant(self) -> MultibodyPlant:
        return self._plant

    def scene_graph(self) -> SceneGraph:
        return self._scene_graph

    def plant_context(self, root_context: Context) -> Context:
        """The plant's (mutable) context inside a root context that holds this station."""
        return self._plant.GetMyMutableContextFromRoot(root_context)

    @property
    def object_bodies(self) -> list:
        return self.models.object_bodies

    @property
    def finger_bodies(self) -> list[int]:
        """Body indices of the two fingers."""
        return [int(self._plant.GetBodyByName(name, self.models.hand).index())
                for name in self.models.hand_spec.fingers]

    def finger_positions(self, root_context: Context) -> np.ndarray:
        """(2, 3) where the fingers' bodies are in the world (the focus of sleeping objects)."""
        plant, plant_context = self._plant, self.plant_context(root_context)
        return np.array([plant.EvalBodyPoseInWorld(plant_context, plant.get_body(BodyIndex(i))).translation()
                         for i in self.finger_bodies])

    @property
    def robot_bodies(self) -> list[int]:
        """Body indices of the moving links of the arm (or mount) and the hand (not the fixed base)."""
        driven = self.models.arm if self.models.arm is not None else self.models.mount
        fixed = {int(b.index()) for b in self._plant.GetBodiesWeldedTo(self._plant.world_body())}
        return [int(i) for instance in (driven, self.models.hand)
                for i in self._plant.GetBodyIndices(instance) if int(i) not in fixed]

    def set_home(self, root_context: Context) -> None:
        """The arm at its home configuration and the hand open, both at rest."""
        plant, plant_context, models = self._plant, self.plant_context(root_context), self.models
        plant.SetPositions(plant_context, models.arm, self.robot.q_home)
        plant.SetVelocities(plant_context, models.arm, np.zeros(self.robot.num_joints))
        set_hand_open(plant, plant_context, models)


def set_hand_open(plant: MultibodyPlant, plant_context: Context, models: SceneModels) -> None:
    """The hand's driven and coupled joints at its open command, the hand at rest."""
    set_hand_joints(plant, plant_context, models, models.hand_spec.open_position)
    plant.SetVelocities(plant_context, models.hand, np.zeros(plant.num_velocities(models.hand)))
