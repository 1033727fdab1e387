"""Weights and their model cards on disk, and a training's resumable checkpoint beside them.

Every shipped model is a weights file (`FILE.pt`) with its card beside it (`FILE.json`: the data, the
command, the seed and the metrics); a training in progress keeps its state in `FILE.checkpoint.pt`
until the weights are saved.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import torch

from drake_grasp.learning.weights import read_record

CHECKPOINT_SUFFIX = ".checkpoint.pt"  # a training's resumable state beside its weights, never shipped


def checkpoint_path(out: Path) -> Path:
    """Where a training writing `out` keeps its resumable state until the weights are saved."""
    return out.with_name(out.stem + CHECKPOINT_SUFFIX)


def save_with_card(save: Callable[..., None], model: torch.nn.Module, out: Path, card: dict) -> None:
    """The weights (by the model's own `save`) and the card beside them; a training checkpoint goes after."""
    out.parent.mkdir(parents=True, exist_ok=True)
    save(model, out, card=card)
    out.with_suffix(".json").write_text(json.dumps(card, indent=1))
    checkpoint_path(out).unlink(missing_ok=True)


def saved_card(path: Path) -> dict:
    """The model card saved in a weights file ({} when it holds none); ValueError names a file that does
    not load."""
    record = read_record(path)
    card = record.get("card") if isinstance(record, dict) else None
    return card if isinstance(card, dict) else {}


def metrics_lines(card: dict, names: tuple[str, ...]) -> list[str]:
    """One line per metrics set of `card` that it has (accuracy, precision, recall, AUROC, ECE)."""
    lines = []
    for name in names:
        if name in card:
            m = card[name]
            lines.append(f"{name.split('_')[0]:>10}: n={m['n']} accuracy {m['accuracy']:.4f} "
                         f"precision {m['precision']:.4f} recall {m['recall']:.4f} "
                         f"AUROC {m['auroc']:.4f} ECE {m['ece']:.4f}")
    return lines
