"""Transfer metrics, censored times to the bound and rliable aggregates
(adpart.learning.transfer_metrics), each against an oracle that does not share its code: hand
computations, the product-limit estimator and Greenwood's band written out with fractions, the
textbook log-rank sums, explicit loops over runs, and rliable itself where it is installed."""

from __future__ import annotations

import re
from fractions import Fraction
from math import exp, log, sqrt
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from adpart.errors import TaskError
from adpart.learning.comparison import ratio_of_medians_ci
from adpart.learning.curves import LearningCurve
from adpart.learning.transfer_metrics import (
    _km_medians,
    iqm,
    jumpstart_gain,
    km_median,
    km_median_ratio,
    logrank_sooner,
    metrics_from_curve,
    metrics_from_gaps,
    performance_profile,
    probability_of_improvement,
)

DOC = Path(__file__).resolve().parents[2] / "docs" / "transfer-metrics.md"
FEW = settings(max_examples=60, deadline=None)

# ------------------------------------------------------------------------- per-run measures

GAPS = np.array([[4.0, 2.0, 0.0],    # within from the last evaluation on
                 [4.0, 4.0, 4.0],    # never: censored
                 [1.0, 0.0, 0.5]])   # within from the second on
EVALUATED = np.array([2, 4, 6])
CUM_STEPS = np.array([[10, 15, 18], [3, 6, 9], [5, 10, 15]])


def test_the_measures_of_a_small_case_by_hand():
    m = metrics_from_gaps(GAPS, EVALUATED, CUM_STEPS, 0.6)
    assert m.jumpstart.tolist() == [4.0, 4.0, 1.0]
    assert m.censored.tolist() == [False, True, False]
    assert m.reached.tolist() == [True, False, True]
    # the censored run is censored at the budget (episode 6, its 9 steps), not at 7
    assert m.time_episodes.tolist() == [6.0, 6.0, 4.0]
    assert m.time_steps.tolist() == [18.0, 9.0, 10.0]
    # run 0: 4 held on [0, 2], then (4+2)/2*2 + (2+0)/2*2 = 8 + 6 + 2
    assert m.auc_episodes.tolist() == [16.0, 24.0, 3.5]
    # run 0 in steps: 4*10 + 3*5 + 1*3; run 2: 1*5 + 0.5*5 + 0.25*5
    assert m.auc_steps.tolist() == [58.0, 36.0, 8.75]
    assert m.asymptotic_gap.tolist() == [2.0, 4.0, 0.5]
    assert metrics_from_gaps(GAPS, EVALUATED, CUM_STEPS, 0.6, last=2).asymptotic_gap.tolist() \
        == [1.0, 4.0, 0.25]
    assert m.event_times("steps")[0].tolist() == [18.0, 9.0, 10.0]
    # success_bound's inf (no V*): every run is within from its first evaluation
    assert metrics_from_gaps(GAPS, EVALUATED, CUM_STEPS, np.inf).time_episodes.tolist() == [2] * 3
    with pytest.raises(ValueError):
        m.jumpstart[0] = 0.0  # read-only
    with pytest.raises(TaskError):
        m.event_times("decisions")


def test_a_dip_out_of_the_bound_restarts_the_clock_and_nan_is_out():
    gaps = np.array([[0.0, 1.0, 0.0], [0.1, 0.2, 0.3], [np.nan, 0.0, 0.0],
                     [0.0, np.nan, 0.0]])
    m = metrics_from_gaps(gaps, EVALUATED, np.tile([1, 2, 3], (4, 1)), 0.5, cap=10.0)
    assert m.time_episodes.tolist() == [6.0, 2.0, 4.0, 6.0]
    assert not m.censored.any()
    # NaN scores the cap: 10 held on [0, 2], then (10+0)/2*2, then 0
    assert m.jumpstart[2] == 10.0 and m.auc_episodes[2] == 30.0


