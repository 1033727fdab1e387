"""Grasp stability CNN report: test accuracy against training-set size (paper Fig. 4).

Trains the CNN on nested subsets of the training scenes (whole scenes, 1,000 to
60,000 grasps, and the full set) and evaluates each on the same held-out scenes (and, with
--novel, on objects never trained on). Writes `OUT.png` (the curve), `OUT.md`
(the table and the data set statistics) and `OUT.json`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from drake_grasp.cli import fail, fraction, positive_int, positive_ints
from drake_grasp.cnn import GraspCNN, load_model
from drake_grasp.grasp_data import GraspDataset, load_grasp_dataset
from drake_grasp.metrics import classification_metrics
from drake_grasp.stability_training import pack, predict_packed, train_stability
from drake_grasp.voxels import GRID

VALIDATION_FRACTION = 0.05  # of the training scenes, for choosing the epoch
MIN_SAMPLES_SEEN = 100_000  # the curve's small subsets train for more epochs


def packed_voxels(data: GraspDataset, index: np.ndarray, chunk: int = 5000) -> np.ndarray:
    """Bit-packed grids of the trials `index`, voxelized in chunks to bound memory."""
    return np.concatenate([pack(data.voxels(index[i:i + chunk])) for i in range(0, len(index), chunk)]
                          ) if len(index) else np.zeros((0, GRID**3 // 8), np.uint8)


def split_indices(data: GraspDataset, *, test_fraction: float, seed: int,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(fit, validation, test) trial indices; the three share no scene.

    Fit lists whole scenes in a seeded random order, so its first n trials (the learning
    curve's subsets) are nested sets of whole scenes.
    """
    pool, test = data.scene_split(test_fraction, seed)
    fit, val = data.subset(pool).scene_split(VALIDATION_FRACTION, seed + 1)
    fit, val = pool[fit], pool[val]
    scenes = np.random.default_rng(seed).permutation(np.unique(data.trial_scene[fit]))
    rank = np.empty(scenes.max() + 1, np.int64)
    rank[scenes] = np.arange(len(scenes))
    return fit[np.argsort(rank[data.trial_scene[fit]], kind="stable")], val, test


def prepare_grids(data: GraspDataset, *, novel: GraspDataset | None, test_fraction: float, seed: int,
                  cache: dict) -> dict:
    """Fills `cache` with the split and the packed grids of every part (once)."""
    if "fit" not in cache:
        if novel is not None:
            seen = sorted(set(novel.scene_object.values()) & set(data.scene_object.values()))
            if seen:
                raise ValueError(f"the novel set holds objects of the training set ({', '.join(seen)})")
        fit, val, test = split_indices(data, test_fraction=test_fraction, seed=seed)
        if len(fit) == 0 or len(val) == 0 or len(test) == 0:
            raise ValueError(f"{len(data)} grasps in {len(np.unique(data.trial_scene))} scenes are too few "
                             "to hold out validation and test scenes; collect more")
        cache.update(fit=fit, val=val, test=test, fit_packed=packed_voxels(data, fit),
                     val_packed=packed_voxels(data, val), test_packed=packed_voxels(data, test))
        if novel is not None:
            cache["novel_packed"] = packed_voxels(novel, np.arange(len(novel)))
    return cache


def fit_and_evaluate(data: GraspDataset, *, novel: GraspDataset | None = None, limit: int | None = None,
                     epochs: int = 10, seed: int = 0, test_fraction: float = 0.1, first_stride: int = 2,
                     log: Callable[[str], None] | None = None, cache: dict | None = None,
                     min_samples_seen: int = 0, patience: int | None = None) -> tuple[GraspCNN, dict]:
    """Trains on the first `limit` training grasps; returns the model and its metrics.

    `cache` (a dict the caller keeps) holds the packed grids between calls; a subset
    trains for more than `epochs` when that is what it takes to see `min_samples_seen`.
    """
    cache = prepare_grids(data, novel=novel, test_fraction=test_fraction, seed=seed,
                          cache={} if cache is None else cache)
    n = len(cache["fit"]) if limit is None else min(limit, len(cache["fit"]))
    fit_labels = data.label[cache["fit"][:n]]
    epochs_here = max(epochs, math.ceil(min_samples_seen / max(n, 1)))
    model, info = train_stability(cache["fit_packed"][:n], fit_labels, val_packed=cache["val_packed"],
                                  val_labels=data.label[cache["val"]], epochs=epochs_here, seed=seed,
                                  first_stride=first_stride, patience=patience, log=log)
    result = {"train_grasps": int(n), "epochs": len(info["history"]), "best_epoch": info["best_epoch"],
              **evaluate(model, data, novel=novel, cache=cache, limit=n), "history": info["history"]}
    return model, result


