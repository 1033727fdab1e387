"""Grasp stability CNN report: test accuracy against training-set size (paper Fig. 4), or held-out
AUROC against the number of training objects at a fixed trial count (--object-counts on one
data set, or --object-sets: one data set per point).

Trains the CNN on nested subsets of the training scenes (whole scenes, 1,000 to
60,000 grasps, and the full set) and evaluates each on the same held-out scenes (and, with
--novel, on objects never trained on). Writes `OUT.png` (the curve), `OUT.md`
(the table and the data set statistics) and `OUT.json`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import (
    fail,
    fraction,
    non_negative_int,
    out_file,
    positive_int,
    positive_ints,
    torch_device,
    use_threads,
)
from drake_grasp.datasets.grasp_data import load_grasp_datasets
from drake_grasp.evaluation.reports import plot_stability_curve
from drake_grasp.learning.stability_training import (
    StabilityConfig,
    checked_full_model,
    evaluate,
    fit_and_evaluate,
    prepare_grids,
    split_indices,
)

MIN_SAMPLES_SEEN = 100_000  # the curve's small subsets train for more epochs


def markdown(rows: list[dict], stats: dict, command: str) -> str:
    by_objects = "train_objects" in rows[0]
    title = "held-out AUROC vs. training objects" if by_objects else "accuracy vs. training-set size"
    columns = (["training objects"] if by_objects else []) + [
        "training grasps", "epochs", "accuracy", "precision", "recall", "AUROC", "novel accuracy",
        "novel AUROC"]
    lines = [f"# Grasp stability CNN: {title}", "", f"`{command}`", "",
             "| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        t, nv = r["test_metrics"], r.get("novel_metrics")
        rates = [f"{t[k]:.4f}" for k in ("accuracy", "precision", "recall", "auroc")]
        novel = [f"{nv['accuracy']:.4f}", f"{nv['auroc']:.4f}"] if nv else ["-", "-"]
        objects = [r["train_objects"]] if by_objects else []
        cells = [*objects, r["train_grasps"], r["epochs"], *rates, *novel]
        lines.append("| " + " | ".join(map(str, cells)) + " |")
    per_object = rows[-1].get("novel_per_object")
    if per_object:
        lines += ["", "Objects never trained on, with the last row's model (top 10 %: the success rate of "
                  "each object's best-scored tenth of trials):", "",
                  "| object | trials | positive rate | AUROC | top 10 % success |", "|---|---|---|---|---|"]
        lines += [f"| {name} | {m['n']} | {m['positive_rate']:.3f} | {m['auroc']:.4f} | "
                  f"{m['top10_success']:.3f} |" for name, m in per_object.items()]
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


def size_curve(data, novel, cache: dict, full, args: argparse.Namespace) -> list[dict]:
    """One row per training-set size of `args.sizes`, the full set last (read from `full`, the
    shipped weights and card, when given)."""
    rows = []
    sizes = [n for n in args.sizes if n < len(cache["fit"])]
    for limit in [*sizes, None]:
        t0 = time.perf_counter()
        if limit is None and full is not None:
            (model, card), n = full, len(cache["fit"])
            result = {"train_grasps": n, "epochs": card.get("epochs"),
                      "best_epoch": card.get("best_epoch"), "weights": str(args.full_model),
                      **evaluate(model, data, novel=novel, cache=cache, rows=slice(0, n),
                                 train_metrics=card.get("train_metrics"))}
        else:
            _, result = fit_and_evaluate(data, config=stability_config(args),
                                         test_fraction=args.test_fraction, novel=novel, limit=limit,
                                         min_samples_seen=args.min_samples, cache=cache, device=args.device)
        result["seconds"] = round(time.perf_counter() - t0, 1)
        rows.append(result)
        m = result["test_metrics"]
        print(f"{result['train_grasps']:>7} grasps: accuracy {m['accuracy']:.4f} AUROC {m['auroc']:.4f} "
              f"({result['seconds']:.0f} s)", flush=True)
    return rows


def stability_config(args: argparse.Namespace) -> StabilityConfig:
    """The training configuration the options ask for."""
    return StabilityConfig(epochs=args.epochs, seed=args.seed, patience=args.patience,
                           first_stride=args.first_stride)


def object_curve(data, novel, cache: dict, args: argparse.Namespace) -> list[dict]:
    """One row per object count K: trained on `args.trials` grasps of the first K training objects."""
    fit_objects = sorted({data.scene_object[int(s)] for s in data.trial_scene[cache["fit"]]})
    order = [fit_objects[i] for i in np.random.default_rng(args.seed).permutation(len(fit_objects))]
    counts = sorted({min(k, len(order)) for k in args.object_counts})
    first = set(order[:counts[0]])
    available = sum(data.scene_object[int(s)] in first for s in data.trial_scene[cache["fit"]])
    trials = args.trials or available
    if trials > available:
        raise ValueError(f"the first {counts[0]} training object(s) have {available} training grasps, fewer "
                         f"than --trials {trials}")
    rows = []
    for k in counts:
        t0 = time.perf_counter()
        _, result = fit_and_evaluate(data, config=stability_config(args), test_fraction=args.test_fraction,
                                     novel=novel, limit=trials, objects=order[:k],
                                     min_samples_seen=args.min_samples, cache=cache, device=args.device)
        result["seconds"] = round(time.perf_counter() - t0, 1)
        rows.append(result)
        held_out = result.get("novel_metrics", result["test_metrics"])
        print(f"{result['train_objects']:>5} objects, {result['train_grasps']} grasps: held-out AUROC "
              f"{held_out['auroc']:.4f} ({result['seconds']:.0f} s)", flush=True)
    return rows


def object_sets_curve(folders: list[Path], novel, validation,
                      args: argparse.Namespace) -> tuple[list[dict], dict]:
    """One row per folder (e.g. the same number of trials on 8, 50, 200 and 600 objects: `collect_grasps
    --object-subset`): trained on its first `args.trials` grasps, evaluated on the same `novel` sets.
    Returns the rows and the statistics of the largest set."""
    sets = [load_grasp_datasets([folder]) for folder in folders]
    fit_sizes = [len(split_indices(data, test_fraction=args.test_fraction, seed=args.seed,
                                   validation_scenes=validation is None)[0]) for data in sets]
    grasps = {n if args.trials is None else min(n, args.trials) for n in fit_sizes}
    if len(grasps) > 1:
        raise ValueError(f"the object sets have {min(fit_sizes)} to {max(fit_sizes)} training grasps: pass "
                         f"--trials {min(fit_sizes)} or fewer, so that every point trains on as many")
    rows, held_out_grids = [], {}
    shared = ("novel_packed",) + (("val_packed", "val_labels") if validation is not None else ())
    for folder, data in zip(folders, sets, strict=True):
        t0 = time.perf_counter()
        cache = prepare_grids(data, novel=novel, test_fraction=args.test_fraction, seed=args.seed,
                              cache=dict(held_out_grids), validation=validation)
        held_out_grids = {key: cache[key] for key in shared if key in cache}
        _, result = fit_and_evaluate(data, config=stability_config(args), test_fraction=args.test_fraction,
                                     novel=novel, limit=args.trials, min_samples_seen=args.min_samples,
                                     cache=cache, device=args.device)
        fit_scenes = data.trial_scene[cache["fit"][:result["train_grasps"]]]
        result = {"train_objects": len({data.scene_object[int(s)] for s in fit_scenes}), "data": str(folder),
                  **result, "seconds": round(time.perf_counter() - t0, 1)}
        rows.append(result)
        held_out = result.get("novel_metrics", result["test_metrics"])
        print(f"{folder}: {result['train_objects']} objects, {result['train_grasps']} grasps: held-out AUROC "
              f"{held_out['auroc']:.4f} ({result['seconds']:.0f} s)", flush=True)
    return rows, max((data.statistics() for data in sets), key=lambda stats: stats["trials"])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp stability_report", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, nargs="+", default=None,
                        help="collect_grasps folder(s) trained on (the primitives, generated objects)")
    parser.add_argument("--object-sets", type=Path, nargs="+", default=None,
                        help="instead of --data: one collect_grasps folder per point of the curve against "
                             "the object count (collect_grasps --object-subset K), --trials grasps each")
    parser.add_argument("--novel", type=Path, nargs="+", default=None,
                        help="collect_grasps folder(s) of objects never trained on")
    parser.add_argument("--validation", type=Path, nargs="+", default=None,
                        help="collect_grasps folder(s) of other objects to choose epochs on")
    parser.add_argument("--out", type=out_file, required=True,
                        help="output prefix: OUT.png, OUT.md, OUT.json")
    parser.add_argument("--sizes", type=positive_ints, default=[1000, 2000, 5000, 10000, 20000, 60000],
                        help="comma-separated training-set sizes (the full set is added)")
    parser.add_argument("--object-counts", type=positive_ints, default=None,
                        help="instead of --sizes: train on the scenes of the first K objects (a seeded "
                             "order, nested), --trials grasps each: held-out AUROC against K")
    parser.add_argument("--trials", type=positive_int, default=None,
                        help="with --object-counts or --object-sets: training grasps at every point "
                             "(default: what the smallest object count has; with --object-sets, each set's "
                             "all)")
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
    parser.add_argument("--device", default="cpu", help="torch device to train on ('cpu', 'cuda')")
    parser.add_argument("--seed", type=non_negative_int, default=0)
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    use_threads(args.threads)
    if (args.data is None) == (args.object_sets is None):
        return fail("give the training data as --data, or one folder per point as --object-sets")
    try:
        args.device = torch_device(args.device)
        novel = load_grasp_datasets(args.novel) if args.novel is not None else None
        validation = load_grasp_datasets(args.validation) if args.validation is not None else None
        if args.object_sets is not None:
            rows, stats = object_sets_curve(args.object_sets, novel, validation, args)
        else:
            data = load_grasp_datasets(args.data)
            cache = prepare_grids(data, novel=novel, test_fraction=args.test_fraction, seed=args.seed,
                                  cache={}, validation=validation)
            full = None if args.full_model is None else checked_full_model(
                args.full_model, data, cache=cache, first_stride=args.first_stride)
            rows = object_curve(data, novel, cache, args) if args.object_counts else size_curve(
                data, novel, cache, full, args)
            stats = data.statistics()
    except ValueError as e:
        return fail(e)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    command = "python -m drake_grasp stability_report " + " ".join(argv)
    for r in rows:
        r.pop("history", None)
    args.out.with_suffix(".json").write_text(json.dumps({"command": command, "statistics": stats,
                                                         "rows": rows}, indent=1))
    args.out.with_suffix(".md").write_text(markdown(rows, stats, command))
    plot_stability_curve(rows, args.out.with_suffix(".png"))
    print(f"report: {args.out.with_suffix('.md')}, {args.out.with_suffix('.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
