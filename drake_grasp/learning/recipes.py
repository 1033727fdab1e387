"""The training recipes of the package's own predictors: data in, a trained model and its model card out.

Each recipe is what `python -m drake_grasp train <model>` runs (the program reads the options, saves
with `model_cards.save_with_card` and prints): the Reachability Predictor on planning-success labels,
the stability CNN on grasp trials, the hold predictor on the trials that lifted their object. The
card records the data, the `command` that made the model, the seed and the metrics. (The baselines'
recipes are `policy.baselines.recipes`; VPG with pushing trains in `evaluation.vpg_push_training`.)
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import torch

from drake_grasp.datasets.shards import load_shards
from drake_grasp.learning.metrics import classification_metrics
from drake_grasp.learning.reachability_features import FEATURES, label_features
from drake_grasp.learning.rp import calibrate_stop_threshold, predict, train_ensemble
from drake_grasp.learning.weights import weights_digest
from drake_grasp.robot.hand import ANY_HAND, HandSpec, check_hand_record, hand_record
from drake_grasp.robot.paths import model_path
from drake_grasp.robot.specs import RobotSpec

Log = Callable[[str], None] | None


def reachability_recipe(robot: RobotSpec, data_dir: Path, *, command: str, features: str = "paper",
                        hidden: tuple[int, ...] = (16, 8), members: int = 1, epochs: int = 60, seed: int = 0,
                        limit: int | None = None, test_dir: Path | None = None,
                        log: Log = None) -> tuple[torch.nn.Module, dict]:
    """The RP of `robot` on `collect_reachability` labels in `data_dir` (the first `limit`); with `test_dir`
    (labels of another seed) the card's test metrics and the stop threshold calibrated on them."""
    data = load_shards(data_dir)
    manifest = json.loads((data_dir / "manifest.json").read_text())
    if manifest.get("robot") != robot.name:
        raise ValueError(f"{data_dir} holds labels of robot '{manifest.get('robot')}', not '{robot.name}'")
    check_hand_record(manifest.get("hand"), robot.hand, f"the reachability labels in {data_dir}")
    a, labels = label_features(data, features), data["label"]
    if limit:
        a, labels = a[:limit], labels[:limit]
    t0 = time.perf_counter()
    model, info = train_ensemble(a, labels, members=members, hidden=hidden, features=features,
                                 epochs=epochs, seed=seed, log=log)
    seconds = time.perf_counter() - t0
    shape = f"MLP {FEATURES[features]}-{'-'.join(map(str, hidden))}-1"
    if members > 1:
        shape = f"{members} x {shape}, mean logit"
    card = {
        "model": f"Reachability Predictor, {shape}, sigmoid, BCE, features '{features}'",
        "robot": robot.name,
        "hand": hand_record(robot.hand),
        "data": {"folder": str(data_dir), "labels": int(len(labels)), "positive_rate": float(labels.mean()),
                 "collection": manifest},
        "command": command,
        "seed": seed, "epochs": epochs,
        "best_epoch": [m["best_epoch"] for m in info["members"]] if members > 1
        else info["members"][0]["best_epoch"],
        "train_seconds": round(seconds, 1),
        # 10 % of the data, held out of fitting (the same rows for every member): what to compare
        "validation": {k: round(v, 5) for k, v in info["validation"].items()},
        "train_metrics": classification_metrics(labels, predict(model, a)),
    }
    if test_dir is not None:
        test = load_shards(test_dir)
        card["test_data"] = str(test_dir)
        p_test = predict(model, label_features(test, features))
        card["test_metrics"] = classification_metrics(test["label"], p_test)
        card["stop_threshold"] = calibrate_stop_threshold(p_test, test["label"])
    return model, card