def evaluate(model: GraspCNN, data: GraspDataset, *, novel: GraspDataset | None, cache: dict,
             limit: int, train_metrics: dict | None = None) -> dict:
    """Metrics of a model trained on the first `limit` fit grasps: training, held-out scenes, novel.

    `train_metrics` already known (the shipped model's card) are taken as they are.
    """
    if train_metrics is None:
        train_metrics = classification_metrics(data.label[cache["fit"][:limit]],
                                               predict_packed(model, cache["fit_packed"][:limit]))
    result = {
        "validation_grasps": int(len(cache["val"])), "test_grasps": int(len(cache["test"])),
        "test_scenes": int(len(np.unique(data.trial_scene[cache["test"]]))),
        "train_metrics": train_metrics,
        "test_metrics": classification_metrics(data.label[cache["test"]],
                                               predict_packed(model, cache["test_packed"])),
    }
    if novel is not None:
        result["novel_metrics"] = classification_metrics(
            novel.label, predict_packed(model, cache["novel_packed"]))
    return result


def split_scene_ids(data: GraspDataset, cache: dict) -> dict[str, list[int]]:
    """The scenes held out for validation and testing (recorded in the model card)."""
    return {part: sorted(int(k) for k in np.unique(data.trial_scene[cache[key]]))
            for part, key in (("validation", "val"), ("test", "test"))}


def checked_full_model(path: Path, data: GraspDataset, *, cache: dict, first_stride: int,
                       ) -> tuple[GraspCNN, dict]:
    """Weights `train stability` made on all of this split's training grasps, and their card.

    ValueError when they were trained on another split, subset or architecture.
    """
    model, record = load_model(path)
    card = record.get("card", {})
    if card.get("split") != split_scene_ids(data, cache) or card.get("train_grasps") != len(cache["fit"]):
        raise ValueError(f"{path} was not trained on all training scenes of this split (another data "
                         "set, seed, test fraction or --limit): retrain it or leave out --full-model")
    if model.first_stride != first_stride:
        raise ValueError(f"{path} has first stride {model.first_stride}, the curve {first_stride}")
    return model, card


