"""Depth frames from a ROS 2 recording (a bag, MCAP or SQLite), read with the `rosbags` package: no ROS
install needed.

A frame is a `sensor_msgs/Image` of depth (`16UC1` or `mono16`: millimetres; `32FC1`: metres), the
`sensor_msgs/CameraInfo` of its camera (the latest at or before it; its K matrix gives the intrinsics,
the image is taken as rectified) and, when the bag records one, the latest `sensor_msgs/JointState`
at or before it. The image's `header.frame_id` names the camera's optical frame (+x right, +y down,
+z forward, as the project's camera frame); its pose in the robot's base frame is the user's (a
camera YAML's `xyz` and `rpy_deg`), and the frame ids of image and CameraInfo must agree.
"""

from __future__ import annotations

import dataclasses as dc
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from drake_grasp.perception.camera import PLAUSIBLE_DEPTH_M, CameraConfig, CameraError

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
JOINT_STATE = "sensor_msgs/msg/JointState"
DEPTH_ENCODINGS = {"16UC1": ("<u2", 0.001), "mono16": ("<u2", 0.001), "32FC1": ("<f4", 1.0)}


@dc.dataclass
class BagFrame:
    """One depth frame of a bag, with its camera and the joint state at its time."""

    stamp_ns: int  # the image's header stamp [ns]
    frame_id: str  # the camera's optical frame, as the image names it
    depth_m: np.ndarray  # (height, width) [m], NaN: no reading
    camera: CameraConfig  # CameraInfo's intrinsics, the user's pose
    joints: dict[str, float] | None  # joint name -> position, None: no JointState before the frame

    def joint_positions(self, names) -> np.ndarray:
        """The positions of `names`, in that order; CameraError when the joint state lacks one."""
        if self.joints is None:
            raise CameraError(f"no JointState was recorded before the frame at {self.stamp_ns} ns")
        missing = [n for n in names if n not in self.joints]
        if missing:
            raise CameraError(f"the JointState lacks the arm's joints {', '.join(missing)} (it has "
                              f"{', '.join(self.joints) or 'none'})")
        return np.array([self.joints[n] for n in names])


def read_bag_frames(path: str | Path, pose: CameraConfig, *, depth_topic: str | None = None,
                    info_topic: str | None = None, joints_topic: str | None = None) -> Iterator[BagFrame]:
    """The bag's depth frames in time order; a topic left None is found by its type (one of that type, or
    the one image topic whose name says depth). CameraError names a bag that cannot be read, a topic
    that is missing or ambiguous, an encoding that is not depth, or frames that disagree."""
    from rosbags.highlevel import AnyReader

    path = Path(path)
    if not path.exists():
        raise CameraError(f"bag not found: {path}")
    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as e:  # rosbags raises its own types for every kind of unreadable bag
        raise CameraError(f"{path.name} is not a readable ROS 2 bag: {str(e).splitlines()[0]}") from None
    try:
        topics = {c.topic: c.msgtype for c in reader.connections}
        depth = _topic(topics, IMAGE, depth_topic, prefer="depth")
        info = _topic(topics, CAMERA_INFO, info_topic)
        joints = _topic(topics, JOINT_STATE, joints_topic, required=False)
        wanted = [c for c in reader.connections if c.topic in {depth, info, joints}]
        latest_info, latest_joints = None, None
        for connection, _, raw in reader.messages(connections=wanted):
            message = reader.deserialize(raw, connection.msgtype)
            if connection.topic == info:
                latest_info = message
            elif connection.topic == joints:
                positions = np.asarray(message.position, dtype=float)
                latest_joints = dict(zip(message.name, positions, strict=False))
            else:
                if latest_info is None:
                    raise CameraError(f"the depth image at {_stamp(message)} ns comes before any CameraInfo "
                                      f"on {info}")
                yield _frame(message, latest_info, pose, latest_joints)
    finally:
        reader.close()


def _topic(topics: dict[str, str], msgtype: str, chosen: str | None, *, prefer: str = "",
           required: bool = True) -> str | None:
    if chosen is not None:
        if topics.get(chosen) != msgtype:
            raise CameraError(f"the bag has no {msgtype} topic {chosen} (its topics: "
                              f"{', '.join(f'{t} ({m})' for t, m in sorted(topics.items()))})")
        return chosen
    found = sorted(t for t, m in topics.items() if m == msgtype)
    if len(found) > 1 and prefer:
        found = [t for t in found if prefer in t.lower()] or found
    if len(found) == 1:
        return found[0]
    if not found and not required:
        return None
    what = "no" if not found else f"{len(found)} ({', '.join(found)}); name one:"
    raise CameraError(f"the bag has {what} {msgtype} topic" + ("" if found else " (its topics: "
                      f"{', '.join(sorted(topics)) or 'none'})"))


def _stamp(message) -> int:
    return int(message.header.stamp.sec) * 1_000_000_000 + int(message.header.stamp.nanosec)


def _frame(image, info, pose: CameraConfig, joints: dict[str, float] | None) -> BagFrame:
    if image.encoding not in DEPTH_ENCODINGS:
        raise CameraError(f"the image encoding '{image.encoding}' is not depth: one of "
                          f"{', '.join(DEPTH_ENCODINGS)} is")
    if image.header.frame_id != info.header.frame_id:
        raise CameraError(f"the depth image's frame '{image.header.frame_id}' is not its CameraInfo's "
                          f"'{info.header.frame_id}'")
    dtype, scale = DEPTH_ENCODINGS[image.encoding]
    dtype = np.dtype(dtype).newbyteorder(">" if image.is_bigendian else "<")
    row = image.width * dtype.itemsize
    data = np.frombuffer(bytes(image.data), dtype=np.uint8)
    if image.step < row or len(data) < image.step * image.height:
        raise CameraError(f"the depth image's data ({len(data)} bytes, step {image.step}) does not hold "
                          f"{image.width} x {image.height} {image.encoding} pixels")
    rows = data[: image.step * image.height].reshape(image.height, image.step)[:, :row]
    depth = rows.copy().view(dtype).reshape(image.height, image.width).astype(np.float32) * scale
    depth = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan).astype(np.float32)
    valid = depth[np.isfinite(depth)]
    if valid.size and not PLAUSIBLE_DEPTH_M[0] <= float(np.median(valid)) <= PLAUSIBLE_DEPTH_M[1]:
        raise CameraError(f"the {image.encoding} depth image reads {float(np.median(valid)):.3g} m at the "
                          "median: no depth camera's (millimetres recorded as 32FC1 metres?)")
    k = np.asarray(info.k, dtype=float)
    if (info.width, info.height) != (image.width, image.height) or k[0] <= 0 or k[4] <= 0:
        raise CameraError(f"the CameraInfo ({info.width} x {info.height}, fx {k[0]:g}, fy {k[4]:g}) does not "
                          f"fit the {image.width} x {image.height} depth image")
    camera = dc.replace(pose, width=int(image.width), height=int(image.height), fx=float(k[0]),
                        fy=float(k[4]), cx=float(k[2]), cy=float(k[5]))
    camera.check()
    return BagFrame(_stamp(image), image.header.frame_id, depth, camera, joints)
