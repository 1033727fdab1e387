"""Timing a joint-space path: cubic segments from rest to rest, within the joints' speed limits."""

from __future__ import annotations

import numpy as np
from pydrake.trajectories import PiecewisePolynomial


def time_path(waypoints: list[np.ndarray], v_max: np.ndarray, min_segment_s: float = 0.2,
              ) -> PiecewisePolynomial:
    """Cubic segments with zero velocity at each waypoint, each joint within its `v_max`.

    A cubic from rest to rest over T has peak speed 1.5 |dq| / T.
    """
    v_max = np.asarray(v_max, dtype=float)
    times = [0.0]
    for a, b in zip(waypoints, waypoints[1:], strict=False):
        times.append(times[-1] + max(min_segment_s, float(np.max(1.5 * np.abs(b - a) / v_max))))
    samples = np.column_stack(waypoints)
    return PiecewisePolynomial.CubicHermite(times, samples, np.zeros_like(samples))
