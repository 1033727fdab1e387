"""Object files as the grasping field writes them (PyBullet-era URDF + OBJ, scanned and CAD meshes):
OBJ meshes without normals, mesh scales, placeholder inertias, millimetres; and the benchmark's
per-object scale. The files are written here in those tools' own formats."""

from pathlib import Path

import numpy as np
import pytest
import trimesh
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.systems.framework import DiagramBuilder

from drake_grasp.robot.config import default_plant_config
from drake_grasp.robot.paths import make_parser
from drake_grasp.robot.plant import add_scene
from drake_grasp.simulation.objects import load_object_set, scaled_object
from drake_grasp.simulation.placement import collision_vertices
from drake_grasp.simulation.scenario import load_scenario
from drake_grasp.simulation.station import Station


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DRAKE_GRASP_CACHE", str(tmp_path / "cache"))


def write_box_obj(path: Path, size, *, normals: bool = False, scale: float = 1.0) -> Path:
    """A box as an exporter writes it: `v`, `vt`, quads `f v/vt` (with `vn` and `v/vt/vn` on request)."""
    half = np.asarray(size, float) / 2 * scale
    corners = [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)] * half
    quads = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    lines = ["mtllib box.mtl", "o box", *(f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in corners),
             "vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1", "usemtl skin"]
    if normals:
        lines += ["vn 0 0 1"]
        lines += [f"f {a}/1/1 {b}/2/1 {c}/3/1 {d}/4/1" for a, b, c, d in quads]
    else:
        lines += [f"f {a}/1 {b}/2 {c}/3 {d}/4" for a, b, c, d in quads]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_pybullet_urdf(folder: Path, name: str, mesh: str, *, mass: float, scale: str = "1 1 1",
                        inertia: str = 'ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"',
                        friction: float | None = 1.0, collision_mesh: str | None = None) -> Path:
    """An object URDF as the field's PyBullet sets write them: PyBullet's `<contact>` friction, a
    placeholder inertia, a scaled mesh (`collision_mesh`: another for collision)."""
    path = folder / f"{name}.urdf"
    contact = ("" if friction is None else
               f'<contact><lateral_friction value="{friction}"/><rolling_friction value="0.0"/></contact>')
    path.write_text(f"""<?xml version="1.0"?>
<robot name="{name}">
  <link name="base_link">
    {contact}
    <inertial><origin xyz="0 0 0" rpy="0 0 0"/><mass value="{mass}"/><inertia {inertia}/></inertial>
    <visual><origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="{mesh}" scale="{scale}"/></geometry></visual>
    <collision><origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="{collision_mesh or mesh}" scale="{scale}"/></geometry></collision>
  </link>
</robot>
""")
    return path


def _body(models, k=0):
    """(plant, the k-th object's body) with the objects parsed into a finalized plant."""
    plant, _ = AddMultibodyPlant(default_plant_config(), DiagramBuilder())
    scene = add_scene(plant, make_parser(plant), robot=None, objects=models)
    plant.Finalize()
    return plant, scene.object_bodies[k]


def _extent(model) -> np.ndarray:
    """The axis-aligned extent of an object's collision geometry in its own frame [m]."""
    station = Station(scenario=load_scenario("single"), robot=None, objects=[model])
    inspector = station.scene_graph().model_inspector()
    return np.ptp(collision_vertices(station.plant(), inspector, station.object_bodies[0]), axis=0)


