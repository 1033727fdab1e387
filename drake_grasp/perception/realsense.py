"""One depth frame from an Intel RealSense camera, through `pyrealsense2` (the `realsense` extra).

Kept thin on purpose: it opens the camera, lets auto-exposure settle, reads one
depth frame in metres and the device's own intrinsics, and stops the camera.
Everything after that (back-projection, ranking, planning) is the same code that
`detect --depth FILE` runs, and `detect --realsense` saves the frame and its
camera file beside its output, so a capture replays exactly. It cannot be tested
without a camera; the missing-package and no-camera cases end with a one-line
`CameraError`.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np

from drake_grasp.perception.camera import CameraConfig, CameraError


@dc.dataclass(frozen=True)
class RealSenseConfig:
    """Which camera and which depth stream to read."""

    serial: str | None = None  # None: the first camera found
    width: int = 640
    height: int = 480
    fps: int = 30
    warmup_frames: int = 30  # frames dropped while auto-exposure settles


def capture_depth(pose: CameraConfig,
                  config: RealSenseConfig = RealSenseConfig()) -> tuple[np.ndarray, CameraConfig]:
    """A depth image [m] (NaN = no reading) and `pose` with the device's intrinsics in place of its own."""
    try:
        import pyrealsense2 as rs
    except ImportError:
        raise CameraError("--realsense needs pyrealsense2: pip install -e '.[realsense]'") from None
    devices = [d.get_info(rs.camera_info.serial_number) for d in rs.context().query_devices()]
    if not devices:
        raise CameraError("no RealSense camera is connected")
    if config.serial is not None and config.serial not in devices:
        raise CameraError(f"no RealSense camera with serial {config.serial}; connected: {', '.join(devices)}")
    stream = rs.config()
    stream.enable_device(config.serial or devices[0])
    stream.enable_stream(rs.stream.depth, config.width, config.height, rs.format.z16, config.fps)
    pipeline = rs.pipeline()
    try:
        profile = pipeline.start(stream)
    except RuntimeError as e:
        raise CameraError(f"the RealSense camera would not start a {config.width} x {config.height} "
                          f"depth stream at {config.fps} fps: {e}") from None
    try:
        depth_scale = profile.get_device().first_depth_sensor().get_depth_scale()  # metres per unit
        for _ in range(config.warmup_frames):
            pipeline.wait_for_frames()
        frame = pipeline.wait_for_frames().get_depth_frame()
        intrinsics = frame.profile.as_video_stream_profile().intrinsics
        raw = np.asanyarray(frame.get_data()).astype(np.float32)
    finally:
        pipeline.stop()
    depth = np.where(raw > 0, raw * depth_scale, np.nan).astype(np.float32)
    camera = dc.replace(pose, width=intrinsics.width, height=intrinsics.height, fx=intrinsics.fx,
                        fy=intrinsics.fy, cx=intrinsics.ppx, cy=intrinsics.ppy)
    camera.check()
    return depth, camera
