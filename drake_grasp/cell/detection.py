"""Grasps from one recorded depth image: the closed loop's perception and ranking, outside the simulator.

    >>> camera = load_camera("camera.yaml")
    >>> found = detect_grasps(load_depth("depth.png"), camera, get_robot("panda"), DetectConfig(plan=True))
    >>> found.ranked.X_WG[0], found.ranked.p_r[0], found.ranked.p_s[0], found.ranked.scores[0]

The image is back-projected into the robot's base frame (which the planner calls
W), less the pixels outside a workspace `mask` and, given the arm's joint positions
`q_current`, less the points on the arm and hand (`RobotSelfFilter`); then cropped to the
workspace box and segmented (`extract_object_cloud`), and the
candidates are sampled and ranked by `rank_grasps` with a policy's scorer: the same
calls the closed loop's `ObjectCloudSystem` and `GraspSelector` make. With
`plan`, the best candidates are planned in rank order (`GraspPlanner.plan` from
`q_current` or home, the transit around the observed objects) until one plans.
"""

from __future__ import annotations

import dataclasses as dc
from pathlib import Path

import numpy as np

from drake_grasp.perception.camera import CameraConfig, CameraError, points_in_base, project_to_image
from drake_grasp.perception.cloud import ObjectCloud, PerceptionError, crop, extract_object_cloud
from drake_grasp.perception.config import PerceptionConfig, SamplingConfig, WorkspaceBox
from drake_grasp.planning.obstacles import ObservedScene
from drake_grasp.planning.planner import GraspPlan, GraspPlanner, PlannerConfig
from drake_grasp.policy.config import SelectionConfig
from drake_grasp.policy.drawing import hand_outline
from drake_grasp.policy.scorers import TWO_CAMERA_POLICIES, make_scorer
from drake_grasp.policy.selector import RankedGrasps, rank_grasps
from drake_grasp.robot.hand import HandSpec
from drake_grasp.robot.self_filter import SELF_FILTER_MARGIN, RobotSelfFilter
from drake_grasp.robot.specs import RobotSpec


@dc.dataclass
class DetectConfig:
    """How `GraspDetector` sees and samples (the closed loop's `sensing` and `sampling` less the camera,
    which comes with each frame), ranks and plans."""

    policy: str = "cnn_rp"
    sampling: SamplingConfig = dc.field(default_factory=SamplingConfig)
    workspace: WorkspaceBox = dc.field(default_factory=WorkspaceBox)  # the cell's box, base frame
    # A real sensor's isolated points above the table go (`cloud.remove_specks`)
    perception: PerceptionConfig = dc.field(default_factory=lambda: PerceptionConfig(remove_specks=True))
    table_height: float = 0.0  # the table top in the base frame, for the planner [m]
    plan: bool = False
    plan_top: int = 10  # candidates planned at most, in rank order
    seed: int = 0
    self_filter_margin: float = SELF_FILTER_MARGIN  # points this near the arm at q_current are the arm's [m]
    # How the CNN policies spend the CNN; the CNN in bfloat16 where this CPU has it natively (twice as fast,
    # p_s within 0.005 of the closed loop's float32 and the same best grasp in 12 of 12 standard frames)
    selection: SelectionConfig = dc.field(default_factory=lambda: SelectionConfig(cnn_precision="auto"))


@dc.dataclass
class Detection:
    cloud: ObjectCloud  # the segmented object points, base frame
    ranked: RankedGrasps  # best first, poses X_WG in the base frame
    plan: GraspPlan | None = None  # the best candidate that planned (with `plan`)
    planned_rank: int | None = None  # its index in `ranked`
    plan_failures: list[str] = dc.field(default_factory=list)  # why the better ones did not
    score_name: str = "score"  # what `ranked.scores` is ("p_r * p_s * p_h" for the default policy)


PRODUCT_POLICIES = ("cnn_rp", "cnn", "rp")  # policies whose score is the product of their predictions


