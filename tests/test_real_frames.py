"""Depth frames as a real cell takes them: a noisy table that is tilted and bumpy by a few millimetres,
the arm in its own picture, a workspace mask, and a camera placed by its view of the table."""

import json

import numpy as np
import pytest
from PIL import Image
from ros_files import UR_HOME, write_arm_yaml, write_ros_arm

from drake_grasp.apps.compare_detect import _cell
from drake_grasp.apps.detect import main as detect
from drake_grasp.perception.calibration import calibrate_on_table
from drake_grasp.perception.camera import (
    load_camera,
    project_to_image,
    save_camera,
    save_depth_png,
)
from drake_grasp.perception.cloud import PLANE_DISTANCE, extract_object_cloud, fit_table
from drake_grasp.perception.config import PerceptionConfig
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.self_filter import RobotSelfFilter

Q_IN_VIEW = [-0.6, 0.5, 0.0, -2.0, 0.0, 2.5, 0.785]  # the Panda's fingers at (0.50, -0.34, 0.15): in view
WORKSPACE = [0.22, -0.45, -0.02, 0.88, 0.38, 0.30]
TILES = (np.arange(0.2, 0.9, 0.14), np.arange(-0.5, 0.4, 0.15))  # tile corners along x and y [m]


def bumpy_table_sdf(seed: int) -> str:
    """A tabletop of 14 x 15 cm tiles over the table, tilted 0.4 deg about y (5 mm over its length), each
    tile 0-3 mm higher and tilted up to 0.3 deg at random: a real table and its cloth."""
    rng = np.random.default_rng(seed)
    parts = []
    for i, x in enumerate(TILES[0]):
        for j, y in enumerate(TILES[1]):
            cx, cy = x + 0.07, y + 0.075
            top = 0.004 + np.tan(np.radians(0.4)) * (cx - 0.2) + rng.uniform(0.0, 0.003)
            roll, pitch = np.radians(rng.uniform(-0.3, 0.3, 2))
            box = ("<geometry><box><size>0.14 0.15 0.02</size></box></geometry>")
            pose = f"<pose>{cx:.4f} {cy:.4f} {top - 0.01:.5f} {roll:.5f} {pitch:.5f} 0</pose>"
            parts.append(f"<collision name='c{i}_{j}'>{pose}{box}<drake:proximity_properties>"
                         "<drake:rigid_hydroelastic/><drake:mu_dynamic>0.6</drake:mu_dynamic>"
                         "</drake:proximity_properties></collision>"
                         f"<visual name='v{i}_{j}'>{pose}{box}</visual>")
    return ("<?xml version='1.0'?><sdf version='1.9' xmlns:drake='http://drake.mit.edu'><model name='cloth'>"
            f"<link name='cloth'>{''.join(parts)}</link></model></sdf>")


@pytest.fixture(scope="module")
def real_like_frame(tmp_path_factory):
    """The noisy camera's frame of three objects on the bumpy, tilted tabletop with the Panda's hand and
    forearm reaching into view (its joint positions Q_IN_VIEW); the objects' true positions."""
    folder = tmp_path_factory.mktemp("frame")
    (folder / "cloth.sdf").write_text(bumpy_table_sdf(0))
    (folder / "scene.yaml").write_text(
        "name: bumpy\nclusters:\n  - centre: [0.6, 0.1]\n    radius: 0.08\n    count: 3\nsettle_time: 1.0\n"
        f"fixtures:\n  - model: {folder / 'cloth.sdf'}\n    xyz: [0.0, 0.0, 0.0]\n"
        "plant_config:\n  time_step: 0.004\n")
    cell, scenario = _cell("panda", str(folder / "scene.yaml"), "primitives", 3, depth_noise=True)
    cell.advance(scenario.settle_time)
    plant, context = cell.station.plant(), cell.station.plant_context(cell.context)
    plant.SetPositions(context, cell.station.models.arm, Q_IN_VIEW)
    save_depth_png(cell.depth_image(), folder / "depth.png")
    save_camera(scenario.sensing.camera, folder / "camera.yaml")
    objects = np.array([plant.EvalBodyPoseInWorld(context, body).translation()
                        for body in cell.station.models.object_bodies])
    return folder, objects


