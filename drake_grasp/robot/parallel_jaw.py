"""Parallel-jaw hands made from their sizes: a palm box and two coupled prismatic finger pads.

`parallel_jaw_sdf` writes such a hand's model from a hand file's sizes (the Franka hand's
`sdf/hand.sdf` is made so from `sdf/hands/franka.yaml`); `random_hand` draws one of a family
of such hands (strokes 5-14 cm, fingers 3.5-8 cm long, pads 1-3 cm wide; the wide family also palms
4-9 cm wide, fingers up to 3.5 cm thick and grasp depths of 0.5-2 cm), deterministic from (seed, k),
for trials of many hands; `write_hand` writes its model and its hand file.
"""

from __future__ import annotations

import dataclasses as dc
from pathlib import Path

import numpy as np

from drake_grasp.robot.hand import HandConfig

PALM_MASS = 0.73  # [kg] the Franka hand's
FINGER_MASS = 0.015  # [kg]
PAD_FRICTION, PALM_FRICTION = 1.0, 0.5
# The family `random_hand` draws from [m]
STROKES = (0.05, 0.14)
FINGER_LENGTHS = (0.035, 0.08)
PAD_WIDTHS = (0.01, 0.03)
FINGER_THICKNESSES = (0.008, 0.016)
PALM_DEPTHS = (0.045, 0.09)
TIP_BEYOND_TCP = 0.01  # the TCP lies this far short of the fingertips, as the Franka hand's
# The wide family's other sizes (`random_hand(wide=True)`) [m]
WIDE_PALM_WIDTHS = (0.04, 0.09)
WIDE_FINGER_THICKNESSES = (0.006, 0.035)
WIDE_GRASP_DEPTHS = (0.005, 0.02)


def _fmt(values) -> str:
    return " ".join(f"{v:.12g}" for v in values)


def _inertial(centre, mass: float, size) -> str:
    x, y, z = size
    ixx, iyy, izz = mass * (y * y + z * z) / 12, mass * (x * x + z * z) / 12, mass * (x * x + y * y) / 12
    return (f"    <inertial>\n      <pose>{_fmt(centre)} 0 0 0</pose>\n      <mass>{mass:.6g}</mass>\n"
            f"      <inertia><ixx>{ixx:.6g}</ixx><ixy>0</ixy><ixz>0</ixz><iyy>{iyy:.6g}</iyy><iyz>0</iyz>"
            f"<izz>{izz:.6g}</izz></inertia>\n    </inertial>\n")


def _rigid(mu: float) -> str:
    return (f"<drake:proximity_properties><drake:rigid_hydroelastic/>"
            f"<drake:mu_dynamic>{mu}</drake:mu_dynamic><drake:mu_static>{mu}</drake:mu_static>"
            f"</drake:proximity_properties>")


def _material(rgba) -> str:
    return f"<material><diffuse>{_fmt(rgba)}</diffuse></material>"


def parallel_jaw_sdf(hand: HandConfig) -> str:
    """The SDF of a hand file's sizes: the palm box (`palm_size` x `palm_depth`) on the flange, two finger
    pads (`finger_size` x `finger_length`) on prismatic joints that open `stroke / 2` each, the right one
    unactuated (the hand file couples it), the left one's effort limit `grip_force`; a `tcp` frame."""
    palm_depth, travel = hand.palm_depth, hand.stroke / 2
    palm = (*hand.palm_size, palm_depth)
    finger = (*hand.finger_size, hand.finger_length)
    grey, dark = (0.9, 0.9, 0.9, 1), (0.2, 0.2, 0.2, 1)

    def finger_link(side: str, sign: int, effort: float) -> str:
        centre = (0, sign * finger[1] / 2, finger[2] / 2)
        box = f"<box><size>{_fmt(finger)}</size></box>"
        return (
            f"  <link name='{side}_finger'>\n    <pose relative_to='hand'>0 0 {palm_depth} 0 0 0</pose>\n"
            + _inertial(centre, FINGER_MASS, finger)
            + f"    <collision name='{side}_pad'><pose>{_fmt(centre)} 0 0 0</pose><geometry>{box}</geometry>"
            f"{_rigid(PAD_FRICTION)}</collision>\n"
            f"    <visual name='{side}_pad_v'><pose>{_fmt(centre)} 0 0 0</pose><geometry>{box}</geometry>"
            f"{_material(dark)}</visual>\n  </link>\n"
            f"  <joint name='{side}_finger_joint' type='prismatic'>\n    <parent>hand</parent>"
            f"<child>{side}_finger</child>\n    <axis><xyz>0 {sign} 0</xyz><limit><lower>0</lower>"
            f"<upper>{travel}</upper><effort>{effort}</effort><velocity>0.2</velocity>"
            f"</limit><dynamics><damping>1</damping></dynamics></axis>\n  </joint>\n"
        )

    box = f"<box><size>{_fmt(palm)}</size></box>"
    palm_pose = f"<pose>0 0 {palm_depth / 2} 0 0 0</pose>"
    return (
        "<?xml version='1.0'?>\n<sdf version='1.9' xmlns:drake='http://drake.mit.edu'>\n"
        "  <model name='hand'>\n  <link name='hand'>\n"
        + _inertial((0, 0, palm_depth / 2), PALM_MASS, palm)
        + f"    <collision name='palm'>{palm_pose}<geometry>{box}</geometry>"
        f"{_rigid(PALM_FRICTION)}</collision>\n"
        f"    <visual name='palm_v'>{palm_pose}<geometry>{box}</geometry>{_material(grey)}</visual>\n"
        "  </link>\n"
        f"  <frame name='tcp' attached_to='hand'><pose>0 0 {hand.tcp_depth} 0 0 0</pose></frame>\n"
        + finger_link("left", 1, hand.grip_force)
        + finger_link("right", -1, 0.0)
        + "  </model>\n</sdf>\n"
    )


