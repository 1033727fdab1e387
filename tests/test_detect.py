"""detect: grasps from a recorded depth image, executed in the scene it came from; bad input."""

import json

import numpy as np
import pytest
from PIL import Image
from scenes import drawn_fraction, one_cube_yaml

from drake_grasp.apps.compare_detect import compare_seed, record_scene
from drake_grasp.apps.detect import main
from drake_grasp.perception.camera import load_camera, load_depth, save_camera
from drake_grasp.perception.config import SamplingConfig
from drake_grasp.robot.paths import OBJECT_SETS_DIR

ONE_CUBE = one_cube_yaml(max_attempts=1)


@pytest.fixture(scope="module")
def cube_scene(tmp_path_factory):
    """A simulated depth image (16-bit PNG, mm) of one cube before the Panda, and its camera YAML."""
    folder = tmp_path_factory.mktemp("scene")
    objects = folder / "objects"
    objects.mkdir()
    (objects / "cube.sdf").write_text((OBJECT_SETS_DIR / "primitives" / "cube.sdf").read_text())
    scenario = folder / "one_cube.yaml"
    scenario.write_text(ONE_CUBE)
    record_scene("panda", str(scenario), str(objects), 0, folder / "depth.png", folder / "camera.yaml")
    return folder


def detect(scene, *extra, depth=None, camera=None) -> int:
    depth, camera = depth or scene / "depth.png", camera or scene / "camera.yaml"
    return main(["--depth", str(depth), "--camera", str(camera), "--out", str(scene / "out" / "grasps.json"),
                 *extra])


def test_detect_ranks_grasps_on_the_cube_and_plans_the_best(cube_scene):
    assert detect(cube_scene, "--top", "3", "--plan", "--candidates", "100") == 0
    found = json.loads((cube_scene / "out" / "grasps.json").read_text())
    assert len(found["grasps"]) == 3 and found["object_points"] > 100
    assert found["score_is"] == "p_r * p_s * p_h"
    for g in found["grasps"]:  # on the 5 cm cube at (0.5, 0.05), the score p_r * p_s * p_h (default models)
        assert np.linalg.norm(np.array(g["position"][:2]) - [0.5, 0.05]) < 0.05
        assert 0 < g["p_h"] <= 1
        assert g["score"] == pytest.approx(g["p_r"] * g["p_s"] * g["p_h"], abs=1e-4)
        X_BG, X_BT, X_BH = (np.array(g[k]) for k in ("X_BG", "X_BT", "X_BH"))
        assert np.allclose(X_BT[:3, 3], X_BG[:3, 3] + 0.01 * X_BG[:3, 2], atol=1e-5)  # 1 cm past the point
        assert np.allclose(X_BH[:3, 3], X_BT[:3, 3] - 0.1034 * X_BG[:3, 2], atol=1e-5)  # Franka's TCP depth
        assert g["opening"] == 0.08
    plan = found["plan"]
    assert plan["rank"] == 0 and len(plan["joint_names"]) == 7
    assert len(plan["transit"]["q"][0]) == 7 and plan["lift"]["t"][-1] > 0
    assert drawn_fraction(cube_scene / "out" / "grasps.png") > 0.05


def test_staged_selection_finds_the_same_best_grasps_with_fewer_cnn_calls(cube_scene):
    found = {}
    for selection in ("full", "staged"):
        assert detect(cube_scene, "--top", "5", "--candidates", "300", "--selection", selection) == 0
        found[selection] = json.loads((cube_scene / "out" / "grasps.json").read_text())["grasps"]
    assert [g["X_BG"] for g in found["staged"]] == [g["X_BG"] for g in found["full"]]
    assert [g["score"] for g in found["staged"]] == [g["score"] for g in found["full"]]


@pytest.mark.slow
def test_the_grasp_detect_plans_is_executed_in_the_same_scene(cube_scene, tmp_path):
    row = compare_seed("panda", str(cube_scene / "one_cube.yaml"), str(cube_scene / "objects"), 0, tmp_path)
    assert row["detect_exit"] == 0
    assert row["detect"]["success"] and row["detect"]["rise"] >= 0.15
    assert row["closed_loop"]["success"]


def _write(path, array=None, image=None):
    if image is not None:
        image.save(path)
    else:
        np.save(path, array)
    return path


