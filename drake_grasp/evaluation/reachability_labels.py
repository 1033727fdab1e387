"""Planning-success labels for the Reachability Predictor: one shard of a `collect_reachability` job.

Poses are uniform over the camera's workspace box (up to 0.3 m above the table,
well beyond the arm's reach), approach angle uniform in [0, 90] degrees from
straight down, wrist roll uniform; each is planned from home by the planner that
`simulate` uses (robot + hand + table, no objects). Shard k is a pure function of
the job's arguments and k: its poses come from rng(seed, k) and its planner is
seeded with (seed, k).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from drake_grasp.datasets.shards import run_jobs
from drake_grasp.learning.reachability_features import reachability_determinant
from drake_grasp.planning.planner import GraspPlanner, PlanFailure, PlannerConfig
from drake_grasp.policy.sampling import grasp_poses, sample_workspace_poses
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.hand import check_hand_record
from drake_grasp.robot.log import program_logging

FAILURE_CODES = {None: 0} | {f: i + 1 for i, f in enumerate(PlanFailure)}
PLAN_CHUNK = 25  # poses per planner job of `planner_labels`
HEIGHT_RANGE = (0.0, 0.3)  # grasp points from the table top up to 0.3 m [m]


def failure_code_names() -> dict[str, str]:
    """The manifest's legend of the stored failure codes."""
    return {str(c): (f.value if f else "success") for f, c in FAILURE_CODES.items()}


def label_shard(k: int, *, robot: str, seed: int, samples: int, shard_size: int,
                lower: list[float], upper: list[float], table_height: float = 0.0, hand: dict | None = None,
                hand_file: str = "") -> dict[str, np.ndarray]:
    """Shard k of a job: poses from rng(seed, k), each planned from home by the arm with the job's `hand`
    (`hand_record`; None: the arm's own), loaded from `hand_file` ("": the arm's own)."""
    arm = get_robot(robot, hand_file)
    if hand is not None or hand_file:
        check_hand_record(hand, arm.hand, "this job's folder")
    planner = GraspPlanner(arm, seed=[seed, k, 1], config=PlannerConfig(table_height=table_height))
    n = min(shard_size, samples - k * shard_size)
    X_WG = sample_workspace_poses(n, lower, upper, np.random.default_rng([seed, k]))
    label = np.zeros(n, np.uint8)
    failure = np.zeros(n, np.uint8)
    seconds = np.zeros(n, np.float32)
    for i, X in enumerate(X_WG):
        result = planner.plan(X)
        label[i], failure[i], seconds[i] = result.success, FAILURE_CODES[result.failure], result.seconds
    return {"X_WG": X_WG[:, :3, :].astype(np.float32),
            "a": reachability_determinant(X_WG).astype(np.float32),
            "label": label, "failure": failure, "plan_seconds": seconds}


def grid_poses(xs: np.ndarray, ys: np.ndarray, z: float, tilt_deg: float, seed: int) -> np.ndarray:
    """(len(ys) * len(xs), 4, 4) grasps on a grid, approach tilted toward the robot base by tilt_deg."""
    X, Y = np.meshgrid(xs, ys)
    p = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, z)])
    toward_base = -p[:, :2] / np.maximum(np.linalg.norm(p[:, :2], axis=1, keepdims=True), 1e-9)
    t = np.radians(tilt_deg)
    approach = np.column_stack([np.sin(t) * toward_base, np.full(len(p), -np.cos(t))])
    return grasp_poses(p, approach, np.random.default_rng(seed).uniform(0, 2 * np.pi, len(p)))


def _plan_chunk(robot: str, seed: int, chunk: tuple[int, np.ndarray]) -> np.ndarray:
    program_logging()  # a worker process
    i, poses = chunk
    planner = GraspPlanner(get_robot(robot), seed=seed + i)
    return np.array([planner.plan(X).success for X in poses])


def planner_labels(robot: str, poses: np.ndarray, workers: int, seed: int) -> np.ndarray:
    """The planner's label of every pose, planned in chunks of a fixed size (chunk i seeded seed + i).

    The chunks do not depend on `workers`, so neither do the labels.
    """
    chunks = list(enumerate(np.array_split(poses, max(1, math.ceil(len(poses) / PLAN_CHUNK)))))
    labels = {i: part for (i, _), part in run_jobs(functools.partial(_plan_chunk, robot, seed), chunks,
                                                   workers=workers)}
    return np.concatenate([labels[i] for i in range(len(chunks))])
