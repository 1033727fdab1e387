"""The one training loop of the learned predictors: Adam, BCE with logits, the best validation epoch kept.

With a checkpoint file, `fit` saves its whole state (weights, optimizer, random
streams, the epoch's order and position) every few minutes and at each epoch's end,
and a later call with the same run picks up where it stopped: an interrupted
training loses at most those minutes, and its result is the uninterrupted one's.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

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
    progress: bool = False  # a progress bar over each epoch's batches


@dataclass(frozen=True)
class Checkpoint:
    """Where `fit` keeps its state, and how often; `run` names the training (data, model, settings):
    a checkpoint of another run is refused rather than resumed."""
    path: Path
    run: dict
    every_seconds: float = 300.0


def fit(model: nn.Module, *, num_samples: int, batch: Batch,
        validate: Callable[[nn.Module], dict[str, float]], config: TrainingConfig,
        rng: np.random.Generator, log: Callable[[str], None] | None = None,
        checkpoint: Checkpoint | None = None) -> dict:
    """Trains `model` in place, on the device its parameters are on; leaves it at its best epoch (lowest
    validation loss), in eval mode.

    Each epoch visits the samples in a random order drawn from `rng`, `batch_size` at a
    time. Returns {"best_epoch", "history", "fit_seconds" (the training's time, over all the
    sessions it took)}; ValueError when no validation loss was finite,
    or when `checkpoint` holds another run's state. The checkpoint file stays when
    training ends (the caller removes it once the model is saved); resumed with a larger
    `epochs`, a finished training goes on.
    """
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    scheduler = (torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, config.epochs)
                 if config.cosine_lr else None)
    loss_fn = nn.BCEWithLogitsLoss()
    device = next(model.parameters()).device
    run = None if checkpoint is None else {"config": _resumable_config(config), "num_samples": num_samples,
                                           **checkpoint.run}
    state = {"epoch": 1, "order": None, "position": 0, "total": 0.0, "best_loss": float("inf"),
             "best_state": None, "best_epoch": 0, "history": [], "stopped": False, "seconds": 0.0}
    if checkpoint is not None and checkpoint.path.exists():
        state = _resume(checkpoint.path, run, model, optimizer, scheduler, rng)
        if log:
            log(f"resuming {checkpoint.path} at epoch {state['epoch']}, sample {state['position']} of "
                f"{num_samples}")
    last_save = clock = time.monotonic()

    def tick() -> None:  # training time, summed over the sessions a resumed training spans
        nonlocal clock
        now = time.monotonic()
        state["seconds"] += now - clock
        clock = now

    def save() -> None:
        nonlocal last_save
        if checkpoint is not None:
            tick()
            _save(checkpoint.path, run, state, model, optimizer, scheduler, rng)
            last_save = time.monotonic()

    while not state["stopped"] and state["epoch"] <= config.epochs:
        epoch = state["epoch"]
        model.train()
        if state["order"] is None:
            state["order"], state["position"], state["total"] = rng.permutation(num_samples), 0, 0.0
        order = state["order"]
        bar = _progress(config.progress, num_samples, state["position"], f"epoch {epoch}")
        for i in range(state["position"], num_samples, config.batch_size):
            x, y = batch(order[i:i + config.batch_size])
            x, y = _to_device(x, device), y.to(device)
            optimizer.zero_grad()
            loss = loss_fn(model(x), y)
            loss.backward()
            optimizer.step()
            state["total"] += float(loss.detach()) * len(y)
            state["position"] = min(i + config.batch_size, num_samples)
            if bar is not None:
                bar.update(len(y))
            if checkpoint is not None and time.monotonic() - last_save >= checkpoint.every_seconds:
                save()
        if bar is not None:
            bar.close()
        if scheduler is not None:
            scheduler.step()
        model.eval()
        with torch.no_grad():
            validation = validate(model)
        train_loss = state["total"] / num_samples
        state["history"].append({"epoch": epoch, "train_loss": train_loss, **validation})
        if log:
            log(f"epoch {epoch:3d}  train loss {train_loss:.4f}  "
                + "  ".join(f"{k.replace('val_', 'validation ')} {v:.4f}" for k, v in validation.items()))
        if validation["val_loss"] < state["best_loss"]:
            state["best_loss"], state["best_epoch"] = validation["val_loss"], epoch
            state["best_state"] = {k: v.detach().clone() for k, v in model.state_dict().items()}
        elif config.patience is not None and epoch - state["best_epoch"] >= config.patience:
            if log:
                log(f"stopping: no better validation loss in {config.patience} epochs")
            state["stopped"] = True  # by patience
        state["epoch"], state["order"], state["position"], state["total"] = epoch + 1, None, 0, 0.0
        save()
    if state["best_state"] is None:
        raise ValueError("the validation loss was never finite: training diverged")
    tick()
    model.load_state_dict(state["best_state"])
    model.eval()
    return {"best_epoch": state["best_epoch"], "history": state["history"],
            "fit_seconds": round(state["seconds"], 3)}


def fingerprint(*arrays: np.ndarray) -> str:
    """A digest of arrays' shapes and bytes: which data a checkpoint was trained on."""
    digest = hashlib.sha1()
    for array in arrays:
        array = np.ascontiguousarray(array)
        digest.update(repr((array.shape, array.dtype.str)).encode())
        digest.update(array.data)
    return digest.hexdigest()


def _resumable_config(config: TrainingConfig) -> dict:
    """The settings a checkpoint must share with the training that resumes it: without a cosine schedule,
    the epoch count, patience and progress bar do not change the steps, so a finished training can go on
    for more epochs or a running one stop sooner."""
    settings = asdict(config)
    del settings["progress"]
    if not config.cosine_lr:
        del settings["epochs"], settings["patience"]
    return settings


def _progress(show: bool, total: int, done: int, label: str):
    if not show:
        return None
    from tqdm import tqdm

    return tqdm(total=total, initial=done, unit="samples", desc=label, leave=False, mininterval=2.0)


def _save(path: Path, run: dict, state: dict, model: nn.Module, optimizer: torch.optim.Optimizer,
          scheduler, rng: np.random.Generator) -> None:
    """The whole training state, written to a temporary file first so an interruption leaves the last one."""
    payload = {"run": run, "state": state, "model": model.state_dict(), "optimizer": optimizer.state_dict(),
               "scheduler": None if scheduler is None else scheduler.state_dict(),
               "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state()}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    tmp.replace(path)


def _resume(path: Path, run: dict, model: nn.Module, optimizer: torch.optim.Optimizer, scheduler,
            rng: np.random.Generator) -> dict:
    try:
        payload = torch.load(path, map_location=next(model.parameters()).device, weights_only=False)
    except Exception as error:  # noqa: BLE001 - a truncated or foreign file
        raise ValueError(f"training checkpoint {path} is unreadable ({error}); remove it to start over") \
            from None
    if payload.get("run") != run:
        raise ValueError(f"training checkpoint {path} belongs to another training run (other data or "
                         "settings); remove it to start over")
    model.load_state_dict(payload["model"])
    optimizer.load_state_dict(payload["optimizer"])
    if scheduler is not None:
        scheduler.load_state_dict(payload["scheduler"])
    rng.bit_generator.state = payload["rng"]
    torch.set_rng_state(payload["torch_rng"])
    return payload["state"]


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
