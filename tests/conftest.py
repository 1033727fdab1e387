import pytest

from drake_grasp.planning.planner import GraspPlanner
from drake_grasp.robot.specs import ROBOTS


@pytest.fixture(scope="session")
def planners() -> dict[str, GraspPlanner]:
    """One planner per arm, shared: building one costs about 0.2 s."""
    return {name: GraspPlanner(spec, seed=0) for name, spec in ROBOTS.items()}
