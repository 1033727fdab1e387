"""The robot out of its own picture: the points on the arm and hand at a joint state, removed.

Every real cell runs such a self-filter: its camera sees the arm, and grasps sampled on the arm's
points are grasps on the robot. `RobotSelfFilter` builds the arm and hand once (the plant the planner
and physics load, `robot.plant.add_scene`), places them at the joint positions the robot reports, and
drops every point within `margin` of their collision geometry. Distances are computed in numpy, a
whole cloud at once: exactly for spheres, capsules, cylinders and boxes (the shipped arms' geometry),
and for meshes and convex shapes (a user's URDF) as the largest distance past a face plane of the
convex hull Drake computes for them, which never under-estimates the region within `margin`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Box, Capsule, Convex, Cylinder, Ellipsoid, Mesh, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

from drake_grasp.robot.paths import add_package
from drake_grasp.robot.plant import add_scene, set_hand_positions
from drake_grasp.robot.specs import RobotSpec

SELF_FILTER_MARGIN = 0.02  # [m] points this near the arm's or hand's collision geometry are the robot's


@dataclass(frozen=True)
class _Part:
    """One collision geometry of the arm or hand: its body, its pose on the body, and its shape."""

    body: int  # BodyIndex
    X_BG: RigidTransform
    kind: str  # "sphere", "capsule", "cylinder", "box" or "hull"
    size: np.ndarray  # sphere (r,), capsule / cylinder (r, length), box (half extents), hull (F, 4) planes
    bound: float  # radius of a sphere about the geometry's origin that holds it [m]


class RobotSelfFilter:
    """Which points of a base-frame cloud lie on the robot at a joint state (built once per robot)."""

    def __init__(self, robot: RobotSpec, *, margin: float = SELF_FILTER_MARGIN):
        if margin < 0:
            raise ValueError(f"the self-filter margin must be >= 0, got {margin}")
        self.robot, self.margin = robot, margin
        self.plant = MultibodyPlant(time_step=0.0)
        from pydrake.geometry import SceneGraph

        scene_graph = SceneGraph()
        self.plant.RegisterAsSourceForSceneGraph(scene_graph)
        parser = Parser(self.plant)
        add_package(parser.package_map())
        models = add_scene(self.plant, parser, robot=robot, table_height=0.0)
        self.plant.Finalize()
        self._hand = models.hand
        self._context = self.plant.CreateDefaultContext()
        self._q_index = [self.plant.GetJointByName(name, models.arm).position_start()
                         for name in robot.joint_names]
        self._models = models
        inspector = scene_graph.model_inspector()
        self._parts = [_part(self.plant, inspector, body, geometry)
                       for instance in (models.arm, models.hand)
                       for body in self.plant.GetBodyIndices(instance)
                       for geometry in self.plant.GetCollisionGeometriesForBody(self.plant.get_body(body))]

    @property
    def num_positions(self) -> int:
        """The arm's joints (`RobotSpec.joint_names`), whose positions `on_robot` takes."""
        return len(self._q_index)

    def on_robot(self, points_B: np.ndarray, q: np.ndarray, *, finger: float | None = None) -> np.ndarray:
        """(N,) True for the points within `margin` of the arm and hand at arm positions `q` and the hand's
        driven joint at `finger` (None: open; the joints that move with it as `HandSpec.joint_positions`)."""
        q = np.asarray(q, dtype=float).ravel()
        if len(q) != self.num_positions:
            raise ValueError(f"the {self.robot.name} arm has {self.num_positions} joints, "
                             f"got {len(q)} joint positions")
        if not np.isfinite(q).all():
            raise ValueError("the joint positions hold NaN or infinity")
        points = np.asarray(points_B, dtype=np.float64).reshape(-1, 3)
        q_all = self.plant.GetPositions(self._context)
        q_all[self._q_index] = q
        hand = self.robot.hand
        set_hand_positions(self.plant, q_all, self._models, hand.open_position if finger is None else finger)
        self.plant.SetPositions(self._context, q_all)
        hit = np.zeros(len(points), dtype=bool)
        for part in self._parts:
            X_WG = self.plant.EvalBodyPoseInWorld(self._context, self.plant.get_body(part.body)) @ part.X_BG
            centre = X_WG.translation()
            near = np.flatnonzero(np.sum((points - centre) ** 2, axis=1) <= (part.bound + self.margin) ** 2)
            if len(near) == 0:
                continue
            X_GW = X_WG.inverse()
            p_G = points[near] @ X_GW.rotation().matrix().T + X_GW.translation()
            hit[near[_distance(part, p_G) <= self.margin]] = True
        return hit

    def remove(self, points_B: np.ndarray, q: np.ndarray, *, finger: float | None = None) -> np.ndarray:
        """The points not on the robot (`on_robot`)."""
        points = np.asarray(points_B, dtype=np.float64).reshape(-1, 3)
        return points[~self.on_robot(points, q, finger=finger)]


