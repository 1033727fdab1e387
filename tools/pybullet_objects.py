"""Writes a generated object set as the grasping field's PyBullet-era object sets come.

    python tools/pybullet_objects.py data/objects/household_validation /tmp/household_pybullet

Each object of a `make_objects` folder (regenerated from its manifest) becomes `NAME.urdf` with
PyBullet's `<contact>` friction, the placeholder inertia `ixx=iyy=izz=1` at the object's mass, a
visual OBJ (`meshes/NAME_visual.obj`, one triangle soup) and a collision OBJ holding each convex
piece as an `o` shape (`meshes/NAME_collision.obj`, as V-HACD writes a decomposition); neither
has normals or Drake tags. `--objects` on the folder measures what the project makes of such files
against the same objects as its own SDF (docs/field_benchmark.md).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drake_grasp.simulation.object_generation import GeneratedObject, generate_object  # noqa: E402


def obj_text(meshes: list[trimesh.Trimesh], shapes: bool) -> str:
    """The meshes as OBJ text without normals: each an `o` shape (`shapes`) or one soup."""
    lines, offset = [], 0
    for k, mesh in enumerate(meshes):
        if shapes:
            lines.append(f"o piece_{k}")
        lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.vertices]
        lines += [f"f {a + offset + 1} {b + offset + 1} {c + offset + 1}" for a, b, c in mesh.faces]
        offset += len(mesh.vertices)
    return "\n".join(lines) + "\n"


def urdf_text(obj: GeneratedObject) -> str:
    com = " ".join(f"{x:.6f}" for x in np.asarray(obj.com))
    mesh = f"meshes/{obj.name}"
    return f"""<?xml version="1.0"?>
<robot name="{obj.name}">
  <link name="baseLink">
    <contact><lateral_friction value="{obj.friction:.3f}"/><rolling_friction value="0.0"/>
      <spinning_friction value="0.0"/></contact>
    <inertial><origin rpy="0 0 0" xyz="{com}"/><mass value="{obj.mass:.4f}"/>
      <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
    <visual><origin rpy="0 0 0" xyz="0 0 0"/>
      <geometry><mesh filename="{mesh}_visual.obj" scale="1 1 1"/></geometry></visual>
    <collision><origin rpy="0 0 0" xyz="0 0 0"/>
      <geometry><mesh filename="{mesh}_collision.obj" scale="1 1 1"/></geometry></collision>
  </link>
</robot>
"""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("object_set", type=Path, help="a make_objects folder (its manifest.json)")
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    try:
        manifest = json.loads((args.object_set / "manifest.json").read_text())
    except (OSError, ValueError) as e:
        print(f"error: {args.object_set} is not a make_objects folder: {e}", file=sys.stderr)
        return 2
    (args.out / "meshes").mkdir(parents=True, exist_ok=True)
    elongation = manifest.get("elongation")
    for entry in manifest["objects"]:
        obj = generate_object(manifest["seed"], entry["index"], tuple(manifest["families"]),
                              None if elongation is None else tuple(elongation))
        pieces = [piece.trimesh() for piece in obj.pieces]
        (args.out / "meshes" / f"{obj.name}_visual.obj").write_text(obj_text(pieces, shapes=False))
        (args.out / "meshes" / f"{obj.name}_collision.obj").write_text(obj_text(pieces, shapes=True))
        (args.out / f"{obj.name}.urdf").write_text(urdf_text(obj))
    print(f"{len(manifest['objects'])} PyBullet-style objects in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
