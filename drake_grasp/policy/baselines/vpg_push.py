"""VPG with pushing (Zeng et al., IROS 2018): push and grasp Q maps over the heightmap, one action a step.

VPG's other primitive is a **push**: the closed hand comes straight down at a heightmap
cell, its fingertips at the highest point within a finger's width of it (so that it
starts above what stands there), travels `robot.task.PUSH_LENGTH` (10 cm) along one of
`PUSH_DIRECTIONS` (16, over a full turn) and rises. Two nets of the grasp baseline's
kind (`vpg.VpgNet`) map the turned heightmap to a **Q value** per cell and angle: the
push net for pushes along the angle, the grasp net for grasps closing along it. Q is
`Q_MAX * sigmoid(logit)`: the rewards (1 for a grasp that lifts, `PUSH_REWARD` for a push
that changes the heightmap, 0 otherwise) discounted by `DISCOUNT` (VPG's 0.5) sum to at
most 2. The robot executes the best action of either map (`best_actions`); training is
`drake_grasp.evaluation.vpg_push_training`.

A push pose is a top-down grasp frame at the push's start (+z_G straight down) whose +x_G
points along the push; the closing axis +y_G is across it, so the two closed fingers
push side by side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from drake_grasp.learning.weights import load_weights
from drake_grasp.policy.baselines.vpg import (
    GRASP_ANGLE_STEP,
    ROTATIONS,
    HeightmapConfig,
    VpgNet,
    best_grasps,
    executed_logits,
    grasp_cell,
    logit_maps,
    spread_spots,
)
from drake_grasp.robot.hand import default_hand
from drake_grasp.robot.paths import MODELS_DIR
from drake_grasp.robot.poses import pose_from_axes

ARCH = "vpg_push_grasp"
DEFAULT_WEIGHTS = MODELS_DIR / "vpg_push.pt"
PUSH_DIRECTIONS = ROTATIONS  # over a full turn, as VPG's
PUSH_ANGLE_STEP = 2 * math.pi / PUSH_DIRECTIONS  # [rad]
FINGER_WIDTH = 0.02  # the push starts above everything within half of it [m]
PUSH_REWARD = 0.5
GRASP_REWARD = 1.0
DISCOUNT = 0.5
Q_MAX = GRASP_REWARD / (1.0 - DISCOUNT)
CHANGE_DEPTH = 0.01  # a cell changed by more than this [m] ...
CHANGE_CELLS = 300  # ... in more than this many cells: the push changed the scene (VPG's rule)
PUSH_REACH = 0.05  # pushes start within this of an object cell [m]


@dataclass(frozen=True)
class Action:
    """One VPG action: a push or a grasp at heightmap cell (i, j), rotation k."""

    push: bool
    i: int
    j: int
    k: int


def push_direction(k: int) -> np.ndarray:
    """(3,) the unit travel of push direction k, turned from world +x about +z."""
    theta = PUSH_ANGLE_STEP * k
    return np.array([math.cos(theta), math.sin(theta), 0.0])


def push_pose(i: int, j: int, k: int, heights: np.ndarray, config: HeightmapConfig) -> np.ndarray:
    """X_WG (4, 4) of the push at cell (i, j) along direction k: straight down, +x_G along the push,
    fingertips at the highest point within half a finger's width (never below `tip_clearance`)."""
    half = max(1, round(FINGER_WIDTH / 2 / config.resolution))
    region = heights[max(i - half, 0):i + half + 1, max(j - half, 0):j + half + 1]
    tip_height = max(float(region.max(initial=0.0)), config.tip_clearance)
    lo = np.asarray(config.centre) - config.size / 2
    p_WG = [lo[0] + (i + 0.5) * config.resolution, lo[1] + (j + 0.5) * config.resolution,
            config.table_height + tip_height + default_hand().tip_beyond_grasp]
    approach = np.array([0.0, 0.0, -1.0])
    return pose_from_axes(np.array(p_WG), approach, np.cross(approach, push_direction(k)))


def push_cell(X_WG: np.ndarray, config: HeightmapConfig) -> tuple[int, int, int]:
    """The (i, j, k) of a push pose: its cell and nearest direction."""
    lo = np.asarray(config.centre) - config.size / 2
    i, j = np.floor((np.asarray(X_WG)[:2, 3] - lo) / config.resolution).astype(int)
    angle = math.atan2(X_WG[1, 0], X_WG[0, 0]) % (2 * math.pi)
    return int(i), int(j), round(angle / PUSH_ANGLE_STEP) % PUSH_DIRECTIONS


