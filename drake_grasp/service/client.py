"""A Python client of the grasp service (`grasp_service.proto`): numpy in, numpy out.

    >>> client = GraspClient("127.0.0.1:50051")
    >>> reply = client.detect(depth_m, camera, q_current=q, plan=True)
    >>> reply["grasps"][0]["X_BG"], reply["score_is"]

A refused request raises `grpc.RpcError` with the server's status code and one-line message.
"""

from __future__ import annotations

import grpc
import numpy as np

from drake_grasp.perception.camera import CameraConfig
from drake_grasp.service import grasp_service_pb2 as pb
from drake_grasp.service import grasp_service_pb2_grpc as rpc


def detect_request(depth_m: np.ndarray, camera: CameraConfig, *, q_current=None, plan: bool = False,
                   mask: np.ndarray | None = None, top: int = 10) -> pb.DetectRequest:
    """The request for a depth image [m] (sent as 32FC1, NaN: no reading) and its camera."""
    depth = np.ascontiguousarray(depth_m, dtype="<f4")
    height, width = depth.shape
    request = pb.DetectRequest(
        depth=pb.DepthImage(width=width, height=height, encoding="32FC1", data=depth.tobytes()),
        camera=pb.Camera(width=camera.width, height=camera.height, fx=camera.fx, fy=camera.fy,
                         cx=camera.cx, cy=camera.cy, xyz=camera.xyz, rpy_deg=camera.rpy_deg,
                         depth_range=camera.depth_range),
        plan=plan, top=top)
    if q_current is not None:
        request.q_current.extend(np.asarray(q_current, dtype=float))
    if mask is not None:
        request.mask = (np.asarray(mask) != 0).astype(np.uint8).tobytes()
    return request


def reply_to_dict(reply: pb.DetectReply) -> dict:
    """The reply with its poses as 4 x 4 arrays and its plan as (t, q) arrays."""
    grasps = [{"X_BG": np.reshape(g.X_BG, (4, 4)), "X_BT": np.reshape(g.X_BT, (4, 4)),
               "X_BH": np.reshape(g.X_BH, (4, 4)), "opening": g.opening, "p_r": g.p_r, "p_s": g.p_s,
               "p_h": g.p_h, "score": g.score} for g in reply.grasps]
    out = {"grasps": grasps, "score_is": reply.score_is, "object_points": reply.object_points,
           "candidates": reply.candidates, "plan_failures": list(reply.plan_failures), "plan": None}
    if reply.planned:
        joints = list(reply.joint_names)
        out["plan"] = {"rank": reply.planned_rank, "joint_names": joints, "t": np.asarray(reply.plan_t),
                       "q": np.reshape(reply.plan_q, (-1, len(joints)))}
    return out


class GraspClient:
    """Calls a grasp server at `address` ("host:port"), with its token when it has one."""

    def __init__(self, address: str, *, token: str = "", timeout: float = 60.0,
                 max_message_mb: float = 64.0):
        limit = int(max_message_mb * 2**20)
        self._channel = grpc.insecure_channel(address, options=[("grpc.max_send_message_length", limit),
                                                                 ("grpc.max_receive_message_length", limit)])
        self._stub = rpc.GraspServiceStub(self._channel)
        self._metadata = [("authorization", f"Bearer {token}")] if token else []
        self.timeout = timeout

    def detect(self, depth_m: np.ndarray, camera: CameraConfig, *, q_current=None, plan: bool = False,
               mask: np.ndarray | None = None, top: int = 10, timeout: float | None = None) -> dict:
        request = detect_request(depth_m, camera, q_current=q_current, plan=plan, mask=mask, top=top)
        return reply_to_dict(self.call("Detect", request, timeout=timeout))

    def call(self, method: str, request, *, timeout: float | None = None):
        """One raw call (`Detect`, `Health`, `Version`) with the client's token and deadline."""
        return getattr(self._stub, method)(request, timeout=timeout or self.timeout, metadata=self._metadata)

    def health(self) -> pb.HealthReply:
        return self.call("Health", pb.HealthRequest())

    def version(self) -> pb.VersionReply:
        return self.call("Version", pb.VersionRequest())

    def close(self) -> None:
        self._channel.close()

    def __enter__(self) -> GraspClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
