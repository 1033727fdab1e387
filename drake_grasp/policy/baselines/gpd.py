"""GPD's grasp images and classifier (ten Pas et al., IJRR 2017), for our hand and our own trials.

A candidate's **grasp image** shows the observed points in its closing region (between
and under the open fingers: the fingers' outer width along y_G, the finger length
along z_G up to the fingertips, the finger width along x_G) from three sides, along
z_G (the approach), y_G (the closing direction) and x_G, each a 60 x 60 picture of the
region scaled to fill it. The **15-channel** image has five channels per view: the
occupancy of each pixel, the mean surface normal of its points in G (three channels),
and their mean depth along the view (0 nearest the viewer, 1 farthest). The
**3-channel** image keeps only the three views' depth channels (ours: GPD's own
smaller representations differ in detail). The classifier is GPD's LeNet: conv 20 x
5^2, max-pool 2, conv 50 x 5^2, max-pool 2, dense 500, ReLU, dense 1 (sigmoid in the
loss), trained from scratch on physics trials of GPG candidates on this package's
training objects, not GPD's released weights (another hand, other data).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import torch
from torch import nn

from drake_grasp.learning.training import predict_probabilities
from drake_grasp.learning.weights import load_weights
from drake_grasp.policy.baselines.gpg import GpgConfig, config_normals
from drake_grasp.robot.hand import HandSpec, default_hand
from drake_grasp.robot.paths import MODELS_DIR
from drake_grasp.robot.poses import check_cloud, check_poses

ARCH = "gpd_lenet"
IMAGE_SIZE = 60
CHANNELS = (15, 3)
DEFAULT_WEIGHTS = MODELS_DIR / "gpd_15.pt"  # trained on trials seen by one camera (policy `gpd1c`)
TWO_CAMERA_WEIGHTS = MODELS_DIR / "gpd_15_two_cameras.pt"  # by two, the clouds fused (policy `gpd`)
VIEWS = ((2, 1, 0), (1, 2, 0), (0, 1, 2))  # (axis viewed along, image row axis, image column axis)


def closing_region(hand: HandSpec) -> np.ndarray:
    """The hand's closing region in G: [x range, y range, z range] [m]."""
    reach, tip = hand.max_half_opening + hand.finger_size[1], hand.tip_beyond_grasp
    return np.array([[-hand.finger_size[0] / 2, hand.finger_size[0] / 2], [-reach, reach],
                     [tip - hand.finger_length, tip]])


