"""Small scenario files and object clouds the tests share."""

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix


def one_cube_yaml(max_attempts: int) -> str:
    """One object at (0.5, 0.05), top-down candidates only, a few attempts: a quick closed loop."""
    return ("name: one_cube\nclusters:\n  - centre: [0.5, 0.05]\n    radius: 0.0\n    count: 1\n"
            "settle_time: 0.6\nsampling: {gamma_deg: [0.0, 0.0], num_candidates: 50}\n"
            f"max_attempts: {max_attempts}\n")


def block_points(seed: int = 0, n: int = 4000) -> np.ndarray:
    """(n, 3) points on the camera-facing faces (top, front, one side) of a 5 x 12 x 6 cm block on the
    table in front of the arm, as a top-down camera sees it (no points on the hidden faces)."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array([0.475, -0.06, 0.0]), np.array([0.525, 0.06, 0.06])
    points = rng.uniform(lo, hi, (n, 3))
    face = rng.integers(0, 3, n)
    points[face == 0, 2] = hi[2]
    points[face == 1, 0] = lo[0]
    points[face == 2, 1] = lo[1]
    return points


def top_down_grasp(scene, *, close_along: int, offset=(0.0, 0.0, 0.0)) -> RigidTransform:
    """Straight down onto the top face's centre, jaws closing along one of the object's horizontal axes.

    close_along: which of the object's two horizontal body axes (0 or 1) the jaws close along.
    """
    X_WO = scene.object_pose()
    R = X_WO.rotation().matrix()
    up = int(np.argmax(np.abs(R[2])))  # the body axis that stands vertical
    horizontal = [i for i in range(3) if i != up]
    y = R[:, horizontal[close_along]].copy()
    y[2] = 0.0
    y /= np.linalg.norm(y)
    z = np.array([0.0, 0.0, -1.0])
    R_WG = RotationMatrix(np.column_stack([np.cross(y, z), y, z]))
    top = scene.observe().points[:, 2].max()
    return RigidTransform(R_WG, [*X_WO.translation()[:2], top] + np.asarray(offset))


def drawn_fraction(png) -> float:
    """The fraction of a PNG's pixels that differ from its most common colour (a blank chart: 0)."""
    import matplotlib.pyplot as plt

    image = plt.imread(png)[..., :3].reshape(-1, 3)
    colours, counts = np.unique(np.round(image, 2), axis=0, return_counts=True)
    return 1.0 - counts.max() / len(image)


def simulate_one_cube(arm, folder) -> tuple[dict, str]:
    """One CNN x RP run of `arm` on the one-cube scene (one attempt) through `python -m
    drake_grasp.simulate`, as a user runs it: (its report, its stderr); asserts it exits 0."""
    import json
    import subprocess
    import sys

    from drake_grasp.robot.paths import REPO_ROOT

    scenario = folder / "one_cube.yaml"
    scenario.write_text(one_cube_yaml(max_attempts=1))
    command = [sys.executable, "-m", "drake_grasp.simulate", "--robot", str(arm), "--scenario", str(scenario),
               "--runs", "1", "--policy", "cnn_rp", "--report", str(folder / "r.json")]
    run = subprocess.run(command, capture_output=True, text=True, timeout=600, cwd=REPO_ROOT)
    assert run.returncode == 0, run.stderr
    return json.loads((folder / "r.json").read_text()), run.stderr


def write_flat_bar(folder) -> None:
    """A screwdriver's handle lying flat, 14 x 2.4 x 1.8 cm, as an SDF file in `folder`."""
    size = "0.14 0.024 0.018"
    (folder / "bar.sdf").write_text(f"""<?xml version="1.0"?>
<sdf version="1.7"><model name="bar"><link name="bar">
  <inertial><mass>0.1</mass><inertia><ixx>1e-5</ixx><iyy>1.6e-4</iyy><izz>1.6e-4</izz>
    <ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial>
  <collision name="c"><geometry><box><size>{size}</size></box></geometry></collision>
  <visual name="v"><geometry><box><size>{size}</size></box></geometry></visual>
</link></model></sdf>""")
