"""Training GPD's classifier on a grasp data set: images made per batch, whole scenes held out.

The split is the stability CNN's (`split_indices`: fit, validation and test share no
scene); each scene's normals are estimated once, and the grasp images of a batch are
made when it is drawn (15 x 60 x 60 floats a trial would take 2 GB for 10,000 trials).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from drake_grasp.datasets.grasp_data import GraspDataset
from drake_grasp.learning.metrics import classification_metrics
from drake_grasp.learning.stability_training import split_indices
from drake_grasp.learning.training import (
    Checkpoint,
    TrainingConfig,
    fingerprint,
    fit,
    predict_probabilities,
    validation_scores,
)
from drake_grasp.policy.baselines.gpd import GpdLeNet, grasp_images
from drake_grasp.policy.baselines.gpg import GpgConfig, config_normals


class ImageSource:
    """Grasp images of any trials of a data set, scene normals estimated once."""

    def __init__(self, data: GraspDataset, channels: int):
        self.data, self.channels = data, channels
        self._normals: dict[int, np.ndarray] = {}

    def normals(self, scene: int) -> np.ndarray:
        """The scene cloud's normals as GPG estimates them, facing the cameras that saw it."""
        if scene not in self._normals:
            cameras = self.data.camera_positions(scene)
            config = GpgConfig() if cameras is None else GpgConfig(camera_positions=cameras)
            self._normals[scene] = config_normals(self.data.clouds[scene], config)
        return self._normals[scene]

    def images(self, index: np.ndarray) -> np.ndarray:
        index = np.asarray(index)
        out = None
        scenes = self.data.trial_scene[index]
        for scene in np.unique(scenes):
            rows = np.flatnonzero(scenes == scene)
            part = grasp_images(self.data.clouds[int(scene)], self.normals(int(scene)),
                                self.data.X_WG[index[rows]], channels=self.channels)
            if out is None:
                out = np.zeros((len(index), *part.shape[1:]), np.float32)
            out[rows] = part
        return out if out is not None else np.zeros((0, self.channels, 1, 1), np.float32)

    def predict(self, model: GpdLeNet, index: np.ndarray, chunk: int = 2048) -> np.ndarray:
        return np.concatenate([predict_probabilities(model, self.images(index[i:i + chunk]), 64)
                               for i in range(0, len(index), chunk)]) if len(index) else np.zeros(0)


def train_gpd(data: GraspDataset, *, channels: int = 15, epochs: int = 10, batch_size: int = 64,
              lr: float = 1e-3, seed: int = 0, test_fraction: float = 0.1, patience: int | None = None,
              log: Callable[[str], None] | None = None, checkpoint: Path | None = None,
              ) -> tuple[GpdLeNet, dict]:
    """GPD's LeNet trained on the data set's fit scenes (epoch chosen on the validation scenes);
    returns it and {best_epoch, history, train/validation/test metrics, trial counts}."""
    fit_rows, val_rows, test_rows = split_indices(data, test_fraction=test_fraction, seed=seed)
    source = ImageSource(data, channels)
    torch.manual_seed(seed)
    model = GpdLeNet(channels)
    labels = data.label.astype(np.float32)

    def batch(rows: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        index = fit_rows[rows]
        return torch.from_numpy(source.images(index)), torch.from_numpy(labels[index])

    def validate(m: GpdLeNet) -> dict[str, float]:
        return validation_scores(labels[val_rows], source.predict(m, val_rows))

    config = TrainingConfig(epochs=epochs, batch_size=batch_size, lr=lr, seed=seed, patience=patience,
                            progress=log is not None)
    run = {"model": "gpd", "channels": channels,
           "data": fingerprint(data.label, data.X_WG, fit_rows, val_rows)}
    info = fit(model, num_samples=len(fit_rows), batch=batch, validate=validate, config=config,
               rng=np.random.default_rng(seed), log=log,
               checkpoint=None if checkpoint is None else Checkpoint(checkpoint, run))
    result = {
        "best_epoch": info["best_epoch"], "history": info["history"], "fit_seconds": info["fit_seconds"],
        "trials": {"fit": len(fit_rows), "validation": len(val_rows), "test": len(test_rows)},
        "train_metrics": classification_metrics(data.label[fit_rows], source.predict(model, fit_rows)),
        "validation_metrics": classification_metrics(data.label[val_rows], source.predict(model, val_rows)),
        "test_metrics": classification_metrics(data.label[test_rows], source.predict(model, test_rows)),
    }
    return model, result


def gpd_metrics(model: GpdLeNet, data: GraspDataset, channels: int) -> dict:
    """Classification metrics on every trial of a data set (e.g. of objects never trained on)."""
    probabilities = ImageSource(data, channels).predict(model, np.arange(len(data)))
    return classification_metrics(data.label, probabilities)
