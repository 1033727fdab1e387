"""Writes the offline models under `sdf/` from published parameters.

Run `python tools/generate_models.py` after changing a number here or in
`drake_grasp/robot/specs.py`; the generated files are committed. Arms get capsule
collision geometry along their links, inertias of those capsules scaled to the
published link masses, and collision filters between links that share a joint
neighbourhood (real arms overlap there by construction).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drake_grasp.robot.contact_model import OBJECT_CONTACT
from drake_grasp.robot.hand import HANDS_DIR, HandConfig
from drake_grasp.robot.parallel_jaw import parallel_jaw_sdf
from drake_grasp.robot.specs import PANDA, UR5, RobotSpec

SDF_DIR = Path(__file__).resolve().parents[1] / "sdf"
DENSITY = 600.0  # kg/m^3, wooden toy blocks

Seg = tuple[tuple[float, float, float], tuple[float, float, float], float]


def _fmt(values) -> str:
    return " ".join(f"{v:.12g}" for v in values)


def _segment_pose(p1, p2) -> tuple[np.ndarray, np.ndarray, float]:
    """Centre, rpy and length of a capsule along the segment p1-p2 (z axis)."""
    p1, p2 = np.asarray(p1, float), np.asarray(p2, float)
    axis = p2 - p1
    length = float(np.linalg.norm(axis))
    centre = (p1 + p2) / 2
    if length < 1e-9:
        return centre, np.zeros(3), 0.0
    z = axis / length
    # Rotation taking +z to z: roll about x then pitch about y (rpy = (r, p, 0)).
    pitch = math.asin(max(-1.0, min(1.0, z[0])))
    roll = math.atan2(-z[1], z[2])
    return centre, np.array([roll, pitch, 0.0]), length


def _rpy_to_matrix(rpy) -> np.ndarray:
    r, p, y = rpy
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _capsules_inertial(segments: list[Seg], mass: float) -> str:
    """Inertial block of solid cylinders (capsule cores) sharing `mass` by volume."""
    pieces = []
    for p1, p2, r in segments:
        centre, rpy, length = _segment_pose(p1, p2)
        length = max(length, r)  # a sphere-like stub still has volume
        pieces.append((centre, _rpy_to_matrix(rpy), r, length, math.pi * r * r * length))
    total = sum(p[4] for p in pieces)
    com = sum(p[0] * p[4] for p in pieces) / total
    inertia = np.zeros((3, 3))
    for centre, rot, r, length, vol in pieces:
        m = mass * vol / total
        i_local = np.diag([m * (3 * r * r + length * length) / 12] * 2 + [m * r * r / 2])
        d = centre - com
        inertia += rot @ i_local @ rot.T + m * (d @ d * np.eye(3) - np.outer(d, d))
    return _inertial_block(com, mass, inertia)


def _inertial_block(com, mass: float, inertia: np.ndarray) -> str:
    return (
        f"    <inertial>\n      <pose>{_fmt(com)} 0 0 0</pose>\n      <mass>{mass:.6g}</mass>\n"
        f"      <inertia><ixx>{inertia[0, 0]:.6g}</ixx><ixy>{inertia[0, 1]:.6g}</ixy>"
        f"<ixz>{inertia[0, 2]:.6g}</ixz><iyy>{inertia[1, 1]:.6g}</iyy>"
        f"<iyz>{inertia[1, 2]:.6g}</iyz><izz>{inertia[2, 2]:.6g}</izz></inertia>\n    </inertial>\n"
    )


def _box_inertia(mass: float, size) -> np.ndarray:
    x, y, z = size
    return np.diag([mass * (y * y + z * z), mass * (x * x + z * z), mass * (x * x + y * y)]) / 12


def _material(rgba) -> str:
    return f"<material><diffuse>{_fmt(rgba)}</diffuse></material>"


def _capsule_geometry(name: str, segments: list[Seg], rgba) -> str:
    out = []
    for k, (p1, p2, r) in enumerate(segments):
        centre, rpy, length = _segment_pose(p1, p2)
        geom = f"<capsule><radius>{r}</radius><length>{length:.6g}</length></capsule>"
        pose = f"<pose>{_fmt(centre)} {_fmt(rpy)}</pose>"
        out.append(f"    <collision name='{name}_c{k}'>{pose}<geometry>{geom}</geometry></collision>\n")
        out.append(
            f"    <visual name='{name}_v{k}'>{pose}<geometry>{geom}</geometry>{_material(rgba)}</visual>\n"
        )
    return "".join(out)


# Per-link capsules (p1, p2, radius) in the link frame, and published link masses.
PANDA_LINKS: list[tuple[list[Seg], float]] = [
    ([((0, 0, 0.03), (0, 0, 0.17), 0.075)], 4.0),
    ([((0, 0, -0.2), (0, 0, -0.06), 0.065)], 4.97),
    ([((0, 0, -0.06), (0, 0, 0.06), 0.06), ((0, -0.06, 0), (0, -0.17, 0), 0.06)], 0.646),
    ([((0, 0, -0.15), (0, 0, -0.03), 0.06), ((0, 0, 0), (0.0825, 0, 0), 0.055)], 3.23),
    ([((0, 0, -0.05), (0, 0, 0.05), 0.06), ((-0.0825, 0.02, 0), (-0.0825, 0.1, 0), 0.055)], 3.59),
    (
        [
            ((0, 0, -0.31), (0, 0, -0.21), 0.06),
            ((0, 0.08, -0.2), (0, 0.08, -0.06), 0.025),
            ((0, 0, -0.1), (0, 0, -0.02), 0.045),
        ],
        1.23,
    ),
    ([((0, 0, -0.05), (0, 0, 0.03), 0.05), ((0.02, 0, 0), (0.088, 0, 0), 0.045)], 1.67),
    ([((0, 0, -0.03), (0, 0, 0.07), 0.045)], 0.735),
]

UR5_LINKS: list[tuple[list[Seg], float]] = [
    ([((0, 0, 0.0), (0, 0, 0.04), 0.075)], 4.0),
    ([((0, 0, 0.065), (0, 0, 0.089), 0.06), ((0, 0, 0.089), (0, -0.13, 0.089), 0.06)], 3.7),
    ([((0, 0, 0.136), (-0.425, 0, 0.136), 0.06)], 8.393),
    ([((0, 0, 0.02), (0, 0, 0.12), 0.055), ((0, 0, 0.016), (-0.392, 0, 0.016), 0.05)], 2.275),
    ([((0, 0, 0.03), (0, 0, 0.1), 0.045)], 1.219),
    ([((0, 0, -0.03), (0, 0, 0.06), 0.045)], 1.219),
    ([((0, 0, -0.03), (0, 0, 0.06), 0.04)], 0.1879),
]


def _child_offsets(spec: RobotSpec) -> list[tuple[np.ndarray, np.ndarray]]:
    """Pose (xyz, rpy) of each link frame in its parent's, from the DH table.

    Modified DH: link i sits at RotX(alpha_{i-1}) TransX(a_{i-1}) TransZ(d_i) of link i-1.
    Standard DH: link i+1 sits at TransZ(d_i) TransX(a_i) RotX(alpha_i) of link i, and
    link 1 coincides with the base. The last entry places the flange.
    """
    dh = spec.dh
    n = len(dh.a)
    offsets = []
    if dh.modified:
        for i in range(n):
            al, a, d = dh.alpha[i], dh.a[i], dh.d[i]
            offsets.append((np.array([a, -d * math.sin(al), d * math.cos(al)]), np.array([al, 0, 0])))
        offsets.append((np.array([0, 0, dh.flange_d]), np.zeros(3)))
    else:
        offsets.append((np.zeros(3), np.zeros(3)))
        for i in range(n):
            offsets.append((np.array([dh.a[i], 0, dh.d[i]]), np.array([dh.alpha[i], 0, 0])))
    return offsets


def write_arm(spec: RobotSpec, links: list[tuple[list[Seg], float]], rgba) -> None:
    n = spec.num_joints
    link_names = [spec.base_link] + [f"{spec.name}_link{i}" for i in range(1, n + 1)]
    offsets = _child_offsets(spec)
    body = [
        f"<?xml version='1.0'?>\n<sdf version='1.9' xmlns:drake='http://drake.mit.edu'>\n"
        f"  <model name='{spec.name}'>\n"
    ]
    for i, name in enumerate(link_names):
        parent = link_names[i - 1] if i > 0 else None
        pose = (
            ""
            if parent is None
            else (
                f"    <pose relative_to='{parent}'>"
                f"{_fmt(offsets[i - 1][0])} {_fmt(offsets[i - 1][1])}</pose>\n"
            )
        )
        segments, mass = links[i]
        body.append(f"  <link name='{name}'>\n{pose}{_capsules_inertial(segments, mass)}")
        body.append(_capsule_geometry(name, segments, rgba))
        body.append("  </link>\n")
        if parent is not None:
            j = i - 1
            body.append(
                f"  <joint name='{spec.joint_names[j]}' type='revolute'>\n"
                f"    <parent>{parent}</parent><child>{name}</child>\n"
                f"    <axis><xyz>0 0 1</xyz><limit><lower>{spec.q_lower[j]}</lower>"
                f"<upper>{spec.q_upper[j]}</upper><effort>{spec.effort_max[j]}</effort>"
                f"<velocity>{spec.v_max[j]}</velocity></limit>"
                f"<dynamics><damping>0.1</damping></dynamics></axis>\n  </joint>\n"
            )
    flange_xyz, flange_rpy = offsets[-1]
    body.append(
        f"  <link name='{spec.flange_link}'>\n"
        f"    <pose relative_to='{link_names[-1]}'>{_fmt(flange_xyz)} {_fmt(flange_rpy)}</pose>\n"
        f"    <inertial><mass>0.001</mass><inertia><ixx>1e-7</ixx><iyy>1e-7</iyy><izz>1e-7</izz>"
        f"</inertia></inertial>\n  </link>\n"
        f"  <joint name='{spec.name}_flange_weld' type='fixed'><parent>{link_names[-1]}</parent>"
        f"<child>{spec.flange_link}</child></joint>\n"
    )
    # Links within two joints of each other overlap by construction: filter them.
    for k in range(len(link_names) - 2):
        members = "".join(f"<drake:member>{m}</drake:member>" for m in link_names[k : k + 3])
        body.append(
            f"  <drake:collision_filter_group name='near{k}'>{members}"
            f"<drake:ignored_collision_filter_group>near{k}</drake:ignored_collision_filter_group>"
            f"</drake:collision_filter_group>\n"
        )
    body.append("  </model>\n</sdf>\n")
    (SDF_DIR / f"{spec.name}.sdf").write_text("".join(body))


def _rigid_props(mu: float) -> str:
    return (
        f"<drake:proximity_properties><drake:rigid_hydroelastic/>"
        f"<drake:mu_dynamic>{mu}</drake:mu_dynamic><drake:mu_static>{mu}</drake:mu_static>"
        f"</drake:proximity_properties>"
    )


def write_hand() -> None:
    """The Franka Hand as `sdf/hands/franka.yaml` gives it: a palm box, two coupled prismatic fingers."""
    from pydrake.common.yaml import yaml_load_typed

    hand = yaml_load_typed(schema=HandConfig, filename=str(HANDS_DIR / "franka.yaml"))
    (SDF_DIR / "hand.sdf").write_text(parallel_jaw_sdf(hand))


def write_table() -> None:
    size = (1.6, 1.6, 0.05)
    box = f"<box><size>{_fmt(size)}</size></box>"
    pose = f"<pose>0.5 0 {-size[2] / 2} 0 0 0</pose>"
    text = (
        "<?xml version='1.0'?>\n<sdf version='1.9' xmlns:drake='http://drake.mit.edu'>\n"
        "  <model name='table'>\n  <link name='table'>\n"
        f"    <collision name='top'>{pose}<geometry>{box}</geometry>{_rigid_props(0.6)}</collision>\n"
        f"    <visual name='top_v'>{pose}<geometry>{box}</geometry>"
        f"{_material((0.55, 0.4, 0.3, 1))}</visual>\n"
        "  </link>\n  </model>\n</sdf>\n"
    )
    (SDF_DIR / "table.sdf").write_text(text)


# --- Objects -------------------------------------------------------------------------------


@dataclass
class Piece:
    """One convex piece of an object: a primitive shape or a convex OBJ mesh."""

    geometry: str  # SDF <geometry> content
    pose: tuple[float, ...]  # xyz rpy in the body frame
    volume: float
    size: tuple[float, float, float]  # bounding box, for the inertia estimate


def box(x, y, z, pose=(0, 0, 0, 0, 0, 0)) -> Piece:
    return Piece(f"<box><size>{_fmt((x, y, z))}</size></box>", pose, x * y * z, (x, y, z))


def cylinder(r, length, pose=(0, 0, 0, 0, 0, 0)) -> Piece:
    return Piece(
        f"<cylinder><radius>{r}</radius><length>{length}</length></cylinder>",
        pose,
        math.pi * r * r * length,
        (2 * r, 2 * r, length),
    )


def prism_mesh(path: Path, profile_xz: list[tuple[float, float]], width_y: float) -> Piece:
    """A convex polygon in the x-z plane extruded along y, written as an OBJ."""
    n = len(profile_xz)
    lines = [f"v {x:.6f} {s * width_y / 2:.6f} {z:.6f}" for s in (-1, 1) for x, z in profile_xz]
    # Side faces, then the two caps (fan triangulation).
    for i in range(n):
        j = (i + 1) % n
        lines.append(f"f {i + 1} {j + 1} {n + j + 1}")
        lines.append(f"f {i + 1} {n + j + 1} {n + i + 1}")
    for i in range(1, n - 1):
        lines.append(f"f 1 {i + 2} {i + 1}")
        lines.append(f"f {n + 1} {n + i + 1} {n + i + 2}")
    path.write_text("\n".join(lines) + "\n")
    xs, zs = zip(*profile_xz, strict=False)
    area = 0.5 * abs(sum(xs[i] * zs[(i + 1) % n] - xs[(i + 1) % n] * zs[i] for i in range(n)))
    geometry = f"<mesh><uri>{path.name}</uri><drake:declare_convex/></mesh>"
    return Piece(
        geometry, (0, 0, 0, 0, 0, 0), area * width_y, (max(xs) - min(xs), width_y, max(zs) - min(zs))
    )


def write_object(folder: Path, name: str, pieces: list[Piece], rgba) -> None:
    mass = DENSITY * sum(p.volume for p in pieces)
    inertia = np.zeros((3, 3))
    com = sum(np.array(p.pose[:3]) * p.volume for p in pieces) / sum(p.volume for p in pieces)
    for p in pieces:
        m = DENSITY * p.volume
        d = np.array(p.pose[:3]) - com
        inertia += _box_inertia(m, p.size) + m * (d @ d * np.eye(3) - np.outer(d, d))
    props = (
        f"<drake:proximity_properties><drake:compliant_hydroelastic/>"
        f"<drake:hydroelastic_modulus>{OBJECT_CONTACT.hydroelastic_modulus:g}</drake:hydroelastic_modulus>"
        f"<drake:mesh_resolution_hint>{OBJECT_CONTACT.resolution_hint:g}</drake:mesh_resolution_hint>"
        f"<drake:mu_dynamic>{OBJECT_CONTACT.friction:g}</drake:mu_dynamic>"
        f"<drake:mu_static>{OBJECT_CONTACT.friction:g}</drake:mu_static>"
        f"</drake:proximity_properties>"
    )
    geoms = []
    for k, p in enumerate(pieces):
        pose = f"<pose>{_fmt(p.pose)}</pose>"
        geoms.append(
            f"    <collision name='c{k}'>{pose}<geometry>{p.geometry}</geometry>{props}</collision>\n"
        )
        geoms.append(
            f"    <visual name='v{k}'>{pose}<geometry>{p.geometry}</geometry>{_material(rgba)}</visual>\n"
        )
    text = (
        "<?xml version='1.0'?>\n<sdf version='1.9' xmlns:drake='http://drake.mit.edu'>\n"
        f"  <model name='{name}'>\n  <link name='{name}'>\n"
        + _inertial_block(com, mass, inertia)
        + "".join(geoms)
        + "  </link>\n  </model>\n</sdf>\n"
    )
    (folder / f"{name}.sdf").write_text(text)


def write_primitives() -> None:
    """The 8 VPG training blocks (paper Sec. IV-C), body frame at the bounding-box centre."""
    folder = SDF_DIR / "objects" / "primitives"
    folder.mkdir(parents=True, exist_ok=True)
    arch_pieces = [
        box(0.024, 0.05, 0.05, (-0.038, 0, 0, 0, 0, 0)),
        box(0.024, 0.05, 0.05, (0.038, 0, 0, 0, 0, 0)),
    ]
    r, strips = 0.026, np.linspace(-0.026, 0.026, 7)
    for k in range(len(strips) - 1):
        x0, x1 = strips[k], strips[k + 1]
        h0, h1 = math.sqrt(max(r * r - x0 * x0, 0)), math.sqrt(max(r * r - x1 * x1, 0))
        profile = [(x0, h0 - 0.025), (x1, h1 - 0.025), (x1, 0.025), (x0, 0.025)]
        arch_pieces.append(prism_mesh(folder / f"arch_strip{k}.obj", profile, 0.05))
    shapes = {
        "triangular_prism": [
            prism_mesh(
                folder / "triangular_prism.obj", [(-0.0465, -0.0245), (0.0465, -0.0245), (0.0, 0.0245)], 0.05
            )
        ],
        "arch": arch_pieces,
        "square_slab": [box(0.05, 0.05, 0.025)],
        "brick": [box(0.1, 0.05, 0.025)],
        "cube": [box(0.05, 0.05, 0.05)],
        "tall_block": [box(0.05, 0.05, 0.1)],
        "half_cylinder": [
            prism_mesh(
                folder / "half_cylinder.obj",
                [(0.025 * math.cos(t), 0.025 * math.sin(t) - 0.0125) for t in np.linspace(0, math.pi, 13)],
                0.05,
            )
        ],
        "cylinder": [cylinder(0.0225, 0.05)],
    }
    colors = [
        (0.9, 0.3, 0.3, 1),
        (0.3, 0.7, 0.3, 1),
        (0.3, 0.4, 0.9, 1),
        (0.9, 0.8, 0.2, 1),
        (0.8, 0.4, 0.8, 1),
        (0.2, 0.8, 0.8, 1),
        (0.95, 0.6, 0.2, 1),
        (0.6, 0.6, 0.6, 1),
    ]
    for (name, pieces), rgba in zip(shapes.items(), colors, strict=False):
        write_object(folder, name, pieces, rgba)


def write_novel() -> None:
    """Household-like shapes never used for training, from convex pieces."""
    folder = SDF_DIR / "objects" / "novel"
    folder.mkdir(parents=True, exist_ok=True)
    banana = []
    for t in np.linspace(-0.6, 0.6, 5):
        x, z = 0.09 * math.sin(t), 0.09 * (math.cos(t) - 1) + 0.02
        banana.append(cylinder(0.016, 0.05, (x, 0, z, 0, math.pi / 2 + t, 0)))
    shapes = {
        "bottle": [
            cylinder(0.032, 0.12, (0, 0, -0.03, 0, 0, 0)),
            cylinder(0.013, 0.045, (0, 0, 0.0525, 0, 0, 0)),
            cylinder(0.016, 0.015, (0, 0, 0.0825, 0, 0, 0)),
        ],
        "mug": [
            cylinder(0.04, 0.09),
            box(0.012, 0.02, 0.06, (0.052, 0, 0, 0, 0, 0)),
            box(0.016, 0.02, 0.012, (0.044, 0, 0.024, 0, 0, 0)),
            box(0.016, 0.02, 0.012, (0.044, 0, -0.024, 0, 0, 0)),
        ],
        "banana": banana,
        "spray_can": [
            cylinder(0.026, 0.15, (0, 0, -0.01, 0, 0, 0)),
            cylinder(0.018, 0.03, (0, 0, 0.08, 0, 0, 0)),
        ],
        "l_bracket": [
            box(0.1, 0.04, 0.012, (0, 0, -0.024, 0, 0, 0)),
            box(0.012, 0.04, 0.06, (-0.044, 0, 0.006, 0, 0, 0)),
        ],
        "juice_box": [box(0.065, 0.04, 0.105)],
    }
    colors = [
        (0.2, 0.6, 0.3, 1),
        (0.9, 0.9, 0.85, 1),
        (0.95, 0.85, 0.2, 1),
        (0.8, 0.1, 0.1, 1),
        (0.5, 0.5, 0.55, 1),
        (1.0, 0.55, 0.1, 1),
    ]
    for (name, pieces), rgba in zip(shapes.items(), colors, strict=False):
        write_object(folder, name, pieces, rgba)


def main() -> None:
    SDF_DIR.mkdir(exist_ok=True)
    (SDF_DIR / "package.xml").write_text(
        "<?xml version='1.0'?>\n<package format='2'>\n  <name>drake_grasp</name>\n"
        "  <version>0.1.0</version>\n  <description>Offline robot, hand, table and object models"
        " of drake_grasp.</description>\n  <maintainer email='dev@drake-grasp.invalid'>drake_grasp"
        "</maintainer>\n  <license>MIT</license>\n</package>\n"
    )
    write_arm(PANDA, PANDA_LINKS, (0.95, 0.95, 0.95, 1))
    write_arm(UR5, UR5_LINKS, (0.4, 0.6, 0.8, 1))
    write_hand()
    write_table()
    write_primitives()
    write_novel()
    print(f"wrote models under {SDF_DIR}")


if __name__ == "__main__":
    main()
