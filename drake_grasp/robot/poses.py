"""Batches of grasp poses as arrays: validation and the compact form data shards store."""

from __future__ import annotations

import numpy as np


def check_poses(X_WG: np.ndarray) -> np.ndarray:
    """X_WG as a float (N, 4, 4) array; ValueError for another shape or a non-finite entry."""
    X_WG = np.asarray(X_WG, dtype=np.float64)
    if X_WG.ndim != 3 or X_WG.shape[1:] != (4, 4):
        raise ValueError(f"expected (N, 4, 4) grasp poses, got {X_WG.shape}")
    if not np.isfinite(X_WG).all():
        raise ValueError("grasp poses contain NaN or infinite values")
    return X_WG


def pose_from_axes(p_WG: np.ndarray, approach: np.ndarray, closing: np.ndarray) -> np.ndarray:
    """X_WG (4, 4) with origin p_WG, +z_G along the unit `approach` and +y_G along the unit `closing`
    (orthogonal to it): the grasp-frame convention of `drake_grasp.robot.hand`."""
    X_WG = np.eye(4)
    X_WG[:3, :3] = np.stack([np.cross(closing, approach), closing, approach], axis=1)
    X_WG[:3, 3] = p_WG
    return X_WG


def homogeneous(X_34: np.ndarray) -> np.ndarray:
    """(N, 4, 4) poses from the (N, 3, 4) top rows that data shards store."""
    X_34 = np.asarray(X_34, dtype=np.float64)
    bottom = np.broadcast_to([0.0, 0.0, 0.0, 1.0], (len(X_34), 1, 4))
    return np.concatenate([X_34, bottom], axis=1)


def check_cloud(points: np.ndarray) -> np.ndarray:
    """An object cloud as a float (M, 3) array; ValueError for another shape, no point, or NaN."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"expected an (M, 3) object cloud, got {points.shape}")
    if len(points) == 0:
        raise ValueError("the object cloud is empty")
    if not np.isfinite(points).all():
        raise ValueError("the object cloud contains NaN or infinite points")
    return points
