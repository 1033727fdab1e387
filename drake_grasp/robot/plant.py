"""The one plant assembly: arm (or floating mount) + hand + table + objects, for every consumer.

The closed loop's station, the planner's collision model and the grasp-trial
scene all build their MultibodyPlant here, so the hand's mounting, its finger
coupler, the collision filters and the actuator gains cannot drift apart.

The arm's base is welded at the world origin and the hand (`HandSpec`: the robot's, or the
one given) to its flange. Without an arm, the hand rides on a floating mount of 3 prismatic
+ 3 revolute joints (x, y, z, yaw, pitch, roll) driven by implicit PD, a stand-in for a stiff
position-controlled arm (the grasp trials). The hand's coupled joints follow its driven one
(one actuated, the others mirrored: independent fingers push the object sideways).
Gravity is off for the actuated instances, as for a gravity-compensated arm.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.schema import Transform
from pydrake.geometry import CollisionFilterDeclaration, GeometrySet, SceneGraph
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import (
    AddModel,
    AddWeld,
    ModelDirective,
    ModelDirectives,
    Parser,
    ProcessModelDirectives,
)
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    Frame,
    JointActuatorIndex,
    ModelInstanceIndex,
    PrismaticJoint,
    RevoluteJoint,
    RigidBody,
    SpatialInertia,
    UnitInertia,
)
from pydrake.systems.framework import Context

from drake_grasp.robot.config import ControlConfig, PdGains
from drake_grasp.robot.contact_model import fill_contact_model, fill_hand_contact
from drake_grasp.robot.hand import HandSpec, default_hand
from drake_grasp.robot.log import parser_warnings
from drake_grasp.robot.specs import RobotSpec

TABLE_URL = "package://drake_grasp/table.sdf"
TCP_FRAME = "drake_grasp_tcp"  # the hand's TCP (`HandSpec.X_HT` in its hand frame), added to every plant
HAND_FRAME = "drake_grasp_hand"  # the hand frame H (`HandSpec.X_BH`), added where it is not the base link's
MOUNT_AXES = [("x", PrismaticJoint, [1, 0, 0]), ("y", PrismaticJoint, [0, 1, 0]),
              ("z", PrismaticJoint, [0, 0, 1]), ("yaw", RevoluteJoint, [0, 0, 1]),
              ("pitch", RevoluteJoint, [0, 1, 0]), ("roll", RevoluteJoint, [1, 0, 0])]


@dataclass(frozen=True)
class ObjectModel:
    """An object's model file: a shipped set's (`package://drake_grasp/...`) or a user's (`file:///...`),
    and what was changed to make a user's file ready for Drake (`model_files.prepare_object_model`)."""

    name: str
    url: str
    notes: tuple[str, ...] = field(default=(), compare=False, repr=False)


@dataclass
class SceneModels:
    """The model instances of an assembled plant (`arm` or `mount` is None)."""

    robot: RobotSpec | None
    hand_spec: HandSpec
    hand: ModelInstanceIndex
    arm: ModelInstanceIndex | None = None
    mount: ModelInstanceIndex | None = None
    objects: list[ModelInstanceIndex] = field(default_factory=list)
    object_bodies: list[RigidBody] = field(default_factory=list)
    object_names: list[str] = field(default_factory=list)
    filled_contact: list[str] = field(default_factory=list)  # objects that got the project's contact model


def object_instance_name(k: int, model: ObjectModel) -> str:
    return f"obj{k:02d}_{model.name}"


@dataclass(frozen=True)
class FixtureModel:
    """A static model welded to the world (furniture on the table): its file and where its frame is."""

    url: str  # package:// URL or file path (SDF, URDF)
    X_WF: RigidTransform


def fixture_instance_name(k: int) -> str:
    return f"fixture_{k}"