def stability_recipe(data_dirs: list[Path], *, command: str, config, checkpoint: Path,
                     test_fraction: float = 0.1, novel_dirs: list[Path] | None = None,
                     validation_dirs: list[Path] | None = None, limit: int | None = None,
                     device: torch.device | None = None, init_weights: Path | None = None,
                     hand: HandSpec | None = None, hands: Sequence[HandSpec] = (),
                     log: Log = None) -> tuple[torch.nn.Module, dict]:
    """The stability CNN (`config`: a `StabilityConfig`) on `collect_grasps` trials, whole scenes held out
    as its test set; `novel_dirs` measured only; `validation_dirs` choose the epoch (default: 5 % of the
    training scenes); `init_weights` fine-tuned instead of a random start. Its state is kept in
    `checkpoint` as it trains (the same call resumes there). The model comes back on the CPU. The trials
    must share one hand (`hand`'s, when given); the card records it. With `config.hand_channel` the
    trials may be of many hands, each a shipped one or one of `hands`; the card records them all and
    `ANY_HAND` as its hand."""
    from drake_grasp.datasets.grasp_data import load_grasp_datasets
    from drake_grasp.learning.cnn import load_model
    from drake_grasp.learning.stability_training import (
        fit_and_evaluate,
        split_scene_ids,
        trial_hand_grids,
        trials_per_hand,
    )

    device = device or torch.device("cpu")
    one_hand = not config.hand_channel
    data = load_grasp_datasets(data_dirs, one_hand)
    novel = load_grasp_datasets(novel_dirs, one_hand) if novel_dirs is not None else None
    validation = load_grasp_datasets(validation_dirs, one_hand) if validation_dirs is not None else None
    made_with = data.manifest.get("hand")
    hand_grids = None
    if one_hand:
        for name, other in (("novel", novel), ("validation", validation)):
            if other is not None and other.manifest.get("hand") != made_with:
                raise ValueError(f"the {name} trials were made with another hand than the training trials")
        if hand is not None:
            check_hand_record(made_with, hand, "the training trials")
    else:
        hand_grids = trial_hand_grids([d for d in (data, novel, validation) if d is not None],
                                      [*hands, *([hand] if hand is not None else [])])
        made_with = ANY_HAND
    init = load_model(init_weights)[0] if init_weights is not None else None
    t0 = time.perf_counter()
    cache: dict = {}
    model, result = fit_and_evaluate(data, config=config, test_fraction=test_fraction, novel=novel,
                                     validation=validation, limit=limit, cache=cache, log=log,
                                     device=device, checkpoint=checkpoint, init=init, hand_grids=hand_grids)
    model.cpu()
    card = {
        "model": f"grasp stability 3D CNN (paper Sec. IV-C), {config.width} channels, first convolution "
                 f"stride {config.first_stride}"
                 + (" (VoxNet variant)" if config.first_stride == 2 else " (paper)")
                 + ", 32^3 occupancy of a 0.1 m cube in the grasp frame"
                 + (" and the voxels under the table plane as a second channel"
                    if config.table_channel else "")
                 + (" and the hand's grid (its palm and the space its pads close over) as the last channel"
                    if config.hand_channel else "")
                 + ", sigmoid, BCE, "
                   "random x/y flips (the hand's symmetry)",
        "hand": made_with,
        **({"hands": trials_per_hand(data)} if config.hand_channel else {}),
        "data": {"folders": [str(f) for f in data_dirs], "collection": data.manifest,
                 "statistics": data.statistics(),
                 "validation": [str(f) for f in validation_dirs] if validation_dirs else "training scenes"},
        "command": command,
        "seed": config.seed, "test_fraction": test_fraction, "device": str(device), "lr": config.lr,
        **({"init": {"weights": str(init_weights), "digest": weights_digest(model_path(init_weights))}}
           if init_weights is not None else {}),
        "train_seconds": round(time.perf_counter() - t0, 1), **result,
        "split": split_scene_ids(data, cache),
    }
    return model, card


def hold_recipe(data_dirs: list[Path], validation_dirs: list[Path], *, command: str):
    """The hold predictor (`learning.hold`) fitted on the trials of `data_dirs` that lifted their object,
    measured on those of `validation_dirs`: (model, card)."""
    from drake_grasp.datasets.grasp_data import load_grasp_datasets
    from drake_grasp.learning.hold import FEATURES as HOLD_FEATURES
    from drake_grasp.learning.hold import fit_hold, lifted_trials, predict_hold, slip_table, trial_lever_size

    sets = {"train": load_grasp_datasets(data_dirs), "validation": load_grasp_datasets(validation_dirs)}
    t0 = time.perf_counter()
    lever_size, held = {}, {}
    for name, data in sets.items():
        index = lifted_trials(data)
        lever_size[name] = trial_lever_size(data, index)
        held[name] = data.label[index].astype(bool)
    model = fit_hold(lever_size["train"], held["train"])
    if sets["validation"].manifest.get("hand") != sets["train"].manifest.get("hand"):
        raise ValueError("the validation trials were made with another hand than the training trials")
    card = {
        "hand": sets["train"].manifest.get("hand"),
        "model": "hold predictor: logistic regression of 'held' against 'object slipped' on "
                 + ", ".join(HOLD_FEATURES)
                 + " (lever: horizontal distance of the grasped segment's centroid from the closing axis; "
                   "size: the segment's diagonal; decimetres)",
        "coefficients": {"bias": round(float(model.bias), 4),
                         **{f: round(float(w), 4)
                            for f, w in zip(HOLD_FEATURES, model.weight[0], strict=True)}},
        "data": {"folders": [str(f) for f in data_dirs],
                 "validation": [str(f) for f in validation_dirs],
                 "trials": "those that lifted their object (success or object slipped)",
                 "read": {part["folder"]: part["loaded"]
                          for part in sets["train"].manifest.get("parts", [sets["train"].manifest])}},
        "command": command,
        "seed": "none (a convex fit: deterministic)",
        "train_seconds": round(time.perf_counter() - t0, 1),
    }
    for name in sets:
        p_h = predict_hold(model, lever_size[name])
        card[f"{name}_metrics"] = classification_metrics(held[name], p_h)
        card[f"{name}_slip_by_lever"] = slip_table(lever_size[name], held[name], p_h)
    return model, card
