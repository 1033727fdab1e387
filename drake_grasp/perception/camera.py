"""A depth camera outside the simulator: its YAML description, depth files, and back-projection.

Camera YAML (`CameraConfig`, loaded with Drake's `yaml_load_typed`): the pinhole
intrinsics of the depth image and the camera's pose in the robot's base frame B,
camera frame C as in Drake and OpenCV (+x right, +y down, +z forward, along the
optical axis):

    width: 640
    height: 480
    fx: 461.04        # focal lengths [px]
    fy: 461.04
    cx: 319.5         # principal point [px]
    cy: 239.5
    xyz: [0.55, 0.0, 1.3]        # p_BC [m]
    rpy_deg: [180.0, 0.0, 0.0]   # R_BC as roll, pitch, yaw [deg]
    depth_range: [0.1, 3.0]      # readings outside are dropped [m] (optional: this default)

Every other field must be given: a missing one is an error naming it (a RealSense's own
intrinsics replace the file's, so its file needs only the pose).

Depth files: PNG of 16-bit integers in millimetres (what most RGB-D drivers save),
`.npy` or OpenEXR `.exr` of floats in metres. Zero or non-finite pixels mean "no
reading". Each format's unit is checked against the values (a metre image saved as
millimetres reads as a few millimetres; a millimetre image as metres reads as
hundreds of metres) and refused with the fix when it does not fit.
"""

# No `from __future__ import annotations`: yaml_load_typed reads the dataclass field types.
import dataclasses as dc
import math
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

DEPTH_FORMATS = (".png", ".npy", ".exr")
PLAUSIBLE_DEPTH_M = (0.05, 20.0)  # a depth camera's median reading lies in here [m]
# The simulated cell's camera: 640 x 480 with a 55 degree vertical field of view, square pixels [px]
SIMULATED_FOCAL = 240.0 / math.tan(math.radians(55.0) / 2)


class CameraError(ValueError):
    """A camera description or depth image that cannot be used; the message names the problem."""


@dc.dataclass
class CameraConfig:
    """Pinhole intrinsics and the camera's pose X_BC in the robot's base frame: a real camera's, and the
    simulated cell's (a scenario's `sensing.camera`, rendered with these intrinsics; the defaults are
    its camera above the table, looking straight down)."""

    width: int = 640
    height: int = 480
    fx: float = SIMULATED_FOCAL
    fy: float = SIMULATED_FOCAL
    cx: float = 319.5
    cy: float = 239.5
    xyz: list[float] = dc.field(default_factory=lambda: [0.55, 0.0, 1.3])
    rpy_deg: list[float] = dc.field(default_factory=lambda: [180.0, 0.0, 0.0])
    depth_range: list[float] = dc.field(default_factory=lambda: [0.1, 3.0])

    @property
    def X_BC(self) -> RigidTransform:
        return RigidTransform(RollPitchYaw(np.radians(self.rpy_deg)), self.xyz)

    def check(self) -> None:
        if self.width < 1 or self.height < 1:
            raise CameraError(f"camera size must be positive, got {self.width} x {self.height}")
        if not (self.fx > 0 and self.fy > 0):
            raise CameraError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        if len(self.xyz) != 3 or len(self.rpy_deg) != 3 or len(self.depth_range) != 2:
            raise CameraError("xyz and rpy_deg need 3 numbers each, depth_range 2")
        if not 0 <= self.depth_range[0] < self.depth_range[1]:
            raise CameraError(f"depth_range must be [near, far] with 0 <= near < far, got {self.depth_range}")

    def scaled(self, factor: int) -> "CameraConfig":
        """The same camera at `factor` times its resolution (the same field of view)."""
        return dc.replace(self, width=self.width * factor, height=self.height * factor, fx=self.fx * factor,
                          fy=self.fy * factor, cx=(self.cx + 0.5) * factor - 0.5,
                          cy=(self.cy + 0.5) * factor - 0.5)

    def placed(self, X_BC: RigidTransform) -> "CameraConfig":
        """This camera (its intrinsics and depth range) with its optical frame at X_BC."""
        rpy_deg = np.degrees(RollPitchYaw(X_BC.rotation()).vector()).tolist()
        return dc.replace(self, xyz=[float(v) for v in X_BC.translation()], rpy_deg=rpy_deg)

    @staticmethod
    def looking_at(xyz, target, **intrinsics) -> "CameraConfig":
        """A camera at `xyz` whose optical axis (+z_C) points at `target`, image +y_C as far down as it
        goes (image right horizontal); `intrinsics` as the fields (default: the simulated camera's)."""
        z = np.asarray(target, float) - np.asarray(xyz, float)
        z /= np.linalg.norm(z)
        x = np.cross([0.0, 0.0, -1.0], z)
        if np.linalg.norm(x) < 1e-9:  # looking straight down: image right along +x
            x = np.array([1.0, 0.0, 0.0])
        x /= np.linalg.norm(x)
        R_BC = RotationMatrix(np.column_stack([x, np.cross(z, x), z]))
        return CameraConfig(**intrinsics).placed(RigidTransform(R_BC, np.asarray(xyz, float)))