def scene_directives(robot: RobotSpec | None, hand: HandSpec, objects: Sequence[ObjectModel] = (),
                     table_height: float = 0.0, fixtures: Sequence[FixtureModel] = (),
                     ) -> list[ModelDirective]:
    """The arm at the origin with the hand on its flange (or a loose hand), the table, the fixtures, the
    objects."""
    directives = []
    if robot is not None:
        directives += [
            ModelDirective(add_model=AddModel(name=robot.name, file=robot.model_url)),
            ModelDirective(add_weld=AddWeld(parent="world", child=f"{robot.name}::{robot.base_link}")),
        ]
    directives.append(ModelDirective(add_model=AddModel(name="hand", file=Path(hand.model_url).as_uri())))
    if robot is not None:
        X_FH = RigidTransform(RollPitchYaw(np.radians(robot.mount_rpy_deg)), robot.mount_xyz)
        X_FB = X_FH if hand.X_BH.IsExactlyIdentity() else X_FH @ hand.X_BH.inverse()  # (the base link's)
        directives.append(ModelDirective(add_weld=AddWeld(parent=f"{robot.name}::{robot.flange_link}",
                                                          child=f"hand::{hand.base_link}",
                                                          X_PC=Transform(X_FB))))
    X_WTable = Transform(RigidTransform([0.0, 0.0, table_height]))
    directives += [
        ModelDirective(add_model=AddModel(name="table", file=TABLE_URL)),
        ModelDirective(add_weld=AddWeld(parent="world", child="table::table", X_PC=X_WTable)),
    ]
    # (The fixtures are welded by `add_scene`: a URDF has no model frame to weld here.)
    directives += [ModelDirective(add_model=AddModel(name=fixture_instance_name(k), file=fixture.url))
                   for k, fixture in enumerate(fixtures)]
    directives += [ModelDirective(add_model=AddModel(name=object_instance_name(k, m), file=m.url))
                   for k, m in enumerate(objects)]
    return directives


def add_scene(plant: MultibodyPlant, parser: Parser, *, robot: RobotSpec | None, hand: HandSpec | None = None,
              objects: Sequence[ObjectModel] = (), table_height: float = 0.0,
              control: ControlConfig | None = None, fixtures: Sequence[FixtureModel] = ()) -> SceneModels:
    """Adds the scene's models to an unfinalized plant; ValueError names a model that does not load.

    The hand is the robot's; without a robot, `hand` (default: the Franka hand) on the floating mount.

    With `control`, the arm (or mount) and fingers get their PD gains and lose gravity
    (a physics plant); without, the plant is a kinematic model (the planner's, which knows no
    fixtures: the cell sees them). Object geometry without Drake contact properties gets the
    project's compliant hydroelastic model, the hand's gets rigid hydroelastic (`contact_model`).
    """
    hand_spec = robot.hand if robot is not None else hand or default_hand()
    renames = {}
    if robot is not None and robot.model_file:
        renames[robot.model_url.removeprefix("file://")] = robot.model_file
    if hand_spec.model_file and hand_spec.model_file != hand_spec.model_url:
        renames[hand_spec.model_url] = hand_spec.model_file  # (a hand's prepared copy)
    try:
        with parser_warnings("the scene's models", renames=renames):
            directives = scene_directives(robot, hand_spec, objects, table_height, fixtures)
            ProcessModelDirectives(ModelDirectives(directives=directives),
                                   plant, parser)
    except RuntimeError as e:
        message = str(e).splitlines()[0]
        for copy, original in renames.items():
            message = message.replace(copy, original)
        raise ValueError(f"could not load the models: {message}") from None
    for k, fixture in enumerate(fixtures):
        root = plant.get_body(plant.GetBodyIndices(plant.GetModelInstanceByName(fixture_instance_name(k)))[0])
        plant.WeldFrames(plant.world_frame(), root.body_frame(), fixture.X_WF)
    models = SceneModels(robot=robot, hand_spec=hand_spec, hand=plant.GetModelInstanceByName("hand"))
    hand_bodies = [plant.get_body(i) for i in plant.GetBodyIndices(models.hand)]
    fill_hand_contact(plant, parser.scene_graph(), hand_bodies)
    base = plant.GetBodyByName(hand_spec.base_link, models.hand).body_frame()
    X_BH = hand_spec.X_BH
    if X_BH.IsExactlyIdentity():
        hand_frame = base
    else:
        hand_frame = plant.AddFrame(FixedOffsetFrame(HAND_FRAME, base, X_BH))
    plant.AddFrame(FixedOffsetFrame(TCP_FRAME, hand_frame, hand_spec.X_HT))
    for coupled in hand_spec.coupled_joints:
        plant.AddCouplerConstraint(joint0=plant.GetJointByName(hand_spec.driven_joint, models.hand),
                                   joint1=plant.GetJointByName(coupled, models.hand), gear_ratio=1.0)
    if robot is not None:
        models.arm = plant.GetModelInstanceByName(robot.name)
        add_missing_actuators(plant, models.arm, robot)
    elif control is not None:
        models.mount = add_floating_mount(plant, hand_frame, control)
    if control is not None:
        set_gains_and_gravity(plant, models, control)
    models.objects = [plant.GetModelInstanceByName(object_instance_name(k, m)) for k, m in enumerate(objects)]
    models.object_bodies = object_free_bodies(plant, models.objects, objects)
    models.object_names = [m.name for m in objects]
    filled = fill_contact_model(plant, parser.scene_graph(), models.object_bodies)
    models.filled_contact = [models.object_names[models.object_bodies.index(b)] for b in filled]
    return models


