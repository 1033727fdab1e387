"""The station diagram: arm + hand + table + objects in physics, and a depth camera.

Contact model (chosen deliberately, see DRAKE_NOTES.md): discrete SAP at a 2 ms
step with hydroelastic contact and point-contact fallback. Objects are compliant
hydroelastic; fingers, palm and table are rigid hydroelastic; arm links fall back
to point contact. Box-on-box point contact is wrong (one diagonal contact, the
object sinks), and SAP is what makes the implicit PD gains and the finger coupler
work. Data collection and evaluation use this same plant configuration.

The arm and the hand are position controlled by the plant's implicit PD
actuators (gravity disabled for them, as a gravity-compensated arm), tracking
the plant's desired-state input ports of the two instances, which the caller
connects (the grasp executive in `simulate`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.common.schema import Transform
from pydrake.geometry import (
    Box,
    Capsule,
    ClippingRange,
    CollisionFilterDeclaration,
    Convex,
    Cylinder,
    DepthRange,
    DepthRenderCamera,
    Ellipsoid,
    GeometrySet,
    MakeRenderEngineVtk,
    Mesh,
    Meshcat,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    RenderCameraCore,
    RenderEngineVtkParams,
    Role,
    SceneGraph,
    Sphere,
)
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.parsing import (
    AddModel,
    AddWeld,
    ModelDirective,
    ModelDirectives,
    ProcessModelDirectives,
)
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import ModelInstanceIndex, PdControllerGains
from pydrake.perception import BaseField, DepthImageToPointCloud
from pydrake.systems.framework import Context, DiagramBuilder
from pydrake.systems.sensors import CameraInfo, PixelType, RgbdSensor

from drake_grasp.hand import MAX_HALF_OPENING
from drake_grasp.objects import ObjectModel
from drake_grasp.paths import make_parser
from drake_grasp.robots import RobotSpec
from drake_grasp.scenario import CameraSpec, Scenario

TIME_STEP = 0.002
HAND_OPEN = MAX_HALF_OPENING
HAND_CLOSED = 0.0
PARKING_Z = -50.0  # removed objects are parked far below the table


def plant_config() -> MultibodyPlantConfig:
    return MultibodyPlantConfig(
        time_step=TIME_STEP,
        discrete_contact_approximation="sap",
        contact_model="hydroelastic_with_fallback",
    )


@dataclass
class Station:
    """Handles to the parts of a built station; ports are exported by `build_station`."""

    robot: RobotSpec
    plant: MultibodyPlant
    scene_graph: SceneGraph
    arm: ModelInstanceIndex
    hand: ModelInstanceIndex
    objects: list[ModelInstanceIndex]
    object_names: list[str]
    camera: RgbdSensor
    camera_info: CameraInfo
    X_WC: RigidTransform
    cloud: DepthImageToPointCloud
    meshcat: Meshcat | None = None
    object_bodies: list = field(default_factory=list)


class ObjectScene(Protocol):
    """What `place_objects` needs of a scene: the arm station or the floating-hand trial scene."""

    plant: MultibodyPlant
    scene_graph: SceneGraph
    object_bodies: list


def camera_pose(spec: CameraSpec) -> RigidTransform:
    return RigidTransform(RollPitchYaw(np.radians(spec.rpy_deg)), spec.xyz)


def camera_info(spec: CameraSpec) -> CameraInfo:
    return CameraInfo(width=spec.width, height=spec.height, fov_y=math.radians(spec.fov_y_deg))


def robot_directives(robot: RobotSpec, table_height: float = 0.0) -> list[ModelDirective]:
    """The arm welded at the world origin, the hand on its flange, the table top at `table_height`."""
    X_WTable = Transform(RigidTransform([0.0, 0.0, table_height]))
    return [
        ModelDirective(add_model=AddModel(name=robot.name, file=robot.model_url)),
        ModelDirective(add_weld=AddWeld(parent="world", child=f"{robot.name}::{robot.base_link}")),
        ModelDirective(add_model=AddModel(name="hand", file="package://drake_grasp/hand.sdf")),
        ModelDirective(
            add_weld=AddWeld(parent=f"{robot.name}::{robot.flange_link}", child="hand::hand")
        ),
        ModelDirective(add_model=AddModel(name="table", file="package://drake_grasp/table.sdf")),
        ModelDirective(add_weld=AddWeld(parent="world", child="table::table", X_PC=X_WTable)),
    ]


def add_depth_camera(builder: DiagramBuilder, scene_graph: SceneGraph, spec: CameraSpec,
                     ) -> tuple[RgbdSensor, CameraInfo, RigidTransform, DepthImageToPointCloud]:
    """A VTK depth camera fixed in the world and the system turning its image into a world cloud."""
    scene_graph.AddRenderer("vtk", MakeRenderEngineVtk(RenderEngineVtkParams()))
    info = camera_info(spec)
    near, far = spec.depth_range
    depth_camera = DepthRenderCamera(
        RenderCameraCore("vtk", info, ClippingRange(near * 0.5, far * 1.5), RigidTransform()),
        DepthRange(near, far),
    )
    X_WC = camera_pose(spec)
    camera = builder.AddNamedSystem(
        "camera", RgbdSensor(scene_graph.world_frame_id(), X_WC, depth_camera, False)
    )
    builder.Connect(scene_graph.get_query_output_port(), camera.query_object_input_port())
    cloud = builder.AddNamedSystem(
        "depth_to_cloud",
        DepthImageToPointCloud(info, PixelType.kDepth32F, 1.0, BaseField.kXYZs),
    )
    builder.Connect(camera.depth_image_32F_output_port(), cloud.depth_image_input_port())
    builder.Connect(camera.body_pose_in_world_output_port(), cloud.camera_pose_input_port())
    return camera, info, X_WC, cloud


def object_instance_name(k: int, model: ObjectModel) -> str:
    return f"obj{k:02d}_{model.name}"


def filter_wrist_hand_collisions(plant: MultibodyPlant, scene_graph: SceneGraph, robot: RobotSpec,
                                 arm: ModelInstanceIndex, hand: ModelInstanceIndex) -> None:
    """The hand is mounted on the last links, whose capsules overlap it by design."""
    bodies = [plant.GetBodyByName(robot.flange_link, arm)]
    bodies += [plant.get_body(i) for i in plant.GetBodyIndices(arm)][-3:]
    bodies += [plant.get_body(i) for i in plant.GetBodyIndices(hand)]
    ids = [g for b in bodies for g in plant.GetCollisionGeometriesForBody(b)]
    scene_graph.collision_filter_manager().Apply(
        CollisionFilterDeclaration().ExcludeWithin(GeometrySet(ids))
    )


def add_hand_coupler(plant: MultibodyPlant, hand: ModelInstanceIndex) -> None:
    plant.AddCouplerConstraint(
        joint0=plant.GetJointByName("left_finger_joint", hand),
        joint1=plant.GetJointByName("right_finger_joint", hand),
        gear_ratio=1.0,
    )


def set_finger_gains(plant: MultibodyPlant, hand: ModelInstanceIndex) -> None:
    """The driven finger's implicit PD (the other follows through the coupler)."""
    plant.GetJointActuatorByName("left_finger_joint", hand).set_controller_gains(
        PdControllerGains(p=2000.0, d=20.0)
    )


