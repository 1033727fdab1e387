"""The reachability determinant a = (x, y, z, a_x, a_y, a_z) of the paper (Sec. III).

Grasp position and approach direction (+z of G) in the robot's base frame B. The
wrist roll is left out: the paper argues it does not change reachability, and the
planner accepts the jaw-swapped twin of every grasp.
"""

from __future__ import annotations

import numpy as np

from drake_grasp.robot.poses import homogeneous


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


FEATURES = {"paper": 6, "roll": 7, "jaw": 12}


def reachability_features(X_WG: np.ndarray, features: str = "paper", X_WB: np.ndarray | None = None,
                          ) -> np.ndarray:
    """RP inputs: the paper's determinant a, optionally with the jaw axis y_G in the base frame.

    `paper`: a = (x, y, z, a_x, a_y, a_z). `roll`: a and |y_G . z_B|, how upright the
    jaw axis is: the wrist roll decides whether the 20 cm wide palm clears the table on
    tilted grasps, which a cannot see. `jaw`: a and the six entries of y_G y_G^T, the
    whole jaw axis (which wrist configuration the grasp needs; it matters for the UR5).
    Both extras are invariant to the jaw swap (y_G -> -y_G) that the planner accepts.
    """
    if features not in FEATURES:
        raise ValueError(f"unknown RP features '{features}'; choose one of: {', '.join(FEATURES)}")
    a = reachability_determinant(X_WG, X_WB)
    if features == "paper":
        return a
    X_WG = np.asarray(X_WG, dtype=np.float64).reshape(-1, 4, 4)
    y = X_WG[:, :3, 1]
    if X_WB is not None:
        y = y @ np.asarray(X_WB, dtype=np.float64)[:3, :3]  # y_B = R_BW y_W, as rows
    if features == "roll":
        return np.hstack([a, np.abs(y[:, 2:3])])
    i, j = np.triu_indices(3)
    return np.hstack([a, y[:, i] * y[:, j]])


def label_features(data: dict[str, np.ndarray], features: str) -> np.ndarray:
    """RP inputs of collected labels (`collect_reachability` shards; their 3x4 poses carry the wrist roll)."""
    if features == "paper":
        return data["a"]
    return reachability_features(homogeneous(data["X_WG"]), features)
