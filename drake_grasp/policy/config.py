"""How the CNN policies select among the candidates (`SelectionConfig`), YAML-loadable.

The CNN is the cost of selection (about 0.6 ms a candidate on a 2-core CPU). By default it is
`staged`: spent where it can change the top ranks (`drake_grasp.policy.scorers`); `staged: false`
scores every candidate, as the paper does. The weights of the stability CNN and of the hold
predictor are named here, so that an evaluation's configuration says which models it ran.
"""

# No `from __future__ import annotations`: yaml_load_typed reads the dataclass field types.
import dataclasses as dc

from drake_grasp.policy.clearance import BLOCKING_VOXELS

DEFAULT_CNN_WEIGHTS = "models/grasp_cnn_all.pt"  # the Franka hand's
DEFAULT_HOLD_WEIGHTS = "models/grasp_hold.pt"
# For a hand with no CNN of its own: one network for any parallel-jaw hand, told which by a hand channel
ANY_HAND_CNN_WEIGHTS = "models/grasp_cnn_any_hand_wide.pt"
PRECISIONS = ("float32", "bfloat16", "auto")  # what `learning.cnn.GraspStabilityPredictor` runs in


@dc.dataclass
class SelectionConfig:
    """How the CNN policies spend the stability CNN on the candidates (see `policy.scorers`)."""

    staged: bool = True  # False: the CNN scores every candidate, as the paper does
    blocking_voxels: int = BLOCKING_VOXELS  # occupied voxels in the hand's swept volume that block
    exact_top: int = 10  # CNN_RP: ranks guaranteed equal to scoring every unblocked candidate
    batch_size: int = 16  # candidates per CNN call while staging (small batches run fastest on a CPU)
    # The stability CNN's weights and a hold predictor (`learning.hold`; the CNN policies rank by
    # p_s * p_h; None: p_s alone, as the paper), by name (`robot.paths.model_path`).
    cnn_weights: str = DEFAULT_CNN_WEIGHTS
    hold_weights: str | None = DEFAULT_HOLD_WEIGHTS  # noqa: UP007 (yaml_load_typed's form)
    # Whether the hold predictor's segmentation joins a part that continues a body end to end, the neck
    # or cap of a lying bottle or can (`perception.cloud.join_end_to_end`); False: plain DBSCAN segments
    hold_join_parts: bool = True
    # Use the CNN and the hold predictor whatever hand made them (a transfer experiment: a model run with a
    # hand it never saw); False: models of another hand are refused (`policy.scorers.make_scorer`)
    any_hand: bool = False
    # The arithmetic the stability CNN runs in (`learning.cnn.GraspStabilityPredictor`): "bfloat16" is
    # about twice as fast on a CPU with native bfloat16 (AVX512-BF16, AMX) and moves p_s by under 0.005;
    # "auto": bfloat16 where native, else float32 (detection's default); "float32" (the closed loop's
    # default) gives every committed table's numbers.
    cnn_precision: str = "float32"

    def __post_init__(self) -> None:
        self.check()

    def for_hand(self, hand) -> "SelectionConfig":
        """This selection for a `HandSpec`: a hand that names its own models (`cnn_weights`,
        `hold_weights`: those of the Franka hand are the defaults) gets them where this selection names
        the defaults; another hand that names none gets the CNN for any parallel-jaw hand
        (`ANY_HAND_CNN_WEIGHTS`) and no hold predictor (the default one was fitted on the Franka hand's
        trials). Models named otherwise stay (and are refused if made with another hand), as do all with
        `any_hand`."""
        from drake_grasp.robot.hand import default_hand

        if self.any_hand:
            return self
        franka = hand.fingerprint == default_hand().fingerprint
        own_cnn = hand.cnn_weights or ("" if franka else ANY_HAND_CNN_WEIGHTS)
        own_hold = hand.hold_weights or ("" if franka else "none")
        replace = {}
        if own_cnn and self.cnn_weights == DEFAULT_CNN_WEIGHTS:
            replace["cnn_weights"] = own_cnn
        if own_hold and self.hold_weights == DEFAULT_HOLD_WEIGHTS:
            replace["hold_weights"] = None if own_hold == "none" else own_hold
        return dc.replace(self, **replace) if replace else self

    def check(self) -> None:
        """ValueError for counts under one (also for a configuration loaded from YAML)."""
        if self.blocking_voxels < 1 or self.exact_top < 1 or self.batch_size < 1:
            raise ValueError(f"selection needs blocking_voxels, exact_top and batch_size >= 1: {self}")
        if self.cnn_precision not in PRECISIONS:
            raise ValueError(f"cnn_precision must be one of {', '.join(PRECISIONS)}: '{self.cnn_precision}'")
