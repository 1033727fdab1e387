"""The grasp-stability data set on disk (`collect_grasps` shards), and its voxel grids on the fly.

Clouds are stored once per scene (int16 steps about the scene's cloud centre, in
the job's `CLOUD_FORMATS`) and trials refer to their scene, so a 100k-trial set
stays a few MB; `GraspDataset.voxels` regenerates the 32^3 grids of any trials with
the one batched `voxelize` that selection uses.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drake_grasp.datasets.shards import MANIFEST, load_shards, shard_files, shard_ranges
from drake_grasp.robot.poses import homogeneous
from drake_grasp.robot.task import OUTCOME_TEXT, SAMPLERS, TrialOutcome

CLOUD_FORMATS = {  # name -> (unit [m], delta-coded): how a job stores its clouds (its manifest's "cloud")
    # each point in 0.1 mm steps
    "points_0.1mm": (1e-4, False),
    # 0.5 mm steps (a sixth of the CNN's 3.1 mm voxel; depth noise is about 1.5 mm), each point stored as
    # its step from the one before in the camera's pixel order: half the bytes once compressed
    "delta_0.5mm": (5e-4, True),
}
CLOUD_FORMAT = "delta_0.5mm"  # of new collections
OBJECT_SET_KEY = "object_names"
SCENE_ID_STRIDE = 10_000_000  # several folders as one: the k-th folder's scene ids are offset by k x this


@dataclass
class GraspDataset:
    """Trials (X_WG, label, outcome, scene) and the object cloud of every scene."""

    X_WG: np.ndarray  # (T, 4, 4)
    label: np.ndarray  # (T,) uint8
    outcome: np.ndarray  # (T,) uint8, TrialOutcome codes
    trial_scene: np.ndarray  # (T,) scene id of each trial
    trial_sampler: np.ndarray  # (T,) uint8: which sampler made each candidate (index in SAMPLERS)
    scene_object: dict[int, str]  # scene id -> object name
    clouds: dict[int, np.ndarray]  # scene id -> (M, 3) world-frame object cloud
    manifest: dict

    def __len__(self) -> int:
        return len(self.label)

    def subset(self, index: np.ndarray) -> GraspDataset:
        return GraspDataset(self.X_WG[index], self.label[index], self.outcome[index],
                            self.trial_scene[index], self.trial_sampler[index], self.scene_object,
                            self.clouds, self.manifest)

    def made_by(self, sampler: str) -> np.ndarray:
        """Indices of the trials whose candidate `sampler` made (`gpg`: GPD's generator, ...)."""
        return np.flatnonzero(self.trial_sampler == SAMPLERS.index(sampler))

    def scene_split(self, test_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """Trial indices (train, test), split by scene: no test trial shares a scene with training.

        Each scene's side is drawn from (seed, scene id) alone, so a scene stays on its side
        as the data set grows; when the draw leaves a side empty, the scene drawn closest to
        the boundary moves over.
        """
        scenes = np.unique(self.trial_scene)
        if len(scenes) < 2:
            raise ValueError(f"{len(self)} grasps in {len(scenes)} scene(s) are too few to hold out "
                             "whole scenes; collect more")
        u = np.array([np.random.default_rng([seed, int(scene)]).random() for scene in scenes])
        is_test_scene = u < test_fraction
        if not is_test_scene.any():
            is_test_scene[np.argmin(u)] = True
        elif is_test_scene.all():
            is_test_scene[np.argmax(u)] = False
        is_test = np.isin(self.trial_scene, scenes[is_test_scene])
        return np.flatnonzero(~is_test), np.flatnonzero(is_test)

    def part_names(self) -> np.ndarray:
        """(T,) the folder each trial came from (`load_grasp_datasets`): its manifest's `folder`."""
        parts = self.manifest.get("parts", [self.manifest])
        names = np.array([str(p.get("folder", "")) for p in parts])
        return names[self.trial_scene // SCENE_ID_STRIDE]

    def trial_objects(self) -> np.ndarray:
        """(T,) the name of each trial's object (its scene's)."""
        return np.array([self.scene_object[int(s)] for s in self.trial_scene])

    def camera_positions(self, scene: int) -> tuple[tuple[float, float, float], ...] | None:
        """Where the cameras that saw `scene` stood (world frame) as its job recorded them (a
        `--second-camera` job does); None: the scenarios' one camera."""
        parts = self.manifest.get("parts", [self.manifest])
        recorded = parts[scene // SCENE_ID_STRIDE].get("camera_positions")
        return None if recorded is None else tuple(tuple(float(v) for v in p) for p in recorded)

    def statistics(self) -> dict:
        """Trials, positive rate, trials and successes per sampler, and outcome counts per object."""
        per_object: dict[str, Counter] = {}
        for scene, outcome in zip(self.trial_scene, self.outcome, strict=True):
            per_object.setdefault(self.scene_object[int(scene)], Counter())[int(outcome)] += 1
        samplers = {SAMPLERS[code]: int(code) for code in np.unique(self.trial_sampler)}
        return {
            "trials": len(self), "scenes": len(np.unique(self.trial_scene)),
            "positive_rate": float(self.label.mean()) if len(self) else float("nan"),
            "samplers": {name: {"trials": int((self.trial_sampler == code).sum()),
                                "success": int(self.label[self.trial_sampler == code].sum())}
                         for name, code in samplers.items()},
            "outcomes": {OUTCOME_TEXT[TrialOutcome(c)]: int((self.outcome == c).sum()) for c in TrialOutcome},
            "per_object": {name: {"trials": sum(c.values()),
                                  **{OUTCOME_TEXT[TrialOutcome(o)]: n for o, n in sorted(c.items())}}
                           for name, c in sorted(per_object.items())},
        }


def encode_cloud(points: np.ndarray, origin: np.ndarray, cloud_format: str) -> np.ndarray | None:
    """(M, 3) int16 of a cloud about `origin`, as `cloud_format` stores it; None when it does not fit."""
    unit, delta = CLOUD_FORMATS[cloud_format]
    steps = np.round((np.asarray(points) - origin) / unit)
    if delta:
        steps = np.diff(steps, axis=0, prepend=np.zeros((1, 3)))
    if len(steps) and np.abs(steps).max() > np.iinfo(np.int16).max:
        return None
    return steps.astype(np.int16)


def decode_cloud(stored: np.ndarray, origin: np.ndarray, cloud_format: str) -> np.ndarray:
    """The (M, 3) world-frame cloud `encode_cloud` stored (to its format's unit)."""
    unit, delta = CLOUD_FORMATS[cloud_format]
    steps = stored.astype(np.float64)
    if delta:
        steps = np.cumsum(steps, axis=0)
    return steps * unit + origin


def read_grasp_manifest(folder: Path) -> dict:
    """The manifest of a `collect_grasps` folder; ValueError names a folder that is not one."""
    folder = Path(folder)
    try:
        manifest = json.loads((folder / MANIFEST).read_text())
    except FileNotFoundError:
        raise ValueError(f"{folder} is not a collect_grasps folder (no {MANIFEST})") from None
    except json.JSONDecodeError:
        raise ValueError(f"corrupt {folder / MANIFEST}") from None
    if manifest.get("kind") != "grasps":
        raise ValueError(f"{folder} holds '{manifest.get('kind')}' data, not grasp trials")
    return manifest


def load_grasp_dataset(folder: Path) -> GraspDataset:
    """Reads a `collect_grasps` folder; ValueError names a folder that is not one."""
    folder = Path(folder)
    manifest = read_grasp_manifest(folder)
    if manifest.get("sampler") not in SAMPLERS:
        raise ValueError(f"{folder}: unknown sampler '{manifest.get('sampler')}'")
    files = shard_files(folder)  # (listed once: what was read is what the card names)
    data = load_shards(folder, files=files)
    names = manifest[OBJECT_SET_KEY]
    ends = np.cumsum(data["scene_cloud_count"])
    starts = ends - data["scene_cloud_count"]
    cloud_format = manifest.get("cloud")
    if cloud_format not in CLOUD_FORMATS:
        raise ValueError(f"{folder}: unknown cloud format '{cloud_format}'")
    clouds, scene_object = {}, {}
    for i, scene in enumerate(data["scene_id"]):
        clouds[int(scene)] = decode_cloud(data["cloud_points"][starts[i]:ends[i]],
                                          data["scene_cloud_origin"][i].astype(np.float64), cloud_format)
        scene_object[int(scene)] = names[int(data["scene_object"][i])]
    # What was read, for a model card: a folder still being collected into grows.
    loaded = {"shards": shard_ranges(files), "trials": int(len(data["label"]))}
    return GraspDataset(homogeneous(data["X_WG"]), data["label"], data["outcome"], data["trial_scene"],
                        data["trial_sampler"], scene_object, clouds,
                        {"folder": str(folder), **manifest, "loaded": loaded})


def load_grasp_datasets(folders: Sequence[Path], one_hand: bool = True) -> GraspDataset:
    """Several `collect_grasps` folders as one data set (one folder: that folder).

    The k-th folder's scene ids are offset by k x `SCENE_ID_STRIDE`, so the first keeps its
    ids and with them its scene split; the manifest lists the folders' manifests under `parts`, the
    hand they share under `hand` (with `one_hand`, folders made with different hands are refused;
    without, `hand` is the first folder's and each part keeps its own).
    """
    if not folders:
        raise ValueError("no collect_grasps folder given")
    sets = [load_grasp_dataset(folder) for folder in folders]
    if len(sets) == 1:
        return sets[0]
    hands = {json.dumps(d.manifest.get("hand"), sort_keys=True): folder for folder, d in zip(folders, sets,
                                                                                           strict=True)}
    if one_hand and len(hands) > 1:
        raise ValueError(f"the trials were made with different hands ({', '.join(map(str, hands.values()))} "
                         "differ): train on one hand's trials")
    for folder, data in zip(folders, sets, strict=True):
        if len(data.clouds) and max(data.clouds) >= SCENE_ID_STRIDE:
            raise ValueError(f"{folder} has scene ids of {SCENE_ID_STRIDE:,} or more; it cannot be combined")
    shifted = [(k * SCENE_ID_STRIDE, d) for k, d in enumerate(sets)]
    return GraspDataset(
        np.concatenate([d.X_WG for d in sets]), np.concatenate([d.label for d in sets]),
        np.concatenate([d.outcome for d in sets]),
        np.concatenate([d.trial_scene.astype(np.int64) + o for o, d in shifted]),
        np.concatenate([d.trial_sampler for d in sets]),
        {scene + o: name for o, d in shifted for scene, name in d.scene_object.items()},
        {scene + o: cloud for o, d in shifted for scene, cloud in d.clouds.items()},
        {"kind": "grasps", "hand": sets[0].manifest.get("hand"), "parts": [d.manifest for d in sets]})
