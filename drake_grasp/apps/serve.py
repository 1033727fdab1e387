"""The grasp service: a gRPC server (drake_grasp/service/grasp_service.proto) that answers Detect
(a depth image, its camera and optionally the arm's joint positions and a workspace mask, in;
ranked grasps with their grasp, TCP and hand poses, and optionally a plan, out), Health and
Version, with the models loaded once per worker.

It listens on 127.0.0.1 unless --host says otherwise; beyond this machine it needs --token (or
the DRAKE_GRASP_TOKEN environment variable), which every request must then carry as
`authorization: Bearer TOKEN`. --workers requests run at once (default: one per core), --queue more
wait, and more than that are refused with RESOURCE_EXHAUSTED. SIGTERM or Ctrl-C stops it cleanly
(requests in flight get --grace seconds). Python clients: drake_grasp.service.client.GraspClient.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading

from drake_grasp.apps.cli import (
    add_hand_option,
    add_sampler_option,
    add_selection_option,
    fail,
    non_negative_int,
    positive_int,
    program_logging,
    selection_config,
)
from drake_grasp.policy.scorers import POLICIES
from drake_grasp.robot.specs import ROBOTS


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp serve", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    parser.add_argument("--port", type=non_negative_int, default=50051, help="port (default 50051; 0: any)")
    parser.add_argument("--token", default=os.environ.get("DRAKE_GRASP_TOKEN", ""),
                        help="the token every request must carry (default: $DRAKE_GRASP_TOKEN)")
    parser.add_argument("--workers", type=positive_int, default=os.cpu_count() or 1,
                        help="requests served at once, a detector each (default: one per core)")
    parser.add_argument("--queue", type=non_negative_int, default=8, help="requests that may wait (8)")
    parser.add_argument("--grace", type=float, default=5.0, help="seconds in-flight requests get at a stop")
    parser.add_argument("--robot", default="panda", help=f"one of {sorted(ROBOTS)} or an arm YAML file")
    add_hand_option(parser)
    parser.add_argument("--policy", default="cnn_rp", help=f"one of {sorted(POLICIES)} (default cnn_rp)")
    parser.add_argument("--candidates", type=positive_int, default=500, help="grasps sampled (default 500)")
    add_sampler_option(parser, "uniform")
    parser.add_argument("--table-height", type=float, default=0.0, help="table top in the base frame [m]")
    add_selection_option(parser)
    parser.add_argument("--seed", type=non_negative_int, default=0)
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    program_logging()
    from drake_grasp.cell.detection import DetectConfig
    from drake_grasp.perception.config import SamplingConfig
    from drake_grasp.service.server import GraspServer, ServeConfig

    config = ServeConfig(host=args.host, port=args.port, token=args.token, workers=args.workers,
                         queue=args.queue, robot=args.robot, hand=args.hand,
                         detect=DetectConfig(policy=args.policy,
                                             sampling=SamplingConfig(num_candidates=args.candidates,
                                                                     sampler=args.sampler),
                                             table_height=args.table_height, seed=args.seed,
                                             selection=selection_config(args)))
    try:
        server = GraspServer(config)
    except (ValueError, RuntimeError) as e:
        return fail(e)
    stopped = threading.Event()

    def stop(signum, frame) -> None:
        stopped.set()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    token = ", token required" if config.token else ""
    print(f"serving {server.servicer.robot.name} / {args.policy} on {server.address} "
          f"({config.workers} workers{token})", flush=True)
    while not stopped.wait(0.5):
        pass
    server.stop(args.grace)
    print("stopped", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
