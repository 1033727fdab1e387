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
from pydrake.systems.framework import Context

from drake_grasp.simulation.objects import ObjectModel
from drake_grasp.simulation.scenario import Scenario

PARKING_Z = -50.0  # removed objects are parked far below the table [m]
FELL_OFF_Z = -0.2  # an object this far below the table top has left the table [m]


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
            plant.SetFreeBodyPose(plant_context, body, RigidTransform(R, [*xy, z]))
            placed.append((np.array([*xy, z]), r))


def park_object(plant: MultibodyPlant, plant_context: Context, body: RigidBody, index: int) -> None:
    """Takes an object out of the scene (the paper removes grasped objects), at rest far below it."""
    plant.SetFreeBodyPose(plant_context, body, RigidTransform([10.0 + 0.5 * index, 0.0, PARKING_Z]))
    plant.SetFreeBodySpatialVelocity(plant_context, body, SpatialVelocity(np.zeros(3), np.zeros(3)))