def add_missing_actuators(plant: MultibodyPlant, arm: ModelInstanceIndex, robot: RobotSpec) -> None:
    """An actuator, named after its joint, for each arm joint that has none (a URDF without transmissions)."""
    for name, effort in zip(robot.joint_names, robot.effort_max, strict=True):
        if not plant.HasJointActuatorNamed(name, arm):
            plant.AddJointActuator(name, plant.GetJointByName(name, arm), effort)


def set_gains_and_gravity(plant: MultibodyPlant, models: SceneModels, control: ControlConfig) -> None:
    """PD gains of the arm joints and the hand's driven joint (the others follow the coupler), its effort
    limit (the hand's `grip_force`, or a force-controlled grip's, `ControlConfig.grip_force`); gravity off."""
    if models.arm is not None:
        robot = models.robot
        for name, effort in zip(robot.joint_names, robot.effort_max, strict=True):
            gains = PdGains(kp=control.arm_kp_per_effort * effort, kd=control.arm_kd_per_effort * effort)
            plant.GetJointActuatorByName(name, models.arm).set_controller_gains(gains.to_drake())
    finger = driven_actuator(plant, models)
    gains, effort = control.finger_actuation(models.hand_spec.joint_per_metre)
    finger.set_controller_gains(gains.to_drake())
    finger.set_effort_limit(effort if effort is not None else models.hand_spec.grip_force)
    for instance in (models.arm, models.mount, models.hand):
        if instance is not None:
            plant.set_gravity_enabled(instance, False)


def set_hand_positions(plant: MultibodyPlant, q: np.ndarray, models: SceneModels, position: float) -> None:
    """In the plant's positions `q`: the hand's driven joint at `position`, and the joints that move with
    it (`HandSpec.joint_positions`; a finalized plant)."""
    for name, value in models.hand_spec.joint_positions(position).items():
        q[plant.GetJointByName(name, models.hand).position_start()] = value


def set_hand_joints(plant: MultibodyPlant, context: Context, models: SceneModels, position: float) -> None:
    """`set_hand_positions` in a (finalized) plant's context."""
    q = plant.GetPositions(context)
    set_hand_positions(plant, q, models, position)
    plant.SetPositions(context, q)


def hand_open_positions(plant: MultibodyPlant, models: SceneModels) -> np.ndarray:
    """The hand instance's positions with its driven joint open (and those that move with it; a finalized
    plant)."""
    context = plant.CreateDefaultContext()
    set_hand_joints(plant, context, models, models.hand_spec.open_position)
    return plant.GetPositions(context, models.hand)


