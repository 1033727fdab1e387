"""The grasp service over loopback: a real gRPC server with real detectors, several clients at once, bad
payloads of every kind, a token, a client that gives up mid-request, and a clean stop on SIGTERM."""

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import grpc
import numpy as np
import pytest
from scenes import one_cube_yaml

from drake_grasp.apps.compare_detect import record_scene
from drake_grasp.cell.detection import DetectConfig
from drake_grasp.perception.camera import load_camera, load_depth
from drake_grasp.perception.config import SamplingConfig
from drake_grasp.robot.paths import OBJECT_SETS_DIR, REPO_ROOT
from drake_grasp.service import grasp_service_pb2 as pb
from drake_grasp.service.client import GraspClient, detect_request
from drake_grasp.service.server import GraspServer, ServeConfig

HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    """A simulated depth image of one cube at (0.5, 0.05) and its camera."""
    folder = tmp_path_factory.mktemp("scene")
    objects = folder / "objects"
    objects.mkdir()
    (objects / "cube.sdf").write_text((OBJECT_SETS_DIR / "primitives" / "cube.sdf").read_text())
    (folder / "one_cube.yaml").write_text(one_cube_yaml(max_attempts=1))
    record_scene("panda", str(folder / "one_cube.yaml"), str(objects), 0, folder / "depth.png",
                 folder / "camera.yaml")
    return load_depth(folder / "depth.png"), load_camera(folder / "camera.yaml")


@pytest.fixture(scope="module")
def server():
    detect = DetectConfig(sampling=SamplingConfig(num_candidates=60))
    server = GraspServer(ServeConfig(port=0, workers=2, queue=2, detect=detect))
    yield server
    server.stop(1.0)


def test_a_client_gets_grasps_with_their_poses_and_a_plan(server, frame):
    depth, camera = frame
    with GraspClient(server.address) as client:
        assert client.health().status == "SERVING"
        version = client.version()
        assert version.protocol == "drake_grasp.v1" and version.robot == "panda"
        reply = client.detect(depth, camera, q_current=HOME, plan=True, top=3)
    assert reply["score_is"] == "p_r * p_s * p_h" and len(reply["grasps"]) == 3
    best = reply["grasps"][0]
    assert np.linalg.norm(best["X_BG"][:2, 3] - [0.5, 0.05]) < 0.05
    assert np.allclose(best["X_BT"][:3, 3], best["X_BG"][:3, 3] + 0.01 * best["X_BG"][:3, 2], atol=1e-6)
    assert best["score"] == pytest.approx(best["p_r"] * best["p_s"] * best["p_h"], abs=1e-5)
    plan = reply["plan"]
    assert plan is not None and plan["q"].shape == (len(plan["t"]), 7)
    assert np.allclose(plan["q"][0], HOME, atol=1e-3)  # it starts where the arm is


