"""Planning-success labels for the Reachability Predictor, at scale.

Samples grasp poses over the camera's whole workspace (positions over the table
and up to 0.3 m above it, well beyond the arm's reach; approach angle uniform in
[0, 90] degrees from straight down; wrist roll uniform), runs the planner that
`simulate` uses on each (robot + hand + table, no objects), and records the
pose, the determinant a = (x, y, z, a_x, a_y, a_z) in the robot base frame, the
label (1 = a complete plan was found), the failure reason and the planning time.

Writes resumable shards to --out: rerunning the same command continues where
it stopped, and Ctrl-C loses only the shards in flight. Shard k depends only on
the command's arguments and k (the planner's searches are bounded by counts, not
time), so the same command writes the same labels however busy the machine is.
"""

from __future__ import annotations

import argparse
import functools
import math
import sys

from drake_grasp.apps.cli import (
    add_hand_option,
    add_job_options,
    collect_shards,
    fail,
    positive_int,
    program_logging,
)
from drake_grasp.datasets.shards import drop_short_shards, write_manifest
from drake_grasp.evaluation.reachability_labels import HEIGHT_RANGE, failure_code_names, label_shard
from drake_grasp.perception.config import WorkspaceBox
from drake_grasp.planning.planner import PLANNER_VERSION
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.hand import hand_record
from drake_grasp.robot.specs import ROBOTS


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.collect_reachability", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", required=True, help=f"one of {sorted(ROBOTS)} or an arm YAML file")
    add_hand_option(parser)
    parser.add_argument("--samples", type=positive_int, required=True, help="labels to collect")
    parser.add_argument("--shard-size", type=positive_int, default=500)
    parser.add_argument("--table-height", type=float, default=0.0,
                        help="table top in the robot base frame [m]; below 0 the arm stands on a "
                             "pedestal (a new setup; default 0)")
    add_job_options(parser)
    args = parser.parse_args(argv)
    program_logging()
    try:
        robot = get_robot(args.robot, args.hand)
        if args.table_height > 0:
            raise ValueError("--table-height must be <= 0: the table top may not rise into the arm's base")
        box = WorkspaceBox()
        lower = [*box.lower[:2], args.table_height + HEIGHT_RANGE[0]]
        upper = [*box.upper[:2], args.table_height + HEIGHT_RANGE[1]]
        job = dict(robot=robot.source, hand=hand_record(robot.hand), seed=args.seed, samples=args.samples,
                   shard_size=args.shard_size, lower=lower, upper=upper, table_height=args.table_height)
        arm = {"robot": robot.name} | ({"robot_source": robot.source} if robot.source != robot.name else {})
        write_manifest(args.out, {"kind": "reachability", "hand": job["hand"],
                                  "planner_version": PLANNER_VERSION, **job, **arm,
                                  "failure_codes": failure_code_names()})
        num_shards = math.ceil(args.samples / args.shard_size)

        def rows_of(k: int) -> int:
            return min(args.shard_size, args.samples - k * args.shard_size)

        drop_short_shards(args.out, rows_of, "label")
    except ValueError as e:
        return fail(e)
    return collect_shards(functools.partial(label_shard, hand_file=args.hand), job, out_dir=args.out,
                          num_shards=num_shards, shard_size=args.shard_size, unit="labels", args=args,
                          rows_of=rows_of)


if __name__ == "__main__":
    sys.exit(main())
