"""How the cell learns what its actions did, apart from what it decides (`cell.executive`).

The executive chooses, plans and moves; a judge tells it what came of that, behind one interface
(`AttemptJudge`), so that the same decisions run in the simulator and on a robot:

- `SimulatorJudge`: the simulator's ground truth (body poses and contacts). A grasp held when its object
  rose `LIFT_HEIGHT` and touches both fingers; a push moved an object when one moved 1 cm; the failure
  memory's scene changed when an object moved; the transit's contacts are counted.
- `GripperJudge`: what a robot knows, the gripper's reported opening and the camera's object cloud. A
  grasp held when the jaws are still apart at the end of the hold (jaws that shut after the lift began
  lost their object); the scene changed when the object cloud did. It has no object
  identities, no heights and no contacts (`Judgement.object_index` is None, `rise` NaN), and it judges
  grasps only: a push needs the simulator's judge.

A judge declares the input ports it reads on the executive (`declare_inputs`); the executive gives it
the context at each decision.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue, Value
from pydrake.math import RigidTransform
from pydrake.systems.framework import Context, LeafSystem

from drake_grasp.perception.cloud import ObjectCloud
from drake_grasp.robot.hand import HandSpec
from drake_grasp.robot.task import CLOSED_ON_NOTHING_TEXT, OBJECT_SLIPPED_TEXT, judge_grasp
from drake_grasp.simulation.contacts import between_fingers, touching
from drake_grasp.simulation.placement import FELL_OFF_Z

PUSH_MOVED = 0.01  # a push moved an object this far or farther [m]
PUSHED_NOTHING = "pushed nothing"
CLOUD_CHANGE_SHARE = 0.05  # the object cloud changed when more of either cloud's points than this lie
# farther than the memory's `scene_change` from the other (a real sensor's noise moves a few edge points)


@dataclass(frozen=True)
class Judgement:
    """What an attempt did: success, the failure mode, the object it was about and how far it rose."""

    success: bool
    failure: str | None
    object_index: int | None = None  # the object grasped or pushed, or nearest the grasp (None: unknown)
    rise: float = float("nan")  # how much higher the object ended [m] (NaN: unknown)


class Scene(abc.ABC):
    """What the failure memory compares: the scene when an attempt began."""

    @abc.abstractmethod
    def changed_since(self, earlier: Scene, distance: float) -> bool:
        """Whether something moved `distance` or more between `earlier` and this scene."""

    def nearest_object(self, point: np.ndarray) -> int | None:
        """The object nearest `point` (None: the scene knows no objects)."""
        return None


@dataclass(frozen=True)
class ObjectPositions(Scene):
    """Each object's position (N, 3), NaN for one no longer on the table."""

    p: np.ndarray

    def changed_since(self, earlier: Scene, distance: float) -> bool:
        """An object that moved `distance` or left the table since `earlier` changed the scene; one that
        was already gone did not."""
        assert isinstance(earlier, ObjectPositions)
        gone = np.isnan(self.p).any(axis=1) & np.isnan(earlier.p).any(axis=1)
        moved = np.linalg.norm(self.p - earlier.p, axis=1)
        return bool(np.any(np.where(gone, False, np.nan_to_num(moved, nan=np.inf) >= distance)))

    def nearest_object(self, point: np.ndarray) -> int | None:
        distance = np.linalg.norm(self.p - np.asarray(point), axis=1)
        return None if np.isnan(distance).all() else int(np.nanargmin(distance))


@dataclass(frozen=True)
class ObservedCloud(Scene):
    """The object cloud (M, 3) the camera saw."""

    points: np.ndarray

    def changed_since(self, earlier: Scene, distance: float) -> bool:
        """More than `CLOUD_CHANGE_SHARE` of either cloud's points lie `distance` or farther from the other
        (an object appeared, went or moved); an empty cloud changed from a non-empty one."""
        assert isinstance(earlier, ObservedCloud)
        a, b = self.points, earlier.points
        if len(a) == 0 or len(b) == 0:
            return len(a) != len(b)
        import open3d as o3d

        cloud_a, cloud_b = (o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p)) for p in (a, b))
        far_a = np.asarray(cloud_a.compute_point_cloud_distance(cloud_b)) >= distance
        far_b = np.asarray(cloud_b.compute_point_cloud_distance(cloud_a)) >= distance
        return bool(far_a.mean() > CLOUD_CHANGE_SHARE or far_b.mean() > CLOUD_CHANGE_SHARE)


class AttemptJudge(abc.ABC):
    """The cell's senses for judging: the executive calls these at its decisions (see the module)."""

    judges_pushes: bool = False

    @abc.abstractmethod
    def declare_inputs(self, system: LeafSystem) -> None:
        """Declares the input ports this judge reads on `system` (the executive)."""

    @abc.abstractmethod
    def scene(self, context: Context, cloud: ObjectCloud) -> Scene:
        """The scene as an attempt begins (`cloud`: what the camera sees now)."""

    @abc.abstractmethod
    def grasp(self, context: Context, scene: Scene, X_WG: np.ndarray, finger: float,
              grip: float | None) -> Judgement:
        """A grasp at the end of its hold (`finger` now, `grip` when the lift began)."""

    def empty_close(self, scene: Scene, X_WG: np.ndarray) -> Judgement:
        """The jaws met while closing: nothing between them."""
        return Judgement(False, CLOSED_ON_NOTHING_TEXT, scene.nearest_object(X_WG[:3, 3]))

    def push(self, context: Context, scene: Scene, X_WG: np.ndarray) -> Judgement:
        """A push at its end."""
        raise ValueError(f"{type(self).__name__} judges grasps only: a push needs the simulator's judge")

    def touched_by_robot(self, context: Context) -> set[int]:
        """The objects the arm or hand touches now (empty where the judge cannot tell)."""
        return set()