POSE_FIELDS = ("xyz", "rpy_deg")
INTRINSIC_FIELDS = ("width", "height", "fx", "fy", "cx", "cy")


def load_camera(path: str | Path, *, intrinsics: bool = True, pose: bool = True) -> CameraConfig:
    """The camera a YAML file describes. It must state its pose (with `pose`; not for a camera still to be
    placed) and, with `intrinsics` (not for a device that reports its own), its size and intrinsics: a
    missing one is a CameraError naming it (only depth_range has a default)."""
    from pydrake.common.yaml import yaml_load

    path = Path(path)
    if not path.is_file():
        raise CameraError(f"camera file not found: {path}")
    try:
        given = yaml_load(filename=str(path))
        camera = yaml_load_typed(schema=CameraConfig, filename=str(path))
    except (RuntimeError, ValueError) as e:
        raise CameraError(f"invalid camera file {path}: {str(e).splitlines()[0]}") from None
    needed = (INTRINSIC_FIELDS if intrinsics else ()) + (POSE_FIELDS if pose else ())
    missing = [name for name in needed if name not in (given or {})]
    if missing:
        raise CameraError(f"camera file {path} lacks {', '.join(missing)}: a camera must state "
                          f"{', '.join(needed)} (depth_range is optional)")
    camera.check()
    return camera


def save_camera(camera: CameraConfig, path: str | Path) -> None:
    Path(path).write_text(yaml_dump_typed(camera))


def load_depth(path: str | Path) -> np.ndarray:
    """A depth image in metres, (height, width) float32, NaN where there is no reading."""
    path = Path(path)
    if not path.is_file():
        raise CameraError(f"depth file not found: {path}")
    suffix = path.suffix.lower()
    readers = {".png": _read_png_mm, ".npy": _read_npy, ".exr": _read_exr}
    if suffix not in readers:
        raise CameraError(f"unknown depth format '{suffix}'; use one of: {', '.join(DEPTH_FORMATS)}")
    depth = np.asarray(readers[suffix](path), dtype=np.float32)
    if depth.ndim == 3 and depth.shape[2] == 1:
        depth = depth[..., 0]
    if depth.ndim != 2:
        raise CameraError(f"a depth image must be 2-D (height, width), got shape {depth.shape}")
    depth = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan)
    valid = depth[np.isfinite(depth)]
    if valid.size == 0:
        raise CameraError(f"{path.name} has no valid depth pixel (all zero or NaN)")
    median = float(np.median(valid))
    lo, hi = PLAUSIBLE_DEPTH_M
    if suffix == ".png" and median < lo:
        raise CameraError(f"{path.name} reads as {median * 1000:.1f} mm at the median: it looks like metres, "
                          "but a depth PNG must hold millimetres (multiply by 1000)")
    if suffix != ".png" and median > hi:
        raise CameraError(f"{path.name} reads as {median:.0f} m at the median: it looks like millimetres, "
                          f"but {suffix} depth must be in metres (divide by 1000)")
    if not lo <= median <= hi:
        raise CameraError(f"{path.name}: a median depth of {median:.3g} m is no depth camera's")
    return depth


def _read_npy(path: Path) -> np.ndarray:
    depth = np.load(path, allow_pickle=False)
    if depth.dtype.kind in "iu":
        raise CameraError(f"{path.name} holds integers: a .npy depth image must be float metres "
                          "(save millimetres as a 16-bit PNG, or divide by 1000)")
    return depth