def draw_curve(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    sizes = [r["train_grasps"] for r in rows]
    ax.plot(sizes, [r["test_metrics"]["accuracy"] for r in rows], "o-", label="held-out scenes (primitives)")
    if "novel_metrics" in rows[0]:
        ax.plot(sizes, [r["novel_metrics"]["accuracy"] for r in rows], "s--", label="novel objects")
    ax.axhline(1 - rows[-1]["test_metrics"]["positive_rate"], color="grey", lw=0.8, ls=":",
               label="always 'unstable'")
    ax.set_xscale("log")
    ax.set_xlabel("training grasps")
    ax.set_ylabel("test accuracy")
    ax.set_title("Grasp stability CNN: accuracy vs. training data")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def markdown(rows: list[dict], stats: dict, command: str) -> str:
    lines = ["# Grasp stability CNN: accuracy vs. training-set size", "", f"`{command}`", "",
             "| training grasps | epochs | accuracy | precision | recall | AUROC "
             "| novel accuracy | novel AUROC |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        t, nv = r["test_metrics"], r.get("novel_metrics")
        novel = f"{nv['accuracy']:.4f} | {nv['auroc']:.4f}" if nv else "- | -"
        lines.append(f"| {r['train_grasps']} | {r['epochs']} | {t['accuracy']:.4f} | {t['precision']:.4f} | "
                     f"{t['recall']:.4f} | {t['auroc']:.4f} | {novel} |")
    lines += ["", f"Test set: {rows[0]['test_grasps']} grasps from {rows[0]['test_scenes']} scenes never "
              f"seen in training (positive rate {rows[0]['test_metrics']['positive_rate']:.3f}).", "",
              "## Data set", "", f"{stats['trials']} trials in {stats['scenes']} scenes, positive rate "
              f"{stats['positive_rate']:.3f}.", "",
              "| object | trials | " + " | ".join(stats["outcomes"]) + " |",
              "|---|---|" + "---|" * len(stats["outcomes"])]
    for name, counts in stats["per_object"].items():
        lines.append(f"| {name} | {counts['trials']} | "
                     + " | ".join(str(counts.get(o, 0)) for o in stats["outcomes"]) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.stability_report", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True, help="collect_grasps folder (primitives)")
    parser.add_argument("--novel", type=Path, default=None, help="collect_grasps folder of novel objects")
    parser.add_argument("--out", type=Path, required=True, help="output prefix: OUT.png, OUT.md, OUT.json")
    parser.add_argument("--sizes", type=positive_ints, default=[1000, 2000, 5000, 10000, 20000, 60000],
                        help="comma-separated training-set sizes (the full set is added)")
    parser.add_argument("--epochs", type=positive_int, default=10,
                        help="epochs per subset (at most, with --patience)")
    parser.add_argument("--min-samples", type=positive_int, default=MIN_SAMPLES_SEEN,
                        help="small subsets train for more epochs, until they have seen this many grasps")
    parser.add_argument("--patience", type=positive_int, default=None,
                        help="stop a subset after this many epochs without a lower validation loss")
    parser.add_argument("--full-model", type=Path, default=None,
                        help="weights `train stability` made on this data with the same seed and test "
                             "fraction: the full-set row evaluates them instead of retraining")
    parser.add_argument("--test-fraction", type=fraction, default=0.1, help="scenes held out for testing")
    parser.add_argument("--first-stride", type=int, choices=(1, 2), default=2,
                        help="2: the VoxNet variant (default, 10x faster on a CPU); 1: the paper's")
    parser.add_argument("--threads", type=positive_int, default=None)
    parser.add_argument("--seed", type=int, default=0)
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    try:
        data = load_grasp_dataset(args.data)
        novel = load_grasp_dataset(args.novel) if args.novel is not None else None
        cache = prepare_grids(data, novel=novel, test_fraction=args.test_fraction, seed=args.seed, cache={})
        full = None if args.full_model is None else checked_full_model(
            args.full_model, data, cache=cache, first_stride=args.first_stride)
        rows = []
        sizes = [n for n in args.sizes if n < len(cache["fit"])]
        for limit in [*sizes, None]:  # the full set last
            t0 = time.perf_counter()
            if limit is None and full is not None:
                (model, card), n = full, len(cache["fit"])
                result = {"train_grasps": n, "epochs": card.get("epochs"),
                          "best_epoch": card.get("best_epoch"), "weights": str(args.full_model),
                          **evaluate(model, data, novel=novel, cache=cache, limit=n,
                                     train_metrics=card.get("train_metrics"))}
            else:
                _, result = fit_and_evaluate(data, novel=novel, limit=limit, epochs=args.epochs,
                                             seed=args.seed, test_fraction=args.test_fraction,
                                             first_stride=args.first_stride, cache=cache,
                                             min_samples_seen=args.min_samples, patience=args.patience)
            result["seconds"] = round(time.perf_counter() - t0, 1)
            rows.append(result)
            m = result["test_metrics"]
            print(f"{result['train_grasps']:>7} grasps: accuracy {m['accuracy']:.4f} AUROC {m['auroc']:.4f} "
                  f"({result['seconds']:.0f} s)", flush=True)
    except ValueError as e:
        return fail(e)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    command = "python -m drake_grasp.stability_report " + " ".join(argv)
    stats = data.statistics()
    for r in rows:
        r.pop("history", None)
    args.out.with_suffix(".json").write_text(json.dumps({"command": command, "statistics": stats,
                                                         "rows": rows}, indent=1))
    args.out.with_suffix(".md").write_text(markdown(rows, stats, command))
    draw_curve(rows, args.out.with_suffix(".png"))
    print(f"report: {args.out.with_suffix('.md')}, {args.out.with_suffix('.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
