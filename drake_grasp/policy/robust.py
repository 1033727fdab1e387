"""Robust p_s: a grasp scored by the CNN at itself and at small errors of its pose.

The argmax of a noisy score over 500 candidates is often where the CNN overrates a grasp: one
whose neighbours (5 mm along the pads or the closing direction, 5 mm shallower, 10 degrees
turned about the approach) it rates far lower sits on a knife's edge of the object's shape, a
fingertip just reaching the widest line, a pad at the rim. The robust p_s of a grasp is the mean
p_s over itself and those neighbours (as robust grasp quality under pose uncertainty, Dex-Net's
sense), and the policy ranks its few best candidates by it (`SelectionConfig.robust_top`). Pure
functions; the policy's scorer calls them (`drake_grasp.policy.scorers`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PoseErrors:
    """The neighbours a grasp is also scored at, in its own frame G."""

    shift: float = 0.005  # [m] along x_G (pad width) and y_G (closing), both ways; and back along z_G
    turn_deg: float = 10.0  # about the approach axis z_G, both ways

    def transforms_G(self) -> np.ndarray:
        """(K, 4, 4) X_GG' of the K neighbours."""
        shifts = [s * axis for axis in np.eye(3)[:2] for s in (-self.shift, self.shift)]
        shifts.append([0.0, 0.0, -self.shift])
        moves = np.tile(np.eye(4), (len(shifts) + 2, 1, 1))
        moves[: len(shifts), :3, 3] = shifts
        for k, sign in enumerate((-1.0, 1.0), start=len(shifts)):
            a = np.radians(sign * self.turn_deg)
            moves[k, :2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
        return moves


def neighbour_poses(X_WG: np.ndarray, errors: PoseErrors = PoseErrors()) -> np.ndarray:
    """(N, K, 4, 4) each of N grasps X_WG (N, 4, 4) moved by each of `errors`' K transforms."""
    return np.einsum("nij,kjl->nkil", np.asarray(X_WG, dtype=np.float64).reshape(-1, 4, 4),
                     errors.transforms_G())


def robust_stability(p_s: np.ndarray, p_s_neighbours: np.ndarray) -> np.ndarray:
    """(N,) the mean of each grasp's p_s (N,) and its neighbours' (N, K)."""
    p_s = np.asarray(p_s, dtype=np.float64)
    return (p_s + np.asarray(p_s_neighbours, dtype=np.float64).sum(axis=1)) / (1 + p_s_neighbours.shape[1])