def _part(plant: MultibodyPlant, inspector, body, geometry) -> _Part:
    shape = inspector.GetShape(geometry)
    X_BG = inspector.GetPoseInFrame(geometry)
    if isinstance(shape, Sphere):
        r = shape.radius()
        return _Part(body, X_BG, "sphere", np.array([r]), r)
    if isinstance(shape, Capsule | Cylinder):
        r, length = shape.radius(), shape.length()
        kind = "capsule" if isinstance(shape, Capsule) else "cylinder"
        return _Part(body, X_BG, kind, np.array([r, length]), float(np.hypot(r, length / 2) + r))
    if isinstance(shape, Box):
        half = np.array([shape.width(), shape.depth(), shape.height()]) / 2
        return _Part(body, X_BG, "box", half, float(np.linalg.norm(half)))
    if isinstance(shape, Ellipsoid):  # bounded by the sphere of its longest semi-axis
        r = max(shape.a(), shape.b(), shape.c())
        return _Part(body, X_BG, "sphere", np.array([r]), r)
    if isinstance(shape, Mesh | Convex):
        hull = shape.GetConvexHull()
        vertices = np.array([hull.vertex(i) for i in range(hull.num_vertices())])
        planes = []
        for f in range(hull.num_faces()):
            n = np.asarray(hull.face_normal(f))
            v0 = vertices[hull.element(f).vertex(0)]
            planes.append([*n, -n @ v0])
        return _Part(body, X_BG, "hull", np.array(planes), float(np.linalg.norm(vertices, axis=1).max()))
    raise ValueError(f"the self-filter does not know the shape {type(shape).__name__} of "
                     f"{inspector.GetName(geometry)}")


def _distance(part: _Part, p: np.ndarray) -> np.ndarray:
    """(N,) signed distances of points in the geometry's frame from its surface (a lower bound for
    hulls' outside points: the most a point lies past one face plane)."""
    if part.kind == "sphere":
        return np.linalg.norm(p, axis=1) - part.size[0]
    if part.kind == "capsule":
        r, length = part.size
        beyond = np.abs(p[:, 2]) - np.minimum(np.abs(p[:, 2]), length / 2)  # past the segment's end
        return np.hypot(np.linalg.norm(p[:, :2], axis=1), beyond) - r
    if part.kind == "cylinder":
        r, length = part.size
        d = np.column_stack([np.linalg.norm(p[:, :2], axis=1) - r, np.abs(p[:, 2]) - length / 2])
        return np.minimum(d.max(axis=1), 0.0) + np.linalg.norm(np.maximum(d, 0.0), axis=1)
    if part.kind == "box":
        d = np.abs(p) - part.size
        return np.minimum(d.max(axis=1), 0.0) + np.linalg.norm(np.maximum(d, 0.0), axis=1)
    return (p @ part.size[:, :3].T + part.size[:, 3]).max(axis=1)
