"""Reachability maps (paper Fig. 5): the RP's p_r over the workspace beside the planner's labels.

For two approach directions (straight down, and tilted toward the robot by
--tilt degrees) the RP is evaluated on a fine grid over the camera's workspace
at one height, and the planner on a coarser grid of the same poses. Dark is
unreachable. Writes the PNG and, beside it, a JSON of how often the RP (p_r >= 0.5)
agrees with the planner on the coarse grid.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from drake_grasp.apps.cli import (
    add_hand_option,
    fail,
    non_negative_int,
    out_file,
    positive_int,
    program_logging,
)
from drake_grasp.evaluation.reachability_labels import grid_poses, planner_labels
from drake_grasp.perception.config import WorkspaceBox
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.specs import ROBOTS


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp reachability_map", description=__doc__)
    parser.add_argument("--robot", required=True, help=f"one of {sorted(ROBOTS)} or an arm YAML file")
    add_hand_option(parser)
    parser.add_argument("--out", type=out_file, required=True, help="PNG file")
    parser.add_argument("--weights", default=None, help="RP weights (default: the shipped ones)")
    parser.add_argument("--height", type=float, default=0.05, help="grasp height above the table [m]")
    parser.add_argument("--tilt", type=float, default=45.0, help="second map's tilt toward the robot [deg]")
    parser.add_argument("--planner-grid", type=positive_int, default=24, help="planner grid cells along y")
    parser.add_argument("--workers", type=positive_int, default=None)
    parser.add_argument("--seed", type=non_negative_int, default=0)
    args = parser.parse_args(argv)
    program_logging()
    try:
        robot = get_robot(args.robot, args.hand)
        from drake_grasp.learning.rp import ReachabilityPredictor

        rp = ReachabilityPredictor.load(args.weights or robot.source)
    except ValueError as e:
        return fail(e)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    box = WorkspaceBox()
    (x0, y0), (x1, y1) = box.lower[:2], box.upper[:2]
    ny = args.planner_grid
    nx = int(round(ny * (x1 - x0) / (y1 - y0)))
    fine = (np.linspace(x0, x1, 4 * nx), np.linspace(y0, y1, 4 * ny))
    coarse = (np.linspace(x0, x1, nx), np.linspace(y0, y1, ny))
    workers = args.workers or os.cpu_count() or 1
    fig, axes = plt.subplots(2, 2, figsize=(10, 9), constrained_layout=True)
    extent = (y0, y1, x0, x1)
    summary = []
    for row, tilt in enumerate((0.0, args.tilt)):
        p_r = rp(grid_poses(*fine, args.height, tilt, args.seed)).reshape(len(fine[1]), len(fine[0]))
        poses = grid_poses(*coarse, args.height, tilt, args.seed)
        labels = planner_labels(robot.source, poses, workers, args.seed).reshape(ny, nx)
        agreement = np.mean((rp(poses) >= 0.5).reshape(ny, nx) == labels)
        summary.append({"tilt_deg": tilt, "cells": int(labels.size), "reachable": float(labels.mean()),
                        "agreement": float(agreement)})
        name = "straight down" if tilt == 0 else f"tilted {tilt:.0f} deg toward the robot"
        for col, (image, title) in enumerate(((p_r, f"RP p_r, {name}"),
                                              (labels.astype(float), f"planner labels, {name}"))):
            ax = axes[row, col]
            # Rows of `image` are y, columns x: show x upward (away from the robot), +y to the left.
            im = ax.imshow(image.T, extent=extent, origin="lower", cmap="viridis", vmin=0, vmax=1,
                           aspect="equal")
            ax.plot(0, 0, "r^", markersize=10)
            ax.set(title=title, xlabel="y [m]", ylabel="x [m]", xlim=(y1, y0), ylim=(min(x0, -0.05), x1))
        axes[row, 1].text(y1 - 0.02, x1 - 0.05, f"RP agrees on {agreement:.1%}", color="w")
    fig.colorbar(im, ax=axes, shrink=0.6, label="reachable")
    fig.suptitle(f"{robot.name}: reachability at z = {args.height:.2f} m, wrist roll random per cell "
                 "(robot base: red triangle)")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    args.out.with_suffix(".json").write_text(json.dumps({"robot": robot.name, "height": args.height,
                                                         "rows": summary}, indent=1))
    print(f"map written to {args.out} (RP against the planner: {args.out.with_suffix('.json')})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