@pytest.mark.parametrize("make, message", [
    (lambda d, p: p / "missing.png", "depth file not found"),
    (lambda d, p: _write(p / "d.jpg", image=Image.new("L", (4, 4))), "unknown depth format"),
    (lambda d, p: _write(p / "d8.png", image=Image.fromarray(np.nan_to_num(d * 100).astype(np.uint8))),
     "8-bit or colour"),
    (lambda d, p: _write(p / "m.png", image=Image.fromarray(np.round(np.nan_to_num(d)).astype(np.uint16))),
     "looks like metres"),
    (lambda d, p: _write(p / "mm.npy", d * 1000.0), "looks like millimetres"),
    (lambda d, p: _write(p / "int.npy", np.nan_to_num(d * 1000).astype(np.uint16)), "holds integers"),
    (lambda d, p: _write(p / "zeros.npy", np.zeros_like(d)), "no valid depth pixel"),
    (lambda d, p: _write(p / "nan.npy", np.full_like(d, np.nan)), "no valid depth pixel"),
    (lambda d, p: _write(p / "small.npy", d[:240, :320]), "intrinsics are for 640 x 480"),
])
def test_bad_depth_exits_2_with_one_line(cube_scene, tmp_path, capsys, make, message):
    depth = make(load_depth(cube_scene / "depth.png"), tmp_path)
    assert detect(cube_scene, depth=depth) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_a_camera_that_does_not_see_the_workspace_exits_2(cube_scene, tmp_path, capsys):
    camera = load_camera(cube_scene / "camera.yaml")
    camera.rpy_deg = [0.0, 0.0, 0.0]  # looking up at the ceiling
    save_camera(camera, tmp_path / "up.yaml")
    assert detect(cube_scene, camera=tmp_path / "up.yaml") == 2
    assert "no depth reading falls inside the workspace" in capsys.readouterr().err


FULL_CAMERA = ("width: 640\nheight: 480\nfx: 461.0\nfy: 461.0\ncx: 319.5\ncy: 239.5\n"
               "xyz: [0.55, 0.0, 1.3]\nrpy_deg: [180.0, 0.0, 0.0]\n")


@pytest.mark.parametrize("text, message", [
    ("width: 640\nheight: wide\n", "invalid camera file"),
    (FULL_CAMERA.replace("fx: 461.0", "fx: -1"), "focal lengths must be positive"),
    (FULL_CAMERA.replace("fx: 461.0\n", ""), "lacks fx: a camera must state width, height, fx"),
    (FULL_CAMERA.replace("xyz: [0.55, 0.0, 1.3]\n", "").replace("cy: 239.5\n", ""), "lacks cy, xyz"),
])
def test_a_bad_camera_file_exits_2(cube_scene, tmp_path, capsys, text, message):
    (tmp_path / "camera.yaml").write_text(text)
    assert detect(cube_scene, camera=tmp_path / "camera.yaml") == 2
    assert message in capsys.readouterr().err


def test_depth_in_metres_from_npy_and_exr_reads_like_the_png(cube_scene, tmp_path):
    import OpenEXR

    depth = load_depth(cube_scene / "depth.png")
    np.save(tmp_path / "d.npy", depth)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"Z": np.nan_to_num(depth).astype(np.float32)}) as exr:
        exr.write(str(tmp_path / "d.exr"))
    for path in (tmp_path / "d.npy", tmp_path / "d.exr"):
        np.testing.assert_array_equal(np.isnan(load_depth(path)), np.isnan(depth))
        np.testing.assert_allclose(np.nan_to_num(load_depth(path)), np.nan_to_num(depth))


