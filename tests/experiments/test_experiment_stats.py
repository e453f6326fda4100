"""The statistics behind experiment claims, against scipy's own Welch test and direct counts."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from adpart.experiments.stats import compare, episodes_to_threshold
from adpart.learning.settings import Run


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


def test_episodes_to_threshold_is_the_curves_episodes_to_gap():
    from adpart.learning.qlearning import q_learning
    from tests.learning.conftest import slippery_grid

    curve = q_learning(slippery_grid(4), Run(runs=6, episodes=30, seed=2, eval_every=3)).curve
    ev = curve.evaluated_episodes()
    for tol in (0.5, 2.0, 5.0):
        ours = episodes_to_threshold(curve.matrix("value_gap"), ev, tol)
        assert np.array_equal(np.where(np.isinf(ours), -1, ours), curve.episodes_to_gap(tol))


def test_bootstrap_ci_mean_and_median():
    from adpart.experiments.stats import bootstrap_ci

    rng = np.random.default_rng(4)
    x = rng.normal(5.0, 1.0, 200)
    m, lo, hi = bootstrap_ci(x, statistic="mean")
    half = 1.96 * x.std(ddof=1) / np.sqrt(x.size)  # normal-theory oracle
    assert m == x.mean() and abs((hi - lo) / 2 - half) < 0.2 * half
    med, lo, hi = bootstrap_ci(np.r_[1.0, 2.0, np.inf], statistic="median")
    assert med == 2.0 and lo <= med <= hi


def test_gap_auc_against_trapezoid_and_caps():
    from adpart.experiments.stats import gap_auc

    gaps = np.array([[4.0, 2.0, 1.0, 0.0], [np.nan, 50.0, -0.1, 0.0]])
    x = np.array([10.0, 20.0, 40.0, 80.0])
    out = gap_auc(gaps, x, cap=8.0)
    assert out[0] == pytest.approx(np.trapezoid(gaps[0], x) / 70.0)
    assert out[1] == pytest.approx(np.trapezoid([8.0, 8.0, 0.0, 0.0], x) / 70.0)


def test_gap_auc_steps_against_a_step_function_loop():
    from adpart.experiments.stats import gap_auc_steps

    gaps = np.array([[5.0, 1.0, 0.0], [np.nan, 2.0, 1.0]])
    cum = np.array([[10.0, 30.0, 60.0], [20.0, 25.0, 90.0]])
    out = gap_auc_steps(gaps, cum, horizon=50.0, cap=6.0)
    for k in range(2):  # oracle: integrate the held gap one step at a time
        total = 0.0
        for t in range(50):
            seen = np.flatnonzero(cum[k] <= t)
            g = 6.0 if seen.size == 0 else gaps[k, seen[-1]]
            total += 6.0 if np.isnan(g) else min(g, 6.0)
        assert out[k] == pytest.approx(total / 50.0)


def test_gap_auc_steps_window_start():
    from adpart.experiments.stats import gap_auc_steps

    gaps = np.array([[5.0, 1.0, 0.0]])
    cum = np.array([[10.0, 30.0, 60.0]])
    # over steps 15-50: gap 5 on 15-30, 1 on 30-50
    assert gap_auc_steps(gaps, cum, 50.0, 6.0, start=15.0)[0] == pytest.approx(
        (5 * 15 + 1 * 20) / 35)
    with pytest.raises(ValueError, match="start"):
        gap_auc_steps(gaps, cum, 50.0, 6.0, start=50.0)
