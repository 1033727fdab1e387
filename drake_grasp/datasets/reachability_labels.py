"""Planning-success labels for the Reachability Predictor: one shard of a `collect_reachability` job.

Poses are uniform over the camera's workspace box (up to 0.3 m above the table,
well beyond the arm's reach), approach angle uniform in [0, 90] degrees from
straight down, wrist roll uniform; each is planned from home by the planner that
`simulate` uses (robot + hand + table, no objects). Shard k is a pure function of
the job's arguments and k: its poses come from rng(seed, k) and its planner is
seeded with (seed, k).
"""

from __future__ import annotations

import numpy as np

from drake_grasp.learning.reachability_features import reachability_determinant
from drake_grasp.planning.planner import GraspPlanner, PlanFailure, PlannerConfig
from drake_grasp.policy.sampling import sample_workspace_poses
from drake_grasp.robots import get_robot

FAILURE_CODES = {None: 0} | {f: i + 1 for i, f in enumerate(PlanFailure)}
HEIGHT_RANGE = (0.0, 0.3)  # grasp points from the table top up to 0.3 m [m]


def failure_code_names() -> dict[str, str]:
    """The manifest's legend of the stored failure codes."""
    return {str(c): (f.value if f else "success") for f, c in FAILURE_CODES.items()}


def label_shard(k: int, *, robot: str, seed: int, samples: int, shard_size: int,
                lower: list[float], upper: list[float], table_height: float = 0.0) -> dict[str, np.ndarray]:
    """Shard k of a job: poses from rng(seed, k), each planned from home."""
    planner = GraspPlanner(get_robot(robot), seed=[seed, k, 1],
                           config=PlannerConfig(table_height=table_height))
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
