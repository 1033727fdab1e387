"""The baselines' training recipes: GPD's classifier on `collect_grasps --sampler gpg` trials and VPG's
grasp net on `--sampler topdown` trials, whole scenes held out, each with its model card (what
`python -m drake_grasp train gpd|vpg` runs; the program saves and prints)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import torch

from drake_grasp.datasets.grasp_data import GraspDataset


def baseline_recipe(model_name: str, data: GraspDataset, data_dirs: list[Path], *, command: str,
                    checkpoint: Path, heldout: GraspDataset | None = None,
                    heldout_dirs: list[Path] | None = None,
                    channels: int = 15, epochs: int = 10, seed: int = 0, test_fraction: float = 0.1,
                    patience: int | None = None,
                    log: Callable[[str], None] | None = None) -> tuple[torch.nn.Module, dict]:
    """`model_name` "gpd" (`channels` 15 or 3) or "vpg" trained on `data` (read from `data_dirs`); with
    `heldout` (objects never trained on) the card's held-out metrics, measured once after training."""
    t0 = time.perf_counter()
    common = dict(epochs=epochs, seed=seed, test_fraction=test_fraction, patience=patience, log=log,
                  checkpoint=checkpoint)
    if model_name == "gpd":
        from drake_grasp.policy.baselines.gpd_training import gpd_metrics, train_gpd

        model, result = train_gpd(data, channels=channels, **common)
        if heldout is not None:
            result["heldout_metrics"] = gpd_metrics(model, heldout, channels)
        description = (f"GPD grasp classifier (ten Pas et al. 2017): LeNet on {channels}-channel "
                       "60 x 60 grasp images of the closing region, sigmoid, BCE")
    elif model_name == "vpg":
        from drake_grasp.policy.baselines.vpg_training import train_vpg, vpg_metrics

        model, result = train_vpg(data, **common)
        if heldout is not None:
            result["heldout_metrics"] = vpg_metrics(model, heldout)
        description = ("VPG grasp net (Zeng et al. 2018, grasping only): a small fully convolutional net on "
                       "2 mm heightmaps turned to 16 jaw angles, BCE at the executed grasp")
    else:
        raise ValueError(f"unknown baseline '{model_name}'; choose gpd or vpg")
    card = {
        "model": description + ", trained from scratch on this package's trials",
        "hand": data.manifest.get("hand"),
        "data": {"folders": [str(f) for f in data_dirs], "collection": data.manifest,
                 "statistics": data.statistics()},
        **({"heldout": {"folders": [str(f) for f in heldout_dirs or []],
                        "objects": heldout.manifest.get("objects"),
                        "trials": len(heldout), "positive_rate": float(heldout.label.mean())}}
           if heldout is not None else {}),
        "command": command,
        "seed": seed, "test_fraction": test_fraction,
        "train_seconds": round(time.perf_counter() - t0, 1), **result,
    }
    return model, card
