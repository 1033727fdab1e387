"""Procedural objects: every family is a valid, deterministic Drake object that rests on the table."""

from pathlib import Path

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant

from drake_grasp.apps.make_objects import main as make_objects
from drake_grasp.paths import make_parser
from drake_grasp.simulation.grasp_trial import GraspTrialScene
from drake_grasp.simulation.object_generation import FAMILIES, MAX_GRASP_WIDTH, generate_object, write_sdf
from drake_grasp.simulation.objects import load_object_set
from drake_grasp.simulation.scenario import load_scenario


@pytest.fixture(scope="module")
def one_of_each(tmp_path_factory):
    folder = tmp_path_factory.mktemp("objects")
    objects = [generate_object(0, k, (family,)) for k, family in enumerate(FAMILIES)]
    for obj in objects:
        write_sdf(obj, folder)
    return folder, objects


def test_every_family_is_graspable_sized_and_parses_as_one_free_body(one_of_each):
    folder, objects = one_of_each
    for obj in objects:
        extents = obj.extents()
        assert extents.min() <= MAX_GRASP_WIDTH + 1e-6 and extents.max() <= 0.2, (obj.name, extents)
        assert 0.02 <= obj.mass <= 0.5 and 0.4 <= obj.friction <= 1.0
    models = load_object_set(str(folder))
    assert sorted(m.name for m in models) == sorted(o.name for o in objects)
    plant = MultibodyPlant(0.001)
    parser = make_parser(plant)
    for m in models:
        parser.AddModels(url=m.url)
    plant.Finalize()
    assert plant.num_bodies() == 1 + len(objects)


def test_concave_meshes_are_decomposed_and_compositions_stay_convex_parts(one_of_each):
    _, objects = one_of_each
    by_family = {o.family: o for o in objects}
    assert len(by_family["mug"].pieces) >= 10  # wall staves, bottom (and a handle)
    assert all(p.kind == "mesh" for p in by_family["extrusion"].pieces)


@pytest.mark.parametrize("family", ["mug", "extrusion", "revolution"])
def test_an_object_settles_on_the_table_and_the_camera_sees_it(one_of_each, family):
    folder, objects = one_of_each
    name = next(o.name for o in objects if o.family == family)
    model = next(m for m in load_object_set(str(folder)) if m.name == name)
    scene = GraspTrialScene(load_scenario("single"), model)
    scene.settle(np.random.default_rng(0))
    assert -0.01 < scene.object_pose().translation()[2] < 0.15  # on the table, not through it
    assert len(scene.observe()) > 50


def test_make_objects_is_deterministic_and_resumes(tmp_path):
    assert make_objects(["--count", "3", "--seed", "4", "--out", str(tmp_path / "a"), "--workers", "1"]) == 0
    assert make_objects(["--count", "3", "--seed", "4", "--out", str(tmp_path / "b"), "--workers", "1"]) == 0
    a, b = sorted((tmp_path / "a").glob("*.sdf")), sorted((tmp_path / "b").glob("*.sdf"))
    assert [p.read_text() for p in a] == [p.read_text() for p in b] and len(a) == 3
    # A larger count keeps the three and adds the fourth; another seed in the folder is refused.
    assert make_objects(["--count", "4", "--seed", "4", "--out", str(tmp_path / "a"), "--workers", "1"]) == 0
    assert len(list((tmp_path / "a").glob("*.sdf"))) == 4
    assert make_objects(["--count", "4", "--seed", "5", "--out", str(tmp_path / "a")]) == 2


def test_a_concave_obj_in_an_object_folder_keeps_its_opening(tmp_path):
    import trimesh

    trimesh.creation.annulus(r_min=0.03, r_max=0.04, height=0.08).export(tmp_path / "ring.obj")
    (model,) = load_object_set(str(tmp_path))
    sdf = model.url.removeprefix("file://")
    assert Path(sdf).read_text().count("<collision") >= 4  # CoACD's pieces, not one hull over the hole