def test_realsense_without_a_camera_exits_2_with_one_line(cube_scene, capsys):
    out = cube_scene / "out" / "live.json"
    assert main(["--realsense", "--camera", str(cube_scene / "camera.yaml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()  # no package (CI) or no camera (a machine with the extra)
    assert len(err.splitlines()) == 1
    assert "needs pyrealsense2" in err or "no RealSense camera is connected" in err
    assert not out.exists()


def test_a_saved_capture_replays_as_the_same_depth_and_camera(cube_scene, tmp_path):
    from drake_grasp.apps.detect import save_capture

    depth, camera = load_depth(cube_scene / "depth.png"), load_camera(cube_scene / "camera.yaml")
    save_capture(depth, camera, tmp_path / "live.json")
    np.testing.assert_allclose(np.nan_to_num(load_depth(tmp_path / "live_depth.png")), np.nan_to_num(depth))
    assert load_camera(tmp_path / "live_camera.yaml") == camera


def test_a_detector_loads_once_and_takes_depth_images_and_point_clouds(cube_scene):
    from drake_grasp import DetectConfig, GraspDetector
    from drake_grasp.perception.camera import points_in_base

    detector = GraspDetector("panda", DetectConfig(sampling=SamplingConfig(num_candidates=100)))
    scorer = detector.scorer
    depth, camera = load_depth(cube_scene / "depth.png"), load_camera(cube_scene / "camera.yaml")
    first = detector.detect(depth=depth, camera=camera)
    again = detector.detect(depth=depth, camera=camera)
    assert detector.scorer is scorer and first.score_name == "p_r * p_s * p_h"
    np.testing.assert_array_equal(first.ranked.X_WG, again.ranked.X_WG)  # the same frame, the same grasps
    from_cloud = detector.detect(cloud_B=points_in_base(depth, camera), viewpoint=np.array(camera.xyz))
    np.testing.assert_array_equal(from_cloud.ranked.X_WG, first.ranked.X_WG)
    assert np.linalg.norm(first.ranked.X_WG[0][:2, 3] - [0.5, 0.05]) < 0.05
    planned = detector.detect(depth=depth, camera=camera, plan=True, q_current=[0.0, -0.785, 0.0, -2.356,
                                                                                0.0, 1.571, 0.785])
    assert planned.plan is not None and detector.planner() is detector.planner()
    with pytest.raises(ValueError, match="not both"):
        detector.detect(depth=depth, camera=camera, cloud_B=np.zeros((5, 3)))
    with pytest.raises(ValueError, match="needs its camera"):
        detector.detect(depth=depth)
    with pytest.raises(ValueError, match="7 finite joint positions"):
        detector.detect(depth=depth, camera=camera, q_current=[0.0, np.nan, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="no finite point"):
        detector.detect(cloud_B=np.full((10, 3), np.nan))
    with pytest.raises(ValueError, match="unknown robot"):
        GraspDetector("kuka")


@pytest.mark.parametrize("storage, encoding", [("mcap", "16UC1"), ("sqlite3", "32FC1")])
def test_detect_reads_a_ros2_bag_frame_by_frame(cube_scene, tmp_path, storage, encoding):
    from ros_files import write_depth_bag

    depth, camera = load_depth(cube_scene / "depth.png"), load_camera(cube_scene / "camera.yaml")
    q = {f"panda_joint{k + 1}": v for k, v in enumerate([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])}
    bag = write_depth_bag(tmp_path / "cell", depth, camera, storage=storage, encoding=encoding,
                          joints=q | {"panda_finger_joint1": 0.04})
    pose = tmp_path / "pose.yaml"  # the optical frame's pose only: CameraInfo has the intrinsics
    pose.write_text(f"xyz: {list(camera.xyz)}\nrpy_deg: {list(camera.rpy_deg)}\n")
    out = tmp_path / "grasps.json"
    assert main(["--bag", str(bag), "--camera", str(pose), "--candidates", "100", "--top", "3",
                 "--out", str(out)]) == 0
    found = json.loads(out.read_text())
    assert len(found["frames"]) == 2 and found["frames"][0]["frame_id"] == "camera_depth_optical_frame"
    assert found["frames"][1]["stamp_ns"] - found["frames"][0]["stamp_ns"] == 100_000_000
    for frame in found["frames"]:
        assert frame["q"] == pytest.approx(list(q.values()))
        assert np.linalg.norm(np.array(frame["grasps"][0]["position"][:2]) - [0.5, 0.05]) < 0.05


def test_a_bag_places_its_camera_by_its_own_tf(cube_scene, tmp_path, capsys):
    """The optical frame's pose from /tf_static (base_link -> camera_link -> camera_depth_optical_frame, as a
    robot_state_publisher and a camera driver record it): the same grasps as the camera YAML's pose."""
    from pydrake.math import RigidTransform, RollPitchYaw
    from ros_files import write_depth_bag

    depth, camera = load_depth(cube_scene / "depth.png"), load_camera(cube_scene / "camera.yaml")
    X_LC = RigidTransform(RollPitchYaw(np.radians([-90.0, 0.0, -90.0])), [0.0, 0.015, 0.0])  # optical in link
    X_BL = camera.X_BC @ X_LC.inverse()
    chain = [("base_link", "camera_link", X_BL.GetAsMatrix4()),
             ("camera_link", "camera_depth_optical_frame", X_LC.GetAsMatrix4())]
    bag = write_depth_bag(tmp_path / "cell", depth, camera, frames=1, tf_static=chain)
    pose = tmp_path / "pose.yaml"
    pose.write_text(f"xyz: {list(camera.xyz)}\nrpy_deg: {list(camera.rpy_deg)}\n")
    by_yaml, by_tf = tmp_path / "yaml.json", tmp_path / "tf.json"
    common = ["--bag", str(bag), "--candidates", "100", "--top", "3"]
    assert main([*common, "--camera", str(pose), "--out", str(by_yaml)]) == 0
    assert main([*common, "--base-frame", "base_link", "--out", str(by_tf)]) == 0
    yaml_frame, tf_frame = (json.loads(f.read_text())["frames"][0] for f in (by_yaml, by_tf))
    np.testing.assert_allclose(tf_frame["camera_pose"]["xyz"], camera.xyz, atol=1e-6)
    for a, b in zip(yaml_frame["grasps"], tf_frame["grasps"], strict=True):
        np.testing.assert_allclose(a["position"], b["position"], atol=2e-3)
    assert main([*common, "--base-frame", "world", "--out", str(by_tf)]) == 0  # not in the TF: kept, with why
    assert "no frame 'world'" in json.loads(by_tf.read_text())["frames"][0]["error"]
    capsys.readouterr()
    plain = write_depth_bag(tmp_path / "plain", depth, camera, frames=1)
    assert main(["--bag", str(plain), "--base-frame", "base_link", "--out", str(by_tf)]) == 2
    err = capsys.readouterr().err
    assert "no tf2_msgs/msg/TFMessage" in err and len(err.strip().splitlines()) == 1
    with pytest.raises(SystemExit):
        main(["--bag", str(plain), "--out", str(by_tf)])  # neither a camera YAML nor --base-frame


def test_a_bag_that_cannot_be_used_exits_2_with_one_line(cube_scene, tmp_path, capsys):
    from ros_files import write_depth_bag

    depth, camera = load_depth(cube_scene / "depth.png"), load_camera(cube_scene / "camera.yaml")
    pose = tmp_path / "pose.yaml"
    pose.write_text(f"xyz: {list(camera.xyz)}\nrpy_deg: {list(camera.rpy_deg)}\n")
    colour = write_depth_bag(tmp_path / "colour", depth, camera, encoding="rgb8", frames=1)
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "metadata.yaml").write_text("not: a bag\n")
    for bag, message in ((colour, "not depth"), (tmp_path / "missing", "bag not found"),
                         (tmp_path / "junk", "not a readable ROS 2 bag")):
        assert main(["--bag", str(bag), "--camera", str(pose), "--out", str(tmp_path / "g.json")]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1


def test_the_transform_tree_chains_the_latest_transforms_and_names_what_it_cannot_connect():
    from types import SimpleNamespace as Msg

    from pydrake.math import RigidTransform, RollPitchYaw

    from drake_grasp.perception.camera import CameraError
    from drake_grasp.perception.ros_bag import TransformTree

    def message(*edges):
        out = []
        for parent, child, X in edges:
            q, p = X.rotation().ToQuaternion(), X.translation()
            out.append(Msg(header=Msg(frame_id=parent), child_frame_id=child, transform=Msg(
                translation=Msg(x=p[0], y=p[1], z=p[2]), rotation=Msg(w=q.w(), x=q.x(), y=q.y(), z=q.z()))))
        return Msg(transforms=out)

    X_BA = RigidTransform(RollPitchYaw(0.1, -0.2, 0.3), [0.5, 0.1, 0.2])
    X_AW = RigidTransform(RollPitchYaw(0.0, 0.4, -1.0), [0.0, 0.0, 0.3])
    X_AC = RigidTransform(RollPitchYaw(-1.5, 0.0, -1.5), [0.02, 0.0, 0.0])
    tree = TransformTree()
    tree.add(message(("/base", "arm", X_BA), ("arm", "wrist", X_AW), ("arm", "camera", X_AC)))
    X = tree.lookup("wrist", "camera")  # up from the wrist, down to the camera
    np.testing.assert_allclose(X.GetAsMatrix4(), (X_AW.inverse() @ X_AC).GetAsMatrix4(), atol=1e-12)
    moved = RigidTransform([0.0, 0.0, 0.5])
    tree.add(message(("base", "arm", moved)))  # /tf: the latest transform of a frame replaces the last
    np.testing.assert_allclose(tree.lookup("base", "camera").GetAsMatrix4(), (moved @ X_AC).GetAsMatrix4(),
                               atol=1e-12)
    tree.add(message(("map", "odom", RigidTransform())))
    with pytest.raises(CameraError, match="does not connect 'base' and 'odom'"):
        tree.lookup("base", "odom")
    with pytest.raises(CameraError, match="no frame 'tool0'"):
        tree.lookup("base", "tool0")
    tree.add(message(("camera", "base", RigidTransform())))
    with pytest.raises(CameraError, match="loop"):
        tree.lookup("base", "camera")
