"""The reachability determinant a = (x, y, z, a_x, a_y, a_z) of the paper (Sec. III).

Grasp position and approach direction (+z of G) in the robot's base frame B. The
wrist roll is left out: the paper argues it does not change reachability, and the
planner accepts the jaw-swapped twin of every grasp.
"""

from __future__ import annotations

import numpy as np


def reachability_determinant(X_WG: np.ndarray, X_WB: np.ndarray | None = None) -> np.ndarray:
    """(N, 6) determinants of (N, 4, 4) grasp poses; X_WB places the robot base (identity by default)."""
    X_WG = np.asarray(X_WG, dtype=np.float64).reshape(-1, 4, 4)
    if X_WB is None:
        p, z = X_WG[:, :3, 3], X_WG[:, :3, 2]
    else:
        X_BW = np.linalg.inv(np.asarray(X_WB, dtype=np.float64))
        p = X_WG[:, :3, 3] @ X_BW[:3, :3].T + X_BW[:3, 3]
        z = X_WG[:, :3, 2] @ X_BW[:3, :3].T
    return np.hstack([p, z])

