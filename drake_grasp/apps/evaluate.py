"""How a trained grasp classifier ranks trials it never trained on: metrics of its weights on
`collect_grasps` folders. Nothing is trained.

    python -m drake_grasp evaluate cnn --weights models/grasp_cnn_all.pt --data data/grasps/novel
    python -m drake_grasp evaluate gpd --weights models/gpd_15.pt --data data/grasps/gpg_one_camera

Per folder and over all of them: accuracy, precision, recall, AUROC, calibration (ECE), the
success rate of the top 10 % of candidates by score (what a policy would execute) and of each
scene's best-scored candidate; `--per-object` adds each object's, `--by-thickness` each thickness
class's (generated objects: the smallest extent in their `make_objects` manifest), `--json` writes
them all.

- `cnn`: the stability CNN's p_s; with `--hold-weights`, also p_s * p_h (`learning.hold`);
  `--clear-approach` keeps only the trials whose hand reached the grasp without touching anything
  (the closed loop's back-off from the table and its planner keep most colliding candidates away).
- `gpd`: GPD's classifier on the trials whose candidates GPG made (all with `--all-samplers`), from
  each scene's stored cloud with its normals facing the cameras that saw it; also each folder's
  trial outcomes.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_grasp.apps.cli import fail, own_trials, positive_int, use_threads
from drake_grasp.datasets.grasp_data import load_grasp_datasets
from drake_grasp.learning.metrics import (
    best_per_scene_success,
    classification_metrics,
    per_group_metrics,
    top_fraction_success,
)
from drake_grasp.robot.task import OUTCOME_TEXT, SAMPLERS, TrialOutcome

if TYPE_CHECKING:
    from drake_grasp.datasets.grasp_data import GraspDataset

THICKNESS_EDGES_CM = (1.5, 2.5, 4.0)  # class edges of an object's smallest extent


def thickness_classes(data: GraspDataset) -> np.ndarray:
    """(T,) the thickness class of each trial's object ("0.0-1.5 cm", ..., "4.0 cm +"): its smallest
    extent, read from the `make_objects` manifest of the object set each folder's trials were made on.
    ValueError names an object set without one (the built-in sets have none)."""
    extents: dict[str, float] = {}
    for part in data.manifest.get("parts", [data.manifest]):
        objects = Path(str(part.get("objects", "")))
        try:
            listed = json.loads((objects / "manifest.json").read_text())["objects"]
            extents.update({o["name"]: 100 * min(o["extents"]) for o in listed})
        except (OSError, ValueError, KeyError, TypeError):
            raise ValueError(f"object set '{objects}' has no make_objects manifest with extents: "
                             "thickness classes need generated objects") from None
    edges = (0.0, *THICKNESS_EDGES_CM)
    names = [f"{lo:.1f}-{hi:.1f} cm" for lo, hi in zip(edges, edges[1:], strict=False)]
    names.append(f"{edges[-1]:.1f} cm +")
    unlisted = sorted(set(data.scene_object.values()) - set(extents))
    if unlisted:
        raise ValueError(f"objects {', '.join(unlisted[:3])} are in no make_objects manifest "
                         "of these folders")
    thickness = np.array([extents[name] for name in data.trial_objects()])
    return np.array(names)[np.searchsorted(THICKNESS_EDGES_CM, thickness, side="right")]


def score_metrics(data: GraspDataset, p: np.ndarray, *, per_object: bool,
                  thickness: np.ndarray | None = None, per_sampler: bool = False) -> dict:
    """{"all": metrics, "per_folder": {folder: metrics}, ["per_object": {name: metrics}],
    ["per_thickness": {class: metrics}] (given the trials' `thickness_classes`), ["per_sampler":
    {sampler: metrics}]} of scores p, each with the success of each scene's best-scored trial
    (`best_per_scene`; per sampler: the best of that sampler's candidates)."""
    overall = {**classification_metrics(data.label, p), "top10_success": top_fraction_success(data.label, p),
               "best_per_scene": best_per_scene_success(data.label, p, data.trial_scene)}
    per_folder = per_group_metrics(data.label, p, data.part_names(), data.trial_scene)
    result = {"all": overall, "per_folder": per_folder}
    if per_object:
        result["per_object"] = per_group_metrics(data.label, p, data.trial_objects(), data.trial_scene)
    if thickness is not None:
        result["per_thickness"] = per_group_metrics(data.label, p, thickness, data.trial_scene)
    if per_sampler:
        samplers = np.array(SAMPLERS)[data.trial_sampler]
        result["per_sampler"] = per_group_metrics(data.label, p, samplers, data.trial_scene)
    return result


def print_scores(title: str, scores: dict) -> None:
    """The overall metrics of `score_metrics` on one line, then one line a folder (and object)."""
    m = scores["all"]
    print(f"{title}: n={m['n']} positive {m['positive_rate']:.3f} accuracy {m['accuracy']:.4f} "
          f"precision {m['precision']:.4f} recall {m['recall']:.4f} AUROC {m['auroc']:.4f} "
          f"ECE {m['ece']:.4f} top 10 % success {m['top10_success']:.3f} "
          f"best of each scene {m['best_per_scene']:.3f}")
    for group in ("per_folder", "per_sampler", "per_thickness", "per_object"):
        for name, g in scores.get(group, {}).items():
            print(f"  {name}: n={g['n']} positive {g['positive_rate']:.3f} AUROC {g['auroc']:.4f} "
                  f"top 10 % success {g['top10_success']:.3f} best of each scene {g['best_per_scene']:.3f}")


def write_json(path: Path | None, result: dict) -> None:
    """`result` as JSON at `path` (its folder made); nothing when `path` is None (no `--json`)."""
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=1))


