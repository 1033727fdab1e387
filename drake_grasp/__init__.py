"""drake_grasp: reachability-aware 6-DoF grasping on Drake (Lou, Yang, Choi, ICRA 2020).

Where a grasp is made: `perception` (depth cloud -> object cloud), `policy`
(sampled, scored, selected, executed), `planning` (IK, transit, timing),
`simulation` (the station, scenes, grasp trials), `learning` (the Reachability
Predictor and the stability CNN), `datasets` (labels and trials on disk), and
`apps` (the programs). `robots`, `hand` and `task` hold the arm specs, the hand and
grasp frame, and the task's constants and success rule.

`from drake_grasp import ReachabilityPredictor, GraspStabilityPredictor` loads the
learned predictors lazily, so that the command-line tools that do not need torch
do not pay for importing it.
"""

__all__ = ["GraspStabilityPredictor", "ReachabilityPredictor"]


def __getattr__(name: str):
    if name == "ReachabilityPredictor":
        from drake_grasp.learning.rp import ReachabilityPredictor

        return ReachabilityPredictor
    if name == "GraspStabilityPredictor":
        from drake_grasp.learning.cnn import GraspStabilityPredictor

        return GraspStabilityPredictor
    raise AttributeError(f"module 'drake_grasp' has no attribute {name!r}")
