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
names them and their digest); `--hand-channel [--hands FILE...]` trains one CNN for any parallel-jaw
hand on trials of many hands.

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
import functools
import sys
from pathlib import Path

from drake_grasp.apps.cli import (
    add_hand_option,
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
from drake_grasp.learning.model_cards import checkpoint_path, metrics_lines, save_with_card
from drake_grasp.learning.reachability_features import FEATURES
from drake_grasp.learning.recipes import hold_recipe, reachability_recipe, stability_recipe
from drake_grasp.learning.rp import save_model as save_rp
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.hand import get_hand
from drake_grasp.robot.specs import ROBOTS


def command_of(args: argparse.Namespace) -> str:
    return "python -m drake_grasp train " + " ".join(args.argv)


def print_metrics(card: dict, names: tuple[str, ...], out: Path) -> None:
    """One line per metrics set of a model card that has it, then where the files went."""
    for line in metrics_lines(card, names):
        print(line)
    print(f"weights: {out}  model card: {out.with_suffix('.json')}")


def _reachability(args: argparse.Namespace) -> int:
    robot = get_robot(args.robot, args.hand)
    model, card = reachability_recipe(
        robot, args.data, command=command_of(args), features=args.features,
        hidden=tuple(int(h) for h in args.hidden.split(",")), members=args.members, epochs=args.epochs,
        seed=args.seed, limit=args.limit, test_dir=args.test, log=print if args.verbose else None)
    save_with_card(functools.partial(save_rp, robot=robot.name), model, args.out, card)
    print_metrics(card, ("train_metrics", "test_metrics"), args.out)
    return 0


def _stability(args: argparse.Namespace) -> int:
    from drake_grasp.learning.cnn import save_model as save_cnn
    from drake_grasp.learning.stability_training import StabilityConfig

    use_threads(args.threads)
    config = StabilityConfig(epochs=args.epochs, lr=args.lr, seed=args.seed, patience=args.patience,
                             first_stride=args.first_stride, width=args.width,
                             table_channel=args.table_channel, hand_channel=args.hand_channel)
    model, card = stability_recipe(
        args.data, command=command_of(args), config=config, checkpoint=checkpoint_path(args.out),
        test_fraction=args.test_fraction, novel_dirs=args.novel, validation_dirs=args.validation,
        limit=args.limit, device=torch_device(args.device), init_weights=args.init,
        hand=get_hand(args.hand) if args.hand else None, hands=[get_hand(str(f)) for f in args.hands],
        log=print if args.verbose else None)
    save_with_card(save_cnn, model, args.out, card)
    print_metrics(card, ("train_metrics", "validation_metrics", "test_metrics", "novel_metrics"), args.out)
    for name, metrics in card.get("novel_per_set", {}).items():
        print(f"  {name}: AUROC {metrics['auroc']:.4f}, top 10 % success {metrics['top10_success']:.3f} "
              f"({metrics['n']} grasps)")
    return 0


def _baseline(args: argparse.Namespace) -> int:
    """`train gpd` and `train vpg`: a baseline's network on its own trials, with a model card."""
    from drake_grasp.datasets.grasp_data import load_grasp_datasets
    from drake_grasp.policy.baselines.recipes import baseline_recipe

    use_threads(args.threads)
    sampler = {"gpd": "gpg", "vpg": "topdown"}[args.model]
    data = own_trials(load_grasp_datasets(args.data), sampler, args.data, args.all_samplers, "training on")
    heldout = (own_trials(load_grasp_datasets(args.heldout), sampler, args.heldout, args.all_samplers,
                          "measuring on") if args.heldout else None)
    if heldout is not None and len(heldout) == 0:
        return fail(f"{' '.join(map(str, args.heldout))} hold no trials")
    model, card = baseline_recipe(
        args.model, data, args.data, command=command_of(args), checkpoint=checkpoint_path(args.out),
        heldout=heldout, heldout_dirs=args.heldout, channels=getattr(args, "channels", 15),
        epochs=args.epochs, seed=args.seed, test_fraction=args.test_fraction, patience=args.patience,
        log=print if args.verbose else None)
    if args.model == "gpd":
        from drake_grasp.policy.baselines.gpd import save_model as save
    else:
        from drake_grasp.policy.baselines.vpg import save_model as save
    save_with_card(save, model, args.out, card)
    print_metrics(card, ("train_metrics", "validation_metrics", "test_metrics", "heldout_metrics"), args.out)
    return 0


def _vpg_push(args: argparse.Namespace) -> int:
    """`train vpg-push`: VPG's push and grasp nets played and learned in rounds, with a model card."""
    from drake_grasp.evaluation.vpg_push_training import (
        PushTrainingConfig,
        plot_training,
        train_vpg_push,
        vpg_push_card,
    )
    from drake_grasp.policy.baselines.vpg_push import save_model as save

    config = PushTrainingConfig(scenario=args.scenario, objects=args.objects,
                                episodes_per_round=args.episodes_per_round, max_actions=args.max_actions,
                                steps_per_round=args.steps_per_round, seed=args.seed)
    model, history = train_vpg_push(config, data_dir=args.data, rounds=args.rounds, workers=args.workers,
                                    ray_address=args.ray_address)
    card = vpg_push_card(config, history, data_dir=args.data, command=command_of(args))
    save_with_card(save, model, args.out, card)
    plot_training(history, args.out.with_suffix(".png"))
    print(f"wrote {args.out}, its card and {args.out.with_suffix('.png')}: {len(history)} rounds, "
          f"{card['data']['actions']} actions")
    return 0


def _hold(args: argparse.Namespace) -> int:
    from drake_grasp.learning.hold import save_hold

    model, card = hold_recipe(args.data, args.validation, command=command_of(args))
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
    add_hand_option(rp)
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
    st.add_argument("--hand", default="", metavar="HAND",
                    help="refuse trials made with another hand than this one (a shipped hand or a hand YAML "
                         "file; default: the hand the trials were made with, which the card records)")
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
    st.add_argument("--table-channel", action="store_true",
                    help="a second input grid, the voxels under the table plane (the object cloud has the "
                         "table removed); with --init from a network without one, its weights start at zero")
    st.add_argument("--hand-channel", action="store_true",
                    help="one CNN for any parallel-jaw hand: a last input grid, the hand's palm and the "
                         "space its pads close over (from its hand file's sizes); the trials may be of many "
                         "hands (with --init from a network without one, its weights start at zero)")
    st.add_argument("--hands", type=Path, nargs="+", default=[], metavar="HAND_FILE",
                    help="with --hand-channel: the hand files of the trials' hands that are not shipped")
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
