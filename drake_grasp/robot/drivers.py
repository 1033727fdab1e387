"""The messages a cell's robot drivers speak: Drake's LCM driver messages, their channels and rates.

The arm: `lcmt_panda_command` (joint positions) and `lcmt_panda_status` (measured positions and
velocities), as Drake's Franka driver sends them, for an arm of any joint count; the gripper:
`lcmt_schunk_wsg_command` (opening and force limit) and `lcmt_schunk_wsg_status` (opening and its
rate), the messages of Drake's gripper drivers (the opening is the distance between the fingers, twice
each finger's travel); the depth camera: `lcmt_image_array` with a 32-bit float depth image in metres,
as Drake's camera publishers send it. `cell.hardware.HardwareStation` speaks them to a robot;
`simulation.lcm_drivers` answers them from the simulated station.
"""

# No `from __future__ import annotations`: yaml_load_typed reads the dataclass field types.
import dataclasses as dc

DEFAULT_LCM_URL = ""  # LCM's own default (udpm://239.255.76.67:7667?ttl=0, this machine's network)


@dc.dataclass
class DriverChannels:
    """The LCM network, channels and rates of a cell's drivers."""

    lcm_url: str = DEFAULT_LCM_URL  # "memq://": in this process only (tests, one-process simulations)
    arm_command: str = "PANDA_COMMAND"
    arm_status: str = "PANDA_STATUS"
    hand_command: str = "SCHUNK_WSG_COMMAND"
    hand_status: str = "SCHUNK_WSG_STATUS"
    images: str = "DRAKE_RGBD_CAMERA_IMAGES"
    command_period: float = 0.005  # [s] arm and gripper commands (and the simulated drivers' status)
    image_period: float = 0.1  # [s] the simulated camera's images
    grip_force: float = 40.0  # [N] the gripper's force limit in every command

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """ValueError naming a rate or force out of range, or an empty channel name."""
        if self.command_period <= 0 or self.image_period <= 0:
            raise ValueError(f"command_period and image_period must be > 0 s, got {self.command_period}, "
                             f"{self.image_period}")
        if self.grip_force <= 0:
            raise ValueError(f"grip_force must be > 0 N, got {self.grip_force}")
        names = (self.arm_command, self.arm_status, self.hand_command, self.hand_status, self.images)
        if not all(names) or len(set(names)) != len(names):
            raise ValueError(f"the five channels need distinct, non-empty names, got {names}")

    @staticmethod
    def check_hand(hand) -> None:
        """ValueError unless the gripper messages fit `hand` (a `HandSpec`): they carry the jaws' opening,
        each of two coupled fingers traveling half of it, as the hand's driven joint does."""
        if hand.closed_position != 0.0 or abs(2 * hand.open_position - hand.stroke) > 1e-9 or len(
                hand.coupled_joints) != 1:
            raise ValueError(f"the gripper messages carry the jaws' opening, each of two coupled fingers "
                             f"half of it; the '{hand.name}' hand's driven joint is not one finger's travel")

    def make_lcm(self):
        """A `DrakeLcm` on the network `lcm_url` names."""
        from pydrake.lcm import DrakeLcm

        return DrakeLcm(self.lcm_url) if self.lcm_url else DrakeLcm()
