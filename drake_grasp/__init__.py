"""drake_grasp: reachability-aware 6-DoF grasping on Drake (Lou, Yang, Choi, ICRA 2020).

`from drake_grasp import ReachabilityPredictor, GraspStabilityPredictor` loads the
learned predictors lazily, so that the command-line tools that do not need torch
do not pay for importing it.
"""

__all__ = ["GraspStabilityPredictor", "ReachabilityPredictor"]


def __getattr__(name: str):
    if name == "ReachabilityPredictor":
        from drake_grasp.rp import ReachabilityPredictor

        return ReachabilityPredictor
    if name == "GraspStabilityPredictor":
        from drake_grasp.cnn import GraspStabilityPredictor

        return GraspStabilityPredictor
    raise AttributeError(f"module 'drake_grasp' has no attribute {name!r}")
