"""Grasp ranking: sample candidates on the object cloud and order them by a pluggable scorer.

A scorer is a pure function `(cloud, X_WG, rng) -> scores` (higher is better);
policies are named scorers. RAND (the paper's baseline) scores uniformly at
random; RP ranks by the arm's Reachability Predictor alone (p_r, ties random),
which isolates what reachability awareness saves the planner; CNN ranks by the
grasp stability CNN alone (p_s); CNN_RP is the paper's policy, p_g = p_r * p_s.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import Value
from pydrake.systems.framework import LeafSystem

from drake_grasp.perception import ObjectCloud
from drake_grasp.robots import RobotSpec
from drake_grasp.sampling import sample_grasps

Scorer = Callable[[ObjectCloud, np.ndarray, np.random.Generator], np.ndarray]


@dataclass
class RankedGrasps:
    """Candidates best first; empty when the object cloud is empty."""

    X_WG: np.ndarray  # (N, 4, 4)
    scores: np.ndarray  # (N,)
    num_object_points: int

    @staticmethod
    def empty() -> RankedGrasps:
        return RankedGrasps(np.zeros((0, 4, 4)), np.zeros(0), 0)


def random_scorer(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """RAND: every candidate equally likely to come first."""
    return rng.uniform(size=len(X_WG))


def reachability_scorer(robot: RobotSpec) -> Scorer:
    """RP: p_r of the arm's shipped predictor; a tiny random term breaks ties among sure grasps."""
    from drake_grasp.rp import ReachabilityPredictor

    rp = ReachabilityPredictor.load(robot.name)

    def score(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return rp(X_WG) + 1e-6 * rng.uniform(size=len(X_WG))

    return score


def stability_scorer(robot: RobotSpec) -> Scorer:
    """CNN: p_s of the shipped stability CNN on the whole object cloud (the hand is the same on every arm)."""
    from drake_grasp.cnn import GraspStabilityPredictor

    cnn = GraspStabilityPredictor.load()

    def score(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return cnn(cloud.points, X_WG) + 1e-6 * rng.uniform(size=len(X_WG))

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


def rank_grasps(cloud: ObjectCloud, scorer: Scorer, *, num_candidates: int,
                gamma_deg: tuple[float, float], rng: np.random.Generator) -> RankedGrasps:
    """Samples `num_candidates` grasps on the cloud and sorts them by score, best first."""
    if len(cloud) == 0:
        return RankedGrasps.empty()
    X_WG = sample_grasps(cloud.points, num_candidates, gamma_deg, rng)
    scores = np.asarray(scorer(cloud, X_WG, rng), dtype=float)
    order = np.argsort(-scores, kind="stable")
    return RankedGrasps(X_WG[order], scores[order], len(cloud))


class GraspSelector(LeafSystem):
    """Object cloud in, ranked grasps out. Randomness is seeded by (seed, time)."""

    def __init__(self, scorer: Scorer, *, num_candidates: int = 500,
                 gamma_deg: tuple[float, float] = (0.0, 90.0), seed: int = 0):
        super().__init__()
        self._scorer = scorer
        self._num_candidates = num_candidates
        self._gamma_deg = tuple(gamma_deg)
        self._seed = seed
        self._cloud_port = self.DeclareAbstractInputPort(
            "object_cloud", Value(ObjectCloud(np.zeros((0, 3)), np.zeros((0, 3))))
        )
        self.DeclareAbstractOutputPort(
            "ranked_grasps", lambda: Value(RankedGrasps.empty()), self._calc,
            prerequisites_of_calc={self.all_sources_ticket()},
        )

    def _calc(self, context, output) -> None:
        rng = np.random.default_rng([self._seed, round(context.get_time() * 1000)])
        output.set_value(rank_grasps(
            self._cloud_port.Eval(context), self._scorer, num_candidates=self._num_candidates,
            gamma_deg=self._gamma_deg, rng=rng,
        ))
