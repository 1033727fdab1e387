"""A simulated robot behind Drake's LCM driver messages: the scenario's scene (its objects dropped as the
closed loop drops them, the arm at home), simulated in wall time, following lcmt_panda_command and
lcmt_schunk_wsg_command and publishing lcmt_panda_status, lcmt_schunk_wsg_status and the depth camera's
lcmt_image_array, as a robot's drivers and camera would (`drake_grasp.robot.drivers`).

It stands in for the robot while a robot stack, or `python -m drake_grasp robot_cell`, is brought up:
run both with the same --lcm-url. It runs until --duration simulated seconds or Ctrl-C / SIGTERM.
"""

from __future__ import annotations

import argparse
import sys
import time

from drake_grasp.apps.cli import add_hand_option, fail, non_negative_int, program_logging, sigterm_interrupts
from drake_grasp.apps.robot_cell import add_driver_options, driver_channels

STEP_S = 0.05  # [s] simulated between looks at the clock and the duration


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp sim_robot", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="panda", help="an arm name or an arm YAML file (default panda)")
    add_hand_option(parser)
    parser.add_argument("--scenario", default="standard", help="the scene and its camera (default standard)")
    parser.add_argument("--objects", default=None, help="the object set (default: the scenario's)")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="the scene's seed")
    parser.add_argument("--duration", type=float, default=None, help="stop after this many simulated seconds")
    parser.add_argument("--realtime-rate", type=float, default=1.0,
                        help="simulated seconds per wall second (1: wall time; 0: as fast as it computes)")
    add_driver_options(parser)
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    program_logging()
    from drake_grasp.robot.arms import get_robot
    from drake_grasp.simulation.lcm_drivers import build_simulated_robot
    from drake_grasp.simulation.objects import load_object_set
    from drake_grasp.simulation.scenario import load_scenario

    try:
        if args.realtime_rate < 0 or (args.duration is not None and args.duration <= 0):
            raise ValueError("--realtime-rate must be >= 0 and --duration > 0")
        robot = get_robot(args.robot, args.hand)
        scenario, channels = load_scenario(args.scenario), driver_channels(args)
        if len(scenario.sensing.cameras) > 1:
            raise ValueError(f"the drivers publish one camera; scenario '{scenario.name}' has "
                             f"{len(scenario.sensing.cameras)}")
        objects = load_object_set(args.objects or scenario.object_set)
        simulated = build_simulated_robot(robot=robot, scenario=scenario, object_models=objects,
                                          seed=args.seed, channels=channels, realtime_rate=args.realtime_rate)
    except (ValueError, FileNotFoundError) as e:
        return fail(e)
    start, wall_start, warned = simulated.context.get_time(), time.monotonic(), False
    print(f"{robot.name} in '{scenario.name}' (seed {args.seed}) on LCM '{channels.lcm_url or 'default'}'",
          flush=True)
    with sigterm_interrupts():
        try:
            while args.duration is None or simulated.context.get_time() - start < args.duration:
                simulated.simulator.AdvanceTo(simulated.context.get_time() + STEP_S)
                rate = (simulated.context.get_time() - start) / max(time.monotonic() - wall_start, 1e-9)
                if args.realtime_rate > 0 and not warned and rate < 0.9 * args.realtime_rate and \
                        simulated.context.get_time() - start >= 2.0:
                    warned = True
                    print(f"warning: the simulation keeps {rate:.2f} of wall time, behind the "
                          f"{args.realtime_rate:g} asked: a controller in wall time sees a slow robot",
                          flush=True)
        except KeyboardInterrupt:
            pass
    print(f"stopped after {simulated.context.get_time() - start:.2f} simulated s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
