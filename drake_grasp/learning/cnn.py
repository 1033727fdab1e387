"""The grasp stability network (paper Sec. IV-C): a voxel 3D CNN on 32^3 grids, and its loader.

conv 32 x 5^3 -> conv 32 x 3^3 -> max-pool 2 -> dense 128 -> dense 1 (sigmoid in
the loss: BCE with logits). `first_stride=2` is the VoxNet variant, about ten
times faster on a CPU; the weights file records which one it is. A network with a
`table_channel` takes a second grid, the voxels under the table plane
(`voxels.below_plane`): its input is (N, 2, G, G, G) instead of (N, G, G, G). A network with a
`hand_channel` takes the hand's grid (`voxels.hand_grid`) as its last channel: one network for any
parallel-jaw hand, told which by its sizes.
"""

from __future__ import annotations

import copy
import threading
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn

from drake_grasp.learning.training import predict_probabilities
from drake_grasp.learning.voxels import GRID, hand_grid, stack_table_channel, voxelize
from drake_grasp.learning.weights import load_weights
from drake_grasp.robot.hand import HandSpec, default_hand
from drake_grasp.robot.paths import MODELS_DIR, model_path
from drake_grasp.robot.poses import check_cloud, check_poses

ARCH = "grasp_cnn"
# The default: trained on the paper's 8 blocks and the generated corpora (plain and long objects, in
# piles, noisy camera). PAPER_WEIGHTS: trained on the 8 blocks alone, as the paper.
DEFAULT_WEIGHTS = MODELS_DIR / "grasp_cnn_all.pt"
PAPER_WEIGHTS = MODELS_DIR / "grasp_cnn.pt"

TRACING = threading.Lock()  # torch's tracer is not thread-safe: one trace at a time in a process
DTYPES = {"float32": torch.float32, "bfloat16": torch.bfloat16}  # `GraspStabilityPredictor`'s precisions


def native_bfloat16() -> bool:
    """Whether this CPU computes in bfloat16 natively (AVX512-BF16 or AMX); elsewhere oneDNN emulates it."""
    try:
        return bool(torch.cpu._is_avx512_bf16_supported() or torch.cpu._is_amx_tile_supported())
    except AttributeError:  # (private probes: a torch without them gets float32)
        return False


def resolve_precision(precision: str) -> str:
    """"auto" as this CPU runs it fastest ("bfloat16" where native, else "float32"); ValueError names an
    unknown precision."""
    if precision == "auto":
        return "bfloat16" if native_bfloat16() else "float32"
    if precision not in DTYPES:
        raise ValueError(f"precision must be one of {', '.join([*DTYPES, 'auto'])}: '{precision}'")
    return precision


