"""What the cameras saw as planning obstacles: columns of a height map, clear of the final approach.

The arm's transit to the pre-grasp must not sweep through the pile, so it is
planned against the observed cloud as a height map: one box per occupied cell of
a horizontal grid, from the table top up to the highest point seen in the cell (a
camera above the table cannot see under a surface, so that space counts as
occupied). Where the cameras' rays are known (`ObservedScene.rays`), the space a
camera saw through is free: a column ends above it, so a shelf seen from above and
from the side is a board over free space, not a block down to the table.

The objects' points in the region the hand and wrist sweep from the pre-grasp to the
grasp (the "approach corridor", in the grasp frame G) are left out, because contact
there is what the stability CNN has learned to judge, and the reachability labels
that train p_r were planned without objects. Scene structure (`ObservedScene.structure`,
a shelf or a stool) is never left out: the hand must not touch it at all.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from drake_grasp.robot.hand import HandSpec, default_hand
from drake_grasp.robot.task import PREGRASP_DISTANCE

WRIST_CLEARANCE = 0.11  # how far behind the palm the corridor continues (the wrist links) [m]
RISING = 0.05  # a ray whose direction has at least this upward component saw its point from below


@dataclass(frozen=True)
class ObstacleConfig:
    cell: float = 0.03  # the height map's cell size [m]
    corridor_margin: float = 0.02  # extra clearance around the approach corridor [m]
    slice: float = 0.02  # the height of the free-space voxels (a cell's column is cut at free ones) [m]
    ray_end_clearance: float = 0.02  # a ray frees the space up to this short of what it hit [m]


@dataclass(frozen=True)
class ObservedScene:
    """What the cameras saw, in the world frame: the objects, scene structure, and the rays they saw along."""

    objects: np.ndarray  # (N, 3)
    structure: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (K, 3)
    rays: tuple[np.ndarray, np.ndarray] | None = None  # (origins (V, 3), ends (V, 3)); None: unknown


def approach_corridor(hand: HandSpec, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """The box (lower, upper) in the grasp frame swept by the hand's palm and the wrist from pre-grasp to
    grasp."""
    z_hand = hand.grasp_depth - hand.tcp_depth  # the hand frame's origin (flange) at the grasp
    half_x, half_y = hand.palm_size[0] / 2, hand.palm_size[1] / 2
    lower = np.array([-half_x, -half_y, z_hand - PREGRASP_DISTANCE - WRIST_CLEARANCE]) - margin
    upper = np.array([half_x, half_y, hand.tip_beyond_grasp]) + margin
    return lower, upper


def in_corridor(points_W: np.ndarray, X_WG: np.ndarray, hand: HandSpec, margin: float) -> np.ndarray:
    """(N, K) bool: which of K points lie in the approach corridor (`approach_corridor(hand, margin)`) of
    each of N grasps (N, 4, 4); one grasp (4, 4) gives (K,)."""
    X_WG = np.asarray(X_WG, dtype=float)
    points_W = np.asarray(points_W, dtype=float).reshape(-1, 3)
    lower, upper = approach_corridor(hand, margin)
    X = X_WG.reshape(-1, 4, 4)
    p_G = np.matmul(points_W[None] - X[:, None, :3, 3], X[:, :3, :3])  # (N, K, 3) in each grasp frame
    inside = np.all((p_G >= lower) & (p_G <= upper), axis=2)
    return inside[0] if X_WG.ndim == 2 else inside


def free_voxels(rays: tuple[np.ndarray, np.ndarray], config: ObstacleConfig, table_z: float,
                top_z: float) -> set[tuple[int, int, int]]:
    """The (i, j, k) voxels (cell i, j of the height map, slice k above `table_z`) some ray passes through
    between `table_z` and `top_z`, up to `config.ray_end_clearance` short of its end; and, for a ray that
    rises to what it hit (the underside of a board, seen from below), the voxel under its end."""
    origins, ends = (np.asarray(a, dtype=float).reshape(-1, 3) for a in rays)
    if len(ends) == 0:
        return set()
    d = ends - origins
    length = np.linalg.norm(d, axis=1)
    u = d / np.where(length > 0, length, 1.0)[:, None]
    # The part of each ray inside the slab table_z <= z <= top_z (origins above or beside it).
    dz = np.where(np.abs(u[:, 2]) > 1e-9, u[:, 2], 1e-9)
    s0 = np.clip(np.minimum((top_z - origins[:, 2]) / dz, (table_z - origins[:, 2]) / dz), 0.0, None)
    s1 = length - config.ray_end_clearance
    step = 0.5 * min(config.cell, config.slice)
    counts = np.maximum(np.ceil((s1 - s0) / step).astype(np.int64), 0)
    ray = np.repeat(np.arange(len(ends)), counts)
    offset = np.arange(len(ray)) - np.repeat(np.cumsum(counts) - counts, counts)
    samples = origins[ray] + u[ray] * (s0[ray] + step * offset)[:, None]
    inside = (samples[:, 2] >= table_z) & (samples[:, 2] <= top_z)
    samples = samples[inside]
    rising = ends[u[:, 2] > RISING]  # an underside: the space right under it was seen
    samples = np.vstack([samples, rising - [0.0, 0.0, config.slice]])
    samples = samples[samples[:, 2] >= table_z]
    keys = np.column_stack([np.floor(samples[:, :2] / config.cell),
                            np.floor((samples[:, 2] - table_z) / config.slice)]).astype(np.int64)
    return set(map(tuple, np.unique(keys, axis=0).tolist()))


def _columns(points_W: np.ndarray, config: ObstacleConfig, table_z: float,
             free: set[tuple[int, int, int]] | None) -> np.ndarray:
    """(M, 4) columns (x, y, bottom, top) of the points: per occupied cell, from the table (or, with `free`
    voxels, from the lowest voxel above a free one) up to the highest point seen; one column a run."""
    if len(points_W) == 0:
        return np.zeros((0, 4))
    cell_index = np.floor(points_W[:, :2] / config.cell).astype(np.int64)
    if free is None:
        cells, inverse = np.unique(cell_index, axis=0, return_inverse=True)
        top = np.full(len(cells), -np.inf)
        np.maximum.at(top, inverse.ravel(), points_W[:, 2])
        return np.column_stack([(cells + 0.5) * config.cell, np.full(len(cells), -np.inf), top])
    slices = np.maximum(np.floor((points_W[:, 2] - table_z) / config.slice).astype(np.int64), 0)
    keys, inverse = np.unique(np.column_stack([cell_index, slices]), axis=0, return_inverse=True)
    top = np.full(len(keys), -np.inf)
    np.maximum.at(top, inverse.ravel(), points_W[:, 2])
    columns = []
    by_cell: dict[tuple[int, int], list[tuple[int, float]]] = {}
    for (i, j, k), z in zip(keys.tolist(), top.tolist(), strict=True):
        by_cell.setdefault((i, j), []).append((k, z))
    for (i, j), occupied in by_cell.items():
        occupied.sort(reverse=True)  # highest slice first
        run_top, run_bottom = None, None
        for k, z in occupied:
            if run_bottom is not None and k >= run_bottom:
                continue  # inside the run already
            if run_top is not None:
                columns.append((i, j, run_bottom, run_top))
            run_top, run_bottom = z, k
            while run_bottom > 0 and (i, j, run_bottom - 1) not in free:
                run_bottom -= 1
        columns.append((i, j, run_bottom, run_top))
    out = np.array(columns, dtype=float)
    bottom = np.where(out[:, 2] > 0, table_z + out[:, 2] * config.slice, -np.inf)
    return np.column_stack([(out[:, :2] + 0.5) * config.cell, bottom, out[:, 3]])


def obstacle_columns(scene: ObservedScene, X_WG: np.ndarray, config: ObstacleConfig, *,
                     hand: HandSpec | None = None, table_z: float = 0.0,
                     free: set[tuple[int, int, int]] | None = None) -> np.ndarray:
    """(M, 4) columns: the centre (x, y) of an occupied cell, the column's bottom (-inf: the table) and
    the highest z seen in it.

    The objects' points inside the approach corridor of the grasp (of `hand`, default the Franka hand)
    are left out; the structure's are not. With
    `free` voxels (`free_voxels` of the scene's rays) a cell's points make one column per run of voxels
    not seen through; without, one column from the table.
    """
    objects = np.asarray(scene.objects, dtype=float).reshape(-1, 3)
    if len(objects):
        objects = objects[~in_corridor(objects, X_WG, hand or default_hand(), config.corridor_margin)]
    kept = np.vstack([objects, np.asarray(scene.structure, dtype=float).reshape(-1, 3)])
    return _columns(kept, config, table_z, free)


def structure_columns(scene: ObservedScene, config: ObstacleConfig, *, table_z: float = 0.0,
                      free: set[tuple[int, int, int]] | None = None) -> np.ndarray:
    """(M, 4) columns of the scene's structure alone (what the approach and the lift must also miss)."""
    return _columns(np.asarray(scene.structure, dtype=float).reshape(-1, 3), config, table_z, free)
