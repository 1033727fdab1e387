"""Grasp pose sampling (paper Sec. IV-B): candidates on the object cloud, or poses over a workspace.

Each pose X_WG gets (grasp-frame convention of `drake_grasp.robot.hand`):
- origin: a point of the object cloud drawn uniformly (`sample_grasps`), or a
  point uniform in a box (`sample_workspace_poses`, the reachability labels);
- approach axis +z_G: angle gamma from straight down (world -z) uniform in
  [gamma1, gamma2] (uniform in the angle, as the paper states it, not in solid
  angle, which would put half of all candidates beyond 60 degrees), azimuth uniform;
- wrist roll about +z_G uniform in [0, 2 pi): sets the closing direction +y_G.

`sample_candidates` chooses among the samplers (`SAMPLERS`): the paper's uniform one above, GPG's hand
placements that clear the observed cloud (`policy.baselines.gpg`), half of each, or VPG's top-down actions.

A grasp point low on an object puts the open fingertips, 2 cm past it, into the table:
`back_off_from_table` moves such a candidate back along its approach until the fingertips
clear the table (a thin object lying flat is then grasped by its sides, the fingertips just
above the table, where every candidate on its surface would hit the table).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from drake_grasp.robot.hand import HandSpec, default_hand
from drake_grasp.robot.task import SAMPLERS

if TYPE_CHECKING:
    from drake_grasp.policy.baselines.gpg import GpgConfig

TABLE_CLEARANCE = 0.003  # [m] the open fingertips' lowest corner above the table after backing off
MAX_BACK_OFF = 0.03  # [m] a candidate that needs more is left as it is (it hits the table)
MIN_BACK_OFF_RISE = 0.2  # backing off raises the fingertips by cos(gamma): not for gamma past ~78 deg


def fingertip_corners_G(hand: HandSpec | None = None) -> np.ndarray:
    """(8, 3) corners of the open fingers' tip faces in the grasp frame (default: the Franka hand's)."""
    hand = hand or default_hand()
    tip, half = hand.tip_beyond_grasp, hand.finger_size[0] / 2
    reach, pad = hand.max_half_opening, hand.finger_size[1]
    return np.array([[x, y, tip] for x in (-half, half) for y in (-reach - pad, -reach, reach, reach + pad)])


def back_off_from_table(X_WG: np.ndarray, table_z: float, clearance: float = TABLE_CLEARANCE,
                        max_back_off: float = MAX_BACK_OFF, *, hand: HandSpec | None = None) -> np.ndarray:
    """(N, 4, 4) the candidates, those whose open fingertips (`hand`'s, default the Franka hand's) reach
    below `table_z + clearance` moved back along their approach axis (-z_G) just far enough to clear it."""
    X_WG = np.array(X_WG, dtype=np.float64)
    lowest = X_WG[:, 2, 3] + (fingertip_corners_G(hand) @ X_WG[:, 2, :3].T).min(axis=0)  # (N,)
    rise = -X_WG[:, 2, 2]  # fingertip rise per metre of back-off: cos(gamma)
    deficit = table_z + clearance - lowest
    back = deficit / np.maximum(rise, MIN_BACK_OFF_RISE)
    move = (deficit > 0) & (rise >= MIN_BACK_OFF_RISE) & (back <= max_back_off)
    X_WG[move, :3, 3] -= back[move, None] * X_WG[move, :3, 2]
    return X_WG


def approach_rotations(approach: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations R_WG whose z column is `approach` and rolled by `roll` about it."""
    z = approach / np.linalg.norm(approach, axis=1, keepdims=True)
    # Any unit vector orthogonal to z, then rotate it by the roll angle about z.
    helper = np.where(np.abs(z[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    x0 = np.cross(helper, z)
    x0 /= np.linalg.norm(x0, axis=1, keepdims=True)
    y0 = np.cross(z, x0)
    c, s = np.cos(roll)[:, None], np.sin(roll)[:, None]
    x = c * x0 + s * y0
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=2)


def approach_directions(gamma: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    """(N, 3) unit approach directions at angle gamma from straight down, turned by azimuth about z."""
    return np.stack([np.sin(gamma) * np.cos(azimuth), np.sin(gamma) * np.sin(azimuth), -np.cos(gamma)],
                    axis=1)


def grasp_poses(origins: np.ndarray, approach: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(N, 4, 4) poses X_WG from grasp points, approach directions and wrist rolls."""
    X = np.tile(np.eye(4), (len(origins), 1, 1))
    X[:, :3, :3] = approach_rotations(approach, roll)
    X[:, :3, 3] = origins
    return X


def _random_approaches(n: int, gamma_deg: tuple[float, float], rng: np.random.Generator) -> np.ndarray:
    g1, g2 = np.radians(gamma_deg)
    if not 0 <= g1 <= g2 <= np.pi / 2 + 1e-9:
        raise ValueError(f"need 0 <= gamma1 <= gamma2 <= 90 degrees, got {gamma_deg}")
    gamma = rng.uniform(g1, g2, size=n)
    return approach_directions(gamma, rng.uniform(0, 2 * np.pi, size=n))


def sample_grasps(points: np.ndarray, n: int, gamma_deg: tuple[float, float],
                  rng: np.random.Generator, table_z: float | None = None, *,
                  hand: HandSpec | None = None) -> np.ndarray:
    """(n, 4, 4) grasp poses X_WG sampled over `points` (M, 3); with the table's height `table_z`,
    `hand` backed off from it (`back_off_from_table`; the random draws are the same either way)."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) == 0:
        raise ValueError("cannot sample grasps on an empty object cloud")
    origins = points[rng.integers(len(points), size=n)]
    approach = _random_approaches(n, gamma_deg, rng)
    X_WG = grasp_poses(origins, approach, rng.uniform(0, 2 * np.pi, size=n))
    return X_WG if table_z is None else back_off_from_table(X_WG, table_z, hand=hand)


def sample_candidates(points_W: np.ndarray, count: int, gamma_deg: tuple[float, float], sampler: str,
                      rng: np.random.Generator, table_z: float | None = None, gpg: GpgConfig | None = None,
                      *, hand: HandSpec | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(<= count, 4, 4) candidates for `hand` (default the Franka hand) on an object cloud from `sampler`,
    and which sampler made each (its index in `SAMPLERS`: `mixed` gives up to count / 2 GPG candidates,
    the rest uniform). The uniform ones are backed off from the table at `table_z`; GPG runs with `gpg`
    (default `GpgConfig()`: the normals toward the scenarios' first camera, the hand above z = 0)."""
    if sampler not in SAMPLERS:
        raise ValueError(f"unknown sampler '{sampler}'; choose one of: {', '.join(SAMPLERS)}")
    if sampler == "uniform":
        parts = [("uniform", sample_grasps(points_W, count, gamma_deg, rng, table_z, hand=hand))]
    elif sampler == "topdown":
        from drake_grasp.policy.baselines.vpg import sample_top_down

        parts = [("topdown", sample_top_down(points_W, count, rng))]
    else:
        from drake_grasp.policy.baselines.gpg import GpgConfig, gpg_candidates

        X_gpg = gpg_candidates(points_W, count if sampler == "gpg" else count // 2, gamma_deg, rng,
                               gpg or GpgConfig(), hand=hand)
        parts = [("gpg", X_gpg)]
        if sampler == "mixed":
            parts.append(("uniform", sample_grasps(points_W, count - len(X_gpg), gamma_deg, rng, table_z,
                                                   hand=hand)))
    candidates = np.concatenate([X.reshape(-1, 4, 4) for _, X in parts])
    made_by = np.concatenate([np.full(len(X), SAMPLERS.index(name), np.uint8) for name, X in parts])
    return candidates, made_by


def sample_workspace_poses(n: int, lower, upper, rng: np.random.Generator,
                           gamma_deg: tuple[float, float] = (0.0, 90.0)) -> np.ndarray:
    """(n, 4, 4) poses uniform over the box [lower, upper], approach and roll as for grasps."""
    origins = rng.uniform(lower, upper, (n, 3))
    approach = _random_approaches(n, gamma_deg, rng)
    return grasp_poses(origins, approach, rng.uniform(0, 2 * np.pi, size=n))


def approach_angle_deg(X_WG: np.ndarray) -> np.ndarray:
    """Angle between each grasp's approach axis and straight down, in degrees."""
    return np.degrees(np.arccos(np.clip(-X_WG[..., 2, 2], -1.0, 1.0)))
