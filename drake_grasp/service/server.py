"""The grasp service: a gRPC server (`grasp_service.proto`) in front of a pool of `GraspDetector`s.

gRPC because a robot stack in any language can call it from the `.proto` alone, with deadlines,
status codes and message-size limits built in (the field's grasp servers use it or ZMQ; ZMQ leaves
framing, errors and limits to each client). The detectors (models, self-filter, planner plant) are built
once, one per worker; a request takes a free one, so `workers` requests run at once and up to
`queue` more wait; beyond that a request is refused with RESOURCE_EXHAUSTED, never dropped. The server
listens on 127.0.0.1 unless told otherwise, and anywhere else only with a token, which every request
must then carry (`authorization: Bearer TOKEN`). Every request is checked (sizes, encodings, NaN,
units) and a bad one answered with INVALID_ARGUMENT and one line; nothing a client sends ends the server.
"""

from __future__ import annotations

import dataclasses as dc
import ipaddress
import logging
import queue
import threading
from concurrent import futures

import grpc
import numpy as np

from drake_grasp.cell.detection import DetectConfig, Detection, GraspDetector
from drake_grasp.perception.camera import PLAUSIBLE_DEPTH_M, CameraConfig
from drake_grasp.robot.arms import get_robot
from drake_grasp.robot.hand import HandSpec
from drake_grasp.service import grasp_service_pb2 as pb
from drake_grasp.service import grasp_service_pb2_grpc as rpc

log = logging.getLogger(__name__)
PROTOCOL = "drake_grasp.v1"
ENCODINGS = {"16UC1": (np.dtype("<u2"), 0.001), "32FC1": (np.dtype("<f4"), 1.0)}
MAX_PIXELS = 4096 * 4096
PLAN_SAMPLES_PER_SECOND = 50.0


@dc.dataclass
class ServeConfig:
    """Where the server listens, who may call it, and how many requests it serves at once."""

    host: str = "127.0.0.1"
    port: int = 50051  # 0: any free port (`GraspServer.port` says which)
    token: str = ""  # required of every request when set; required to listen beyond loopback
    workers: int = 2  # detectors, each serving one request at a time
    queue: int = 8  # requests waiting for a detector beyond the workers; more are refused
    max_request_mb: float = 64.0  # larger requests are refused by gRPC itself
    detect: DetectConfig = dc.field(default_factory=DetectConfig)
    robot: str = "panda"
    hand: str = ""  # a shipped hand or a hand YAML file; "": the arm's

    def check(self) -> None:
        if not is_loopback(self.host) and not self.token:
            raise ValueError(f"listening on {self.host} (beyond this machine) needs a token (--token)")
        if self.workers < 1 or self.queue < 0:
            raise ValueError(f"workers must be >= 1 and queue >= 0, got {self.workers} and {self.queue}")
        if not 0 <= self.port <= 65535:
            raise ValueError(f"port must be 0-65535, got {self.port}")


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class RequestError(ValueError):
    """A request the server cannot use; its message is the one line the client gets."""


def depth_from_request(image: pb.DepthImage) -> np.ndarray:
    """The request's depth image [m], NaN where there is no reading (0, NaN and, as ROS's REP 118 writes
    too near and too far, infinities); RequestError names what is wrong."""
    if image.encoding not in ENCODINGS:
        raise RequestError(f"depth encoding '{image.encoding}' is not one of {', '.join(ENCODINGS)}")
    if image.width == 0 or image.height == 0 or image.width * image.height > MAX_PIXELS:
        raise RequestError(f"depth size {image.width} x {image.height} is empty or over {MAX_PIXELS} pixels")
    dtype, scale = ENCODINGS[image.encoding]
    expected = image.width * image.height * dtype.itemsize
    if len(image.data) != expected:
        raise RequestError(f"depth data holds {len(image.data)} bytes; {image.width} x {image.height} "
                           f"{image.encoding} needs {expected}")
    pixels = np.frombuffer(image.data, dtype=dtype).reshape(image.height, image.width)
    depth = pixels.astype(np.float32) * scale
    depth = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan).astype(np.float32)
    valid = depth[np.isfinite(depth)]
    if valid.size == 0:
        raise RequestError("depth has no valid pixel (all zero or NaN)")
    median = float(np.median(valid))
    if not PLAUSIBLE_DEPTH_M[0] <= median <= PLAUSIBLE_DEPTH_M[1]:
        hint = " (millimetres sent as 32FC1 metres?)" if median > PLAUSIBLE_DEPTH_M[1] else \
            " (metres sent as 16UC1 millimetres?)"
        raise RequestError(f"depth reads {median:.4g} m at the median: no depth camera's{hint}")
    return depth


