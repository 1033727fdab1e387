"""Training and evaluating the grasp stability CNN on a grasp data set (arrays in, a model out).

Grids are kept bit-packed in memory (4 KB each, so 100k grids take 400 MB) and
unpacked per batch. The hand is symmetric, so a grid flipped along x (mirror)
or y (the jaws swapped, or mirrored) shows a grasp with the same outcome:
training draws random flips of both axes. The epoch with the lowest validation
loss is kept. Whole scenes are held out: the test scenes, and among the rest
the validation scenes that choose the epoch; the training scenes are listed one
after another, so their first n grasps (the learning curve's subsets) are nested
sets of whole scenes. With `table_channel`, each grid carries the voxels under the
simulated table (its top is the world's z = 0 plane in every scenario) as a second
channel; with `hand_channel`, the grid of the hand that tried it (`voxels.hand_grid`, looked up
by the hand fingerprint its folder's manifest records) as the last.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

from drake_grasp.datasets.grasp_data import SCENE_ID_STRIDE, GraspDataset
from drake_grasp.learning.cnn import GraspCNN, load_model, predict_grids
from drake_grasp.learning.metrics import classification_metrics, per_group_metrics
from drake_grasp.learning.training import Checkpoint, TrainingConfig, fingerprint, fit, validation_scores
from drake_grasp.learning.voxels import GRID, hand_grid, stack_table_channel, voxelize
from drake_grasp.robot.hand import HandSpec, default_hand, get_hand, known_hands

HandGrids = dict[str, np.ndarray]  # a hand's fingerprint -> its `voxels.hand_grid`

VALIDATION_FRACTION = 0.05  # of the training scenes, for choosing the epoch
SIMULATED_TABLE = (np.array([0.0, 0.0, 1.0]), 0.0)  # the trials' table top: z = 0 (n . p + d = 0)


def pack(grids: np.ndarray) -> np.ndarray:
    """(N, G, G, G) or (N, C, G, G, G) uint8 occupancy -> (N, C G^3 / 8) bits."""
    return np.packbits(grids.reshape(len(grids), -1), axis=1)


def unpack(packed: np.ndarray, shape: tuple[int, ...] = (GRID,) * 3) -> np.ndarray:
    """Bits from `pack` -> (N, *shape) uint8 (`shape`: one grid's, `GraspCNN.input_shape`)."""
    return np.unpackbits(packed, axis=1, count=math.prod(shape)).reshape(-1, *shape)


def random_flips(grids: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Each grid (its channels together) flipped along x and along y, each with probability 1/2
    (index i -> G-1-i)."""
    out = grids.copy()
    fx, fy = rng.random(len(grids)) < 0.5, rng.random(len(grids)) < 0.5
    out[fx] = np.flip(out[fx], axis=-3)
    out[fy] = np.flip(out[fy], axis=-2)
    return out


def predict_packed(model: GraspCNN, packed: np.ndarray, batch_size: int = 512) -> np.ndarray:
    """p_s of packed grids (`pack`), unpacked a batch at a time."""
    return np.concatenate([predict_grids(model, unpack(packed[i:i + batch_size], model.input_shape))
                           for i in range(0, len(packed), batch_size)]) if len(packed) else np.zeros(0)


@dataclass(frozen=True)
class StabilityConfig:
    """How the stability CNN is trained: the network (`first_stride`, `width`), the optimisation and the
    augmentation. With `patience`, training stops once that many epochs in a row have not lowered the
    validation loss."""

    epochs: int = 10
    batch_size: int = 64
    lr: float = 1e-3  # Adam's rate
    seed: int = 0
    patience: int | None = None
    first_stride: int = 2  # 2: the VoxNet variant; 1: the paper's (10x slower)
    width: int = 32  # channels of the first convolution
    augment: bool = True  # random x/y flips (the hand's symmetry)
    table_channel: bool = False  # a second input channel: the voxels under the table (`voxels.below_plane`)
    hand_channel: bool = False  # a last input channel: the hand's grid (`voxels.hand_grid`)


def train_stability(packed: np.ndarray, labels: np.ndarray, *, val_packed: np.ndarray,
                    val_labels: np.ndarray, config: StabilityConfig = StabilityConfig(),
                    log: Callable[[str], None] | None = None, device: torch.device | str = "cpu",
                    checkpoint: Path | None = None, init: GraspCNN | None = None) -> tuple[GraspCNN, dict]:
    """Trains the CNN on bit-packed grids; returns the best-validation-loss model and its history.

    With `checkpoint`, an interrupted training resumes from that file; `init`: start from that
    network's weights (fine-tuning; its stride and width must be `config`'s; a network without a table
    channel starts one with zero weights, `GraspCNN.with_channels`).
    """
    c = config
    if len(labels) < 2 or len(val_labels) < 1:
        raise ValueError(f"need training and validation grasps, got {len(labels)} and {len(val_labels)}")
    torch.manual_seed(c.seed)
    rng = np.random.default_rng(c.seed)
    model = GraspCNN(c.first_stride, width=c.width, table_channel=c.table_channel,
                     hand_channel=c.hand_channel)
    if init is not None:
        if (init.first_stride, init.width) != (c.first_stride, c.width):
            raise ValueError(f"the initial weights have stride {init.first_stride} and width {init.width}, "
                             f"not {c.first_stride} and {c.width}")
        for kind, has, wanted in (("table", init.table_channel, c.table_channel),
                                  ("hand", init.hand_channel, c.hand_channel)):
            if has and not wanted:
                raise ValueError(f"the initial weights have a {kind} channel: train with one")
        model.load_state_dict(init.with_channels(c.table_channel, c.hand_channel).state_dict())
    model = model.to(device)
    y_all = torch.from_numpy(np.asarray(labels, np.float32))

    def batch(rows: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        idx = np.sort(rows)  # packed rows read in order
        grids = unpack(packed[idx], model.input_shape)
        if c.augment:
            grids = random_flips(grids, rng)
        return torch.from_numpy(np.ascontiguousarray(grids)), y_all[idx]

    def validate(m: GraspCNN) -> dict[str, float]:
        return validation_scores(val_labels, predict_packed(m, val_packed))

    run = {"model": "stability", "first_stride": c.first_stride, "width": c.width, "augment": c.augment,
           "lr": c.lr, **({"table_channel": True} if c.table_channel else {}),
           **({"hand_channel": True} if c.hand_channel else {}),
           "data": fingerprint(packed, labels, val_packed, val_labels),
           **({"init": fingerprint(*(t.cpu().numpy() for t in init.state_dict().values()))}
              if init is not None else {})}
    info = fit(model, num_samples=len(labels), batch=batch, validate=validate,
               config=TrainingConfig(epochs=c.epochs, batch_size=c.batch_size, lr=c.lr, seed=c.seed,
                                     patience=c.patience, progress=log is not None),
               rng=rng, log=log, checkpoint=None if checkpoint is None else Checkpoint(checkpoint, run))
    return model, info


def _part_hands(data: GraspDataset) -> list[tuple[str, str]]:
    """(fingerprint, name) of the hand of each folder of `data` (its manifest's; a folder that records
    none was the Franka hand's)."""
    franka = default_hand()
    return [((part.get("hand") or {}).get("fingerprint") or franka.fingerprint,
             (part.get("hand") or {}).get("name", franka.name))
            for part in data.manifest.get("parts", [data.manifest])]


def trial_hands(data: GraspDataset) -> np.ndarray:
    """(T,) the fingerprint of the hand that tried each trial (its folder's, `_part_hands`)."""
    prints = np.array([print_ for print_, _ in _part_hands(data)])
    return prints[data.trial_scene // SCENE_ID_STRIDE]


def _hand_names(data: GraspDataset) -> dict[str, str]:
    return dict(_part_hands(data))


def trial_hand_grids(datasets: Sequence[GraspDataset], hands: Sequence[HandSpec] = ()) -> HandGrids:
    """The grid of every hand that tried a trial of `datasets`, found by fingerprint among the shipped
    hands and `hands`; ValueError names a hand that is neither."""
    known = {h.fingerprint: h for h in [*(get_hand(name) for name in known_hands()), *hands]}
    grids: HandGrids = {}
    for data in datasets:
        for print_, name in _hand_names(data).items():
            if print_ not in known:
                raise ValueError(f"trials of the '{name}' hand ({print_}), neither shipped nor given: "
                                 "name its hand file with --hands")
            grids[print_] = hand_grid(known[print_])
    return grids


def trials_per_hand(data: GraspDataset) -> list[dict]:
    """Each hand that tried trials of `data`: its name, fingerprint and trial count (a model card's)."""
    names, hands = _hand_names(data), trial_hands(data)
    return [{"name": names[print_], "fingerprint": str(print_), "trials": int(count)}
            for print_, count in zip(*np.unique(hands, return_counts=True), strict=True)]


def trial_grids(data: GraspDataset, index: np.ndarray, table_channel: bool = False,
                hand_grids: HandGrids | None = None) -> np.ndarray:
    """(n, G, G, G) uint8 grids of the trials `index`, in that order, each on its scene's stored cloud;
    (n, C, G, G, G) with the table channel (the simulated table's) and, given `hand_grids`, the hand
    channel (the grid of each trial's hand). ValueError names a hand `hand_grids` lacks."""
    index = np.asarray(index)
    out = np.zeros((len(index), GRID, GRID, GRID), np.uint8)
    scenes = data.trial_scene[index]
    for scene in np.unique(scenes):
        rows = np.flatnonzero(scenes == scene)
        out[rows] = voxelize(data.clouds[int(scene)], data.X_WG[index[rows]])
    channels = [out]
    if table_channel:
        channels.append(stack_table_channel(out, data.X_WG[index], SIMULATED_TABLE)[:, 1])
    if hand_grids is not None:
        hands = trial_hands(data)[index]
        missing = sorted(set(hands) - set(hand_grids))
        if missing:
            raise ValueError(f"no hand file for the trials' hand {missing[0]}: give it with --hands")
        channels.append(np.stack([hand_grids[h] for h in hands]) if len(hands) else out.copy())
    return np.stack(channels, axis=1) if len(channels) > 1 else out


def packed_voxels(data: GraspDataset, index: np.ndarray, chunk: int = 5000, table_channel: bool = False,
                  hand_grids: HandGrids | None = None) -> np.ndarray:
    """Bit-packed grids of the trials `index` (`trial_grids`), voxelized in chunks to bound memory."""
    channels = 1 + table_channel + (hand_grids is not None)
    return np.concatenate([pack(trial_grids(data, index[i:i + chunk], table_channel, hand_grids))
                           for i in range(0, len(index), chunk)]
                          ) if len(index) else np.zeros((0, channels * GRID**3 // 8), np.uint8)


def split_indices(data: GraspDataset, *, test_fraction: float, seed: int, validation_scenes: bool = True,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(fit, validation, test) trial indices; the three share no scene.

    Fit lists whole scenes in a seeded random order, so its first n trials (the learning
    curve's subsets) are nested sets of whole scenes. Without `validation_scenes` (the
    epoch is chosen on a validation set of other objects) validation is empty.
    """
    pool, test = data.scene_split(test_fraction, seed)
    if validation_scenes:
        fit, val = data.subset(pool).scene_split(VALIDATION_FRACTION, seed + 1)
        fit, val = pool[fit], pool[val]
    else:
        fit, val = pool, np.zeros(0, np.int64)
    scenes = np.unique(data.trial_scene[fit])
    rank = np.empty(len(scenes), np.int64)
    rank[np.random.default_rng(seed).permutation(len(scenes))] = np.arange(len(scenes))
    return fit[np.argsort(rank[np.searchsorted(scenes, data.trial_scene[fit])], kind="stable")], val, test


def prepare_grids(data: GraspDataset, *, novel: GraspDataset | None, test_fraction: float, seed: int,
                  cache: dict, validation: GraspDataset | None = None, table_channel: bool = False,
                  hand_grids: HandGrids | None = None) -> dict:
    """Fills `cache` with the split and the packed grids of every part (once).

    With `validation` (trials of other objects) the epoch is chosen on it rather than on
    held-out scenes of the training objects. Grids of `novel` and `validation` already in `cache`
    are kept, so that several training sets are judged on the same held-out sets voxelized once.
    `table_channel`, `hand_grids`: the grids carry the table and the hand (`trial_grids`)."""

    def grids(part: GraspDataset, index: np.ndarray) -> np.ndarray:
        return packed_voxels(part, index, table_channel=table_channel, hand_grids=hand_grids)

    if "fit" not in cache:
        for name, part, other_name, other in (("novel", novel, "training", data),
                                              ("validation", validation, "training", data),
                                              ("validation", validation, "novel (test)", novel)):
            if part is None or other is None:
                continue
            seen = sorted(set(part.scene_object.values()) & set(other.scene_object.values()))
            if seen:
                raise ValueError(f"the {name} set holds objects of the {other_name} set "
                                 f"({', '.join(seen[:5])})")
        fit, val, test = split_indices(data, test_fraction=test_fraction, seed=seed,
                                       validation_scenes=validation is None)
        if len(fit) == 0 or len(test) == 0 or (validation is None and len(val) == 0):
            raise ValueError(f"{len(data)} grasps in {len(np.unique(data.trial_scene))} scenes are too few "
                             "to hold out validation and test scenes; collect more")
        if validation is not None and len(validation) == 0:
            raise ValueError("the validation set holds no grasps")
        if validation is None:
            cache.update(val_packed=grids(data, val), val_labels=data.label[val])
        elif "val_packed" not in cache:
            cache.update(val_packed=grids(validation, np.arange(len(validation))),
                         val_labels=validation.label)
        cache.update(fit=fit, val=val, test=test, fit_packed=grids(data, fit), test_packed=grids(data, test))
        if novel is not None and "novel_packed" not in cache:
            cache["novel_packed"] = grids(novel, np.arange(len(novel)))
    return cache


def interleaved_rows(data: GraspDataset, fit_index: np.ndarray, objects: list[str]) -> np.ndarray:
    """Positions in `fit_index` of the trials of `objects`' scenes, scenes taken from each object in turn
    (its first scene, then every object's second, ...), so that any prefix spreads over the objects."""
    scenes_of: dict[str, list[int]] = {name: [] for name in objects}
    for scene in dict.fromkeys(int(s) for s in data.trial_scene[fit_index]):  # fit's scene order
        name = data.scene_object[scene]
        if name in scenes_of:
            scenes_of[name].append(scene)
    turn = [scenes[i] for i in range(max(map(len, scenes_of.values()), default=0))
            for scenes in scenes_of.values() if i < len(scenes)]
    position = {scene: k for k, scene in enumerate(turn)}
    rows = np.flatnonzero([int(s) in position for s in data.trial_scene[fit_index]])
    return rows[np.argsort([position[int(s)] for s in data.trial_scene[fit_index[rows]]], kind="stable")]


def fit_and_evaluate(data: GraspDataset, *, config: StabilityConfig = StabilityConfig(),
                     test_fraction: float = 0.1, novel: GraspDataset | None = None,
                     validation: GraspDataset | None = None, limit: int | None = None,
                     objects: list[str] | None = None, min_samples_seen: int = 0, cache: dict | None = None,
                     log: Callable[[str], None] | None = None, device: torch.device | str = "cpu",
                     checkpoint: Path | None = None, init: GraspCNN | None = None,
                     hand_grids: HandGrids | None = None) -> tuple[GraspCNN, dict]:
    """Trains on the first `limit` training grasps (of scenes of `objects` only, if given); returns the
    model and its metrics. `test_fraction` of the scenes (seeded by `config.seed`) are held out.

    `cache` (a dict the caller keeps) holds the packed grids between calls; a subset
    trains for more than `config.epochs` when that is what it takes to see `min_samples_seen`;
    `checkpoint` makes the training resumable; `init` as `train_stability`; `hand_grids` (every trial's
    hand's) with `config.hand_channel`.
    """
    seed = config.seed
    cache = prepare_grids(data, novel=novel, test_fraction=test_fraction, seed=seed,
                          cache={} if cache is None else cache, validation=validation,
                          table_channel=config.table_channel,
                          hand_grids=hand_grids if config.hand_channel else None)
    # Positions in the fit list (whole scenes in order): a slice, which copies nothing, unless objects
    # are chosen.
    rows: slice | np.ndarray = slice(0, len(cache["fit"]) if limit is None else min(limit, len(cache["fit"])))
    if objects is not None:
        rows = interleaved_rows(data, cache["fit"], objects)[:limit]
    n = len(cache["fit"][rows])
    if n == 0:
        raise ValueError("no training grasps on the chosen objects")
    fit_labels = data.label[cache["fit"][rows]]
    epochs_here = max(config.epochs, math.ceil(min_samples_seen / max(n, 1)))
    model, info = train_stability(cache["fit_packed"][rows], fit_labels, val_packed=cache["val_packed"],
                                  val_labels=cache["val_labels"], config=replace(config, epochs=epochs_here),
                                  log=log, device=device, checkpoint=checkpoint, init=init)
    result = {"train_grasps": int(n), "epochs": len(info["history"]), "best_epoch": info["best_epoch"],
              "fit_seconds": info["fit_seconds"],
              **evaluate(model, data, novel=novel, cache=cache, rows=rows), "history": info["history"]}
    if objects is not None:
        scenes = data.trial_scene[cache["fit"][rows]]
        result["train_objects"] = len({data.scene_object[int(s)] for s in scenes})
    return model, result


def evaluate(model: GraspCNN, data: GraspDataset, *, novel: GraspDataset | None, cache: dict,
             rows: slice | np.ndarray, train_metrics: dict | None = None) -> dict:
    """Metrics of a model trained on the fit grasps at positions `rows`: training, held-out scenes, novel.

    `train_metrics` already known (the shipped model's card) are taken as they are.
    """
    if train_metrics is None:
        train_metrics = classification_metrics(data.label[cache["fit"][rows]],
                                               predict_packed(model, cache["fit_packed"][rows]))
    result = {
        "validation_grasps": int(len(cache["val_labels"])), "test_grasps": int(len(cache["test"])),
        "test_scenes": int(len(np.unique(data.trial_scene[cache["test"]]))),
        "train_metrics": train_metrics,
        "validation_metrics": classification_metrics(cache["val_labels"],
                                                     predict_packed(model, cache["val_packed"])),
        "test_metrics": classification_metrics(data.label[cache["test"]],
                                               predict_packed(model, cache["test_packed"])),
    }
    if novel is not None:
        p_novel = predict_packed(model, cache["novel_packed"])
        result["novel_metrics"] = classification_metrics(novel.label, p_novel)
        result["novel_per_object"] = per_group_metrics(novel.label, p_novel, novel.trial_objects())
        if "parts" in novel.manifest:  # several held-out folders: each one's metrics too
            result["novel_per_set"] = per_group_metrics(novel.label, p_novel, novel.part_names())
    return result


def split_scene_ids(data: GraspDataset, cache: dict) -> dict[str, list[int]]:
    """The scenes held out for validation and testing (recorded in the model card)."""
    return {part: sorted(int(k) for k in np.unique(data.trial_scene[cache[key]]))
            for part, key in (("validation", "val"), ("test", "test"))}


def checked_full_model(path: Path, data: GraspDataset, *, cache: dict, first_stride: int,
                       ) -> tuple[GraspCNN, dict]:
    """Weights `train stability` made on all of this split's training grasps, and their card.

    ValueError when they were trained on another split, subset or architecture.
    """
    model, record = load_model(path)
    card = record.get("card", {})
    if card.get("split") != split_scene_ids(data, cache) or card.get("train_grasps") != len(cache["fit"]):
        raise ValueError(f"{path} was not trained on all training scenes of this split (another data "
                         "set, seed, test fraction or --limit): retrain it or leave out --full-model")
    if model.first_stride != first_stride:
        raise ValueError(f"{path} has first stride {model.first_stride}, the curve {first_stride}")
    return model, card


