"""Approach clearance in the CNN's voxel grid: does the open hand's way in run into the observed cloud?

The hand comes in along +z_G from the pre-grasp, open, so on its way it sweeps
every point that lies in front of (at lower z_G than) its palm and fingers at the
grasp: two finger columns and the palm's slab, cut to the grid's 0.1 m cube. A
candidate whose grid has occupied voxels inside that swept volume would push or
hit what the camera saw, so the staged selection skips the CNN for it. On the
100,000 training trials, three voxels block 40 % of the trials (half of the
approach collisions) and 1 of the 17,496 successes (docs/selection_speed.md). The check sees only the observed
surface and the cube, so it catches part of the approach collisions, never
invents one where the camera saw nothing.
"""

from __future__ import annotations

from functools import cache

import numba
import numpy as np

from drake_grasp.learning.voxels import CUBE, GRID
from drake_grasp.robot.hand import HandSpec, default_hand

BLOCKING_VOXELS = 3  # occupied voxels in the swept volume that block a candidate


def hand_sweep_mask(grid: int = GRID, cube: float = CUBE, hand: HandSpec | None = None) -> np.ndarray:
    """(grid, grid, grid) bool: the voxels whose centres the open hand (default the Franka hand) passes
    through on its approach."""
    hand = hand or default_hand()
    c = (np.arange(grid) + 0.5) * (cube / grid) - cube / 2
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    tip = hand.tip_beyond_grasp  # fingertips at the grasp, along z_G
    finger_base = tip - hand.finger_length  # where the palm ends
    reach, (pad_x, pad_y), (palm_x, palm_y) = hand.max_half_opening, hand.finger_size, hand.palm_size
    fingers = ((np.abs(x) <= pad_x / 2) & (z <= tip) & (np.abs(y) >= reach) & (np.abs(y) <= reach + pad_y))
    palm = (np.abs(x) <= palm_x / 2) & (np.abs(y) <= palm_y / 2) & (z <= finger_base)
    return fingers | palm


def approach_blocked(grids: np.ndarray, *, min_voxels: int = BLOCKING_VOXELS,
                     hand: HandSpec | None = None) -> np.ndarray:
    """(N,) bool: candidates with at least `min_voxels` occupied voxels in the swept volume of `hand`
    (default the Franka hand)."""
    grids = np.asarray(grids)
    if grids.ndim != 4 or len(set(grids.shape[1:])) != 1:
        raise ValueError(f"expected (N, G, G, G) occupancy grids, got {grids.shape}")
    flat = np.ascontiguousarray(grids).reshape(len(grids), -1)
    return _occupied_at(flat, _swept_voxels(grids.shape[1], hand or default_hand())) >= min_voxels


@numba.njit(cache=True)
def _occupied_at(flat: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """(N,) the nonzero entries of each row of `flat` (N, V) at `indices`: a tenth of the time of numpy's
    gather, which copies N x len(indices) entries first."""
    counts = np.zeros(flat.shape[0], np.int64)
    for n in range(flat.shape[0]):
        for i in indices:
            if flat[n, i] != 0:
                counts[n] += 1
    return counts


@cache
def _swept_voxels(grid: int, hand: HandSpec) -> np.ndarray:
    """The flat indices of `hand_sweep_mask(grid, hand=hand)`, made once per grid size and hand."""
    return np.flatnonzero(hand_sweep_mask(grid, hand=hand))


STRUCTURE_SAMPLE = 0.02  # the structure's points are thinned to one per cube of this size for the check [m]


def thinned(points_W: np.ndarray, size: float = STRUCTURE_SAMPLE) -> np.ndarray:
    """One point of `points_W` per occupied cube of `size` (the first in the cloud's order)."""
    points_W = np.asarray(points_W, dtype=float).reshape(-1, 3)
    _, first = np.unique(np.floor(points_W / size).astype(np.int64), axis=0, return_index=True)
    return points_W[np.sort(first)]


def corridor_blocked(structure_W: np.ndarray, X_WG: np.ndarray, margin: float, *,
                     hand: HandSpec | None = None) -> np.ndarray:
    """(N,) bool: candidates whose approach corridor (`planning.obstacles.approach_corridor`: the hand,
    default the Franka hand, and wrist from the pre-grasp to the grasp, `margin` around it) holds a point
    of the scene's structure (give it `thinned`: the check costs N x its points).

    The planner would refuse them (the hand must not touch the structure), so the sampler draws
    others instead (`policy.selector.sample_clear_grasps`)."""
    from drake_grasp.planning.obstacles import in_corridor

    X_WG = np.asarray(X_WG, dtype=float).reshape(-1, 4, 4)
    points = np.asarray(structure_W, dtype=float).reshape(-1, 3)
    if len(points) == 0 or len(X_WG) == 0:
        return np.zeros(len(X_WG), dtype=bool)
    return in_corridor(points, X_WG, hand or default_hand(), margin).any(axis=1)
