"""Putting objects into a scene: random drops in the scenario's clusters, and parking removed ones."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import Box, Capsule, Convex, Cylinder, Ellipsoid, Mesh, SceneGraphInspector, Sphere
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import RigidBody
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context

from drake_grasp.simulation.objects import ObjectModel
from drake_grasp.simulation.scenario import Cluster, Scenario

PARKING_Z = -50.0  # removed objects are parked far below the table [m]
FELL_OFF_Z = -0.2  # an object this far below the table top has left the table [m]
MAX_REDROPS = 3  # settles after which an object that keeps rolling away is left where it lies


def choose_objects(models: Sequence[ObjectModel], count: int, rng: np.random.Generator) -> list[ObjectModel]:
    """`count` objects drawn uniformly (with replacement) from a set."""
    return [models[i] for i in rng.integers(len(models), size=count)]


def bounding_radius(plant: MultibodyPlant, inspector: SceneGraphInspector, body: RigidBody) -> float:
    """Radius of a sphere about the body origin that holds all its collision geometry."""
    radius = 0.0
    for gid in plant.GetCollisionGeometriesForBody(body):
        shape = inspector.GetShape(gid)
        p = np.linalg.norm(inspector.GetPoseInFrame(gid).translation())
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


def _random_xy(cluster: Cluster, rng: np.random.Generator) -> np.ndarray:
    """A point uniformly distributed on the cluster's disc."""
    rho, phi = cluster.radius * math.sqrt(rng.uniform()), rng.uniform(0, 2 * math.pi)
    return np.array(cluster.centre) + rho * np.array([math.cos(phi), math.sin(phi)])


def _random_rotation(rng: np.random.Generator) -> RotationMatrix:
    quaternion = rng.normal(size=4)
    return RotationMatrix(Quaternion(quaternion / np.linalg.norm(quaternion)))


def place_objects(plant: MultibodyPlant, plant_context: Context, inspector: SceneGraphInspector,
                  bodies: Sequence[RigidBody], scenario: Scenario, rng: np.random.Generator) -> None:
    """Drops the objects at random poses in the scenario's clusters, without overlaps.

    Each object takes a random orientation and a random (x, y) in its cluster, and
    the lowest height at which its bounding sphere clears those placed before it.
    """
    placed: list[tuple[np.ndarray, float]] = []
    remaining = iter(bodies)
    for cluster in scenario.clusters:
        for _ in range(cluster.count):
            body = next(remaining)
            r = bounding_radius(plant, inspector, body)
            xy = _random_xy(cluster, rng)
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
            plant.SetFreeBodyPose(plant_context, body, RigidTransform(_random_rotation(rng), [*xy, z]))
            placed.append((np.array([*xy, z]), r))


def object_clusters(scenario: Scenario) -> list[Cluster]:
    """The cluster of each object, in the scene's object order."""
    return [cluster for cluster in scenario.clusters for _ in range(cluster.count)]


def strays(plant: MultibodyPlant, plant_context: Context, bodies: Sequence[RigidBody],
           scenario: Scenario) -> np.ndarray:
    """Indices of the objects resting farther than `scenario.settle_within` from their cluster's centre
    (or off the table); none when the scenario keeps objects where they lie."""
    if scenario.settle_within <= 0:
        return np.zeros(0, dtype=int)
    p = np.array([plant.EvalBodyPoseInWorld(plant_context, b).translation() for b in bodies])
    centres = np.array([c.centre for c in object_clusters(scenario)])
    away = np.linalg.norm(p[:, :2] - centres, axis=1) > scenario.settle_within
    return np.flatnonzero(away | (p[:, 2] < FELL_OFF_Z))


def settle_in_clusters(simulator: Simulator, plant: MultibodyPlant, plant_context: Context,
                       inspector: SceneGraphInspector, bodies: Sequence[RigidBody], scenario: Scenario,
                       rng: np.random.Generator) -> int:
    """With `scenario.settle_within`, lets the dropped scene settle (`settle_time`) and drops the objects
    that rolled away again, in their clusters above the others, and settles again, `MAX_REDROPS` times at
    most; returns how many drops were repeated. Without it, does nothing: the executive's first wait
    settles the scene."""
    if scenario.settle_within <= 0:
        return 0
    clusters, redrops = object_clusters(scenario), 0
    simulator.AdvanceTo(simulator.get_context().get_time() + scenario.settle_time)
    for _ in range(MAX_REDROPS):
        away = strays(plant, plant_context, bodies, scenario)
        if len(away) == 0:
            break
        top = max(plant.EvalBodyPoseInWorld(plant_context, b).translation()[2]
                  + bounding_radius(plant, inspector, b) for b in bodies)
        for k in away:
            r = bounding_radius(plant, inspector, bodies[k])
            xy = _random_xy(clusters[k], rng)
            z = top + scenario.drop_height + r
            plant.SetFreeBodyPose(plant_context, bodies[k], RigidTransform(_random_rotation(rng), [*xy, z]))
            plant.SetFreeBodySpatialVelocity(plant_context, bodies[k], SpatialVelocity.Zero())
            top += 2 * r
        redrops += len(away)
        simulator.AdvanceTo(simulator.get_context().get_time() + scenario.settle_time)
    return redrops


def park_object(plant: MultibodyPlant, plant_context: Context, body: RigidBody, index: int) -> None:
    """Takes an object out of the scene (the paper removes grasped objects), at rest far below it."""
    plant.SetFreeBodyPose(plant_context, body, RigidTransform([10.0 + 0.5 * index, 0.0, PARKING_Z]))
    plant.SetFreeBodySpatialVelocity(plant_context, body, SpatialVelocity(np.zeros(3), np.zeros(3)))