def test_pybullet_urdf_with_normal_less_scaled_obj_and_placeholder_inertia_loads_and_renders(tmp_path):
    folder = tmp_path / "pile"
    (folder / "meshes").mkdir(parents=True)
    write_box_obj(folder / "meshes" / "tea_visual.obj", (0.05, 0.08, 0.16))
    write_box_obj(folder / "meshes" / "tea_collision.obj", (0.05, 0.08, 0.16))
    path = write_pybullet_urdf(folder, "tea", "meshes/tea_collision.obj", mass=0.2, scale="0.9 0.9 0.9")
    text = path.read_text().replace('meshes/tea_collision.obj" scale="0.9 0.9 0.9"/></geometry></visual>',
                                    'meshes/tea_visual.obj" scale="0.9 0.9 0.9"/></geometry></visual>')
    path.write_text(text)
    models = load_object_set(str(folder))
    assert [m.name for m in models] == ["tea"]
    # Notes name PyBullet's friction, read, and the impossible inertia and what replaced it.
    friction_note, note = models[0].notes
    assert friction_note == "friction as PyBullet's <contact> lateral_friction gives it"
    assert "inertia 1 1 1 kg m^2" in note and "recomputed from its collision pieces' hulls" in note
    plant, body = _body(models)
    I = body.default_rotational_inertia().CopyToFullMatrix3()  # noqa: E741
    a, b, c = 0.9 * np.array([0.05, 0.08, 0.16])  # the box at the file's scale: a solid box's inertia
    expected = 0.2 / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    np.testing.assert_allclose(I, expected, rtol=0.02, atol=1e-9)
    assert body.default_mass() == pytest.approx(0.2)
    # The renderer takes the normal-less visual (Drake refuses an OBJ without normals): the camera sees it.
    scenario = load_scenario("single")
    station = Station(scenario=scenario, robot=None, objects=models)
    context = station.CreateDefaultContext()
    station.plant().SetFreeBodyPose(station.plant_context(context), station.object_bodies[0],
                                    RigidTransform([0.5, 0.0, 0.072]))
    cloud = station.GetOutputPort("point_cloud_W").Eval(context).xyzs().T
    top = cloud[np.isfinite(cloud).all(axis=1) & (np.abs(cloud[:, 0] - 0.5) < 0.02)
                & (np.abs(cloud[:, 1]) < 0.03)]
    assert top[:, 2].max() == pytest.approx(0.072 + 0.9 * 0.08, abs=0.004)


def test_a_sensible_inertia_is_kept_and_the_file_used_as_it_is(tmp_path):
    folder = tmp_path / "set"
    (folder / "meshes").mkdir(parents=True)
    write_box_obj(folder / "meshes" / "box.obj", (0.05, 0.05, 0.1), normals=True)
    inertia = 'ixx="2.1e-4" ixy="0" ixz="0" iyy="2.1e-4" iyz="0" izz="8.3e-5"'
    path = write_pybullet_urdf(folder, "box", "meshes/box.obj", mass=0.2, inertia=inertia, friction=None)
    (model,) = load_object_set(str(folder))
    assert model.notes == () and model.url == path.resolve().as_uri()


def test_an_obj_in_millimetres_is_refused_with_one_line_and_read_when_the_user_says_so(tmp_path):
    folder = tmp_path / "mm"
    folder.mkdir()
    write_box_obj(folder / "can.obj", (66.0, 66.0, 120.0))  # a bare OBJ, exported in millimetres
    with pytest.raises(ValueError, match=r"120 m across.*millimetres: --object-units mm"):
        load_object_set(str(folder))
    (model,) = load_object_set(str(folder), units="mm")
    assert model.notes == ("lengths read in mm (scaled by 0.001)",)
    np.testing.assert_allclose(np.sort(_extent(model)), [0.066, 0.066, 0.12], atol=0.002)


def test_a_urdf_in_millimetres_is_refused_naming_its_file(tmp_path):
    folder = tmp_path / "cad"
    (folder / "meshes").mkdir(parents=True)
    write_box_obj(folder / "meshes" / "part.obj", (40.0, 60.0, 150.0), normals=True)
    write_pybullet_urdf(folder, "part", "meshes/part.obj", mass=0.3)
    with pytest.raises(ValueError, match=r"part\.urdf is 150 m across"):
        load_object_set(str(folder))
    (model,) = load_object_set(str(folder), units="mm")
    assert "lengths read in mm (scaled by 0.001)" in model.notes


def test_a_scaled_object_has_every_length_scaled_and_its_mass_kept(tmp_path):
    (cube,) = [m for m in load_object_set("primitives") if m.name == "brick"]
    half = scaled_object(cube, 0.5)
    assert half.name == cube.name and half.url != cube.url
    assert scaled_object(cube, 1.0) == cube
    extents = [_extent(m) for m in (cube, half)]
    np.testing.assert_allclose(extents[1], 0.5 * extents[0], atol=1e-6)
    bodies = [_body([m])[1] for m in (cube, half)]
    assert bodies[1].default_mass() == pytest.approx(bodies[0].default_mass())
    inertias = [b.default_rotational_inertia().CopyToFullMatrix3() for b in bodies]
    np.testing.assert_allclose(inertias[1], 0.25 * inertias[0], rtol=1e-4)
    assert extents[0].max() == pytest.approx(0.1)


