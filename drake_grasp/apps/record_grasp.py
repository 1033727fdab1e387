"""One grasp attempt of the closed loop, recorded as a self-contained Meshcat HTML page.

Builds the cell for one seeded scene, draws the policy's candidates coloured by
p_g (p_r * p_s), lets the executive plan and execute its first attempt in physics
with Meshcat recording, and writes Meshcat's static HTML: open it in any browser
(no install, no server) and play the animation from the "Animations" controls.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from drake_grasp.apps.cli import fail, quiet_drake
from drake_grasp.policy.scorers import POLICIES, make_scorer
from drake_grasp.robots import ROBOTS, get_robot
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import load_scenario


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp.record_grasp", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="panda", help=f"one of {sorted(ROBOTS)} (default panda)")
    parser.add_argument("--scenario", default="standard", help="scenario name or YAML (default standard)")
    parser.add_argument("--objects", default=None, help="object set (default: the scenario's)")
    parser.add_argument("--policy", default="cnn_rp", help=f"one of {sorted(POLICIES)} (default cnn_rp)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("reports/grasp_cnn_rp.html"),
                        help="the HTML page to write (default reports/grasp_cnn_rp.html)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    quiet_drake()
    try:
        robot = get_robot(args.robot)
        scorer = make_scorer(args.policy, robot)
        scenario = load_scenario(args.scenario)
        models = load_object_set(args.objects or scenario.object_set)
    except ValueError as e:
        return fail(e)
    from pydrake.geometry import StartMeshcat

    from drake_grasp.policy.cell import build_cell, run_attempt
    from drake_grasp.policy.drawing import draw_scored_candidates

    meshcat = StartMeshcat()
    cell = build_cell(robot=robot, scenario=scenario, scorer=scorer, object_models=models, seed=args.seed,
                      meshcat=meshcat)
    cell.simulator.AdvanceTo(scenario.settle_time)
    ranked = cell.ranked_grasps()
    draw_scored_candidates(meshcat, "candidates", ranked.X_WG[:100], ranked.scores[:100])
    task = run_attempt(cell, record=True)
    attempt = task.attempt
    if attempt is None:
        return fail(f"the executive made no attempt: {task.mode.value}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(meshcat.StaticHtml())
    outcome = "success" if attempt.success else attempt.failure
    name = "no object" if attempt.object_index is None else cell.objects[attempt.object_index].name
    print(f"{outcome}: {name} "
          f"rose {100 * attempt.rise:.1f} cm; wrote {args.out} ({args.out.stat().st_size / 1e6:.1f} MB)")
    return 0
