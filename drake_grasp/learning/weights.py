"""Loading a learned model's weights file: one set of clear errors for every network."""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path

import torch
from torch import nn


def read_record(path: str | Path, what: str = "") -> object:
    """What a weights file holds (torch's `weights_only` load, on the CPU); ValueError names a missing or
    damaged file (`what` the model it should hold)."""
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise ValueError(f"weights file not found: {path}") from None
    except Exception as e:  # torch raises many types for a damaged file
        model = f"{what} " if what else ""
        raise ValueError(f"corrupt {model}weights {path}: {str(e).splitlines()[0]}") from None


def load_weights(path: str | Path, *, arch: str, what: str,
                 build: Callable[[dict], nn.Module]) -> tuple[nn.Module, dict]:
    """The network `build(record)` makes, with the file's state loaded, in eval mode, and the record.

    ValueError names a missing file, a damaged one, or one holding another network (`arch`).
    """
    record = read_record(path, what)
    if not isinstance(record, dict) or record.get("arch") != arch:
        found = record.get("arch") if isinstance(record, dict) else type(record).__name__
        raise ValueError(f"{path}: not {what} weights (arch {found!r})")
    try:
        model = build(record)
        model.load_state_dict(record["state_dict"])
    except (KeyError, RuntimeError, TypeError, ValueError) as e:
        raise ValueError(f"corrupt {what} weights {path}: {str(e).splitlines()[0]}") from None
    model.eval()
    return model, record


def weights_digest(path: str | Path) -> str:
    """The first 12 hex digits of the file's SHA-256: which weights a result was made with."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:12]
    except OSError as e:
        raise ValueError(f"cannot read weights file {path}: {e.strerror}") from None
