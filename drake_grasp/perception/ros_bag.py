"""Depth frames from a ROS 2 recording (a bag, MCAP or SQLite), read with the `rosbags` package: no ROS
install needed.

A frame is a `sensor_msgs/Image` of depth (`16UC1` or `mono16`: millimetres; `32FC1`: metres), the
`sensor_msgs/CameraInfo` of its camera (the latest at or before it; its K matrix gives the intrinsics,
the image is taken as rectified) and, when the bag records one, the latest `sensor_msgs/JointState`
at or before it. The image's `header.frame_id` names the camera's optical frame (+x right, +y down,
+z forward, as the project's camera frame), and the frame ids of image and CameraInfo must agree. The
optical frame's pose in the robot's base frame is the user's (a camera YAML's `xyz` and `rpy_deg`), or,
given the base frame's name, the bag's own: the chain of `tf2_msgs/TFMessage` transforms on `/tf_static`
and `/tf` from the base frame to the image's frame (each transform as last recorded at or before the
image: a camera on the wrist moves with the arm).
"""

from __future__ import annotations

import dataclasses as dc
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform

from drake_grasp.perception.camera import PLAUSIBLE_DEPTH_M, CameraConfig, CameraError

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
JOINT_STATE = "sensor_msgs/msg/JointState"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
TF_TOPICS = ("/tf_static", "/tf")
DEPTH_ENCODINGS = {"16UC1": ("<u2", 0.001), "mono16": ("<u2", 0.001), "32FC1": ("<f4", 1.0)}


@dc.dataclass
class BagFrame:
    """One depth frame of a bag, with its camera and the joint state at its time."""

    stamp_ns: int  # the image's header stamp [ns]
    frame_id: str  # the camera's optical frame, as the image names it
    depth_m: np.ndarray  # (height, width) [m], NaN: no reading
    camera: CameraConfig | None  # CameraInfo's intrinsics; the user's pose, or the bag's TF's (None: `error`)
    joints: dict[str, float] | None  # joint name -> position, None: no JointState before the frame
    error: str | None = None  # why the frame has no camera: the TF recorded before it does not place it

    def joint_positions(self, names) -> np.ndarray:
        """The positions of `names`, in that order; CameraError when the joint state lacks one."""
        if self.joints is None:
            raise CameraError(f"no JointState was recorded before the frame at {self.stamp_ns} ns")
        missing = [n for n in names if n not in self.joints]
        if missing:
            raise CameraError(f"the JointState lacks the arm's joints {', '.join(missing)} (it has "
                              f"{', '.join(self.joints) or 'none'})")
        return np.array([self.joints[n] for n in names])


class TransformTree:
    """The frames a bag's TF messages connect: each child frame's parent and pose in it, as last recorded."""

    def __init__(self) -> None:
        self._parent: dict[str, tuple[str, RigidTransform]] = {}  # child -> (parent, X_PC)

    def add(self, message) -> None:
        """The transforms of one `tf2_msgs/TFMessage`."""
        for stamped in message.transforms:
            t, q = stamped.transform.translation, stamped.transform.rotation
            rotation = Quaternion(w=q.w, x=q.x, y=q.y, z=q.z)
            norm = np.linalg.norm(rotation.wxyz())
            if not np.isfinite(norm) or norm < 1e-9:
                raise CameraError(f"the TF transform {stamped.header.frame_id} -> {stamped.child_frame_id} "
                                  "has no rotation (a zero quaternion)")
            rotation = Quaternion(rotation.wxyz() / norm)
            self._parent[_frame_name(stamped.child_frame_id)] = (
                _frame_name(stamped.header.frame_id), RigidTransform(rotation, [t.x, t.y, t.z]))

    def _to_root(self, frame: str) -> tuple[str, RigidTransform]:
        """(the root of `frame`'s tree, X_root_frame)."""
        X, seen = RigidTransform(), {frame}
        while frame in self._parent:
            frame, X_PF = self._parent[frame]
            if frame in seen:
                raise CameraError(f"the bag's TF frames form a loop through '{frame}'")
            seen.add(frame)
            X = X_PF @ X
        return frame, X

    def lookup(self, base: str, frame: str) -> RigidTransform:
        """X_base_frame; CameraError when the TF recorded so far does not connect the two."""
        base, frame = _frame_name(base), _frame_name(frame)
        known = sorted(set(self._parent) | {p for p, _ in self._parent.values()})
        for name in (base, frame):
            if name not in known:
                raise CameraError(f"the bag's TF has no frame '{name}' (its frames: "
                                  f"{', '.join(known) or 'none'})")
        root_b, X_RB = self._to_root(base)
        root_f, X_RF = self._to_root(frame)
        if root_b != root_f:
            raise CameraError(f"the bag's TF does not connect '{base}' and '{frame}' (their trees end at "
                              f"'{root_b}' and '{root_f}')")
        return X_RB.inverse() @ X_RF


def _frame_name(name: str) -> str:
    return name.lstrip("/")  # (ROS 1 style names carry a leading slash)


def read_bag_frames(path: str | Path, pose: CameraConfig, *, depth_topic: str | None = None,
                    info_topic: str | None = None, joints_topic: str | None = None,
                    base_frame: str | None = None) -> Iterator[BagFrame]:
    """The bag's depth frames in time order; a topic left None is found by its type (one of that type, or
    the one image topic whose name says depth). With `base_frame`, each frame's camera pose is the bag's
    TF from that frame to the image's (`pose` then gives only the depth range). CameraError names a bag
    that cannot be read, a topic that is missing or ambiguous, an encoding that is not depth, frames that
    disagree, or a TF that does not place the camera."""
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
        tf_topics = set()
        if base_frame is not None:
            tf_topics = {t for t in TF_TOPICS if topics.get(t) == TF_MESSAGE}
            if not tf_topics:
                raise CameraError(f"the bag records no {TF_MESSAGE} on {' or '.join(TF_TOPICS)} to place the "
                                  f"camera from '{base_frame}': give the camera's pose in a camera YAML")
        wanted = [c for c in reader.connections if c.topic in {depth, info, joints} | tf_topics]
        latest_info, latest_joints, tree = None, None, TransformTree()
        for connection, _, raw in reader.messages(connections=wanted):
            message = reader.deserialize(raw, connection.msgtype)
            if connection.topic in tf_topics:
                tree.add(message)
            elif connection.topic == info:
                latest_info = message
            elif connection.topic == joints:
                positions = np.asarray(message.position, dtype=float)
                latest_joints = dict(zip(message.name, positions, strict=False))
            else:
                if latest_info is None:
                    raise CameraError(f"the depth image at {_stamp(message)} ns comes before any CameraInfo "
                                      f"on {info}")
                if base_frame is None:
                    yield _frame(message, latest_info, pose, latest_joints)
                    continue
                try:
                    X_BC = tree.lookup(base_frame, message.header.frame_id)
                except CameraError as e:  # (the TF may come later in the bag: the next frames may have it)
                    frame = _frame(message, latest_info, pose, latest_joints)
                    yield dc.replace(frame, camera=None, error=str(e))
                else:
                    yield _frame(message, latest_info, pose.placed(X_BC), latest_joints)
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
