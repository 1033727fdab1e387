"""The Reachability Predictor (paper Sec. IV-C): an MLP on the determinant a, and its loader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from drake_grasp.paths import MODELS_DIR
from drake_grasp.reachability import FEATURES, reachability_features
from drake_grasp.robots import get_robot
from drake_grasp.weights import load_weights

ARCH = "reachability_mlp"


class ReachabilityMLP(nn.Module):
    """inputs -> hidden... -> 1 with ReLU, inputs normalized by stored statistics; outputs logits."""

    def __init__(self, hidden: tuple[int, ...] = (16, 8), features: str = "paper"):
        super().__init__()
        self.hidden, self.features = tuple(hidden), features
        inputs = FEATURES[features]
        sizes = (inputs, *self.hidden)
        layers: list[nn.Module] = []
        for a, b in zip(sizes, sizes[1:], strict=False):
            layers += [nn.Linear(a, b), nn.ReLU()]
        layers.append(nn.Linear(sizes[-1], 1))
        self.net = nn.Sequential(*layers)
        self.register_buffer("input_mean", torch.zeros(inputs))
        self.register_buffer("input_std", torch.ones(inputs))

    def forward(self, a: torch.Tensor) -> torch.Tensor:
        return self.net((a - self.input_mean) / self.input_std).squeeze(-1)


def save_model(model: ReachabilityMLP, path, *, robot: str, card: dict) -> None:
    torch.save({"arch": ARCH, "hidden": list(model.hidden), "features": model.features, "robot": robot,
                "state_dict": model.state_dict(), "card": card}, path)


def load_model(path) -> tuple[ReachabilityMLP, dict]:
    """The model and its saved record; ValueError names a missing or corrupt file."""
    return load_weights(path, arch=ARCH, what="reachability", build=lambda record: ReachabilityMLP(
        tuple(record["hidden"]), record.get("features", "paper")))


class ReachabilityPredictor:
    """p_r for a batch of grasps in one vectorized call.

    >>> rp = ReachabilityPredictor.load("panda")          # shipped weights
    >>> p_r = rp(X_WG)          # (N, 4, 4) grasp poses, or (N, 6) determinants
    """

    def __init__(self, model: ReachabilityMLP, robot: str, X_WB: np.ndarray | None = None):
        self.model, self.robot, self.X_WB = model, robot, X_WB

    @classmethod
    def load(cls, robot_or_path: str) -> ReachabilityPredictor:
        path = Path(robot_or_path)
        if not path.suffix:
            path = MODELS_DIR / f"reachability_{get_robot(robot_or_path).name}.pt"
        model, record = load_model(path)
        return cls(model, record["robot"])

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        poses = np.asarray(poses, dtype=np.float64)
        if poses.ndim == 3 and poses.shape[1:] == (4, 4):
            a = reachability_features(poses, self.model.features, self.X_WB)
        elif poses.ndim == 2 and poses.shape[1] == 6:
            if self.model.features != "paper":
                raise ValueError(f"this RP uses '{self.model.features}' features: pass (N, 4, 4) grasp poses")
            a = poses
        else:
            raise ValueError(f"expected (N, 4, 4) grasp poses or (N, 6) determinants, got {poses.shape}")
        if not np.isfinite(a).all():
            raise ValueError("grasp poses contain NaN or infinite values")
        with torch.inference_mode():
            return torch.sigmoid(self.model(torch.from_numpy(a.astype(np.float32)))).numpy()
