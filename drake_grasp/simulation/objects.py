"""Object sets: the shipped `primitives` and `novel` sets, or any folder of SDF/URDF/OBJ files."""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drake_grasp.paths import OBJECT_SETS_DIR

MODEL_SUFFIXES = (".sdf", ".urdf")
MESH_SUFFIXES = (".obj",)


@dataclass(frozen=True)
class ObjectModel:
    name: str
    url: str  # package://drake_grasp/... or file:///...


def object_set_names() -> list[str]:
    return sorted(p.name for p in OBJECT_SETS_DIR.iterdir() if p.is_dir())


def load_object_set(name_or_path: str) -> list[ObjectModel]:
    """The models of a shipped set (by name) or of a folder (by path).

    A folder may hold SDF/URDF files (one free body each) and bare OBJ meshes,
    which are wrapped as compliant convex objects of 0.1 kg. Raises ValueError
    when the set is unknown or holds nothing usable.
    """
    shipped = OBJECT_SETS_DIR / name_or_path
    if "/" not in name_or_path and shipped.is_dir():
        return [
            ObjectModel(p.stem, f"package://drake_grasp/objects/{name_or_path}/{p.name}")
            for p in sorted(shipped.glob("*.sdf"))
        ]
    folder = Path(name_or_path).expanduser()
    if not folder.is_dir():
        raise ValueError(
            f"unknown object set '{name_or_path}': not one of {', '.join(object_set_names())} "
            "and not a folder"
        )
    models = [
        ObjectModel(p.stem, p.resolve().as_uri())
        for p in sorted(folder.iterdir())
        if p.suffix.lower() in MODEL_SUFFIXES
    ]
    meshes = [p for p in sorted(folder.iterdir()) if p.suffix.lower() in MESH_SUFFIXES]
    # An OBJ that a model file already references is not an object of its own.
    referenced = " ".join(Path(m.url[len("file://"):]).read_text(errors="ignore") for m in models)
    meshes = [p for p in meshes if p.name not in referenced]
    if meshes:
        wrap_dir = Path(tempfile.mkdtemp(prefix="drake_grasp_objects_"))
        models += [ObjectModel(p.stem, wrap_obj(p, wrap_dir).as_uri()) for p in meshes]
    if not models:
        raise ValueError(f"object set folder {folder} holds no usable .sdf, .urdf or .obj file")
    return models


def wrap_obj(mesh: Path, out_dir: Path, mass: float = 0.1) -> Path:
    """Writes an SDF that makes a bare OBJ a compliant convex object."""
    vertices = np.array(
        [[float(v) for v in line.split()[1:4]] for line in mesh.read_text().splitlines()
         if line.startswith("v ")]
    )
    if len(vertices) < 4 or not np.isfinite(vertices).all():
        raise ValueError(f"mesh {mesh} has no usable vertices")
    size = vertices.max(axis=0) - vertices.min(axis=0)
    inertia = mass / 12 * np.array(
        [size[1] ** 2 + size[2] ** 2, size[0] ** 2 + size[2] ** 2, size[0] ** 2 + size[1] ** 2]
    )
    centre = (vertices.max(axis=0) + vertices.min(axis=0)) / 2
    geometry = f"<mesh><uri>{mesh.resolve().as_uri()}</uri><drake:declare_convex/></mesh>"
    props = (
        "<drake:proximity_properties><drake:compliant_hydroelastic/>"
        "<drake:hydroelastic_modulus>1e6</drake:hydroelastic_modulus>"
        "<drake:mesh_resolution_hint>0.01</drake:mesh_resolution_hint>"
        "<drake:mu_dynamic>0.8</drake:mu_dynamic><drake:mu_static>0.8</drake:mu_static>"
        "</drake:proximity_properties>"
    )
    text = (
        "<?xml version='1.0'?>\n<sdf version='1.9' xmlns:drake='http://drake.mit.edu'>\n"
        f"<model name='{mesh.stem}'><link name='{mesh.stem}'>\n"
        f"<inertial><pose>{centre[0]} {centre[1]} {centre[2]} 0 0 0</pose><mass>{mass}</mass>"
        f"<inertia><ixx>{inertia[0]}</ixx><iyy>{inertia[1]}</iyy><izz>{inertia[2]}</izz></inertia>"
        "</inertial>\n"
        f"<collision name='c'><geometry>{geometry}</geometry>{props}</collision>\n"
        f"<visual name='v'><geometry>{geometry}</geometry></visual>\n"
        "</link></model></sdf>\n"
    )
    out = out_dir / f"{mesh.stem}.sdf"
    out.write_text(text)
    return out
