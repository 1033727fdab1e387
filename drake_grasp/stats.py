"""Rates over runs: the mean and its 95 % confidence interval (Student's t), as the results report them."""

from __future__ import annotations

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
