"""The grasping cell on a robot: the closed loop (perception, policy, planner, executive) driving an arm, a
parallel gripper and a fixed depth camera through Drake's LCM driver messages, in wall time.

The robot's drivers must speak the messages of `drake_grasp.robot.drivers` (the arm's
lcmt_panda_command / lcmt_panda_status, of any joint count; the gripper's lcmt_schunk_wsg_command /
lcmt_schunk_wsg_status; the camera's lcmt_image_array with a depth image in float metres or uint16
millimetres), on the channels and LCM network given below. The camera's intrinsics and pose in the
arm's base frame come from --camera (a camera YAML, as `detect` takes) or the scenario. Grasps are
judged by the jaws (the gripper's reported opening): the program prints each attempt and writes them
to --report. With no robot at hand, `python -m drake_grasp sim_robot` stands in for one.
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import json
import sys
from pathlib import Path

from drake_grasp.apps.cli import (
    add_hand_option,
    add_sampler_option,
    fail,
    positive_int,
    program_logging,
    sigterm_interrupts,
)

POLL_S = 0.1  # [s] how often the program looks at the executive


def add_driver_options(parser: argparse.ArgumentParser) -> None:
    """--lcm-url and the five channels (`DriverChannels`)."""
    from drake_grasp.robot.drivers import DriverChannels

    defaults = DriverChannels()
    parser.add_argument("--lcm-url", default=defaults.lcm_url,
                        help="the LCM network (default: LCM's own, udpm://239.255.76.67:7667?ttl=0)")
    for name in ("arm_command", "arm_status", "hand_command", "hand_status", "images"):
        parser.add_argument(f"--{name.replace('_', '-')}-channel", dest=name, default=getattr(defaults, name),
                            help=f"(default {getattr(defaults, name)})")


def driver_channels(args: argparse.Namespace):
    from drake_grasp.robot.drivers import DriverChannels

    return DriverChannels(lcm_url=args.lcm_url, arm_command=args.arm_command, arm_status=args.arm_status,
                          hand_command=args.hand_command, hand_status=args.hand_status, images=args.images)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp robot_cell", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="panda", help="an arm name or an arm YAML file (default panda)")
    add_hand_option(parser)
    parser.add_argument("--scenario", default="standard",
                        help="the scenario whose camera, workspace, sampling and timing the cell uses")
    parser.add_argument("--camera", type=Path, default=None, help="camera YAML (intrinsics and pose)")
    parser.add_argument("--policy", default="cnn_rp", help="the policy (default cnn_rp)")
    add_sampler_option(parser, None)
    parser.add_argument("--attempts", type=positive_int, default=None,
                        help="stop after this many attempts (default: when the executive ends the run)")
    parser.add_argument("--wait", type=float, default=10.0, help="seconds to wait for the drivers (10)")
    parser.add_argument("--report", type=Path, default=None, help="write the attempts here as JSON")
    add_driver_options(parser)
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    program_logging()
    from drake_grasp.cell.diagram import build_robot_cell
    from drake_grasp.cell.episode import RESETTLE_S
    from drake_grasp.cell.executive import END_MODES, Mode
    from drake_grasp.cell.hardware import DriversSilentError
    from drake_grasp.perception.camera import CameraError, load_camera
    from drake_grasp.policy.scorers import make_scorer
    from drake_grasp.robot.arms import get_robot
    from drake_grasp.simulation.scenario import load_scenario

    try:
        robot = get_robot(args.robot, args.hand)
        scenario, channels = load_scenario(args.scenario), driver_channels(args)
        if args.camera is not None:
            sensing = dc.replace(scenario.sensing, camera=load_camera(args.camera), extra_cameras=[])
            scenario = dc.replace(scenario, sensing=sensing)
        if args.sampler:
            scenario = scenario.with_sampler(args.sampler)
        cell = build_robot_cell(robot=robot, scenario=scenario, scorer=make_scorer(args.policy, robot),
                                channels=channels)
        cell.hardware.wait_for_drivers(args.wait)
    except (ValueError, FileNotFoundError, CameraError, DriversSilentError) as e:
        return fail(e)
    print(f"{robot.name} on LCM '{channels.lcm_url or 'default'}': the drivers answer; the cell starts",
          flush=True)
    attempts: list[dict] = []
    with sigterm_interrupts():
        try:
            while args.attempts is None or len(attempts) < args.attempts:
                state = cell.task_state()
                if state.mode in END_MODES:
                    print(f"the run ended: {state.mode.value}", flush=True)
                    break
                if state.mode is Mode.ATTEMPT_DONE:
                    attempt = dc.asdict(state.attempt)
                    attempts.append(attempt)
                    print(f"attempt {len(attempts)}: {'held' if attempt['success'] else attempt['failure']}",
                          flush=True)
                    cell.executive.start_next_attempt(cell.context, RESETTLE_S if attempt["planned"] else 0.0)
                cell.simulator.AdvanceTo(cell.context.get_time() + POLL_S)
        except KeyboardInterrupt:
            print("stopped", flush=True)
    if args.report is not None:
        args.report.write_text(json.dumps({"robot": robot.name, "attempts": attempts}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
