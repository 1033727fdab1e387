"""Training commands for the learned predictors.

`python -m drake_grasp train reachability --robot R --data DIR --out FILE [--test DIR]`
trains the Reachability Predictor (the paper's MLP 6 -> 16 -> 8 -> 1, sigmoid,
binary cross-entropy) on planning-success labels from `collect_reachability`,
stores the input normalization in the weights file, and writes a model card
(`FILE` with a `.json` suffix) with the data, command, seed and metrics.

`python -m drake_grasp train stability --data DIR --out FILE [--novel DIR]`
trains the grasp stability 3D CNN on `collect_grasps` trials, holding out whole
scenes (never seen in training) as the test set, and writes its model card too;
`--init WEIGHTS [--lr RATE]` fine-tunes those weights instead of starting at random (the card
names them and their digest).

`python -m drake_grasp train gpd --data DIR --out FILE [--channels 15|3]` trains GPD's
LeNet on grasp images of `collect_grasps --sampler gpg` trials (the GPD baseline,
`drake_grasp.policy.baselines.gpd`), with the same scene split and a model card;
`python -m drake_grasp train vpg --data DIR --out FILE` VPG's grasp net on
`collect_grasps --sampler topdown` trials (`drake_grasp.policy.baselines.vpg`).

`python -m drake_grasp train vpg-push --data DIR --rounds N --out FILE` trains VPG whole, its push and
grasp nets together by VPG's self-supervised rewards, playing the challenging scene in the simulator
(`drake_grasp.evaluation.vpg_push_training`); each episode and each round's nets stay in DIR, so
the same command with more rounds continues it.

`python -m drake_grasp train hold --data DIR... --validation DIR... --out FILE` fits the hold
predictor (`drake_grasp.learning.hold`: does a lifted object stay in the hand or pivot out of the
lift, from the lever of its weight about the jaws) on the trials that lifted their object.

The CNN, GPD and VPG trainings keep their state in FILE's `.checkpoint.pt` sibling every five minutes
and after each epoch: the same command, run again after an interruption, resumes
there (and the file goes once the weights are saved).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import torch

from drake_grasp.apps.cli import (
    fail,
    fraction,
    non_negative_int,
    out_file,
    own_trials,
    positive_float,
    positive_int,
    torch_device,
    use_threads,
)
from drake_grasp.datasets.shards import load_shards
from drake_grasp.learning.cnn import save_model as save_cnn
from drake_grasp.learning.metrics import classification_metrics
from drake_grasp.learning.reachability_features import FEATURES, label_features
from drake_grasp.learning.rp import calibrate_stop_threshold, predict, save_model, train_ensemble
from drake_grasp.learning.weights import weights_digest
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.paths import model_path
from drake_grasp.robot.specs import ROBOTS


def print_metrics(card: dict, names: tuple[str, ...], out: Path) -> None:
    """One line per metrics set of a model card that has it, then where the files went."""
    for name in names:
        if name in card:
            m = card[name]
            print(f"{name.split('_')[0]:>10}: n={m['n']} accuracy {m['accuracy']:.4f} "
                  f"precision {m['precision']:.4f} recall {m['recall']:.4f} "
                  f"AUROC {m['auroc']:.4f} ECE {m['ece']:.4f}")
    print(f"weights: {out}  model card: {out.with_suffix('.json')}")


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


def _reachability(args: argparse.Namespace) -> int:
    robot = get_robot(args.robot)
    data = load_shards(args.data)
    manifest = json.loads((args.data / "manifest.json").read_text())
    if manifest.get("robot") != robot.name:
        raise ValueError(f"{args.data} holds labels of robot '{manifest.get('robot')}', not '{robot.name}'")
    a, labels = label_features(data, args.features), data["label"]
    if args.limit:
        a, labels = a[:args.limit], labels[:args.limit]
    hidden = tuple(int(h) for h in args.hidden.split(","))
    t0 = time.perf_counter()
    model, info = train_ensemble(a, labels, members=args.members, hidden=hidden, features=args.features,
                                 epochs=args.epochs, seed=args.seed, log=print if args.verbose else None)
    seconds = time.perf_counter() - t0
    shape = f"MLP {FEATURES[args.features]}-{'-'.join(map(str, hidden))}-1"
    if args.members > 1:
        shape = f"{args.members} x {shape}, mean logit"
    card = {
        "model": f"Reachability Predictor, {shape}, sigmoid, BCE, features '{args.features}'",
        "robot": robot.name,
        "data": {"folder": str(args.data), "labels": int(len(labels)), "positive_rate": float(labels.mean()),
                 "collection": manifest},
        "command": "python -m drake_grasp train " + " ".join(args.argv),
        "seed": args.seed, "epochs": args.epochs,
        "best_epoch": [m["best_epoch"] for m in info["members"]] if args.members > 1
        else info["members"][0]["best_epoch"],
        "train_seconds": round(seconds, 1),
        # 10 % of --data, held out of fitting (the same rows for every member): what to compare
        "validation": {k: round(v, 5) for k, v in info["validation"].items()},
        "train_metrics": classification_metrics(labels, predict(model, a)),
    }
    if args.test is not None:
        test = load_shards(args.test)
        card["test_data"] = str(args.test)
        p_test = predict(model, label_features(test, args.features))
        card["test_metrics"] = classification_metrics(test["label"], p_test)
        card["stop_threshold"] = calibrate_stop_threshold(p_test, test["label"])
    save_with_card(functools.partial(save_model, robot=robot.name), model, args.out, card)
    print_metrics(card, ("train_metrics", "test_metrics"), args.out)
    return 0


def _stability(args: argparse.Namespace) -> int:
    from drake_grasp.datasets.grasp_data import load_grasp_datasets
    from drake_grasp.learning.stability_training import StabilityConfig, fit_and_evaluate, split_scene_ids

    use_threads(args.threads)
    device = torch_device(args.device)
    data = load_grasp_datasets(args.data)
    novel = load_grasp_datasets(args.novel) if args.novel is not None else None
    validation = load_grasp_datasets(args.validation) if args.validation is not None else None
    log = print if args.verbose else None
    init = None
    if args.init is not None:
        from drake_grasp.learning.cnn import load_model

        init, _ = load_model(args.init)
    t0 = time.perf_counter()
    cache: dict = {}
    config = StabilityConfig(epochs=args.epochs, lr=args.lr, seed=args.seed, patience=args.patience,
                             first_stride=args.first_stride, width=args.width)
    model, result = fit_and_evaluate(data, config=config, test_fraction=args.test_fraction, novel=novel,
                                     validation=validation, limit=args.limit, cache=cache, log=log,
                                     device=device, checkpoint=checkpoint_path(args.out), init=init)
    model.cpu()
    card = {
        "model": f"grasp stability 3D CNN (paper Sec. IV-C), {args.width} channels, first convolution "
                 f"stride {args.first_stride}"
                 + (" (VoxNet variant)" if args.first_stride == 2 else " (paper)")
                 + ", 32^3 occupancy of a 0.1 m cube in the grasp frame, sigmoid, BCE, "
                   "random x/y flips (the hand's symmetry)",
        "data": {"folders": [str(f) for f in args.data], "collection": data.manifest,
                 "statistics": data.statistics(),
                 "validation": [str(f) for f in args.validation] if args.validation else "training scenes"},
        "command": "python -m drake_grasp train " + " ".join(args.argv),
        "seed": args.seed, "test_fraction": args.test_fraction, "device": str(device), "lr": args.lr,
        **({"init": {"weights": str(args.init), "digest": weights_digest(model_path(args.init))}}
           if args.init is not None else {}),
        "train_seconds": round(time.perf_counter() - t0, 1), **result,
        "split": split_scene_ids(data, cache),
    }
    save_with_card(save_cnn, model, args.out, card)
    print_metrics(card, ("train_metrics", "validation_metrics", "test_metrics", "novel_metrics"), args.out)
    for name, metrics in card.get("novel_per_set", {}).items():
        print(f"  {name}: AUROC {metrics['auroc']:.4f}, top 10 % success {metrics['top10_success']:.3f} "
              f"({metrics['n']} grasps)")
    return 0


def _baseline(args: argparse.Namespace) -> int:
    """`train gpd` and `train vpg`: a baseline's network on its own trials, with a model card."""
    from drake_grasp.datasets.grasp_data import load_grasp_datasets

    use_threads(args.threads)
    sampler = {"gpd": "gpg", "vpg": "topdown"}[args.model]
    data = own_trials(load_grasp_datasets(args.data), sampler, args.data, args.all_samplers, "training on")
    heldout = (own_trials(load_grasp_datasets(args.heldout), sampler, args.heldout, args.all_samplers,
                          "measuring on") if args.heldout else None)
    if heldout is not None and len(heldout) == 0:
        return fail(f"{' '.join(map(str, args.heldout))} hold no trials")
    log = print if args.verbose else None
    t0 = time.perf_counter()
    common = dict(epochs=args.epochs, seed=args.seed, test_fraction=args.test_fraction,
                  patience=args.patience, log=log, checkpoint=checkpoint_path(args.out))
    if args.model == "gpd":
        from drake_grasp.policy.baselines.gpd import save_model as save
        from drake_grasp.policy.baselines.gpd_training import gpd_metrics, train_gpd

        model, result = train_gpd(data, channels=args.channels, **common)
        if heldout is not None:
            result["heldout_metrics"] = gpd_metrics(model, heldout, args.channels)
        description = (f"GPD grasp classifier (ten Pas et al. 2017): LeNet on {args.channels}-channel "
                       "60 x 60 grasp images of the closing region, sigmoid, BCE")
    else:
        from drake_grasp.policy.baselines.vpg import save_model as save
        from drake_grasp.policy.baselines.vpg_training import train_vpg, vpg_metrics

        model, result = train_vpg(data, **common)
        if heldout is not None:
            result["heldout_metrics"] = vpg_metrics(model, heldout)
        description = ("VPG grasp net (Zeng et al. 2018, grasping only): a small fully convolutional net on "
                       "2 mm heightmaps turned to 16 jaw angles, BCE at the executed grasp")
    card = {
        "model": description + ", trained from scratch on this package's trials",
        "data": {"folders": [str(f) for f in args.data], "collection": data.manifest,
                 "statistics": data.statistics()},
        **({"heldout": {"folders": [str(f) for f in args.heldout], "objects": heldout.manifest.get("objects"),
                        "trials": len(heldout), "positive_rate": float(heldout.label.mean())}}
           if heldout is not None else {}),
        "command": "python -m drake_grasp train " + " ".join(args.argv),
        "seed": args.seed, "test_fraction": args.test_fraction,
        "train_seconds": round(time.perf_counter() - t0, 1), **result,
    }
    save_with_card(save, model, args.out, card)
    print_metrics(card, ("train_metrics", "validation_metrics", "test_metrics", "heldout_metrics"), args.out)
    return 0