def test_gaps_are_scored_within_zero_and_the_cap():
    gaps = np.array([[-1e-15, 50.0, np.nan]])
    m = metrics_from_gaps(gaps, [1, 2, 3], [[1, 2, 3]], 1.0, cap=20.0)
    assert m.jumpstart.tolist() == [0.0]
    assert m.asymptotic_gap.tolist() == [(0.0 + 20.0 + 20.0) / 3]
    assert m.auc_episodes.tolist() == [0.0 + 10.0 + 20.0]
    inf = metrics_from_gaps(gaps, [1, 2, 3], [[1, 2, 3]], 1.0)  # default cap: inf
    assert inf.auc_episodes[0] == np.inf and inf.asymptotic_gap[0] == np.inf


def _inputs(**change):
    return {"gaps": np.zeros((2, 3)), "evaluated": [1, 2, 3], "cum_steps": np.zeros((2, 3)),
            "threshold": 1.0, **change}


@pytest.mark.parametrize("bad", [
    _inputs(evaluated=[2, 2, 3]),
    _inputs(cum_steps=[[3, 2, 1], [1, 2, 3]]),
    _inputs(cum_steps=np.zeros((2, 2))),
    _inputs(threshold=np.nan),
    _inputs(gaps=np.zeros(3), cum_steps=np.zeros(3)),
])
def test_malformed_inputs_are_task_errors(bad):
    with pytest.raises(TaskError):
        metrics_from_gaps(**bad)


def test_jumpstart_gain_is_the_baseline_s_first_gap_minus_the_method_s():
    method = metrics_from_gaps([[1.0, 0.0], [1.0, 0.0]], [5, 10], [[5, 9], [6, 9]], 0.1)
    baseline = metrics_from_gaps([[3.0, 0.0], [5.0, 0.0]], [5, 10], [[5, 9], [6, 9]], 0.1)
    est, lo, hi = jumpstart_gain(method, baseline)
    assert est == 3.0
    assert 2.0 <= lo <= est <= hi <= 4.0  # the method's runs are equal: boot = mean(b) - 1
    late = metrics_from_gaps([[1.0, 0.0]], [6, 10], [[5, 9]], 0.1)
    with pytest.raises(TaskError, match="same first evaluation"):
        jumpstart_gain(late, baseline)


def _loop_metrics(value_gap, steps, evaluated, threshold, last, cap):
    """The measures by explicit loops over runs and evaluations (no vectorised code)."""
    K = value_gap.shape[0]
    out = {k: [] for k in ("jump", "t_ep", "t_st", "cens", "auc_ep", "auc_st", "asym")}
    for k in range(K):
        cum, total = [], 0
        for e in range(value_gap.shape[1]):
            total += int(steps[k, e])
            cum.append(total)
        g = [float(value_gap[k, e - 1]) for e in evaluated]
        x = [float(e) for e in evaluated]
        s = [float(cum[e - 1]) for e in evaluated]
        scored = [min(max(cap if np.isnan(v) else v, 0.0), cap) for v in g]
        event = None
        for j in range(len(g)):
            if all(v <= threshold for v in g[j:]):  # NaN <= t is False
                event = j
                break
        j = len(g) - 1 if event is None else event
        out["jump"].append(scored[0])
        out["t_ep"].append(x[j])
        out["t_st"].append(s[j])
        out["cens"].append(event is None)
        for key, xs in (("auc_ep", x), ("auc_st", s)):
            area = scored[0] * xs[0]
            for i in range(1, len(xs)):
                area += (scored[i] + scored[i - 1]) / 2 * (xs[i] - xs[i - 1])
            out[key].append(area)
        tail = scored[-min(last, len(scored)):]
        out["asym"].append(sum(tail) / len(tail))
    return out


@FEW
@given(st.integers(1, 5), st.integers(1, 12), st.integers(1, 5), st.integers(1, 4),
       st.integers(0, 2**32 - 1))
