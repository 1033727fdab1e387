"""Model files as other tools write them, made ready for Drake: mesh paths and mesh formats.

ROS and Gazebo files name meshes by `package://NAME/...` or `model://NAME/...` and in STL or
DAE, which Drake cannot collide with; exported OBJ files often carry no vertex normals, which
Drake's renderer needs. `ready_mesh` resolves a reference to an absolute path and converts an STL
or DAE mesh to OBJ, or copies an OBJ without normals with them, once, in a cache folder.
`prepare_object_model` does it for an object's SDF or URDF, reads its lengths in the units the
user names, refuses one too large to be a table-top object, and replaces impossible inertias
(`robot.object_files`); `scaled_object_file` makes a scaled copy. `prepared_copy` writes a model
with its meshes made ready and edits applied to a cache folder: a hand's (`prepare_hand_model`: its
ROS transmissions go) and an arm's (`robot.arms.prepare_model`, which does more).
"""

from __future__ import annotations

import dataclasses as dc
import hashlib
import json
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

from drake_grasp.robot.contact_model import OBJECT_CONTACT
from drake_grasp.robot.object_files import (
    MAX_OBJECT_SIZE,
    MESH_UNITS,
    fix_inertias,
    mesh_reference,
    model_size,
    obj_has_normals,
    obj_with_normals,
    pybullet_friction,
    scale_model_tree,
    set_mesh_reference,
    split_collision_meshes,
)
from drake_grasp.robot.paths import SDF_DIR, cache_dir

UNCOLLIDABLE_MESHES = (".stl", ".dae")
REFERENCE_SCHEMES = ("package://", "model://")
DRAKE_NAMESPACE = "http://drake.mit.edu"
PREPARATION_VERSION = 2  # bump when a model's preparation changes what it writes (the cache key has it)


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
    tag = hashlib.sha256(str(path).encode()).hexdigest()[:8]
    if path.suffix.lower() == ".obj" and not obj_has_normals(path):
        with_normals = out_dir / f"{path.stem}_{tag}.obj"
        return str(with_normals if with_normals.exists() else obj_with_normals(path, with_normals))
    if path.suffix.lower() not in UNCOLLIDABLE_MESHES:
        return str(path)
    import open3d as o3d

    converted = out_dir / f"{path.stem}_{tag}.obj"
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
    found = (mesh_reference(mesh, root.tag == "robot") for mesh in root.iter("mesh"))
    return [reference for reference in found if reference is not None]


# (a cached preparation of an older version is remade)
PREPARE_VERSION = b"5: normals, units, PyBullet's shapes and friction, inertias"
NOTES_FILE = "notes.txt"
AS_IS_FILE = "as_is"


@dc.dataclass(frozen=True)
class PreparedModel:
    """An object's model file ready for Drake, and what was changed to make it so (one line each)."""

    path: Path
    notes: tuple[str, ...] = ()


def _parse(model: Path) -> ET.Element:
    try:
        return ET.parse(model).getroot()
    except (OSError, ET.ParseError) as e:
        raise ValueError(f"could not parse the object model {model}: {e}") from None


def _write(root: ET.Element, out: Path) -> Path:
    ET.register_namespace("drake", "http://drake.mit.edu")
    partial = out.with_suffix(f".{os.getpid()}.partial")
    ET.ElementTree(root).write(partial, xml_declaration=True, encoding="utf-8")
    partial.replace(out)
    return out


def _make_meshes_ready(root: ET.Element, model: Path, packages: PackageFinder, out_dir: Path) -> bool:
    """Every mesh reference of the tree made an absolute path to a mesh Drake reads; whether any changed."""
    changed = False
    for element, reference in _mesh_references(root):
        ready = ready_mesh(reference, model.parent, packages, out_dir)
        changed |= Path(ready) != (model.parent / reference.removeprefix("file://")).resolve()
        set_mesh_reference(element, root.tag == "robot", ready)
    return changed