def run_detect(folder, *extra) -> dict:
    out = folder / "out" / f"{len(extra)}.json"
    assert detect(["--depth", str(folder / "depth.png"), "--camera", str(folder / "camera.yaml"),
                   "--workspace", *map(str, WORKSPACE), "--candidates", "300", "--out", str(out),
                   *extra]) == 0
    return json.loads(out.read_text())


def test_with_the_joint_state_no_grasp_is_on_the_table_or_the_arm(real_like_frame):
    folder, objects = real_like_frame
    found = run_detect(folder, "--q", *map(str, Q_IN_VIEW))
    assert found["table"]["object_points_within_5mm"] < 0.02
    assert found["table"]["margin_mm"] >= 1000 * PLANE_DISTANCE
    for grasp in found["grasps"]:  # every one of the top 10 on an object, none on the table or the hand
        assert np.linalg.norm(objects[:, :2] - grasp["position"][:2], axis=1).min() < 0.08
        assert grasp["above_table"] > 0.01
    blind = run_detect(folder)  # without the joint state the hand and forearm are "objects"
    assert blind["object_points"] > found["object_points"] + 500
    off_objects = [np.linalg.norm(objects[:, :2] - g["position"][:2], axis=1).min() for g in blind["grasps"]]
    assert max(off_objects) > 0.15


def test_a_workspace_mask_keeps_only_its_pixels(real_like_frame, tmp_path):
    folder, objects = real_like_frame
    camera = load_camera(folder / "camera.yaml")
    mask = np.zeros((camera.height, camera.width), np.uint8)
    u, v = project_to_image(np.array([[0.6, 0.1, 0.0]]), camera)[0].astype(int)
    mask[v - 90:v + 90, u - 90:u + 90] = 255  # a square about the objects, without the arm
    Image.fromarray(mask).save(tmp_path / "mask.png")
    found = run_detect(folder, "--mask", str(tmp_path / "mask.png"))
    for grasp in found["grasps"]:
        assert np.linalg.norm(objects[:, :2] - grasp["position"][:2], axis=1).min() < 0.08
    Image.fromarray(mask[:100]).save(tmp_path / "small.png")
    Image.fromarray(np.zeros_like(mask)).save(tmp_path / "empty.png")
    for bad in ("small.png", "empty.png", "missing.png"):
        assert detect(["--depth", str(folder / "depth.png"), "--camera", str(folder / "camera.yaml"),
                       "--mask", str(tmp_path / bad), "--out", str(tmp_path / "x.json")]) == 2


def test_the_margin_above_the_table_follows_its_scatter_and_the_distance_from_the_camera():
    rng = np.random.default_rng(0)
    xs, ys = np.meshgrid(np.linspace(0.2, 1.2, 200), np.linspace(-0.4, 0.4, 160))
    table = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    camera = np.array([0.0, 0.0, 0.6])
    distance = np.linalg.norm(table - camera, axis=1)
    table[:, 2] += rng.normal(0.0, 0.002 * distance**2)  # a sensor's noise grows with the distance
    box = np.column_stack([rng.uniform(0.3, 0.36, 600), rng.uniform(-0.03, 0.03, 600), np.full(600, 0.008)])
    specks = rng.uniform([0.2, -0.4, 0.02], [1.2, 0.4, 0.1], (40, 3))
    points = np.vstack([table, box, specks])
    flat = fit_table(np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)]))
    assert flat.margin == PLANE_DISTANCE  # a noiseless table: the least margin, as before
    overall = fit_table(points)
    by_range = fit_table(points, viewpoint=camera)
    near, far = by_range.margin_at(np.array([[0.3, 0.0, 0.0], [1.2, 0.0, 0.0]]))
    assert near < 0.008 < far and overall.margin > 0.008  # one margin for all would take the flat box
    cloud = extract_object_cloud(points, lower=[0.1, -0.5, -0.05], upper=[1.3, 0.5, 0.3], viewpoint=camera,
                                 config=PerceptionConfig(remove_specks=True))
    assert len(cloud) >= 0.9 * len(box)
    assert np.mean(by_range.heights(cloud.points) <= 0.005) < 0.02
    assert not any((cloud.points == speck).all(axis=1).any() for speck in specks)  # the specks went