def test_a_learning_curve_gives_the_measures_of_its_plain_arrays(K, N, every, last, seed):
    """LearningCurve.from_matrices against plain arrays read by explicit loops; the time in
    episodes is the curve's own episodes_to_gap where that is not -1."""
    rng = np.random.default_rng(seed)
    evaluated = np.unique(np.r_[np.arange(every, N + 1, every), N])
    gap = np.full((K, N), np.nan)
    gap[:, evaluated - 1] = rng.choice([0.0, 0.05, 0.2, 1.0, 3.0, np.nan], size=(K, evaluated.size),
                                       p=[0.3, 0.2, 0.2, 0.15, 0.1, 0.05])
    steps = rng.integers(1, 30, size=(K, N))
    curve = LearningCurve.from_matrices(
        steps=steps, decisions=steps, returns=np.zeros((K, N)),
        discounted_returns=np.zeros((K, N)),
        eval_value=np.where(np.isin(np.arange(1, N + 1), evaluated),
                            -5.0 - np.nan_to_num(gap, nan=1.0), np.nan),
        value_gap=gap)
    assert curve.evaluated_episodes().tolist() == evaluated.tolist()
    m = metrics_from_curve(curve, 0.1, last=last, cap=4.0)
    want = _loop_metrics(gap, steps, evaluated, 0.1, last, 4.0)
    assert m.jumpstart.tolist() == want["jump"]
    assert m.time_episodes.tolist() == want["t_ep"]
    assert m.time_steps.tolist() == want["t_st"]
    assert m.censored.tolist() == want["cens"]
    np.testing.assert_allclose(m.auc_episodes, want["auc_ep"], rtol=1e-12)
    np.testing.assert_allclose(m.auc_steps, want["auc_st"], rtol=1e-12)
    np.testing.assert_allclose(m.asymptotic_gap, want["asym"], rtol=1e-12)
    first = curve.episodes_to_gap(0.1)
    assert np.array_equal(first >= 0, ~m.censored)
    assert m.time_episodes[~m.censored].tolist() == first[first >= 0].tolist()


# ------------------------------------------------------------------------- Kaplan-Meier


def _product_limit(times, censored):
    """Exact S(t_j) at the distinct event times, from the definition: n_j = runs with time >=
    t_j (a censoring at t_j is still at risk), d_j = events at t_j."""
    steps, s = [], Fraction(1)
    for t in sorted({t for t, c in zip(times, censored, strict=True) if not c}):
        n = sum(1 for u in times if u >= t)
        d = sum(1 for u, c in zip(times, censored, strict=True) if u == t and not c)
        s *= Fraction(n - d, n)
        steps.append((t, s, n, d))
    return steps


def _brute_median(times, censored):
    return next((float(t) for t, s, _, _ in _product_limit(times, censored)
                 if s <= Fraction(1, 2)), np.inf)


def test_the_kaplan_meier_median_of_a_small_case_by_hand():
    # S = 5/6, 4/6, 3/6 at 3, 5, 7: the median is 7; the two runs censored at 10 never get there
    assert km_median([3, 5, 7, 9, 10, 10], [0, 0, 0, 0, 1, 1]).estimate == 7.0
    # censoring at 4 raises the later steps: S(5) = 3/4 * 2/3 = 1/2 (not 4/6)
    assert km_median([2, 4, 5, 8], [0, 1, 0, 0]).estimate == 5.0
    assert km_median([1, 2, 3, 4], [0, 0, 0, 0]).estimate == 2.0  # the lower median
    # 2 of 5 reach: S never gets down to 1/2
    assert km_median([1, 2, 9, 9, 9], [0, 0, 1, 1, 1]).estimate == np.inf
    assert tuple(km_median([9, 9], [1, 1])) == (np.inf, np.inf, np.inf)


def _greenwood_band(times, censored, level):
    """(t_j, lower, upper) of the log-log band, written from Greenwood's formula: v = sum d /
    (n (n - d)) / log(S)^2, S^exp(+-z sqrt v); undefined (S = 0) taken as S."""
    z = stats.norm.ppf(0.5 + level / 2)
    out, g = [], 0.0
    for t, s, n, d in _product_limit(times, censored):
        if s == 0:
            out.append((t, 0.0, 0.0))
            continue
        g += d / (n * (n - d))
        sd = sqrt(g) / abs(log(float(s)))
        out.append((t, float(s) ** exp(z * sd), float(s) ** exp(-z * sd)))
    return out


