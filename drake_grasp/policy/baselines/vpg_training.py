"""Training VPG's grasp net on its trials: the loss at the executed cell and jaw angle only, as VPG does.

Trials are `collect_grasps --sampler topdown` data (straight-down grasps at heightmap
cells): each scene's heightmap is made once from its stored cloud, each trial's cell
and rotation read back from its pose. The split is the stability CNN's (whole scenes).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch import nn

from drake_grasp.datasets.grasp_data import GraspDataset
from drake_grasp.learning.metrics import classification_metrics
from drake_grasp.learning.stability_training import split_indices
from drake_grasp.learning.training import Checkpoint, TrainingConfig, fingerprint, fit, validation_scores
from drake_grasp.policy.baselines.vpg import HeightmapConfig, VpgNet, executed_logits, grasp_cell, heightmap


class ExecutedGraspLogit(nn.Module):
    """The net's logit at each trial's executed (cell, rotation): what VPG's loss sees."""

    def __init__(self, net: VpgNet):
        super().__init__()
        self.net = net

    def forward(self, batch: tuple[torch.Tensor, torch.Tensor]) -> torch.Tensor:
        heights, cells = batch  # (B, H, W), (B, 3) rows of (i, j, k)
        return executed_logits(self.net, heights, cells)


class TrialTensors:
    """Heightmaps (one per scene) and executed cells of a data set's trials."""

    def __init__(self, data: GraspDataset, config: HeightmapConfig | None = None):
        config = config or HeightmapConfig()
        scenes = sorted(int(s) for s in np.unique(data.trial_scene))
        self.row = {scene: r for r, scene in enumerate(scenes)}
        self.heights = torch.from_numpy(np.stack([heightmap(data.clouds[s], config) for s in scenes]))
        self.cells = torch.as_tensor([grasp_cell(X, config) for X in data.X_WG], dtype=torch.long)
        n = config.cells
        if ((self.cells[:, :2] < 0) | (self.cells[:, :2] >= n)).any():
            raise ValueError("some trials lie outside the heightmap's square: not VPG trials "
                             "(collect_grasps --sampler topdown)")
        self.scene_row = torch.as_tensor([self.row[int(s)] for s in data.trial_scene], dtype=torch.long)
        self.labels = torch.as_tensor(data.label, dtype=torch.float32)

    def batch(self, index: np.ndarray) -> tuple[tuple[torch.Tensor, torch.Tensor], torch.Tensor]:
        index = torch.as_tensor(index, dtype=torch.long)
        return (self.heights[self.scene_row[index]], self.cells[index]), self.labels[index]

    def predict(self, model: ExecutedGraspLogit, index: np.ndarray, chunk: int = 64) -> np.ndarray:
        out = []
        with torch.inference_mode():
            for i in range(0, len(index), chunk):
                x, _ = self.batch(index[i:i + chunk])
                out.append(torch.sigmoid(model(x)).numpy())
        return np.concatenate(out) if out else np.zeros(0)


def train_vpg(data: GraspDataset, *, epochs: int = 10, batch_size: int = 16, lr: float = 1e-3, seed: int = 0,
              test_fraction: float = 0.1, patience: int | None = None, width: int = 32,
              log: Callable[[str], None] | None = None, checkpoint: Path | None = None,
              ) -> tuple[VpgNet, dict]:
    """VPG's net trained on the fit scenes' trials (epoch chosen on the validation scenes); returns it and
    {best_epoch, history, trial counts, train/validation/test metrics at the executed grasps}."""
    fit_rows, val_rows, test_rows = split_indices(data, test_fraction=test_fraction, seed=seed)
    tensors = TrialTensors(data)
    torch.manual_seed(seed)
    model = ExecutedGraspLogit(VpgNet(width))

    def validate(m: ExecutedGraspLogit) -> dict[str, float]:
        return validation_scores(data.label[val_rows], tensors.predict(m, val_rows))

    config = TrainingConfig(epochs=epochs, batch_size=batch_size, lr=lr, seed=seed, patience=patience,
                            progress=log is not None)
    run = {"model": "vpg", "width": width,
           "data": fingerprint(data.label, data.X_WG, fit_rows, val_rows)}
    info = fit(model, num_samples=len(fit_rows), batch=lambda rows: tensors.batch(fit_rows[rows]),
               validate=validate, config=config, rng=np.random.default_rng(seed), log=log,
               checkpoint=None if checkpoint is None else Checkpoint(checkpoint, run))

    def metrics(rows: np.ndarray) -> dict:
        return classification_metrics(data.label[rows], tensors.predict(model, rows))

    return model.net, {
        "best_epoch": info["best_epoch"], "history": info["history"], "fit_seconds": info["fit_seconds"],
        "trials": {"fit": len(fit_rows), "validation": len(val_rows), "test": len(test_rows)},
        "train_metrics": metrics(fit_rows), "validation_metrics": metrics(val_rows),
        "test_metrics": metrics(test_rows),
    }


def vpg_metrics(net: VpgNet, data: GraspDataset) -> dict:
    """Classification metrics of the net at the executed grasps of every trial of a data set."""
    probabilities = TrialTensors(data).predict(ExecutedGraspLogit(net), np.arange(len(data)))
    return classification_metrics(data.label, probabilities)