def driven_actuator(plant: MultibodyPlant, models: SceneModels):
    """The actuator of the hand's driven joint (one named after it is added where the model has none)."""
    joint = plant.GetJointByName(models.hand_spec.driven_joint, models.hand)
    for i in range(plant.num_actuators()):  # (an unfinalized plant lists no actuators by model instance)
        actuator = plant.get_joint_actuator(JointActuatorIndex(i))
        if actuator.joint().index() == joint.index():
            return actuator
    return plant.AddJointActuator(joint.name(), joint, models.hand_spec.grip_force)


def add_floating_mount(plant: MultibodyPlant, hand_frame: Frame,
                       control: ControlConfig) -> ModelInstanceIndex:
    """Joints x, y, z (prismatic, world axes) then yaw, pitch, roll (revolute), welded to the hand frame.

    The chain's rotation is Rz(yaw) Ry(pitch) Rx(roll), Drake's RollPitchYaw. Its
    gimbal lock (pitch = +-90 degrees) only removes a direction of motion, so a held
    hand stays held there.
    """
    mount = plant.AddModelInstance("mount")
    tiny = SpatialInertia(1e-3, np.zeros(3), UnitInertia.SolidSphere(0.01))
    parent = plant.world_frame()
    for name, joint_type, axis in MOUNT_AXES:
        body = plant.AddRigidBody(f"mount_{name}", mount, tiny)
        joint = plant.AddJoint(joint_type(f"mount_{name}", parent, body.body_frame(), axis))
        gains = control.mount_translation if joint_type is PrismaticJoint else control.mount_rotation
        plant.AddJointActuator(f"mount_{name}", joint).set_controller_gains(gains.to_drake())
        parent = body.body_frame()
    plant.WeldFrames(parent, hand_frame)
    return mount


def mount_positions(X_WH: RigidTransform) -> np.ndarray:
    """Mount joint positions (x, y, z, yaw, pitch, roll) that put the hand frame at X_WH."""
    rpy = RollPitchYaw(X_WH.rotation())
    return np.concatenate([X_WH.translation(), [rpy.yaw_angle(), rpy.pitch_angle(), rpy.roll_angle()]])


def object_free_bodies(plant: MultibodyPlant, instances: list[ModelInstanceIndex],
                       objects: Sequence[ObjectModel]) -> list[RigidBody]:
    """The one free body of each object instance; ValueError names an object with more or fewer bodies,
    or one its file fixes in place (a static model, a joint to the world)."""
    out = []
    for instance, model in zip(instances, objects, strict=True):
        bodies = [plant.get_body(i) for i in plant.GetBodyIndices(instance)]
        if len(bodies) != 1:
            raise ValueError(f"object '{model.name}' must have exactly one body, has {len(bodies)}")
        if any(plant.get_joint(j).child_body().index() == bodies[0].index() for j in plant.GetJointIndices()):
            raise ValueError(f"object '{model.name}' is fixed in place by its file (a static model or a "
                             "joint to the world); an object must be a free body")
        out.append(bodies[0])
    return out


def filter_hand_collisions(plant: MultibodyPlant, scene_graph: SceneGraph, models: SceneModels) -> None:
    """No contact among the hand's bodies (palm, fingers) and the wrist links it is mounted on.

    The last links' capsules overlap the hand by design; the fingers meet when closed
    on nothing. Call after `plant.Finalize()`.
    """
    bodies = [plant.get_body(i) for i in plant.GetBodyIndices(models.hand)]
    if models.arm is not None:
        bodies.append(plant.GetFrameByName(models.robot.flange_link, models.arm).body())
        bodies += [plant.get_body(i) for i in plant.GetBodyIndices(models.arm)][-3:]
    ids = [g for b in bodies for g in plant.GetCollisionGeometriesForBody(b)]
    scene_graph.collision_filter_manager().Apply(CollisionFilterDeclaration().ExcludeWithin(GeometrySet(ids)))