def test_several_clients_at_once_are_all_answered_or_refused_with_a_status(server, frame):
    depth, camera = frame
    statuses, lock = [], threading.Lock()

    def one_client() -> None:
        with GraspClient(server.address, timeout=120) as client:
            for _ in range(2):
                try:
                    client.detect(depth, camera, top=1)
                    status = grpc.StatusCode.OK
                except grpc.RpcError as e:
                    status = e.code()
                with lock:
                    statuses.append(status)

    threads = [threading.Thread(target=one_client) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
    assert len(statuses) == 12  # none lost
    assert set(statuses) <= {grpc.StatusCode.OK, grpc.StatusCode.RESOURCE_EXHAUSTED}
    assert statuses.count(grpc.StatusCode.OK) >= 4  # two workers and two waiting places served some


def _bad(request: pb.DetectRequest, change) -> pb.DetectRequest:
    bad = pb.DetectRequest()
    bad.CopyFrom(request)
    change(bad)
    return bad


def test_bad_payloads_of_every_kind_are_refused_with_one_line(server, frame):
    depth, camera = frame
    good = detect_request(depth, camera)
    mm = np.nan_to_num(depth * 1000).astype("<u2")
    cases = {
        "encoding": lambda r: setattr(r.depth, "encoding", "rgb8"),
        "bytes": lambda r: setattr(r.depth, "data", r.depth.data[:-4]),
        "over": lambda r: setattr(r.depth, "width", 100_000),
        "no valid pixel": lambda r: setattr(r.depth, "data", np.full(depth.shape, np.nan, "<f4").tobytes()),
        "metres sent as 16UC1": lambda r: (setattr(r.depth, "encoding", "16UC1"),
                                           setattr(r.depth, "data", np.round(np.nan_to_num(depth)).astype(
                                               "<u2").tobytes())),
        "millimetres sent as 32FC1": lambda r: setattr(r.depth, "data", mm.astype("<f4").tobytes()),
        "NaN or infinity": lambda r: setattr(r.camera, "fx", float("nan")),
        "xyz and rpy_deg": lambda r: r.camera.xyz.pop(),
        "but the depth image": lambda r: setattr(r.camera, "width", 320),
        "joint positions": lambda r: r.q_current.extend([0.0, 1.0]),
        "mask holds": lambda r: setattr(r, "mask", b"\x01" * 10),
        "no depth reading falls inside": lambda r: r.camera.xyz.__setitem__(2, 30.0),
    }
    with GraspClient(server.address) as client:
        for message, change in cases.items():
            with pytest.raises(grpc.RpcError) as refused:
                client.call("Detect", _bad(good, change))
            assert refused.value.code() == grpc.StatusCode.INVALID_ARGUMENT, message
            assert message in refused.value.details() and "\n" not in refused.value.details(), message
        huge = pb.DetectRequest()
        huge.CopyFrom(good)
        huge.mask = b"\x01" * (65 * 2**20)
        with pytest.raises(grpc.RpcError) as refused:
            client.call("Detect", huge)
        assert refused.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
        assert client.health().status == "SERVING"  # and it still serves
        assert len(client.detect(depth, camera, top=1)["grasps"]) == 1


def test_a_client_that_gives_up_mid_request_leaves_the_server_serving(server, frame):
    depth, camera = frame
    with GraspClient(server.address) as client:
        with pytest.raises(grpc.RpcError) as gone:
            client.detect(depth, camera, timeout=0.05)
        assert gone.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
        time.sleep(0.5)
        assert len(client.detect(depth, camera, top=2)["grasps"]) == 2
        assert client.health().busy == 0


def test_a_token_is_required_when_the_server_has_one_and_beyond_loopback(frame):
    depth, camera = frame
    with pytest.raises(ValueError, match="needs a token"):
        GraspServer(ServeConfig(host="0.0.0.0", port=0, workers=1))
    server = GraspServer(ServeConfig(port=0, workers=1, queue=0, token="s3cret",
                                     detect=DetectConfig(sampling=SamplingConfig(num_candidates=30))))
    try:
        for token in ("", "wrong"):
            with GraspClient(server.address, token=token) as client, pytest.raises(grpc.RpcError) as refused:
                client.detect(depth, camera)
            assert refused.value.code() == grpc.StatusCode.UNAUTHENTICATED
        with GraspClient(server.address, token="s3cret") as client:
            assert len(client.detect(depth, camera, top=1)["grasps"]) == 1
    finally:
        server.stop(1.0)


def test_serve_stops_cleanly_on_sigterm():
    command = [sys.executable, "-m", "drake_grasp", "serve", "--port", "0", "--workers", "1"]
    process = subprocess.Popen(command, cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env=os.environ | {"PYTHONPATH": str(Path(REPO_ROOT))})
    try:
        line = process.stdout.readline()
        assert "serving panda / cnn_rp on 127.0.0.1:" in line, process.stderr.read()
        address = line.split(" on ")[1].split(" ")[0]
        with GraspClient(address) as client:
            assert client.health().status == "SERVING"
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=30) == 0
        assert "stopped" in process.stdout.read()
    finally:
        process.kill()


def test_the_generated_modules_are_those_of_the_proto(tmp_path):
    from grpc_tools import protoc

    proto = "drake_grasp/service/grasp_service.proto"
    assert protoc.main(["protoc", f"-I{REPO_ROOT}", f"--python_out={tmp_path}",
                        f"--grpc_python_out={tmp_path}", str(REPO_ROOT / proto)]) == 0
    for name in ("grasp_service_pb2.py", "grasp_service_pb2_grpc.py"):
        assert (tmp_path / "drake_grasp" / "service" / name).read_text() == \
            (REPO_ROOT / "drake_grasp" / "service" / name).read_text(), f"regenerate {name} from {proto}"
