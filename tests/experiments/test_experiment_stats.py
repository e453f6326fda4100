"""The statistics behind experiment claims, against scipy's own Welch test and direct counts."""

from __future__ import annotations

import numpy as np
from scipy import stats

from adpart.experiments.stats import compare, episodes_to_threshold


def test_welch_interval_agrees_with_scipy_ttest():
    rng = np.random.default_rng(0)
    a = rng.normal(10.0, 2.0, 25)
    b = rng.normal(12.0, 3.0, 30)
    c = compare(a, b, "a", "b", level=0.95)
    p = stats.ttest_ind(a, b, equal_var=False).pvalue
    # the 95% interval excludes 0 exactly when Welch's two-sided p-value is below 0.05
    assert (c.diff_ci[1] < 0 or c.diff_ci[0] > 0) == (p < 0.05)
    assert c.diff == a.mean() - b.mean()
    assert c.ratio_ci[0] <= c.ratio <= c.ratio_ci[1]
    assert "n=25/30" in c.sentence("steps")


def test_clear_difference_is_called_and_equal_samples_are_not():
    a = np.array([10.0, 11, 9, 10, 10])
    b = a + 100
    assert compare(a, b, "fast", "slow").a_smaller
    assert "no significant difference" in compare(a, a.copy(), "x", "y").sentence("t")


def test_episodes_to_threshold_requires_staying_below():
    gaps = np.full((3, 6), np.nan)
    evaluated = np.array([2, 4, 6])
    gaps[0, [1, 3, 5]] = [1.0, 0.0, 0.0]  # below from episode 4 on
    gaps[1, [1, 3, 5]] = [0.0, 1.0, 0.0]  # dips at 2, back up at 4: counts from 6
    gaps[2, [1, 3, 5]] = [1.0, 1.0, 1.0]  # never
    out = episodes_to_threshold(gaps, evaluated, 0.5)
    assert out.tolist() == [4.0, 6.0, np.inf]