def object_free_bodies(plant: MultibodyPlant, instances: list[ModelInstanceIndex],
                       objects: list[ObjectModel]) -> list:
    """The one body of each object instance; ValueError names an object with more or fewer."""
    out = []
    for instance, model in zip(instances, objects, strict=True):
        bodies = [plant.get_body(i) for i in plant.GetBodyIndices(instance)]
        if len(bodies) != 1:
            raise ValueError(f"object '{model.name}' must have exactly one body, has {len(bodies)}")
        out.append(bodies[0])
    return out


def build_station(
    builder: DiagramBuilder,
    *,
    robot: RobotSpec,
    scenario: Scenario,
    objects: list[ObjectModel],
    meshcat: Meshcat | None = None,
) -> Station:
    """Adds the plant, scene graph, camera and point cloud to `builder`.

    The caller connects the plant's desired-state inputs of `arm` and `hand` and
    reads the world-frame cloud from `cloud.point_cloud_output_port()`.
    """
    plant, scene_graph = AddMultibodyPlant(plant_config(), builder)
    parser = make_parser(plant)
    directives = robot_directives(robot) + [
        ModelDirective(add_model=AddModel(name=object_instance_name(k, m), file=m.url))
        for k, m in enumerate(objects)
    ]
    try:
        ProcessModelDirectives(ModelDirectives(directives=directives), plant, parser)
    except RuntimeError as e:
        raise ValueError(f"could not load the models: {str(e).splitlines()[0]}") from None
    arm = plant.GetModelInstanceByName(robot.name)
    hand = plant.GetModelInstanceByName("hand")
    object_instances = [plant.GetModelInstanceByName(object_instance_name(k, m))
                        for k, m in enumerate(objects)]
    for instance in (arm, hand):
        plant.set_gravity_enabled(instance, False)
    add_hand_coupler(plant, hand)
    for name, effort in zip(robot.joint_names, robot.effort_max, strict=True):
        actuator = plant.GetJointActuatorByName(name, arm)
        actuator.set_controller_gains(PdControllerGains(p=100.0 * effort, d=10.0 * effort))
    set_finger_gains(plant, hand)
    object_bodies = object_free_bodies(plant, object_instances, objects)
    plant.Finalize()
    filter_wrist_hand_collisions(plant, scene_graph, robot, arm, hand)

    camera, info, X_WC, cloud = add_depth_camera(builder, scene_graph, scenario.camera)
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(
            builder, scene_graph, meshcat, MeshcatVisualizerParams(role=Role.kIllustration)
        )
    return Station(
        robot=robot, plant=plant, scene_graph=scene_graph, arm=arm, hand=hand,
        objects=object_instances, object_names=[m.name for m in objects], camera=camera,
        camera_info=info, X_WC=X_WC, cloud=cloud, meshcat=meshcat, object_bodies=object_bodies,
    )