@pytest.mark.parametrize("times, censored", [
    ([1, 2, 3, 4, 5, 6], [0] * 6),
    (list(range(1, 11)) + [10] * 10, [0] * 10 + [1] * 10),
    ([2, 3, 3, 5, 7, 7, 8, 11, 12, 12], [0, 0, 1, 0, 0, 0, 1, 0, 0, 1]),
])
def test_the_median_s_interval_is_read_off_greenwood_s_log_log_band(times, censored):
    band = _greenwood_band(times, censored, 0.9)
    low = next((float(t) for t, lo, _ in band if lo <= 0.5), np.inf)
    high = next((float(t) for t, _, hi in band if hi <= 0.5), np.inf)
    est, lo, hi = km_median(times, censored, level=0.9)
    assert (est, lo, hi) == (_brute_median(times, censored), low, high)
    assert lo <= est <= hi


def test_the_linear_band_can_be_chosen():
    est, lo, hi = km_median(list(range(1, 21)), [0] * 20, method="linear")
    assert lo < est == 10.0 < hi


event_samples = st.integers(1, 25).flatmap(lambda n: st.tuples(
    st.lists(st.integers(1, 12), min_size=n, max_size=n),
    st.lists(st.booleans(), min_size=n, max_size=n)))


@FEW
@given(event_samples)
def test_the_km_median_is_the_brute_force_product_limit_median(sample):
    times, censored = sample
    want = _brute_median(times, censored)
    assert km_median(times, censored).estimate == want
    # the bootstrap's vectorised medians agree too (rows: the sample and a reversed copy)
    t = np.array([times, times[::-1]], dtype=np.float64)
    c = np.array([censored, censored[::-1]], dtype=bool)
    assert _km_medians(t, c).tolist() == [want, want]


@FEW
@given(st.lists(st.integers(1, 1000), min_size=1, max_size=40))
def test_without_censoring_the_km_median_is_the_inverted_cdf_sample_median(times):
    want = float(np.quantile(times, 0.5, method="inverted_cdf"))
    assert km_median(times, [False] * len(times)).estimate == want


@FEW
@given(event_samples, st.data())
def test_censoring_runs_at_the_budget_never_makes_the_median_smaller(sample, data):
    budget = 12
    times, reached = np.array(sample[0], dtype=float), np.array(sample[1])
    censored = ~reached
    times[censored] = budget  # a run that never gets there is censored at the budget
    more = np.array(data.draw(st.lists(st.booleans(), min_size=times.size,
                                       max_size=times.size)))
    before = km_median(times, censored).estimate
    after = km_median(np.where(more, budget, times), censored | more).estimate
    assert after >= before


# ------------------------------------------------------------------------- log-rank


def test_the_log_rank_statistic_of_a_tiny_case_by_hand():
    """A reaches at 1, 2, 3; B at 2 and 5, and one B run is censored at 4.
    t=1: N=6, N_A=3, O=1: E_A=1/2, V=1/2*5/6*3/5=1/4;  t=2: N=5, N_A=2, O=2: E_A=4/5,
    V=4/5*3/5*3/4=9/25;  t=3: N=3, N_A=1, O=1: E_A=1/3, V=1/3*2/3*1=2/9;  t=5: N=1, N_A=0: 0.
    O_A - E_A = 1/2 + 1/5 + 2/3 = 41/30, V = 749/900, so Z = 41/sqrt(749)."""
    z = 41 / sqrt(749)
    res = logrank_sooner([1, 2, 3], [0, 0, 0], [2, 4, 5], [0, 1, 0])
    assert res.statistic == pytest.approx(z, rel=1e-12)
    assert res.pvalue == pytest.approx(stats.norm.sf(z), rel=1e-12)
    two = logrank_sooner([1, 2, 3], [0, 0, 0], [2, 4, 5], [0, 1, 0], alternative="two-sided")
    assert two.pvalue == pytest.approx(stats.chi2.sf(z * z, 1), rel=1e-9)
    later = logrank_sooner([1, 2, 3], [0, 0, 0], [2, 4, 5], [0, 1, 0], alternative="later")
    assert later.pvalue == pytest.approx(stats.norm.cdf(z), rel=1e-12)


