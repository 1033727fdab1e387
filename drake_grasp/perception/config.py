"""What the cell sees and makes of it: its cameras, its workspace box, what perception keeps besides the
objects, and the grasp candidates drawn on the object cloud. The simulated cell reads them from a
scenario's `sensing` and `sampling`; `detect` and the grasp service take the workspace, the perception
options and the sampling (their camera comes with each frame)."""

# No `from __future__ import annotations`: yaml_load_typed reads the dataclass field types.
import dataclasses as dc

from drake_grasp.perception.camera import CameraConfig
from drake_grasp.robot.task import SAMPLERS


@dc.dataclass
class PerceptionConfig:
    """Scene structure and free space (`perception.cloud`); the defaults see objects on a bare table."""

    # Segments (`cloud.segment_objects`) whose footprint is longer than this are scene structure
    # (furniture, a shelf): no grasp candidates on them, but part of the CNN's input and of the planning
    # world [m]; 0: every point above the table belongs to an object.
    structure_extent: float = 0.0
    # The cloud carries its cameras' rays, so that planning counts the space a camera saw through as free
    # (a camera from the side sees under a shelf); False: under an observed surface is occupied.
    free_space: bool = False
    # Isolated points above the table (`cloud.remove_specks`: a real sensor's noise) are dropped. Off in the
    # simulated cell, whose clouds have few (its objects' sparse edge points are most of what it drops);
    # `detect`, which reads real frames, turns it on.
    remove_specks: bool = False

    def __post_init__(self) -> None:
        if self.structure_extent < 0.0:
            raise ValueError(f"structure_extent must be >= 0, got {self.structure_extent}")


WORKSPACE_LOWER = (0.12, -0.75, -0.02)  # the cell's workspace box in the robot's base frame [m]
WORKSPACE_UPPER = (1.28, 0.75, 0.30)


@dc.dataclass
class WorkspaceBox:
    """The part of the cameras' view that is workspace: points outside this box (the robot's base frame)
    are cropped before segmentation [m]."""

    lower: list[float] = dc.field(default_factory=lambda: list(WORKSPACE_LOWER))
    upper: list[float] = dc.field(default_factory=lambda: list(WORKSPACE_UPPER))

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """ValueError for a box that is not one (also for one loaded from YAML)."""
        if len(self.lower) != 3 or len(self.upper) != 3 or any(
                not lo < hi for lo, hi in zip(self.lower, self.upper, strict=True)):
            raise ValueError(f"the workspace box needs 3 numbers a corner and lower < upper on every axis, "
                             f"got {list(self.lower)} .. {list(self.upper)}")


@dc.dataclass
class SensingConfig:
    """A cell's depth cameras (fixed in the robot's base frame), its workspace and its perception."""

    camera: CameraConfig = dc.field(default_factory=CameraConfig)
    # More depth cameras: their clouds join the first's (base frame) before segmentation.
    extra_cameras: list[CameraConfig] = dc.field(default_factory=list)
    workspace: WorkspaceBox = dc.field(default_factory=WorkspaceBox)
    perception: PerceptionConfig = dc.field(default_factory=PerceptionConfig)

    @property
    def cameras(self) -> list[CameraConfig]:
        """Every camera, the first first."""
        return [self.camera, *self.extra_cameras]

    @property
    def camera_positions(self) -> tuple[tuple[float, float, float], ...]:
        """Where the depth cameras stand (base frame), the first camera first."""
        return tuple(tuple(float(v) for v in c.xyz) for c in self.cameras)


@dc.dataclass
class SamplingConfig:
    """The grasp candidates drawn on an object cloud before a policy ranks them (`policy.sampling`)."""

    num_candidates: int = 500
    # Approach angles from straight down, drawn uniformly in [low, high] [deg]
    gamma_deg: list[float] = dc.field(default_factory=lambda: [0.0, 90.0])
    # Which sampler draws them (`robot.task.SAMPLERS`): "uniform" (the paper's: grasp points on the
    # cloud, random approach and roll), "gpg" (hand placements centred on the cloud and pushed in until
    # they would touch it), "mixed" (half of each) or "topdown"
    sampler: str = "uniform"
    # GPG's hand, pushed in, stops where it would touch the table (flat objects get shallow grasps)
    # instead of being dropped when it would go below it
    gpg_stop_at_table: bool = False

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """ValueError naming a field out of its range (also for one loaded from YAML)."""
        if self.num_candidates < 1:
            raise ValueError(f"num_candidates must be >= 1, got {self.num_candidates}")
        if len(self.gamma_deg) != 2 or not 0.0 <= self.gamma_deg[0] <= self.gamma_deg[1] <= 90.0:
            raise ValueError(f"gamma_deg needs [low, high] with 0 <= low <= high <= 90, got {self.gamma_deg}")
        if self.sampler not in SAMPLERS:
            raise ValueError(f"unknown sampler '{self.sampler}'; choose one of: {', '.join(SAMPLERS)}")