class GraspDetector:
    """Grasps from depth images or point clouds for one arm, policy and selection: the models, the
    self-filter and the planner's plant are loaded once and serve every `detect` call.

        >>> detector = GraspDetector("panda")
        >>> found = detector.detect(depth=load_depth("depth.png"), camera=load_camera("camera.yaml"))
        >>> found.ranked.X_WG[0], found.ranked.scores[0]
    """

    def __init__(self, robot: RobotSpec | str = "panda", config: DetectConfig | None = None):
        from drake_grasp.robot.arms import get_robot

        self.robot = get_robot(robot) if isinstance(robot, str) else robot
        self.config = config = config or DetectConfig()
        config.workspace.check()
        config.sampling.check()
        if config.self_filter_margin < 0:
            raise ValueError(f"the self-filter margin must be >= 0, got {config.self_filter_margin}")
        if config.policy in TWO_CAMERA_POLICIES:
            raise ValueError(f"policy '{config.policy}' fuses two cameras; detection reads one (GPD with one "
                             "camera is 'gpd1c')")
        self.scorer = make_scorer(config.policy, self.robot, config.selection)
        self._self_filter: RobotSelfFilter | None = None
        self._planner: GraspPlanner | None = None

    @property
    def cnn_precision(self) -> str:
        """The arithmetic of its stability CNN on this CPU ("auto" resolved: "float32" or "bfloat16")."""
        from drake_grasp.learning.cnn import resolve_precision

        return resolve_precision(self.config.selection.cnn_precision)

    def self_filter(self) -> RobotSelfFilter:
        """The arm's self-filter (built at the first call that gives joint positions)."""
        if self._self_filter is None:
            self._self_filter = RobotSelfFilter(self.robot, margin=self.config.self_filter_margin)
        return self._self_filter

    def planner(self) -> GraspPlanner:
        """The planner (built at the first call that plans)."""
        if self._planner is None:
            self._planner = GraspPlanner(self.robot, seed=self.config.seed,
                                         config=PlannerConfig(table_height=self.config.table_height))
        return self._planner

    def object_cloud(self, *, depth: np.ndarray | None = None, camera: CameraConfig | None = None,
                     cloud_B: np.ndarray | None = None, viewpoint: np.ndarray | None = None,
                     q_current: np.ndarray | None = None, mask: np.ndarray | None = None) -> ObjectCloud:
        """The object cloud of a depth image (with its `camera`; `mask`: its workspace pixels) or of a
        base-frame cloud `cloud_B` (`viewpoint`: the camera's position, when known), less the points on
        the arm at `q_current`; CameraError when no reading falls in the workspace or no object is on
        the table, PerceptionError for an empty or non-finite cloud."""
        config = self.config
        if (depth is None) == (cloud_B is None):
            raise ValueError("give a depth image (with its camera) or a point cloud, not both")
        if depth is not None:
            if camera is None:
                raise ValueError("a depth image needs its camera (intrinsics and pose)")
            points_B, viewpoint = points_in_base(depth, camera, mask), np.asarray(camera.xyz, dtype=float)
        else:
            points_B = np.asarray(cloud_B, dtype=np.float64)
            if points_B.ndim != 2 or points_B.shape[1] != 3:
                raise PerceptionError(f"a point cloud must be (N, 3), got {points_B.shape}")
            if len(points_B) == 0:
                raise PerceptionError("the point cloud is empty")
            if not np.isfinite(points_B).any():
                raise PerceptionError("the point cloud has no finite point (NaN everywhere)")
        if q_current is not None:
            points_B = self.self_filter().remove(points_B, q_current)
        box = config.workspace
        if len(crop(points_B, box.lower, box.upper)) == 0:
            raise CameraError(f"no depth reading falls inside the workspace box {box.lower} .. "
                              f"{box.upper}: check the camera pose (xyz, rpy_deg)")
        cloud = extract_object_cloud(points_B, lower=box.lower, upper=box.upper, seed=config.seed,
                                     viewpoint=viewpoint, config=config.perception)
        if len(cloud) == 0:
            raise CameraError("the camera sees the workspace but no object on the table (only the table "
                              "plane)")
        return cloud

    def detect(self, *, depth: np.ndarray | None = None, camera: CameraConfig | None = None,
               cloud_B: np.ndarray | None = None, viewpoint: np.ndarray | None = None,
               q_current: np.ndarray | None = None, mask: np.ndarray | None = None,
               plan: bool | None = None) -> Detection:
        """Ranked grasps (`object_cloud`'s inputs) and, with `plan` (default: the config's), a plan of the
        best that plans, from `q_current` or home. The same inputs give the same grasps (the config's
        seed draws every candidate)."""
        config = self.config
        if q_current is not None:
            q_current = np.asarray(q_current, dtype=float).ravel()
            if len(q_current) != len(self.robot.joint_names) or not np.isfinite(q_current).all():
                raise ValueError(f"q_current needs the {self.robot.name} arm's {len(self.robot.joint_names)} "
                                 f"finite joint positions ({', '.join(self.robot.joint_names)})")
        cloud = self.object_cloud(depth=depth, camera=camera, cloud_B=cloud_B, viewpoint=viewpoint,
                                  q_current=q_current, mask=mask)
        sampling = config.sampling
        seen_from = camera.xyz if depth is not None else viewpoint  # (GPG's normals face it)
        ranked = rank_grasps(cloud, self.scorer, num_candidates=sampling.num_candidates,
                             gamma_deg=tuple(sampling.gamma_deg), rng=np.random.default_rng(config.seed),
                             sampler=sampling.sampler, gpg_stop_at_table=sampling.gpg_stop_at_table,
                             camera_positions=None if seen_from is None else [np.asarray(seen_from, float)],
                             hand=self.robot.hand)
        found = Detection(cloud, ranked, score_name=score_name(config.policy, ranked))
        if config.plan if plan is None else plan:
            planner = self.planner()
            for k in range(min(config.plan_top, len(ranked))):
                result = planner.plan(ranked.X_WG[k], q_start=q_current,
                                      observed=ObservedScene(cloud.points, cloud.structure))
                if result.success:
                    found.plan, found.planned_rank = result.plan, k
                    break
                found.plan_failures.append(result.failure.value)
        return found