def camera_from_request(camera: pb.Camera, depth: np.ndarray) -> CameraConfig:
    numbers = [camera.fx, camera.fy, camera.cx, camera.cy, *camera.xyz, *camera.rpy_deg, *camera.depth_range]
    if not np.isfinite(numbers).all():
        raise RequestError("the camera holds NaN or infinity")
    if len(camera.xyz) != 3 or len(camera.rpy_deg) != 3 or len(camera.depth_range) not in (0, 2):
        raise RequestError("the camera needs xyz and rpy_deg (3 numbers each), depth_range 2 or none")
    if (camera.width, camera.height) != (depth.shape[1], depth.shape[0]):
        raise RequestError(f"the camera is {camera.width} x {camera.height} but the depth image "
                           f"{depth.shape[1]} x {depth.shape[0]}")
    config = CameraConfig(width=camera.width, height=camera.height, fx=camera.fx, fy=camera.fy, cx=camera.cx,
                          cy=camera.cy, xyz=list(camera.xyz), rpy_deg=list(camera.rpy_deg),
                          depth_range=list(camera.depth_range) or [0.1, 3.0])
    try:
        config.check()
    except ValueError as e:
        raise RequestError(str(e)) from None
    return config


def reply_from_detection(found: Detection, joint_names, top: int, hand: HandSpec) -> pb.DetectReply:
    ranked = found.ranked
    X_GT, X_GH = hand.X_GT.GetAsMatrix4(), hand.X_GH.GetAsMatrix4()
    reply = pb.DetectReply(score_is=found.score_name, object_points=len(found.cloud), candidates=len(ranked))
    for k in range(min(top, len(ranked))):
        X_BG = ranked.X_WG[k]
        reply.grasps.append(pb.Grasp(X_BG=X_BG.ravel(), X_BT=(X_BG @ X_GT).ravel(),
                                     X_BH=(X_BG @ X_GH).ravel(), opening=hand.stroke, p_r=ranked.p_r[k],
                                     p_s=ranked.p_s[k], p_h=ranked.p_h[k], score=ranked.scores[k]))
    reply.plan_failures.extend(found.plan_failures)
    if found.plan is not None:
        reply.planned, reply.planned_rank = True, found.planned_rank
        reply.joint_names.extend(joint_names)
        offset = 0.0
        for name in ("transit", "approach", "lift"):
            trajectory = getattr(found.plan, name)
            start, end = trajectory.start_time(), trajectory.end_time()
            t = np.append(np.arange(start, end, 1 / PLAN_SAMPLES_PER_SECOND), end)
            reply.plan_t.extend(offset + t - trajectory.start_time())
            reply.plan_q.extend(np.concatenate([trajectory.value(x).ravel() for x in t]))
            offset += trajectory.end_time() - trajectory.start_time()
    return reply


