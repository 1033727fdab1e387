"""Choose the "nothing graspable" stop on validation reports: each report's runs cut where the stop would
have ended them (exact: `evaluation.benchmark.cut_at_grasp_threshold`), at every threshold of a grid.

    python -m drake_grasp grasp_threshold --validation reports/benchmark/panda_benchmark_pile_cnn_rp.json \\
        reports/benchmark/panda_benchmark_packed_cnn_rp.json --out reports/benchmark/threshold

The choice: the highest grasp success pooled over the validation reports among the thresholds that cost
no validation report more than --max-declutter-loss of its declutter rate (the stop the reports ran
with, 0 for none, when none gains). Runs that ran with a stop cannot be replayed under it: the grid
starts at the highest stop any report ran with. The --tests reports are cut at the same thresholds and
shown beside, never chosen on. Writes OUT.md and OUT.json; `simulate --grasp-threshold` (or
`loop.grasp_threshold` in a configuration) runs the stop.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import fail, out_file, write_report_pair
from drake_grasp.evaluation.benchmark import choose_threshold, threshold_sweep

THRESHOLDS = tuple(np.round(np.arange(0.0, 0.95, 0.05), 2))


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp grasp_threshold", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--validation", type=Path, nargs="+", required=True,
                        help="simulate reports to choose on (policies that predict p_s)")
    parser.add_argument("--tests", type=Path, nargs="*", default=[],
                        help="reports shown beside, never chosen on")
    parser.add_argument("--max-declutter-loss", type=float, default=0.01,
                        help="the most declutter (completion) a validation report may lose (default 0.01)")
    parser.add_argument("--out", type=out_file, default=None, help="write OUT.md and OUT.json")
    return parser.parse_args(argv)


def read_report(path: Path) -> tuple[list[dict], float]:
    """A report's runs and the "nothing graspable" stop they ran with (0: none); ValueError when it is
    not a report or made no stability prediction."""
    try:
        report = json.loads(path.read_text())
        runs = report["runs"]
        stop = float(((report.get("evaluation") or {}).get("loop") or {}).get("grasp_threshold", 0.0))
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
        raise ValueError(f"{path} is not a simulate report ({e})") from None
    if not runs:
        raise ValueError(f"{path} holds no runs")
    if not any(a.get("p_s") is not None for r in runs for a in r["attempt_log"]):
        raise ValueError(f"{path}: its policy predicts no p_s, so no threshold would stop it")
    return runs, stop


def replayable(thresholds: tuple[float, ...], ran_with: float) -> tuple[float, ...]:
    """The thresholds a report run with the stop at `ran_with` can be cut at: that stop and those above."""
    return (ran_with, *(t for t in thresholds if t > ran_with + 1e-9)) if ran_with > 0 else thresholds


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        reports = {p: read_report(p) for p in [*args.validation, *args.tests]}
        runs = {p: report_runs for p, (report_runs, _) in reports.items()}
        ran_with = max(stop for _, stop in reports.values())
        thresholds = replayable(THRESHOLDS, ran_with)
        validation = {p.stem: threshold_sweep(runs[p], thresholds) for p in args.validation}
        tests = {p.stem: threshold_sweep(runs[p], thresholds) for p in args.tests}
    except ValueError as e:
        return fail(e)
    chosen = choose_threshold(list(validation.values()), max_declutter_loss=args.max_declutter_loss)
    names = [*(f"{n} (validation)" for n in validation), *(f"{n} (test)" for n in tests)]
    sweeps = [*validation.values(), *tests.values()]
    command = " ".join(argv if argv is not None else sys.argv[1:])
    ran = (f" The reports ran with the stop at {ran_with:g}: a lower one cannot be replayed on them."
           if ran_with > 0 else "")
    lines = [f"`python -m drake_grasp grasp_threshold {command}`", "",
             f"Chosen on the validation reports: grasp threshold **{chosen:g}** (0: off). Each cell: "
             f"grasp success % (successes/attempts), declutter %, rounds the stop ended.{ran}", "",
             "| threshold | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for k, t in enumerate(thresholds):
        cells = [f"{100 * s[k]['gsr'].rate:.1f} ({s[k]['gsr'].numerator}/{s[k]['gsr'].denominator}), "
                 f"{100 * s[k]['dr'].rate:.1f}, {s[k]['stopped']}" for s in sweeps]
        mark = "**" if t == chosen else ""
        lines.append(f"| {mark}{t:.2f}{mark} | " + " | ".join(cells) + " |")
    result = {"chosen": chosen, "ran_with": ran_with, "thresholds": list(map(float, thresholds)),
              "reports": {name: [{"threshold": r["threshold"], "gsr": r["gsr"].rate, "dr": r["dr"].rate,
                                  "stopped": r["stopped"]} for r in sweep]
                          for name, sweep in zip(names, sweeps, strict=True)}}
    write_report_pair(args.out, result, "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
