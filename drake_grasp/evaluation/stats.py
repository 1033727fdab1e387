"""Rates over runs: the mean and its 95 % confidence interval (Student's t), as the results report them;
rates over trials: the Wilson interval, and the sign test of paired outcomes."""

from __future__ import annotations

import math

import numpy as np

# Two-sided 95 % quantiles of Student's t for 1-30 degrees of freedom; 1.96 beyond.
_T_975 = [12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
          2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
          2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042]


def mean_ci95(values) -> tuple[float, float]:
    """(mean, half width of its 95 % confidence interval); the half width is NaN for one value."""
    x = np.asarray(values, dtype=float)
    if len(x) == 0:
        return float("nan"), float("nan")
    if len(x) == 1:
        return float(x[0]), float("nan")
    df = len(x) - 1
    t = _T_975[df - 1] if df <= len(_T_975) else 1.96
    return float(x.mean()), float(t * x.std(ddof=1) / np.sqrt(len(x)))


def wilson_ci95(successes: int, n: int) -> tuple[float, float]:
    """The Wilson score interval (95 %) of a success rate."""
    if n == 0:
        return float("nan"), float("nan")
    z, p = 1.959964, successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def sign_test_p(wins: int, losses: int) -> float:
    """Two-sided exact sign test (McNemar's exact test) of discordant pairs: wins against losses."""
    n = wins + losses
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, i) for i in range(min(wins, losses) + 1)) / 2**n
    return min(1.0, 2 * tail)