def _vpg_push(args: argparse.Namespace) -> int:
    """`train vpg-push`: VPG's push and grasp nets played and learned in rounds, with a model card."""
    from drake_grasp.evaluation.vpg_push_training import (
        PushTrainingConfig,
        plot_training,
        train_vpg_push,
    )
    from drake_grasp.policy.baselines.vpg_push import save_model as save

    config = PushTrainingConfig(scenario=args.scenario, objects=args.objects,
                                episodes_per_round=args.episodes_per_round, max_actions=args.max_actions,
                                steps_per_round=args.steps_per_round, seed=args.seed)
    model, history = train_vpg_push(config, data_dir=args.data, rounds=args.rounds, workers=args.workers,
                                    ray_address=args.ray_address)
    totals = {key: sum(row[key] for row in history)
              for key in ("actions", "grasps", "grasp_successes", "pushes", "pushes_changed")}
    last = history[-max(len(history) // 4, 1):]
    card = {
        "model": "VPG (Zeng et al. 2018) with pushing: push and grasp nets (small fully convolutional nets "
                 "on 2 mm heightmaps, 16 push directions over a full turn, 16 jaw angles over half a turn), "
                 "Q = 2 sigmoid, Huber loss at the executed action, VPG's rewards and discount 0.5",
        "data": {"folder": str(args.data), "settings": dataclasses.asdict(config), **totals},
        "command": "python -m drake_grasp train " + " ".join(args.argv),
        "seed": args.seed, "rounds": len(history),
        "training_metrics": {  # the last quarter of the rounds: what the nets do now
            "rounds": len(last),
            "grasp_success": sum(r["grasp_successes"] for r in last) / max(sum(r["grasps"] for r in last), 1),
            "push_share": sum(r["pushes"] for r in last) / max(sum(r["actions"] for r in last), 1),
            "pushes_changed": sum(r["pushes_changed"] for r in last) / max(sum(r["pushes"] for r in last), 1),
        },
        "train_seconds": round(sum(r["play_seconds"] + r["learn_seconds"] for r in history), 1),  # wall
        "history": history,
    }
    save_with_card(save, model, args.out, card)
    plot_training(history, args.out.with_suffix(".png"))
    print(f"wrote {args.out}, its card and {args.out.with_suffix('.png')}: {len(history)} rounds, "
          f"{totals['actions']} actions")
    return 0


def _hold(args: argparse.Namespace) -> int:
    from drake_grasp.datasets.grasp_data import load_grasp_datasets
    from drake_grasp.learning.hold import (
        FEATURES,
        fit_hold,
        lifted_trials,
        predict_hold,
        save_hold,
        slip_table,
        trial_lever_size,
    )

    sets = {"train": load_grasp_datasets(args.data), "validation": load_grasp_datasets(args.validation)}
    t0 = time.perf_counter()
    lever_size, held = {}, {}
    for name, data in sets.items():
        index = lifted_trials(data)
        lever_size[name] = trial_lever_size(data, index)
        held[name] = data.label[index].astype(bool)
    model = fit_hold(lever_size["train"], held["train"])
    card = {
        "model": "hold predictor: logistic regression of 'held' against 'object slipped' on "
                 + ", ".join(FEATURES) + " (lever: horizontal distance of the grasped segment's centroid "
                   "from the closing axis; size: the segment's diagonal; decimetres)",
        "coefficients": {"bias": round(float(model.bias), 4),
                         **{f: round(float(w), 4) for f, w in zip(FEATURES, model.weight[0], strict=True)}},
        "data": {"folders": [str(f) for f in args.data], "validation": [str(f) for f in args.validation],
                 "trials": "those that lifted their object (success or object slipped)",
                 "read": {part["folder"]: part["loaded"]
                          for part in sets["train"].manifest.get("parts", [sets["train"].manifest])}},
        "command": "python -m drake_grasp train " + " ".join(args.argv),
        "seed": "none (a convex fit: deterministic)",
        "train_seconds": round(time.perf_counter() - t0, 1),
    }
    for name in sets:
        p_h = predict_hold(model, lever_size[name])
        card[f"{name}_metrics"] = classification_metrics(held[name], p_h)
        card[f"{name}_slip_by_lever"] = slip_table(lever_size[name], held[name], p_h)
    save_with_card(save_hold, model, args.out, card)
    print_metrics(card, ("train_metrics", "validation_metrics"), args.out)
    for row in card["validation_slip_by_lever"]:
        print(f"  lever {row['lever_cm']:>6} cm: {row['n']:6d} lifted, slipped {row['slip_rate']:.3f}, "
              f"predicted {row['predicted']:.3f}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp train", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="model", required=True)
    rp = sub.add_parser("reachability", help="the Reachability Predictor of one robot")
    rp.add_argument("--robot", required=True, help=f"one of {sorted(ROBOTS)} or an arm YAML file")
    rp.add_argument("--data", type=Path, required=True, help="collect_reachability output folder")
    rp.add_argument("--out", type=out_file, required=True, help="weights file (.pt); the card goes beside it")
    rp.add_argument("--test", type=Path, default=None, help="held-out labels (another seed)")
    rp.add_argument("--hidden", default="16,8", help="hidden layer sizes (default: the paper's 16,8)")
    rp.add_argument("--features", choices=sorted(FEATURES), default="paper",
                    help="paper: a = (x, y, z, a_x, a_y, a_z); roll: a and how upright the jaw axis is; "
                         "jaw: a and the whole jaw axis (jaw-swap invariant)")
    rp.add_argument("--epochs", type=positive_int, default=60)
    rp.add_argument("--limit", type=positive_int, default=None, help="use only the first N labels")
    rp.add_argument("--members", type=positive_int, default=1,
                    help="MLPs trained from seeds SEED, SEED+1, ... whose mean logit is the prediction")
    rp.add_argument("--seed", type=non_negative_int, default=0)
    rp.add_argument("-v", "--verbose", action="store_true")
    st = sub.add_parser("stability", help="the grasp stability 3D CNN")
    st.add_argument("--data", type=Path, nargs="+", required=True,
                    help="collect_grasps output folder(s), trained on together")
    st.add_argument("--out", type=out_file, required=True, help="weights file (.pt); the card goes beside it")
    st.add_argument("--novel", type=Path, nargs="+", default=None,
                    help="collect_grasps folder(s) of objects never trained on: metrics only, together "
                         "and per folder")
    st.add_argument("--validation", type=Path, nargs="+", default=None,
                    help="collect_grasps folder(s) of other objects to choose the epoch on (default: 5 %% "
                         "of the training scenes); never the --novel test sets")
    st.add_argument("--test-fraction", type=fraction, default=0.1, help="scenes held out for the test set")
    st.add_argument("--epochs", type=positive_int, default=10)
    st.add_argument("--patience", type=positive_int, default=None,
                    help="stop after this many epochs without a lower validation loss")
    st.add_argument("--limit", type=positive_int, default=None, help="train on only N grasps")
    st.add_argument("--first-stride", type=int, choices=(1, 2), default=2,
                    help="2: the VoxNet variant (default, 10x faster on a CPU); 1: the paper's")
    st.add_argument("--threads", type=positive_int, default=None, help="torch threads (default: all cores)")
    st.add_argument("--width", type=positive_int, default=32,
                    help="channels of both convolutions (32, the paper's; wider if held-out objects gain)")
    st.add_argument("--device", default="cpu",
                    help="torch device to train on ('cpu', 'cuda'); the weights are saved for the CPU")
    st.add_argument("--seed", type=non_negative_int, default=0)
    st.add_argument("--init", type=Path, default=None, metavar="WEIGHTS",
                    help="start from these weights instead of at random (fine-tuning: their stride and "
                         "width must match)")
    st.add_argument("--lr", type=positive_float, default=1e-3, help="Adam's learning rate (default 1e-3)")
    st.add_argument("-v", "--verbose", action="store_true")
    for name, helps in (("gpd", ("GPD's grasp classifier (the GPD baseline)", "--sampler gpg")),
                        ("vpg", ("VPG's grasp net (the VPG baseline)", "--sampler topdown"))):
        baseline = sub.add_parser(name, help=helps[0])
        baseline.add_argument("--data", type=Path, nargs="+", required=True,
                              help=f"collect_grasps {helps[1]} (or mixed) output folder(s), trained on "
                                   "together")
        baseline.add_argument("--out", type=out_file, required=True,
                              help="weights file (.pt); the card goes beside it")
        if name == "gpd":
            baseline.add_argument("--channels", type=int, choices=(15, 3), default=15,
                                  help="grasp image channels")
        baseline.add_argument("--heldout", type=Path, nargs="+", default=None,
                              help="collect_grasps folder(s) of objects never trained on: the card's "
                                   "held-out metrics (measured once, after training; never for selection)")
        baseline.add_argument("--all-samplers", action="store_true",
                              help=f"train on every trial, not only those {helps[1].split()[-1]} made")
        baseline.add_argument("--test-fraction", type=fraction, default=0.1,
                              help="scenes held out for the test set")
        baseline.add_argument("--epochs", type=positive_int, default=10)
        baseline.add_argument("--patience", type=positive_int, default=None,
                              help="stop after this many epochs without a lower validation loss")
        baseline.add_argument("--threads", type=positive_int, default=None,
                              help="torch threads (default: all cores)")
        baseline.add_argument("--seed", type=non_negative_int, default=0)
        baseline.add_argument("-v", "--verbose", action="store_true")
    push = sub.add_parser("vpg-push", help="VPG with pushing: push and grasp nets, self-supervised in the "
                          "simulator")
    push.add_argument("--data", type=Path, required=True, help="the training's folder (episodes and nets)")
    push.add_argument("--out", type=out_file, required=True,
                      help="weights file (.pt); the card and the training's curves go beside it")
    push.add_argument("--rounds", type=positive_int, required=True, help="rounds to reach (continues DIR)")
    push.add_argument("--scenario", default="challenging",
                      help="the scene played (a shipped one or a YAML file)")
    push.add_argument("--objects", default="primitives", help="its objects (a set or a folder)")
    push.add_argument("--episodes-per-round", type=positive_int, default=2)
    push.add_argument("--max-actions", type=positive_int, default=20, help="actions an episode")
    push.add_argument("--steps-per-round", type=positive_int, default=40, help="gradient steps after a round")
    push.add_argument("--workers", type=int, default=0,
                      help="worker processes (default: one per core; a round plays its episodes at once)")
    push.add_argument("--ray-address", default=None, help="play the episodes on a Ray cluster")
    push.add_argument("--seed", type=non_negative_int, default=0)
    hold = sub.add_parser("hold", help="the hold predictor (pivoting out of the lift)")
    hold.add_argument("--data", type=Path, nargs="+", required=True, help="collect_grasps output folder(s)")
    hold.add_argument("--validation", type=Path, nargs="+", required=True,
                      help="collect_grasps folder(s) of other objects, for the card's metrics")
    hold.add_argument("--out", type=out_file, required=True,
                      help="weights file (.pt); the card goes beside it")
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    args.argv = argv
    programs = {"reachability": _reachability, "stability": _stability, "gpd": _baseline, "vpg": _baseline,
                "vpg-push": _vpg_push, "hold": _hold}
    try:
        return programs[args.model](args)
    except ValueError as e:
        return fail(e)


if __name__ == "__main__":
    sys.exit(main())
