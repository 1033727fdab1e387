"""Training the grasp stability CNN on voxel grids (pure: arrays in, a model out).

Grids are kept bit-packed in memory (4 KB each, so 100k grids take 400 MB) and
unpacked per batch. The hand is symmetric, so a grid flipped along x (mirror)
or y (the jaws swapped, or mirrored) shows a grasp with the same outcome:
training draws random flips of both axes. The epoch with the lowest validation
loss is kept.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from torch import nn

from drake_grasp.cnn import GraspCNN, predict_grids
from drake_grasp.voxels import GRID


def pack(grids: np.ndarray) -> np.ndarray:
    """(N, G, G, G) uint8 occupancy -> (N, G^3 / 8) bits."""
    return np.packbits(grids.reshape(len(grids), -1), axis=1)


def unpack(packed: np.ndarray, grid: int = GRID) -> np.ndarray:
    return np.unpackbits(packed, axis=1, count=grid**3).reshape(-1, grid, grid, grid)


def random_flips(grids: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Each grid flipped along x and along y, each with probability 1/2 (index i -> G-1-i)."""
    out = grids.copy()
    fx, fy = rng.random(len(grids)) < 0.5, rng.random(len(grids)) < 0.5
    out[fx] = out[fx, ::-1]
    out[fy] = out[fy, :, ::-1]
    return out


def predict_packed(model: GraspCNN, packed: np.ndarray, batch_size: int = 512) -> np.ndarray:
    return np.concatenate([predict_grids(model, unpack(packed[i:i + batch_size], model.grid))
                           for i in range(0, len(packed), batch_size)]) if len(packed) else np.zeros(0)


def train_stability(packed: np.ndarray, labels: np.ndarray, *, val_packed: np.ndarray,
                    val_labels: np.ndarray, epochs: int = 10, batch_size: int = 64, lr: float = 1e-3,
                    seed: int = 0, first_stride: int = 2, augment: bool = True, patience: int | None = None,
                    log: Callable[[str], None] | None = None) -> tuple[GraspCNN, dict]:
    """Trains the CNN with Adam and BCE; returns the best-validation-loss model and its history.

    With `patience`, training stops once that many epochs in a row have not lowered the
    validation loss.
    """
    if len(labels) < 2 or len(val_labels) < 1:
        raise ValueError(f"need training and validation grasps, got {len(labels)} and {len(val_labels)}")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    model = GraspCNN(first_stride)
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)
    loss_fn = nn.BCEWithLogitsLoss()
    y_all = torch.from_numpy(np.asarray(labels, np.float32))
    best = (float("inf"), {k: v.clone() for k, v in model.state_dict().items()}, 0)
    history = []
    for epoch in range(epochs):
        model.train()
        order = rng.permutation(len(labels))
        total = 0.0
        for i in range(0, len(order), batch_size):
            idx = np.sort(order[i:i + batch_size])
            grids = unpack(packed[idx], model.grid)
            if augment:
                grids = random_flips(grids, rng)
            optimizer.zero_grad()
            loss = loss_fn(model(torch.from_numpy(np.ascontiguousarray(grids))), y_all[idx])
            loss.backward()
            optimizer.step()
            total += float(loss.detach()) * len(idx)
        model.eval()
        p = np.clip(predict_packed(model, val_packed), 1e-7, 1 - 1e-7)
        y = np.asarray(val_labels, np.float64)
        val_loss = float(-np.mean(y * np.log(p) + (1 - y) * np.log(1 - p)))
        val_accuracy = float(((p >= 0.5) == (y > 0.5)).mean())
        history.append({"epoch": epoch + 1, "train_loss": total / len(labels), "val_loss": val_loss,
                        "val_accuracy": val_accuracy})
        if log:
            log(f"epoch {epoch + 1:3d}  train loss {total / len(labels):.4f}  "
                f"validation loss {val_loss:.4f}  accuracy {val_accuracy:.4f}")
        if val_loss < best[0]:
            best = (val_loss, {k: v.clone() for k, v in model.state_dict().items()}, epoch + 1)
        elif patience is not None and epoch + 1 - best[2] >= patience:
            if log:
                log(f"stopping: no better validation loss in {patience} epochs")
            break
    if best[2] == 0:
        raise ValueError("the validation loss was never finite: training diverged")
    model.load_state_dict(best[1])
    model.eval()
    return model, {"best_epoch": best[2], "history": history}
