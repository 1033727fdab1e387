"""Physics and control configuration of every plant the project builds (typed, YAML-loadable).

Contact model, chosen deliberately: discrete SAP at a 2 ms step with hydroelastic
contact and point-contact fallback. Objects are compliant hydroelastic; fingers,
palm and table are rigid hydroelastic; arm links fall back to point contact.
Box-on-box point contact is physically wrong (one diagonal contact, the object
sinks), and SAP is what makes the plant's implicit PD actuators and the finger
coupler work (TAMSI ignores PD gains). Labels of borderline grasps change with the
contact model, so trials and the closed loop share this one configuration.
"""

# No `from __future__ import annotations`: yaml_load_typed reads the dataclass field types.
import dataclasses as dc

from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.multibody.tree import PdControllerGains

DEFAULT_TIME_STEP = 0.002  # [s] of the grasp trials that label the CNN; the closed-loop scenarios step 4 ms


def default_plant_config() -> MultibodyPlantConfig:
    return MultibodyPlantConfig(time_step=DEFAULT_TIME_STEP, discrete_contact_approximation="sap",
                                contact_model="hydroelastic_with_fallback")


@dc.dataclass
class PdGains:
    """Proportional and derivative gains of an implicit PD actuator (SI units of its joint)."""

    kp: float
    kd: float

    def to_drake(self) -> PdControllerGains:
        return PdControllerGains(p=self.kp, d=self.kd)


MAX_GRIP_FORCE = 140.0  # [N] the Franka hand's peak grasp force
GRIP_SATURATION = 0.007  # [m] a force-controlled grip is at full force this far or more from closed
GRIP_CLOSING_SPEED = 0.35  # [m/s] a force-controlled grip's fingers close at most this fast, either finger


@dc.dataclass
class ControlConfig:
    """Gains of the position-controlled arm, fingers and floating-hand mount, and how the hand grips.

    Arm joint i gets kp = `arm_kp_per_effort` x its effort limit (kd the same way):
    stiff like a position-controlled arm. The mount's gains make the floating hand
    of the grasp trials as stiff as that arm.

    The grip: with `grip_force` None the driven finger is the PD spring `finger` under the hand
    model's effort limit (40 N, shared by the two fingers through the coupler: up to 20 N on the
    object, and less on a narrow one, 2000 N/m x the finger's travel), as the grasp trials that
    label the CNN grip. With a force [N], the grip is force-controlled as a Franka hand's `grasp`
    action is: each finger presses the object with that force whatever its width (the effort limit
    is twice it, and the PD is stiff enough to reach it `GRIP_SATURATION` short of closed); the
    Franka hand's rated continuous grasp force is 70 N.
    """

    arm_kp_per_effort: float = 100.0  # [1/rad]
    arm_kd_per_effort: float = 10.0  # [s/rad]
    finger: PdGains = dc.field(default_factory=lambda: PdGains(kp=2000.0, kd=20.0))
    mount_translation: PdGains = dc.field(default_factory=lambda: PdGains(kp=2.0e4, kd=4.0e2))
    mount_rotation: PdGains = dc.field(default_factory=lambda: PdGains(kp=5.0e2, kd=5.0))
    grip_force: float | None = None  # [N] on the object (see above)

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """ValueError for a grip force out of the hand's range (also for one loaded from YAML)."""
        if self.grip_force is not None and not 0.0 < self.grip_force <= MAX_GRIP_FORCE:
            raise ValueError(f"grip_force must be in (0, {MAX_GRIP_FORCE:g}] N (the Franka hand's peak), "
                             f"got {self.grip_force}")

    def finger_actuation(self, joint_per_metre: float = 1.0) -> tuple[PdGains, float | None]:
        """The hand's driven joint's PD gains and its effort limit (None: the hand's own), in the joint's
        units: `joint_per_metre` of its travel per metre of one finger's (`HandSpec.joint_per_metre`; 1
        for a prismatic finger), so that a finger feels the same spring or force on any hand."""
        self.check()
        if self.grip_force is None:
            scale = joint_per_metre**2
            return PdGains(kp=self.finger.kp / scale, kd=self.finger.kd / scale), None
        effort = 2.0 * self.grip_force / joint_per_metre  # (both fingers press: twice the work)
        return PdGains(kp=effort / (GRIP_SATURATION * joint_per_metre),
                       kd=effort / (GRIP_CLOSING_SPEED * joint_per_metre)), effort
