"""Sleeping objects: what rests away from the hand is locked, so the contact solver carries only what moves.

In a pile of 30 objects most bodies lie still through an attempt, yet each one
stays an unknown of every contact solve. Objects that have rested for a while and
lie away from the action are locked (`RigidBody.Lock`: zero velocity, out of the
solver's unknowns) and their contacts with each other and with the fixed world
(the table) are filtered out of the geometry queries, which otherwise compute a
hydroelastic contact surface for every touching pair at every step. Contacts
between a sleeping object and anything awake stay, so a sleeping object still
holds up what rests on it. An object is unlocked, and its filters lifted, the
moment the action comes near:

- an object falls asleep after `rest_s` with speed under `rest_speed` and angular
  speed under `rest_angular_speed`, when no focus point (the hand, the grasp point
  of the attempt in progress) is within `awake_radius` of its bounding sphere;
- it wakes when a focus point comes that close, or when it touches the robot or an
  awake object that moves.

The driver calls `update` between short simulation steps (the cell polls every
0.1 s); a wake-up is therefore late by at most one poll, which `awake_radius`
covers at the arm's speeds. Off by default: a scenario turns it on with
`object_sleep: {enabled: true}`.
"""

# No `from __future__ import annotations`: yaml_load_typed reads the dataclass field types.
import dataclasses as dc
from collections.abc import Sequence

import numpy as np
from pydrake.geometry import (
    Box,
    Capsule,
    CollisionFilterDeclaration,
    Convex,
    Cylinder,
    Ellipsoid,
    FilterId,
    GeometrySet,
    Mesh,
    SceneGraph,
    SceneGraphInspector,
    Sphere,
)
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import RigidBody
from pydrake.systems.framework import Context

from drake_grasp.simulation.contacts import BodyPairs


@dc.dataclass
class ObjectSleepConfig:
    """When objects sleep and wake (see the module docstring)."""

    enabled: bool = False
    rest_speed: float = 0.005  # [m/s]
    rest_angular_speed: float = 0.05  # [rad/s]
    rest_s: float = 0.3  # at rest this long before sleeping [s]
    awake_radius: float = 0.06  # a focus point this close to an object's bounding sphere keeps it awake [m]


def bounding_radius(inspector: SceneGraphInspector, plant: MultibodyPlant, body: RigidBody) -> float:
    """The radius of a sphere about the body's origin that holds all its collision geometry."""
    radius = 0.0
    for geometry in plant.GetCollisionGeometriesForBody(body):
        X_BS = inspector.GetPoseInFrame(geometry)
        shape = inspector.GetShape(geometry)
        if isinstance(shape, Sphere):
            reach = shape.radius()
        elif isinstance(shape, Box):
            reach = 0.5 * float(np.linalg.norm(shape.size()))
        elif isinstance(shape, Cylinder):
            reach = float(np.hypot(shape.radius(), 0.5 * shape.length()))
        elif isinstance(shape, Capsule):
            reach = shape.radius() + 0.5 * shape.length()
        elif isinstance(shape, Ellipsoid):
            reach = max(shape.a(), shape.b(), shape.c())
        elif isinstance(shape, Mesh | Convex):
            hull = shape.GetConvexHull()
            reach = max(float(np.linalg.norm(hull.vertex(i))) for i in range(hull.num_vertices()))
        else:
            raise ValueError(f"cannot bound a {type(shape).__name__} for sleeping")
        radius = max(radius, float(np.linalg.norm(X_BS.translation())) + reach)
    return radius


