"""Grasp-stability trials at scale: one shard of a `collect_grasps` job.

Per scene: one object of the set dropped at a random pose (scenario `single`),
the depth camera's view turned into the object cloud by the closed loop's
perception, M candidates sampled over the scenario's approach cone, and each
candidate tried by the floating hand in physics (`simulation.grasp_trial`).
Stored compactly: per scene the object, its settled pose and its cloud (integers
in `CLOUD_UNIT` steps), per trial the scene, X_WG, label, outcome and rise.
Scene j is a pure function of (seed, j).
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np

from drake_grasp.datasets.grasp_data import CLOUD_UNIT
from drake_grasp.policy.sampling import sample_grasps
from drake_grasp.simulation.grasp_trial import GraspTrialScene
from drake_grasp.simulation.objects import ObjectModel, load_object_set
from drake_grasp.simulation.scenario import load_scenario


def scene_trials(scene_id: int, *, models: list[ObjectModel], scenario_arg: str, seed: int,
                 per_scene: int, depth_noise: bool = False) -> dict[str, np.ndarray]:
    """One scene: objects settled on the table, observed, and `per_scene` grasps tried.

    A one-object scenario (`single`) drops one object drawn from the set; a scenario of N
    objects (`pile`) drops between 1 and N, drawn with replacement, in its clusters.
    """
    scenario = load_scenario(scenario_arg)
    if depth_noise:  # (else as the scenario file says)
        scenario = scenario.with_depth_noise()
    rng = np.random.default_rng([seed, scene_id])
    pile = scenario.num_objects > 1
    if pile:  # 1 to N objects, in the first cluster
        count = int(rng.integers(1, scenario.num_objects + 1))
        scenario = dc.replace(scenario, clusters=[dc.replace(scenario.clusters[0], count=count)])
        chosen = [int(i) for i in rng.integers(len(models), size=count)]
    else:
        chosen = [int(rng.integers(len(models)))]
    scene = GraspTrialScene(scenario, [models[i] for i in chosen], noise_seed=seed * 1_000_003 + scene_id)
    scene.settle(rng)
    cloud = scene.observe()
    X_WO = scene.object_pose().GetAsMatrix34()
    origin = cloud.points.mean(axis=0) if len(cloud) else np.zeros(3)
    quantized = np.round((cloud.points - origin) / CLOUD_UNIT)
    if len(cloud) == 0 or np.abs(quantized).max() > np.iinfo(np.int16).max:
        # The object left the camera's view (rolled off) or is too large to store: no trials.
        X_WG, results = np.zeros((0, 4, 4)), []
        quantized = np.zeros((0, 3))
    else:
        X_WG = sample_grasps(cloud.points, per_scene, tuple(scenario.gamma_deg), rng)
        results = [scene.run(X) for X in X_WG]
    arrays = {
        "scene_id": np.array([scene_id], np.int32),
        "scene_object": np.array([chosen[0]], np.int16),  # a pile's first object
        "scene_X_WO": X_WO[None].astype(np.float32),
        "scene_cloud_origin": origin[None].astype(np.float32),
        "scene_cloud_count": np.array([len(quantized)], np.int32),
        "cloud_points": quantized.astype(np.int16),
        "trial_scene": np.full(len(results), scene_id, np.int32),
        "X_WG": X_WG[:, :3, :].astype(np.float32),
        "label": np.array([r.success for r in results], np.uint8),
        "outcome": np.array([int(r.outcome) for r in results], np.uint8),
        "rise": np.array([r.rise for r in results], np.float16),
    }
    if pile:  # (only then: one-object data sets keep their format)
        arrays["scene_num_objects"] = np.array([len(chosen)], np.int16)
        arrays["trial_object"] = np.array([chosen[r.object_index] for r in results], np.int16)  # judged
    return arrays


def grasp_shard(k: int, *, objects: str, scenario: str, seed: int, scenes: int, scenes_per_shard: int,
                per_scene: int, depth_noise: bool = False) -> dict[str, np.ndarray]:
    """Shard k: scenes [k * scenes_per_shard, ...), each a pure function of (seed, scene id)."""
    models = load_object_set(objects)
    first = k * scenes_per_shard
    parts = [scene_trials(j, models=models, scenario_arg=scenario, seed=seed, per_scene=per_scene,
                          depth_noise=depth_noise)
             for j in range(first, min(first + scenes_per_shard, scenes))]
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