CUP_PIECES = {"floor": ((-0.04, -0.04, 0.0), (0.04, 0.04, 0.01)),  # (low, high) corners [m]
              "left": ((-0.04, -0.04, 0.0), (0.04, -0.03, 0.08)),
              "right": ((-0.04, 0.03, 0.0), (0.04, 0.04, 0.08))}


def write_decomposed_cup(path: Path) -> Path:
    """A U-shaped cup (a floor and two walls, open at the top) as V-HACD writes a decomposition: one OBJ
    holding each convex piece as an `o` shape, no normals."""
    lines, offset = [], 0
    for name, (lo, hi) in CUP_PIECES.items():
        lines.append(f"o {name}")
        lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                  for z in (lo[2], hi[2])]
        quads = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
        lines += [f"f {a + offset} {b + offset} {c + offset} {d + offset}" for a, b, c, d in quads]
        offset += 8
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_decomposed_collision_mesh_collides_as_its_pieces_with_the_files_friction(tmp_path):
    folder = tmp_path / "pile"
    (folder / "meshes").mkdir(parents=True)
    write_decomposed_cup(folder / "meshes" / "cup_collision.obj")
    write_box_obj(folder / "meshes" / "cup_visual.obj", (0.08, 0.08, 0.08))
    write_pybullet_urdf(folder, "cup", "meshes/cup_visual.obj", mass=0.15, friction=0.45,
                        collision_mesh="meshes/cup_collision.obj")
    (model,) = load_object_set(str(folder))
    assert ("a collision OBJ of several shapes (a convex decomposition) collides as one convex piece per "
            "shape, as PyBullet collides it") in model.notes
    assert "friction as PyBullet's <contact> lateral_friction gives it" in model.notes
    station = Station(scenario=load_scenario("single"), robot=None, objects=[model])
    plant, inspector = station.plant(), station.scene_graph().model_inspector()
    geometries = plant.GetCollisionGeometriesForBody(station.object_bodies[0])
    assert len(geometries) == 3
    # The cup's inside is free: no piece's hull holds a point between the walls (the file's hull would).
    inside = np.array([0.0, 0.0, 0.05])
    for g in geometries:
        hull = inspector.GetConvexHull(g)
        X_BG = inspector.GetPoseInFrame(g)
        vertices = np.array([X_BG.multiply(hull.vertex(i)) for i in range(hull.num_vertices())])
        assert not ((vertices.min(axis=0) < inside) & (inside < vertices.max(axis=0))).all()
    assert _frictions(station) == pytest.approx([0.45] * 3)
    # The placeholder inertia becomes the three pieces' at one density (not the solid cube's of the hull).
    pieces = [trimesh.creation.box(bounds=bounds) for bounds in CUP_PIECES.values()]
    inertia = sum(np.asarray(box.moment_inertia_frame(np.eye(4))) for box in pieces) * 0.15 / sum(
        box.volume for box in pieces)  # (trimesh: about the frame's origin, the file's centre of mass)
    np.testing.assert_allclose(_body([model])[1].default_rotational_inertia().CopyToFullMatrix3(), inertia,
                               rtol=1e-3, atol=1e-9)
    np.testing.assert_allclose(np.ptp(collision_vertices(plant, inspector, station.object_bodies[0]), axis=0),
                               [0.08, 0.08, 0.08], atol=1e-6)
    # A friction of 1.0, which Drake also reports for a geometry that names none, is the file's too.
    write_pybullet_urdf(folder, "cup", "meshes/cup_visual.obj", mass=0.15, friction=1.0,
                        collision_mesh="meshes/cup_collision.obj")
    (model,) = load_object_set(str(folder))
    assert _frictions(Station(scenario=load_scenario("single"), robot=None, objects=[model])) == [1.0] * 3


def _frictions(station: Station) -> list[float]:
    """The static friction of each collision geometry of the station's first object."""
    inspector = station.scene_graph().model_inspector()
    return [inspector.GetProximityProperties(g).GetProperty("material", "coulomb_friction").static_friction()
            for g in station.plant().GetCollisionGeometriesForBody(station.object_bodies[0])]
