"""Grasp Pose Generator (GPG), the candidate stage of GPD (ten Pas et al., IJRR 2017), for our hand.

For each of `num_samples` points drawn from the object cloud:
1. **Local frame** from the surface normals within `frame_radius`: with M = sum n n^T,
   the eigenvector of the largest eigenvalue is the normal axis (turned to agree with
   the point's normal, which faces the camera), that of the smallest the curvature
   axis (along which the normals do not turn: a cylinder's axis), and their cross
   product the binormal.
2. **Hand search**: the frame is turned about the curvature axis to `orientations`
   angles in [-90, 90] degrees; each gives an approach (minus the turned normal) and a
   closing direction (the turned binormal). For `finger_offsets` placements of the
   hand along the closing direction, the open hand is pushed along the approach until
   a finger or the palm would touch a point (less a margin), at most `max_depth`
   beyond the first surface between the fingers. A placement is kept when the
   fingertips get at least `min_depth` past that surface, at least `min_points`
   points lie between the fingers, and no corner of the hand is below the table
   (`table_height`, the cloud has no table; with `stop_at_table` the push stops at the
   table instead, as GPD's collision check stops it); of each orientation's kept placements
   the middle one of those with the most points between the fingers. Approaches more
   than `max_gamma_deg` from straight down are dropped; with 0 (top grasps only) the
   hand comes straight down instead, its jaws turned about the vertical.
The candidates are poses X_WG in this package's convention (`drake_grasp.robot.hand`: +z the
approach, +y the closing direction, fingertips `HandSpec.tip_beyond_grasp` past the
origin), so every consumer (CNN, RP, planner, trials) takes them as they are.
The hand is a `HandSpec`'s boxes (default the Franka hand); GPD's own parameters were for
another hand.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import open3d as o3d

from drake_grasp.robot.hand import HandSpec, default_hand
from drake_grasp.robot.poses import check_cloud, pose_from_axes
from drake_grasp.simulation.scenario import FIRST_CAMERA_XYZ


@dataclass(frozen=True)
class GpgConfig:
    num_samples: int = 100  # cloud points to build frames at
    frame_radius: float = 0.01  # neighbourhood of a frame [m] (GPD: 1 cm)
    normal_radius: float = 0.01  # neighbourhood of a point's normal [m]
    orientations: int = 9  # hand orientations about the curvature axis, over [-90, 90] degrees (odd: 0 too)
    finger_offsets: int = 10  # hand placements along the closing direction
    min_points: int = 10  # points between the fingers
    min_depth: float = 0.01  # fingertips at least this far past the first surface [m]
    max_depth: float = 0.03  # and at most this far [m]
    margin: float = 0.002  # kept between the hand and any point [m]
    table_height: float | None = 0.0  # the table top (z) no part of the hand may go below; None: no table
    # True: a hand pushed in is stopped where it would touch the table (as GPD's own collision check
    # stops it, the table being in its cloud), so flat objects get shallow grasps; False: it is dropped
    stop_at_table: bool = False
    max_gamma_deg: float = 90.0  # approaches more than this from straight down are dropped [deg]
    camera_positions: tuple[tuple[float, float, float], ...] = (FIRST_CAMERA_XYZ,)  # where the cloud was seen

    def __post_init__(self) -> None:
        if min(self.num_samples, self.orientations, self.finger_offsets, self.min_points) < 1:
            raise ValueError(f"GPG needs at least one sample, orientation, offset and point: {self}")
        if not 0 <= self.min_depth <= self.max_depth:
            raise ValueError(f"GPG needs 0 <= min_depth <= max_depth: {self}")


def estimate_normals(points_W: np.ndarray, *, radius: float, camera_positions) -> np.ndarray:
    """(M, 3) unit surface normals (open3d, up to 30 neighbours within `radius`), each facing the camera
    that looks at its surface most squarely (with one camera: facing it; a fused cloud's side faces
    then face the side camera that saw them)."""
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points_W))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=30))
    normals = np.asarray(cloud.normals).copy()
    cameras = np.asarray(camera_positions, dtype=float).reshape(-1, 3)
    to_camera = cameras[None] - points_W[:, None]  # (M, C, 3)
    to_camera /= np.linalg.norm(to_camera, axis=2, keepdims=True)
    facing = np.einsum("mk,mck->mc", normals, to_camera)  # cosines with +normal
    flip = (-facing).max(axis=1) > facing.max(axis=1)
    normals[flip] *= -1
    return normals


def local_frame(normals: np.ndarray, own_normal: np.ndarray) -> np.ndarray | None:
    """(3, 3) columns [normal, binormal, curvature axis] of a neighbourhood's normals; None if degenerate."""
    if len(normals) < 3:
        return None
    w, V = np.linalg.eigh(normals.T @ normals)  # ascending eigenvalues
    normal, axis = V[:, 2], V[:, 0]
    if normal @ own_normal < 0:
        normal = -normal
    binormal = np.cross(axis, normal)
    return np.stack([normal, binormal, axis], axis=1)


