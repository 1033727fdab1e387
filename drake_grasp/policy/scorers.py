"""Policies as scorers: pure functions `(cloud, X_WG, rng) -> scores` (higher is better).

RAND (the paper's baseline) scores uniformly at random; RP ranks by the arm's
Reachability Predictor alone (p_r, ties random), which isolates what
reachability awareness saves the planner; CNN ranks by the grasp stability CNN
alone (p_s); CNN_RP is the paper's policy, p_g = p_r * p_s.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drake_grasp.perception import ObjectCloud
from drake_grasp.robots import RobotSpec

Scorer = Callable[[ObjectCloud, np.ndarray, np.random.Generator], np.ndarray]
TIE_BREAK = 1e-6  # a tiny random term orders candidates a predictor scores alike


def random_scorer(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """RAND: every candidate equally likely to come first."""
    return rng.uniform(size=len(X_WG))


def reachability_scorer(robot: RobotSpec) -> Scorer:
    """RP: p_r of the arm's shipped predictor."""
    from drake_grasp.learning.rp import ReachabilityPredictor

    rp = ReachabilityPredictor.load(robot.name)

    def score(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return rp(X_WG) + TIE_BREAK * rng.uniform(size=len(X_WG))

    return score


def stability_scorer(robot: RobotSpec) -> Scorer:
    """CNN: p_s of the shipped stability CNN on the whole object cloud (the hand is the same on every arm)."""
    from drake_grasp.learning.cnn import GraspStabilityPredictor

    cnn = GraspStabilityPredictor.load()

    def score(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return cnn(cloud.points, X_WG) + TIE_BREAK * rng.uniform(size=len(X_WG))

    return score


def reachable_stability_scorer(robot: RobotSpec) -> Scorer:
    """CNN_RP, the paper's policy: p_g = p_r * p_s."""
    reachable, stable = reachability_scorer(robot), stability_scorer(robot)

    def score(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return reachable(cloud, X_WG, rng) * stable(cloud, X_WG, rng)

    return score


POLICIES: dict[str, Callable[[RobotSpec], Scorer]] = {
    "rand": lambda robot: random_scorer,
    "rp": reachability_scorer,
    "cnn": stability_scorer,
    "cnn_rp": reachable_stability_scorer,
}


def make_scorer(policy: str, robot: RobotSpec) -> Scorer:
    try:
        factory = POLICIES[policy]
    except KeyError:
        raise ValueError(f"unknown policy '{policy}'; choose one of: {', '.join(sorted(POLICIES))}") from None
    return factory(robot)
