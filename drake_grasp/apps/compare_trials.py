"""Paired grasp trials: the same candidates tried two ways (`collect_grasps` jobs that differ in one option).

Two jobs of the same seed, objects and scenario sample the same scenes and candidates; one that
changes only how a candidate is executed (`--grasp-depth-offset`) tries each of them another way.
A trial of the variant is paired with the base's trial of the same scene and index when their
grasp orientations agree (a variant that changed the scenes or candidates pairs nothing there).
Printed and written (OUT.md, OUT.json): the pairs' success rates, their outcomes side by side,
the trials that changed label, and the success rate among the pairs where neither hand collided
on its approach.

    python -m drake_grasp.compare_trials data/grasps/depth_study/offset_0 \
        data/grasps/depth_study/offset_0.01 --out reports/depth_study/offset_0.01
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from drake_grasp.apps.cli import fail, out_file, write_report_pair
from drake_grasp.datasets.grasp_data import GraspDataset, load_grasp_dataset
from drake_grasp.task import OUTCOME_TEXT, TrialOutcome

ORIENTATION_TOLERANCE = 1e-4  # rotation matrix entries of one candidate in both jobs (stored as float32)


def pair_trials(base: GraspDataset, variant: GraspDataset) -> tuple[np.ndarray, np.ndarray]:
    """Indices (i, j) of the base's and the variant's trials that are one candidate tried two ways."""
    pairs_i, pairs_j = [], []
    for scene in np.intersect1d(base.trial_scene, variant.trial_scene):
        i, j = np.flatnonzero(base.trial_scene == scene), np.flatnonzero(variant.trial_scene == scene)
        if len(i) != len(j):  # (a scene that came out another way pairs nothing)
            continue
        if np.abs(base.X_WG[i, :3, :3] - variant.X_WG[j, :3, :3]).max() <= ORIENTATION_TOLERANCE:
            pairs_i.append(i)
            pairs_j.append(j)
    if not pairs_i:
        raise ValueError("the two jobs share no candidates: same --seed, --objects, --scenario and sampler?")
    return np.concatenate(pairs_i), np.concatenate(pairs_j)


def compare(base: GraspDataset, variant: GraspDataset) -> dict:
    i, j = pair_trials(base, variant)
    a, b = base.label[i].astype(bool), variant.label[j].astype(bool)
    collides = TrialOutcome.COLLIDES_ON_APPROACH
    clear = (base.outcome[i] != collides) & (variant.outcome[j] != collides)
    return {
        "pairs": len(i), "scenes": int(len(np.unique(base.trial_scene[i]))),
        "unpaired": {"base": len(base) - len(i), "variant": len(variant) - len(j)},
        "success": {"base": float(a.mean()), "variant": float(b.mean())},
        "outcomes": {OUTCOME_TEXT[o]: {"base": int((base.outcome[i] == o).sum()),
                                       "variant": int((variant.outcome[j] == o).sum())}
                     for o in TrialOutcome},
        "success_to_failure": int((a & ~b).sum()), "failure_to_success": int((~a & b).sum()),
        "neither_collides": {"pairs": int(clear.sum()),
                             "base": float(a[clear].mean()) if clear.any() else None,
                             "variant": float(b[clear].mean()) if clear.any() else None},
    }


def markdown(result: dict) -> str:
    lines = [f"`{result['command']}`", "",
             f"{result['pairs']} paired trials in {result['scenes']} scenes "
             f"(unpaired: base {result['unpaired']['base']}, variant {result['unpaired']['variant']}).", "",
             "| | base | variant |", "|---|---|---|",
             f"| success rate | {100 * result['success']['base']:.1f} % | "
             f"{100 * result['success']['variant']:.1f} % |"]
    lines += [f"| trials: {name} | {n['base']} | {n['variant']} |" for name, n in result["outcomes"].items()]
    clear = result["neither_collides"]
    if clear["pairs"]:
        lines.append(f"| success rate where neither collides ({clear['pairs']} pairs) | "
                     f"{100 * clear['base']:.1f} % | {100 * clear['variant']:.1f} % |")
    lines += ["", f"Success to failure: {result['success_to_failure']}; failure to success: "
                  f"{result['failure_to_success']}."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.compare_trials", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("base", type=Path, help="collect_grasps folder: the candidates as sampled")
    parser.add_argument("variant", type=Path,
                        help="collect_grasps folder: the same candidates tried another way")
    parser.add_argument("--out", type=out_file, default=None, help="output prefix: OUT.md, OUT.json")
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    try:
        result = {"command": "python -m drake_grasp.compare_trials " + " ".join(argv),
                  **compare(load_grasp_dataset(args.base), load_grasp_dataset(args.variant))}
    except ValueError as e:
        return fail(e)
    write_report_pair(args.out, result, markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
