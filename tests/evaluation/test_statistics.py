"""The statistics of reports and the leaderboard: rliable's definitions, computed with SciPy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import mannwhitneyu

from tactile_braille.evaluation.statistics import (
    bootstrap_interval,
    iqm,
    performance_profile,
    probability_of_improvement,
)


def test_the_bootstrap_interval_brackets_the_mean_and_shrinks_with_more_data():
    rng = np.random.default_rng(0)
    small, large = rng.normal(1.0, 1.0, 10), rng.normal(1.0, 1.0, 1000)
    low, high = bootstrap_interval(small)
    assert low < small.mean() < high
    low_large, high_large = bootstrap_interval(large)
    assert high_large - low_large < (high - low) / 5  # width ~ 1/sqrt(n)
    assert low_large < 1.0 < high_large
    assert bootstrap_interval([2.0, 2.0, 2.0]) == (2.0, 2.0)
    assert all(np.isnan(bootstrap_interval([])))
    assert bootstrap_interval([1.0, None, 3.0]) != (np.nan, np.nan)  # None (not reached) is skipped
    assert bootstrap_interval(small) == bootstrap_interval(small)  # seeded: pages regenerate alike
    with pytest.raises(ValueError, match="statistic must be one of"):
        bootstrap_interval(small, "median")


def test_iqm_trims_a_quarter_at_each_end_and_has_an_interval():
    assert iqm([1, 2, 3, 4, 5, 6, 7, 100]) == pytest.approx(np.mean([3, 4, 5, 6]))
    assert iqm([1.0, 2.0, 3.0]) == 2.0  # fewer than 4 values: nothing to trim
    assert np.isnan(iqm([]))
    values = [0.2, 0.4, 0.5, 0.9, 1.0]
    low, high = bootstrap_interval(values, "iqm")
    assert 0.2 <= low < iqm(values) < high <= 1.0


def test_the_probability_of_improvement_counts_pairs_and_ties_half():
    # Of the 4 pairs, 3 wins and 1 tie: (1 > .5), (1 > .2), (.5 = .5), (.5 > .2).
    value, (low, high) = probability_of_improvement([1.0, 0.5], [0.5, 0.2])
    assert value == pytest.approx((1 + 1 + 0.5 + 1) / 4) and 0.0 <= low <= value <= high <= 1.0
    assert probability_of_improvement([1.0] * 3, [1.0] * 3) == (0.5, (0.5, 0.5))
    assert probability_of_improvement([0.0], [1.0])[0] == 0.0
    with pytest.raises(ValueError, match="at least one run of each"):
        probability_of_improvement([], [1.0])
    # The Mann-Whitney U statistic over the pairs, as SciPy computes it.
    rng = np.random.default_rng(3)
    x, y = rng.integers(0, 4, 7).astype(float), rng.integers(0, 4, 5).astype(float)
    assert probability_of_improvement(x, y)[0] == pytest.approx(mannwhitneyu(x, y).statistic / 35)


def test_the_performance_profile_is_the_share_above_each_threshold_each_task_weighing_the_same():
    # Task 1: 1 of 4 runs above 0.9; task 2: 2 of 2. The profile at 0.9 is (1/4 + 2/2) / 2, not 3/6.
    tasks = [[0.5, 0.7, 0.9, 1.0], [0.95, 1.0]]
    share, low, high = performance_profile(tasks, [0.0, 0.9, 0.99, 1.0])
    assert share.tolist() == pytest.approx([1.0, (1 / 4 + 1) / 2, (1 / 4 + 1 / 2) / 2, 0.0])
    assert np.all(low <= share) and np.all(share <= high) and np.all((low >= 0) & (high <= 1))
    assert low[1] < share[1] < high[1]  # task 1's runs are uncertain about 0.9
    assert (low[0], high[0], low[3], high[3]) == (1.0, 1.0, 0.0, 0.0)  # every run above 0, none above 1
    # Stratified: no resampling moves runs between tasks, so task 2's certain share keeps the bound.
    assert low[1] >= 0.5
    # Non-increasing in the threshold, strict '>' at a run's own score.
    grid = np.linspace(0, 1, 101)
    assert np.all(np.diff(performance_profile(tasks, grid)[0]) <= 0)
    assert performance_profile([[0.9]], [0.9])[0].tolist() == [0.0]
    one = performance_profile([[0.9], [0.2]], [0.5])
    assert [v.tolist() for v in one] == [[0.5], [0.5], [0.5]]  # one run a task: nothing to resample
    # A task of one run beside tasks of more: its share is certain in every resample, the others vary.
    mixed, low_mixed, high_mixed = performance_profile([[0.9], [0.2, 0.8]], [0.5])
    assert mixed.tolist() == [(1 + 0.5) / 2] and low_mixed[0] == 0.5 and high_mixed[0] == 1.0
    assert np.array_equal(performance_profile(tasks, grid)[1], performance_profile(tasks, grid)[1])
    with pytest.raises(ValueError, match="at least one run of each task"):
        performance_profile([[1.0], []], [0.5])
