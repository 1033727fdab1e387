"""Putting objects into a scene: random drops in the scenario's clusters or upright packing side by side,
objects drawn and scaled as the scenario says, and parking removed ones."""

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

from drake_grasp.simulation.objects import ObjectModel, scaled_object
from drake_grasp.simulation.scenario import Cluster, Scenario

PARKING_Z = -50.0  # removed objects are parked far below the table [m]
FELL_OFF_Z = -0.2  # an object this far below the table top has left the table [m]
MAX_REDROPS = 3  # settles after which an object that keeps rolling away is left where it lies
PACKED_GAP = 0.003  # packed objects' footprints stay this far apart [m]
PACKED_LIFT = 0.002  # a packed object starts this far above the table [m]
PACKED_TRIES = 200  # random spots tried for a packed object before its cluster's disc grows
PACKED_GROWTH = 1.25  # the disc's radius grows by this factor when no spot is free


def choose_objects(models: Sequence[ObjectModel], count: int, rng: np.random.Generator,
                   scale: Sequence[float] = (1.0, 1.0)) -> list[ObjectModel]:
    """`count` objects drawn uniformly (with replacement) from a set, each scaled by a factor drawn from
    [low, high] of `scale` (drawn after the objects, and only when the range is not [1, 1])."""
    return scale_objects([models[i] for i in rng.integers(len(models), size=count)], scale, rng)


def scale_objects(models: Sequence[ObjectModel], scale: Sequence[float],
                  rng: np.random.Generator) -> list[ObjectModel]:
    """The objects, each scaled by a factor drawn from [low, high] of `scale` (nothing drawn for [1, 1])."""
    low, high = (float(x) for x in scale)
    if (low, high) == (1.0, 1.0):
        return list(models)
    factors = rng.uniform(low, high, size=len(models)) if high > low else np.full(len(models), low)
    return [scaled_object(model, factor) for model, factor in zip(models, factors, strict=True)]


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


def collision_vertices(plant: MultibodyPlant, inspector: SceneGraphInspector, body: RigidBody) -> np.ndarray:
    """(n, 3) points on the body's collision geometry (corners, rims, hull vertices), in the body frame."""
    out = [np.zeros((0, 3))]
    ring = np.linspace(0, 2 * math.pi, 24, endpoint=False)
    circle = np.column_stack([np.cos(ring), np.sin(ring), np.zeros(24)])
    ball = np.vstack([circle, np.column_stack([np.cos(ring), np.zeros(24), np.sin(ring)]),
                      np.column_stack([np.zeros(24), np.cos(ring), np.sin(ring)])])
    for gid in plant.GetCollisionGeometriesForBody(body):
        shape = inspector.GetShape(gid)
        if isinstance(shape, Box):
            half = np.array([shape.width(), shape.depth(), shape.height()]) / 2
            points = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
        elif isinstance(shape, Cylinder):
            points = np.vstack([circle * shape.radius() + [0, 0, z] for z in (-shape.length() / 2,
                                                                               shape.length() / 2)])
        elif isinstance(shape, Sphere):
            points = ball * shape.radius()
        elif isinstance(shape, Capsule):
            points = np.vstack([ball * shape.radius() + [0, 0, z] for z in (-shape.length() / 2,
                                                                             shape.length() / 2)])
        elif isinstance(shape, Ellipsoid):
            points = ball * [shape.a(), shape.b(), shape.c()]
        elif isinstance(shape, Convex | Mesh):
            hull = shape.GetConvexHull()  # already scaled
            points = np.array([hull.vertex(i) for i in range(hull.num_vertices())])
        else:
            continue
        X = inspector.GetPoseInFrame(gid)
        out.append(points @ X.rotation().matrix().T + X.translation())
    return np.vstack(out)


