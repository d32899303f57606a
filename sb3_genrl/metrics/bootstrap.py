"""Percentile bootstrap intervals of Pearson's R and Spearman's rho over models.

The models are resampled with replacement: resample ``b`` takes the models
``np.random.default_rng(seed).integers(0, n, size=(resamples, n))[b]``, and the interval is the 2.5th and 97.5th
percentile of the coefficient over the resamples in which it is defined (a resample whose values are all equal has
none; the number of defined ones is reported). Our own rather than ``scipy.stats.bootstrap``: one draw of resamples
serves both coefficients, and a resample with a constant column is dropped instead of failing the whole interval.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

DEFAULT_RESAMPLES = 2000
BOOTSTRAP_SEED = 0
CONFIDENCE = 0.95


@dataclasses.dataclass(frozen=True)
class Interval:
    """A percentile bootstrap interval.

    :param low: lower end (``nan`` when no resample defines the coefficient)
    :param high: upper end
    :param defined: resamples in which the coefficient is defined
    :param resamples: resamples drawn
    """

    low: float
    high: float
    defined: int
    resamples: int


def rowwise_pearson(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Pearson's R of each row pair of ``x`` and ``y`` (``(B, n)`` each), ``nan`` where a row is constant."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    xc = x - x.mean(axis=1, keepdims=True)
    yc = y - y.mean(axis=1, keepdims=True)
    defined = (np.ptp(x, axis=1) > 0) & (np.ptp(y, axis=1) > 0)
    denominator = np.sqrt((xc * xc).sum(axis=1) * (yc * yc).sum(axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (xc * yc).sum(axis=1) / denominator
    return np.where(defined, np.clip(r, -1.0, 1.0), np.nan)


def spearman(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Spearman's rho and its two-sided p-value (``nan`` for fewer than 3 values or a constant one)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if len(x) < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return math.nan, math.nan
    from scipy.stats import spearmanr  # scipy.stats costs about 0.5 s; every `genrl` command reaches this module

    result = spearmanr(x, y)
    return float(result.statistic), float(result.pvalue)


def _interval(values: np.ndarray, resamples: int) -> Interval:
    defined = values[np.isfinite(values)]
    if not len(defined):
        return Interval(math.nan, math.nan, 0, resamples)
    tail = 100 * (1 - CONFIDENCE) / 2
    low, high = np.percentile(defined, [tail, 100 - tail])
    return Interval(float(low), float(high), len(defined), resamples)


def bootstrap_correlations(
    x: np.ndarray, y: np.ndarray, *, resamples: int = DEFAULT_RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> tuple[Interval, Interval]:
    """95% percentile bootstrap intervals of Pearson's R and of Spearman's rho between paired values.

    :param x: one value per model
    :param y: the paired value per model
    :param resamples: bootstrap resamples
    :param seed: seed of the resamples (see the module's description)
    :return: the Pearson interval and the Spearman interval (``nan`` ends for fewer than 3 models)
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"x and y must be 1-D of the same length, got shapes {x.shape} and {y.shape}")
    if resamples < 1:
        raise ValueError(f"resamples must be at least 1, got {resamples}")
    if len(x) < 3:
        nothing = Interval(math.nan, math.nan, 0, resamples)
        return nothing, nothing
    from scipy.stats import rankdata  # scipy.stats costs about 0.5 s; every `genrl` command reaches this module

    index = np.random.default_rng(seed).integers(0, len(x), size=(resamples, len(x)))
    xs, ys = x[index], y[index]
    pearson = rowwise_pearson(xs, ys)
    ranked = rowwise_pearson(rankdata(xs, axis=1), rankdata(ys, axis=1))
    return _interval(pearson, resamples), _interval(ranked, resamples)
