"""The hold predictor p_h: whether a grasp that lifts its object holds it against the pivot of its weight.

A parallel-jaw grasp away from an object's centre of mass lets the object pivot about the
jaws' closing axis as it is lifted, when the pads' torsional friction cannot carry gravity's
torque m g d: a long bottle taken near one end turns until it hangs and rises less than the
task asks ("object slipped"). The stability CNN sees the 10 cm around the grasp and cannot
tell where a 25 cm object's mass lies. The hold predictor looks at the whole observed object:

- the object cloud is split into objects (`perception.cloud.segment_objects`, DBSCAN; with `join_parts`, a
  part that continues a body end to end, a lying bottle's neck that the camera sees apart from its
  body, joins it: `perception.cloud.join_end_to_end`), and the object of a candidate is the segment of the
  cloud point nearest its grasp point;
- `lever`: the horizontal distance of that segment's centroid from the closing axis (gravity's
  torque about the axis is m g lever) [m];
- `size`: the diagonal of the segment's axis-aligned box [m] (an object's mass grows with it).

p_h = sigmoid(b + w . (lever, lever * size, lever^2)), fitted by logistic regression on the
physics trials that lifted their object (a success against "object slipped"). The policies
rank by p_r * p_s * p_h (`SelectionConfig.hold_weights`: the shipped `models/grasp_hold.pt` by
default, fitted on plain DBSCAN segments and used with `join_parts`, `SelectionConfig.hold_join_parts`;
None leaves p_h out, as the paper).
Pure functions; the model is a `torch.nn.Linear` saved like the other networks.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import torch
from torch import nn

from drake_grasp.learning.weights import load_weights
from drake_grasp.perception.cloud import join_end_to_end, segment_objects
from drake_grasp.robot.paths import MODELS_DIR, model_path

ARCH = "hold-logistic-v1"
DEFAULT_WEIGHTS = MODELS_DIR / "grasp_hold.pt"
FEATURES = ("lever", "lever*size", "lever^2")
FEATURE_SCALE = 10.0  # features in decimetres: coefficients of order one
NOISE_NEIGHBOURHOOD = 0.03  # [m] a grasp point nearest a DBSCAN noise point takes the points this near


def lever_and_size(points_W: np.ndarray, X_WG: np.ndarray, labels: np.ndarray | None = None,
                   join_parts: bool = False) -> np.ndarray:
    """(N, 2) [lever, size] of N candidates X_WG (N, 4, 4) on an object cloud (M, 3), see the module.

    `labels`: the cloud's segments if already computed (else `segment_objects`, and with `join_parts`
    `join_end_to_end` of them). A
    grasp point whose nearest point is DBSCAN noise takes the points within `NOISE_NEIGHBOURHOOD` as
    its object (that nearest point alone when it lies farther: a lone reading, lever from it and size 0).
    """
    points_W = np.asarray(points_W, dtype=np.float64)
    X_WG = np.asarray(X_WG, dtype=np.float64).reshape(-1, 4, 4)
    if len(points_W) == 0:
        raise ValueError("hold features need a non-empty object cloud")
    if labels is None:
        labels = segment_objects(points_W)
        if join_parts:
            labels = join_end_to_end(points_W, labels)
    keys = np.unique(labels[labels >= 0])
    segments = [points_W[labels == k] for k in keys]
    centroids = np.array([seg.mean(axis=0) for seg in segments]).reshape(-1, 3)
    sizes = np.array([np.linalg.norm(np.ptp(seg, axis=0)) for seg in segments])
    p_WG = X_WG[:, :3, 3]
    search = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor(points_W))
    search.knn_index()
    nearest = search.knn_search(o3d.core.Tensor(p_WG), 1)[0].numpy()[:, 0].astype(int)
    label = labels[nearest]
    on_object = label >= 0
    c, s = np.zeros((len(X_WG), 3)), np.zeros(len(X_WG))
    c[on_object] = centroids[np.searchsorted(keys, label[on_object])]
    s[on_object] = sizes[np.searchsorted(keys, label[on_object])]
    noise = np.flatnonzero(~on_object)  # nearest a noise point: the points around the grasp point
    for start in range(0, len(noise), 32):  # (32 candidates x the cloud at a time)
        chunk = noise[start:start + 32]
        d = (points_W[None] - p_WG[chunk, None]) ** 2
        near_mask = d[..., 0] + d[..., 1] + d[..., 2] <= NOISE_NEIGHBOURHOOD**2
        for i, mask in zip(chunk, near_mask, strict=True):
            near = points_W[mask] if mask.any() else points_W[[nearest[i]]]
            c[i], s[i] = near.mean(axis=0), np.linalg.norm(np.ptp(near, axis=0))
    r, y = c - p_WG, X_WG[:, :3, 1]
    return np.column_stack([np.abs(r[:, 0] * y[:, 1] - r[:, 1] * y[:, 0]), s])


def hold_features(lever_size: np.ndarray) -> np.ndarray:
    """(N, 3) model inputs from (N, 2) [lever, size]."""
    lever, size = (np.asarray(lever_size, dtype=np.float64) * FEATURE_SCALE).T
    return np.stack([lever, lever * size, lever**2], axis=1)


class HoldModel(nn.Linear):
    """Logistic regression on `hold_features`: the logit of p_h."""

    def __init__(self):
        super().__init__(len(FEATURES), 1)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return super().forward(features).squeeze(-1)


def fit_hold(lever_size: np.ndarray, held: np.ndarray, *, l2: float = 1e-3,
             iterations: int = 50) -> HoldModel:
    """Maximum-likelihood logistic regression (Newton's method, a little L2 on the weights) of `held`
    (1: lifted and held, 0: slipped) on the features of `lever_size`."""
    A = np.column_stack([np.ones(len(held)), hold_features(lever_size)])
    y = np.asarray(held, dtype=np.float64)
    if len(y) == 0 or y.min() == y.max():
        raise ValueError("fitting the hold predictor needs both held and slipped trials")
    w = np.zeros(A.shape[1])
    w[0] = np.log(y.mean() / (1 - y.mean()))
    ridge = l2 * len(y) * np.diag([0.0] + [1.0] * (A.shape[1] - 1))
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-A @ w))
        step = np.linalg.solve((A * (p * (1 - p))[:, None]).T @ A + ridge, A.T @ (p - y) + ridge @ w)
        w -= step
        if np.abs(step).max() < 1e-9:
            break
    model = HoldModel().requires_grad_(False)
    with torch.no_grad():
        model.bias.copy_(torch.tensor([w[0]]))
        model.weight.copy_(torch.tensor(w[None, 1:]))
    return model


def predict_hold(model: HoldModel, lever_size: np.ndarray) -> np.ndarray:
    """(N,) p_h."""
    with torch.no_grad():
        logits = model(torch.as_tensor(hold_features(lever_size), dtype=torch.float32))
    return torch.sigmoid(logits).numpy().astype(np.float64)


def save_hold(model: HoldModel, path: str | Path, *, card: dict) -> None:
    """The model and its card."""
    torch.save({"arch": ARCH, "state_dict": model.state_dict(), "card": card}, path)


class HoldPredictor:
    """p_h of candidates on an object cloud, from a saved `HoldModel`; `join_parts`: whether a part that
    continues a body end to end joins it (`perception.cloud.join_end_to_end`)."""

    def __init__(self, model: HoldModel, join_parts: bool = False):
        self.model = model
        self.join_parts = join_parts

    @classmethod
    def load(cls, path: str | Path = DEFAULT_WEIGHTS, join_parts: bool = False) -> HoldPredictor:
        """The hold predictor saved at `path` (a shipped one also by its repository name)."""
        model, _ = load_weights(model_path(path), arch=ARCH, what="hold predictor",
                                build=lambda record: HoldModel())
        return cls(model, join_parts)

    def __call__(self, points_W: np.ndarray, X_WG: np.ndarray) -> np.ndarray:
        return predict_hold(self.model, lever_and_size(points_W, X_WG, join_parts=self.join_parts))


def lifted_trials(dataset) -> np.ndarray:
    """Indices of a `GraspDataset`'s trials that lifted their object: held (success) or slipped."""
    from drake_grasp.robot.task import TrialOutcome

    return np.flatnonzero(np.isin(dataset.outcome, [TrialOutcome.SUCCESS, TrialOutcome.OBJECT_SLIPPED]))


def trial_lever_size(dataset, index: np.ndarray) -> np.ndarray:
    """(n, 2) [lever, size] of a `GraspDataset`'s trials `index`, each on its scene's stored cloud."""
    index = np.asarray(index)
    out = np.zeros((len(index), 2))
    scenes = dataset.trial_scene[index]
    for scene in np.unique(scenes):
        rows = np.flatnonzero(scenes == scene)
        out[rows] = lever_and_size(dataset.clouds[int(scene)], dataset.X_WG[index[rows]])
    return out


LEVER_BINS = (0.0, 0.02, 0.04, 0.06, 0.08, 0.12, 1.0)  # [m] for the slip-rate table of a model card


def slip_table(lever_size: np.ndarray, held: np.ndarray, p_h: np.ndarray) -> list[dict]:
    """Per lever bin: trials, the measured slip rate and the predicted one (a calibration table)."""
    rows = []
    for lo, hi in zip(LEVER_BINS[:-1], LEVER_BINS[1:], strict=True):
        m = (lever_size[:, 0] >= lo) & (lever_size[:, 0] < hi)
        if m.any():
            rows.append({"lever_cm": f"{100 * lo:.0f}-{100 * hi:.0f}", "n": int(m.sum()),
                         "slip_rate": round(float(1 - held[m].mean()), 4),
                         "predicted": round(float(1 - p_h[m].mean()), 4)})
    return rows