class SimulatorJudge(AttemptJudge):
    """The simulator's ground truth: body poses and contacts (input ports `body_poses`, `body_contacts`).

    Body indices refer to the plant of `body_poses`: `object_body_indices` the objects,
    `finger_body_indices` the two fingers, `robot_body_indices` the arm and hand; `num_bodies` is the
    plant's body count; `hand` says when the jaws met (`HandSpec.jaws_met`); `success_rule` is one of
    `robot.task.SUCCESS_RULES` (the scenario's).
    """

    judges_pushes = True

    def __init__(self, *, object_body_indices: Sequence[int], finger_body_indices: Sequence[int],
                 robot_body_indices: Sequence[int], num_bodies: int, hand: HandSpec,
                 success_rule: str = "lifted"):
        self._hand = hand
        self._success_rule = success_rule
        self._objects = [int(i) for i in object_body_indices]
        self._fingers = [int(i) for i in finger_body_indices]
        self._robot_bodies = [int(i) for i in robot_body_indices]
        self._num_bodies = num_bodies

    def declare_inputs(self, system: LeafSystem) -> None:
        self._poses_port = system.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()] * self._num_bodies))
        self._contacts_port = system.DeclareAbstractInputPort("body_contacts", Value(frozenset()))

    def _positions(self, context: Context) -> np.ndarray:
        """(N, 3) object positions; NaN for an object no longer on the table (grasped or fallen)."""
        poses = self._poses_port.Eval(context)
        p = np.array([poses[i].translation() for i in self._objects]).reshape(-1, 3)
        p[p[:, 2] < FELL_OFF_Z] = np.nan
        return p

    def scene(self, context: Context, cloud: ObjectCloud) -> ObjectPositions:
        return ObjectPositions(self._positions(context))

    def grasp(self, context: Context, scene: Scene, X_WG: np.ndarray, finger: float,
              grip: float | None) -> Judgement:
        """The task's success rule (the scenario's): lifted LIFT_HEIGHT, or held (risen and touching both
        fingers at the end of the hold, the jaws apart)."""
        assert isinstance(scene, ObjectPositions)
        rise = np.nan_to_num(self._positions(context)[:, 2] - scene.p[:, 2], nan=-np.inf)
        pairs = self._contacts_port.Eval(context)
        in_hand = [k for k, body in enumerate(self._objects) if between_fingers(pairs, body, self._fingers)]
        k = max(in_hand, key=lambda j: rise[j]) if in_hand else scene.nearest_object(X_WG[:3, 3])
        failure = judge_grasp(float(rise[k]), self._hand.jaws_met(finger), k in in_hand, self._success_rule)
        return Judgement(failure is None, failure, k, float(rise[k]))

    def push(self, context: Context, scene: Scene, X_WG: np.ndarray) -> Judgement:
        """A push succeeds when it moved an object on the table `PUSH_MOVED` or more (or off the table)."""
        assert isinstance(scene, ObjectPositions)
        on_table = ~np.isnan(scene.p[:, 0])
        moved = np.linalg.norm(self._positions(context)[on_table] - scene.p[on_table], axis=1)
        success = bool((np.nan_to_num(moved, nan=np.inf) >= PUSH_MOVED).any())  # NaN: fell off the table
        return Judgement(success, None if success else PUSHED_NOTHING, scene.nearest_object(X_WG[:3, 3]))

    def touched_by_robot(self, context: Context) -> set[int]:
        pairs = self._contacts_port.Eval(context)
        return {k for k, body in enumerate(self._objects) if touching(pairs, body, self._robot_bodies)}


class GripperJudge(AttemptJudge):
    """What a robot's gripper reports: its opening (the executive's `hand_state`) through the lift and the
    hold, and the object cloud for the failure memory (see the module); `hand` says when the jaws met
    (`HandSpec.jaws_met`)."""

    def __init__(self, hand: HandSpec):
        self._hand = hand

    def declare_inputs(self, system: LeafSystem) -> None:
        """None: the gripper's opening is the executive's own `hand_state`."""

    def scene(self, context: Context, cloud: ObjectCloud) -> ObservedCloud:
        return ObservedCloud(np.asarray(cloud.points, dtype=float).copy())

    def grasp(self, context: Context, scene: Scene, X_WG: np.ndarray, finger: float,
              grip: float | None) -> Judgement:
        """Held: the jaws are still apart at the end of the hold. How far they closed in between says
        little: a held object settles in the pads (in the packed benchmark's held grasps they closed by up
        to 74 %). Jaws that shut after holding something when the lift began lost it in the lift."""
        if not self._hand.jaws_met(finger):
            return Judgement(True, None)
        held_at_lift = grip is not None and not self._hand.jaws_met(grip)
        return Judgement(False, OBJECT_SLIPPED_TEXT if held_at_lift else CLOSED_ON_NOTHING_TEXT)
