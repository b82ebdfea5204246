"""Statistics of a metric over seeds: mean, sample standard deviation, a seeded percentile-bootstrap 95%
confidence interval of the mean, and the interquartile mean (IQM). Used by ``mope report``, the benchmark and
the reproductions."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass
class MetricStats:
    """Aggregate of one metric over the seeds of a group."""

    n: int
    mean: float
    std: float
    ci_low: float
    ci_high: float
    iqm: float
    values: list[float]



def bootstrap_ci(values: Sequence[float], n_boot: int = 10_000, seed: int = 0,
                 level: float = 0.95) -> tuple[float, float]:
    """Percentile bootstrap confidence interval of the mean (NumPy generator seeded with ``seed``).

    Resamples ``n`` values with replacement ``n_boot`` times and returns the ``(1 - level) / 2`` and
    ``(1 + level) / 2`` percentiles of the resampled means. One value gives a zero-width interval.
    """
    x = np.asarray(values, dtype=np.float64)
    if x.size == 0:
        return math.nan, math.nan
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, x.size, size=(n_boot, x.size))].mean(axis=1)
    lo, hi = np.percentile(means, [50 * (1 - level), 50 * (1 + level)])
    return float(lo), float(hi)


def iqm(values: Sequence[float]) -> float:
    """Interquartile mean: the mean after dropping the lowest and highest 25% (``scipy.stats.trim_mean``)."""
    from scipy.stats import trim_mean

    x = np.asarray(values, dtype=np.float64)
    return float(trim_mean(x, 0.25)) if x.size else math.nan


def aggregate(values: Sequence[float], n_boot: int = 10_000, seed: int = 0) -> MetricStats:
    """Mean, sample std (ddof 1; 0 for one value), bootstrap 95% CI and IQM of the finite values."""
    x = np.asarray([v for v in values if math.isfinite(v)], dtype=np.float64)
    if x.size == 0:
        return MetricStats(0, math.nan, math.nan, math.nan, math.nan, math.nan, [])
    lo, hi = bootstrap_ci(x, n_boot, seed)
    std = float(x.std(ddof=1)) if x.size > 1 else 0.0
    return MetricStats(int(x.size), float(x.mean()), std, lo, hi, iqm(x), [float(v) for v in x])


__all__ = ["MetricStats", "aggregate", "bootstrap_ci", "iqm"]
