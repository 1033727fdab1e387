"""Grasp ranking: sample candidates on the object cloud and order them by a scorer (a policy).

The candidates come from the sampling's sampler (`policy.sampling.sample_candidates`: the paper's
uniform one by default, or GPG's hand placements). With scene structure in the cloud (a stool the
objects lie under), only candidates whose approach corridor is clear of it are kept
(`policy.clearance.corridor_blocked`: the planner would refuse the others), drawing again until there
are `num_candidates` or `MAX_SAMPLING_ROUNDS` draws are spent. A policy with its own candidates (GPD,
VPG) keeps them all.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import Value
from pydrake.systems.framework import LeafSystem

from drake_grasp.perception.cloud import ObjectCloud
from drake_grasp.planning.obstacles import ObstacleConfig
from drake_grasp.policy.clearance import corridor_blocked, thinned
from drake_grasp.policy.sampling import sample_candidates
from drake_grasp.policy.scorers import GraspScores, Scorer, Tier
from drake_grasp.robot.hand import HandSpec
from drake_grasp.robot.stages import stage

MAX_SAMPLING_ROUNDS = 20  # draws of `num_candidates` while scene structure blocks candidates


@dataclass
class RankedGrasps:
    """Candidates best first; empty when the object cloud is empty.

    `p_r` and `p_s` hold the policy's predictions in the same order, NaN where the
    policy made none (RAND makes neither; staged selection leaves some unscored, their
    score NaN too). `push` marks the candidates that are pushes (VPG with pushing): a push
    starts at X_WG and travels `robot.task.PUSH_LENGTH` along +x_G.
    """

    X_WG: np.ndarray  # (N, 4, 4)
    scores: np.ndarray  # (N,)
    num_object_points: int
    p_r: np.ndarray | None = None  # (N,)
    p_s: np.ndarray | None = None  # (N,)
    p_h: np.ndarray | None = None  # (N,)
    push: np.ndarray | None = None  # (N,) bool

    def __post_init__(self) -> None:
        nan = np.full(len(self.scores), np.nan)
        self.push = np.zeros(len(self.scores), bool) if self.push is None else np.asarray(self.push, bool)
        self.p_r = nan.copy() if self.p_r is None else np.asarray(self.p_r, dtype=float)
        self.p_s = nan.copy() if self.p_s is None else np.asarray(self.p_s, dtype=float)
        self.p_h = nan.copy() if self.p_h is None else np.asarray(self.p_h, dtype=float)

    def __len__(self) -> int:
        return len(self.scores)

    @staticmethod
    def empty() -> RankedGrasps:
        return RankedGrasps(np.zeros((0, 4, 4)), np.zeros(0), 0)


def rank_grasps(cloud: ObjectCloud, scorer: Scorer, *, num_candidates: int,
                gamma_deg: tuple[float, float], rng: np.random.Generator, sampler: str = "uniform",
                camera_positions: Sequence[Sequence[float]] | None = None,
                gpg_stop_at_table: bool = False, hand: HandSpec | None = None) -> RankedGrasps:
    """Samples `num_candidates` grasps for `hand` (default the Franka hand) on the cloud with `sampler`
    (`sample_clear_grasps`; or takes up to that many of the policy's own candidates) and sorts them, best
    first: by score, then those the policy left unscored (`Tier`), by p_r."""
    if len(cloud) == 0:
        return RankedGrasps.empty()
    own_candidates = getattr(scorer, "candidates", None)
    if own_candidates is not None:
        X_WG = own_candidates(cloud.points, num_candidates, gamma_deg, rng, table_z=cloud.table_z)
        if len(X_WG) == 0:
            return RankedGrasps(np.zeros((0, 4, 4)), np.zeros(0), len(cloud))
    else:
        X_WG = sample_clear_grasps(cloud, num_candidates, gamma_deg, rng, sampler=sampler,
                                   camera_positions=camera_positions, gpg_stop_at_table=gpg_stop_at_table,
                                   hand=hand)
        if len(X_WG) == 0:
            return RankedGrasps(np.zeros((0, 4, 4)), np.zeros(0), len(cloud))
    scored = GraspScores.of(scorer(cloud, X_WG, rng))
    order = ranked_order(scored)
    return RankedGrasps(X_WG[order], scored.score[order], len(cloud),
                        p_r=None if scored.p_r is None else scored.p_r[order],
                        p_s=None if scored.p_s is None else scored.p_s[order],
                        p_h=None if scored.p_h is None else scored.p_h[order],
                        push=None if scored.push is None else scored.push[order])


def ranked_order(scored: GraspScores) -> np.ndarray:
    """Indices of the scored candidates, best first: by score, then those the policy left unscored
    (`Tier`), by p_r."""
    n = len(scored.score)
    tier = np.full(n, Tier.SCORED) if scored.tier is None else scored.tier
    fallback = np.zeros(n) if scored.p_r is None else scored.p_r
    key = np.where(tier <= Tier.SCORED, scored.score, fallback)
    return np.lexsort((-key, tier))  # stable: by tier, then best key first


def sample_clear_grasps(cloud: ObjectCloud, count: int, gamma_deg: tuple[float, float],
                        rng: np.random.Generator, *, sampler: str = "uniform",
                        camera_positions: Sequence[Sequence[float]] | None = None,
                        gpg_stop_at_table: bool = False, hand: HandSpec | None = None) -> np.ndarray:
    """Up to `count` candidates for `hand` (default the Franka hand) on the objects from `sampler`
    (`sample_candidates`; GPG's normals face the `camera_positions` that saw the cloud, its hand kept above
    the cloud's table, stopped there with `gpg_stop_at_table`) whose approach corridor holds no scene
    structure; all of the first draw when the cloud has none."""
    gpg = None
    if sampler in ("gpg", "mixed"):
        from drake_grasp.policy.baselines.gpg import GpgConfig

        gpg = GpgConfig() if camera_positions is None else GpgConfig(
            camera_positions=tuple(tuple(float(v) for v in c) for c in camera_positions))
        if cloud.table_z is not None:
            gpg = replace(gpg, table_height=cloud.table_z)
        gpg = replace(gpg, stop_at_table=gpg_stop_at_table)

    def draw() -> np.ndarray:
        return sample_candidates(cloud.points, count, gamma_deg, sampler, rng, cloud.table_z, gpg,
                                 hand=hand)[0]

    X_WG = draw()
    if len(cloud.structure) == 0:
        return X_WG
    margin, structure = ObstacleConfig().corridor_margin, thinned(cloud.structure)
    kept = [X_WG[~corridor_blocked(structure, X_WG, margin, hand=hand)]]
    for _ in range(MAX_SAMPLING_ROUNDS - 1):
        if sum(len(k) for k in kept) >= count:
            break
        X_WG = draw()
        kept.append(X_WG[~corridor_blocked(structure, X_WG, margin, hand=hand)])
    return np.concatenate(kept)[:count]


class GraspSelector(LeafSystem):
    """Object cloud in, ranked grasps out (for `hand`, default the Franka hand). Randomness is seeded by
    (seed, time)."""

    def __init__(self, scorer: Scorer, *, num_candidates: int = 500,
                 gamma_deg: tuple[float, float] = (0.0, 90.0), seed: int = 0, sampler: str = "uniform",
                 camera_positions: Sequence[Sequence[float]] | None = None, gpg_stop_at_table: bool = False,
                 hand: HandSpec | None = None):
        super().__init__()
        self._scorer = scorer
        self._num_candidates = num_candidates
        self._gamma_deg = tuple(gamma_deg)
        self._sampler = sampler
        self._camera_positions = camera_positions
        self._gpg_stop_at_table = gpg_stop_at_table
        self._hand = hand
        self._seed = seed
        self._cloud_port = self.DeclareAbstractInputPort("object_cloud", Value(ObjectCloud.empty()))
        self.DeclareAbstractOutputPort(
            "ranked_grasps", lambda: Value(RankedGrasps.empty()), self._calc,
            prerequisites_of_calc={self.all_sources_ticket()},
        )

    @stage("selection")
    def _calc(self, context, output) -> None:
        rng = np.random.default_rng([self._seed, round(context.get_time() * 1000)])
        output.set_value(rank_grasps(
            self._cloud_port.Eval(context), self._scorer, num_candidates=self._num_candidates,
            gamma_deg=self._gamma_deg, rng=rng, sampler=self._sampler,
            camera_positions=self._camera_positions, gpg_stop_at_table=self._gpg_stop_at_table,
            hand=self._hand,
        ))