class ObjectSleep:
    """Locks resting objects away from the focus points and unlocks them when the action comes near."""

    def __init__(self, plant: MultibodyPlant, scene_graph: SceneGraph, object_bodies: Sequence[RigidBody],
                 robot_body_indices: Sequence[int], config: ObjectSleepConfig):
        self._plant, self._scene_graph, self.config = plant, scene_graph, config
        self._bodies = list(object_bodies)
        self._index_of = {int(b.index()): k for k, b in enumerate(self._bodies)}  # body index -> object
        self._robot = {int(i) for i in robot_body_indices}
        inspector = scene_graph.model_inspector()
        self._radius = np.array([bounding_radius(inspector, plant, b) for b in self._bodies])
        self._geometries = [list(plant.GetCollisionGeometriesForBody(b)) for b in self._bodies]
        self._fixed_geometries = [g for b in plant.GetBodiesWeldedTo(plant.world_body())
                                  for g in plant.GetCollisionGeometriesForBody(b)]
        self._rest_since: list[float | None] = [None] * len(self._bodies)
        self._filter: tuple[frozenset, FilterId] | None = None  # the sleepers it filters, its id

    def forget(self) -> None:
        """Forgets rest times and filters, after the context was reset to a state without locks or filters."""
        self._rest_since = [None] * len(self._bodies)
        self._filter = None

    def asleep(self, plant_context: Context) -> np.ndarray:
        """Which objects are locked, as a boolean array."""
        return np.array([b.is_locked(plant_context) for b in self._bodies], bool)

    def update(self, root_context: Context, focus_W: np.ndarray, contacts: BodyPairs) -> None:
        """Puts objects to sleep and wakes them for the state in `root_context` (see the module docstring).

        `focus_W`: (k, 3) points where the action is; `contacts`: the touching body pairs."""
        if not self.config.enabled:
            return
        plant_context = self._plant.GetMyMutableContextFromRoot(root_context)
        self._sleep_and_wake(plant_context, focus_W, contacts)
        self._filter_sleepers(self._scene_graph.GetMyMutableContextFromRoot(root_context),
                              frozenset(np.flatnonzero(self.asleep(plant_context)).tolist()))

    def _filter_sleepers(self, scene_graph_context: Context, sleepers: frozenset) -> None:
        """No contact queries among the sleeping objects and the fixed world: replaces the last filter."""
        if self._filter is not None and self._filter[0] == sleepers:
            return
        manager = self._scene_graph.collision_filter_manager(scene_graph_context)
        if self._filter is not None:
            manager.RemoveDeclaration(self._filter[1])
            self._filter = None
        if sleepers:
            geometries = [g for k in sorted(sleepers) for g in self._geometries[k]] + self._fixed_geometries
            self._filter = (sleepers, manager.ApplyTransient(
                CollisionFilterDeclaration().ExcludeWithin(GeometrySet(geometries))))

    def _sleep_and_wake(self, plant_context: Context, focus_W: np.ndarray, contacts: BodyPairs) -> None:
        plant, config, t = self._plant, self.config, plant_context.get_time()
        p_WO = np.array([plant.EvalBodyPoseInWorld(plant_context, b).translation() for b in self._bodies])
        focus_W = np.asarray(focus_W, float).reshape(-1, 3)
        if len(focus_W):
            gap = np.linalg.norm(p_WO[:, None, :] - focus_W[None, :, :], axis=2).min(axis=1) - self._radius
            near = gap < config.awake_radius
        else:
            near = np.zeros(len(self._bodies), bool)
        asleep = self.asleep(plant_context)
        moving = np.zeros(len(self._bodies), bool)
        for k, body in enumerate(self._bodies):
            if asleep[k]:
                continue
            V = plant.EvalBodySpatialVelocityInWorld(plant_context, body)
            at_rest = (np.linalg.norm(V.translational()) < config.rest_speed
                       and np.linalg.norm(V.rotational()) < config.rest_angular_speed)
            moving[k] = not at_rest
            if not at_rest:
                self._rest_since[k] = None
            elif self._rest_since[k] is None:
                self._rest_since[k] = t
        stirred = self._robot | {int(b.index()) for b, m in zip(self._bodies, moving, strict=True) if m}
        touched = set()
        for a, b in contacts:
            for mine, other in ((a, b), (b, a)):
                if mine in self._index_of and other in stirred:
                    touched.add(self._index_of[mine])
        for k, body in enumerate(self._bodies):
            if asleep[k] and (near[k] or k in touched):
                body.Unlock(plant_context)
                self._rest_since[k] = None
            elif (not asleep[k] and not near[k] and self._rest_since[k] is not None
                  and t - self._rest_since[k] >= config.rest_s):
                body.Lock(plant_context)
