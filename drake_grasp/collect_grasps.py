"""Self-supervised grasp-stability data: physics trials of sampled grasps on single objects.

Per scene: one object of the set dropped at a random pose (scenario `single`),
the depth camera's view turned into the object cloud by the closed loop's
perception, M candidates sampled over the full top hemisphere (gamma in
[0, 90] degrees, roll uniform), and each candidate tried by the floating hand in
physics (`drake_grasp.grasp_trials`): approach from the pre-grasp, close at 20 N
per finger, lift. Label 1 when the object ends 15 cm higher and held.

Stored compactly: per scene the object, its settled pose and its cloud (0.1 mm
integers), per trial the scene, X_WG, label, outcome and rise; the 32^3 voxel
grids are regenerated on the fly (`drake_grasp.grasp_data`). Writes resumable
shards to --out: rerunning the same command continues where it stopped, a
larger --trials extends the set, and Ctrl-C loses only the shards in flight.
"""

from __future__ import annotations

import argparse
import functools
import math
import sys
from pathlib import Path

import numpy as np

from drake_grasp.cli import fail, non_negative_int, positive_int, quiet_drake
from drake_grasp.grasp_data import CLOUD_UNIT, OBJECT_SET_KEY
from drake_grasp.grasp_trials import OUTCOME_TEXT, GraspTrialScene
from drake_grasp.objects import ObjectModel, load_object_set
from drake_grasp.sampling import sample_grasps
from drake_grasp.scenario import load_scenario
from drake_grasp.shards import drop_short_shards, run_shards, write_manifest


def scene_trials(scene_id: int, *, models: list[ObjectModel], scenario_arg: str, seed: int,
                 per_scene: int) -> dict[str, np.ndarray]:
    """One scene: a random object settled on the table, observed, and `per_scene` grasps tried."""
    scenario = load_scenario(scenario_arg)
    rng = np.random.default_rng([seed, scene_id])
    k = int(rng.integers(len(models)))
    scene = GraspTrialScene(scenario, models[k])
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
    return {
        "scene_id": np.array([scene_id], np.int32),
        "scene_object": np.array([k], np.int16),
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


def grasp_shard(k: int, *, objects: str, scenario: str, seed: int, scenes: int, scenes_per_shard: int,
                per_scene: int) -> dict[str, np.ndarray]:
    """Shard k: scenes [k * scenes_per_shard, ...), each a pure function of (seed, scene id)."""
    quiet_drake()
    models = load_object_set(objects)
    first = k * scenes_per_shard
    parts = [scene_trials(j, models=models, scenario_arg=scenario, seed=seed, per_scene=per_scene)
             for j in range(first, min(first + scenes_per_shard, scenes))]
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.collect_grasps", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--objects", default="primitives",
                        help="object set: 'primitives', 'novel' or a folder of SDF/URDF/OBJ files")
    parser.add_argument("--trials", type=positive_int, required=True,
                        help="grasp trials to run (scenes = trials / --per-scene, rounded up)")
    parser.add_argument("--out", type=Path, required=True, help="folder of the shards")
    parser.add_argument("--seed", type=non_negative_int, default=0)
    parser.add_argument("--per-scene", type=positive_int, default=100, help="candidates tried per scene")
    parser.add_argument("--scenes-per-shard", type=positive_int, default=5)
    parser.add_argument("--scenario", default="single", help="scene layout (default: single)")
    parser.add_argument("--workers", type=positive_int, default=None, help="default: one per core")
    parser.add_argument("--ray-address", default=None,
                        help="run on a Ray cluster ('auto', 'ray://host:10001') instead of local workers")
    args = parser.parse_args(argv)
    quiet_drake()
    try:
        models = load_object_set(args.objects)
        scenario = load_scenario(args.scenario)
        if scenario.num_objects != 1:
            raise ValueError(f"scenario '{scenario.name}' drops {scenario.num_objects} objects; "
                             "stability trials need a one-object scenario such as 'single'")
        scenes = math.ceil(args.trials / args.per_scene)
        job = dict(objects=args.objects, scenario=args.scenario, seed=args.seed, scenes=scenes,
                   scenes_per_shard=args.scenes_per_shard, per_scene=args.per_scene)
        write_manifest(args.out, {"kind": "grasps", **job, OBJECT_SET_KEY: [m.name for m in models],
                                  "outcome_codes": {str(int(c)): t for c, t in OUTCOME_TEXT.items()}},
                       size_key="scenes")
        num_shards = math.ceil(scenes / args.scenes_per_shard)
        drop_short_shards(args.out, lambda k: min(args.scenes_per_shard, scenes - k * args.scenes_per_shard),
                          "scene_id")
        print(f"{args.trials} trials: {scenes} scenes of {args.per_scene} grasps on "
              f"{len(models)} objects ({', '.join(m.name for m in models)})", flush=True)
        run_shards(functools.partial(grasp_shard, **job), num_shards=num_shards, out_dir=args.out,
                   workers=args.workers or 0, ray_address=args.ray_address, unit="trials",
                   shard_size=args.scenes_per_shard * args.per_scene,
                   progress_stats=lambda arrays: (len(arrays["label"]), int(arrays["label"].sum())))
    except (ValueError, RuntimeError) as e:
        return fail(e)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished shards are kept in {args.out}; rerun the command to continue",
              file=sys.stderr)
        return 130
    print(f"trials in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
