"""Policies as scorers: pure functions `(cloud, X_WG, rng) -> GraspScores` (higher is better).

RAND (the paper's baseline) scores uniformly at random; RP ranks by the arm's
Reachability Predictor alone (p_r, ties random), which isolates what
reachability awareness saves the planner; CNN ranks by the grasp stability CNN
alone (p_s); CNN_RP is the paper's policy, p_g = p_r * p_s. Each scorer also
returns the predictions it made (p_r, p_s), for drawing and for knowing when to stop.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drake_grasp.perception import ObjectCloud
from drake_grasp.robots import RobotSpec

TIE_BREAK = 1e-6  # a tiny random term orders candidates a predictor scores alike


@dataclass
class GraspScores:
    """A policy's scores of N candidates, with the predictions it made on the way (None: not made)."""

    score: np.ndarray  # (N,) what the policy ranks by
    p_r: np.ndarray | None = None  # (N,) reachability
    p_s: np.ndarray | None = None  # (N,) stability

    @staticmethod
    def of(value: GraspScores | np.ndarray) -> GraspScores:
        """A scorer's answer; a plain array is a score alone."""
        return value if isinstance(value, GraspScores) else GraspScores(np.asarray(value, dtype=float))


Scorer = Callable[[ObjectCloud, np.ndarray, np.random.Generator], GraspScores]


def random_scorer(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> GraspScores:
    """RAND: every candidate equally likely to come first."""
    return GraspScores(rng.uniform(size=len(X_WG)))


def reachability_scorer(robot: RobotSpec) -> Scorer:
    """RP: p_r of the arm's shipped predictor."""
    from drake_grasp.learning.rp import ReachabilityPredictor

    rp = ReachabilityPredictor.load(robot.source or robot.name)

    def score(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> GraspScores:
        p_r = rp(X_WG)
        return GraspScores(p_r + TIE_BREAK * rng.uniform(size=len(X_WG)), p_r=p_r)

    return score


def stability_scorer(robot: RobotSpec) -> Scorer:
    """CNN: p_s of the shipped stability CNN on the whole object cloud (the hand is the same on every arm)."""
    from drake_grasp.learning.cnn import GraspStabilityPredictor

    cnn = GraspStabilityPredictor.load()

    def score(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> GraspScores:
        p_s = cnn(cloud.points, X_WG)
        return GraspScores(p_s + TIE_BREAK * rng.uniform(size=len(X_WG)), p_s=p_s)

    return score


def reachable_stability_scorer(robot: RobotSpec) -> Scorer:
    """CNN_RP, the paper's policy: p_g = p_r * p_s."""
    reachable, stable = reachability_scorer(robot), stability_scorer(robot)

    def score(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> GraspScores:
        r, s = reachable(cloud, X_WG, rng), stable(cloud, X_WG, rng)
        return GraspScores(r.score * s.score, p_r=r.p_r, p_s=s.p_s)

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
