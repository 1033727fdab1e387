"""Straight TCP lines in joint space: Drake's differential IK stepped along a Cartesian segment.

The grasp trials that label the stability CNN move the hand rigidly along the
approach axis and lift it straight up; the arm executes the same motions by
following closely spaced TCP poses on the segment (fixed orientation), each reached
by a few steps of `DoDifferentialInverseKinematics` (joint position limits and a
per-step joint travel limit, so the path cannot jump between IK branches).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import (
    DifferentialInverseKinematicsParameters,
    DifferentialInverseKinematicsStatus,
    DoDifferentialInverseKinematics,
)
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, JacobianWrtVariable
from pydrake.systems.framework import Context


@dataclass(frozen=True)
class LineConfig:
    step: float = 0.01  # TCP spacing of the waypoints [m]
    iterations: int = 2  # differential IK steps per waypoint
    final_iterations: int = 4  # extra steps allowed at the end of the segment
    max_joint_step: float = 0.2  # joint travel per differential IK step [rad]
    position_tolerance: float = 0.002  # TCP off the line at any waypoint [m]
    end_position_tolerance: float = 0.001  # TCP off the segment's end [m]
    orientation_tolerance: float = np.radians(1.0)  # TCP rotation off the start's [rad]


def pose_error(X_current: RigidTransform, X_target: RigidTransform) -> np.ndarray:
    """Spatial displacement [rotation vector; translation] that takes X_current to X_target (world frame)."""
    angle_axis = X_target.rotation().multiply(X_current.rotation().inverse()).ToAngleAxis()
    return np.concatenate([angle_axis.axis() * angle_axis.angle(),
                           X_target.translation() - X_current.translation()])


class StraightLineIK:
    """Joint paths whose TCP follows straight segments, for one arm in a kinematic plant.

    `full` maps the arm's configuration to the plant's whole position vector (the
    fingers as the planner keeps them); `positions` selects the arm's entries in it.
    """

    def __init__(self, plant: MultibodyPlant, context: Context, tcp: Frame, *, positions: slice,
                 full: Callable[[np.ndarray], np.ndarray], q_lower: np.ndarray, q_upper: np.ndarray,
                 config: LineConfig | None = None):
        self.plant, self.context, self.tcp = plant, context, tcp
        self.positions, self.full = positions, full
        self.config = config or LineConfig()
        n = len(q_lower)
        self.params = DifferentialInverseKinematicsParameters(n, n)
        self.params.set_time_step(1.0)  # velocities are per-step joint displacements
        self.params.set_joint_position_limits((np.asarray(q_lower), np.asarray(q_upper)))
        step = self.config.max_joint_step * np.ones(n)
        self.params.set_joint_velocity_limits((-step, step))

    def _set(self, q: np.ndarray) -> None:
        self.plant.SetPositions(self.context, self.full(q))

    def tcp_pose(self, q: np.ndarray) -> RigidTransform:
        self._set(q)
        return self.tcp.CalcPoseInWorld(self.context)

    def _step(self, q: np.ndarray, X_target: RigidTransform) -> np.ndarray | None:
        self._set(q)
        world = self.plant.world_frame()
        J = self.plant.CalcJacobianSpatialVelocity(self.context, JacobianWrtVariable.kV, self.tcp,
                                                   np.zeros(3), world, world)[:, self.positions]
        V = pose_error(self.tcp.CalcPoseInWorld(self.context), X_target)
        result = DoDifferentialInverseKinematics(q, np.zeros_like(q), V, J, self.params)
        if result.status == DifferentialInverseKinematicsStatus.kNoSolutionFound:
            return None
        return q + np.asarray(result.joint_velocities).ravel()

    def _within(self, q: np.ndarray, X_target: RigidTransform, position_tolerance: float) -> bool:
        error = pose_error(self.tcp_pose(q), X_target)
        return (np.linalg.norm(error[3:]) <= position_tolerance
                and np.linalg.norm(error[:3]) <= self.config.orientation_tolerance)

    def line(self, q_start: np.ndarray, p_end: np.ndarray) -> list[np.ndarray] | None:
        """Joint waypoints moving the TCP from its pose at q_start to position p_end, orientation kept.

        None when the arm cannot follow the segment (a joint limit, a singularity, or
        a waypoint off the line by more than the tolerance).
        """
        c = self.config
        X_start = self.tcp_pose(q_start)
        p_start = X_start.translation()
        steps = max(1, int(np.ceil(np.linalg.norm(p_end - p_start) / c.step)))
        q, path = np.asarray(q_start, dtype=float), [np.asarray(q_start, dtype=float)]
        for k in range(1, steps + 1):
            X_k = RigidTransform(X_start.rotation(), p_start + (p_end - p_start) * k / steps)
            last = k == steps
            for i in range(c.iterations + (c.final_iterations if last else 0)):
                q = self._step(q, X_k)
                if q is None:
                    return None
                if last and i + 1 >= c.iterations and self._within(q, X_k, c.end_position_tolerance):
                    break
            tolerance = c.end_position_tolerance if last else c.position_tolerance
            if not self._within(q, X_k, tolerance):
                return None
            path.append(q)
        return path
