"""How a stability CNN ranks grasps it never trained on: metrics of weights on `collect_grasps` trials.

    python -m drake_grasp.evaluate_cnn --weights models/grasp_cnn_all.pt \
        --data data/grasps/heldout data/grasps/novel

Per folder and over all of them: accuracy, precision, recall, AUROC, calibration (ECE),
and the success rate of the top 10 % of candidates by p_s (what a policy would execute);
`--per-object` adds each object's, `--by-thickness` each thickness class's (generated
objects: the smallest extent in their `make_objects` manifest), `--json` writes them all;
`--finger-symmetry` scores as `simulate --finger-symmetry` does; `--clear-approach` keeps only the
trials whose hand reached the grasp without touching anything (the closed loop's back-off from the
table and its planner keep most colliding candidates away, so these are the ones its ranking decides
among).
With `--hold-weights`, the same metrics of the score p_s * p_h too (p_h:
`drake_grasp.learning.hold`). Nothing is trained.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import fail, use_threads
from drake_grasp.apps.evaluation import (
    evaluation_parser,
    print_scores,
    score_metrics,
    thickness_classes,
    write_json,
)
from drake_grasp.datasets.grasp_data import load_grasp_datasets


def evaluate_weights(weights: Path, folders: list[Path], *, per_object: bool = False,
                     by_thickness: bool = False, hold_weights: Path | None = None,
                     finger_symmetry: bool = False, clear_approach: bool = False) -> dict:
    """`score_metrics` of p_s, with "weights"; with `hold_weights`, "with_hold": those of p_s * p_h.
    `finger_symmetry`: p_s as the mean over each grasp's two finger assignments (`predict_grids`);
    `clear_approach`: only the trials that did not collide on the approach."""
    from drake_grasp.learning.cnn import load_model
    from drake_grasp.learning.stability_training import packed_voxels, predict_packed

    model, _ = load_model(weights)
    data = load_grasp_datasets(folders)
    if clear_approach:
        from drake_grasp.task import TrialOutcome

        data = data.subset(np.flatnonzero(data.outcome != TrialOutcome.COLLIDES_ON_APPROACH))
    # (an object set without extents fails here, before the CNN runs)
    groups = {"per_object": per_object, "thickness": thickness_classes(data) if by_thickness else None}
    p = predict_packed(model, packed_voxels(data, np.arange(len(data))), finger_symmetry=finger_symmetry)
    result = {"weights": str(weights), "finger_symmetry": finger_symmetry, "clear_approach": clear_approach,
              **score_metrics(data, p, **groups)}
    if hold_weights is not None:
        from drake_grasp.learning.hold import HoldPredictor, predict_hold, trial_lever_size

        hold = HoldPredictor.load(hold_weights)
        p_h = predict_hold(hold.model, trial_lever_size(data, np.arange(len(data)), z_scale=hold.z_scale))
        result["with_hold"] = {"hold_weights": str(hold_weights),
                               **score_metrics(data, p * p_h, **groups)}
    return result


def main(argv: list[str] | None = None) -> int:
    parser = evaluation_parser("evaluate_cnn", __doc__, "models/grasp_cnn_all.pt",
                               "the CNN's weights (the policies' default)")
    parser.add_argument("--hold-weights", type=Path, default=None,
                        help="a hold predictor: also the metrics of p_s * p_h")
    parser.add_argument("--finger-symmetry", action="store_true",
                        help="p_s as the mean over each grasp's two finger assignments (as `simulate "
                             "--finger-symmetry` scores)")
    parser.add_argument("--clear-approach", action="store_true",
                        help="only the trials whose approach touched nothing (those the closed loop's "
                             "ranking decides among)")
    args = parser.parse_args(argv)
    use_threads(args.threads)
    try:
        result = evaluate_weights(args.weights, args.data, per_object=args.per_object,
                                  by_thickness=args.by_thickness, hold_weights=args.hold_weights,
                                  finger_symmetry=args.finger_symmetry, clear_approach=args.clear_approach)
    except ValueError as e:
        return fail(e)
    for title, scores in ((f"{args.weights}", result),
                          (f"p_s * p_h ({args.hold_weights})", result.get("with_hold"))):
        if scores is not None:
            print_scores(title, scores)
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
