"""The grasp stability network (paper Sec. IV-C): a voxel 3D CNN on 32^3 grids.

conv 32 x 5^3 -> conv 32 x 3^3 -> max-pool 2 -> dense 128 -> dense 1 (sigmoid in
the loss: BCE with logits). `first_stride=2` is the VoxNet variant, about ten
times faster on a CPU; the weights file records which one it is.
"""

from __future__ import annotations

import torch
from torch import nn

from drake_grasp.voxels import GRID


class GraspCNN(nn.Module):
    def __init__(self, first_stride: int = 2, grid: int = GRID):
        super().__init__()
        self.first_stride, self.grid = first_stride, grid
        side = ((grid - 5) // first_stride + 1 - 2) // 2
        self.features = nn.Sequential(
            nn.Conv3d(1, 32, 5, stride=first_stride), nn.ReLU(),
            nn.Conv3d(32, 32, 3), nn.ReLU(),
            nn.MaxPool3d(2), nn.Flatten(),
        )
        self.head = nn.Sequential(nn.Linear(32 * side**3, 128), nn.ReLU(), nn.Linear(128, 1))

    def forward(self, voxels: torch.Tensor) -> torch.Tensor:
        """(N, G, G, G) occupancy (any dtype) -> (N,) logits."""
        return self.head(self.features(voxels.float().unsqueeze(1))).squeeze(-1)