def random_hand(seed: int, k: int, wide: bool = False) -> HandConfig:
    """Hand k of the family `seed` (its `model` is `NAME.sdf`, beside its hand file). `wide`: also palms of
    their own width (`WIDE_PALM_WIDTHS`, else 3 cm wider than the pads), thicker fingers
    (`WIDE_FINGER_THICKNESSES`) and grasp depths of their own (`WIDE_GRASP_DEPTHS`, else 1 cm), drawn
    after the others (a hand of the narrow family keeps its sizes)."""
    rng = np.random.default_rng([seed, k, 7])
    stroke, length, pad, thickness, palm_depth = (
        round(float(rng.uniform(*bounds)), 3)  # (millimetres: the joint's limit is the stroke's half exactly)
        for bounds in (STROKES, FINGER_LENGTHS, PAD_WIDTHS, FINGER_THICKNESSES, PALM_DEPTHS))
    palm_width, grasp_depth = max(0.05, round(pad + 0.03, 4)), 0.01
    if wide:
        palm_width, thickness, grasp_depth = (
            round(float(rng.uniform(*bounds)), 3)
            for bounds in (WIDE_PALM_WIDTHS, WIDE_FINGER_THICKNESSES, WIDE_GRASP_DEPTHS))
    name = f"parallel_jaw_{'w' if wide else 's'}{seed}_{k:02d}"
    return HandConfig(
        name=name, model=f"{name}.sdf", base_link="hand", fingers=["left_finger", "right_finger"],
        driven_joint="left_finger_joint", coupled_joints=["right_finger_joint"],
        open_position=stroke / 2, closed_position=0.0, closed_on_nothing=0.002, grip_force=40.0,
        stroke=stroke, tcp_depth=round(palm_depth + length - TIP_BEYOND_TCP, 4), palm_depth=palm_depth,
        palm_size=[max(palm_width, pad), round(stroke + 2 * thickness + 0.1, 4)],
        finger_length=length, finger_size=[pad, thickness], grasp_depth=grasp_depth)


def hand_yaml(hand: HandConfig) -> str:
    """The hand file of `hand` (the fields a hand file takes that differ from their defaults)."""
    default = HandConfig()
    lines = [f"# A parallel-jaw hand of drake_grasp's family (robot.parallel_jaw): "
             f"{hand.stroke * 1000:.0f} mm stroke, {hand.finger_length * 1000:.0f} mm fingers"]
    for field in dc.fields(HandConfig):
        value = getattr(hand, field.name)
        if value == getattr(default, field.name) and field.name != "grasp_depth":
            continue
        lines.append(f"{field.name}: {value}")
    return "\n".join(lines) + "\n"


def write_hand(hand: HandConfig, folder: Path) -> Path:
    """Writes `hand.model` (its SDF) and `NAME.yaml` into `folder`; returns the hand file."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / hand.model).write_text(parallel_jaw_sdf(hand))
    path = folder / f"{hand.name}.yaml"
    path.write_text(hand_yaml(hand))
    return path
