"""Timing joint-space paths within the joints' speed and acceleration limits.

`time_path`: a few far-apart waypoints (a transit), each segment the fastest rest-to-rest motion along
its straight joint-space line (a trapezoid of speed, or a triangle when the segment is short).
`time_line`: many close waypoints (a straight TCP line), one smooth rest-to-rest motion
through all of them.
"""

from __future__ import annotations

import numpy as np
from pydrake.trajectories import PiecewisePolynomial


def time_path(waypoints: list[np.ndarray], v_max: np.ndarray, a_max: np.ndarray, min_segment_s: float = 0.2,
              ) -> PiecewisePolynomial:
    """Straight joint-space segments at rest at each waypoint, each as fast as `v_max` and `a_max` allow.

    Along a segment q = q_a + s (q_b - q_a), the path parameter s accelerates at the largest rate every
    joint allows, cruises at the largest common speed and decelerates (a triangle if it never reaches
    that speed); a segment shorter than `min_segment_s` is slowed to it. The pieces are quadratic in
    time, so the Hermite cubics through their ends reproduce them exactly.
    """
    v_max, a_max = np.asarray(v_max, dtype=float), np.asarray(a_max, dtype=float)
    times, samples, rates = [0.0], [np.asarray(waypoints[0], dtype=float)], [np.zeros_like(v_max)]
    for q_a, q_b in zip(waypoints, waypoints[1:], strict=False):
        dq = np.asarray(q_b, dtype=float) - np.asarray(q_a, dtype=float)
        for dt, s, s_dot in _fastest_rest_to_rest(dq, v_max, a_max, min_segment_s):
            times.append(times[-1] + dt)
            samples.append(q_a + s * dq)
            rates.append(s_dot * dq)
    return PiecewisePolynomial.CubicHermite(times, np.column_stack(samples), np.column_stack(rates))


def _fastest_rest_to_rest(dq: np.ndarray, v_max: np.ndarray, a_max: np.ndarray, min_duration_s: float,
                          ) -> list[tuple[float, float, float]]:
    """The knots (time since the previous knot, s, ds/dt) of s: 0 -> 1 along dq after its start."""
    moving = np.abs(dq) > 1e-12
    if not moving.any():
        return [(min_duration_s, 1.0, 0.0)]
    v = float(np.min(v_max[moving] / np.abs(dq[moving])))  # the fastest ds/dt every joint allows
    a = float(np.min(a_max[moving] / np.abs(dq[moving])))
    duration = 1.0 / v + v / a if v * v / a < 1.0 else 2.0 / np.sqrt(a)
    if duration < min_duration_s:  # the same acceleration, a lower cruise: v^2 - a T v + a = 0
        duration = min_duration_s
        v = 0.5 * (a * duration - np.sqrt(a * a * duration * duration - 4.0 * a))
    v = min(v, np.sqrt(a))  # a triangle peaks at sqrt(a)
    t_ramp = v / a
    s_ramp = 0.5 * a * t_ramp * t_ramp
    cruise = duration - 2.0 * t_ramp
    if cruise <= 1e-9:
        return [(0.5 * duration, 0.5, v), (0.5 * duration, 1.0, 0.0)]
    return [(t_ramp, s_ramp, v), (cruise, 1.0 - s_ramp, v), (t_ramp, 1.0, 0.0)]


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
