"""Self-supervised grasp trials in physics: a floating hand grasps one object on the table.

The trial scene is the closed-loop station without the arm: the same table, the
same hand (`hand.sdf`), the same plant configuration and contact model
(`station.plant_config`: discrete SAP at 2 ms, hydroelastic with point fallback),
the same depth camera and perception. The hand rides on a floating mount of
3 prismatic + 3 revolute joints (x, y, z, yaw, pitch, roll) held by the plant's
implicit PD actuators with gravity off, standing in for a stiff, gravity-
compensated arm; the fingers are coupled and close with the same 20 N per finger.

One trial of a grasp X_WG (paper Sec. IV-D), from the settled scene each time:
1. approach: the open hand must get from the pre-grasp (10 cm back along the
   approach axis) to the grasp without touching the object or the table, checked
   on Drake's collision geometry at `APPROACH_CHECKS` poses along the way
   ("hand collides on approach": no physics needed, the rigidly held hand would
   have pushed the object or stopped at the table);
2. close the fingers (`CLOSE_DURATION`), lift the hand 20 cm in `LIFT_DURATION`
   and hold it (`HOLD_DURATION`), in physics, with the executive's timings;
3. judge with the executive's own rule (`executive.judge_lift`): label 1 when the
   object ends at least `LIFT_HEIGHT` (15 cm) higher, else "closed on nothing",
   "object slipped" or "not lifted".
"""

from __future__ import annotations