def common_square(heights: np.ndarray, cells: int) -> np.ndarray:
    """The centred `cells` x `cells` part of a square map grown about the same centre (`vpg.covering`)."""
    start = (len(heights) - cells) // 2
    if start < 0:
        raise ValueError(f"a {len(heights)}-cell map holds no {cells}-cell square")
    return heights[start:start + cells, start:start + cells]


def scene_changed(before: np.ndarray, after: np.ndarray) -> bool:
    """VPG's push reward test on two maps of the same square: more than `CHANGE_CELLS` cells changed by
    more than `CHANGE_DEPTH`."""
    return int((np.abs(after - before) > CHANGE_DEPTH).sum()) > CHANGE_CELLS


class VpgPushGraspNet(nn.Module):
    """VPG's two nets: push Q and grasp Q per cell and angle, each `Q_MAX * sigmoid` of a `VpgNet`."""

    def __init__(self, width: int = 32):
        super().__init__()
        self.width = width
        self.push = VpgNet(width)
        self.grasp = VpgNet(width)

    def q_maps(self, heights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(push, grasp) Q maps of one heightmap, each (ROTATIONS, H, W)."""
        push = Q_MAX * torch.sigmoid(logit_maps(self.push, heights, PUSH_ANGLE_STEP))
        grasp = Q_MAX * torch.sigmoid(logit_maps(self.grasp, heights))
        return push.numpy(), grasp.numpy()

    def executed_q(self, heights: torch.Tensor, cells: torch.Tensor, push: torch.Tensor) -> torch.Tensor:
        """(N,) Q of each executed action: (i, j, k) rows of `cells` on their heightmaps, `push` (N,) bool."""
        q = torch.zeros(len(cells), dtype=heights.dtype)
        for is_push, net, step in ((True, self.push, PUSH_ANGLE_STEP), (False, self.grasp, GRASP_ANGLE_STEP)):
            rows = torch.nonzero(push == is_push).squeeze(1)
            if len(rows):
                logits = executed_logits(net, heights[rows], cells[rows], step)
                q = q.index_put((rows,), Q_MAX * torch.sigmoid(logits))
        return q


def object_near(heights: np.ndarray, config: HeightmapConfig, min_height: float = 0.01) -> np.ndarray:
    """(H, W) bool: cells within `PUSH_REACH` of a cell where an object stands."""
    reach = max(1, round(PUSH_REACH / config.resolution))
    occupied = torch.from_numpy((heights >= min_height).astype(np.float32))[None, None]
    near = torch.nn.functional.max_pool2d(occupied, 2 * reach + 1, stride=1, padding=reach)
    return near[0, 0].numpy() > 0


def best_actions(heights: np.ndarray, q_push: np.ndarray, q_grasp: np.ndarray, count: int,
                 config: HeightmapConfig, spacing: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(X_WG (K, 4, 4), push (K,) bool, Q (K,)): up to `count` grasps and `count` pushes, one a spot
    `spacing` cells apart (`vpg.best_grasps`), grasps on object cells, pushes starting within
    `PUSH_REACH` of one; in no particular order."""
    X_grasp = best_grasps(heights, q_grasp, count, config, spacing=spacing)
    q_g = np.array([q_grasp[k, i, j] for i, j, k in (grasp_cell(X, config) for X in X_grasp)])
    masked = np.where(object_near(heights, config)[None], q_push, -1.0)
    i, j = spread_spots(masked.max(axis=0), count, spacing)
    k = masked.argmax(axis=0)[i, j]
    X_push = np.array([push_pose(a, b, c, heights, config) for a, b, c in zip(i, j, k, strict=True)])
    X_push = X_push.reshape(-1, 4, 4)
    q_p = masked[k, i, j] if len(i) else np.zeros(0)
    X_WG = np.concatenate([X_grasp.reshape(-1, 4, 4), X_push])
    push = np.concatenate([np.zeros(len(X_grasp), bool), np.ones(len(X_push), bool)])
    return X_WG, push, np.concatenate([q_g, q_p]).astype(float)


def action_of(X_WG: np.ndarray, push: bool, config: HeightmapConfig) -> Action:
    """The heightmap action of a candidate pose."""
    return Action(push, *(push_cell(X_WG, config) if push else grasp_cell(X_WG, config)))


def save_model(model: VpgPushGraspNet, path, *, card: dict) -> None:
    torch.save({"arch": ARCH, "width": model.width, "state_dict": model.state_dict(), "card": card}, path)


def load_model(path) -> tuple[VpgPushGraspNet, dict]:
    """The two nets and their saved record; ValueError names a missing or corrupt file."""
    return load_weights(path, arch=ARCH, what="VPG push and grasp nets",
                        build=lambda record: VpgPushGraspNet(int(record["width"])))