def _hand_box_corners(d: float, s: float, hand: HandSpec) -> np.ndarray:
    """(16, 3) corners (u, v, w) of the fingers' and the palm's boxes: fingertips at u = d, centre v = s."""
    fw, pw = hand.finger_size[0] / 2, hand.palm_size[0] / 2
    reach = hand.max_half_opening + hand.finger_size[1]
    u_base = d - hand.finger_length
    half_palm = hand.palm_size[1] / 2
    boxes = [((u_base, d), (s - reach, s + reach), (-fw, fw)),
             ((u_base - hand.palm_depth, u_base), (s - half_palm, s + half_palm), (-pw, pw))]
    return np.array([[u, v, w] for (u_lo, u_hi), (v_lo, v_hi), (w_lo, w_hi) in boxes
                     for u in (u_lo, u_hi) for v in (v_lo, v_hi) for w in (w_lo, w_hi)])


def table_stop_depth(p: np.ndarray, R: np.ndarray, offsets: np.ndarray, floor: float,
                     hand: HandSpec) -> np.ndarray:
    """(K,) the deepest fingertip depth d at each offset along the closing direction that keeps every
    corner of the hand at or above z = `floor`, for a hand at point p with axes R (columns approach,
    closing, axis) whose approach points down."""
    corners = np.stack([_hand_box_corners(0.0, s, hand) for s in offsets])  # (K, 16, 3) at d = 0
    z0 = p[2] + corners @ R[2]  # each corner's height at d = 0; it falls by -approach_z per metre of d
    return (z0.min(axis=1) - floor) / -R[2, 0] - 1e-9


