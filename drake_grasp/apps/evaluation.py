"""What the evaluation programs (`evaluate_cnn`, `evaluate_gpd`) share: their options, the metrics
of a classifier's scores on `collect_grasps` trials, and how they are printed and saved."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_grasp.apps.cli import positive_int
from drake_grasp.learning.metrics import (
    best_per_scene_success,
    classification_metrics,
    per_group_metrics,
    top_fraction_success,
)

if TYPE_CHECKING:
    from drake_grasp.datasets.grasp_data import GraspDataset


def evaluation_parser(program: str, description: str, weights: str,
                      weights_help: str) -> argparse.ArgumentParser:
    """The options every evaluation program shares: --weights, --data, --per-object, --threads, --json."""
    parser = argparse.ArgumentParser(prog=f"python -m drake_grasp.{program}", description=description,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--weights", type=Path, default=Path(weights),
                        help=f"{weights_help} (default: {weights})")
    parser.add_argument("--data", type=Path, nargs="+", required=True, help="collect_grasps folder(s)")
    parser.add_argument("--per-object", action="store_true", help="also each object's metrics")
    parser.add_argument("--by-thickness", action="store_true",
                        help="also the metrics per thickness class (each object's smallest extent, "
                             "from its `make_objects` manifest)")
    parser.add_argument("--threads", type=positive_int, default=None, help="torch threads (default: all)")
    parser.add_argument("--json", type=Path, default=None, help="write the metrics here")
    return parser


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
                  thickness: np.ndarray | None = None) -> dict:
    """{"all": metrics, "per_folder": {folder: metrics}, ["per_object": {name: metrics}],
    ["per_thickness": {class: metrics}] (given the trials' `thickness_classes`)} of scores p, each
    with the success of each scene's best-scored trial (`best_per_scene`)."""
    overall = {**classification_metrics(data.label, p), "top10_success": top_fraction_success(data.label, p),
               "best_per_scene": best_per_scene_success(data.label, p, data.trial_scene)}
    per_folder = per_group_metrics(data.label, p, data.part_names(), data.trial_scene)
    result = {"all": overall, "per_folder": per_folder}
    if per_object:
        result["per_object"] = per_group_metrics(data.label, p, data.trial_objects(), data.trial_scene)
    if thickness is not None:
        result["per_thickness"] = per_group_metrics(data.label, p, thickness, data.trial_scene)
    return result


def print_scores(title: str, scores: dict) -> None:
    """The overall metrics of `score_metrics` on one line, then one line a folder (and object)."""
    m = scores["all"]
    print(f"{title}: n={m['n']} positive {m['positive_rate']:.3f} accuracy {m['accuracy']:.4f} "
          f"precision {m['precision']:.4f} recall {m['recall']:.4f} AUROC {m['auroc']:.4f} "
          f"ECE {m['ece']:.4f} top 10 % success {m['top10_success']:.3f} "
          f"best of each scene {m['best_per_scene']:.3f}")
    for group in ("per_folder", "per_thickness", "per_object"):
        for name, g in scores.get(group, {}).items():
            print(f"  {name}: n={g['n']} positive {g['positive_rate']:.3f} AUROC {g['auroc']:.4f} "
                  f"top 10 % success {g['top10_success']:.3f} best of each scene {g['best_per_scene']:.3f}")


def write_json(path: Path | None, result: dict) -> None:
    """`result` as JSON at `path` (its folder made); nothing when `path` is None (no `--json`)."""
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=1))
