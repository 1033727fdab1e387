"""Model files as other tools write them, made ready for Drake: mesh paths and mesh formats.

ROS and Gazebo files name meshes by `package://NAME/...` or `model://NAME/...` and in STL or
DAE, which Drake cannot collide with. `ready_mesh` resolves a reference to an absolute path and
converts an STL or DAE mesh to OBJ (with vertex normals, for the renderer) once, in a cache
folder; `prepare_object_model` does it for an object's SDF or URDF (an arm's model goes through
`robot.arms`, which does more).
"""

from __future__ import annotations

import dataclasses as dc
import hashlib
import os
import xml.etree.ElementTree as ET
from pathlib import Path

from drake_grasp.robot.paths import cache_dir

UNCOLLIDABLE_MESHES = (".stl", ".dae")
REFERENCE_SCHEMES = ("package://", "model://")


@dc.dataclass(frozen=True)
class PackageFinder:
    """Where the packages of `package://NAME/...` (and Gazebo's `model://NAME/...`) paths live: a
    package.xml's (`known`), then a `search` folder, then a folder above the model, that holds or is
    NAME. `hint`: what the error of a package not found tells the user to do."""

    known: dict[str, Path]
    search: list[Path]
    model: Path
    hint: str

    def find(self, reference: str) -> Path:
        scheme = "package://" if reference.startswith("package://") else "model://"
        package, _, rest = reference[len(scheme):].partition("/")
        if package in self.known:
            return self.known[package] / rest
        for folder in [*self.search, *self.model.parents]:
            for root in (folder / package, folder):
                if root.name == package and root.is_dir() and (root / rest).exists():
                    return root / rest
        raise ValueError(f"mesh {reference} in {self.model}: no folder '{package}' above the model or in "
                         f"{', '.join(map(str, self.search)) or 'the search path'}; {self.hint}")


def ready_mesh(reference: str, folder: Path, packages: PackageFinder, out_dir: Path) -> str:
    """An absolute path to the mesh, converted to OBJ when Drake cannot collide with its format."""
    if reference.startswith(REFERENCE_SCHEMES):
        path = packages.find(reference)
    else:
        path = (folder / reference.removeprefix("file://")).resolve()
    if not path.is_file():
        raise ValueError(f"mesh not found: {path} (named in {packages.model})")
    if path.suffix.lower() not in UNCOLLIDABLE_MESHES:
        return str(path)
    import open3d as o3d

    converted = out_dir / f"{path.stem}_{hashlib.sha256(str(path).encode()).hexdigest()[:8]}.obj"
    if not converted.exists():
        mesh = o3d.io.read_triangle_mesh(str(path))
        if len(mesh.vertices) == 0:
            raise ValueError(f"mesh {path} has no vertices")
        mesh.compute_vertex_normals()  # (the renderer needs normals; STL files carry only face normals)
        mesh.triangle_normals = o3d.utility.Vector3dVector()  # (OBJ holds vertex normals only)
        partial = converted.with_suffix(f".{os.getpid()}.obj")
        o3d.io.write_triangle_mesh(str(partial), mesh, write_vertex_normals=True)
        partial.replace(converted)
    return str(converted)


def _mesh_references(root: ET.Element) -> list[tuple[ET.Element, str]]:
    """(element, reference) of every mesh of an URDF (`<mesh filename>`) or SDF (`<mesh><uri>`) tree."""
    out = []
    for mesh in root.iter("mesh"):
        if root.tag == "robot":
            out.append((mesh, mesh.get("filename", "")))
        elif (uri := mesh.find("uri")) is not None and uri.text:
            out.append((uri, uri.text.strip()))
    return out


def needs_preparation(reference: str) -> bool:
    return reference.startswith(REFERENCE_SCHEMES) or Path(reference).suffix.lower() in UNCOLLIDABLE_MESHES


def prepare_object_model(model: Path, set_folder: Path) -> Path:
    """The object's model file as it is, or, when it names meshes by `package://`/`model://` or in a
    format Drake cannot collide with, a cached copy with absolute OBJ meshes (packages found in
    `set_folder` or above the model). ValueError names a mesh that cannot be found or read."""
    try:
        root = ET.parse(model).getroot()
    except (OSError, ET.ParseError) as e:
        raise ValueError(f"could not parse the object model {model}: {e}") from None
    references = _mesh_references(root)
    if not any(needs_preparation(ref) for _, ref in references):
        return model
    digest = hashlib.sha256(model.read_bytes() + str(model.resolve()).encode()).hexdigest()[:12]
    out_dir = cache_dir() / "object_models" / f"{model.stem}-{digest}"
    out = out_dir / model.name
    if out.exists():
        return out
    out_dir.mkdir(parents=True, exist_ok=True)
    packages = PackageFinder({}, [set_folder], model, f"put the package's folder in {set_folder}")
    for element, reference in references:
        ready = ready_mesh(reference, model.parent, packages, out_dir)
        if root.tag == "robot":
            element.set("filename", ready)
        else:
            element.text = ready
    ET.register_namespace("drake", "http://drake.mit.edu")
    partial = out.with_suffix(f".{os.getpid()}.partial")
    ET.ElementTree(root).write(partial, xml_declaration=True, encoding="utf-8")
    partial.replace(out)
    return out
