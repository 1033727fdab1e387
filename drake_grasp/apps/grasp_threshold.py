"""Choose the "nothing graspable" stop (`simulate --grasp-threshold`) on closed-loop validation runs.

A run that ends "nothing graspable" stops when the best untried candidate scores under the
threshold: it gives up on objects the policy cannot grasp (fewer failures, higher grasp
success) and leaves them on the table (lower completion). Every validation report (`simulate
--report`, made without the stop) is cut at each threshold of the grid exactly as the stop
would have cut it (`drake_grasp.results.cut_at_grasp_threshold`: the same seeds give the same
runs up to the stop). The choice: the threshold with the highest pooled grasp success over the
validation reports among those that cost no validation report more than `--max-completion-loss`
of its completion (mean over runs); the lowest such threshold on a tie, 0 (off) when none
gains. `--tests` reports are cut at the same thresholds and shown beside, after the choice,
never used for it. Writes OUT.md and OUT.json.

    python -m drake_grasp.grasp_threshold --validation V1.json V2.json --out reports/nothing_graspable/choice
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import fail, fraction, out_file, write_report_pair
from drake_grasp.results import cut_at_grasp_threshold

GRID = tuple(round(0.05 * k, 2) for k in range(17))  # 0 (off), 0.05, ..., 0.8


def cut_report(runs: list[dict], threshold: float) -> dict:
    """One report's runs cut at `threshold`: mean rates over runs, pooled counts, runs stopped."""
    cuts = [cut_at_grasp_threshold(run, threshold) for run in runs]
    attempts, successes = sum(c["attempts"] for c in cuts), sum(c["successes"] for c in cuts)
    return {"threshold": threshold, "runs": len(cuts), "attempts": attempts, "successes": successes,
            "stopped": sum(c["stopped"] for c in cuts),
            "grasp_success_rate": float(np.mean([c["grasp_success_rate"] for c in cuts])),
            "completion_rate": float(np.mean([c["completion_rate"] for c in cuts]))}


def choose(validation: dict[str, list[dict]], max_completion_loss: float) -> float:
    """The threshold of the module's rule, from every report's rows (one per GRID threshold)."""
    best, best_success = 0.0, None
    for i, threshold in enumerate(GRID):
        if any(rows[0]["completion_rate"] - rows[i]["completion_rate"] > max_completion_loss + 1e-12
               for rows in validation.values()):  # (rows[0]: the report without the stop)
            continue
        attempts = sum(rows[i]["attempts"] for rows in validation.values())
        success = sum(rows[i]["successes"] for rows in validation.values()) / attempts if attempts else 0.0
        if best_success is None or success > best_success + 1e-12:
            best, best_success = threshold, success
    return best


def read_runs(path: Path) -> list[dict]:
    try:
        report = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"cannot read the report {path}: {e}") from None
    if not isinstance(report, dict) or not report.get("runs"):
        raise ValueError(f"{path} is not a simulate report with runs")
    if report.get("cell", {}).get("grasp_threshold"):
        raise ValueError(f"{path} was made with a grasp threshold already: cut only reports made without")
    return report["runs"]


def markdown(result: dict) -> str:
    """One row per threshold shown, one column per report: grasp success (pooled counts) / completion."""
    reports = [(role, name) for role in ("validation", "tests") for name in result[role]]
    head = ["threshold"] + [f"{Path(name).stem} ({role})" for role, name in reports]
    lines = [f"`{result['command']}`", "",
             f"Chosen on the validation reports: grasp threshold **{result['chosen']}** "
             f"(the highest pooled validation grasp success among the thresholds that cost no validation "
             f"report more than {100 * result['max_completion_loss']:.0f} points of completion; 0: off). "
             "Each cell: grasp success % (successes of attempts), completion %, runs the stop ended.", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for i, threshold in enumerate(result["grid"]):
        if threshold not in result["shown"]:
            continue
        rows = [result[role][name][i] for role, name in reports]
        cells = [f"{100 * r['grasp_success_rate']:.1f} ({r['successes']}/{r['attempts']}), "
                 f"{100 * r['completion_rate']:.1f}, {r['stopped']}" for r in rows]
        lines.append(f"| {threshold:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.grasp_threshold", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--validation", type=Path, nargs="+", required=True,
                        help="simulate reports of validation objects (the choice is made on these)")
    parser.add_argument("--tests", type=Path, nargs="*", default=[],
                        help="simulate reports shown beside, after the choice")
    parser.add_argument("--max-completion-loss", type=fraction, default=0.01,
                        help="completion a validation report may lose (default 0.01: one point)")
    parser.add_argument("--out", type=out_file, required=True, help="output prefix: OUT.md, OUT.json")
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    try:
        runs = {role: {str(p): read_runs(p) for p in paths}
                for role, paths in (("validation", args.validation), ("tests", args.tests))}
    except ValueError as e:
        return fail(e)
    rows = {role: {name: [cut_report(r, t) for t in GRID] for name, r in reports.items()}
            for role, reports in runs.items()}
    chosen = choose(rows["validation"], args.max_completion_loss)
    result = {"command": "python -m drake_grasp.grasp_threshold " + " ".join(argv), "chosen": chosen,
              "max_completion_loss": args.max_completion_loss, "grid": list(GRID),
              "shown": sorted({0.0, chosen, *GRID[6:13:2]}), **rows}
    write_report_pair(args.out, result, markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
