"""Voxelization (paper Sec. IV-A): 32^3 binary occupancy of a 0.1 m cube at each grasp, in G.

One function for training, selection, notebooks and the bench: all candidates at
once, by one transform of the cloud into every grasp frame and one scatter.
Voxel (i, j, k) covers p_G in [-L/2 + i h, -L/2 + (i+1) h) along x (likewise y, z),
with L = 0.1 m and h = L / 32.
"""

from __future__ import annotations

import numpy as np

GRID = 32
CUBE = 0.1  # edge of the voxel cube [m]


def voxelize(points_W: np.ndarray, X_WG: np.ndarray, *, grid: int = GRID, cube: float = CUBE) -> np.ndarray:
    """(N, grid, grid, grid) uint8 occupancy of the cloud (M, 3) around N grasps (N, 4, 4).

    The cloud is sorted once along x; each grasp transforms only the slab of points
    within the cube's half diagonal of it in x.
    """
    points_W = np.asarray(points_W, dtype=np.float64)
    X_WG = np.asarray(X_WG, dtype=np.float64).reshape(-1, 4, 4)
    n = len(X_WG)
    out = np.zeros((n, grid, grid, grid), dtype=np.uint8)
    if len(points_W) == 0 or n == 0:
        return out
    # Points sorted along x: each grasp's neighbours lie in one contiguous slab.
    order = np.argsort(points_W[:, 0], kind="stable")
    sorted_points = points_W[order]
    radius = cube * np.sqrt(3) / 2
    lo = np.searchsorted(sorted_points[:, 0], X_WG[:, 0, 3] - radius, side="left")
    hi = np.searchsorted(sorted_points[:, 0], X_WG[:, 0, 3] + radius, side="right")
    scale = grid / cube
    flat = out.reshape(n, -1)
    for g in range(n):
        slab = sorted_points[lo[g]:hi[g]]
        # p_G = R_WG^T (p_W - p_WG), as row vectors: (p_W - p_WG) R_WG.
        idx = np.floor(((slab - X_WG[g, :3, 3]) @ X_WG[g, :3, :3] + cube / 2) * scale).astype(np.int64)
        idx = idx[((idx >= 0) & (idx < grid)).all(axis=1)]
        flat[g, (idx[:, 0] * grid + idx[:, 1]) * grid + idx[:, 2]] = 1
    return out


def voxelize_naive(points_W: np.ndarray, X_WG: np.ndarray, *, grid: int = GRID,
                   cube: float = CUBE) -> np.ndarray:
    """Reference per-grasp, per-point loop (for tests and the bench's comparison only)."""
    out = np.zeros((len(X_WG), grid, grid, grid), dtype=np.uint8)
    for n, X in enumerate(np.asarray(X_WG, dtype=np.float64)):
        R, p = X[:3, :3], X[:3, 3]
        for q in np.asarray(points_W, dtype=np.float64):
            g = R.T @ (q - p)
            i, j, k = (int(np.floor((c + cube / 2) * (grid / cube))) for c in g)
            if 0 <= i < grid and 0 <= j < grid and 0 <= k < grid:
                out[n, i, j, k] = 1
    return out
