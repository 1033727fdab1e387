"""Ranked (and planned) grasps from one recorded depth image and its camera description.

The closed loop's perception and ranking on a depth file: back-project into the
robot's base frame (only the pixels of a workspace --mask, when given), take the arm
out of the picture (--q: its joint positions), crop to the workspace, remove the
table, sample candidates and rank them by the policy (default the paper's
p_r * p_s). Writes the top grasps as
JSON (the grasp's, TCP's and hand's poses X_BG, X_BT, X_BH in the base frame, p_r,
p_s, p_h and the score, `score_is` naming it) and a PNG of them drawn over the
image; with --plan also the joint trajectory of the best candidate that plans.
With --bag it reads every depth frame of a ROS 2 bag (sensor_msgs/Image, its
CameraInfo's intrinsics, the JointState at that time for the self-filter and the
plan's start; the camera YAML then gives only the pose of the image's frame_id, or,
with --base-frame, the bag's /tf_static and /tf place it) and writes one JSON of all
frames. With --realsense it reads one frame from an
Intel RealSense camera instead of a
file (the `realsense` extra; untested here, for want of a camera) and saves it
beside the output as OUT_depth.png and OUT_camera.yaml, so the run replays.

Depth: PNG of 16-bit millimetres, or .npy / .exr of float metres; zero or NaN
pixels are "no reading". The camera YAML holds the intrinsics and the camera's pose
in the base frame (see `drake_grasp.perception.camera`). Bad input ends with one line and exit
code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_grasp.apps.cli import (
    add_hand_option,
    add_sampler_option,
    add_selection_option,
    fail,
    non_negative_int,
    out_file,
    positive_int,
    program_logging,
    selection_config,
)
from drake_grasp.cell.detection import DetectConfig
from drake_grasp.perception.config import WORKSPACE_LOWER, WORKSPACE_UPPER, SamplingConfig, WorkspaceBox
from drake_grasp.policy.scorers import POLICIES
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.specs import ROBOTS

if TYPE_CHECKING:
    from drake_grasp.perception.camera import CameraConfig


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drake_grasp detect", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--depth", type=Path, help="depth image: .png (mm), .npy or .exr (m)")
    source.add_argument("--bag", type=Path, help="a ROS 2 bag (MCAP or SQLite): the grasps of each depth "
                        "frame, with its CameraInfo and JointState")
    source.add_argument("--realsense", nargs="?", const="", metavar="SERIAL",
                        help="capture one frame from a RealSense camera (the first one, or SERIAL); "
                             "the camera YAML then gives only the pose, the device its intrinsics")
    parser.add_argument("--camera", type=Path, default=None,
                        help="camera YAML: intrinsics and pose X_BC (with --calibrate: the intrinsics; with "
                             "--bag: the pose, or nothing with --base-frame)")
    bag = parser.add_argument_group("--bag: topics (default: found by their message types)")
    bag.add_argument("--depth-topic", default=None, help="sensor_msgs/Image depth topic")
    bag.add_argument("--info-topic", default=None, help="sensor_msgs/CameraInfo topic")
    bag.add_argument("--joints-topic", default=None, help="sensor_msgs/JointState topic")
    bag.add_argument("--base-frame", default=None, metavar="FRAME",
                     help="the camera's pose from the bag's /tf_static and /tf: the transform from FRAME "
                          "(the arm's base frame as the bag names it) to the image's frame_id")
    parser.add_argument("--mask", type=Path, default=None,
                        help="image the depth's size whose non-zero pixels are the workspace")
    parser.add_argument("--q", type=float, nargs="+", default=None, metavar="RAD",
                        help="the arm's joint positions when the frame was taken: its points leave the "
                             "cloud (the self-filter) and --plan starts there")
    parser.add_argument("--self-filter-margin", type=float, default=None, metavar="M",
                        help="points this near the arm's and hand's collision geometry are the robot's "
                             f"[m] (default {DetectConfig.self_filter_margin})")
    parser.add_argument("--robot", default="panda",
                        help=f"one of {sorted(ROBOTS)} or an arm YAML file (default panda)")
    add_hand_option(parser)
    parser.add_argument("--policy", default="cnn_rp", help=f"one of {sorted(POLICIES)} (default cnn_rp)")
    parser.add_argument("--workspace", type=float, nargs=6,
                        default=[*WORKSPACE_LOWER, *WORKSPACE_UPPER],
                        metavar=("XMIN", "YMIN", "ZMIN", "XMAX", "YMAX", "ZMAX"),
                        help="the box (base frame, m) whose points are the table and objects")
    parser.add_argument("--table-height", type=float, default=0.0, help="table top in the base frame [m]")
    parser.add_argument("--candidates", type=positive_int, default=500, help="grasps sampled (default 500)")
    parser.add_argument("--gamma-deg", type=float, nargs=2, default=[0.0, 90.0], metavar=("MIN", "MAX"),
                        help="approach angles sampled, from straight down (default 0 90)")
    add_sampler_option(parser, "uniform")
    parser.add_argument("--top", type=positive_int, default=10, help="grasps written and drawn (default 10)")
    parser.add_argument("--plan", action="store_true",
                        help="plan the best candidates (at most --top) in rank order until one plans")
    add_selection_option(parser)
    parser.add_argument("--seed", type=non_negative_int, default=0)
    calibrate = parser.add_argument_group("--calibrate: place the camera by the table")
    calibrate.add_argument("--calibrate", action="store_true",
                           help="fit the table plane and write the camera YAML to --out")
    calibrate.add_argument("--point-in-base", type=float, nargs=3, metavar=("X", "Y", "Z"),
                           help="the named table point in the arm's base frame [m] (z: the table top)")
    calibrate.add_argument("--table-pixel", type=float, nargs=2, metavar=("U", "V"), default=None,
                           help="the pixel that sees the named table point (default: the image centre)")
    calibrate.add_argument("--x-pixel", type=float, nargs=2, metavar=("U", "V"), default=None,
                           help="a table pixel along the base's +x from the named point (default: image up)")
    parser.add_argument("--out", type=out_file, required=True,
                        help="grasps JSON to write (with --calibrate: the camera YAML)")
    parser.add_argument("--image", type=Path, default=None,
                        help="PNG of the top grasps (default: OUT with .png)")
    args = parser.parse_args(argv)
    if args.camera is None and not (args.bag is not None and args.base_frame is not None):
        parser.error("--camera is required (with --bag, --base-frame takes the pose from the bag's TF)")
    if args.base_frame is not None and args.bag is None:
        parser.error("--base-frame reads a bag's TF: it needs --bag")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    program_logging()
    if args.calibrate:
        return calibrate(args)
    from drake_grasp.cell.detection import GraspDetector, detection_to_dict, draw_detection
    from drake_grasp.perception.camera import load_camera, load_depth, load_mask
    from drake_grasp.perception.realsense import RealSenseConfig, capture_depth

    try:
        sampling = SamplingConfig(num_candidates=args.candidates, gamma_deg=args.gamma_deg,
                                  sampler=args.sampler)
        workspace = WorkspaceBox(lower=args.workspace[:3], upper=args.workspace[3:])
        config = DetectConfig(policy=args.policy, sampling=sampling, workspace=workspace,
                              table_height=args.table_height, plan=args.plan, plan_top=args.top,
                              seed=args.seed, selection=selection_config(args))
        if args.self_filter_margin is not None:
            config.self_filter_margin = args.self_filter_margin
        # (checks the arm, its hand, the policy and the configuration)
        detector = GraspDetector(get_robot(args.robot, args.hand), config)
        robot = detector.robot
        if args.bag is not None:
            return detect_bag(args, detector)
        camera = load_camera(args.camera, intrinsics=args.realsense is None)
        if args.realsense is not None:
            depth, camera = capture_depth(camera, RealSenseConfig(serial=args.realsense or None))
            save_capture(depth, camera, args.out)
        else:
            depth = load_depth(args.depth)
        mask = load_mask(args.mask, depth.shape) if args.mask is not None else None
        found = detector.detect(depth=depth, camera=camera, q_current=args.q, mask=mask)
    except ValueError as e:  # CameraError and PerceptionError are ValueErrors
        return fail(e)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(detection_to_dict(found, robot, top=args.top), indent=1))
    image = args.image or args.out.with_suffix(".png")
    draw_detection(depth, camera, found, image, top=args.top, hand=robot.hand)
    best = found.ranked
    print(f"{len(found.cloud)} object points, {len(best)} candidates; "
          f"best: {found.score_name} {best.scores[0]:.3f} (p_r {best.p_r[0]:.3f}, p_s {best.p_s[0]:.3f}) "
          f"at {best.X_WG[0][:3, 3].round(3).tolist()}")
    if args.plan:
        if found.plan is None:
            print(f"none of the top {args.top} planned: {', '.join(found.plan_failures)}")
        else:
            print(f"planned rank {found.planned_rank + 1} "
                  f"({found.planned_rank} better ones failed: {', '.join(found.plan_failures) or '-'})")
    print(f"wrote {args.out} and {image}")
    return 0


def detect_bag(args: argparse.Namespace, detector) -> int:
    """--bag: every depth frame's grasps into one JSON (`frames`, in time order); a frame without objects,
    with a joint state that lacks the arm's joints or (--base-frame) one the TF does not place yet is kept
    with its `error`; with --base-frame each frame records the camera pose it used."""
    from drake_grasp.cell.detection import detection_to_dict
    from drake_grasp.perception.camera import CameraConfig, CameraError, load_camera, load_mask
    from drake_grasp.perception.ros_bag import read_bag_frames

    robot = detector.robot
    from_tf = args.base_frame is not None
    pose = (CameraConfig() if args.camera is None
            else load_camera(args.camera, intrinsics=False, pose=not from_tf))
    frames = []
    for frame in read_bag_frames(args.bag, pose, depth_topic=args.depth_topic, info_topic=args.info_topic,
                                 joints_topic=args.joints_topic, base_frame=args.base_frame):
        entry = {"stamp_ns": frame.stamp_ns, "frame_id": frame.frame_id}
        if frame.camera is None:
            entry["error"] = frame.error
            print(f"frame at {frame.stamp_ns} ns: {frame.error}")
            frames.append(entry)
            continue
        if from_tf:
            entry["camera_pose"] = {"from": f"TF {args.base_frame} -> {frame.frame_id}",
                                    "xyz": np.round(frame.camera.xyz, 6).tolist(),
                                    "rpy_deg": np.round(frame.camera.rpy_deg, 4).tolist()}
        try:
            q = frame.joint_positions(robot.joint_names) if frame.joints is not None else args.q
            mask = load_mask(args.mask, frame.depth_m.shape) if args.mask is not None else None
            found = detector.detect(depth=frame.depth_m, camera=frame.camera, q_current=q, mask=mask)
        except ValueError as e:
            entry["error"] = str(e).splitlines()[0]
            print(f"frame at {frame.stamp_ns} ns: {entry['error']}")
        else:
            entry["q"] = None if q is None else np.round(np.asarray(q, dtype=float), 6).tolist()
            entry |= detection_to_dict(found, robot, top=args.top)
            best = found.ranked
            print(f"frame at {frame.stamp_ns} ns: {len(found.cloud)} object points; best {found.score_name} "
                  f"{best.scores[0]:.3f} at {best.X_WG[0][:3, 3].round(3).tolist()}")
        frames.append(entry)
    if not frames:
        raise CameraError(f"{args.bag.name} holds no depth frame")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"bag": str(args.bag), "robot": robot.name, "frames": frames}, indent=1))
    print(f"{len(frames)} frames, {sum('error' not in f for f in frames)} with grasps; wrote {args.out}")
    return 0


def calibrate(args: argparse.Namespace) -> int:
    """--calibrate: the camera YAML whose pose puts the base frame on the table seen in the frame."""
    from drake_grasp.perception.calibration import calibrate_on_table
    from drake_grasp.perception.camera import load_camera, load_depth, load_mask, save_camera

    try:
        if args.depth is None:
            raise ValueError("--calibrate reads a recorded frame: give --depth")
        if args.point_in_base is None:
            raise ValueError("--calibrate needs --point-in-base X Y Z: where the named table point lies "
                             "in the arm's base frame")
        camera = load_camera(args.camera, pose=False)
        depth = load_depth(args.depth)
        mask = load_mask(args.mask, depth.shape) if args.mask is not None else None
        found = calibrate_on_table(depth, camera, p_BP=args.point_in_base, table_pixel=args.table_pixel,
                                   x_pixel=args.x_pixel, mask=mask, seed=args.seed)
    except ValueError as e:
        return fail(e)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_camera(found.camera, args.out)
    print(found.summary())
    print(f"wrote {args.out}; the table top is at z = {args.point_in_base[2]:g} in the base frame "
          f"(detect --table-height {args.point_in_base[2]:g})")
    return 0


def save_capture(depth: np.ndarray, camera: CameraConfig, out: Path) -> None:
    """The captured frame as OUT_depth.png (mm) and its camera as OUT_camera.yaml, to replay with --depth."""
    from drake_grasp.perception.camera import save_camera, save_depth_png

    out.parent.mkdir(parents=True, exist_ok=True)
    save_depth_png(depth, out.with_name(f"{out.stem}_depth.png"))
    save_camera(camera, out.with_name(f"{out.stem}_camera.yaml"))


if __name__ == "__main__":
    sys.exit(main())
