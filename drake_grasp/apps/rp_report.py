"""Reachability Predictor report: held-out metrics and accuracy versus training labels.

Trains the paper's MLP (6-16-8-1) on the first 1k, 2k, 5k, ... labels of --data,
and on all of them wider MLPs and the `roll` features (the determinant plus how
upright the jaw axis is) and `jaw` features (plus the whole jaw axis), evaluates each on the held-out
--test labels (collected with another seed), and writes a JSON report, a
markdown table and a PNG learning curve.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import fail, non_negative_int, out_file, positive_int, program_logging
from drake_grasp.datasets.shards import load_shards
from drake_grasp.learning.metrics import classification_metrics
from drake_grasp.learning.reachability_features import FEATURES, label_features
from drake_grasp.learning.rp import predict, train_reachability

SIZES = (1_000, 2_000, 5_000, 10_000, 20_000, 50_000, 100_000)
WIDE = (64, 64, 32)
WIDER = (256, 256, 128)


def label_noise(data: dict, manifest: dict, count: int, seed: int) -> dict:
    """How often the planner's label changes when only its IK restarts, or only the wrist roll, change."""
    from pydrake.math import RotationMatrix

    from drake_grasp.planning.planner import GraspPlanner, PlannerConfig
    from drake_grasp.robot.arms import get_robot
    from drake_grasp.robot.poses import homogeneous

    planner = GraspPlanner(get_robot(manifest.get("robot_source", manifest["robot"])), seed=seed + 1000,
                           config=PlannerConfig(table_height=manifest.get("table_height", 0.0)))
    X_WG = homogeneous(data["X_WG"][:count])
    labels = data["label"][:count].astype(bool)
    replanned = np.array([planner.plan(X).success for X in X_WG])
    rng = np.random.default_rng(seed)
    rolled = X_WG.copy()
    for X in rolled:
        X[:3, :3] = X[:3, :3] @ RotationMatrix.MakeZRotation(rng.uniform(0, 2 * np.pi)).matrix()
    rerolled = np.array([planner.plan(X).success for X in rolled])
    return {"poses": int(count), "changed_by_ik_restarts": float(np.mean(replanned != labels)),
            "changed_by_wrist_roll": float(np.mean(rerolled != labels))}


def _name(row: dict) -> str:
    inputs = FEATURES[row["features"]]
    return f"MLP {inputs}-{'-'.join(map(str, row['hidden']))}-1 ({row['features']})"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp rp_report", description=__doc__)
    parser.add_argument("--data", type=Path, required=True)
    parser.add_argument("--test", type=Path, required=True)
    parser.add_argument("--out", type=out_file, required=True, help="report stem: writes .json, .md and .png")
    parser.add_argument("--epochs", type=positive_int, default=60)
    parser.add_argument("--seed", type=non_negative_int, default=0)
    parser.add_argument("--noise", type=int, default=1000,
                        help="held-out poses to replan for the label-noise estimate (0: skip)")
    args = parser.parse_args(argv)
    program_logging()
    try:
        train, test = load_shards(args.data), load_shards(args.test)
        manifest = json.loads((args.test / "manifest.json").read_text())
        robot = manifest["robot"]
    except (ValueError, OSError, KeyError) as e:
        return fail(e)
    n_all = len(train["label"])
    runs = [(n, (16, 8), "paper") for n in SIZES if n < n_all] + [
        (n_all, (16, 8), "paper"), (n_all, WIDE, "paper"), (n_all, (16, 8), "roll"), (n_all, WIDE, "roll"),
        (n_all, WIDE, "jaw"), (n_all, WIDER, "jaw")]
    inputs = {f: (label_features(train, f), label_features(test, f)) for f in ("paper", "roll", "jaw")}
    rows = []
    for n, hidden, features in runs:
        x_train, x_test = inputs[features]
        t0 = time.perf_counter()
        model, info = train_reachability(x_train[:n], train["label"][:n], hidden=hidden, features=features,
                                         epochs=args.epochs, seed=args.seed)
        metrics = classification_metrics(test["label"], predict(model, x_test))
        rows.append({"labels": n, "hidden": list(hidden), "features": features,
                     "train_seconds": round(time.perf_counter() - t0, 1), "best_epoch": info["best_epoch"],
                     **metrics})
        print(f"{n:>7} labels, {_name(rows[-1])}: accuracy {metrics['accuracy']:.4f} "
              f"AUROC {metrics['auroc']:.4f} ECE {metrics['ece']:.4f}", flush=True)
    noise = label_noise(test, manifest, args.noise, args.seed) if args.noise else None
    if noise:
        print(f"label noise on {noise['poses']} held-out poses: {noise['changed_by_ik_restarts']:.1%} change "
              f"with other IK restarts, {noise['changed_by_wrist_roll']:.1%} with a redrawn wrist roll")
    report = {"robot": robot, "train_data": str(args.data), "test_data": str(args.test), "label_noise": noise,
              "command": "python -m drake_grasp rp_report "
                         + " ".join(sys.argv[1:] if argv is None else argv),
              "rows": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(report, indent=1))
    lines = [f"Reachability Predictor, {robot}: held-out test set of {rows[0]['n']} labels "
             f"(positive rate {rows[0]['positive_rate']:.1%})", "",
             "| training labels | MLP | accuracy | precision | recall | AUROC | ECE |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['labels']} | {_name(r)} | {r['accuracy']:.4f} | "
              f"{r['precision']:.4f} | {r['recall']:.4f} | {r['auroc']:.4f} | {r['ece']:.4f} |" for r in rows]
    if noise:
        lines += ["", f"Label noise: replanning {noise['poses']} held-out poses changes "
                      f"{noise['changed_by_ik_restarts']:.1%} of labels with other IK restarts and "
                      f"{noise['changed_by_wrist_roll']:.1%} with a redrawn wrist roll."]
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paper = [r for r in rows if r["hidden"] == [16, 8] and r["features"] == "paper"]
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    ax.semilogx([r["labels"] for r in paper], [100 * r["accuracy"] for r in paper], "o-",
                label=_name(paper[0]))
    for r, marker in zip(rows[len(paper):], "s^Dvp", strict=True):
        ax.semilogx([r["labels"]], [100 * r["accuracy"]], marker, label=_name(r))
    ax.set(xlabel="training labels", ylabel="held-out accuracy [%]", title=f"Reachability Predictor, {robot}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.savefig(args.out.with_suffix(".png"), dpi=110)
    print(f"report: {args.out.with_suffix('.json')} (.md, .png beside it)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