def _textbook_chi2(ta, ca, tb, cb):
    """(O_A - E_A)^2 / V summed over the distinct event times (Mantel 1966)."""
    pooled = list(zip(ta, ca, strict=True)) + list(zip(tb, cb, strict=True))
    o_e, v = 0.0, 0.0
    for t in sorted({t for t, c in pooled if not c}):
        n = sum(1 for u, _ in pooled if u >= t)
        n_a = sum(1 for u in ta if u >= t)
        o = sum(1 for u, c in pooled if u == t and not c)
        o_a = sum(1 for u, c in zip(ta, ca, strict=True) if u == t and not c)
        e_a = o * n_a / n
        o_e += o_a - e_a
        v += e_a * (1 - n_a / n) * (n - o) / (n - 1) if n > 1 else 0.0
    return o_e, v


@FEW
@given(event_samples, event_samples)
def test_log_rank_is_the_textbook_chi_square(a, b):
    (ta, ca), (tb, cb) = a, b
    o_e, v = _textbook_chi2(ta, ca, tb, cb)
    res = logrank_sooner(ta, ca, tb, cb, alternative="two-sided")
    if v == 0:  # then every O_Aj = E_Aj: no information (all censored, say)
        assert o_e == pytest.approx(0.0, abs=1e-12)
        assert res == (0.0, 1.0)
    else:
        assert res.statistic == pytest.approx(o_e / sqrt(v), rel=1e-9, abs=1e-12)
        assert res.pvalue == pytest.approx(stats.chi2.sf(o_e * o_e / v, 1), rel=1e-6,
                                           abs=1e-12)


# ------------------------------------------------------------------------- ratio of KM medians


def test_without_censoring_the_ratio_is_the_ratio_of_medians_ci():
    """The existing comparison (plain inverted-cdf medians) draws the same runs for a seed."""
    rng = np.random.default_rng(1)
    a, b = rng.integers(5, 40, size=9), rng.integers(10, 60, size=12)
    want = ratio_of_medians_ci(a, b, seed=3)
    got = km_median_ratio(a, np.zeros(9, bool), b, np.zeros(12, bool), seed=3)
    assert tuple(got) == pytest.approx(want, rel=1e-15)


def test_censored_runs_stay_censored_in_the_resamples():
    reach, never = ([3, 4, 5, 6], [0, 0, 0, 0]), ([50, 50, 50], [1, 1, 1])
    assert tuple(km_median_ratio(*reach, *never)) == (0.0, 0.0, 0.0)  # B never: 0
    assert tuple(km_median_ratio(*never, *reach)) == (np.inf, np.inf, np.inf)
    # the old rule (budget + 1) would give a finite ratio with a zero-width interval
    assert ratio_of_medians_ci([51, 51, 51], [3, 4, 5, 6])[0] < np.inf
    est, lo, hi = km_median_ratio([4, 6, 8, 10, 50, 50], [0, 0, 0, 0, 1, 1],
                                  [2, 3, 4, 5, 6, 7], [0] * 6, n_boot=500)
    assert est == 8 / 4 and lo <= est <= hi == np.inf  # some resamples have >= half censored


# ------------------------------------------------------------------------- over cells


def test_iqm_by_hand_and_over_cells():
    assert iqm([[1, 2, 3, 4, 5, 6, 7, 100]]).estimate == 4.5  # mean of 3, 4, 5, 6
    # 2 cells (columns) of 3 runs: pooled 1 2 3 10 20 30, floor(6/4) = 1 cut at each end
    assert iqm(np.array([[1, 10], [2, 20], [3, 30]])).estimate == pytest.approx(35 / 4)
    assert iqm([[1, 2, 3], [10, 20, 30]]).estimate == pytest.approx(35 / 4)


