"""Policies as scorers: callables `(cloud, X_WG, rng) -> GraspScores` (higher is better).

RAND (the paper's baseline) scores uniformly at random; RP ranks by the arm's
Reachability Predictor alone (p_r, ties random), which isolates what
reachability awareness saves the planner; CNN ranks by the grasp stability CNN
alone (p_s); CNN_RP is the paper's policy, p_g = p_r * p_s (both times p_h, the hold
predictor's, unless `SelectionConfig.hold_weights` is None); GPD1C and GPD are
the GPD baseline with one camera and with two (its own candidates and classifier;
`simulate` adds the second camera for GPD); VPG is VPG's grasping (its own net over
a heightmap, straight-down grasps) and VPG_PUSH VPG whole, pushes and grasps by their Q maps. Each scorer also
returns the predictions it made (p_r, p_s), for drawing and for knowing when to stop.
The CNN's voxel grids hold every point the cameras saw near the grasp, observed scene
structure (`ObjectCloud.structure`, a shelf) included; candidates lie on the objects only.

The CNN is the cost of selection (about 0.6 ms a candidate on a 2-core CPU). By
default (`SelectionConfig.staged`) it is spent where it can matter (`staged=False`
scores every candidate, as the paper does): candidates whose open hand would run into the
observed cloud on its way in (`drake_grasp.policy.clearance`) are not scored and
rank last, and CNN_RP scores the rest in decreasing p_r and stops once its
`exact_top` best p_g reach the highest p_r left (p_s <= 1, so p_r bounds p_g):
those ranks are exactly the ones scoring everything would give them among the
unblocked candidates. The candidates left unscored rank after them by p_r.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_grasp.perception.cloud import ObjectCloud
from drake_grasp.policy.clearance import approach_blocked
from drake_grasp.policy.config import SelectionConfig
from drake_grasp.robot.hand import HandSpec, check_model_hand
from drake_grasp.robot.specs import RobotSpec
from drake_grasp.simulation.scenario import FIRST_CAMERA_XYZ, SECOND_CAMERA_XYZ, Scenario

if TYPE_CHECKING:
    from drake_grasp.policy.baselines.vpg import HeightmapConfig

TIE_BREAK = 1e-6  # a tiny random term orders candidates a predictor scores alike


class Tier:
    """Where a candidate ranks: every scored candidate before every unscored one."""

    SCORED = 0
    UNSCORED = 1  # staged selection: its p_r bound could not reach the top ranks, ranked by p_r
    BLOCKED = 2  # staged selection: the open hand's approach runs into the observed cloud


@dataclass
class GraspScores:
    """A policy's scores of N candidates, with the predictions it made on the way (None: not made).

    `score` is NaN where the policy did not score a candidate; `tier` (None: all scored)
    says where such candidates rank (`Tier`).
    """

    score: np.ndarray  # (N,) what the policy ranks by
    p_r: np.ndarray | None = None  # (N,) reachability
    p_s: np.ndarray | None = None  # (N,) stability
    p_h: np.ndarray | None = None  # (N,) hold (only with a hold predictor)
    tier: np.ndarray | None = None  # (N,) Tier codes
    push: np.ndarray | None = None  # (N,) bool: the candidate is a push (VPG with pushing)

    @staticmethod
    def of(value: GraspScores | np.ndarray) -> GraspScores:
        """A scorer's answer; a plain array is a score alone."""
        return value if isinstance(value, GraspScores) else GraspScores(np.asarray(value, dtype=float))


Scorer = Callable[[ObjectCloud, np.ndarray, np.random.Generator], GraspScores]
# A scorer object with a method `candidates(points_W, count, gamma_deg, rng) -> X_WG` brings its
# own candidates (GPD's GPG); the others score the paper's uniform samples (`rank_grasps`).


