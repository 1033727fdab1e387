"""Timing joint-space paths within the joints' speed limits.

`time_path`: a few far-apart waypoints (a transit), cubic segments from rest to rest.
`time_line`: many close waypoints (a straight TCP line), one smooth rest-to-rest motion
through all of them.
"""

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


def time_line(waypoints: list[np.ndarray], v_max: np.ndarray, min_duration_s: float) -> PiecewisePolynomial:
    """One motion through closely spaced waypoints, at rest at both ends.

    The waypoints' index s (equal TCP spacing along a line) follows the smooth
    ease s(t) = 3 (t/T)^2 - 2 (t/T)^3, whose peak rate 1.5 / T bounds each joint's
    speed by 1.5 max_k |dq_k| n / T for n steps.
    """
    samples = np.column_stack(waypoints)
    n = samples.shape[1] - 1
    if n < 1:
        return PiecewisePolynomial(samples[:, :1])
    steepest = np.max(np.abs(np.diff(samples, axis=1)), axis=1) * n  # |dq/ds| per joint
    duration = max(min_duration_s, float(np.max(1.5 * steepest / np.asarray(v_max, dtype=float))))
    tau = np.linspace(0.0, 1.0, 2001)
    times = duration * np.interp(np.linspace(0.0, 1.0, n + 1), 3 * tau**2 - 2 * tau**3, tau)
    zero = np.zeros((samples.shape[0], 1))
    return PiecewisePolynomial.CubicWithContinuousSecondDerivatives(times, samples, zero, zero)
