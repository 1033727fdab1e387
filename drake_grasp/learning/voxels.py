"""Voxelization (paper Sec. IV-A): 32^3 binary occupancy of a 0.1 m cube at each grasp, in G.

One function for training, selection, notebooks and the bench: all candidates at
once. The cloud is bucketed once into cells of a quarter cube (only occupied
cells are stored, so a stray far point costs nothing); each grasp visits only the
cells within the cube's half diagonal of it, and a compiled kernel (numba)
transforms those points into the grasp frame and sets their voxels. The kernel is
serial: numba's parallel threading layer is process-wide state that a library
should not choose for its users, and 500 grasps cost a few tens of milliseconds
against the CNN's half second.
Voxel (i, j, k) covers p_G in [-L/2 + i h, -L/2 + (i+1) h) along x (the same along y and z),
with L = 0.1 m and h = L / 32.

`below_plane` is the second input of a CNN with a table channel: the voxels whose centres lie under
the table plane, so that the network sees where the fingertips meet the table (the object cloud has
the table removed). `hand_grid` is the input of a CNN with a hand channel: the hand's palm and the
space its open pads close over, in the grasp frame, the same at every grasp of one hand, so that one
network learns how grasps of hands of other sizes fare.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numba
import numpy as np

from drake_grasp.robot.poses import check_poses

if TYPE_CHECKING:
    from drake_grasp.robot.hand import HandSpec

GRID = 32
CUBE = 0.1  # edge of the voxel cube [m]
CELLS_PER_CUBE = 4  # bucket size for the neighbour search: a quarter of the cube's edge


def reach_offsets(cell: float, radius: float) -> np.ndarray:
    """(K, 3) integer cell offsets whose cells may hold a point within `radius` of a point in cell 0."""
    k = math.ceil(radius / cell) + 1
    o = np.stack(np.meshgrid(*[np.arange(-k, k + 1)] * 3, indexing="ij"), -1).reshape(-1, 3)
    gap = np.clip(np.abs(o) - 1, 0, None) * cell
    return o[(gap**2).sum(1) <= radius * radius].astype(np.int64)


@numba.njit(cache=True)
def _scatter(points, cell_keys, cell_start, cell_count, dims, lo, cell, offsets, X_WG, grid, cube, out):
    scale = grid / cube
    half = cube / 2
    for g in range(X_WG.shape[0]):
        px, py, pz = X_WG[g, 0, 3], X_WG[g, 1, 3], X_WG[g, 2, 3]
        R = X_WG[g, :3, :3]
        cx = int(math.floor((px - lo[0]) / cell))
        cy = int(math.floor((py - lo[1]) / cell))
        cz = int(math.floor((pz - lo[2]) / cell))
        for o in range(offsets.shape[0]):
            ix, iy, iz = cx + offsets[o, 0], cy + offsets[o, 1], cz + offsets[o, 2]
            if ix < 0 or iy < 0 or iz < 0 or ix >= dims[0] or iy >= dims[1] or iz >= dims[2]:
                continue
            key = (ix * dims[1] + iy) * dims[2] + iz
            c = np.searchsorted(cell_keys, key)
            if c == cell_keys.shape[0] or cell_keys[c] != key:
                continue  # an empty cell
            for p in range(cell_start[c], cell_start[c] + cell_count[c]):
                dx, dy, dz = points[p, 0] - px, points[p, 1] - py, points[p, 2] - pz
                # p_G = R_WG^T (p_W - p_WG)
                i = int(math.floor((dx * R[0, 0] + dy * R[1, 0] + dz * R[2, 0] + half) * scale))
                if i < 0 or i >= grid:
                    continue
                j = int(math.floor((dx * R[0, 1] + dy * R[1, 1] + dz * R[2, 1] + half) * scale))
                if j < 0 or j >= grid:
                    continue
                k = int(math.floor((dx * R[0, 2] + dy * R[1, 2] + dz * R[2, 2] + half) * scale))
                if 0 <= k < grid:
                    out[g, i, j, k] = 1


def voxelize(points_W: np.ndarray, X_WG: np.ndarray, *, grid: int = GRID, cube: float = CUBE) -> np.ndarray:
    """(N, grid, grid, grid) uint8 occupancy of the cloud (M, 3) around N grasps (N, 4, 4)."""
    points_W = np.asarray(points_W, dtype=np.float64)
    X_WG = np.ascontiguousarray(check_poses(X_WG))
    if points_W.ndim != 2 or points_W.shape[1] != 3:
        raise ValueError(f"expected an (M, 3) point cloud, got {points_W.shape}")
    out = np.zeros((len(X_WG), grid, grid, grid), dtype=np.uint8)
    if len(points_W) == 0 or len(X_WG) == 0:
        return out
    cell = cube / CELLS_PER_CUBE
    lo = points_W.min(axis=0)
    ijk = np.floor((points_W - lo) / cell).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = np.argsort(key, kind="stable")
    cell_keys, cell_start, cell_count = np.unique(key[order], return_index=True, return_counts=True)
    offsets = reach_offsets(cell, cube * math.sqrt(3) / 2)
    sorted_points = np.ascontiguousarray(points_W[order])
    _scatter(sorted_points, cell_keys, cell_start.astype(np.int64), cell_count.astype(np.int64), dims, lo,
             cell, offsets, X_WG, grid, cube, out)
    return out


def below_plane(X_WG: np.ndarray, normal, offset: float, *, grid: int = GRID, cube: float = CUBE,
                ) -> np.ndarray:
    """(N, grid, grid, grid) uint8: 1 where the voxel's centre lies under the plane n . p + d = 0 (n up,
    world frame) at each of N grasps (N, 4, 4)."""
    X_WG = check_poses(X_WG)
    n = np.asarray(normal, dtype=np.float64).reshape(3)
    c = ((np.arange(grid) + 0.5) * (cube / grid) - cube / 2).astype(np.float32)  # voxel centres along an axis
    height0 = (X_WG[:, :3, 3] @ n + offset).astype(np.float32)  # (N,) the grasp origin's height
    a = np.einsum("nij,i->nj", X_WG[:, :3, :3], n).astype(np.float32)  # (N, 3): the height gained per metre
    # along x_G, y_G, z_G
    heights_xy = height0[:, None, None] + a[:, 0, None, None] * c[:, None] + a[:, 1, None, None] * c[None, :]
    return (heights_xy[..., None] + a[:, 2, None, None, None] * c < 0).astype(np.uint8)


def hand_grid(hand: HandSpec, *, grid: int = GRID, cube: float = CUBE) -> np.ndarray:
    """(grid, grid, grid) uint8: 1 where the voxel's centre lies in the hand's palm box or in the space its
    open pads close over, at a grasp (in G; the boxes of the hand file: `palm_size` x `palm_depth`, and
    `finger_size[0]` wide, `stroke` across, `finger_length` deep beyond the palm). The space between the
    pads rather than the pads themselves: a stroke wider than the cube still shows as far as the cube
    reaches."""
    c = (np.arange(grid) + 0.5) * (cube / grid) - cube / 2
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    z_H = z - hand.X_GH.translation()[2]  # the hand frame H is G moved along z
    palm = ((np.abs(x) <= hand.palm_size[0] / 2) & (np.abs(y) <= hand.palm_size[1] / 2)
            & (z_H >= 0) & (z_H <= hand.palm_depth))
    closing = ((np.abs(x) <= hand.finger_size[0] / 2) & (np.abs(y) <= hand.stroke / 2)
               & (z_H > hand.palm_depth) & (z_H <= hand.palm_depth + hand.finger_length))
    return (palm | closing).astype(np.uint8)


def stack_table_channel(occupancy: np.ndarray, X_WG: np.ndarray, table: tuple[np.ndarray, float] | None, *,
                        cube: float = CUBE) -> np.ndarray:
    """(N, 2, G, G, G): the occupancy grids (N, G, G, G) at the grasps X_WG and, as their second channel, the
    voxels under `table` ((n, d) of n . p + d = 0 in the world frame; None: no table seen, an empty
    channel)."""
    under = (np.zeros_like(occupancy) if table is None
             else below_plane(X_WG, table[0], table[1], grid=occupancy.shape[-1], cube=cube))
    return np.stack([occupancy, under], axis=1)


def occupied_voxel_centers(grid: np.ndarray, X_WG: np.ndarray, *, cube: float = CUBE) -> np.ndarray:
    """(K, 3) world positions of the occupied voxels' centres of one (G, G, G) grid at grasp X_WG."""
    grid = np.asarray(grid)
    h = cube / grid.shape[0]
    p_G = (np.argwhere(grid > 0) + 0.5) * h - cube / 2
    X_WG = check_poses(np.asarray(X_WG)[None])[0]
    return p_G @ X_WG[:3, :3].T + X_WG[:3, 3]