@pytest.mark.parametrize("mesh", [False, True], ids=["cylinders", "meshes"])
def test_the_self_filter_takes_a_users_arm_whatever_its_collision_shapes(tmp_path, mesh):
    robot = get_robot(str(write_arm_yaml(tmp_path, write_ros_arm(tmp_path, mesh_collision=mesh))))
    self_filter = RobotSelfFilter(robot, margin=0.01)
    rng = np.random.default_rng(0)
    # Points on the forearm cylinder (r 4 cm, 30 cm from 4.6 cm) where the arm puts it, and 10 cm off it
    # along its middle (away from the elbow's and wrist's links).
    self_filter.on_robot(np.zeros((1, 3)), UR_HOME)  # the plant's poses at UR_HOME
    X_WL = self_filter.plant.EvalBodyPoseInWorld(self_filter._context,
                                                 self_filter.plant.GetBodyByName("forearm_link"))
    angle, along = rng.uniform(0, 2 * np.pi, 500), rng.uniform(0.13, 0.26, 500)
    on_L = np.column_stack([0.04 * np.cos(angle), 0.04 * np.sin(angle), along])
    off_L = np.column_stack([0.14 * np.cos(angle), 0.14 * np.sin(angle), along])
    on, off = (X_WL.multiply(p.T).T for p in (on_L, off_L))
    assert self_filter.on_robot(on, UR_HOME).mean() > 0.97
    assert not self_filter.on_robot(off, UR_HOME).any()
    with pytest.raises(ValueError, match="6 joints"):
        self_filter.on_robot(on, UR_HOME[:5])


def test_calibrate_places_the_camera_by_the_table_and_detect_then_finds_the_objects(real_like_frame,
                                                                                   tmp_path, capsys):
    folder, objects = real_like_frame
    truth = load_camera(folder / "camera.yaml")
    # The user's named point: a table spot at (0.3, 0.3) in the base frame; +x toward (0.8, 0.3).
    point, toward = np.array([0.3, 0.3, 0.0]), np.array([0.8, 0.3, 0.0])
    (u, v), (ux, vx) = project_to_image(np.array([point, toward]), truth)
    intrinsics = tmp_path / "intrinsics.yaml"
    intrinsics.write_text("".join(f"{k}: {getattr(truth, k)}\n" for k in ("width", "height", "fx", "fy",
                                                                           "cx", "cy")))
    placed = tmp_path / "placed.yaml"
    assert detect(["--calibrate", "--depth", str(folder / "depth.png"), "--camera", str(intrinsics),
                   "--table-pixel", str(u), str(v), "--x-pixel", str(ux), str(vx),
                   "--point-in-base", "0.3", "0.3", "0.0", "--out", str(placed)]) == 0
    assert "mm RMS" in capsys.readouterr().out
    camera = load_camera(placed)
    # The tabletop is 4-9 mm above the table under it and tilted: the pose is as good as that.
    assert np.allclose(camera.xyz, truth.xyz, atol=0.015)
    R = camera.X_BC.rotation().inverse() @ truth.X_BC.rotation()
    assert np.degrees(R.ToAngleAxis().angle()) < 1.0
    out = tmp_path / "grasps.json"
    assert detect(["--depth", str(folder / "depth.png"), "--camera", str(placed), "--q", *map(str, Q_IN_VIEW),
                   "--workspace", *map(str, WORKSPACE), "--candidates", "300", "--out", str(out)]) == 0
    for grasp in json.loads(out.read_text())["grasps"]:
        assert np.linalg.norm(objects[:, :2] - grasp["position"][:2], axis=1).min() < 0.08
    # Without a named point, or with a frame that shows no table, it refuses with one line.
    assert detect(["--calibrate", "--depth", str(folder / "depth.png"), "--camera", str(intrinsics),
                   "--out", str(placed)]) == 2
    wall = np.full((truth.height, truth.width), np.nan, np.float32)
    wall[:, : truth.width // 2] = 1.0
    wall[:, truth.width // 2:] = np.linspace(0.5, 2.0, truth.width - truth.width // 2)[None, :]
    with pytest.raises(ValueError, match="no table|edge-on|straight on|dominant"):
        calibrate_on_table(wall * np.linspace(0.6, 1.4, truth.height)[:, None], truth, p_BP=[0.5, 0, 0])
