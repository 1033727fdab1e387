import shutil

import pytest

from drake_grasp.planning.planner import GraspPlanner
from drake_grasp.robot.paths import OBJECT_SETS_DIR
from drake_grasp.robot.specs import ROBOTS


@pytest.fixture(scope="session")
def planners() -> dict[str, GraspPlanner]:
    """One planner per arm, shared: building one costs about 0.2 s."""
    return {name: GraspPlanner(spec, seed=0) for name, spec in ROBOTS.items()}


@pytest.fixture
def cube_folder(tmp_path):
    """An object folder holding the primitives' cube alone."""
    folder = tmp_path / "objects"
    folder.mkdir()
    shutil.copy(OBJECT_SETS_DIR / "primitives" / "cube.sdf", folder)
    return folder
