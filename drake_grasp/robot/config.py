"""Physics and control configuration of every plant the project builds (typed, YAML-loadable).

Contact model, chosen deliberately: discrete SAP at a 2 ms step with hydroelastic
contact and point-contact fallback. Objects are compliant hydroelastic; fingers,
palm and table are rigid hydroelastic; arm links fall back to point contact.
Box-on-box point contact is physically wrong (one diagonal contact, the object
sinks), and SAP is what makes the plant's implicit PD actuators and the finger
coupler work (TAMSI ignores PD gains). Labels of borderline grasps change with the
contact model, so trials and the closed loop share this one configuration.
"""

from __future__ import annotations

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


@dc.dataclass
class ControlConfig:
    """Gains of the position-controlled arm, fingers and floating-hand mount.

    Arm joint i gets kp = `arm_kp_per_effort` x its effort limit (kd the same way):
    stiff like a position-controlled arm. The mount's gains make the floating hand
    of the grasp trials as stiff as that arm.
    """

    arm_kp_per_effort: float = 100.0  # [1/rad]
    arm_kd_per_effort: float = 10.0  # [s/rad]
    finger: PdGains = dc.field(default_factory=lambda: PdGains(kp=2000.0, kd=20.0))
    mount_translation: PdGains = dc.field(default_factory=lambda: PdGains(kp=2.0e4, kd=4.0e2))
    mount_rotation: PdGains = dc.field(default_factory=lambda: PdGains(kp=5.0e2, kd=5.0))
