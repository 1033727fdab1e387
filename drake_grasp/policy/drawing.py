"""Meshcat pictures of grasps: candidates as approach arrows, a chosen grasp as an open gripper."""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Meshcat, Rgba

from drake_grasp.hand import FINGER_LENGTH, GRASP_DEPTH, MAX_HALF_OPENING, TCP_DEPTH_TO_TIP
from drake_grasp.policy.selector import RankedGrasps


def hand_outline(X_WG: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Line segments (3, K) start and end of an open gripper at grasp X_WG, in the world."""
    tip = GRASP_DEPTH + TCP_DEPTH_TO_TIP
    base = tip - FINGER_LENGTH
    w = MAX_HALF_OPENING
    p_G = np.array([  # fingers, palm, wrist stub (segment pairs)
        [0, w, tip], [0, w, base], [0, -w, tip], [0, -w, base],
        [0, w, base], [0, -w, base], [0, 0, base], [0, 0, base - 0.05],
    ])
    p_W = p_G @ X_WG[:3, :3].T + X_WG[:3, 3]
    return p_W[0::2].T, p_W[1::2].T


def draw_candidates(meshcat: Meshcat, ranked: RankedGrasps, *, planned: bool, chosen: int = 0,
                    count: int = 100) -> None:
    """Candidates as approach arrows (best first); the chosen one green if it planned, else red."""
    X = ranked.X_WG[:count]
    start = X[:, :3, 3] - 0.03 * X[:, :3, 2]
    meshcat.SetLineSegments("grasps/candidates", start.T, X[:, :3, 3].T, 1.0, Rgba(0.2, 0.4, 1.0, 0.8))
    color = Rgba(0.1, 0.9, 0.1, 1.0) if planned else Rgba(0.9, 0.1, 0.1, 1.0)
    meshcat.SetLineSegments("grasps/chosen", *hand_outline(ranked.X_WG[chosen]), 4.0, color)