def random_scorer(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> GraspScores:
    """RAND: every candidate equally likely to come first."""
    return GraspScores(rng.uniform(size=len(X_WG)))


def reachability_scorer(robot: RobotSpec) -> Scorer:
    """RP: p_r of the arm's shipped predictor."""
    from drake_grasp.learning.rp import ReachabilityPredictor, rp_weights

    rp = ReachabilityPredictor.load(str(rp_weights(robot)))

    def score(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> GraspScores:
        p_r = rp(X_WG)
        return GraspScores(p_r + TIE_BREAK * rng.uniform(size=len(X_WG)), p_r=p_r)

    return score


def table_plane(cloud: ObjectCloud) -> tuple[np.ndarray, float] | None:
    """The cloud's table top as (n, d) of n . p + d = 0 in the world frame: the fitted plane, else the
    level plane at `table_z`; None when no table was seen."""
    if cloud.table is not None:
        return np.asarray(cloud.table.normal, dtype=np.float64), float(cloud.table.offset)
    if cloud.table_z is not None:
        return np.array([0.0, 0.0, 1.0]), -float(cloud.table_z)
    return None


def staged_stability(cnn, cloud: ObjectCloud, X_WG: np.ndarray, prior: np.ndarray | None,
                     config: SelectionConfig, hand: HandSpec | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(p_s, tier) of N candidates with the CNN spent as `config` says; p_s is NaN where not scored.

    The grids see the cloud's objects and structure (and its table, for a CNN with a table channel).
    Staged, candidates whose `hand` (default the Franka hand) would run into the cloud (`approach_blocked`)
    are not scored. With
    a `prior` in [0, 1] that the policy
    multiplies p_s by (CNN_RP's p_r, times p_h with a hold predictor) the unblocked candidates are
    scored in decreasing prior, `batch_size` at a time, until the `exact_top` best prior * p_s reach
    the highest prior not yet scored.
    """
    grids = cnn.voxelize(cloud.scene_points, X_WG, table_plane(cloud))
    n = len(X_WG)
    p_s, tier = np.full(n, np.nan), np.full(n, Tier.SCORED)
    if not config.staged:
        p_s[:] = cnn.predict(grids)
        return p_s, tier
    blocked = approach_blocked(grids if grids.ndim == 4 else grids[:, 0], min_voxels=config.blocking_voxels,
                               hand=hand)
    tier[blocked] = Tier.BLOCKED
    open_ = np.flatnonzero(~blocked)
    if prior is None:
        p_s[open_] = cnn.predict(grids[open_], batch_size=config.batch_size)
        return p_s, tier
    queue = open_[np.argsort(-prior[open_], kind="stable")]
    done = 0
    while done < len(queue):
        batch = queue[done:done + config.batch_size]
        p_s[batch] = cnn.predict(grids[batch])
        done += len(batch)
        if done < len(queue):
            scored = queue[:done]
            best = np.sort(prior[scored] * p_s[scored])[::-1][:config.exact_top]
            if len(best) == config.exact_top and best[-1] >= prior[queue[done]]:
                break
    tier[queue[done:]] = Tier.UNSCORED
    return p_s, tier


def _stability_cnn(selection: SelectionConfig, hand: HandSpec):
    """The CNN `selection` names (one with a hand channel told `hand`)."""
    from drake_grasp.learning.cnn import GraspStabilityPredictor

    return GraspStabilityPredictor.load(selection.cnn_weights, precision=selection.cnn_precision, hand=hand)


def _hold_predictor(selection: SelectionConfig):
    """The hold predictor `selection` names, or None."""
    if selection.hold_weights is None:
        return None
    from drake_grasp.learning.hold import HoldPredictor

    return HoldPredictor.load(selection.hold_weights, join_parts=selection.hold_join_parts)


def stability_scorer(robot: RobotSpec, selection: SelectionConfig | None = None) -> Scorer:
    """CNN: p_s of the stability CNN on the whole object cloud (the hand is the same on every arm);
    times p_h with a hold predictor."""
    return hand_stability_scorer(robot.hand, selection)


def hand_stability_scorer(hand: HandSpec, selection: SelectionConfig | None = None) -> Scorer:
    """`stability_scorer` for a hand alone (no arm): what a floating hand's trials rank by."""
    selection = selection or SelectionConfig()
    cnn, hold = _stability_cnn(selection, hand), _hold_predictor(selection)

    def score(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> GraspScores:
        p_h = None if hold is None else hold(cloud.points, X_WG)
        p_s, tier = staged_stability(cnn, cloud, X_WG, p_h, selection, hand)
        score = p_s + TIE_BREAK * rng.uniform(size=len(X_WG))
        score = score if p_h is None else score * p_h
        return GraspScores(score, p_s=p_s, p_h=p_h, tier=tier)

    return score


def reachable_stability_scorer(robot: RobotSpec, selection: SelectionConfig | None = None) -> Scorer:
    """CNN_RP, the paper's policy: p_g = p_r * p_s (* p_h with a hold predictor)."""
    from drake_grasp.learning.rp import ReachabilityPredictor, rp_weights

    selection = selection or SelectionConfig()
    rp = ReachabilityPredictor.load(str(rp_weights(robot)))
    cnn, hold = _stability_cnn(selection, robot.hand), _hold_predictor(selection)

    def score(cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> GraspScores:
        p_r = rp(X_WG)
        p_h = None if hold is None else hold(cloud.points, X_WG)
        prior = p_r if p_h is None else p_r * p_h  # (bounds p_g as p_r does: staged selection stays exact)
        p_s, tier = staged_stability(cnn, cloud, X_WG, prior, selection, robot.hand)
        n = len(X_WG)
        p_g = (prior + TIE_BREAK * rng.uniform(size=n)) * (p_s + TIE_BREAK * rng.uniform(size=n))
        return GraspScores(p_g, p_r=p_r, p_s=p_s, p_h=p_h, tier=tier)

    return score


class GpdScorer:
    """GPD: GPG's candidates on the object cloud, scored by GPD's classifier (`drake_grasp.policy.baselines`);
    reachability plays no part, as in the paper's baseline. `camera_positions`: where the cloud was
    seen from (the normals face those cameras): one camera for `gpd1c`, two for `gpd`."""

    def __init__(self, weights: str | Path | None = None,
                 camera_positions: tuple[tuple[float, float, float], ...] = (FIRST_CAMERA_XYZ,)):
        from drake_grasp.policy.baselines.gpd import DEFAULT_WEIGHTS, GpdClassifier
        from drake_grasp.policy.baselines.gpg import GpgConfig

        path = weights or DEFAULT_WEIGHTS
        self.gpg = GpgConfig(camera_positions=tuple(tuple(p) for p in camera_positions))
        try:
            self.classifier = GpdClassifier.load(path, gpg=self.gpg)
        except ValueError as e:
            raise ValueError(f"{e} (the GPD baseline's classifier: collect_grasps --sampler gpg, then "
                             "train gpd, as docs/baselines.md says)") from None
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # (cloud, its normals)

    @classmethod
    def two_cameras(cls) -> GpdScorer:
        """`gpd`: the clouds of the scenario's camera and the second one fused, scored by the classifier
        trained on such clouds (the one-camera classifier misjudges their grasps)."""
        from drake_grasp.policy.baselines.gpd import TWO_CAMERA_WEIGHTS

        return cls(TWO_CAMERA_WEIGHTS, camera_positions=(FIRST_CAMERA_XYZ, SECOND_CAMERA_XYZ))

    def _normals(self, points_W: np.ndarray) -> np.ndarray:
        """The cloud's normals; `rank_grasps` asks for candidates and then scores on the same cloud, so
        the last cloud's are kept rather than estimated twice."""
        from drake_grasp.policy.baselines.gpg import config_normals

        if self._last is None or self._last[0] is not points_W:
            self._last = (points_W, config_normals(points_W, self.gpg))
        return self._last[1]

    def candidates(self, points_W: np.ndarray, count: int, gamma_deg: tuple[float, float],
                   rng: np.random.Generator, table_z: float | None = None) -> np.ndarray:
        """GPG's candidates, the hand kept above the measured table (`table_z`; default: GPG's own)."""
        from drake_grasp.policy.baselines.gpg import gpg_candidates

        config = self.gpg if table_z is None else replace(self.gpg, table_height=table_z)
        return gpg_candidates(points_W, count, gamma_deg, rng, config, self._normals(points_W))

    def __call__(self, cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> GraspScores:
        score = self.classifier(cloud.points, X_WG, self._normals(cloud.points)).astype(float)
        return GraspScores(score + TIE_BREAK * rng.uniform(size=len(X_WG)))


class VpgScorer:
    """VPG's grasping (`vpg`): the net's best straight-down grasps over the heightmap, by its grasp
    probability, one a spot 1 cm apart (so that after a failure the next spot is elsewhere, as VPG's
    online learning would move it); reachability plays no part, as in the paper's baseline."""

    def __init__(self, weights: str | Path | None = None):
        from drake_grasp.policy.baselines.vpg import DEFAULT_WEIGHTS, load_model

        try:
            self.model = load_model(weights or DEFAULT_WEIGHTS)[0]
        except ValueError as e:
            raise ValueError(f"{e} (the VPG baseline's net: collect_grasps --sampler topdown, then "
                             "train vpg, as docs/baselines.md says)") from None
        self._last: tuple[np.ndarray, float | None, HeightmapConfig, np.ndarray, np.ndarray] | None = None
        # (cloud, table height, its heightmap's config, heights, q maps)

    @staticmethod
    def _heightmap_config(points_W: np.ndarray, table_z: float | None) -> HeightmapConfig:
        """VPG's square, grown to hold every point of the cloud, heights above the measured table."""
        from drake_grasp.policy.baselines.vpg import HeightmapConfig, covering

        base = HeightmapConfig() if table_z is None else HeightmapConfig(table_height=table_z)
        return covering(points_W, base)

    def _maps(self, points_W: np.ndarray, table_z: float | None
              ) -> tuple[HeightmapConfig, np.ndarray, np.ndarray]:
        """(heightmap config, heights, q maps) of a cloud, heights above the measured table (`table_z`;
        default: the heightmap's own); `rank_grasps` asks for candidates and then scores on the same
        cloud, so the last cloud's maps are kept rather than computed twice."""
        from drake_grasp.policy.baselines.vpg import heightmap, q_maps

        if self._last is None or self._last[0] is not points_W or self._last[1] != table_z:
            config = self._heightmap_config(points_W, table_z)
            heights = heightmap(points_W, config)
            self._last = (points_W, table_z, config, heights, q_maps(self.model, heights))
        return self._last[2:]

    def candidates(self, points_W: np.ndarray, count: int, gamma_deg: tuple[float, float],
                   rng: np.random.Generator, table_z: float | None = None) -> np.ndarray:
        from drake_grasp.policy.baselines.vpg import CANDIDATE_SPACING, best_grasps

        config, heights, q = self._maps(points_W, table_z)  # top-down only, whatever the cone
        return best_grasps(heights, q, count, config, spacing=CANDIDATE_SPACING)

    def __call__(self, cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> GraspScores:
        from drake_grasp.policy.baselines.vpg import grasp_cell

        config, _, q = self._maps(cloud.points, cloud.table_z)
        score = np.array([q[k, i, j] for i, j, k in (grasp_cell(X, config) for X in X_WG)], dtype=float)
        return GraspScores(score + TIE_BREAK * rng.uniform(size=len(X_WG)))


@dataclass
class VpgObservation:
    """What VPG with pushing saw and offered at one observation (for its training)."""

    config: HeightmapConfig
    heights: np.ndarray  # (H, W) [m above the table]
    X_WG: np.ndarray  # (K, 4, 4) its candidates
    push: np.ndarray  # (K,) bool
    best_q: float  # the highest Q among them (VPG's value of the state)


class VpgPushScorer(VpgScorer):
    """VPG with pushing (`vpg_push`): the best pushes and grasps of its two Q maps, one a spot 1 cm apart,
    ranked by Q together (the first one is VPG's action). With `explore` > 0 (its training), the ranking
    puts a random primitive's candidates first with that probability (VPG's epsilon-greedy);
    `observations` (when given) collects what each ranking saw and offered."""

    def __init__(self, weights: str | Path | None = None, *, explore: float = 0.0,
                 observations: list[VpgObservation] | None = None):
        from drake_grasp.policy.baselines.vpg_push import DEFAULT_WEIGHTS, load_model

        try:
            self.model = load_model(weights or DEFAULT_WEIGHTS)[0]
        except ValueError as e:
            raise ValueError(f"{e} (VPG with pushing: train vpg-push, as docs/vpg_push.md says)") from None
        self.explore = explore
        self.observations = observations
        self._last = None
        self._offered: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # (X_WG, push, Q)

    def _maps(self, points_W: np.ndarray, table_z: float | None):
        """(heightmap config, heights, (push Q, grasp Q)) of a cloud, kept for the same cloud."""
        from drake_grasp.policy.baselines.vpg import heightmap

        if self._last is None or self._last[0] is not points_W or self._last[1] != table_z:
            config = self._heightmap_config(points_W, table_z)
            heights = heightmap(points_W, config)
            self._last = (points_W, table_z, config, heights, self.model.q_maps(heights))
        return self._last[2:]

    def candidates(self, points_W: np.ndarray, count: int, gamma_deg: tuple[float, float],
                   rng: np.random.Generator, table_z: float | None = None) -> np.ndarray:
        from drake_grasp.policy.baselines.vpg import CANDIDATE_SPACING
        from drake_grasp.policy.baselines.vpg_push import best_actions

        config, heights, (q_push, q_grasp) = self._maps(points_W, table_z)
        X_WG, push, q = best_actions(heights, q_push, q_grasp, count, config, CANDIDATE_SPACING)
        self._offered = (X_WG, push, q)
        if self.observations is not None:
            self.observations.append(VpgObservation(config, heights, X_WG, push, float(q.max(initial=0.0))))
        return X_WG

    def __call__(self, cloud: ObjectCloud, X_WG: np.ndarray, rng: np.random.Generator) -> GraspScores:
        from drake_grasp.policy.baselines.vpg_push import Q_MAX

        if self._offered is None or self._offered[0] is not X_WG:
            raise ValueError("VPG with pushing scores only the candidates it offered (its `candidates`)")
        _, push, q = self._offered
        score = q + TIE_BREAK * rng.uniform(size=len(X_WG))
        if self.explore > 0 and rng.uniform() < self.explore:
            pushing = bool(rng.uniform() < 0.5)
            score = score + np.where(push == pushing, 2 * Q_MAX, 0.0)
        return GraspScores(score, push=push)


POLICIES: dict[str, Callable[[RobotSpec, SelectionConfig], Scorer]] = {
    "rand": lambda robot, selection: random_scorer,
    "rp": lambda robot, selection: reachability_scorer(robot),
    "cnn": stability_scorer,
    "cnn_rp": reachable_stability_scorer,
    "gpd1c": lambda robot, selection: GpdScorer(),
    "gpd": lambda robot, selection: GpdScorer.two_cameras(),
    "vpg": lambda robot, selection: VpgScorer(),
    "vpg_push": lambda robot, selection: VpgPushScorer(),
}
USES_CNN = ("cnn", "cnn_rp")  # the policies a SelectionConfig changes
USES_RP = ("rp", "cnn_rp")


def policy_weights(policy: str, robot: RobotSpec,
                   selection: SelectionConfig | None = None) -> list[Path]:
    """The weights files a policy's scorer loads: with the code, what its results depend on."""
    from drake_grasp.learning.rp import rp_weights
    from drake_grasp.policy.baselines import gpd, vpg, vpg_push
    from drake_grasp.robot.paths import model_path

    selection = (selection or SelectionConfig()).for_hand(robot.hand)
    files = [rp_weights(robot)] if policy in USES_RP else []
    if policy in USES_CNN:
        files += [model_path(w) for w in (selection.cnn_weights, selection.hold_weights) if w is not None]
    baselines = {"gpd1c": gpd.DEFAULT_WEIGHTS, "gpd": gpd.TWO_CAMERA_WEIGHTS, "vpg": vpg.DEFAULT_WEIGHTS,
                 "vpg_push": vpg_push.DEFAULT_WEIGHTS}
    return files + ([baselines[policy]] if policy in baselines else [])


TWO_CAMERA_POLICIES = ("gpd",)  # they see the scene through the scenario's camera and a second one


def policy_scenario(policy: str, scenario: Scenario) -> Scenario:
    """The scenario as the policy sees it: the two-camera policies get the second camera."""
    return scenario.with_second_camera() if policy in TWO_CAMERA_POLICIES else scenario


def make_scorer(policy: str, robot: RobotSpec, selection: SelectionConfig | None = None) -> Scorer:
    """The policy's scorer for `robot` and its hand; ValueError for an unknown policy, or one whose models
    were made with another hand (their cards' `hand`)."""
    try:
        factory = POLICIES[policy]
    except KeyError:
        raise ValueError(f"unknown policy '{policy}'; choose one of: {', '.join(sorted(POLICIES))}") from None
    from drake_grasp.learning.model_cards import saved_card
    from drake_grasp.robot.paths import model_path

    selection = (selection or SelectionConfig()).for_hand(robot.hand)

    transferred = {str(model_path(w)) for w in (selection.cnn_weights, selection.hold_weights)
                   if w is not None and selection.any_hand}
    for path in policy_weights(policy, robot, selection):
        if str(path) not in transferred:
            check_model_hand(saved_card(path), robot.hand, f"{path.name} (policy '{policy}')")
    return factory(robot, selection)