def _read_png_mm(path: Path) -> np.ndarray:
    from PIL import Image

    try:
        image = Image.open(path)
        image.load()
    except OSError as e:  # PIL's UnidentifiedImageError and truncated files are OSErrors
        raise CameraError(f"{path.name} is not a readable PNG: {e}") from None
    if image.mode not in ("I;16", "I;16B", "I"):
        raise CameraError(f"{path.name} is an 8-bit or colour image ({image.mode}): a depth PNG must hold "
                          "16-bit integers in millimetres")
    return np.asarray(image, dtype=np.float32) / 1000.0


def _read_exr(path: Path) -> np.ndarray:
    import OpenEXR

    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = exr.channels()
            name = next((n for n in ("Z", "depth", "Y", "R") if n in channels), next(iter(channels)))
            return np.asarray(channels[name].pixels, dtype=np.float32)
    except Exception as e:  # OpenEXR raises several types for a file it cannot read
        raise CameraError(f"{path.name} is not a readable OpenEXR depth image: {e}") from None


def save_depth_png(depth_m: np.ndarray, path: str | Path) -> None:
    """A depth image [m] as a 16-bit PNG in millimetres (0: no reading)."""
    from PIL import Image

    mm = np.where(np.isfinite(depth_m), np.round(np.asarray(depth_m) * 1000.0), 0)
    Image.fromarray(np.clip(mm, 0, 65535).astype(np.uint16)).save(path)


def points_in_camera(depth_m: np.ndarray, camera: CameraConfig, mask: np.ndarray | None = None) -> np.ndarray:
    """The image's readings within the camera's depth range (and, with `mask`, its non-zero pixels) as
    (N, 3) points in the camera frame C, in row-major pixel order."""
    if depth_m.shape != (camera.height, camera.width):
        raise CameraError(f"the depth image is {depth_m.shape[1]} x {depth_m.shape[0]} but the camera's "
                          f"intrinsics are for {camera.width} x {camera.height}")
    z = depth_m.astype(np.float64).ravel()
    near, far = camera.depth_range
    keep = (z >= near) & (z <= far)  # (NaN compares false)
    if mask is not None:
        keep &= np.asarray(mask, dtype=bool).ravel()
    pixels = np.flatnonzero(keep)
    z = z[pixels]
    v, u = np.divmod(pixels, camera.width)
    p_C = np.empty((len(z), 3))
    p_C[:, 0] = (u - camera.cx) * z / camera.fx
    p_C[:, 1] = (v - camera.cy) * z / camera.fy
    p_C[:, 2] = z
    return p_C


def points_in_base(depth_m: np.ndarray, camera: CameraConfig, mask: np.ndarray | None = None) -> np.ndarray:
    """The image's readings within the camera's depth range (and `mask`) as (N, 3) points in the base
    frame."""
    p_C = points_in_camera(depth_m, camera, mask)
    X_BC = camera.X_BC
    return p_C @ X_BC.rotation().matrix().T + X_BC.translation()


def load_mask(path: str | Path, shape: tuple[int, int]) -> np.ndarray:
    """A workspace mask image (any PNG; non-zero pixels are workspace) as a (height, width) bool array the
    size of the depth image; a CameraError names a missing, unreadable, mis-sized or empty mask."""
    from PIL import Image

    path = Path(path)
    if not path.is_file():
        raise CameraError(f"mask file not found: {path}")
    try:
        image = Image.open(path)
        image.load()
    except OSError as e:
        raise CameraError(f"{path.name} is not a readable image: {e}") from None
    mask = np.asarray(image)
    mask = mask.any(axis=2) if mask.ndim == 3 else mask != 0
    if mask.shape != tuple(shape):
        raise CameraError(f"the mask {path.name} is {mask.shape[1]} x {mask.shape[0]} but the depth image is "
                          f"{shape[1]} x {shape[0]}")
    if not mask.any():
        raise CameraError(f"the mask {path.name} has no non-zero pixel: nothing would be workspace")
    return mask


def project_to_image(p_B: np.ndarray, camera: CameraConfig) -> np.ndarray:
    """(N, 2) pixel coordinates (u, v) of base-frame points; NaN behind the camera."""
    X_CB = camera.X_BC.inverse()
    p_C = np.asarray(p_B, dtype=np.float64) @ X_CB.rotation().matrix().T + X_CB.translation()
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.column_stack([camera.fx * p_C[:, 0] / p_C[:, 2] + camera.cx,
                              camera.fy * p_C[:, 1] / p_C[:, 2] + camera.cy])
    uv[p_C[:, 2] <= 0] = np.nan
    return uv
