"""Object model files as the grasping field writes them: what `model_files.prepare_object_model` fixes.

Object sets written for PyBullet and exported from CAD or scanners commonly carry
- OBJ meshes without vertex normals (`vn` lines), which Drake's renderer refuses: a copy with
  area-weighted vertex normals is written (`obj_with_normals`);
- placeholder inertias (PyBullet computes a body's inertia from its collision shape unless told
  otherwise, so its object files often say `ixx=iyy=izz=1` whatever the mass): a body whose inertia
  is impossible or absurd for its mass and size gets the inertia of its collision geometries' convex
  hulls at the file's mass (`inertia_problem`, `pieces_inertia`);
- meshes in millimetres: a body larger than `MAX_OBJECT_SIZE` is refused unless the user says the
  units are millimetres, and then scaled (`scale_model_tree`);
- what PyBullet does that Drake does not: a collision OBJ of several shapes (a V-HACD decomposition)
  collides as one convex hull per shape (`split_collision_meshes`), and a link's `<contact>` carries
  its friction (`pybullet_friction`).
`scale_model_tree` also makes the scaled copies that a scenario's per-object scale range asks for.
The functions work on parsed URDF (`<robot>`) or SDF (`<sdf>`) trees with absolute mesh paths.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Callable
from copy import deepcopy
from pathlib import Path

import numpy as np

MAX_OBJECT_SIZE = 2.0  # [m] a table-top object larger than this is a file in other units (millimetres)
# An inertia whose trace is below this fraction of its collision hull's (at the same mass) is absurd.
MIN_INERTIA_FRACTION = 0.01
MESH_UNITS = {"m": 1.0, "mm": 0.001}
DRAKE_NS = "{http://drake.mit.edu}"
_PRIMITIVE_LENGTHS = {"radius", "length", "size", "radii"}  # SDF primitive fields in metres


# -- OBJ normals ---------------------------------------------------------------------------------
def obj_has_normals(path: Path) -> bool:
    with open(path, errors="ignore") as f:
        return any(line.startswith("vn ") for line in f)


Faces = list[tuple[int, list[list[str]]]]  # (the shape of a face, its `v/vt/vn` references)


def _read_obj(path: Path) -> tuple[np.ndarray, list[str], Faces, list[str]]:
    """(vertices, the `v` and `vt` lines, faces as (their shape, their `v/vt/vn` refs), each shape's `o` or
    `g` line: shape k follows the k-th such line, shape 0 (faces before any) has "")."""
    vertices, lines, faces, shapes = [], [], [], [""]
    with open(path, errors="ignore") as f:
        for line in f:
            head = line.split(maxsplit=1)[0] if line.strip() else ""
            if head == "v":
                vertices.append([float(x) for x in line.split()[1:4]])
                lines.append(line)
            elif head == "vt":
                lines.append(line)
            elif head == "f":
                faces.append((len(shapes) - 1, [r.split("/") for r in line.split()[1:]]))
            elif head in ("o", "g"):
                shapes.append(line)
    if len(vertices) < 3 or not faces:
        raise ValueError(f"mesh {path} has no faces")
    return np.asarray(vertices, float), lines, faces, shapes


def _vertex_index(ref: str, count: int) -> int:
    k = int(ref)
    return k - 1 if k > 0 else count + k


def _write_obj(out: Path, header: str, v: np.ndarray, lines: list[str], faces: Faces,
               shapes: list[str] | None = None, texture: bool = True) -> Path:
    """Writes `out` atomically: `lines` (the vertices among them), area-weighted vertex normals (a face
    vertex's normal index is its vertex index) and the faces, each shape's after its `o`/`g` line."""
    n, shapes = len(v), shapes or [""]
    normals = np.zeros_like(v)
    face_lines, shape = [], 0
    for k, refs in faces:
        if k != shape:
            face_lines.append(shapes[k])
            shape = k
        ids = [_vertex_index(r[0], n) for r in refs]
        for a, b in zip(ids[1:-1], ids[2:], strict=True):  # fan triangles; the cross product weighs by area
            normals[[ids[0], a, b]] += np.cross(v[a] - v[ids[0]], v[b] - v[ids[0]])
        uv = [r[1] if texture and len(r) > 1 and r[1] else "" for r in refs]
        corners = " ".join(f"{i + 1}/{t}/{i + 1}" for i, t in zip(ids, uv, strict=True))
        face_lines.append(f"f {corners}\n")
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 0, normals / np.maximum(length, 1e-300), [0.0, 0.0, 1.0])
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_suffix(f".{os.getpid()}.partial")
    with open(partial, "w") as f:
        f.write(f"# {header} (drake_grasp)\n")
        f.writelines(lines)
        f.writelines(f"vn {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in normals)
        f.writelines(face_lines)
    partial.replace(out)
    return out


def obj_with_normals(path: Path, out: Path) -> Path:
    """Writes `out`: the OBJ's vertices, texture coordinates and faces with area-weighted vertex normals
    (a face vertex's normal index is its vertex index). Material references are left out: the copy lives
    apart from the file's `.mtl` and textures (depth cameras and the contact model need only geometry)."""
    v, lines, faces, shapes = _read_obj(path)
    return _write_obj(out, f"{path.name} with vertex normals", v, lines, faces, shapes)


# -- PyBullet's collision semantics --------------------------------------------------------------
def obj_shapes(path: Path) -> list[np.ndarray]:
    """The vertices of each shape of an OBJ file (its faces after each `o` or `g` line; the faces before
    any such line are one more), as PyBullet's importer reads shapes; shapes without faces are left out."""
    v, _, faces, _ = _read_obj(path)
    shapes: dict[int, set[int]] = {}
    for shape, refs in faces:
        shapes.setdefault(shape, set()).update(_vertex_index(r[0], len(v)) for r in refs)
    return [v[sorted(ids)] for ids in shapes.values()]


def _solid(points: np.ndarray) -> bool:
    """Whether points span a volume (a convex hull with an inside), not a point, segment or plane."""
    if len(points) < 4:
        return False
    centred = points - points.mean(axis=0)
    singular = np.linalg.svd(centred, compute_uv=False)
    return bool(singular[2] > 1e-6 * max(singular[0], 1e-300))


def _piece_obj(points: np.ndarray, out: Path, header: str) -> Path:
    """Writes `out`: the convex hull of `points` as a closed OBJ with vertex normals."""
    hull = hull_mesh(points)
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in hull.vertices]
    faces = [(0, [[str(i + 1)] for i in face]) for face in hull.faces]
    return _write_obj(out, header, np.asarray(hull.vertices), lines, faces, texture=False)


def mesh_reference(mesh: ET.Element, urdf: bool) -> tuple[ET.Element, str] | None:
    """(the element that holds a `<mesh>`'s file reference, the reference): URDF `<mesh filename>`, SDF
    `<mesh><uri>` (None without one)."""
    if urdf:
        return mesh, mesh.get("filename", "")
    uri = mesh.find("uri")
    return (uri, uri.text.strip()) if uri is not None and uri.text else None


def set_mesh_reference(element: ET.Element, urdf: bool, reference: str) -> None:
    """Makes the element `mesh_reference` found name `reference`."""
    if urdf:
        element.set("filename", reference)
    else:
        element.text = reference


def _collision_obj(collision: ET.Element, urdf: bool) -> tuple[ET.Element, str] | None:
    """`mesh_reference` of a collision's mesh when it is an OBJ file, else None."""
    mesh = collision.find("geometry/mesh")
    found = None if mesh is None else mesh_reference(mesh, urdf)
    return found if found is not None and found[1].strip().lower().endswith(".obj") else None


def split_collision_meshes(root: ET.Element, out_dir: Path) -> list[str]:
    """Replaces each collision OBJ of several shapes (a V-HACD decomposition, as PyBullet-era object sets
    ship them) by one collision per shape, each the convex hull of its shape (shapes that span no volume are
    left out): PyBullet collides a mesh as one convex hull per shape, Drake as one convex hull of the whole
    file (a decomposed bowl would be a solid dome). Mesh paths must be absolute; returns one line per split
    mesh."""
    urdf = root.tag == "robot"
    notes = []
    for link in root.iter("link"):
        for position, collision in reversed(list(enumerate(list(link)))):
            if collision.tag != "collision" or (found := _collision_obj(collision, urdf)) is None:
                continue
            path = Path(found[1].strip())
            shapes = [points for points in obj_shapes(path) if _solid(points)]
            if len(shapes) < 2:
                continue
            link.remove(collision)
            name = collision.get("name") or "collision"
            for k, points in reversed(list(enumerate(shapes))):
                piece = _piece_obj(points, out_dir / f"{path.stem}_piece{k:02d}.obj",
                                   f"shape {k} of {path.name}, its convex hull")
                piece_collision = deepcopy(collision)
                piece_collision.set("name", f"{name}_{k}")
                set_mesh_reference(_collision_obj(piece_collision, urdf)[0], urdf, str(piece))
                link.insert(position, piece_collision)
            notes.append("a collision OBJ of several shapes (a convex decomposition) collides as one convex "
                         "piece per shape, as PyBullet collides it")
    return notes


def pybullet_friction(root: ET.Element, tags: Callable[[float], str]) -> list[str]:
    """A URDF link's PyBullet `<contact><lateral_friction value=.../>` made its collisions' Drake friction:
    each collision without Drake proximity properties gets `tags(friction)` (a `<drake:proximity_properties>`
    element as text) and the `<contact>` element goes (Drake's parser does not read it). Returns one line
    per link."""
    if root.tag != "robot":
        return []
    notes = []
    for link in root.iter("link"):
        contact = link.find("contact")
        if contact is None:
            continue
        friction_element = contact.find("lateral_friction")
        link.remove(contact)
        if friction_element is None or friction_element.get("value") is None:
            continue
        friction = float(friction_element.get("value"))
        if not friction >= 0:
            raise ValueError(f"link '{link.get('name')}' has a negative or undefined lateral_friction")
        for collision in link.findall("collision"):
            if collision.find(f"{DRAKE_NS}proximity_properties") is None:
                wrapped = f'<w xmlns:drake="{DRAKE_NS[1:-1]}">{tags(friction)}</w>'
                collision.append(ET.fromstring(wrapped)[0])
        notes.append("friction as PyBullet's <contact> lateral_friction gives it")
    return notes


# -- the geometry of a body ----------------------------------------------------------------------
def _numbers(text: str | None, count: int, default: float = 0.0) -> np.ndarray:
    values = [float(x) for x in (text or "").split()]
    return np.array(values + [default] * (count - len(values)))[:count]


def _pose_matrix(xyz: np.ndarray, rpy: np.ndarray) -> np.ndarray:
    from pydrake.math import RollPitchYaw

    X = np.eye(4)
    X[:3, :3] = RollPitchYaw(rpy).ToRotationMatrix().matrix()
    X[:3, 3] = xyz
    return X


def _unit_sphere() -> np.ndarray:
    import trimesh

    return trimesh.creation.icosphere(subdivisions=2).vertices


def _circle_points(radius: float, length: float) -> np.ndarray:
    a = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    ring = np.column_stack([radius * np.cos(a), radius * np.sin(a)])
    return np.vstack([np.column_stack([ring, np.full(32, -length / 2)]),
                      np.column_stack([ring, np.full(32, length / 2)])])


def _mesh_points(path: str, scale: np.ndarray) -> np.ndarray:
    import trimesh

    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as e:  # trimesh raises many types for a file it cannot read
        raise ValueError(f"mesh {path} could not be read: {str(e).splitlines()[0]}") from None
    points = np.asarray(mesh.vertices, float) * scale
    if len(points) == 0 or not np.isfinite(points).all():
        raise ValueError(f"mesh {path} has no usable vertices")
    return points


def _shape_points(kind: str, params: dict[str, str | None]) -> np.ndarray:
    """Points on a geometry's surface in its own frame (mesh: its vertices, scaled)."""
    if kind == "box":
        half = _numbers(params["size"], 3) / 2
        return np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    if kind == "cylinder":
        return _circle_points(float(params["radius"]), float(params["length"]))
    if kind == "capsule":
        r, length = float(params["radius"]), float(params["length"])
        return np.vstack([_circle_points(r, length), _unit_sphere() * r + [0, 0, length / 2],
                          _unit_sphere() * r - [0, 0, length / 2]])
    if kind == "sphere":
        return _unit_sphere() * float(params["radius"])
    if kind == "ellipsoid":
        return _unit_sphere() * _numbers(params["radii"], 3)
    if kind == "mesh":
        return _mesh_points(str(params["path"]), _numbers(params["scale"], 3, 1.0))
    return np.zeros((0, 3))


def _urdf_geometry(geometry: ET.Element) -> tuple[str, dict] | None:
    for shape in geometry:
        attrs = dict(shape.attrib)
        if shape.tag == "mesh":
            attrs = {"path": attrs.get("filename"), "scale": attrs.get("scale")}
        return shape.tag.split("}")[-1], attrs
    return None


def _sdf_geometry(geometry: ET.Element) -> tuple[str, dict] | None:
    for shape in geometry:
        fields = {child.tag: child.text for child in shape}
        if shape.tag == "mesh":
            fields = {"path": (fields.get("uri") or "").strip(), "scale": fields.get("scale")}
        return shape.tag.split("}")[-1], fields
    return None


def collision_points(link: ET.Element, urdf: bool) -> np.ndarray:
    """(n, 3) points of a URDF or SDF link's collision geometry, in the link frame [the file's units]."""
    return np.vstack([np.zeros((0, 3)), *collision_point_sets(link, urdf)])


def collision_point_sets(link: ET.Element, urdf: bool) -> list[np.ndarray]:
    """The points of each of a URDF or SDF link's collision geometries, in the link frame."""
    out = []
    for collision in link.findall("collision"):
        geometry = collision.find("geometry")
        if geometry is None:
            continue
        if urdf:
            origin = collision.find("origin")
            xyz, rpy = (None, None) if origin is None else (origin.get("xyz"), origin.get("rpy"))
            X = _pose_matrix(_numbers(xyz, 3), _numbers(rpy, 3))
            shape = _urdf_geometry(geometry)
        else:
            pose = collision.find("pose")
            values = _numbers(None if pose is None else pose.text, 6)
            X = _pose_matrix(values[:3], values[3:])
            shape = _sdf_geometry(geometry)
        if shape is not None:
            points = _shape_points(*shape)
            if len(points):
                out.append(points @ X[:3, :3].T + X[:3, 3])
    return out


# -- inertia -------------------------------------------------------------------------------------
def hull_mesh(points: np.ndarray):
    """The convex hull of points as a closed, outward-facing trimesh (open3d's qhull)."""
    import open3d as o3d
    import trimesh

    # To 0.01 mm and unique: near-duplicate points give qhull (here and in Drake) degenerate faces.
    points = np.unique(np.round(np.asarray(points, float), 5), axis=0)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    hull, _ = cloud.compute_convex_hull()
    return outward(trimesh.Trimesh(np.asarray(hull.vertices), np.asarray(hull.triangles), process=True))


def outward(mesh):
    """Flips a closed trimesh whose faces point inward (negative signed volume)."""
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def hull_inertia(points: np.ndarray, mass: float, p_LoLcm: np.ndarray) -> np.ndarray:
    """The inertia [kg m^2] about the point p_LoLcm (link frame axes) of the points' convex hull, solid,
    of `mass`."""
    unit = hull_mesh(points).mass_properties  # at unit density
    I_cm = np.asarray(unit["inertia"]) * (mass / max(unit["mass"], 1e-18))
    d = np.asarray(p_LoLcm, float) - np.asarray(unit["center_mass"], float)
    return I_cm + mass * (np.dot(d, d) * np.eye(3) - np.outer(d, d))


def pieces_inertia(point_sets: list[np.ndarray], mass: float, p_LoLcm: np.ndarray) -> np.ndarray:
    """The inertia [kg m^2] about p_LoLcm of a body of `mass` made of the convex hulls of `point_sets` (a
    link's collision geometries) at one density, overlaps counted twice; the hull of all the points when
    no set spans a volume. A concave body decomposed into pieces (a bowl) keeps its shape's inertia."""
    pieces = [hull_mesh(points).mass_properties for points in point_sets if _solid(points)]
    if not pieces:
        return hull_inertia(np.vstack(point_sets), mass, p_LoLcm)
    density = mass / sum(piece["mass"] for piece in pieces)  # (unit density: a piece's mass is its volume)
    inertia = np.zeros((3, 3))
    for piece in pieces:
        m = piece["mass"] * density
        d = np.asarray(p_LoLcm, float) - np.asarray(piece["center_mass"], float)
        inertia += np.asarray(piece["inertia"]) * density + m * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return inertia


def inertia_problem(I: np.ndarray, mass: float, points: np.ndarray,  # noqa: E741
                    p_LoLcm: np.ndarray) -> str | None:
    """Why an inertia [kg m^2] about the centre of mass cannot belong to a body of `mass` whose geometry
    is `points` (link frame), or None: not a valid rotational inertia, more than the whole mass at the
    body's diameter would give, or a hundredth of its hull's."""
    if not np.isfinite(I).all():
        return "not finite"
    moments = np.linalg.eigvalsh((I + I.T) / 2)
    scale = max(float(np.max(np.abs(moments))), 1e-30)
    if moments[0] <= 0 or moments[2] > moments[0] + moments[1] + 1e-6 * scale:
        return "not a rotational inertia (its moments break the triangle inequality)"
    if len(points) < 4:
        return None
    diameter = float(np.max(np.linalg.norm(points - points.mean(axis=0), axis=1))) * 2
    if moments[2] > mass * diameter ** 2:
        return f"more than {mass:g} kg can have within {diameter:.3g} m"
    hull = hull_inertia(points, mass, p_LoLcm)
    if np.trace(I) < MIN_INERTIA_FRACTION * np.trace(hull):
        return f"under a hundredth of its collision hull's at {mass:g} kg"
    return None


def _inertia_matrix(element: ET.Element, urdf: bool) -> np.ndarray:
    names = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    if urdf:
        v = {n: float(element.get(n, "0")) for n in names}
    else:
        v = {n: float(e.text) if (e := element.find(n)) is not None and e.text else 0.0 for n in names}
    return np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]],
                     [v["ixz"], v["iyz"], v["izz"]]])


