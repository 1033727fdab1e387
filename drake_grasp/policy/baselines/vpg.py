"""VPG's grasping half (Zeng et al., IROS 2018) in our simulator: heightmap, rotated FCN, top-down grasps.

The scene is seen as a **heightmap**: the object cloud's highest point per 2 mm cell
over a 0.448 m square of the table (224 x 224 cells, as VPG's; in the closed loop
grown to hold every object in view, `covering`), in metres above the table. A grasp
is a cell and one of `ROTATIONS` jaw angles: the hand comes straight down onto the
cell's height, its jaws closing along the angle (VPG turns the hand in 16 steps over
a full turn; a parallel jaw turned by half a turn is the same grasp, so ours are 16
steps over half a turn). The **network** is a small fully convolutional trunk
(ImageNet weights cannot be downloaded here, so no DenseNet) applied to the heightmap
turned by each angle (padded first, as VPG does, so that no corner leaves the frame);
its output, turned back, is one grasp logit per cell and angle. Pushing, VPG's other
half, is `drake_grasp.policy.baselines.vpg_push` (the same net turned to 16 push directions
over a full turn).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch
from torch import nn
from torch.nn import functional

from drake_grasp.learning.weights import load_weights
from drake_grasp.robot.hand import default_hand
from drake_grasp.robot.paths import MODELS_DIR
from drake_grasp.robot.poses import check_cloud, pose_from_axes

ARCH = "vpg_fcn"
DEFAULT_WEIGHTS = MODELS_DIR / "vpg.pt"
ROTATIONS = 16
GRASP_ANGLE_STEP = math.pi / ROTATIONS  # jaw angles span half a turn [rad]
HEIGHT_SCALE = 0.1  # heights are divided by this before the network [m]


@dataclass(frozen=True)
class HeightmapConfig:
    centre: tuple[float, float] = (0.5, 0.0)  # of the square, on the table [m]
    size: float = 0.448  # edge of the square [m]
    resolution: float = 0.002  # edge of a cell [m]
    table_height: float = 0.0  # the table top [m]
    tip_clearance: float = 0.005  # fingertips stay this far above the table [m]

    @property
    def cells(self) -> int:
        return round(self.size / self.resolution)


def heightmap(points_W: np.ndarray, config: HeightmapConfig = HeightmapConfig()) -> np.ndarray:
    """(cells, cells) float32: the highest point above the table per cell (0 where none nearby); row i
    runs along world +x, column j along +y, from the square's low corner."""
    points_W = check_cloud(points_W)
    n = config.cells
    lo = np.asarray(config.centre) - config.size / 2
    ij = np.floor((points_W[:, :2] - lo) / config.resolution).astype(np.int64)
    inside = ((ij >= 0) & (ij < n)).all(axis=1)
    out = np.zeros(n * n, np.float32)
    heights = (points_W[inside, 2] - config.table_height).astype(np.float32)
    np.maximum.at(out, ij[inside, 0] * n + ij[inside, 1], np.maximum(heights, 0.0))
    out = out.reshape(n, n)
    # The camera's points lie 2-3 mm apart on the table: a cell no point fell in takes the highest of
    # its eight neighbours.
    padded = np.pad(out, 1)
    neighbours = np.max([padded[1 + di:1 + di + n, 1 + dj:1 + dj + n]
                         for di in (-1, 0, 1) for dj in (-1, 0, 1)], axis=0)
    return np.where(out > 0, out, neighbours)


def rotation_angle(k: int, step: float = GRASP_ANGLE_STEP) -> float:
    """The angle of rotation k (by default a grasp's closing direction) from world +x about +z [rad]."""
    return step * k


def grasp_pose(i: int, j: int, k: int, heights: np.ndarray,
               config: HeightmapConfig = HeightmapConfig()) -> np.ndarray:
    """X_WG (4, 4) of the grasp at cell (i, j), rotation k: straight down (+z_G = -z_W) onto the cell's
    height, jaws closing along the rotation's angle, fingertips never below `tip_clearance`."""
    theta = rotation_angle(k)
    closing = np.array([math.cos(theta), math.sin(theta), 0.0])
    approach = np.array([0.0, 0.0, -1.0])
    lo = np.asarray(config.centre) - config.size / 2
    height = max(float(heights[i, j]), default_hand().tip_beyond_grasp + config.tip_clearance)
    p_WG = [lo[0] + (i + 0.5) * config.resolution, lo[1] + (j + 0.5) * config.resolution,
            config.table_height + height]
    return pose_from_axes(np.array(p_WG), approach, closing)