class GraspCNN(nn.Module):
    """The paper's network (Sec. IV-C): two 3D convolutions (`width` channels; 32 in the paper), a max
    pool, a hidden layer of 128, one logit. `first_stride` 2 is the VoxNet variant. Its input channels:
    the occupancy, then the table's (`table_channel`), then the hand's (`hand_channel`)."""

    def __init__(self, first_stride: int = 2, grid: int = GRID, width: int = 32, table_channel: bool = False,
                 hand_channel: bool = False):
        super().__init__()
        self.first_stride, self.grid, self.width = first_stride, grid, width
        self.table_channel, self.hand_channel = table_channel, hand_channel
        side = ((grid - 5) // first_stride + 1 - 2) // 2
        self.features = nn.Sequential(
            nn.Conv3d(self.channels, width, 5, stride=first_stride), nn.ReLU(),
            nn.Conv3d(width, width, 3), nn.ReLU(),
            nn.MaxPool3d(2), nn.Flatten(),
        )
        self.head = nn.Sequential(nn.Linear(width * side**3, 128), nn.ReLU(), nn.Linear(128, 1))

    @property
    def channels(self) -> int:
        return 1 + self.table_channel + self.hand_channel

    @property
    def input_shape(self) -> tuple[int, ...]:
        """One grid's shape: (G, G, G), or (C, G, G, G) with a table or hand channel."""
        g = (self.grid,) * 3
        return (self.channels, *g) if self.channels > 1 else g

    def forward(self, voxels: torch.Tensor) -> torch.Tensor:
        """(N, G, G, G) occupancy, or (N, C, G, G, G) with a table or hand channel (any dtype) -> (N,)
        logits."""
        x = voxels.float()
        return self.head(self.features(x if self.channels > 1 else x.unsqueeze(1))).squeeze(-1)

    def with_channels(self, table_channel: bool, hand_channel: bool) -> GraspCNN:
        """This network with the table and hand channels asked for, the new ones' first-layer weights zero:
        the same p_s as this one until it is trained (the start of a fine-tune that teaches it the table or
        the hand). ValueError when it has a channel not asked for."""
        if (self.table_channel and not table_channel) or (self.hand_channel and not hand_channel):
            raise ValueError("the network has a channel that was not asked for")
        model = GraspCNN(self.first_stride, self.grid, self.width, table_channel, hand_channel)
        w = self.state_dict()["features.0.weight"]  # (width, channels, 5, 5, 5)
        names = ["occupancy"] + ["table"] * self.table_channel + ["hand"] * self.hand_channel
        column = {name: w[:, k:k + 1] for k, name in enumerate(names)}
        wanted = ["occupancy"] + ["table"] * table_channel + ["hand"] * hand_channel
        weight = torch.cat([column.get(name, torch.zeros_like(w[:, :1])) for name in wanted], dim=1)
        model.load_state_dict({**self.state_dict(), "features.0.weight": weight})
        return model


def save_model(model: GraspCNN, path: str | Path, *, card: dict) -> None:
    torch.save({"arch": ARCH, "first_stride": model.first_stride, "grid": model.grid, "width": model.width,
                "table_channel": model.table_channel, "hand_channel": model.hand_channel,
                "state_dict": model.state_dict(), "card": card}, path)


def load_model(path: str | Path) -> tuple[GraspCNN, dict]:
    """The network and its saved record (a shipped file also by its repository name,
    `robot.paths.model_path`); ValueError names a missing or corrupt file."""
    return load_weights(model_path(path), arch=ARCH, what="grasp CNN",
                        build=lambda record: GraspCNN(int(record["first_stride"]), int(record["grid"]),
                                                      int(record.get("width", 32)),
                                                      bool(record.get("table_channel", False)),
                                                      bool(record.get("hand_channel", False))))


def predict_grids(model: GraspCNN, grids: np.ndarray, batch_size: int = 512) -> np.ndarray:
    """p_s of (N, G, G, G) occupancy grids, in batches."""
    return predict_probabilities(model, grids, batch_size)


class _InPrecision(nn.Module):
    """A network run in another precision, on float grids, to float logits. Its first convolution stays in
    float32: with one input channel it gains nothing from bfloat16 matrix units (it ran 1.7 times slower
    in bfloat16 on AMX, where the second ran 7 times faster)."""

    def __init__(self, model: GraspCNN, dtype: torch.dtype):
        super().__init__()
        self.channels, self.dtype = model.channels, dtype
        self.first = model.features[0]
        self.rest = nn.Sequential(*model.features[1:]).to(dtype)
        self.head = model.head.to(dtype)

    def forward(self, voxels: torch.Tensor) -> torch.Tensor:
        x = voxels.float()
        x = self.first(x if self.channels > 1 else x.unsqueeze(1)).to(self.dtype)
        return self.head(self.rest(x)).squeeze(-1).float()


class GraspStabilityPredictor:
    """p_s for an object cloud and a batch of grasp poses, in one call.

    >>> cnn = GraspStabilityPredictor.load()               # models/grasp_cnn_all.pt
    >>> p_s = cnn(points_W, X_WG)    # (M, 3) object cloud, (N, 4, 4) grasps -> (N,)

    `precision` "bfloat16" runs the network after its first layer in bfloat16 (oneDNN on AVX512-BF16 or
    AMX: about twice the speed of float32, p_s within 0.005 on the validation trials, AUROC unchanged; on
    a CPU without native bfloat16 it is emulated and slower); "auto" is bfloat16 where native, else
    float32; "float32", the default, is what the tables were measured with.

    A network with a hand channel is fed `hand`'s grid (`voxels.hand_grid`; None: the Franka hand's).
    """

    def __init__(self, model: GraspCNN, precision: str = "float32", hand: HandSpec | None = None):
        self.model = model.eval().to(memory_format=torch.channels_last_3d)
        self.precision = resolve_precision(precision)
        self._frozen: torch.jit.ScriptModule | None = None
        self.hand_grid = (hand_grid(hand or default_hand(), grid=model.grid)
                          if model.hand_channel else None)

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_frozen": None}  # (a frozen module does not pickle: made again on use)

    def inference_module(self) -> torch.jit.ScriptModule:
        """The network traced and frozen for inference, in channels-last layout: oneDNN fuses each
        convolution with its ReLU and pre-packs the weights: 1.6 times the eager module's speed on 500
        grids, 1.3 times channels-last alone in batches of 16, the same p_s to float rounding. Made on
        first use, one model at a time in a process (torch's tracer is not thread-safe). (torch marks
        TorchScript deprecated for `torch.compile`, which here takes about a minute a process to compile
        and runs slower.)"""
        with TRACING:
            if self._frozen is None:
                example = torch.zeros((16, *self.model.input_shape))
                module = self.model if self.precision == "float32" else \
                    _InPrecision(copy.deepcopy(self.model), DTYPES[self.precision]).eval()
                with torch.inference_mode(), warnings.catch_warnings():
                    warnings.simplefilter("ignore", DeprecationWarning)
                    traced = torch.jit.trace(module, example)
                    self._frozen = torch.jit.optimize_for_inference(torch.jit.freeze(traced))
        return self._frozen

    @classmethod
    def load(cls, path: str | Path = DEFAULT_WEIGHTS, precision: str = "float32",
             hand: HandSpec | None = None) -> GraspStabilityPredictor:
        """The CNN saved at `path` (a shipped one also by its repository name), run in `precision` (with a
        hand channel: for `hand`)."""
        return cls(load_model(path)[0], precision, hand)

    def voxelize(self, points_W: np.ndarray, X_WG: np.ndarray,
                 table: tuple[np.ndarray, float] | None = None) -> np.ndarray:
        """The network's input grids of an object cloud (M, 3) at N grasps (N, 4, 4): (N, G, G, G)
        occupancy, and with a table channel (N, 2, G, G, G), the second the voxels under `table`
        ((normal, offset) of n . p + d = 0 in the world frame; None: no table seen, an empty channel);
        with a hand channel, the hand's grid last."""
        X_WG = check_poses(X_WG)
        occupancy = voxelize(check_cloud(points_W), X_WG, grid=self.model.grid)
        grids = stack_table_channel(occupancy, X_WG, table) if self.model.table_channel else occupancy
        if self.hand_grid is None:
            return grids
        hand = np.broadcast_to(self.hand_grid, occupancy.shape)[:, None]
        return np.concatenate([grids if grids.ndim == 5 else grids[:, None], hand], axis=1)

    def predict(self, grids: np.ndarray, batch_size: int = 512) -> np.ndarray:
        """p_s of the grids `voxelize` made, `batch_size` at a time."""
        module, p_s = self.inference_module(), np.zeros(len(grids), np.float32)
        with torch.inference_mode():
            for i in range(0, len(grids), batch_size):
                batch = torch.from_numpy(grids[i:i + batch_size]).float()
                p_s[i:i + batch_size] = torch.sigmoid(module(batch))
        return p_s

    def __call__(self, points_W: np.ndarray, X_WG: np.ndarray,
                 table: tuple[np.ndarray, float] | None = None) -> np.ndarray:
        return self.predict(self.voxelize(points_W, X_WG, table))