def search_hand(p: np.ndarray, approach: np.ndarray, closing: np.ndarray, axis: np.ndarray,
                rel: np.ndarray, config: GpgConfig, hand: HandSpec) -> np.ndarray | None:
    """The kept hand placement at point p for one orientation, as X_WG (4, 4); None if none is kept.
    `rel`: the cloud's points near p, less p.

    Every placement along the closing direction is searched at once (a row per offset). Of the
    placements with the most points between the fingers, the middle one: the object then sits as
    centred between the fingers as the offsets allow.
    """
    reach, (pad_x, pad_y), (palm_x, palm_y) = hand.max_half_opening, hand.finger_size, hand.palm_size
    w = rel @ axis
    slab = np.abs(w) <= max(pad_x, palm_x) / 2  # only points at the hand's height can touch it
    rel, w = rel[slab], w[slab]
    u, v = rel @ approach, rel @ closing
    in_finger_height = np.abs(w) <= pad_x / 2
    in_palm_height = np.abs(w) <= palm_x / 2
    offsets = np.linspace(-0.75, 0.75, config.finger_offsets) * reach
    side = np.abs(v[None, :] - offsets[:, None])  # (offsets, points): distance from the hand's centre plane
    between = in_finger_height & (side < reach)
    rows = np.flatnonzero(between.sum(axis=1) >= config.min_points)
    if len(rows) == 0:
        return None
    offsets, side, between = offsets[rows], side[rows], between[rows]
    u_top = np.where(between, u, np.inf).min(axis=1)  # the first surface between the fingers
    on_fingers = in_finger_height & (side >= reach) & (side <= reach + pad_y)
    on_palm = in_palm_height & (side <= palm_y / 2)
    d = u_top + config.max_depth  # fingertip depth: pushed in until a finger or the palm would touch
    d = np.minimum(d, np.where(on_fingers, u, np.inf).min(axis=1) - config.margin)
    d = np.minimum(d, np.where(on_palm, u, np.inf).min(axis=1) + hand.finger_length - config.margin)
    R = np.stack([approach, closing, axis], axis=1)  # (u, v, w) -> world
    if config.stop_at_table and config.table_height is not None and approach[2] < -1e-9:
        d = np.minimum(d, table_stop_depth(p, R, offsets, config.table_height + config.margin, hand))
    counts = (between & (u >= (d - hand.finger_length)[:, None]) & (u <= d[:, None])).sum(axis=1)
    kept: list[tuple[int, float, float]] = []  # (points between the fingers, offset s, fingertip depth d)
    for k in np.flatnonzero((d - u_top >= config.min_depth) & (counts >= config.min_points)):
        if config.table_height is not None:
            corners_W = p + _hand_box_corners(d[k], offsets[k], hand) @ R.T
            if corners_W[:, 2].min() < config.table_height + config.margin:
                continue
        kept.append((int(counts[k]), offsets[k], d[k]))
    if not kept:
        return None
    most = max(count for count, _, _ in kept)
    best = [(s, d) for count, s, d in kept if count == most]
    s, d = best[len(best) // 2]
    origin = p + d * approach + s * closing - hand.tip_beyond_grasp * approach
    return pose_from_axes(origin, approach, closing)


def hand_orientations(frame: np.ndarray, angles: np.ndarray, max_gamma_deg: float):
    """(approach, closing, axis) triples of the hand turned about the frame's curvature axis to each
    angle, those within `max_gamma_deg` of straight down. Top grasps only (max_gamma_deg 0): straight
    down, the closing direction turned about the vertical instead, from the frame's binormal."""
    normal, binormal, axis = frame.T
    if max_gamma_deg <= 0.0:
        down = np.array([0.0, 0.0, -1.0])
        horizontal = binormal - (binormal @ down) * down
        if np.linalg.norm(horizontal) < 1e-6:
            horizontal = np.array([1.0, 0.0, 0.0])
        horizontal /= np.linalg.norm(horizontal)
        for theta in angles:  # [-90, 90] degrees: the jaw's half turn (a jaw swap is the same grasp)
            closing = np.cos(theta) * horizontal + np.sin(theta) * np.cross(down, horizontal)
            yield down, closing, np.cross(down, closing)
        return
    for theta in angles:
        turned_normal = np.cos(theta) * normal + np.sin(theta) * binormal
        approach = -turned_normal
        if approach[2] > -np.cos(np.radians(max_gamma_deg)) + 1e-9:
            continue  # beyond the approach cone (from below the horizontal, by default)
        yield approach, -np.sin(theta) * normal + np.cos(theta) * binormal, axis


def config_normals(points_W: np.ndarray, config: GpgConfig) -> np.ndarray:
    """The cloud's normals as `config` has GPG estimate them."""
    return estimate_normals(points_W, radius=config.normal_radius, camera_positions=config.camera_positions)


def generate_candidates(points_W: np.ndarray, rng: np.random.Generator,
                        config: GpgConfig = GpgConfig(), normals: np.ndarray | None = None, *,
                        hand: HandSpec | None = None) -> np.ndarray:
    """(K, 4, 4) GPG candidates X_WG for `hand` (default the Franka hand) on an object cloud (M, 3),
    K <= num_samples * orientations.

    `normals`: the cloud's, when the caller has them (`config_normals`)."""
    hand = hand or default_hand()
    points_W = check_cloud(points_W)  # ValueError for an empty or non-finite cloud
    normals = config_normals(points_W, config) if normals is None else normals
    tree = o3d.geometry.KDTreeFlann(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points_W)))
    hand_reach = np.linalg.norm([hand.finger_length + hand.palm_depth + config.max_depth,
                                 hand.palm_size[1] / 2 + hand.max_half_opening, hand.palm_size[0] / 2])
    samples = rng.choice(len(points_W), size=min(config.num_samples, len(points_W)), replace=False)
    angles = np.linspace(-np.pi / 2, np.pi / 2, config.orientations)
    out = []
    for i in samples:
        p = points_W[i]
        _, near, _ = tree.search_radius_vector_3d(p, config.frame_radius)
        frame = local_frame(normals[np.asarray(near)], normals[i])
        if frame is None:
            continue
        _, around, _ = tree.search_radius_vector_3d(p, hand_reach)
        rel = points_W[np.asarray(around)] - p
        for approach, closing, axis in hand_orientations(frame, angles, config.max_gamma_deg):
            X_WG = search_hand(p, approach, closing, axis, rel, config, hand)
            if X_WG is not None:
                out.append(X_WG)
    return np.array(out).reshape(-1, 4, 4)


def gpg_candidates(points_W: np.ndarray, count: int, gamma_deg: tuple[float, float], rng: np.random.Generator,
                   config: GpgConfig = GpgConfig(), normals: np.ndarray | None = None, *,
                   hand: HandSpec | None = None) -> np.ndarray:
    """At most `count` GPG candidates for `hand` (default the Franka hand) within the approach cone (gamma
    up to gamma_deg[1]), in random order; frames at count / 4 sampled points, at least 8 (each gives up
    to `orientations` candidates)."""
    config = replace(config, num_samples=max(8, count // 4), max_gamma_deg=float(gamma_deg[1]))
    X_WG = generate_candidates(points_W, rng, config, normals, hand=hand)
    return X_WG[rng.permutation(len(X_WG))[:count]]
