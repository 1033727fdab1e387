"""Arm specifications: published kinematics, limits and the home configuration.

The numbers here are the single source for the generated arm models in `sdf/`
(see `tools/generate_models.py`) and for everything that needs joint limits
(IK, OMPL state bounds, time parameterization). Any other URDF or SDF arm comes in
through a YAML description (`drake_grasp.robot.arms`): `get_robot("path/to/arm.yaml")`.
"""

from __future__ import annotations

import dataclasses as dc
from dataclasses import dataclass

import numpy as np

from drake_grasp.robot.hand import HandSpec, default_hand


@dataclass(frozen=True)
class DhTable:
    """A Denavit-Hartenberg table; `modified` selects Craig's convention.

    Modified (Craig): X_{i-1,i} = RotX(alpha_{i-1}) TransX(a_{i-1}) RotZ(q_i) TransZ(d_i).
    Standard: X_{i-1,i} = RotZ(q_i) TransZ(d_i) TransX(a_i) RotX(alpha_i).
    `flange_d` is a final offset along the last z axis (0 for UR5, whose tool
    frame is already DH frame 6).
    """

    modified: bool
    a: tuple[float, ...]
    d: tuple[float, ...]
    alpha: tuple[float, ...]
    flange_d: float = 0.0


@dataclass(frozen=True)
class RobotSpec:
    """Everything the station and the planner need to know about one arm."""

    name: str
    model_url: str
    base_link: str
    flange_link: str
    joint_names: tuple[str, ...]
    q_home: tuple[float, ...]
    q_lower: tuple[float, ...]
    q_upper: tuple[float, ...]
    v_max: tuple[float, ...]
    effort_max: tuple[float, ...]
    dh: DhTable | None = None
    source: str = ""  # what get_robot takes to make this spec again (a name or a YAML path)
    # Arms from a YAML file: the hand's pose on the flange, joint 1's centre and a bound on the
    # flange's distance from it (computed from the model), and the RP weights for this arm.
    mount_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mount_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    shoulder: tuple[float, float, float] = (0.0, 0.0, 0.0)
    reach: float = 0.0
    reachability_weights: str = ""
    model_file: str = ""  # the user's model file (model_url is its prepared copy), named in messages
    hand: HandSpec = dc.field(default_factory=default_hand)  # the hand on the flange

    def with_hand(self, hand: HandSpec) -> RobotSpec:
        """The same arm with another hand on its flange (mounted as `mount_xyz`, `mount_rpy_deg` say)."""
        return dc.replace(self, hand=hand)

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array(self.q_lower), np.array(self.q_upper)

    def shoulder_and_reach(self) -> tuple[np.ndarray, float]:
        """Joint 2's centre in the base frame and an upper bound on the flange's distance from it.

        The bound is the sum of the link offsets beyond joint 2: no configuration
        puts the flange farther away, so a farther target has no IK solution.
        """
        dh = self.dh
        if dh is None:
            return np.array(self.shoulder), self.reach
        first = 2 if dh.modified else 1
        lengths = [float(np.hypot(dh.a[i], dh.d[i])) for i in range(first, len(dh.a))]
        return np.array([0.0, 0.0, dh.d[0]]), sum(lengths) + dh.flange_d


_PI = np.pi

PANDA = RobotSpec(
    name="panda",
    source="panda",
    model_url="package://drake_grasp/panda.sdf",
    base_link="panda_link0",
    flange_link="panda_link8",
    joint_names=tuple(f"panda_joint{i}" for i in range(1, 8)),
    q_home=(0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785),
    # Franka Emika datasheet (FR3/Panda robot and interface specifications).
    q_lower=(-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973),
    q_upper=(2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973),
    v_max=(2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61),
    effort_max=(87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0),
    dh=DhTable(
        modified=True,
        a=(0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088),
        d=(0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0),
        alpha=(0.0, -_PI / 2, _PI / 2, _PI / 2, -_PI / 2, _PI / 2, _PI / 2),
        flange_d=0.107,
    ),
)

UR5 = RobotSpec(
    name="ur5",
    source="ur5",
    model_url="package://drake_grasp/ur5.sdf",
    base_link="ur5_link0",
    flange_link="ur5_tool0",
    joint_names=(
        "ur5_shoulder_pan",
        "ur5_shoulder_lift",
        "ur5_elbow",
        "ur5_wrist_1",
        "ur5_wrist_2",
        "ur5_wrist_3",
    ),
    q_home=(3.1416, -2.0, 1.7, -1.271, -1.571, 0.0),
    # Universal Robots UR5 (CB3) technical specifications.
    q_lower=(-2 * _PI,) * 6,
    q_upper=(2 * _PI,) * 6,
    v_max=(3.15,) * 6,
    effort_max=(150.0, 150.0, 150.0, 28.0, 28.0, 28.0),
    dh=DhTable(
        modified=False,
        a=(0.0, -0.425, -0.39225, 0.0, 0.0, 0.0),
        d=(0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823),
        alpha=(_PI / 2, 0.0, 0.0, _PI / 2, -_PI / 2, 0.0),
    ),
)

ROBOTS: dict[str, RobotSpec] = {spec.name: spec for spec in (PANDA, UR5)}
