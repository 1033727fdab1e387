"""The scenes of a noisy-camera grasp job seen again through a perfect camera: paired clouds.

A `collect_grasps` scene is a pure function of (seed, scene id), and the camera's noise has a random
stream of its own, so the scene can be rebuilt, settled again and observed without depth noise: the
same objects where they lay, the same trials with their outcomes, and the cloud a noise-free camera
sees. The pair (noisy cloud, perfect cloud) of every trial measures what the camera alone changes in
a model's ranking, and a model can train on both.

A rebuilt scene is kept only when its objects settled where they did (the physics or the object
generator may have changed since the job ran): every point of the noise-free cloud but a few lies
within `MATCH_DISTANCE` of the stored noisy cloud (its `MATCH_PERCENTILE`-th percentile distance).
Other scenes are left out, with their trials.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d

from drake_grasp.datasets.grasp_collection import build_scene, first_objects
from drake_grasp.datasets.grasp_data import (
    LEGACY_CLOUD_FORMAT,
    decode_cloud,
    encode_cloud,
    read_grasp_manifest,
)
from drake_grasp.datasets.shards import shard_path
from drake_grasp.simulation.divergence import is_divergence
from drake_grasp.simulation.objects import load_object_set

MATCH_DISTANCE = 0.006  # [m] about four times the noise model's axial deviation at the table
MATCH_PERCENTILE = 95
SCENE_KEYS = ("scene_id", "scene_object", "scene_X_WO", "scene_cloud_origin", "scene_cloud_count",
              "scene_num_objects")  # one row a scene (`scene_num_objects`: piles only)
TRIAL_KEYS = ("trial_scene", "X_WG", "label", "outcome", "rise", "trial_sampler", "trial_object")  # a trial


def cloud_distance(points: np.ndarray, reference: np.ndarray) -> float:
    """The `MATCH_PERCENTILE`-th percentile of the distances from `points` to their nearest `reference` point
    (inf when either is empty)."""
    if len(points) == 0 or len(reference) == 0:
        return float("inf")
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    ref = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(reference, dtype=np.float64)))
    return float(np.percentile(np.asarray(cloud.compute_point_cloud_distance(ref)), MATCH_PERCENTILE))


def perfect_camera_manifest(source_manifest: dict, source: Path) -> dict:
    """The manifest of the re-rendered job: the source's, without depth noise, naming its source."""
    manifest = {k: v for k, v in source_manifest.items() if k != "depth_noise"}
    return {**manifest, "rerendered_from": str(source), "match_distance_m": MATCH_DISTANCE}


def read_source_manifest(source: Path) -> dict:
    """The source job's manifest; ValueError when it is no noisy-camera grasp job to re-render."""
    manifest = read_grasp_manifest(source)
    if not manifest.get("depth_noise"):
        raise ValueError(f"{source} was observed without depth noise: "
                         "its clouds are a perfect camera's already")
    if manifest.get("grasp_depth_offset") or manifest.get("second_camera"):
        raise ValueError(f"{source}: re-rendering handles one-camera jobs without a grasp-depth offset")
    return manifest


def rerender_shard(k: int, *, source: str) -> dict[str, np.ndarray]:
    """Shard k of the source job with every scene observed again without depth noise (see the module);
    scenes that did not settle as before are left out with their trials."""
    manifest = read_source_manifest(Path(source))
    models = first_objects(load_object_set(manifest["objects"]), manifest.get("object_subset"))
    cloud_format = manifest.get("cloud", LEGACY_CLOUD_FORMAT)
    with np.load(shard_path(Path(source), k)) as data:
        arrays = {key: data[key] for key in data.files}
    unknown = set(arrays) - set(SCENE_KEYS) - set(TRIAL_KEYS) - {"cloud_points"}
    if unknown:
        raise ValueError(f"{source} shard {k} stores {', '.join(sorted(unknown))}, which re-rendering "
                         "does not know how to carry")
    ends = np.cumsum(arrays["scene_cloud_count"])
    kept, clouds, origins = [], [], []
    for i, scene_id in enumerate(arrays["scene_id"]):
        stored = decode_cloud(arrays["cloud_points"][ends[i] - arrays["scene_cloud_count"][i]:ends[i]],
                              arrays["scene_cloud_origin"][i].astype(np.float64), cloud_format)
        _, scene, _, rng = build_scene(int(scene_id), models=models, scenario_arg=manifest["scenario"],
                                       seed=manifest["seed"])
        try:
            scene.settle(rng)
            points = scene.observe().points
        except RuntimeError as e:
            if not is_divergence(e):
                raise
            continue
        origin = points.mean(axis=0) if len(points) else np.zeros(3)
        encoded = encode_cloud(points, origin, cloud_format)
        if encoded is None or cloud_distance(points, stored) > MATCH_DISTANCE:
            continue
        kept.append(i)
        clouds.append(encoded)
        origins.append(origin)
    scene_rows = np.array(kept, dtype=np.int64)
    trial_rows = np.isin(arrays["trial_scene"], arrays["scene_id"][scene_rows])
    out = {key: (value[scene_rows] if key in SCENE_KEYS else value[trial_rows])
           for key, value in arrays.items() if key != "cloud_points"}
    out["scene_cloud_origin"] = np.array(origins, np.float32).reshape(-1, 3)
    out["scene_cloud_count"] = np.array([len(c) for c in clouds], np.int32)
    out["cloud_points"] = np.concatenate(clouds) if clouds else np.zeros((0, 3), np.int16)
    return out
