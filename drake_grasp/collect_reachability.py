"""Planning-success labels for the Reachability Predictor, at scale.

Samples grasp poses over the camera's whole workspace (positions over the table
and up to 0.3 m above it, well beyond the arm's reach; approach angle uniform in
[0, 90] degrees from straight down; wrist roll uniform), runs the planner that
`simulate` uses on each (robot + hand + table, no objects), and records the
pose, the determinant a = (x, y, z, a_x, a_y, a_z) in the robot base frame, the
label (1 = a complete plan was found), the failure reason and the planning time.

Writes resumable shards to --out: rerunning the same command continues where
it stopped, and Ctrl-C loses only the shards in flight.
"""

from __future__ import annotations

import argparse
import functools
import math
import sys
from pathlib import Path

import numpy as np

from drake_grasp.cli import fail, non_negative_int, positive_int, quiet_drake
from drake_grasp.planner import PLANNER_VERSION, GraspPlanner, PlanFailure
from drake_grasp.reachability import reachability_determinant
from drake_grasp.robots import ROBOTS, get_robot
from drake_grasp.sampling import approach_rotations
from drake_grasp.scenario import load_scenario
from drake_grasp.shards import drop_short_shards, run_shards, write_manifest

FAILURE_CODES = {None: 0} | {f: i + 1 for i, f in enumerate(PlanFailure)}
HEIGHT_RANGE = (0.0, 0.3)  # grasp points from the table top up to 0.3 m [m]
_planners: dict[str, GraspPlanner] = {}


def sample_poses(n: int, lower, upper, rng: np.random.Generator) -> np.ndarray:
    """(n, 4, 4) grasp poses uniform over the box, gamma uniform in [0, 90] deg, roll uniform."""
    p = rng.uniform(lower, upper, (n, 3))
    gamma = rng.uniform(0, math.pi / 2, n)
    azimuth = rng.uniform(0, 2 * math.pi, n)
    approach = np.stack([np.sin(gamma) * np.cos(azimuth), np.sin(gamma) * np.sin(azimuth),
                         -np.cos(gamma)], axis=1)
    X = np.tile(np.eye(4), (n, 1, 1))
    X[:, :3, :3] = approach_rotations(approach, rng.uniform(0, 2 * math.pi, n))
    X[:, :3, 3] = p
    return X


def label_shard(k: int, *, robot: str, seed: int, samples: int, shard_size: int,
                lower: list[float], upper: list[float], table_height: float = 0.0) -> dict[str, np.ndarray]:
    """Shard k of a job: poses from rng(seed, k), each planned from home."""
    quiet_drake()
    key = f"{robot}@{table_height}"
    if key not in _planners:
        _planners[key] = GraspPlanner(get_robot(robot), seed=seed, table_height=table_height)
    planner = _planners[key]
    planner.rng = np.random.default_rng([seed, k, 1])
    n = min(shard_size, samples - k * shard_size)
    X_WG = sample_poses(n, lower, upper, np.random.default_rng([seed, k]))
    label = np.zeros(n, np.uint8)
    failure = np.zeros(n, np.uint8)
    seconds = np.zeros(n, np.float32)
    for i, X in enumerate(X_WG):
        result = planner.plan(X)
        label[i], failure[i], seconds[i] = result.success, FAILURE_CODES[result.failure], result.seconds
    return {"X_WG": X_WG[:, :3, :].astype(np.float32),
            "a": reachability_determinant(X_WG).astype(np.float32),
            "label": label, "failure": failure, "plan_seconds": seconds}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.collect_reachability", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", required=True, help=f"one of {sorted(ROBOTS)}")
    parser.add_argument("--samples", type=positive_int, required=True, help="labels to collect")
    parser.add_argument("--out", type=Path, required=True, help="folder of the shards")
    parser.add_argument("--seed", type=non_negative_int, default=0)
    parser.add_argument("--workers", type=positive_int, default=None, help="default: one per core")
    parser.add_argument("--shard-size", type=positive_int, default=500)
    parser.add_argument("--table-height", type=float, default=0.0,
                        help="table top in the robot base frame [m]; below 0 the arm stands on a "
                             "pedestal (a new setup; default 0)")
    parser.add_argument("--ray-address", default=None,
                        help="run on a Ray cluster ('auto', 'ray://host:10001') instead of local workers")
    args = parser.parse_args(argv)
    quiet_drake()
    try:
        get_robot(args.robot)
        if args.table_height > 0:
            raise ValueError("--table-height must be <= 0: the table top may not rise into the arm's base")
        box = load_scenario("standard")
        lower = [*box.workspace_min[:2], args.table_height + HEIGHT_RANGE[0]]
        upper = [*box.workspace_max[:2], args.table_height + HEIGHT_RANGE[1]]
        job = dict(robot=args.robot, seed=args.seed, samples=args.samples, shard_size=args.shard_size,
                   lower=lower, upper=upper, table_height=args.table_height)
        write_manifest(args.out, {"kind": "reachability", "planner_version": PLANNER_VERSION, **job,
                                  "failure_codes": {str(c): (f.value if f else "success")
                                                    for f, c in FAILURE_CODES.items()}})
        num_shards = math.ceil(args.samples / args.shard_size)
        drop_short_shards(args.out, lambda k: min(args.shard_size, args.samples - k * args.shard_size),
                          "label")
        run_shards(functools.partial(label_shard, **job), num_shards=num_shards, out_dir=args.out,
                   workers=args.workers or 0, ray_address=args.ray_address, unit="labels",
                   shard_size=args.shard_size,
                   progress_stats=lambda arrays: (len(arrays["label"]), int(arrays["label"].sum())))
    except (ValueError, RuntimeError) as e:
        return fail(e)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished shards are kept in {args.out}; rerun the command to continue",
              file=sys.stderr)
        return 130
    print(f"labels in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