def prepare_object_model(model: Path, set_folder: Path, units: str = "m") -> PreparedModel:
    """The object's model file as it is, or a cached copy made ready for Drake: meshes named by
    `package://`/`model://` (packages found in `set_folder` or above the model), in a format Drake cannot
    collide with or without normals, as absolute OBJ files; lengths in `units` ("m" or "mm") made metres;
    a collision OBJ of several shapes split into one convex piece per shape and a URDF link's PyBullet
    `<contact>` friction made Drake's (as PyBullet collides them: `object_files.split_collision_meshes`,
    `pybullet_friction`); impossible or absurd inertias replaced by that of the collision pieces' hulls at
    the file's mass. ValueError names a mesh that cannot be found or read, or an object too large to be
    one (a file in millimetres)."""
    if units not in MESH_UNITS:
        raise ValueError(f"unknown object units '{units}'; choose one of: {', '.join(MESH_UNITS)}")
    digest = hashlib.sha256(model.read_bytes() + str(model.resolve()).encode() + units.encode()
                            + PREPARE_VERSION).hexdigest()[:12]
    out_dir = cache_dir() / "object_models" / f"{model.stem}-{digest}"
    out = out_dir / model.name
    if (out_dir / AS_IS_FILE).exists():
        return PreparedModel(model)
    if out.exists():
        notes = (out_dir / NOTES_FILE).read_text().splitlines() if (out_dir / NOTES_FILE).exists() else []
        return PreparedModel(out, tuple(notes))
    root = _parse(model)
    out_dir.mkdir(parents=True, exist_ok=True)
    packages = PackageFinder({}, [set_folder], model, f"put the package's folder in {set_folder}")
    changed = _make_meshes_ready(root, model, packages, out_dir)
    notes = []
    if units != "m":
        scale_model_tree(root, MESH_UNITS[units])
        notes.append(f"lengths read in {units} (scaled by {MESH_UNITS[units]:g})")
        changed = True
    size = model_size(root)
    if size > MAX_OBJECT_SIZE:
        hint = ("; its lengths look like millimetres: --object-units mm reads them so" if units == "m"
                else "")
        raise ValueError(f"object model {model} is {size:.3g} m across, too large for a table-top "
                         f"object{hint}")
    notes += split_collision_meshes(root, out_dir)
    notes += pybullet_friction(root, OBJECT_CONTACT.urdf_tags)
    notes += [f"{line}: recomputed from its collision pieces' hulls at the file's mass"
              for line in fix_inertias(root)]
    if not changed and not notes:
        (out_dir / AS_IS_FILE).touch()
        return PreparedModel(model)
    (out_dir / NOTES_FILE).write_text("".join(f"{line}\n" for line in notes))
    return PreparedModel(_write(root, out), tuple(notes))


SHIPPED_PACKAGES = {"drake_grasp": SDF_DIR}
SCALE_DECIMALS = 3  # scales are rounded to this many decimals (one cached copy serves the draws alike)


def scaled_object_file(model: Path, scale: float) -> Path:
    """A cached copy of an object's SDF or URDF with every length scaled by `scale` (rounded to
    `SCALE_DECIMALS`; `object_files.scale_model_tree`), its meshes named by absolute paths."""
    scale = round(float(scale), SCALE_DECIMALS)
    if scale == 1.0:
        return model
    if not scale > 0:
        raise ValueError(f"an object's scale must be positive, got {scale}")
    digest = hashlib.sha256(model.read_bytes() + str(model.resolve()).encode()).hexdigest()[:12]
    out_dir = cache_dir() / "object_models" / "scaled" / f"{model.stem}-{digest}"
    out = out_dir / f"{model.stem}_x{scale:.{SCALE_DECIMALS}f}{model.suffix}"
    if out.exists():
        return out
    out_dir.mkdir(parents=True, exist_ok=True)
    root = _parse(model)
    packages = PackageFinder(SHIPPED_PACKAGES, [], model, "the object's packages must be above it")
    _make_meshes_ready(root, model, packages, out_dir)
    scale_model_tree(root, scale)
    return _write(root, out)

# -- a model file made ready for Drake (arms: `robot.arms.prepare_model`; hands) --------------
@dc.dataclass
class Preparation:
    """What prepare_model changed in a model, for the arm's notes and its base link."""

    world_child: str = ""  # the link the model welded to its `world` link
    notes: list[str] = dc.field(default_factory=list)


