"""The Reachability Predictor (paper Sec. IV-C): an MLP on the determinant a, its training and its loader."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch import nn

from drake_grasp.learning.reachability_features import FEATURES, reachability_features
from drake_grasp.learning.training import TrainingConfig, fit, predict_probabilities
from drake_grasp.learning.weights import load_weights
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.paths import MODELS_DIR
from drake_grasp.robot.poses import check_poses
from drake_grasp.robot.specs import RobotSpec

ARCH = "reachability_mlp"


class ReachabilityMLP(nn.Module):
    """inputs -> hidden... -> 1 with ReLU, inputs normalized by stored statistics; outputs logits."""

    def __init__(self, hidden: tuple[int, ...] = (16, 8), features: str = "paper"):
        super().__init__()
        self.hidden, self.features = tuple(hidden), features
        inputs = FEATURES[features]
        sizes = (inputs, *self.hidden)
        layers: list[nn.Module] = []
        for a, b in zip(sizes, sizes[1:], strict=False):
            layers += [nn.Linear(a, b), nn.ReLU()]
        layers.append(nn.Linear(sizes[-1], 1))
        self.net = nn.Sequential(*layers)
        self.register_buffer("input_mean", torch.zeros(inputs))
        self.register_buffer("input_std", torch.ones(inputs))

    def forward(self, a: torch.Tensor) -> torch.Tensor:
        return self.net((a - self.input_mean) / self.input_std).squeeze(-1)


class ReachabilityEnsemble(nn.Module):
    """Several `ReachabilityMLP`s of one shape, trained alike from other seeds; outputs their mean logit."""

    def __init__(self, members: int, hidden: tuple[int, ...], features: str):
        super().__init__()
        self.hidden, self.features = tuple(hidden), features
        self.members = nn.ModuleList(ReachabilityMLP(hidden, features) for _ in range(members))

    def forward(self, a: torch.Tensor) -> torch.Tensor:
        return torch.stack([member(a) for member in self.members]).mean(0)


RPModel = ReachabilityMLP | ReachabilityEnsemble


def num_members(model: RPModel) -> int:
    return len(model.members) if isinstance(model, ReachabilityEnsemble) else 1


def save_model(model: RPModel, path, *, robot: str, card: dict) -> None:
    torch.save({"arch": ARCH, "hidden": list(model.hidden), "features": model.features, "robot": robot,
                "members": num_members(model), "state_dict": model.state_dict(), "card": card}, path)


def _build(record: dict) -> RPModel:
    hidden, features = tuple(record["hidden"]), record.get("features", "paper")
    members = int(record.get("members", 1))
    if members > 1:
        return ReachabilityEnsemble(members, hidden, features)
    return ReachabilityMLP(hidden, features)


def load_model(path) -> tuple[RPModel, dict]:
    """The model (one MLP, or an ensemble of them) and its saved record; ValueError names a missing or
    corrupt file."""
    return load_weights(path, arch=ARCH, what="reachability", build=_build)


def validation_split(n: int, rng: np.random.Generator, fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """(validation rows, fit rows) of n labels: a permutation from `rng`, its first `fraction` held out."""
    order = rng.permutation(n)
    n_val = max(1, int(fraction * n))
    return order[:n_val], order[n_val:]


def predict(model: RPModel, a: np.ndarray) -> np.ndarray:
    """p_r of (N, inputs) RP features, in one pass (the MLP is small: 100,000 poses take milliseconds)."""
    return predict_probabilities(model, np.asarray(a, np.float32), batch_size=max(len(a), 1))


def train_reachability(a: np.ndarray, labels: np.ndarray, *, hidden: tuple[int, ...] = (16, 8),
                       features: str = "paper", epochs: int = 60, batch_size: int = 256, lr: float = 3e-3,
                       seed: int = 0, validation_fraction: float = 0.1, split_seed: int | None = None,
                       log: Callable[[str], None] | None = None) -> tuple[ReachabilityMLP, dict]:
    """Trains an MLP on (N, inputs) RP features (cosine learning rate); keeps the best validation epoch.
    The validation rows are drawn from `split_seed` (default `seed`)."""
    if len(a) < 20:
        raise ValueError(f"need at least 20 labels to train, got {len(a)}")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    val, fit_index = validation_split(len(a), rng, validation_fraction)
    if split_seed is not None and split_seed != seed:
        val, fit_index = validation_split(len(a), np.random.default_rng(split_seed), validation_fraction)
    x = torch.from_numpy(np.asarray(a, np.float32))
    y = torch.from_numpy(np.asarray(labels, np.float32))
    model = ReachabilityMLP(hidden, features)
    model.input_mean.copy_(x[fit_index].mean(0))
    model.input_std.copy_(x[fit_index].std(0).clamp_min(1e-6))
    loss_fn = nn.BCEWithLogitsLoss()

    def batch(rows: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        idx = torch.from_numpy(fit_index[rows])
        return x[idx], y[idx]

    def validate(m: ReachabilityMLP) -> dict[str, float]:
        logits = m(x[val])
        return {"val_loss": float(loss_fn(logits, y[val])),
                "val_accuracy": float(((logits > 0).float() == y[val]).float().mean())}

    info = fit(model, num_samples=len(fit_index), batch=batch, validate=validate,
               config=TrainingConfig(epochs=epochs, batch_size=batch_size, lr=lr, seed=seed, cosine_lr=True),
               rng=rng, log=log)
    return model, info


def train_ensemble(a: np.ndarray, labels: np.ndarray, *, members: int, seed: int = 0,
                   validation_fraction: float = 0.1, log: Callable[[str], None] | None = None,
                   **options) -> tuple[RPModel, dict]:
    """`members` MLPs (`train_reachability` with seeds seed, seed + 1, ...) on the same fit and validation
    rows (those of `seed`); one member is a plain MLP. Returns the model and {members' infos, the
    model's validation loss and accuracy}."""
    models, infos = [], []
    for m in range(members):
        model, info = train_reachability(a, labels, seed=seed + m, split_seed=seed,
                                         validation_fraction=validation_fraction, log=log, **options)
        models.append(model)
        infos.append(info)
        if log is not None:
            log(f"member {m + 1} of {members}: best epoch {info['best_epoch']}")
    if members == 1:
        ensemble = models[0]
    else:
        ensemble = ReachabilityEnsemble(members, models[0].hidden, models[0].features)
        for slot, model in zip(ensemble.members, models, strict=True):
            slot.load_state_dict(model.state_dict())
        ensemble.eval()
    val, _ = validation_split(len(a), np.random.default_rng(seed), validation_fraction)
    with torch.no_grad():
        logits = ensemble(torch.from_numpy(np.asarray(a[val], np.float32)))
    y = torch.from_numpy(np.asarray(labels[val], np.float32))
    validation = {"val_loss": float(nn.functional.binary_cross_entropy_with_logits(logits, y)),
                  "val_accuracy": float(((logits > 0).float() == y).float().mean())}
    return ensemble, {"members": infos, "validation": validation}


def calibrate_stop_threshold(p_r: np.ndarray, labels: np.ndarray, max_missed: float = 0.01) -> dict:
    """The p_r below which a grasp is not worth planning, from held-out labels.

    The threshold below which only `max_missed` of the held-out poses that planned
    lie (the `max_missed` quantile of their p_r). The closed loop ends a run with
    "nothing reachable" when none of its candidates reaches it: for an object that
    any of them could reach, that is unlikely.
    """
    p_r, labels = np.asarray(p_r, dtype=float), np.asarray(labels).astype(bool)
    if not labels.any():
        raise ValueError("no held-out pose planned: the stop threshold cannot be calibrated")
    threshold = float(np.quantile(p_r[labels], max_missed))
    below = p_r < threshold
    return {"threshold": threshold, "max_missed": max_missed, "poses_below": int(below.sum()),
            "planned_below": int((below & labels).sum()), "unplannable_below": int((below & ~labels).sum()),
            "unplannable": int((~labels).sum())}


class ReachabilityPredictor:
    """p_r for a batch of grasps in one vectorized call.

    >>> rp = ReachabilityPredictor.load("panda")          # shipped weights
    >>> p_r = rp(X_WG)          # (N, 4, 4) grasp poses, or (N, 6) determinants
    """

    def __init__(self, model: RPModel, robot: str, stop_threshold: float = 0.0):
        self.model, self.robot = model, robot
        self.stop_threshold = stop_threshold  # no candidate reaches it: nothing reachable (0: none)

    @classmethod
    def load(cls, robot_or_path: str) -> ReachabilityPredictor:
        """From a weights file, or an arm's: a built-in arm's shipped weights, an arm YAML's own."""
        path = Path(robot_or_path)
        if path.suffix not in (".pt", ".pth"):
            path = arm_weights(robot_or_path)
        model, record = load_model(path)
        stop = record.get("card", {}).get("stop_threshold", {}).get("threshold", 0.0)
        return cls(model, record["robot"], float(stop))

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        poses = np.asarray(poses, dtype=np.float64)
        if poses.ndim == 2 and poses.shape[1] == 6:
            if self.model.features != "paper":
                raise ValueError(f"this RP uses '{self.model.features}' features: pass (N, 4, 4) grasp poses")
            if not np.isfinite(poses).all():
                raise ValueError("grasp poses contain NaN or infinite values")
            a = poses
        elif poses.ndim == 3:
            a = reachability_features(check_poses(poses), self.model.features)
        else:
            raise ValueError(f"expected (N, 4, 4) grasp poses or (N, 6) determinants, got {poses.shape}")
        return predict(self.model, a)


def rp_weights(robot: RobotSpec) -> Path:
    """The RP weights of an arm with the hand it carries: the arm's own (`arm_weights`) with the hand its
    file names; with another, `reachability_<arm>_<hand>.pt` beside them (ValueError when there is none)."""
    own = get_robot(robot.source or robot.name)
    if own.hand.fingerprint == robot.hand.fingerprint:
        return arm_weights(robot.source or robot.name)
    default = Path(own.reachability_weights or MODELS_DIR / f"reachability_{own.name}.pt")
    path = default.with_name(f"reachability_{own.name}_{robot.hand.name}.pt")
    if not path.exists():
        raise ValueError(f"no reachability predictor for arm '{own.name}' with the '{robot.hand.name}' hand "
                         f"at {path}: collect and train one (collect_reachability --hand, then train "
                         "reachability --hand)")
    return path


def arm_weights(robot_name_or_yaml: str) -> Path:
    """The RP weights file of an arm: a built-in arm's shipped one, an arm YAML's own."""
    robot = get_robot(robot_name_or_yaml)
    path = Path(robot.reachability_weights or MODELS_DIR / f"reachability_{robot.name}.pt")
    if not path.exists():
        raise ValueError(f"no reachability predictor for arm '{robot.name}' at {path}: collect and "
                         "train one (collect_reachability, then train reachability)")
    return path