def choose_objects(models: list[ObjectModel], count: int, rng: np.random.Generator) -> list[ObjectModel]:
    """`count` objects drawn uniformly (with replacement) from a set."""
    return [models[i] for i in rng.integers(len(models), size=count)]


def bounding_radius(plant: MultibodyPlant, scene_graph_inspector, body) -> float:
    """Radius of a sphere about the body origin that holds all its collision geometry."""
    radius = 0.0
    for gid in plant.GetCollisionGeometriesForBody(body):
        shape = scene_graph_inspector.GetShape(gid)
        p = np.linalg.norm(scene_graph_inspector.GetPoseInFrame(gid).translation())
        if isinstance(shape, Box):
            r = np.linalg.norm([shape.width(), shape.depth(), shape.height()]) / 2
        elif isinstance(shape, Cylinder):
            r = math.hypot(shape.radius(), shape.length() / 2)
        elif isinstance(shape, Sphere):
            r = shape.radius()
        elif isinstance(shape, Capsule):
            r = shape.radius() + shape.length() / 2
        elif isinstance(shape, Ellipsoid):
            r = max(shape.a(), shape.b(), shape.c())
        elif isinstance(shape, Convex | Mesh):
            hull = shape.GetConvexHull()  # already scaled
            r = max(float(np.linalg.norm(hull.vertex(i))) for i in range(hull.num_vertices()))
        else:
            r = 0.1
        radius = max(radius, p + r)
    return radius


def place_objects(station: ObjectScene, plant_context: Context, scenario: Scenario,
                  rng: np.random.Generator) -> None:
    """Drops the objects at random poses in the scenario's clusters, without overlaps.

    Each object takes a random orientation and a random (x, y) in its cluster, and
    the lowest height at which its bounding sphere clears those placed before it.
    """
    inspector = station.scene_graph.model_inspector()
    placed: list[tuple[np.ndarray, float]] = []
    bodies = iter(station.object_bodies)
    for cluster in scenario.clusters:
        for _ in range(cluster.count):
            body = next(bodies)
            r = bounding_radius(station.plant, inspector, body)
            rho, phi = cluster.radius * math.sqrt(rng.uniform()), rng.uniform(0, 2 * math.pi)
            xy = np.array(cluster.centre) + rho * np.array([math.cos(phi), math.sin(phi)])
            z = scenario.drop_height + r
            candidates = sorted([z] + [
                pz + math.sqrt((pr + r) ** 2 - d2) for p, pr in placed
                if (d2 := float(np.sum((p[:2] - xy) ** 2))) < (pr + r) ** 2
                for pz in [p[2]]
            ])
            for z in candidates:
                if z >= scenario.drop_height + r and all(
                    np.sum((p - [*xy, z]) ** 2) >= (pr + r) ** 2 - 1e-9 for p, pr in placed
                ):
                    break
            quaternion = rng.normal(size=4)
            R = RotationMatrix(Quaternion(quaternion / np.linalg.norm(quaternion)))
            station.plant.SetFreeBodyPose(plant_context, body, RigidTransform(R, [*xy, z]))
            placed.append((np.array([*xy, z]), r))


def park_object(station: Station, plant_context: Context, index: int) -> None:
    """Takes an object out of the scene (the paper removes grasped objects)."""
    body = station.object_bodies[index]
    X = RigidTransform([10.0 + 0.5 * index, 0.0, PARKING_Z])
    station.plant.SetFreeBodyPose(plant_context, body, X)
    station.plant.SetFreeBodySpatialVelocity(plant_context, body, SpatialVelocity(np.zeros(3), np.zeros(3)))
