"""The field's statistics over seeds, as rliable defines them (Agarwal et al. 2021), computed with SciPy.

>>> iqm([1, 2, 3, 4, 5, 6, 7, 100])
4.5
>>> probability_of_improvement([1.0, 0.5], [0.5, 0.2])[0]
0.875
>>> performance_profile([[0.5, 1.0], [1.0, 1.0]], [0.0, 0.9, 1.0])[0].tolist()
[1.0, 0.75, 0.0]

Values that are None or not finite (a run that never reached a threshold) are left out; the
intervals are percentile bootstraps, seeded so that a page regenerates identically.
"""

from __future__ import annotations

import numpy as np

RESAMPLES = 10_000
"""Bootstrap resamples of each interval."""


def _finite(values) -> np.ndarray:
    return np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=float)


def iqm(values) -> float:
    """The interquartile mean: the mean of the middle half, a quarter of the values (rounded down)
    trimmed at each end (``scipy.stats.trim_mean``); NaN for no values."""
    from scipy.stats import trim_mean

    values = _finite(values)
    return float(trim_mean(values, 0.25)) if values.size else float("nan")


def bootstrap_interval(values, statistic: str = "mean", confidence: float = 0.95) -> tuple[float, float]:
    """A percentile-bootstrap interval of the ``"mean"`` or the ``"iqm"`` of ``values``
    (``scipy.stats.bootstrap``): (NaN, NaN) for no values, the statistic itself for one value or
    equal ones."""
    from scipy.stats import bootstrap, trim_mean

    functions = {"mean": np.mean, "iqm": lambda v, axis=-1: trim_mean(v, 0.25, axis=axis)}
    if statistic not in functions:
        raise ValueError(f"statistic must be one of {sorted(functions)}, got {statistic!r}")
    function, values = functions[statistic], _finite(values)
    if values.size == 0:
        return float("nan"), float("nan")
    if values.size == 1 or np.ptp(values) == 0:
        value = float(function(values, axis=-1))
        return value, value
    result = bootstrap((values,), function, n_resamples=RESAMPLES, confidence_level=confidence,
                       method="percentile", rng=np.random.default_rng(0))  # fmt: skip
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def probability_of_improvement(x, y, confidence: float = 0.95) -> tuple[float, tuple[float, float]]:
    """P(X > Y) of a run of X against a run of Y, ties counting half (rliable's probability of
    improvement on one task: the Mann-Whitney U statistic over the pairs, as
    ``scipy.stats.mannwhitneyu(x, y).statistic / (len(x) * len(y))``), with a percentile-bootstrap
    interval (``scipy.stats.bootstrap``, resampling each side's runs)."""
    from scipy.stats import bootstrap

    x, y = _finite(x), _finite(y)
    if x.size == 0 or y.size == 0:
        raise ValueError("a probability of improvement needs at least one run of each method")
    value = float(_pairs_won(x, y))
    if x.size < 2 or y.size < 2 or np.ptp(np.concatenate([x, y])) == 0:
        return value, (value, value)
    result = bootstrap((x, y), _pairs_won, n_resamples=RESAMPLES, confidence_level=confidence, paired=False,
                       method="percentile", rng=np.random.default_rng(0))  # fmt: skip
    return value, (float(result.confidence_interval.low), float(result.confidence_interval.high))


def _pairs_won(a: np.ndarray, b: np.ndarray, axis: int = -1) -> np.ndarray:
    """The share of the pairs (one of ``a``, one of ``b``) that ``a`` wins, ties half, along ``axis``
    (the bootstrap's resamples stacked on the others)."""
    a, b = np.moveaxis(a, axis, -1)[..., :, None], np.moveaxis(b, axis, -1)[..., None, :]
    return (a > b).mean(axis=(-2, -1)) + 0.5 * (a == b).mean(axis=(-2, -1))


def performance_profile(
    scores_by_task, thresholds, confidence: float = 0.95
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """rliable's performance profile: at each threshold tau, the share of runs scoring above tau
    (``score > tau``), each task weighing the same (its runs' share, averaged over the tasks), with a
    stratified percentile-bootstrap interval (``scipy.stats.bootstrap``: each task's runs resampled
    apart, one sample per task).

    Args:
        scores_by_task: per task, its runs' scores (one list of one task: that task's profile).
        thresholds: the taus.
        confidence: the interval's level.

    Returns:
        (shares, low, high), each an array over ``thresholds``. A task of one run is certain under
        resampling (its one run is drawn every time): its share enters every resample as it is, and
        where every task has one run the interval collapses to the value.
    """
    from scipy.stats import bootstrap

    taus = np.asarray(thresholds, dtype=float)
    samples = [_finite(scores) for scores in scores_by_task]
    if not samples or any(s.size == 0 for s in samples):
        raise ValueError("a performance profile needs at least one run of each task")

    def above(runs: np.ndarray, axis: int = -1) -> np.ndarray:
        """A task's runs (..., n) -> the share above each tau, (taus, ...)."""
        runs = np.moveaxis(runs, axis, -1)
        return (runs[None] > taus.reshape(-1, *[1] * runs.ndim)).mean(-1)

    certain = sum((above(s) for s in samples if s.size < 2), np.zeros(len(taus)))
    resampled = [s for s in samples if s.size >= 2]
    if not resampled:
        value = certain / len(samples)
        return value, value.copy(), value.copy()

    def shares(*runs, axis=-1):
        total = sum(above(r, axis) for r in runs)  # (taus, resamples...)
        return (total + certain.reshape(-1, *[1] * (total.ndim - 1))) / len(samples)

    value = shares(*resampled)
    result = bootstrap(resampled, shares, n_resamples=RESAMPLES, confidence_level=confidence, paired=False,
                       method="percentile", rng=np.random.default_rng(0))  # fmt: skip
    return value, result.confidence_interval.low, result.confidence_interval.high
