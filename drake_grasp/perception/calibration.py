"""A fixed camera placed by its view of the table: the table plane in one depth frame gives the camera's
height and tilt, and a point the user names on the table (and where the arm's base stands from it)
gives the rest of its pose.

The base frame B is put on the table plane, z up: the table point seen at pixel `table_pixel` has base
coordinates `p_BP` (the user measures where the arm's base stands relative to it; z is the table top's
height in the base frame), and the base's +x axis runs along the table toward the point seen at
`x_pixel` (by default the image's up direction, laid on the table). The table plane is the frame's
dominant plane (`cloud.fit_plane`, refined by least squares on its inliers). This is a quick start for a
fixed camera over a flat table, good to a few millimetres and a degree where the user's measurement is;
a hand-eye calibration (a marker on the flange, several arm poses) is better and sees what this cannot
(the base's yaw about the table normal comes only from `x_pixel`).
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from drake_grasp.perception.camera import CameraConfig, CameraError, points_in_camera
from drake_grasp.perception.cloud import PLANE_DISTANCE, fit_plane, refine_plane

MIN_TABLE_SHARE = 0.2  # the table must be at least this share of the frame's readings
MAX_TILT_DEG = 85.0  # a camera that sees the table more edge-on than this cannot be placed by it


@dc.dataclass(frozen=True)
class TableCalibration:
    """The camera (intrinsics and the pose X_BC found) and how well the table fitted."""

    camera: CameraConfig
    residual_rms: float  # the table points' RMS distance from the plane [m]
    table_share: float  # the share of the frame's readings on the table plane
    height: float  # the camera's distance from the table plane [m]
    tilt_deg: float  # the optical axis from straight down at the table

    def summary(self) -> str:
        return (f"table plane: {1000 * self.residual_rms:.1f} mm RMS over {100 * self.table_share:.0f} % "
                f"of the readings; camera {self.height:.3f} m above it, tilted {self.tilt_deg:.1f} deg from "
                f"straight down; camera at xyz {np.round(self.camera.xyz, 4).tolist()}, "
                f"rpy_deg {np.round(self.camera.rpy_deg, 2).tolist()}")


def pixel_on_plane(pixel, camera: CameraConfig, normal: np.ndarray, offset: float) -> np.ndarray:
    """The point p_C where the ray through `pixel` (u, v) meets the plane n . p + d = 0 (camera frame)."""
    u, v = pixel
    if not (0 <= u < camera.width and 0 <= v < camera.height):
        raise CameraError(f"pixel ({u}, {v}) is outside the {camera.width} x {camera.height} image")
    ray = np.array([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0])
    along = normal @ ray
    if abs(along) < 1e-9 or -offset / along <= 0:
        raise CameraError(f"the ray through pixel ({u}, {v}) does not meet the table plane")
    return ray * (-offset / along)


def calibrate_on_table(depth_m: np.ndarray, camera: CameraConfig, *, p_BP, table_pixel=None,
                       x_pixel=None, mask: np.ndarray | None = None, seed: int = 0) -> TableCalibration:
    """`camera` with the pose X_BC that puts the base frame on the table plane seen in `depth_m` (see the
    module's text); a CameraError when the frame shows no table plane or a pixel misses it."""
    p_C = points_in_camera(depth_m, camera, mask)
    if len(p_C) < 100:
        raise CameraError(f"the frame has {len(p_C)} readings in the camera's depth range: too few to find "
                          "a table")
    normal, offset = fit_plane(p_C, seed=seed)
    normal, offset = refine_plane(p_C, normal, offset)
    if offset < 0:  # the normal points from the table toward the camera (the origin of C)
        normal, offset = -normal, -offset
    distances = p_C @ normal + offset
    on_table = np.abs(distances) <= PLANE_DISTANCE
    share = float(on_table.mean())
    if share < MIN_TABLE_SHARE:
        raise CameraError(f"the dominant plane holds only {100 * share:.0f} % of the readings: the frame "
                          f"shows no table (at least {100 * MIN_TABLE_SHARE:.0f} % needed); mask the rest "
                          "out (--mask)")
    tilt = float(np.degrees(np.arccos(np.clip(-normal[2], -1.0, 1.0))))  # optical axis +z_C vs. -n
    if tilt > MAX_TILT_DEG:
        raise CameraError(f"the camera sees the dominant plane {tilt:.0f} deg from straight on: that is a "
                          "wall, or the camera looks along the table, not down at it")
    table_pixel = table_pixel if table_pixel is not None else (camera.cx, camera.cy)
    p_CP = pixel_on_plane(table_pixel, camera, normal, offset)
    if x_pixel is not None:
        toward = pixel_on_plane(x_pixel, camera, normal, offset) - p_CP
    else:
        toward = np.array([0.0, -1.0, 0.0])  # the image's up direction
    x = toward - (toward @ normal) * normal
    if np.linalg.norm(x) < 1e-6:
        raise CameraError("the base's +x direction lies along the table's normal: name a second table pixel "
                          "(--x-pixel) away from the first")
    x /= np.linalg.norm(x)
    R_CT = RotationMatrix(np.column_stack([x, np.cross(normal, x), normal]))  # table frame T: z up, at P
    X_CT = RigidTransform(R_CT, p_CP)
    X_BT = RigidTransform(np.asarray(p_BP, dtype=float))
    X_BC = X_BT @ X_CT.inverse()
    placed = dc.replace(camera, xyz=[float(c) for c in X_BC.translation()],
                        rpy_deg=[float(a) for a in np.degrees(RollPitchYaw(X_BC.rotation()).vector())])
    rms = float(np.sqrt(np.mean(distances[on_table] ** 2)))
    return TableCalibration(placed, rms, share, float(offset), tilt)
