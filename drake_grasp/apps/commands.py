"""`python -m drake_grasp <command>` (or `drake-grasp <command>`): every program of the package, listed
and run by name. `python -m drake_grasp.simulate` and `python -m drake_grasp.collect_reachability`
run the same programs as `simulate` and `collect_reachability` here."""

from __future__ import annotations

import importlib
import sys

from drake_grasp.apps.allocator import run_with_fast_allocator

# command -> (module in drake_grasp.apps, what it does)
COMMANDS = {
    "simulate": ("simulate", "closed-loop grasping runs in physics, with the paper's metrics"),
    "experiments": ("experiments", "a table of evaluations (the paper's by default), resumable, with charts"),
    "detect": ("detect", "ranked (and planned) grasps from a depth image, a ROS 2 bag or a RealSense"),
    "serve": ("serve", "the grasp service: a gRPC server with the models loaded once"),
    "robot_cell": ("robot_cell", "the grasping cell on a robot, through Drake's LCM driver messages"),
    "sim_robot": ("sim_robot", "a simulated robot behind those messages, standing in for one"),
    "collect_reachability": ("collect_reachability", "planning-success labels for an arm's RP"),
    "collect_grasps": ("collect_grasps", "self-supervised grasp trials in physics (stability labels)"),
    "train": ("train", "train the RP, the stability CNN, the hold predictor or a baseline"),
    "grasp_threshold": ("grasp_threshold", "choose the 'nothing graspable' stop on validation reports"),
    "evaluate": ("evaluate", "metrics of a trained CNN or GPD classifier on grasp trials"),
    "make_objects": ("make_objects", "a procedural object set"),
    "make_hands": ("make_hands", "a family of parallel-jaw hand files"),
    "reachability_map": ("reachability_map", "an arm's reachability map: RP against the planner"),
    "rp_report": ("rp_report", "the RP's held-out metrics and its learning curve"),
    "stability_report": ("stability_report", "the CNN's learning curve on grasp trials"),
    "record_grasp": ("record_grasp", "one grasp attempt as a self-contained Meshcat page"),
    "compare_detect": ("compare_detect", "detect's grasps against the closed loop's in the same scenes"),
    "bench": ("bench", "the pipeline's stage costs on this machine, as a table"),
}


def usage() -> str:
    width = max(map(len, COMMANDS))
    lines = [f"  {name:<{width}}  {what}" for name, (_, what) in COMMANDS.items()]
    return ("usage: python -m drake_grasp <command> [options]   (or: drake-grasp <command> ...)\n\n"
            "commands:\n" + "\n".join(lines)
            + "\n\n`python -m drake_grasp <command> --help` tells its options.")


def main(argv: list[str] | None = None) -> int:
    """Runs the command `argv` names (None: this process's command line, with a faster allocator)."""
    if argv is None:
        run_with_fast_allocator()
        argv = sys.argv[1:]
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0
    name = argv[0].replace("-", "_")
    if name not in COMMANDS:
        print(f"error: unknown command '{argv[0]}'; choose one of: {', '.join(COMMANDS)}", file=sys.stderr)
        return 2
    module = importlib.import_module(f"drake_grasp.apps.{COMMANDS[name][0]}")
    return module.main(argv[1:])