def grasp_cell(X_WG: np.ndarray, config: HeightmapConfig = HeightmapConfig()) -> tuple[int, int, int]:
    """The (i, j, k) of a top-down grasp pose: its cell and nearest rotation (jaw swaps folded)."""
    lo = np.asarray(config.centre) - config.size / 2
    i, j = np.floor((np.asarray(X_WG)[:2, 3] - lo) / config.resolution).astype(int)
    angle = math.atan2(X_WG[1, 1], X_WG[0, 1]) % math.pi
    return int(i), int(j), round(angle / math.pi * ROTATIONS) % ROTATIONS


def sample_top_down(points_W: np.ndarray, count: int, rng: np.random.Generator,
                    config: HeightmapConfig = HeightmapConfig(), min_height: float = 0.01) -> np.ndarray:
    """(<= count, 4, 4) random VPG actions: cells where an object stands (`min_height` above the table)
    and random rotations, as poses (VPG's exploration, and its training trials)."""
    heights = heightmap(points_W, config)
    cells = np.argwhere(heights >= min_height)
    if len(cells) == 0:
        return np.zeros((0, 4, 4))
    pick = cells[rng.integers(len(cells), size=count)]
    return np.array([grasp_pose(i, j, int(k), heights, config)
                     for (i, j), k in zip(pick, rng.integers(ROTATIONS, size=count), strict=True)])


