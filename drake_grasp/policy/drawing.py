"""Meshcat pictures of grasps: candidates as approach arrows (plain or coloured by a score), a chosen
grasp as an open gripper, clouds and the CNN's voxel grid."""

from __future__ import annotations

import numpy as np
from matplotlib import colormaps
from pydrake.geometry import Meshcat, Rgba
from pydrake.perception import BaseField, Fields, PointCloud

from drake_grasp.learning.voxels import CUBE, occupied_voxel_centers
from drake_grasp.policy.selector import RankedGrasps
from drake_grasp.robot.hand import HandSpec, default_hand

COLOR_BINS = 10  # scores are drawn in this many colours (one Meshcat object each)
PLANNED_COLOR = Rgba(0.1, 0.9, 0.1, 1.0)
FAILED_COLOR = Rgba(0.9, 0.1, 0.1, 1.0)


def hand_outline(X_WG: np.ndarray, hand: HandSpec | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Line segments (3, K) start and end of an open gripper (default the Franka hand) at grasp X_WG, in
    the world."""
    hand = hand or default_hand()
    tip = hand.tip_beyond_grasp
    base = tip - hand.finger_length
    w = hand.max_half_opening
    p_G = np.array([  # fingers, palm, wrist stub (segment pairs)
        [0, w, tip], [0, w, base], [0, -w, tip], [0, -w, base],
        [0, w, base], [0, -w, base], [0, 0, base], [0, 0, base - 0.05],
    ])
    p_W = p_G @ X_WG[:3, :3].T + X_WG[:3, 3]
    return p_W[0::2].T, p_W[1::2].T


def draw_candidates(meshcat: Meshcat, ranked: RankedGrasps, *, planned: bool, chosen: int = 0,
                    count: int = 100, hand: HandSpec | None = None) -> None:
    """Candidates as approach arrows (best first); the chosen one, as `hand` open, green if it planned,
    else red."""
    X = ranked.X_WG[:count]
    start = X[:, :3, 3] - 0.03 * X[:, :3, 2]
    meshcat.SetLineSegments("grasps/candidates", start.T, X[:, :3, 3].T, 1.0, Rgba(0.2, 0.4, 1.0, 0.8))
    draw_gripper(meshcat, "grasps/chosen", ranked.X_WG[chosen], PLANNED_COLOR if planned else FAILED_COLOR,
                 hand=hand)


def score_colors(values: np.ndarray, *, cmap: str = "viridis", vmin: float = 0.0,
                 vmax: float = 1.0) -> tuple[np.ndarray, list[Rgba]]:
    """Each value's colour bin (N,), NaN in bin 0, and the bins' colours (low to high)."""
    t = np.clip((np.nan_to_num(np.asarray(values, float), nan=vmin) - vmin) / (vmax - vmin), 0.0, 1.0)
    bins = np.minimum((t * COLOR_BINS).astype(int), COLOR_BINS - 1)
    colors = [Rgba(*colormaps[cmap]((b + 0.5) / COLOR_BINS)) for b in range(COLOR_BINS)]
    return bins, colors


def draw_scored_candidates(meshcat: Meshcat, path: str, X_WG: np.ndarray, values: np.ndarray, *,
                           length: float = 0.04, cmap: str = "viridis") -> None:
    """Candidates as approach arrows ending at the grasp point, coloured by a score in [0, 1]."""
    X_WG = np.asarray(X_WG)
    bins, colors = score_colors(values, cmap=cmap)
    meshcat.Delete(path)
    for b, color in enumerate(colors):
        X = X_WG[bins == b]
        if len(X):
            start = X[:, :3, 3] - length * X[:, :3, 2]
            meshcat.SetLineSegments(f"{path}/{b}", start.T, X[:, :3, 3].T, 2.0, color)


def draw_gripper(meshcat: Meshcat, path: str, X_WG: np.ndarray, color: Rgba = PLANNED_COLOR, *,
                 hand: HandSpec | None = None) -> None:
    """One open gripper (default the Franka hand) at grasp X_WG."""
    meshcat.SetLineSegments(path, *hand_outline(np.asarray(X_WG), hand), 4.0, color)


def draw_points(meshcat: Meshcat, path: str, points_W: np.ndarray, *, rgb: tuple[float, float, float],
                point_size: float = 0.003) -> None:
    """A cloud (M, 3) in one colour."""
    points_W = np.asarray(points_W, dtype=np.float32)
    cloud = PointCloud(len(points_W), Fields(BaseField.kXYZs | BaseField.kRGBs))
    cloud.mutable_xyzs()[:] = points_W.T
    cloud.mutable_rgbs()[:] = np.round(np.array(rgb)[:, None] * 255).astype(np.uint8)
    meshcat.SetObject(path, cloud, point_size)


def draw_voxels(meshcat: Meshcat, path: str, grid: np.ndarray, X_WG: np.ndarray, *, cube: float = CUBE,
                rgb: tuple[float, float, float] = (1.0, 0.5, 0.0)) -> None:
    """The CNN's occupancy grid at grasp X_WG: one point per occupied voxel, voxel-sized."""
    centers = occupied_voxel_centers(grid, X_WG, cube=cube)
    draw_points(meshcat, path, centers, rgb=rgb, point_size=cube / np.asarray(grid).shape[0])