def grasp_images(points_W: np.ndarray, normals_W: np.ndarray, X_WG: np.ndarray, *, channels: int = 15,
                 size: int = IMAGE_SIZE, hand: HandSpec | None = None) -> np.ndarray:
    """(N, channels, size, size) float32 grasp images of N candidates X_WG on a cloud with its normals,
    of the closing region of `hand` (default the Franka hand).

    Each candidate looks only at the points within its region's bounding sphere (a k-d tree's), in the
    cloud's order, and each image's sums are one weighted `bincount`: per pixel the same sums, in the same
    order, as one count per view and quantity.
    """
    if channels not in CHANNELS:
        raise ValueError(f"GPD grasp images have {' or '.join(map(str, CHANNELS))} channels, not {channels}")
    points_W, X_WG = check_cloud(points_W), check_poses(X_WG)
    out = np.zeros((len(X_WG), channels, size, size), np.float32)
    region = closing_region(hand or default_hand())
    lo, extent = region[:, 0], region[:, 1] - region[:, 0]
    # A sphere about the grasp frame's origin that holds the region (a little more: the k-d tree's query
    # must not miss a point on its boundary) [m].
    radius = float(np.linalg.norm(np.abs(region).max(axis=1))) + 1e-6
    tree = o3d.geometry.KDTreeFlann(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points_W)))
    pixels, views = size * size, np.array(VIEWS)
    for n, X in enumerate(X_WG):
        R, p = X[:3, :3], X[:3, 3]
        near = np.sort(np.asarray(tree.search_radius_vector_3d(p, radius)[1], dtype=np.int64))
        p_G = (points_W[near] - p) @ R
        inside = ((p_G >= region[:, 0]) & (p_G < region[:, 1])).all(axis=1)
        if not inside.any():
            continue
        t = (p_G[inside] - lo) / extent  # in [0, 1) along each axis
        pixel = np.minimum((t * size).astype(np.int64), size - 1)
        # (3, m): each point's pixel in each view, the views' pixels one after the other
        flat = (pixel[:, views[:, 1]] * size + pixel[:, views[:, 2]]).T + pixels * np.arange(3)[:, None]
        count = np.bincount(flat.ravel(), minlength=3 * pixels)
        hit = count > 0
        # Averaged per pixel: the depth along each view, and for 15 channels the normal's three components.
        averaged = [t[:, views[:, 0]].T]
        if channels == 15:
            n_G = normals_W[near[inside]] @ R
            averaged += [np.broadcast_to(n_G[:, k], flat.shape) for k in range(3)]
        bins = np.concatenate([flat.ravel() + 3 * pixels * q for q in range(len(averaged))])
        sums = np.bincount(bins, weights=np.concatenate([a.ravel() for a in averaged]),
                           minlength=len(averaged) * 3 * pixels).reshape(len(averaged), 3 * pixels)
        sums[:, hit] /= count[hit]
        images = sums.reshape(len(averaged), 3, size, size)
        if channels == 3:
            out[n] = images[0]
            continue
        image = out[n].reshape(3, 5, size, size)  # per view: occupancy, normal (3), depth
        image[:, 0] = hit.reshape(3, size, size)
        image[:, 1:4] = images[1:4].transpose(1, 0, 2, 3)
        image[:, 4] = images[0]
    return out


class GpdLeNet(nn.Module):
    """GPD's LeNet on (N, C, 60, 60) grasp images -> (N,) logits."""

    def __init__(self, channels: int = 15, size: int = IMAGE_SIZE):
        super().__init__()
        self.channels, self.size = channels, size
        side = ((size - 4) // 2 - 4) // 2
        self.net = nn.Sequential(
            nn.Conv2d(channels, 20, 5), nn.MaxPool2d(2),
            nn.Conv2d(20, 50, 5), nn.MaxPool2d(2), nn.Flatten(),
            nn.Linear(50 * side * side, 500), nn.ReLU(), nn.Linear(500, 1),
        )

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.net(images.float()).squeeze(-1)


def save_model(model: GpdLeNet, path: str | Path, *, card: dict) -> None:
    torch.save({"arch": ARCH, "channels": model.channels, "size": model.size,
                "state_dict": model.state_dict(), "card": card}, path)


def load_model(path: str | Path) -> tuple[GpdLeNet, dict]:
    """The network and its saved record; ValueError names a missing or corrupt file."""
    return load_weights(path, arch=ARCH, what="GPD classifier",
                        build=lambda record: GpdLeNet(int(record["channels"]), int(record["size"])))


class GpdClassifier:
    """GPD's grasp score of candidates on an object cloud, in one call.

    >>> gpd = GpdClassifier.load("models/gpd_15.pt")
    >>> score = gpd(points_W, X_WG)    # (M, 3) object cloud, (N, 4, 4) candidates -> (N,)
    """

    def __init__(self, model: GpdLeNet, gpg: GpgConfig | None = None):
        self.model, self.gpg = model, gpg or GpgConfig()  # the normals as GPG estimates them

    @classmethod
    def load(cls, path: str | Path = DEFAULT_WEIGHTS, **kwargs) -> GpdClassifier:
        return cls(load_model(path)[0], **kwargs)

    def __call__(self, points_W: np.ndarray, X_WG: np.ndarray,
                 normals: np.ndarray | None = None) -> np.ndarray:
        """`normals`: the cloud's, when the caller has them (`gpg.config_normals`)."""
        points_W = check_cloud(points_W)
        normals = config_normals(points_W, self.gpg) if normals is None else normals
        images = grasp_images(points_W, normals, X_WG, channels=self.model.channels, size=self.model.size)
        return predict_probabilities(self.model, images, 64)
