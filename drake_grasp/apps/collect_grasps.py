"""Self-supervised grasp-stability data: physics trials of sampled grasps, on single objects or in piles.

Per scene: one object of the set dropped at a random pose (scenario `single`), or
1 to 6 of them in a pile (scenario `pile`: the trial judges the object between the
fingers, else the one that rose most),
the depth camera's view turned into the object cloud by the closed loop's
perception, M candidates sampled over the full top hemisphere (gamma in
[0, 90] degrees, roll uniform; or with --sampler gpg, GPD's candidates), and
each candidate tried by the floating hand in physics
(`drake_grasp.simulation.grasp_trial`): approach from the pre-grasp, close at 20 N
per finger, lift. Label 1 when the grasp succeeds by the scenario's rule (the paper's: the object
ends 15 cm higher and held). With --choose-by the candidates tried are the policy's own choices.

Stored compactly: per scene the object, its settled pose and its cloud (0.1 mm
integers), per trial the scene, X_WG, label, outcome and rise (for piles also the
number of objects per scene and the judged object per trial); the 32^3 voxel
grids are regenerated on the fly (`drake_grasp.datasets.grasp_data`). Writes resumable
shards to --out: rerunning the same command continues where it stopped, a
larger --trials extends the set, and Ctrl-C loses only the shards in flight.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
from pathlib import Path

from drake_grasp.apps.cli import (
    add_hand_option,
    add_job_options,
    collect_shards,
    fail,
    note_contact_fill,
    positive_int,
    program_logging,
)
from drake_grasp.datasets.grasp_data import CLOUD_FORMAT, OBJECT_SET_KEY
from drake_grasp.datasets.shards import MANIFEST, drop_short_shards, write_manifest
from drake_grasp.evaluation.grasp_collection import PolicyChoice, first_objects, grasp_shard
from drake_grasp.learning.model_cards import saved_card
from drake_grasp.policy.config import DEFAULT_HOLD_WEIGHTS, SelectionConfig
from drake_grasp.robot.hand import DEFAULT_HAND, check_model_hand, get_hand, hand_record
from drake_grasp.robot.object_files import MESH_UNITS
from drake_grasp.robot.paths import model_path, repo_name
from drake_grasp.robot.task import OUTCOME_TEXT, SAMPLERS
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import load_scenario

LISTED_NAMES = 8  # object names printed at the start


MAX_DEPTH_OFFSET = 0.03  # [m] at 0.035 the palm meets the surface (fingers 55 mm long, tips 20 mm past it)


def grasp_depth_offset(text: str) -> float:
    """A depth in metres, 0 to MAX_DEPTH_OFFSET (a value in millimetres is refused, not misread)."""
    value = float(text)
    if not 0.0 <= value <= MAX_DEPTH_OFFSET:
        raise argparse.ArgumentTypeError(f"must lie in [0, {MAX_DEPTH_OFFSET}] metres, got {text}")
    return value


def job_cloud_format(out_dir: Path) -> str:
    """How the job in `out_dir` stores its clouds, as its manifest says (a job keeps its format as it
    grows); `CLOUD_FORMAT` for a new job."""
    try:
        manifest = json.loads((out_dir / MANIFEST).read_text())
    except (FileNotFoundError, json.JSONDecodeError):  # (a corrupt manifest is refused by write_manifest)
        return CLOUD_FORMAT
    return manifest.get("cloud", CLOUD_FORMAT)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp collect_grasps", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--objects", default="primitives",
                        help="object set: 'primitives', 'novel' or a folder of SDF/URDF/OBJ files")
    parser.add_argument("--trials", type=positive_int, required=True,
                        help="grasp trials to run (scenes = trials / --per-scene, rounded up)")
    parser.add_argument("--per-scene", type=positive_int, default=100, help="candidates tried per scene")
    parser.add_argument("--scenes-per-shard", type=positive_int, default=5)
    parser.add_argument("--scenario", default="single",
                        help="'single' (one object, the default) or 'pile' (1 to 6 objects in clutter)")
    parser.add_argument("--depth-noise", action="store_true",
                        help="observe through the depth camera's noise model (simulation/depth_noise.py)")
    parser.add_argument("--sampler", choices=SAMPLERS, default="uniform",
                        help="uniform: the paper's sampler over the approach cone (default); gpg: GPD's "
                             "candidate generator, hand placements that clear the observed cloud; mixed: "
                             "half GPG, the rest uniform (fewer trials lost to approach collisions); "
                             "topdown: VPG's actions, straight down at heightmap cells")
    parser.add_argument("--object-units", choices=sorted(MESH_UNITS), default="m",
                        help="the lengths of the --objects folder's files (default m; mm: scaled by 0.001)")
    parser.add_argument("--object-subset", type=positive_int, default=None, metavar="K",
                        help="only the first K objects of the set, in a fixed seeded order (subsets nest: "
                             "the first 8 are among the first 50), for curves against the object count")
    parser.add_argument("--second-camera", action="store_true",
                        help="observe through a second depth camera from the side too, the clouds fused "
                             "(as the 'gpd' policy sees the scene)")
    parser.add_argument("--grasp-depth-offset", type=grasp_depth_offset, default=0.0, metavar="METRES",
                        help="try every candidate this much deeper along its approach (0 to "
                             f"{MAX_DEPTH_OFFSET} m; default 0: the grasp point on the surface, as the "
                             "paper); the same seed without it tries the same candidates, paired")
    parser.add_argument("--grip-force", type=float, default=None, metavar="N",
                        help="the trials grip force-controlled, N newtons a finger whatever the object's "
                             "width, as a Franka hand's grasp action (up to 140; default: the scenario's "
                             "grip, a spring of up to 20 N); labels of another grip are another job")
    parser.add_argument("--gpg-stop-at-table", action="store_true",
                        help="GPG's hand is pushed in no lower than the observed table, as the closed loop "
                             "with sampling.gpg_stop_at_table (flat objects get shallow grasps instead of "
                             "none); needs --sampler gpg or mixed")
    parser.add_argument("--choose-by", default=None, metavar="CNN",
                        help="try the policy's own choices: --choose-from candidates from --sampler, ranked "
                             "by this stability CNN times --choose-hold's p_h, and the --per-scene it would "
                             "try one after another if each failed (its mistakes are what its training "
                             "lacks); default: candidates drawn at random")
    parser.add_argument("--choose-hold", default=DEFAULT_HOLD_WEIGHTS, metavar="WEIGHTS",
                        help="the hold predictor of --choose-by (default: the hand's own, as the policy's: "
                             f"{DEFAULT_HOLD_WEIGHTS} for the Franka hand; 'none': p_s alone)")
    parser.add_argument("--choose-from", type=positive_int, default=500, metavar="N",
                        help="candidates --choose-by ranks a scene (default 500, as the closed loop)")
    add_hand_option(parser)
    add_job_options(parser)
    args = parser.parse_args(argv)
    program_logging()
    try:
        hand = get_hand(args.hand or DEFAULT_HAND)
        models = first_objects(load_object_set(args.objects, args.object_units), args.object_subset)
        note_contact_fill(models)
        scenario = load_scenario(args.scenario)
        if args.grip_force is not None:
            scenario = scenario.with_grip_force(args.grip_force)
        if scenario.num_objects > 1 and len(scenario.clusters) > 1:
            raise ValueError(f"scenario '{scenario.name}' has {len(scenario.clusters)} clusters; "
                             "trials in a pile need one ('pile')")
        if args.gpg_stop_at_table and args.sampler not in ("gpg", "mixed"):
            raise ValueError(f"--gpg-stop-at-table needs --sampler gpg or mixed, not '{args.sampler}'")
        choice = None
        if args.choose_by is not None:  # (the default hold predictor is the hand's own, as the policy's)
            selection = SelectionConfig(cnn_weights=args.choose_by, hold_weights=(
                None if args.choose_hold == "none" else args.choose_hold)).for_hand(hand)
            for weights in filter(None, (selection.cnn_weights, selection.hold_weights)):
                check_model_hand(saved_card(model_path(weights)), hand, f"{weights} (--choose-by)")
            choice = PolicyChoice(cnn_weights=repo_name(selection.cnn_weights), hold_weights=(
                None if selection.hold_weights is None else repo_name(selection.hold_weights)),
                candidates=args.choose_from)
        scenes = math.ceil(args.trials / args.per_scene)
        job = dict(hand=hand_record(hand), objects=args.objects, scenario=args.scenario, seed=args.seed,
                   scenes=scenes, scenes_per_shard=args.scenes_per_shard, per_scene=args.per_scene,
                   depth_noise=args.depth_noise, sampler=args.sampler, object_subset=args.object_subset,
                   second_camera=args.second_camera, grasp_depth_offset=args.grasp_depth_offset,
                   cloud=job_cloud_format(args.out))
        if args.object_units != "m":  # (a job in metres, the default, keeps the manifest it always had)
            job["object_units"] = args.object_units
        if scenario.control.grip_force is not None:  # (a spring-grip job keeps the manifest it always had)
            job["grip_force"] = scenario.control.grip_force  # labels made with another grip are another job
        if scenario.success_rule != "lifted":  # (a job judged by the paper's rule keeps its manifest)
            job["success_rule"] = scenario.success_rule  # labels judged by another rule are another job
        if args.gpg_stop_at_table:  # (as is a job whose GPG hand kept above the table, the default)
            job["gpg_stop_at_table"] = True
        if choice is not None:  # (a job of sampled candidates keeps its manifest)
            job["chosen_by"] = choice.record()
        names = [m.name for m in models]
        # Where the cameras stood, for GPD's normals (`GraspDataset.camera_positions`):
        cameras = scenario.with_second_camera().sensing.camera_positions
        seen_from = {"camera_positions": [list(p) for p in cameras]} if args.second_camera else {}
        write_manifest(args.out, {"kind": "grasps", **job, **seen_from, OBJECT_SET_KEY: names,
                                  "outcome_codes": {str(int(c)): t for c, t in OUTCOME_TEXT.items()}},
                       size_key="scenes")
        num_shards = math.ceil(scenes / args.scenes_per_shard)
        drop_short_shards(args.out, lambda k: min(args.scenes_per_shard, scenes - k * args.scenes_per_shard),
                          "scene_id")
        listed = ", ".join(names[:LISTED_NAMES]) + (f", ... ({len(names) - LISTED_NAMES} more)"
                                                    if len(names) > LISTED_NAMES else "")
        print(f"{args.trials} trials: {scenes} scenes of {args.per_scene} grasps on "
              f"{len(models)} objects ({listed})", flush=True)
    except ValueError as e:
        return fail(e)
    def rows_of(k: int) -> int:  # (a scene whose object left the camera's view has no trials)
        return min(args.scenes_per_shard, scenes - k * args.scenes_per_shard) * args.per_scene

    return collect_shards(functools.partial(grasp_shard, hand_file=args.hand), job, out_dir=args.out,
                          num_shards=num_shards, shard_size=args.scenes_per_shard * args.per_scene,
                          unit="trials", args=args, rows_of=rows_of)


if __name__ == "__main__":
    sys.exit(main())