def score_name(policy: str, ranked: RankedGrasps) -> str:
    """What a detection's score is: the product of the predictions the policy made, or the policy's own."""
    if policy not in PRODUCT_POLICIES:
        return f"{policy} score"
    made = [name for name in ("p_r", "p_s", "p_h") if np.isfinite(getattr(ranked, name)).any()]
    return " * ".join(made)


def detect_grasps(depth_m: np.ndarray, camera: CameraConfig, robot: RobotSpec,
                  config: DetectConfig | None = None, *, q_current: np.ndarray | None = None,
                  mask: np.ndarray | None = None) -> Detection:
    """One detection with a detector built for it (`GraspDetector`; build one to detect many times)."""
    return GraspDetector(robot, config).detect(depth=depth_m, camera=camera, q_current=q_current, mask=mask)


NEAR_TABLE = 0.005  # [m] object points this near the fitted table are counted (table left in the cloud?)


def table_summary(cloud: ObjectCloud) -> dict | None:
    """The fitted table plane: its normal, the margin above it that the objects begin at, its points' RMS
    residual, and the share of object points within `NEAR_TABLE` of it; None when no table was seen."""
    table = cloud.table
    if table is None:
        return None
    near = float(np.mean(table.heights(cloud.points) <= NEAR_TABLE)) if len(cloud) else 0.0
    return {"normal": np.round(table.normal, 5).tolist(), "margin_mm": round(1000 * table.margin, 2),
            "residual_rms_mm": round(1000 * table.residual_rms, 2),
            "object_points_within_5mm": round(near, 4)}


