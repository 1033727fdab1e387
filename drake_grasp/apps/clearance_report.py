"""How staged selection's approach-clearance check agrees with the physics trials.

For each blocking threshold (occupied voxels in the open hand's swept volume,
`drake_grasp.policy.clearance`), on every trial of each grasp data set: the share
of trials it blocks, of the approach collisions it catches, and of the successes
it would have thrown away. The threshold is chosen on the training objects' trials
(the first --data); the others are reported beside it. Writes OUT.md and OUT.json.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import fail, out_file, positive_ints, write_report_pair
from drake_grasp.datasets.grasp_data import GraspDataset, load_grasp_dataset
from drake_grasp.policy.clearance import BLOCKING_VOXELS, hand_sweep_mask
from drake_grasp.task import TrialOutcome

CHUNK = 5000  # trials voxelized at a time (32 KB of grid each)


def swept_voxels(data: GraspDataset) -> np.ndarray:
    """(T,) occupied voxels in the hand's swept volume of every trial."""
    mask = hand_sweep_mask().ravel()
    out = np.zeros(len(data), np.int64)
    for start in range(0, len(data), CHUNK):
        index = np.arange(start, min(start + CHUNK, len(data)))
        out[index] = data.voxels(index).reshape(len(index), -1)[:, mask].sum(axis=1)
    return out


def agreement(data: GraspDataset, thresholds: list[int]) -> list[dict]:
    hits = swept_voxels(data)
    success = data.label == 1
    collides = data.outcome == TrialOutcome.COLLIDES_ON_APPROACH
    rows = []
    for k in thresholds:
        blocked = hits >= k
        caught = float(blocked[collides].mean()) if collides.any() else None
        rows.append({"blocking_voxels": k, "trials": len(data), "blocked": float(blocked.mean()),
                     "approach_collisions_caught": caught,
                     "successes": int(success.sum()), "successes_blocked": int((blocked & success).sum())})
    return rows


def markdown(results: dict[str, list[dict]], command: str) -> str:
    lines = ["# Approach clearance against the physics trials", "", f"`{command}`", "",
             f"Staged selection blocks a candidate at {BLOCKING_VOXELS} voxels (chosen on the first data "
             "set).", "",
             "| data | blocking voxels | trials blocked | approach collisions caught | successes blocked |",
             "|---|---|---|---|---|"]
    for name, rows in results.items():
        for r in rows:
            caught = r["approach_collisions_caught"]
            caught = "-" if caught is None else f"{caught:.1%}"
            lines.append(f"| {name} | {r['blocking_voxels']} | {r['blocked']:.1%} | {caught} | "
                         f"{r['successes_blocked']} of {r['successes']} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.clearance_report", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, nargs="+", required=True,
                        help="collect_grasps folders; the first is the training objects'")
    parser.add_argument("--thresholds", type=positive_ints, default=[1, 2, 3, 4, 6],
                        help="blocking thresholds to report (occupied voxels)")
    parser.add_argument("--out", type=out_file, required=True, help="output prefix: OUT.md, OUT.json")
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    try:
        results = {str(folder): agreement(load_grasp_dataset(folder), args.thresholds)
                   for folder in args.data}
    except ValueError as e:
        return fail(e)
    command = "python -m drake_grasp.clearance_report " + " ".join(argv)
    write_report_pair(args.out, {"command": command, "results": results}, markdown(results, command))
    return 0


if __name__ == "__main__":
    sys.exit(main())
