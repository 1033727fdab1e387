"""The observed objects as planning obstacles: the object cloud as columns, clear of the final approach.

The arm's transit to the pre-grasp must not sweep through the pile, so it is
planned against the observed object cloud as a height map: one box per occupied
cell of a horizontal grid, from the table top up to the highest point seen in the
cell (a camera above the table cannot see under a surface, so that space counts
as occupied). The final approach and the lift are not: the region the hand and
wrist sweep from the pre-grasp to the grasp (the "approach corridor", in the grasp
frame G) is left out, because contact there is what the stability CNN has learned
to judge, and the reachability labels that train p_r were planned without objects.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_grasp.robot.hand import GRASP_DEPTH, TCP_DEPTH, TCP_DEPTH_TO_TIP
from drake_grasp.robot.task import PREGRASP_DISTANCE

PALM_HALF_THICKNESS = 0.0315  # the palm's half size along x_G [m]
PALM_HALF_WIDTH = 0.102  # the palm's half size along y_G, the closing direction [m]
WRIST_CLEARANCE = 0.11  # how far behind the palm the corridor continues (the wrist links) [m]


@dataclass(frozen=True)
class ObstacleConfig:
    cell: float = 0.03  # the height map's cell size [m]
    corridor_margin: float = 0.02  # extra clearance around the approach corridor [m]


def approach_corridor(margin: float) -> tuple[np.ndarray, np.ndarray]:
    """The box (lower, upper) in the grasp frame swept by the hand and wrist from pre-grasp to grasp."""
    z_hand = GRASP_DEPTH - TCP_DEPTH  # the hand frame's origin (flange) at the grasp
    lower = np.array([-PALM_HALF_THICKNESS, -PALM_HALF_WIDTH,
                      z_hand - PREGRASP_DISTANCE - WRIST_CLEARANCE]) - margin
    upper = np.array([PALM_HALF_THICKNESS, PALM_HALF_WIDTH, GRASP_DEPTH + TCP_DEPTH_TO_TIP]) + margin
    return lower, upper


def obstacle_columns(points_W: np.ndarray, X_WG: np.ndarray, config: ObstacleConfig) -> np.ndarray:
    """(M, 3) columns: the centre (x, y) of each occupied cell and the highest z seen in it.

    Points inside the grasp's approach corridor are left out.
    """
    points_W = np.asarray(points_W, dtype=float).reshape(-1, 3)
    if len(points_W) == 0:
        return np.zeros((0, 3))
    X_WG = np.asarray(X_WG, dtype=float)
    p_G = (points_W - X_WG[:3, 3]) @ X_WG[:3, :3]
    lower, upper = approach_corridor(config.corridor_margin)
    kept = points_W[~np.all((p_G >= lower) & (p_G <= upper), axis=1)]
    if len(kept) == 0:
        return np.zeros((0, 3))
    cell_index = np.floor(kept[:, :2] / config.cell).astype(np.int64)
    cells, inverse = np.unique(cell_index, axis=0, return_inverse=True)
    top = np.full(len(cells), -np.inf)
    np.maximum.at(top, inverse.ravel(), kept[:, 2])
    return np.column_stack([(cells + 0.5) * config.cell, top])