def detection_to_dict(found: Detection, robot: RobotSpec, *, top: int,
                      samples_per_second: float = 50.0) -> dict:
    """JSON-ready: the top grasps (the grasp frame's, the TCP's and the hand's poses in the base frame, the
    opening, p_r, p_s, p_h with a hold predictor, and the score, `score_is` saying what it is) and the
    plan's joint trajectory."""
    ranked = found.ranked
    hand = robot.hand
    X_GT, X_GH = hand.X_GT.GetAsMatrix4(), hand.X_GH.GetAsMatrix4()

    def number(x: float) -> float | None:
        return None if np.isnan(x) else round(float(x), 5)

    table = found.cloud.table
    grasps = [{"rank": k, "X_BG": np.round(ranked.X_WG[k], 6).tolist(),
               "position": np.round(ranked.X_WG[k][:3, 3], 5).tolist(),
               **({"above_table": round(float(table.heights(ranked.X_WG[k][None, :3, 3])[0]), 4)}
                  if table is not None else {}),
               "approach": np.round(ranked.X_WG[k][:3, 2], 5).tolist(),
               "X_BT": np.round(ranked.X_WG[k] @ X_GT, 6).tolist(),
               "X_BH": np.round(ranked.X_WG[k] @ X_GH, 6).tolist(),
               "opening": round(hand.stroke, 4),
               "p_r": number(ranked.p_r[k]), "p_s": number(ranked.p_s[k]), "score": number(ranked.scores[k]),
               **({"p_h": number(ranked.p_h[k])} if np.isfinite(ranked.p_h[k]) else {})}
              for k in range(min(top, len(ranked)))]
    out = {"robot": robot.name, "hand": hand.name, "object_points": len(found.cloud),
           "candidates": len(ranked),
           "score_is": found.score_name, "table": table_summary(found.cloud), "grasps": grasps}
    if found.plan is not None:
        segments = {}
        for name in ("transit", "approach", "lift"):
            trajectory = getattr(found.plan, name)
            t = np.arange(trajectory.start_time(), trajectory.end_time(), 1.0 / samples_per_second)
            t = np.append(t, trajectory.end_time())
            q = np.array([trajectory.value(x).ravel() for x in t])
            segments[name] = {"t": np.round(t, 4).tolist(), "q": np.round(q, 5).tolist()}
        out["plan"] = {"rank": found.planned_rank, "joint_names": list(robot.joint_names), **segments}
    elif found.plan_failures:
        out["plan"] = None
        out["plan_failures"] = found.plan_failures
    return out


def draw_detection(depth_m: np.ndarray, camera: CameraConfig, found: Detection, path: str | Path, *,
                   top: int = 10, hand: HandSpec | None = None) -> None:
    """The depth image with the top grasps drawn as open grippers (`hand`, default the Franka hand; best in
    green, the planned one ringed)."""
    from matplotlib import colormaps
    from matplotlib.figure import Figure  # no pyplot: the caller's backend (a notebook's) stays as it is

    fig = Figure(figsize=(camera.width / 100, camera.height / 100), dpi=100)
    ax = fig.subplots()
    table = float(np.median(depth_m[np.isfinite(depth_m)]))  # most pixels see the table
    ax.imshow(depth_m, cmap="gray", vmin=table - 0.15, vmax=table + 0.01)  # the 15 cm above it, nearer darker
    cloud_uv = project_to_image(found.cloud.points[::5], camera)
    ax.plot(cloud_uv[:, 0], cloud_uv[:, 1], ",", color="orange", alpha=0.5)
    for k in reversed(range(min(top, len(found.ranked)))):
        start, end = hand_outline(found.ranked.X_WG[k], hand)
        uv0, uv1 = project_to_image(start.T, camera), project_to_image(end.T, camera)
        color = colormaps["RdYlGn"](1.0 - k / max(top, 1))
        for a, b in zip(uv0, uv1, strict=True):
            ax.plot([a[0], b[0]], [a[1], b[1]], "-", color=color, lw=2.5 if k == 0 else 1.2)
        tip = project_to_image(found.ranked.X_WG[k][None, :3, 3], camera)[0]
        ax.text(tip[0] + 4, tip[1] - 4, str(k + 1), color=color, fontsize=8, weight="bold")
        if k == found.planned_rank:
            ax.plot(*tip, "o", ms=16, mfc="none", mec="cyan", mew=2)
    ax.set_axis_off()
    planned = "" if found.planned_rank is None else f"; ringed: planned (rank {found.planned_rank + 1})"
    ax.set_title(f"top {min(top, len(found.ranked))} grasps (1 = best p_g){planned}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
