"""How GPD's classifier ranks GPG candidates: metrics of its weights on `collect_grasps` trials.

    python -m drake_grasp.evaluate_gpd --weights models/gpd_15.pt \
        --data data/grasps/gpg_one_camera data/grasps/gpg_two_cameras

Scores the trials whose candidates GPG made (all trials with --all-samplers) from each scene's
stored cloud, its normals facing the cameras that saw it (a `--second-camera` job records two),
and prints accuracy, precision, recall, AUROC, calibration (ECE), the success rate of the top
10 % by score and of each scene's best-scored candidate, over all folders and per folder (and
with --per-object / --by-thickness per object / thickness class), and each folder's trial
outcomes. Nothing is trained.
"""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import fail, own_trials, use_threads
from drake_grasp.apps.evaluation import (
    evaluation_parser,
    print_scores,
    score_metrics,
    thickness_classes,
    write_json,
)
from drake_grasp.task import OUTCOME_TEXT, TrialOutcome


def evaluate_gpd(weights: Path, folders: list[Path], *, all_samplers: bool = False,
                 per_object: bool = False, by_thickness: bool = False) -> dict:
    """`score_metrics` of the classifier's scores on the folders' GPG trials, with "weights"."""
    from drake_grasp.baselines.gpd import load_model
    from drake_grasp.baselines.gpd_training import ImageSource
    from drake_grasp.datasets.grasp_data import load_grasp_datasets

    model, _ = load_model(weights)
    data = own_trials(load_grasp_datasets(folders), "gpg", folders, all_samplers, "scoring")
    if len(data) == 0:
        raise ValueError(f"{' '.join(map(str, folders))} hold no trials")
    thickness = thickness_classes(data) if by_thickness else None  # (before the classifier runs)
    p = ImageSource(data, model.channels).predict(model, np.arange(len(data)))
    parts = data.part_names()  # (each trial's folder)
    outcomes = {name: dict(Counter(OUTCOME_TEXT[TrialOutcome(int(o))] for o in data.outcome[parts == name]))
                for name in dict.fromkeys(parts)}
    metrics = score_metrics(data, p, per_object=per_object, thickness=thickness)
    return {"weights": str(weights), **metrics, "outcomes": outcomes}


def main(argv: list[str] | None = None) -> int:
    parser = evaluation_parser("evaluate_gpd", __doc__, "models/gpd_15.pt",
                               "GPD's classifier (the policies')")
    parser.add_argument("--all-samplers", action="store_true",
                        help="score every trial, not only those of GPG's candidates")
    args = parser.parse_args(argv)
    use_threads(args.threads)
    try:
        result = evaluate_gpd(args.weights, args.data, all_samplers=args.all_samplers,
                              per_object=args.per_object, by_thickness=args.by_thickness)
    except ValueError as e:
        return fail(e)
    print_scores(str(args.weights), result)
    for name, counts in result["outcomes"].items():
        print(f"  {name} outcomes: " + ", ".join(f"{text} {n}" for text, n in sorted(counts.items())))
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