class MaxPool2x2(nn.Module):
    """`nn.MaxPool2d(2)`; in inference on maps of even height and width as two pairwise maxima: the same
    values, about twice as fast on the CPU for the large turned maps. (Training keeps torch's pooling,
    whose gradient goes to one of tied maxima where `amax` would split it.)"""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = x.shape[-2:]
        if h % 2 or w % 2 or (torch.is_grad_enabled() and x.requires_grad):
            return functional.max_pool2d(x, 2)
        return x.unflatten(-1, (w // 2, 2)).amax(-1).unflatten(-2, (h // 2, 2)).amax(-2)


class VpgNet(nn.Module):
    """A small fully convolutional net: (N, 1, H, W) heights -> (N, H, W) grasp logits.

    Three poolings and a dilated convolution give each output cell a view 72 cells
    (14 cm) across, wider than the open jaws (8 cm): enough to see whether an object
    fits between the fingers and what stands where they come down. As in VPG, the
    logits are made at the features' resolution (1/8) and upsampled bilinearly.
    """

    def __init__(self, width: int = 32):
        super().__init__()
        self.width = width
        # Each ReLU after its pooling: max-pooling and ReLU commute exactly, and the ReLU then touches a
        # quarter of the values.
        self.down = nn.Sequential(
            nn.Conv2d(1, width // 2, 5, padding=2), MaxPool2x2(), nn.ReLU(),
            nn.Conv2d(width // 2, width, 3, padding=1), MaxPool2x2(), nn.ReLU(),
            nn.Conv2d(width, width, 3, padding=1), MaxPool2x2(), nn.ReLU(),
            nn.Conv2d(width, width, 3, padding=2, dilation=2), nn.ReLU(),
        )
        self.head = nn.Sequential(nn.Conv2d(width, width // 2, 3, padding=1), nn.ReLU(),
                                  nn.Conv2d(width // 2, 1, 1))

    def forward(self, heights: torch.Tensor) -> torch.Tensor:
        logits = self.head(self.down(heights / HEIGHT_SCALE))
        return functional.interpolate(logits, size=heights.shape[-2:], mode="bilinear",
                                      align_corners=False).squeeze(1)


STRIDE = 8  # the net's total pooling
CANDIDATE_SPACING = 5  # cells (1 cm) between the closed loop's candidate spots (`best_grasps`)
WINDOW = 128  # cells of the training window: the net's view (72) and the upsampling's reach, with margin


def covering(points_W: np.ndarray, config: HeightmapConfig = HeightmapConfig()) -> HeightmapConfig:
    """`config` with its square about the same centre grown, in whole net strides, to hold every point
    of the cloud: VPG's 0.448 m workspace, or more where objects lie beyond it (rolled away, or a
    30-object pile spread wider), so that every object in view can be grasped."""
    points_W = check_cloud(points_W)
    reach = float(np.abs(points_W[:, :2] - np.asarray(config.centre)).max())
    step = STRIDE * config.resolution
    size = max(config.size, math.ceil(round((2 * reach + config.resolution) / step, 6)) * step)
    return replace(config, size=size)


def rotation_padding(cells: int) -> int:
    """Cells of zeros to put around a square map of `cells` before turning it, so that no part of it
    leaves the frame at any angle (VPG pads its heightmap to the diagonal too): a whole number of strides."""
    return math.ceil((math.sqrt(2.0) - 1.0) * cells / 2 / STRIDE) * STRIDE


def _padded_for_turning(heights: torch.Tensor) -> tuple[torch.Tensor, int]:
    """(N, H, W) maps with `rotation_padding` cells of table around them, and that padding."""
    pad = rotation_padding(max(heights.shape[-2:]))
    return functional.pad(heights, (pad, pad, pad, pad)), pad


def _rotate(images: torch.Tensor, angles: torch.Tensor) -> torch.Tensor:
    """(N, C, H, W) images turned by `angles` (N,) [rad] about their centres (bilinear, zeros outside)."""
    c, s = torch.cos(angles), torch.sin(angles)
    zero = torch.zeros_like(c)
    theta = torch.stack([torch.stack([c, -s, zero], 1), torch.stack([s, c, zero], 1)], 1)
    grid = functional.affine_grid(theta, list(images.shape), align_corners=False)
    return functional.grid_sample(images, grid, align_corners=False)


def _angles(k: torch.Tensor, step: float, dtype: torch.dtype) -> torch.Tensor:
    return torch.as_tensor([rotation_angle(int(r), step) for r in k], dtype=dtype)


def rotated_logits(model: VpgNet, heights: torch.Tensor, k: torch.Tensor,
                   step: float = GRASP_ANGLE_STEP) -> torch.Tensor:
    """(N, H, W) logits of rotation k[n] (angle k[n] * step) for heightmap n: the map turned so that the
    rotation's direction (the jaws' closing, a push's travel) lies along the image's row axis, the network,
    and its output turned back."""
    _, h, w = heights.shape
    padded, pad = _padded_for_turning(heights)
    angles = _angles(k, step, heights.dtype)
    turned = _rotate(padded[:, None], -angles)  # the closing direction onto the row axis
    return _rotate(model(turned)[:, None], angles)[:, 0, pad:pad + h, pad:pad + w]


def executed_logits(model: VpgNet, heights: torch.Tensor, cells: torch.Tensor,
                    step: float = GRASP_ANGLE_STEP) -> torch.Tensor:
    """(N,) the logit of each (i, j, k) row of `cells` on its heightmap: what `rotated_logits` gives at
    that cell, with the net run on a `WINDOW` of the turned map around it (aligned to the net's stride,
    so the same up to the map's edge) at a fraction of the cost: for training on executed grasps."""
    heights, pad = _padded_for_turning(heights)  # as `rotated_logits` turns the map
    n, h, w = heights.shape
    angles = _angles(cells[:, 2], step, heights.dtype)
    turned = _rotate(heights[:, None], -angles)
    # Where each cell lies in the turned map (`_rotate`'s normalized coordinates, x along columns).
    x = (2 * (cells[:, 1] + pad).to(heights.dtype) + 1) / w - 1
    y = (2 * (cells[:, 0] + pad).to(heights.dtype) + 1) / h - 1
    c, s = torch.cos(angles), torch.sin(angles)
    col = ((c * x - s * y + 1) * w - 1) / 2
    row = ((s * x + c * y + 1) * h - 1) / 2
    margin = WINDOW  # zeros around the map, so every window lies inside (a multiple of STRIDE)
    padded = functional.pad(turned, (margin, margin, margin, margin))
    top = (torch.round((row - WINDOW / 2) / STRIDE) * STRIDE).long()
    left = (torch.round((col - WINDOW / 2) / STRIDE) * STRIDE).long()
    windows = torch.stack([padded[b, :, margin + top[b]:margin + top[b] + WINDOW,
                                  margin + left[b]:margin + left[b] + WINDOW] for b in range(n)])
    logits = model(windows)[:, None]
    grid = torch.stack([(2 * (col - left) + 1) / WINDOW - 1, (2 * (row - top) + 1) / WINDOW - 1], 1)
    return functional.grid_sample(logits, grid[:, None, None], align_corners=False)[:, 0, 0, 0]


def logit_maps(model: VpgNet, heights: np.ndarray, step: float = GRASP_ANGLE_STEP) -> torch.Tensor:
    """(ROTATIONS, H, W) logits of one heightmap, every cell and rotation (angles k * step)."""
    with torch.inference_mode():
        batch = torch.from_numpy(np.ascontiguousarray(heights, np.float32))[None].expand(ROTATIONS, -1, -1)
        return rotated_logits(model, batch, torch.arange(ROTATIONS), step)


def q_maps(model: VpgNet, heights: np.ndarray) -> np.ndarray:
    """(ROTATIONS, H, W) grasp probabilities of one heightmap, every cell and rotation."""
    return torch.sigmoid(logit_maps(model, heights)).numpy()


def save_model(model: VpgNet, path, *, card: dict) -> None:
    torch.save({"arch": ARCH, "width": model.width, "state_dict": model.state_dict(), "card": card}, path)


def load_model(path) -> tuple[VpgNet, dict]:
    """The network and its saved record; ValueError names a missing or corrupt file."""
    return load_weights(path, arch=ARCH, what="VPG grasp net",
                        build=lambda record: VpgNet(int(record["width"])))


def spread_spots(best_q: np.ndarray, count: int, spacing: int) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) of up to `count` cells of a (H, W) map, best first, at least `spacing` cells apart along a
    row or a column (greedy); cells below 0 are never taken."""
    order = np.argsort(-best_q, axis=None, kind="stable")
    order = order[best_q.reshape(-1)[order] >= 0]
    free = np.ones(best_q.shape, dtype=bool)
    spots: list[tuple[int, int]] = []
    for cell in order:
        a, b = divmod(int(cell), best_q.shape[1])
        if not free[a, b]:
            continue
        spots.append((a, b))
        if len(spots) == count:
            break
        free[max(a - spacing + 1, 0):a + spacing, max(b - spacing + 1, 0):b + spacing] = False
    i, j = np.array(spots, dtype=int).reshape(-1, 2).T
    return i, j


def best_grasps(heights: np.ndarray, q: np.ndarray, count: int,
                config: HeightmapConfig = HeightmapConfig(), spacing: int = 0) -> np.ndarray:
    """(K <= count, 4, 4) the best (cell, rotation) grasps of a heightmap by the net's q maps
    (`q_maps`), best first, only at cells where something stands (VPG grasps objects). With `spacing`
    > 0: one grasp a spot (its cell's best rotation), spots at least `spacing` cells apart along a row
    or a column (greedy, best first), so that the list spans the objects instead of the few cells
    around the best one (VPG's 500 best cell-rotations lie within about a centimetre)."""
    q = np.where(heights[None] < 1e-3, -1.0, q)
    if spacing <= 0:
        flat = np.argsort(-q, axis=None, kind="stable")[:count]
        flat = flat[q.reshape(-1)[flat] >= 0]
        k, i, j = np.unravel_index(flat, q.shape)
    else:
        i, j = spread_spots(q.max(axis=0), count, spacing)
        k = q.argmax(axis=0)[i, j]
    X_WG = np.array([grasp_pose(a, b, c, heights, config) for a, b, c in zip(i, j, k, strict=True)])
    return X_WG.reshape(-1, 4, 4)