def convex_hull_2d(points: np.ndarray) -> np.ndarray:
    """The convex hull of (n, 2) points, counter-clockwise (Andrew's monotone chain)."""
    unique = sorted({(float(x), float(y)) for x, y in np.round(points, 6)})
    if len(unique) < 3:
        return np.array(unique)

    def half(ordered):
        chain = []
        for p in ordered:
            while len(chain) >= 2 and ((chain[-1][0] - chain[-2][0]) * (p[1] - chain[-2][1])
                                       - (chain[-1][1] - chain[-2][1]) * (p[0] - chain[-2][0])) <= 0:
                chain.pop()
            chain.append(p)
        return chain[:-1]

    return np.array(half(unique) + half(unique[::-1]))


def polygons_overlap(a: np.ndarray, b: np.ndarray, gap: float = 0.0) -> bool:
    """Whether two convex polygons come closer than `gap` along every edge normal (separating axes)."""
    for polygon in (a, b):
        edges = np.roll(polygon, -1, axis=0) - polygon
        for nx, ny in np.column_stack([edges[:, 1], -edges[:, 0]]):
            norm = math.hypot(nx, ny)
            if norm < 1e-12:
                continue
            axis = np.array([nx, ny]) / norm
            pa, pb = a @ axis, b @ axis
            if pa.max() + gap <= pb.min() or pb.max() + gap <= pa.min():
                return False
    return True


def _random_xy(cluster: Cluster, rng: np.random.Generator, radius: float | None = None) -> np.ndarray:
    """A point uniformly distributed on the cluster's disc (of `radius` instead of the cluster's)."""
    radius = cluster.radius if radius is None else radius
    rho, phi = radius * math.sqrt(rng.uniform()), rng.uniform(0, 2 * math.pi)
    return np.array(cluster.centre) + rho * np.array([math.cos(phi), math.sin(phi)])


def pack_objects(plant: MultibodyPlant, plant_context: Context, inspector: SceneGraphInspector,
                 bodies: Sequence[RigidBody], scenario: Scenario, rng: np.random.Generator) -> None:
    """Stands the objects upright (body frame +z up) on the table side by side in their clusters: each at a
    random yaw and a random spot of its cluster's disc where its footprint keeps `PACKED_GAP` from those
    placed before; a cluster too full for the next object grows its disc by `PACKED_GROWTH`."""
    placed: list[np.ndarray] = []
    remaining = iter(bodies)
    for cluster in scenario.clusters:
        radius = cluster.radius
        for _ in range(cluster.count):
            body = next(remaining)
            points = collision_vertices(plant, inspector, body)
            while True:
                for _ in range(PACKED_TRIES):
                    yaw, xy = rng.uniform(0, 2 * math.pi), _random_xy(cluster, rng, radius)
                    c, s = math.cos(yaw), math.sin(yaw)
                    footprint = convex_hull_2d(points[:, :2] @ np.array([[c, s], [-s, c]]) + xy)
                    if not any(polygons_overlap(footprint, other, PACKED_GAP) for other in placed):
                        break
                else:
                    radius *= PACKED_GROWTH
                    continue
                break
            placed.append(footprint)
            z = PACKED_LIFT - float(points[:, 2].min())
            X_WB = RigidTransform(RotationMatrix.MakeZRotation(yaw), [*xy, z])
            plant.SetFreeBodyPose(plant_context, body, X_WB)


def _random_rotation(rng: np.random.Generator) -> RotationMatrix:
    quaternion = rng.normal(size=4)
    return RotationMatrix(Quaternion(quaternion / np.linalg.norm(quaternion)))


def place_objects(plant: MultibodyPlant, plant_context: Context, inspector: SceneGraphInspector,
                  bodies: Sequence[RigidBody], scenario: Scenario, rng: np.random.Generator) -> None:
    """Puts the objects in the scenario's clusters, without overlaps: packed upright (`pack_objects`) when
    the scenario says so, else dropped: each object takes a random orientation and a random (x, y) in
    its cluster, and the lowest height at which its bounding sphere clears those placed before it.
    """
    if scenario.placement == "packed":
        pack_objects(plant, plant_context, inspector, bodies, scenario, rng)
        return
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