# -- the classifiers --------------------------------------------------------------------------------
def evaluate_weights(weights: Path, folders: list[Path], *, per_object: bool = False,
                     by_thickness: bool = False, hold_weights: Path | None = None,
                     clear_approach: bool = False, per_sampler: bool = False,
                     hands: list[Path] | None = None, as_hand: str = "") -> dict:
    """`score_metrics` of p_s, with "weights"; with `hold_weights`, "with_hold": those of p_s * p_h.
    `clear_approach`: only the trials that did not collide on the approach. A CNN with a hand channel is
    fed each trial's hand (a shipped one or one of the hand files `hands`), and its trials may be of
    many hands; with `as_hand` (a shipped hand or a hand file), that hand's for every trial instead (what
    the network makes of the trials when told another hand made them)."""
    from drake_grasp.learning.cnn import load_model
    from drake_grasp.learning.stability_training import packed_voxels, predict_packed, trial_hand_grids
    from drake_grasp.learning.voxels import hand_grid
    from drake_grasp.robot.hand import get_hand

    model, _ = load_model(weights)
    data = load_grasp_datasets(folders, one_hand=not model.hand_channel)
    hand_grids = (trial_hand_grids([data], [get_hand(str(f)) for f in hands or []])
                  if model.hand_channel else None)
    if as_hand:
        if not model.hand_channel:
            raise ValueError(f"{weights} has no hand channel: --as-hand tells nothing")
        told = hand_grid(get_hand(as_hand))
        hand_grids = {print_: told for print_ in hand_grids}
    if clear_approach:
        data = data.subset(np.flatnonzero(data.outcome != TrialOutcome.COLLIDES_ON_APPROACH))
    # (an object set without extents fails here, before the CNN runs)
    groups = {"per_object": per_object, "thickness": thickness_classes(data) if by_thickness else None,
              "per_sampler": per_sampler}
    p = predict_packed(model, packed_voxels(data, np.arange(len(data)), table_channel=model.table_channel,
                                            hand_grids=hand_grids))
    result = {"weights": str(weights), "clear_approach": clear_approach,
              **({"as_hand": as_hand} if as_hand else {}), **score_metrics(data, p, **groups)}
    if hold_weights is not None:
        from drake_grasp.learning.hold import HoldPredictor, predict_hold, trial_lever_size

        hold = HoldPredictor.load(hold_weights)
        p_h = predict_hold(hold.model, trial_lever_size(data, np.arange(len(data))))
        result["with_hold"] = {"hold_weights": str(hold_weights),
                               **score_metrics(data, p * p_h, **groups)}
    return result


def evaluate_gpd(weights: Path, folders: list[Path], *, all_samplers: bool = False,
                 per_object: bool = False, by_thickness: bool = False) -> dict:
    """`score_metrics` of the classifier's scores on the folders' GPG trials, with "weights"."""
    from drake_grasp.policy.baselines.gpd import load_model
    from drake_grasp.policy.baselines.gpd_training import ImageSource
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


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp evaluate", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="classifier", required=True)
    for name, weights, what in (("cnn", "models/grasp_cnn_all.pt", "the stability CNN (the policies')"),
                                ("gpd", "models/gpd_15.pt", "GPD's classifier (the policies')")):
        one = sub.add_parser(name, help=what)
        one.add_argument("--weights", type=Path, default=Path(weights), help=f"{what} (default: {weights})")
        one.add_argument("--data", type=Path, nargs="+", required=True, help="collect_grasps folder(s)")
        one.add_argument("--per-object", action="store_true", help="also each object's metrics")
        one.add_argument("--by-thickness", action="store_true",
                         help="also the metrics per thickness class (each object's smallest extent, "
                              "from its `make_objects` manifest)")
        one.add_argument("--threads", type=positive_int, default=None, help="torch threads (default: all)")
        one.add_argument("--json", type=Path, default=None, help="write the metrics here")
        if name == "cnn":
            one.add_argument("--hold-weights", type=Path, default=None,
                             help="a hold predictor: also the metrics of p_s * p_h")
            one.add_argument("--per-sampler", action="store_true",
                             help="also the metrics of each sampler's candidates (a mixed job holds two)")
            one.add_argument("--clear-approach", action="store_true",
                             help="only the trials whose approach touched nothing (those the closed "
                                  "loop's ranking decides among)")
            one.add_argument("--hands", type=Path, nargs="+", default=[], metavar="HAND_FILE",
                             help="for a CNN with a hand channel: the hand files of the trials' hands that "
                                  "are not shipped")
            one.add_argument("--as-hand", default="", metavar="HAND",
                             help="for a CNN with a hand channel: tell it this hand (shipped or a file) made "
                                  "every trial (does the channel matter?)")
        else:
            one.add_argument("--all-samplers", action="store_true",
                             help="score every trial, not only those of GPG's candidates")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    use_threads(args.threads)
    try:
        if args.classifier == "cnn":
            result = evaluate_weights(args.weights, args.data, per_object=args.per_object,
                                      by_thickness=args.by_thickness, hold_weights=args.hold_weights,
                                      clear_approach=args.clear_approach, per_sampler=args.per_sampler,
                                      hands=args.hands, as_hand=args.as_hand)
        else:
            result = evaluate_gpd(args.weights, args.data, all_samplers=args.all_samplers,
                                  per_object=args.per_object, by_thickness=args.by_thickness)
    except ValueError as e:
        return fail(e)
    print_scores(str(args.weights), result)
    if "with_hold" in result:
        print_scores(f"p_s * p_h ({args.hold_weights})", result["with_hold"])
    for name, counts in result.get("outcomes", {}).items():
        print(f"  {name} outcomes: " + ", ".join(f"{text} {n}" for text, n in sorted(counts.items())))
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
