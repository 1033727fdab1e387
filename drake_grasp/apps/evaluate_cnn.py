"""How a stability CNN ranks grasps it never trained on: metrics of weights on `collect_grasps` trials.

    python -m drake_grasp.evaluate_cnn --weights models/grasp_cnn_all.pt \
        --data data/grasps/heldout data/grasps/novel

Per folder and over all of them: accuracy, precision, recall, AUROC, calibration (ECE),
and the success rate of the top 10 % of candidates by p_s (what a policy would execute);
`--per-object` adds each object's, `--json` writes them all. With `--hold-weights`, the same
metrics of the score p_s * p_h too (p_h: `drake_grasp.learning.hold`). Nothing is trained.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import fail, positive_int, use_threads
from drake_grasp.datasets.grasp_data import load_grasp_datasets
from drake_grasp.learning.metrics import (
    best_per_scene_success,
    classification_metrics,
    per_group_metrics,
    top_fraction_success,
)


def score_metrics(data, p: np.ndarray, *, per_object: bool) -> dict:
    """{"all": metrics, "per_folder": {folder: metrics}, ["per_object": {name: metrics}]} of scores p,
    each with the success of each scene's best-scored trial (`best_per_scene`)."""
    overall = {**classification_metrics(data.label, p), "top10_success": top_fraction_success(data.label, p),
               "best_per_scene": best_per_scene_success(data.label, p, data.trial_scene)}
    per_folder = per_group_metrics(data.label, p, data.part_names(), data.trial_scene)
    result = {"all": overall, "per_folder": per_folder}
    if per_object:
        names = np.array([data.scene_object[int(s)] for s in data.trial_scene])
        result["per_object"] = per_group_metrics(data.label, p, names, data.trial_scene)
    return result


def evaluate_weights(weights: Path, folders: list[Path], *, per_object: bool = False,
                     hold_weights: Path | None = None) -> dict:
    """`score_metrics` of p_s, with "weights"; with `hold_weights`, "with_hold": those of p_s * p_h."""
    from drake_grasp.learning.cnn import load_model
    from drake_grasp.learning.stability_training import packed_voxels, predict_packed

    model, _ = load_model(weights)
    data = load_grasp_datasets(folders)
    p = predict_packed(model, packed_voxels(data, np.arange(len(data))))
    result = {"weights": str(weights), **score_metrics(data, p, per_object=per_object)}
    if hold_weights is not None:
        from drake_grasp.learning.hold import HoldPredictor, predict_hold, trial_lever_size

        hold = HoldPredictor.load(hold_weights)
        p_h = predict_hold(hold.model, trial_lever_size(data, np.arange(len(data))))
        result["with_hold"] = {"hold_weights": str(hold_weights),
                               **score_metrics(data, p * p_h, per_object=per_object)}
    return result


def evaluation_parser(program: str, description: str, weights: str,
                      weights_help: str) -> argparse.ArgumentParser:
    """The options every evaluation program shares: --weights, --data, --per-object, --threads, --json."""
    parser = argparse.ArgumentParser(prog=f"python -m drake_grasp.{program}", description=description,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--weights", type=Path, default=Path(weights),
                        help=f"{weights_help} (default: {weights})")
    parser.add_argument("--data", type=Path, nargs="+", required=True, help="collect_grasps folder(s)")
    parser.add_argument("--per-object", action="store_true", help="also each object's metrics")
    parser.add_argument("--threads", type=positive_int, default=None, help="torch threads (default: all)")
    parser.add_argument("--json", type=Path, default=None, help="write the metrics here")
    return parser


def write_json(path: Path | None, result: dict) -> None:
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=1))


def main(argv: list[str] | None = None) -> int:
    parser = evaluation_parser("evaluate_cnn", __doc__, "models/grasp_cnn_all.pt",
                               "the CNN's weights (the policies' default)")
    parser.add_argument("--hold-weights", type=Path, default=None,
                        help="a hold predictor: also the metrics of p_s * p_h")
    args = parser.parse_args(argv)
    use_threads(args.threads)
    try:
        result = evaluate_weights(args.weights, args.data, per_object=args.per_object,
                                  hold_weights=args.hold_weights)
    except ValueError as e:
        return fail(e)
    for title, scores in ((f"{args.weights}", result),
                          (f"p_s * p_h ({args.hold_weights})", result.get("with_hold"))):
        if scores is not None:
            print_scores(title, scores)
    write_json(args.json, result)
    return 0


def print_scores(title: str, scores: dict) -> None:
    """The overall metrics of `score_metrics` on one line, then one line a folder (and object)."""
    m = scores["all"]
    print(f"{title}: n={m['n']} positive {m['positive_rate']:.3f} accuracy {m['accuracy']:.4f} "
          f"precision {m['precision']:.4f} recall {m['recall']:.4f} AUROC {m['auroc']:.4f} "
          f"ECE {m['ece']:.4f} top 10 % success {m['top10_success']:.3f} "
          f"best of each scene {m['best_per_scene']:.3f}")
    for group in ("per_folder", "per_object"):
        for name, g in scores.get(group, {}).items():
            print(f"  {name}: n={g['n']} positive {g['positive_rate']:.3f} AUROC {g['auroc']:.4f} "
                  f"top 10 % success {g['top10_success']:.3f} best of each scene {g['best_per_scene']:.3f}")


if __name__ == "__main__":
    sys.exit(main())