def test_the_bootstrap_resamples_within_cells():
    """Every cell constant: a stratified resample always pools 4 zeros and 4 tens, so the
    interval is the point; pooling the runs before resampling would not be."""
    est, lo, hi = iqm([[0.0] * 4, [10.0] * 4])
    assert est == lo == hi == 5.0
    p = performance_profile([[0.0] * 4, [10.0] * 4], [-1, 5, 10])
    assert p.fraction.tolist() == p.low.tolist() == p.high.tolist() == [1.0, 0.5, 0.0]
    est, lo, hi = probability_of_improvement([[1.0] * 3, [5.0] * 2], [[0.0] * 4, [5.0] * 3])
    assert est == lo == hi == (1.0 + 0.5) / 2


@FEW
@given(st.lists(st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=8), min_size=1,
                max_size=4), st.randoms(use_true_random=False))
def test_iqm_is_invariant_to_permuting_runs(cells, random):
    shuffled = []
    for cell in cells:
        cell = list(cell)
        random.shuffle(cell)
        shuffled.append(cell)
    random.shuffle(shuffled)
    assert iqm(shuffled, n_boot=10).estimate == pytest.approx(iqm(cells, n_boot=10).estimate,
                                                              rel=1e-12, abs=1e-9)


def test_probability_of_improvement_by_hand():
    # x=1 beats 0; x=2 beats 0 and ties the two 2s; x=3 beats all: (1 + 2 + 3) / 9
    assert probability_of_improvement([[1, 2, 3]], [[2, 2, 0]]).estimate == pytest.approx(2 / 3)
    two = probability_of_improvement([[1, 2, 3], [1]], [[2, 2, 0], [0, 5]])
    assert two.estimate == pytest.approx((2 / 3 + 1 / 2) / 2)
    lower = probability_of_improvement([[1, 2, 3]], [[2, 2, 0]], better="lower")
    assert lower.estimate == pytest.approx(1 / 3)  # ties count half either way
    with pytest.raises(TaskError):
        probability_of_improvement([[1]], [[1], [2]])


@FEW
@given(st.lists(st.lists(st.integers(-5, 5), min_size=1, max_size=10), min_size=1,
                max_size=4))
def test_probability_of_improvement_of_x_over_itself_is_one_half(cells):
    res = probability_of_improvement(cells, cells, n_boot=200)
    assert res.estimate == 0.5
    assert res.low <= 0.5 <= res.high


def test_performance_profile_by_hand():
    p = performance_profile([[0.0, 1.0], [2.0, 3.0]], [-1.0, 0.5, 3.0])
    assert p.fraction.tolist() == [1.0, 0.75, 0.0]  # strictly above tau
    assert np.all(p.low <= p.fraction) and np.all(p.fraction <= p.high)


# ------------------------------------------------------------------------- rliable


def test_iqm_and_probability_of_improvement_agree_with_rliable():
    """rliable's metrics module needs only numpy and scipy (install with pip install --no-deps
    rliable: its bootstrap and plots need arch, seaborn and absl)."""
    metrics = pytest.importorskip("rliable.metrics")
    rng = np.random.default_rng(7)
    for runs, tasks in ((5, 3), (10, 7), (4, 1)):
        x = rng.integers(0, 6, size=(runs, tasks)).astype(float)  # ties within and across
        y = rng.normal(2.5, 2.0, size=(runs, tasks))
        assert iqm(x, n_boot=10).estimate == pytest.approx(metrics.aggregate_iqm(x), rel=1e-12)
        assert iqm(y, n_boot=10).estimate == pytest.approx(metrics.aggregate_iqm(y), rel=1e-12)
        assert probability_of_improvement(x, y, n_boot=10).estimate == pytest.approx(
            metrics.probability_of_improvement(x, y), rel=1e-12)
        assert probability_of_improvement(y, x, n_boot=10).estimate == pytest.approx(
            metrics.probability_of_improvement(y, x), rel=1e-12)


# ------------------------------------------------------------------------- the docs page


def test_the_docs_example_runs():
    blocks = re.findall(r"^```python\n(.*?)^```", DOC.read_text(), re.MULTILINE | re.DOTALL)
    assert blocks
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), {})  # noqa: S102  (the page's own example)