def _set_inertia(element: ET.Element, I: np.ndarray, urdf: bool) -> None:  # noqa: E741
    values = {"ixx": I[0, 0], "ixy": I[0, 1], "ixz": I[0, 2], "iyy": I[1, 1], "iyz": I[1, 2], "izz": I[2, 2]}
    for name, value in values.items():
        if urdf:
            element.set(name, f"{value:.6e}")
        else:
            child = element.find(name)
            if child is None:
                child = ET.SubElement(element, name)
            child.text = f"{value:.6e}"


def fix_inertias(root: ET.Element) -> list[str]:
    """Replaces each link's impossible or absurd inertia (`inertia_problem`) by that of its collision
    geometries' hulls (`pieces_inertia`) at the file's mass, about the file's centre of mass (link axes);
    returns one line per replaced inertia."""
    urdf = root.tag == "robot"
    notes = []
    for link in root.iter("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        mass_element = inertial.find("mass")
        if mass_element is None:
            continue
        mass = float(mass_element.get("value", "0") if urdf else (mass_element.text or "0"))
        inertia = inertial.find("inertia")
        if inertia is None or not mass > 0:
            continue
        pose_element = inertial.find("origin" if urdf else "pose")
        if urdf:
            pose = np.concatenate([_numbers(None if pose_element is None else pose_element.get("xyz"), 3),
                                   _numbers(None if pose_element is None else pose_element.get("rpy"), 3)])
        else:
            pose = _numbers(None if pose_element is None else pose_element.text, 6)
        R_LI = _pose_matrix(pose[:3], pose[3:])[:3, :3]
        I_file = R_LI @ _inertia_matrix(inertia, urdf) @ R_LI.T  # link axes
        point_sets = collision_point_sets(link, urdf)
        points = np.vstack([np.zeros((0, 3)), *point_sets])
        problem = inertia_problem(I_file, mass, points, pose[:3])
        if problem is None or len(points) < 4:
            continue
        _set_inertia(inertia, pieces_inertia(point_sets, mass, pose[:3]), urdf)
        if pose_element is not None:  # the inertia is now in link axes
            if urdf:
                pose_element.set("rpy", "0 0 0")
            else:
                pose_element.text = " ".join(f"{x:.6g}" for x in pose[:3]) + " 0 0 0"
        moments = np.linalg.eigvalsh((I_file + I_file.T) / 2)
        notes.append(f"inertia {' '.join(f'{m:.3g}' for m in moments)} kg m^2 of link "
                     f"'{link.get('name')}' is {problem}")
    return notes


def model_size(root: ET.Element) -> float:
    """The largest extent of any link's collision geometry [the file's units] (0 without geometry)."""
    sizes = [float(np.max(np.ptp(p, axis=0))) for link in root.iter("link")
             if len(p := collision_points(link, root.tag == "robot"))]
    return max(sizes, default=0.0)


# -- scaling -------------------------------------------------------------------------------------
def _scaled_text(text: str | None, scale: float, count: int | None = None) -> str:
    values = [float(x) for x in (text or "").split()]
    k = len(values) if count is None else count
    return " ".join(f"{v * scale:.9g}" if i < k else f"{v:.9g}" for i, v in enumerate(values))


def scale_model_tree(root: ET.Element, scale: float) -> None:
    """Scales every length of a URDF or SDF tree by `scale` in place: poses' translations, primitive sizes,
    mesh scales, and inertias (by scale^2). Masses are kept (as a simulator's global scaling keeps them)."""
    if scale == 1.0:
        return
    if root.tag == "robot":
        for element in root.iter("origin"):
            if element.get("xyz"):
                element.set("xyz", _scaled_text(element.get("xyz"), scale))
        for tag, names in (("box", ("size",)), ("cylinder", ("radius", "length")), ("sphere", ("radius",)),
                           ("capsule", ("radius", "length"))):
            for element in root.iter(tag):
                for name in names:
                    if element.get(name):
                        element.set(name, _scaled_text(element.get(name), scale))
        for element in root.iter("mesh"):
            element.set("scale", _scaled_text(element.get("scale") or "1 1 1", scale))
        for element in root.iter("inertia"):
            for name, value in element.attrib.items():
                element.set(name, f"{float(value) * scale ** 2:.6e}")
        return
    for element in root.iter("pose"):
        element.text = _scaled_text(element.text, scale, 3)
    for shape in ("box", "cylinder", "sphere", "capsule", "ellipsoid"):
        for element in root.iter(shape):
            for child in element:
                if child.tag in _PRIMITIVE_LENGTHS:
                    child.text = _scaled_text(child.text, scale)
    for element in root.iter("mesh"):
        child = element.find("scale")
        if child is None:
            child = ET.SubElement(element, "scale")
            child.text = "1 1 1"
        child.text = _scaled_text(child.text, scale)
    for element in root.iter("inertia"):
        for child in element:
            if child.text:
                child.text = f"{float(child.text) * scale ** 2:.6e}"
    for element in root.iter(f"{DRAKE_NS}mesh_resolution_hint"):
        element.text = _scaled_text(element.text, scale)
