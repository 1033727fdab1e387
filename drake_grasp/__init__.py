"""drake_grasp: reachability-aware 6-DoF grasping on Drake (Lou, Yang, Choi, ICRA 2020).

The layers, bottom up: `robot` (arm specs and loading, the hand, the task, the one
plant assembly), `perception` (depth -> object cloud), `datasets` (data on disk),
`planning` (IK, transit, timing), `simulation` (scenarios, objects, the station, grasp
trials), `learning` (the Reachability Predictor, the stability CNN, the hold predictor),
`policy` (where a grasp is sampled and scored), `cell` (where it is executed: the
executive and the episode; `GraspDetector`), `evaluation` (configuration, runs, reports,
data-labelling jobs), `service` (the gRPC grasp service and its client) and `apps` (the
programs: `python -m drake_grasp <command>`).

`from drake_grasp import GraspDetector, ReachabilityPredictor, GraspStabilityPredictor`
loads the grasp detector (models loaded once, grasps from depth images and clouds) and the
learned predictors lazily, so that the command-line tools that do not need torch do not
pay for importing it.
"""

__all__ = ["DetectConfig", "GraspDetector", "GraspStabilityPredictor", "ReachabilityPredictor"]


def __getattr__(name: str):
    if name in ("GraspDetector", "DetectConfig"):
        from drake_grasp.cell import detection

        return getattr(detection, name)
    if name == "ReachabilityPredictor":
        from drake_grasp.learning.rp import ReachabilityPredictor

        return ReachabilityPredictor
    if name == "GraspStabilityPredictor":
        from drake_grasp.learning.cnn import GraspStabilityPredictor

        return GraspStabilityPredictor
    raise AttributeError(f"module 'drake_grasp' has no attribute {name!r}")
