"""The one training loop of the learned predictors: Adam, BCE with logits, the best validation epoch kept."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

Batch = Callable[[np.ndarray], tuple[torch.Tensor, torch.Tensor]]  # sample indices -> (inputs, labels)


@dataclass(frozen=True)
class TrainingConfig:
    epochs: int = 10
    batch_size: int = 64
    lr: float = 1e-3
    seed: int = 0
    patience: int | None = None  # stop after this many epochs without a lower validation loss
    cosine_lr: bool = False  # anneal the learning rate to 0 over `epochs`


def fit(model: nn.Module, *, num_samples: int, batch: Batch,
        validate: Callable[[nn.Module], dict[str, float]], config: TrainingConfig,
        rng: np.random.Generator, log: Callable[[str], None] | None = None) -> dict:
    """Trains `model` in place, on the device its parameters are on; leaves it at its best epoch (lowest
    validation loss), in eval mode.

    Each epoch visits the samples in a random order drawn from `rng`, `batch_size` at a
    time. Returns {"best_epoch", "history"}; ValueError when no validation loss was finite.
    """
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    scheduler = (torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, config.epochs)
                 if config.cosine_lr else None)
    loss_fn = nn.BCEWithLogitsLoss()
    device = next(model.parameters()).device
    best_loss, best_state, best_epoch = float("inf"), None, 0
    history = []
    for epoch in range(1, config.epochs + 1):
        model.train()
        order = rng.permutation(num_samples)
        total = 0.0
        for i in range(0, num_samples, config.batch_size):
            x, y = batch(order[i:i + config.batch_size])
            x, y = _to_device(x, device), y.to(device)
            optimizer.zero_grad()
            loss = loss_fn(model(x), y)
            loss.backward()
            optimizer.step()
            total += float(loss.detach()) * len(y)
        if scheduler is not None:
            scheduler.step()
        model.eval()
        with torch.no_grad():
            validation = validate(model)
        history.append({"epoch": epoch, "train_loss": total / num_samples, **validation})
        if log:
            log(f"epoch {epoch:3d}  train loss {total / num_samples:.4f}  "
                + "  ".join(f"{k.replace('val_', 'validation ')} {v:.4f}" for k, v in validation.items()))
        if validation["val_loss"] < best_loss:
            best_loss, best_epoch = validation["val_loss"], epoch
            best_state = {k: v.clone() for k, v in model.state_dict().items()}
        elif config.patience is not None and epoch - best_epoch >= config.patience:
            if log:
                log(f"stopping: no better validation loss in {config.patience} epochs")
            break
    if best_state is None:
        raise ValueError("the validation loss was never finite: training diverged")
    model.load_state_dict(best_state)
    model.eval()
    return {"best_epoch": best_epoch, "history": history}


def _to_device(x: torch.Tensor | tuple, device: torch.device) -> torch.Tensor | tuple:
    """A batch's inputs (a tensor or a tuple of tensors, as the model takes them) on `device`."""
    return tuple(_to_device(v, device) for v in x) if isinstance(x, tuple) else x.to(device)


def validation_scores(labels: np.ndarray, probs: np.ndarray) -> dict[str, float]:
    """{"val_loss": binary cross-entropy, "val_accuracy": at 0.5} of predicted probabilities, what `fit`
    chooses the epoch by."""
    y = np.asarray(labels, np.float64)
    p = np.clip(np.asarray(probs), 1e-7, 1 - 1e-7)
    return {"val_loss": float(-np.mean(y * np.log(p) + (1 - y) * np.log(1 - p))),
            "val_accuracy": float(((p >= 0.5) == (y > 0.5)).mean())}


def predict_probabilities(model: nn.Module, inputs: np.ndarray, batch_size: int = 4096) -> np.ndarray:
    """sigmoid(model(inputs)) in batches, without gradients, on the model's device."""
    out = np.zeros(len(inputs), np.float32)
    device = next(model.parameters()).device
    with torch.inference_mode():
        for i in range(0, len(inputs), batch_size):
            x = torch.from_numpy(inputs[i:i + batch_size]).to(device)
            out[i:i + batch_size] = torch.sigmoid(model(x)).cpu().numpy()
    return out
