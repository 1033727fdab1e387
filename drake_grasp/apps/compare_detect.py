"""`detect` on the simulator's depth images, its grasps executed in the same scenes, against the closed loop.

For each seed, the scene of a closed-loop run (`simulate --seed S`) is built and
settles; its depth image is written as a 16-bit PNG in millimetres beside its
camera YAML (what a real camera gives), and `python -m drake_grasp detect --plan`
runs on those two files. The grasp it planned is then executed in that scene by
the cell's own executive (`GraspExecutive.request_grasp`): same motions, same
success rule. The same scene, built again, runs the closed loop's own first
attempt. Prints and writes (--out DIR: summary.json and each seed's files) both
success rates over the seeds with 95 % intervals. --depth-noise puts the camera's
noise model in both (the recorded PNG then holds the noisy image).
"""

from __future__ import annotations

import argparse
import functools
import json
import subprocess
import sys
from pathlib import Path

from drake_grasp.apps.cli import fail, non_negative_int, out_folder, positive_int, program_logging
from drake_grasp.cell.diagram import run_attempt
from drake_grasp.datasets.shards import run_jobs
from drake_grasp.robot.specs import ROBOTS
from drake_grasp.simulation.scenario import load_scenario


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp compare_detect", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="panda",
                        help=f"one of {sorted(ROBOTS)} or an arm YAML file (default panda)")
    parser.add_argument("--scenario", default="standard", help="scenario name or YAML (default standard)")
    parser.add_argument("--objects", default=None, help="object set (default: the scenario's)")
    parser.add_argument("--runs", type=positive_int, default=10, help="seeds (default 10)")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="the first seed")
    parser.add_argument("--workers", type=positive_int, default=None, help="processes (default: 1 per core)")
    parser.add_argument("--depth-noise", action="store_true", help="the camera with its noise model")
    parser.add_argument("--out", type=out_folder, required=True, help="folder for the files and summary.json")
    return parser.parse_args(argv)


def _cell(robot_name: str, scenario_arg: str, objects_arg: str | None, seed: int, depth_noise: bool = False):
    """The closed loop's cell for the seeded scene (as `simulate --seed` builds it), and its scenario."""
    from drake_grasp.cell.diagram import build_cell
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.robot.arms import get_robot
    from drake_grasp.simulation.objects import load_object_set

    robot, scenario = get_robot(robot_name), load_scenario(scenario_arg)
    if depth_noise:  # (else as the scenario file says)
        scenario = scenario.with_depth_noise()
    cell = build_cell(robot=robot, scenario=scenario, scorer=make_scorer("cnn_rp", robot),
                      object_models=load_object_set(objects_arg or scenario.object_set), seed=seed)
    return cell, scenario


def record_scene(robot_name: str, scenario_arg: str, objects_arg: str | None, seed: int,
                 depth_png: Path, camera_yaml: Path, depth_noise: bool = False) -> None:
    """What the camera sees once the objects rest, as a depth PNG (mm) and its camera YAML."""
    from drake_grasp.perception.camera import save_camera, save_depth_png

    cell, scenario = _cell(robot_name, scenario_arg, objects_arg, seed, depth_noise)
    cell.advance_to_next_look()
    save_depth_png(cell.depth_image(), depth_png)
    save_camera(scenario.sensing.camera, camera_yaml)


def first_attempt(robot_name: str, scenario_arg: str, objects_arg: str | None, seed: int,
                  requested=None, depth_noise: bool = False) -> dict:
    """The seeded scene's first attempt: the cell's own choice, or the `requested` grasp."""
    cell, _ = _cell(robot_name, scenario_arg, objects_arg, seed, depth_noise)
    if requested is not None:
        cell.executive.request_grasp(cell.context, requested)
    attempt = run_attempt(cell).attempt
    return {"planned": attempt.planned, "success": attempt.success, "failure": attempt.failure,
            "rise": round(attempt.rise, 4), "grasp_point": attempt.grasp_point}


def compare_seed(robot_name: str, scenario_arg: str, objects_arg: str | None, seed: int, out: Path,
                 depth_noise: bool = False) -> dict:
    """Both first attempts of one seed's scene: detect's (from the recorded files) and the closed loop's."""
    import numpy as np

    program_logging()
    folder = out / f"seed_{seed:03d}"
    folder.mkdir(parents=True, exist_ok=True)
    depth, camera, grasps = folder / "depth.png", folder / "camera.yaml", folder / "grasps.json"
    record_scene(robot_name, scenario_arg, objects_arg, seed, depth, camera, depth_noise)
    scenario = load_scenario(scenario_arg)  # detect samples and crops as the closed loop does
    box = scenario.sensing.workspace
    command = [sys.executable, "-m", "drake_grasp", "detect", "--depth", str(depth), "--camera", str(camera),
               "--robot", robot_name, "--plan", "--seed", str(seed), "--out", str(grasps),
               "--candidates", str(scenario.sampling.num_candidates),
               "--gamma-deg", *map(str, scenario.sampling.gamma_deg),
               "--workspace", *map(str, [*box.lower, *box.upper])]
    run = subprocess.run(command, capture_output=True, text=True, timeout=900)
    row = {"seed": seed, "detect_exit": run.returncode}
    plan = json.loads(grasps.read_text()).get("plan") if run.returncode == 0 else None
    if plan is None:
        row["detect"] = {"planned": False, "success": False,
                         "failure": run.stderr.strip() or "none of its top grasps planned"}
    else:
        X_WG = np.array(json.loads(grasps.read_text())["grasps"][plan["rank"]]["X_BG"])
        row["detect"] = first_attempt(robot_name, scenario_arg, objects_arg, seed, X_WG, depth_noise)
    row["closed_loop"] = first_attempt(robot_name, scenario_arg, objects_arg, seed, None, depth_noise)
    return row


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    program_logging()
    from drake_grasp.evaluation.stats import mean_ci95
    from drake_grasp.robot.arms import get_robot
    from drake_grasp.simulation.objects import load_object_set

    try:
        robot = get_robot(args.robot)
        scenario = load_scenario(args.scenario)
        load_object_set(args.objects or scenario.object_set)
    except ValueError as e:
        return fail(e)
    seeds = list(range(args.seed, args.seed + args.runs))
    job = functools.partial(compare_seed, robot.source, args.scenario, args.objects, out=args.out,
                            depth_noise=args.depth_noise)
    results = run_jobs(job, seeds, workers=args.workers or 0, worker_init=program_logging)
    rows = sorted((row for _, row in results), key=lambda row: row["seed"])
    print("seed  detect                          closed loop")
    for r in rows:
        d, c = r["detect"], r["closed_loop"]
        print(f"{r['seed']:>4}  {'success' if d['success'] else d['failure']:<30}  "
              f"{'success' if c['success'] else c['failure']}")
    summary = {"robot": robot.name, "scenario": scenario.name, "objects": args.objects or scenario.object_set,
               "depth_noise": args.depth_noise, "seeds": seeds, "rows": rows}
    for key in ("detect", "closed_loop"):
        mean, half = mean_ci95([r[key]["success"] for r in rows])
        summary[f"{key}_success_rate"], summary[f"{key}_ci95"] = mean, half
        print(f"{key}: first-attempt success {mean:.0%} +- {half:.0%} over {len(rows)} scenes")
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