import copy
import enum
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import (
    AddModel,
    AddWeld,
    ModelDirective,
    ModelDirectives,
    ProcessModelDirectives,
)
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant
from pydrake.multibody.tree import (
    ModelInstanceIndex,
    PdControllerGains,
    PrismaticJoint,
    RevoluteJoint,
    SpatialInertia,
    UnitInertia,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context, DiagramBuilder
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from drake_grasp.executive import CLOSE_DURATION, HOLD_DURATION, judge_lift
from drake_grasp.hand import LIFT_HEIGHT, PREGRASP_DISTANCE, X_GH
from drake_grasp.objects import ObjectModel
from drake_grasp.paths import make_parser
from drake_grasp.perception import ObjectCloud, extract_object_cloud
from drake_grasp.planner import LIFT_EXTRA
from drake_grasp.scenario import Scenario
from drake_grasp.station import (
    HAND_CLOSED,
    HAND_OPEN,
    add_depth_camera,
    add_hand_coupler,
    object_free_bodies,
    object_instance_name,
    place_objects,
    plant_config,
    set_finger_gains,
)

LIFT_DURATION = 1.0  # [s], the planner's shortest lift segment
APPROACH_CHECKS = 11  # hand poses checked from the pre-grasp to the grasp: every 1 cm
X_W_PARK = RigidTransform([-1.0, 0.0, 1.0])  # the hand waits out of the camera's view
# Mount gains: stiff like the position-controlled arm (its joints use p = 100 x effort).
TRANSLATION_GAINS = PdControllerGains(p=2.0e4, d=4.0e2)  # [N/m], [N s/m]
ROTATION_GAINS = PdControllerGains(p=5.0e2, d=5.0)  # [N m/rad], [N m s/rad]


class TrialOutcome(enum.IntEnum):
    """Stored as uint8 codes in the data shards."""

    SUCCESS = 0
    COLLIDES_ON_APPROACH = 1
    CLOSED_ON_NOTHING = 2
    OBJECT_SLIPPED = 3
    NOT_LIFTED = 4

    @property
    def text(self) -> str:
        return OUTCOME_TEXT[self]


OUTCOME_TEXT = {
    TrialOutcome.SUCCESS: "success",
    TrialOutcome.COLLIDES_ON_APPROACH: "hand collides on approach",
    TrialOutcome.CLOSED_ON_NOTHING: "closed on nothing",
    TrialOutcome.OBJECT_SLIPPED: "object slipped",
    TrialOutcome.NOT_LIFTED: "not lifted",
}
_FROM_JUDGE = {None: TrialOutcome.SUCCESS, "closed on nothing": TrialOutcome.CLOSED_ON_NOTHING,
               "object slipped": TrialOutcome.OBJECT_SLIPPED, "not lifted": TrialOutcome.NOT_LIFTED}


def mount_positions(X_WH: RigidTransform) -> np.ndarray:
    """Mount joint positions (x, y, z, yaw, pitch, roll) that put the hand frame at X_WH."""
    rpy = RollPitchYaw(X_WH.rotation())
    return np.concatenate([X_WH.translation(), [rpy.yaw_angle(), rpy.pitch_angle(), rpy.roll_angle()]])


def add_floating_mount(plant: MultibodyPlant, hand: ModelInstanceIndex) -> ModelInstanceIndex:
    """Joints x, y, z (prismatic, world axes) then yaw, pitch, roll (revolute), welded to the hand.

    The chain's rotation is Rz(yaw) Ry(pitch) Rx(roll), Drake's RollPitchYaw. Its
    gimbal lock (pitch = +-90 degrees) only removes a direction of motion, so a
    held hand stays held there.
    """
    mount = plant.AddModelInstance("mount")
    tiny = SpatialInertia(1e-3, np.zeros(3), UnitInertia.SolidSphere(0.01))
    parent = plant.world_frame()
    axes = [("x", PrismaticJoint, [1, 0, 0]), ("y", PrismaticJoint, [0, 1, 0]),
            ("z", PrismaticJoint, [0, 0, 1]), ("yaw", RevoluteJoint, [0, 0, 1]),
            ("pitch", RevoluteJoint, [0, 1, 0]), ("roll", RevoluteJoint, [1, 0, 0])]
    for name, joint_type, axis in axes:
        body = plant.AddRigidBody(f"mount_{name}", mount, tiny)
        joint = plant.AddJoint(joint_type(f"mount_{name}", parent, body.body_frame(), axis))
        actuator = plant.AddJointActuator(f"mount_{name}", joint)
        gains = TRANSLATION_GAINS if joint_type is PrismaticJoint else ROTATION_GAINS
        actuator.set_controller_gains(gains)
        parent = body.body_frame()
    plant.WeldFrames(parent, plant.GetFrameByName("hand", hand))
    plant.set_gravity_enabled(mount, False)
    plant.set_gravity_enabled(hand, False)
    return mount


@dataclass
class TrialResult:
    outcome: TrialOutcome
    rise: float  # how much higher the object ended [m]

    @property
    def success(self) -> bool:
        return self.outcome is TrialOutcome.SUCCESS


class GraspTrialScene:
    """One object on the table, a depth camera and the floating hand, ready for many trials."""

    def __init__(self, scenario: Scenario, model: ObjectModel):
        self.scenario = scenario
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlant(plant_config(), builder)
        directives = [
            ModelDirective(add_model=AddModel(name="hand", file="package://drake_grasp/hand.sdf")),
            ModelDirective(add_model=AddModel(name="table", file="package://drake_grasp/table.sdf")),
            ModelDirective(add_weld=AddWeld(parent="world", child="table::table")),
            ModelDirective(add_model=AddModel(name=object_instance_name(0, model), file=model.url)),
        ]
        try:
            ProcessModelDirectives(ModelDirectives(directives=directives), plant, make_parser(plant))
        except RuntimeError as e:
            raise ValueError(f"could not load the models: {str(e).splitlines()[0]}") from None
        self.hand = plant.GetModelInstanceByName("hand")
        self.mount = add_floating_mount(plant, self.hand)
        add_hand_coupler(plant, self.hand)
        set_finger_gains(plant, self.hand)
        instance = plant.GetModelInstanceByName(object_instance_name(0, model))
        self.object_bodies = object_free_bodies(plant, [instance], [model])
        plant.Finalize()
        self.plant, self.scene_graph = plant, scene_graph
        self.camera, _, self.X_WC, self.cloud = add_depth_camera(builder, scene_graph, scenario.camera)
        q_park = mount_positions(X_W_PARK)
        self._mount_source = builder.AddNamedSystem(
            "mount_command", TrajectorySource(PiecewisePolynomial(q_park.reshape(-1, 1)), 1))
        builder.Connect(self._mount_source.get_output_port(), plant.get_desired_state_input_port(self.mount))
        self.diagram = builder.Build()
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        self._hand_geometries = {g for i in plant.GetBodyIndices(self.hand)
                                 for g in plant.GetCollisionGeometriesForBody(plant.get_body(i))}
        self._settled: Context | None = None
        self._z_settled = 0.0

    # -- the scene ------------------------------------------------------------------------
    def _set_hand(self, X_WH: RigidTransform, finger: float) -> None:
        plant, context = self.plant, self.plant_context
        plant.SetPositions(context, self.mount, mount_positions(X_WH))
        plant.SetVelocities(context, self.mount, np.zeros(6))
        plant.SetPositions(context, self.hand, [finger, finger])
        plant.SetVelocities(context, self.hand, np.zeros(2))

    def settle(self, rng: np.random.Generator) -> None:
        """Drops the object at a random pose (the scenario's cluster) and lets it come to rest."""
        self.context.SetTime(0.0)
        place_objects(self, self.plant_context, self.scenario, rng)
        self._set_hand(X_W_PARK, HAND_OPEN)
        self._command(PiecewisePolynomial(mount_positions(X_W_PARK).reshape(-1, 1)), HAND_OPEN)
        self.simulator.Initialize()
        self.simulator.AdvanceTo(self.scenario.settle_time)
        self._settled = copy.deepcopy(self.context)
        self._z_settled = self.object_pose().translation()[2]

    def object_pose(self) -> RigidTransform:
        return self.plant.EvalBodyPoseInWorld(self.plant_context, self.object_bodies[0])

    def observe(self) -> ObjectCloud:
        """The object cloud as the closed loop sees it: depth image -> crop -> RANSAC -> normals."""
        points = self.cloud.point_cloud_output_port().Eval(
            self.cloud.GetMyContextFromRoot(self.context)).xyzs().T
        return extract_object_cloud(points, lower=self.scenario.workspace_min,
                                    upper=self.scenario.workspace_max,
                                    camera_position=self.X_WC.translation())

    def _command(self, mount: PiecewisePolynomial, finger: float) -> None:
        self._mount_source.UpdateTrajectory(mount)
        self.plant.get_desired_state_input_port(self.hand).FixValue(self.plant_context, [finger, 0.0])

    # -- one trial ------------------------------------------------------------------------
    def _reset(self) -> None:
        if self._settled is None:
            raise RuntimeError("settle() the scene before running trials")
        self.context.SetTimeStateAndParametersFrom(self._settled)

    def hand_touches_something(self) -> bool:
        query = self.plant.get_geometry_query_input_port().Eval(self.plant_context)
        return any(p.id_A in self._hand_geometries or p.id_B in self._hand_geometries
                   for p in query.ComputePointPairPenetration())

    def approach_collides(self, X_WG: RigidTransform) -> bool:
        """Whether the open hand touches anything on its way from the pre-grasp to the grasp."""
        self._reset()
        X_WH = X_WG @ X_GH
        for s in np.linspace(1.0, 0.0, APPROACH_CHECKS):
            self._set_hand(X_WH @ RigidTransform([0.0, 0.0, -s * PREGRASP_DISTANCE]), HAND_OPEN)
            if self.hand_touches_something():
                return True
        return False

    def run(self, X_WG: np.ndarray | RigidTransform) -> TrialResult:
        """Approach check, then close, lift and hold in physics; the executive's success rule."""
        X_WG = X_WG if isinstance(X_WG, RigidTransform) else RigidTransform(np.asarray(X_WG))
        if self.approach_collides(X_WG):
            return TrialResult(TrialOutcome.COLLIDES_ON_APPROACH, 0.0)
        self._reset()
        X_WH = X_WG @ X_GH
        self._set_hand(X_WH, HAND_OPEN)
        q_grasp = mount_positions(X_WH)
        q_lift = q_grasp + [0.0, 0.0, LIFT_HEIGHT + LIFT_EXTRA, 0.0, 0.0, 0.0]
        t0 = self.context.get_time()
        times = t0 + np.cumsum([0.0, CLOSE_DURATION, LIFT_DURATION, HOLD_DURATION])
        knots = np.column_stack([q_grasp, q_grasp, q_lift, q_lift])
        self._command(PiecewisePolynomial.CubicHermite(times, knots, np.zeros_like(knots)), HAND_CLOSED)
        self.simulator.Initialize()
        self.simulator.AdvanceTo(times[-1])
        rise = float(self.object_pose().translation()[2] - self._z_settled)
        finger = float(self.plant.GetPositions(self.plant_context, self.hand)[0])
        return TrialResult(_FROM_JUDGE[judge_lift(rise, finger)], rise)
