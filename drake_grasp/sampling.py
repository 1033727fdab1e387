"""Grasp pose sampling (paper Sec. IV-B): N grasp points uniform over the object cloud.

Each candidate X_WG gets (grasp-frame convention of `drake_grasp.hand`):
- origin: a point drawn uniformly from the object cloud;
- approach axis +z_G: angle gamma from straight down (world -z) uniform in
  [gamma1, gamma2] (uniform in the angle, as the paper states it, not in solid
  angle, which would put half of all candidates beyond 60 degrees), azimuth uniform;
- wrist roll about +z_G uniform in [0, 2 pi): sets the closing direction +y_G.
"""

from __future__ import annotations

import numpy as np


def approach_rotations(approach: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations R_WG whose z column is `approach` and rolled by `roll` about it."""
    z = approach / np.linalg.norm(approach, axis=1, keepdims=True)
    # Any unit vector orthogonal to z, then rotate it by the roll angle about z.
    helper = np.where(np.abs(z[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    x0 = np.cross(helper, z)
    x0 /= np.linalg.norm(x0, axis=1, keepdims=True)
    y0 = np.cross(z, x0)
    c, s = np.cos(roll)[:, None], np.sin(roll)[:, None]
    x = c * x0 + s * y0
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=2)


def sample_grasps(points: np.ndarray, n: int, gamma_deg: tuple[float, float],
                  rng: np.random.Generator) -> np.ndarray:
    """(n, 4, 4) grasp poses X_WG sampled over `points` (M, 3)."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) == 0:
        raise ValueError("cannot sample grasps on an empty object cloud")
    g1, g2 = np.radians(gamma_deg)
    if not 0 <= g1 <= g2 <= np.pi / 2 + 1e-9:
        raise ValueError(f"need 0 <= gamma1 <= gamma2 <= 90 degrees, got {gamma_deg}")
    origins = points[rng.integers(len(points), size=n)]
    gamma = rng.uniform(g1, g2, size=n)
    azimuth = rng.uniform(0, 2 * np.pi, size=n)
    approach = np.stack(
        [np.sin(gamma) * np.cos(azimuth), np.sin(gamma) * np.sin(azimuth), -np.cos(gamma)], axis=1
    )
    X = np.tile(np.eye(4), (n, 1, 1))
    X[:, :3, :3] = approach_rotations(approach, rng.uniform(0, 2 * np.pi, size=n))
    X[:, :3, 3] = origins
    return X


def approach_angle_deg(X_WG: np.ndarray) -> np.ndarray:
    """Angle between each grasp's approach axis and straight down, in degrees."""
    return np.degrees(np.arccos(np.clip(-X_WG[..., 2, 2], -1.0, 1.0)))