def parse_model_xml(text: str, model: Path, what: str) -> ET.Element:
    """The root of a URDF or SDF text, comments kept (the copy keeps the user's line numbers); a file that
    uses Drake's `drake:` tags without declaring their namespace (which Drake's parser allows) is read as
    if it did. ValueError names a file that does not parse."""

    def parse(text: str) -> ET.Element:
        return ET.fromstring(text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True,
                                                                             insert_pis=True)))
    try:
        return parse(text)
    except ET.ParseError as e:
        root_tag = re.search(r"<(robot|sdf)(?=[\s>/])", text)
        if "unbound prefix" in str(e) and root_tag and "xmlns:drake" not in text:
            declared = text[:root_tag.end()] + f' xmlns:drake="{DRAKE_NAMESPACE}"' + text[root_tag.end():]
            try:
                return parse(declared)
            except ET.ParseError:
                pass
        raise ValueError(f"could not parse the {what} model {model}: {e}") from None


def prepared_copy(model: Path, packages: PackageFinder, *, kind: str, name: str, key: str,
                  edit: Callable[[ET.Element, bool, Preparation], None]) -> Path:
    """The model (an arm's or a hand's: `kind`) with its meshes made ready for Drake (`ready_mesh`) and
    `edit(root, is_urdf, preparation)` applied, written once to the cache."""
    # The cached copy refers to the meshes by absolute path: the key holds the model's place and
    # the state of every file beside it, so a moved or edited model is prepared again.
    files = sorted(p for p in model.parent.rglob("*") if p.is_file())
    state = [(str(p), p.stat().st_size, p.stat().st_mtime_ns) for p in files]
    key = (f"{PREPARATION_VERSION} {model.resolve()} {state} {sorted(packages.known.items())} "
           f"{packages.search} {key}")
    digest = hashlib.sha256(model.read_bytes() + key.encode())
    out_dir = cache_dir() / f"{kind}s" / f"{name}-{digest.hexdigest()[:12]}"
    out = out_dir / model.name
    if out.exists():
        return out
    out_dir.mkdir(parents=True, exist_ok=True)
    text = model.read_text(errors="replace")
    root = parse_model_xml(text, model, kind)
    urdf = root.tag == "robot"
    for mesh in root.iter("mesh"):
        if urdf:
            mesh.set("filename", ready_mesh(mesh.get("filename", ""), model.parent, packages, out_dir))
        else:
            uri = mesh.find("uri")
            if uri is not None and uri.text:
                uri.text = ready_mesh(uri.text.strip(), model.parent, packages, out_dir)
    preparation = Preparation()
    edit(root, urdf, preparation)
    ET.register_namespace("drake", DRAKE_NAMESPACE)
    partial = out.with_suffix(f".{os.getpid()}.partial")  # workers may prepare the same model at once
    start = re.search(rf"<{root.tag}[\s>/]", text)
    head = text[:start.start()] if start else ""  # the declaration and comments before the root, as they are
    partial.write_text(head + ET.tostring(root, encoding="unicode") + "\n")
    notes = out.with_suffix(".prepared.json")
    notes.write_text(json.dumps(dc.asdict(preparation)))
    partial.replace(out)
    return out


def prepare_hand_model(model: Path, packages: PackageFinder, name: str) -> Path:
    """A copy of a hand's model, line for line, with absolute OBJ meshes and no ROS transmissions (the
    hand's driven joint gets one actuator: `robot.plant.driven_actuator`), cached as arms are."""

    def edit(root: ET.Element, urdf: bool, preparation: Preparation) -> None:
        if urdf:
            remove_transmissions(root)

    return prepared_copy(model, packages, kind="hand", name=name, edit=edit, key="")


def placeholder(parent: ET.Element, element: ET.Element, what: str) -> None:
    """Replaces `element` by a comment of as many lines, so the lines after it keep their numbers."""
    lines = ET.tostring(element, encoding="unicode").count("\n") - (element.tail or "").count("\n")
    comment = ET.Comment(f" drake_grasp: {what} " + "\n" * max(lines, 0))
    comment.tail = element.tail
    parent.insert(list(parent).index(element), comment)
    parent.remove(element)


def remove_transmissions(robot: ET.Element) -> None:
    """ROS transmissions go (names repeat across them, `mechanicalReduction` is Gazebo's): each arm joint
    gets one actuator named after it, with its URDF effort limit."""
    for transmission in robot.findall("transmission"):
        placeholder(robot, transmission, f"transmission {transmission.get('name', '')}")
