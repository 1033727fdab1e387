"""Reachability Predictor report: held-out metrics and accuracy versus training labels.

Trains the paper's MLP (6-16-8-1) on the first 1k, 2k, 5k, ... labels of --data
and a wider variant on all of them, evaluates each on the held-out --test labels
(collected with another seed), and writes a JSON report, a markdown table and a
PNG learning curve.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from drake_grasp.cli import fail, positive_int
from drake_grasp.metrics import classification_metrics
from drake_grasp.shards import load_shards
from drake_grasp.train import predict, train_reachability

SIZES = (1_000, 2_000, 5_000, 10_000, 20_000, 50_000, 100_000)
WIDE = (64, 64, 32)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.rp_report", description=__doc__)
    parser.add_argument("--data", type=Path, required=True)
    parser.add_argument("--test", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True, help="report stem: writes .json, .md and .png")
    parser.add_argument("--epochs", type=positive_int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    try:
        train, test = load_shards(args.data), load_shards(args.test)
        robot = json.loads((args.data / "manifest.json").read_text())["robot"]
    except (ValueError, OSError, KeyError) as e:
        return fail(e)
    n_all = len(train["label"])
    sizes = [n for n in SIZES if n < n_all] + [n_all]
    rows = []
    for hidden in [(16, 8)] * len(sizes) + [WIDE]:
        n = sizes[len(rows)] if len(rows) < len(sizes) else n_all
        t0 = time.perf_counter()
        model, info = train_reachability(train["a"][:n], train["label"][:n], hidden=hidden,
                                         epochs=args.epochs, seed=args.seed)
        metrics = classification_metrics(test["label"], predict(model, test["a"]))
        rows.append({"labels": n, "hidden": list(hidden), "train_seconds": round(time.perf_counter() - t0, 1),
                     "best_epoch": info["best_epoch"], **metrics})
        print(f"{n:>7} labels, MLP 6-{'-'.join(map(str, hidden))}-1: accuracy {metrics['accuracy']:.4f} "
              f"AUROC {metrics['auroc']:.4f} ECE {metrics['ece']:.4f}", flush=True)
    report = {"robot": robot, "train_data": str(args.data), "test_data": str(args.test),
              "command": "python -m drake_grasp.rp_report "
                         + " ".join(sys.argv[1:] if argv is None else argv),
              "rows": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(report, indent=1))
    lines = [f"Reachability Predictor, {robot}: held-out test set of {rows[0]['n']} labels "
             f"(positive rate {rows[0]['positive_rate']:.1%})", "",
             "| training labels | MLP | accuracy | precision | recall | AUROC | ECE |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['labels']} | 6-{'-'.join(map(str, r['hidden']))}-1 | {r['accuracy']:.4f} | "
              f"{r['precision']:.4f} | {r['recall']:.4f} | {r['auroc']:.4f} | {r['ece']:.4f} |" for r in rows]
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paper = [r for r in rows if r["hidden"] == [16, 8]]
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    ax.semilogx([r["labels"] for r in paper], [100 * r["accuracy"] for r in paper], "o-",
                label="MLP 6-16-8-1")
    wide = rows[-1]
    ax.semilogx([wide["labels"]], [100 * wide["accuracy"]], "s",
                label=f"MLP 6-{'-'.join(map(str, WIDE))}-1")
    ax.set(xlabel="training labels", ylabel="held-out accuracy [%]", title=f"Reachability Predictor, {robot}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.savefig(args.out.with_suffix(".png"), dpi=110)
    print(f"report: {args.out.with_suffix('.json')} (.md, .png beside it)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