class GraspServicer(rpc.GraspServiceServicer):
    """The service's calls over a pool of detectors (one per worker, built once)."""

    def __init__(self, config: ServeConfig):
        self.config = config
        self._free: queue.Queue[GraspDetector] = queue.Queue()
        for _ in range(config.workers):
            self._free.put(GraspDetector(get_robot(config.robot, config.hand), config.detect))
        self._lock = threading.Lock()
        self._waiting = self._busy = self._served = self._refused = 0
        self.robot = self._free.queue[0].robot

    def _authorized(self, context) -> bool:
        if not self.config.token:
            return True
        metadata = dict(context.invocation_metadata())
        return metadata.get("authorization") == f"Bearer {self.config.token}"

    def _refuse(self, context, code: grpc.StatusCode, message: str):
        with self._lock:
            self._refused += 1
        context.abort(code, message)

    def Detect(self, request, context):
        if not self._authorized(context):
            self._refuse(context, grpc.StatusCode.UNAUTHENTICATED, "missing or wrong token")
        try:
            depth = depth_from_request(request.depth)
            camera = camera_from_request(request.camera, depth)
            q = np.asarray(request.q_current, dtype=float) if len(request.q_current) else None
            mask = None
            if request.mask:
                if len(request.mask) != depth.size:
                    raise RequestError(f"the mask holds {len(request.mask)} bytes, the depth image "
                                       f"{depth.size} pixels")
                mask = np.frombuffer(request.mask, dtype=np.uint8).reshape(depth.shape) != 0
        except RequestError as e:
            self._refuse(context, grpc.StatusCode.INVALID_ARGUMENT, str(e))
        with self._lock:
            if self._waiting >= self.config.queue + self.config.workers:
                full = True
            else:
                full, self._waiting = False, self._waiting + 1
        if full:
            self._refuse(context, grpc.StatusCode.RESOURCE_EXHAUSTED, "the server is full; retry later")
        detector = self._free.get()
        with self._lock:
            self._busy += 1
        gone = not context.is_active()  # the client gave up while the request waited
        try:
            if gone:
                return pb.DetectReply()  # nobody reads it
            found = detector.detect(depth=depth, camera=camera, q_current=q, mask=mask, plan=request.plan)
            reply = reply_from_detection(found, self.robot.joint_names, request.top or 10, self.robot.hand)
        except ValueError as e:  # bad joint positions, no object in view, a camera that misses the workspace
            self._refuse(context, grpc.StatusCode.INVALID_ARGUMENT, str(e).splitlines()[0])
        except Exception as e:  # never the server's end: the client gets one line, the log the rest
            log.exception("detect failed")
            message = f"{type(e).__name__}: {(str(e).splitlines() or [''])[0]}"
            self._refuse(context, grpc.StatusCode.INTERNAL, message)
        finally:
            self._free.put(detector)
            with self._lock:
                self._busy -= 1
                self._waiting -= 1
        with self._lock:
            self._served += 1
        return reply

    def Health(self, request, context):
        if not self._authorized(context):
            self._refuse(context, grpc.StatusCode.UNAUTHENTICATED, "missing or wrong token")
        with self._lock:
            return pb.HealthReply(status="SERVING", workers=self.config.workers, busy=self._busy,
                                  served=self._served, refused=self._refused)

    def Version(self, request, context):
        from importlib.metadata import PackageNotFoundError, version

        if not self._authorized(context):
            self._refuse(context, grpc.StatusCode.UNAUTHENTICATED, "missing or wrong token")
        try:
            package = version("drake_grasp")
        except PackageNotFoundError:
            package = "unknown"
        return pb.VersionReply(package_version=package, protocol=PROTOCOL, robot=self.robot.name,
                               policy=self.config.detect.policy, joint_names=list(self.robot.joint_names))


class GraspServer:
    """The gRPC server, started; `stop` ends it (in-flight requests get `grace` seconds)."""

    def __init__(self, config: ServeConfig):
        config.check()
        self.config = config
        self.servicer = GraspServicer(config)
        limit = int(config.max_request_mb * 2**20)
        self._server = grpc.server(
            futures.ThreadPoolExecutor(max_workers=config.workers + config.queue + 2),
            options=[("grpc.max_receive_message_length", limit), ("grpc.max_send_message_length", limit)])
        rpc.add_GraspServiceServicer_to_server(self.servicer, self._server)
        host = f"[{config.host}]" if ":" in config.host else config.host
        self.port = self._server.add_insecure_port(f"{host}:{config.port}")
        if self.port == 0:
            raise ValueError(f"could not listen on {config.host}:{config.port}")
        self._server.start()

    @property
    def address(self) -> str:
        host = f"[{self.config.host}]" if ":" in self.config.host else self.config.host
        return f"{host}:{self.port}"

    def wait(self) -> None:
        self._server.wait_for_termination()

    def stop(self, grace: float = 5.0) -> None:
        self._server.stop(grace).wait()
