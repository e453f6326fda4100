"""Transfer metrics of learning curves, censored times to the bound, and rliable aggregates.

docs/transfer-metrics.md gives the definitions with their sources and the choices made where a
paper leaves one; in short:

* **Per run** (Taylor & Stone, "Transfer learning for reinforcement learning domains: a survey",
  JMLR 10, 2009, section 2.1, the five measures of transfer): the *jumpstart* (the value gap at
  the first evaluation), the *time to threshold* (the first evaluation from which the gap stays
  within a bound, the rule of :func:`adpart.learning.curves.episodes_within`), as an event time
  that is *right-censored* at the budget when a run never gets there, the *area under the gap
  curve* (their "total reward", for a gap: smaller is better) and the *asymptotic gap* (their
  "asymptotic performance"), in episodes and in cumulative primitive steps:
  :func:`metrics_from_gaps`, :func:`metrics_from_curve`, :class:`TransferMetrics`.
* **Censored event times** (Kaplan & Meier, JASA 53, 1958; Mantel, Cancer Chemother. Rep. 50,
  1966): the Kaplan-Meier median time to the bound with a CI from the survival function's
  confidence band (:func:`km_median`), the log-rank test of "A reaches the bound sooner than B"
  (:func:`logrank_sooner`) and the ratio of two KM medians with a bootstrap CI over runs
  (:func:`km_median_ratio`).
* **Aggregates over cells** (tasks or environments; Agarwal et al., "Deep reinforcement learning
  at the edge of the statistical precipice", NeurIPS 2021, the ``rliable`` library): the
  interquartile mean (:func:`iqm`), the probability of improvement (:func:`probability_of_
  improvement`) and performance profiles (:func:`performance_profile`), each with a stratified
  bootstrap CI that resamples runs within each cell.

Pure numpy and scipy: no I/O, no plugins.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
from scipy import stats

from adpart.errors import TaskError
from adpart.learning.curves import LearningCurve, episodes_within

__all__ = [
    "Interval",
    "LogRank",
    "Profile",
    "TransferMetrics",
    "censored_data",
    "iqm",
    "jumpstart_gain",
    "km_median",
    "km_median_ratio",
    "logrank_sooner",
    "metrics_from_curve",
    "metrics_from_gaps",
    "performance_profile",
    "probability_of_improvement",
]

#: A survival probability within this (relative) distance of 1/2 counts as 1/2 when the median
#: is read off the curve: ``(5/6)(4/5)(3/4)`` rounds to either side of 0.5.
_HALF_TOLERANCE = 1e-10

Unit = Literal["episodes", "steps"]


class Interval(NamedTuple):
    """A point estimate and the two ends of its confidence interval (a plain 3-tuple too)."""

    estimate: float
    low: float
    high: float


class LogRank(NamedTuple):
    """The log-rank statistic ``Z`` (positive when A reaches the bound sooner than expected
    under "no difference") and its p-value for the chosen alternative."""

    statistic: float
    pvalue: float


class Profile(NamedTuple):
    """A performance profile: per threshold ``tau``, the fraction of runs scoring above it and
    a pointwise confidence band."""

    taus: np.ndarray
    fraction: np.ndarray
    low: np.ndarray
    high: np.ndarray


# --------------------------------------------------------------------------- per run


@dataclass(frozen=True, eq=False)
class TransferMetrics:
    """Taylor & Stone's (2009, sec. 2.1) measures of ``K`` runs, one entry per run.

    Gaps are *scored* before they enter a measure: NaN (a greedy policy with no finite value)
    counts as ``cap``, a gap above ``cap`` as ``cap`` and a negative gap (rounding of an exact
    evaluation) as 0. The time to threshold uses the raw gaps and the rule of
    :func:`adpart.learning.curves.episodes_within` (NaN is above the bound).

    Attributes:
        threshold: the bound on the value gap.
        evaluated: ``(m,)`` the episodes at which the runs were evaluated.
        jumpstart: ``(K,)`` the scored gap at the first evaluation (lower is better).
        time_episodes: ``(K,)`` the time to threshold in episodes: the first evaluated episode
            from which the gap stays ``<= threshold`` through the last evaluation; for a
            censored run, the last evaluated episode (the budget), at which it was still out.
        time_steps: ``(K,)`` the same event in cumulative primitive steps at the end of that
            episode; a censored run is censored at its total steps at the last evaluation.
        censored: ``(K,)`` True where the run never stays within the bound (its times are
            censoring times: the event, if it comes, comes later).
        auc_episodes: ``(K,)`` the area under the scored gap over episodes ``[0, last
            evaluation]`` (trapezoids between evaluations; on ``[0, first evaluation]`` the
            first gap is held: the untrained policy is not scored). Divide by the budget for a
            mean gap.
        auc_steps: ``(K,)`` the same over the run's cumulative primitive steps.
        asymptotic_gap: ``(K,)`` the mean scored gap over the last ``last`` evaluations.
        last: the number of evaluations ``asymptotic_gap`` averages.
    """

    threshold: float
    evaluated: np.ndarray
    jumpstart: np.ndarray
    time_episodes: np.ndarray
    time_steps: np.ndarray
    censored: np.ndarray
    auc_episodes: np.ndarray
    auc_steps: np.ndarray
    asymptotic_gap: np.ndarray
    last: int

    def __post_init__(self) -> None:
        for name in ("evaluated", "jumpstart", "time_episodes", "time_steps", "censored",
                     "auc_episodes", "auc_steps", "asymptotic_gap"):
            arr = np.array(getattr(self, name))
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def n_runs(self) -> int:
        return int(self.censored.size)

    @property
    def reached(self) -> np.ndarray:
        """``(K,)`` True where the run stays within the bound from some evaluation on."""
        return ~self.censored

    def event_times(self, unit: Unit = "episodes") -> tuple[np.ndarray, np.ndarray]:
        """``(times, censored)`` of the time to threshold in ``unit`` (``"episodes"`` or
        ``"steps"``), the arguments of :func:`km_median`, :func:`logrank_sooner` and
        :func:`km_median_ratio`."""
        if unit == "episodes":
            return self.time_episodes, self.censored
        if unit == "steps":
            return self.time_steps, self.censored
        raise TaskError(f"unit must be 'episodes' or 'steps', not {unit!r}")


def metrics_from_gaps(gaps: np.ndarray, evaluated: np.ndarray, cum_steps: np.ndarray,
                      threshold: float, *, last: int = 3, cap: float = np.inf
                      ) -> TransferMetrics:
    """Taylor & Stone's (JMLR 2009, sec. 2.1) per-run measures from gaps at evaluation points.

    Args:
        gaps: ``(K, m)`` value gaps of ``K`` runs at their ``m`` evaluations.
        evaluated: ``(m,)`` increasing episode numbers of the evaluations (after that many
            episodes; 1-based in a :class:`~adpart.learning.curves.LearningCurve`).
        cum_steps: ``(K, m)`` cumulative primitive steps of each run at each evaluation
            (non-decreasing along a row).
        threshold: the bound (e.g. :func:`adpart.learning.comparison.success_bound`).
        last: how many final evaluations the asymptotic gap averages (all if fewer).
        cap: the score of a NaN gap and the ceiling of every gap (default ``inf``: a run with
            a policy that does not finish has an infinite area; give the largest gap a policy
            can have for finite areas).

    Returns:
        A :class:`TransferMetrics`. A run that never stays within ``threshold`` is *censored*
        at the last evaluation (episodes) and at its steps there, not set to the budget plus
        one: :func:`km_median` and :func:`logrank_sooner` treat it as "later than this".
    """
    g = np.asarray(gaps, dtype=np.float64)
    if g.ndim != 2 or g.shape[0] == 0 or g.shape[1] == 0:
        raise TaskError(f"gaps must be a non-empty (runs, evaluations) matrix, got {g.shape}")
    K, m = g.shape
    x = np.asarray(evaluated, dtype=np.float64)
    if x.shape != (m,) or np.any(np.diff(x) <= 0) or x[0] < 0:
        raise TaskError(f"evaluated must be {m} increasing episode numbers >= 0, got {x}")
    steps = np.asarray(cum_steps, dtype=np.float64)
    if steps.shape != (K, m) or np.any(np.diff(steps, axis=1) < 0) or np.any(steps < 0):
        raise TaskError(f"cum_steps must be a ({K}, {m}) matrix non-decreasing along each run, "
                        f"got shape {steps.shape}")
    if not last >= 1:
        raise TaskError(f"last must be at least 1, got {last}")
    if not threshold >= 0:  # NaN too; inf (success_bound without V*) is every gap
        raise TaskError(f"threshold must be a gap >= 0, got {threshold}")
    scored = np.clip(np.where(np.isnan(g), cap, g), 0.0, cap)
    # the one rule of episodes_within, on the evaluation columns: 1-based column -> position
    position = episodes_within(g, np.arange(1, m + 1), threshold) - 1
    censored = position < 0
    at = np.where(censored, m - 1, position)
    time_episodes = x[at]
    time_steps = steps[np.arange(K), at]
    return TransferMetrics(
        threshold=float(threshold),
        evaluated=np.asarray(evaluated).copy(),
        jumpstart=scored[:, 0].copy(),
        time_episodes=time_episodes,
        time_steps=time_steps,
        censored=censored,
        auc_episodes=_held_trapezoid(scored, np.broadcast_to(x, (K, m))),
        auc_steps=_held_trapezoid(scored, steps),
        asymptotic_gap=scored[:, -min(last, m):].mean(axis=1),
        last=int(last),
    )


def metrics_from_curve(curve: LearningCurve, threshold: float, *, last: int = 3,
                       cap: float = np.inf) -> TransferMetrics:
    """:func:`metrics_from_gaps` of a learning curve: its ``value_gap`` at the evaluated
    episodes (:meth:`~adpart.learning.curves.LearningCurve.evaluated_episodes`) and the
    cumulative sum of its ``steps`` column at the end of those episodes."""
    evaluated = curve.evaluated_episodes()
    if evaluated.size == 0:
        raise TaskError("the learning curve has no evaluated episode")
    gaps = curve.matrix("value_gap")[:, evaluated - 1]
    cum_steps = np.cumsum(curve.matrix("steps"), axis=1)[:, evaluated - 1]
    return metrics_from_gaps(gaps, evaluated, cum_steps, threshold, last=last, cap=cap)


def _held_trapezoid(g: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Per row, ``g[0] * x[0]`` (the first value held back to 0) plus the trapezoids of ``g``
    over ``x``; a zero-width segment adds 0 even next to an infinite gap."""
    with np.errstate(invalid="ignore"):
        first = np.where(x[:, 0] > 0, g[:, 0] * x[:, 0], 0.0)
        dx = np.diff(x, axis=1)
        parts = np.where(dx > 0, 0.5 * (g[:, 1:] + g[:, :-1]) * dx, 0.0)
    return first + parts.sum(axis=1)


def jumpstart_gain(method: TransferMetrics, baseline: TransferMetrics, *, level: float = 0.95,
                   n_boot: int = 2000, seed: int = 0) -> Interval:
    """Taylor & Stone's (2009, sec. 2.1) jumpstart of ``method`` over ``baseline``: the
    baseline's mean gap at the first evaluation minus the method's (positive when the method
    starts closer to optimal), with a percentile-bootstrap CI (each learner's runs resampled
    independently). Both must be first evaluated after the same episode."""
    if method.evaluated[0] != baseline.evaluated[0]:
        raise TaskError(
            f"jumpstarts are comparable only at the same first evaluation; the method's is "
            f"after episode {method.evaluated[0]}, the baseline's after {baseline.evaluated[0]}")
    a, b = method.jumpstart, baseline.jumpstart
    rng = np.random.default_rng(seed)
    boot_a = a[rng.integers(0, a.size, size=(n_boot, a.size))].mean(axis=1)
    boot_b = b[rng.integers(0, b.size, size=(n_boot, b.size))].mean(axis=1)
    with np.errstate(invalid="ignore"):
        return _interval(float(b.mean() - a.mean()), boot_b - boot_a, level)


# --------------------------------------------------------------------------- censored times


def _event_arrays(times: np.ndarray, censored: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    c = np.asarray(censored, dtype=bool).reshape(-1)
    if t.shape != c.shape or t.size == 0:
        raise TaskError(f"need as many censoring flags as times (at least one), got {t.size} "
                        f"times and {c.size} flags")
    if not np.all(np.isfinite(t)):
        raise TaskError("event and censoring times must be finite (censor a run that never "
                        "gets there at its budget instead of giving it inf)")
    return t, c


def censored_data(times: np.ndarray, censored: np.ndarray) -> stats.CensoredData:
    """``scipy.stats.CensoredData``: the uncensored times are events, the censored ones are
    right-censored (the event comes after them, if at all)."""
    t, c = _event_arrays(times, censored)
    return stats.CensoredData(uncensored=t[~c], right=t[c])


def _first_at_or_below_half(times: np.ndarray, survival: np.ndarray) -> float:
    """The first of ``times`` where ``survival`` is at most 1/2; ``inf`` if none."""
    below = survival <= 0.5 * (1.0 + _HALF_TOLERANCE)
    return float(times[np.argmax(below)]) if below.any() else float("inf")


def km_median(times: np.ndarray, censored: np.ndarray, *, level: float = 0.95,
              method: Literal["log-log", "linear"] = "log-log") -> Interval:
    """The Kaplan-Meier (1958) median time to the bound, with a confidence interval.

    The product-limit estimate ``S(t) = prod_{t_j <= t} (1 - d_j / n_j)`` of "not yet within the
    bound" comes from ``scipy.stats.ecdf`` on :func:`censored_data` (at a tie, events come
    before censorings). The median is the first time with ``S(t) <= 1/2``; without censoring
    that is the ``inverted_cdf`` sample median (the lower median of an even sample). It is
    ``inf`` when ``S`` never gets down to 1/2 (fewer than half the runs get there, counting
    the censored ones as possibly never).

    The interval is read off the survival function's pointwise confidence band (Greenwood's
    variance, ``method`` as in ``scipy.stats``' ``ECDFResult.sf.confidence_interval``; the
    log-log transform keeps the band in [0, 1]), as Brookmeyer & Crowley (Biometrics 38, 1982)
    do: the low end is the first time the band's lower curve is at most 1/2, the high end the
    first time its upper curve is (``inf`` if never). Where the band is undefined (``S`` is
    still 1, or already 0) it is taken as ``S`` itself; so with few events the interval is too
    narrow at the low end (no run within the bound gives ``[inf, inf]``).

    Args:
        times: ``(n,)`` event or censoring times (e.g. :meth:`TransferMetrics.event_times`).
        censored: ``(n,)`` True where the time is a censoring time.
        level: the confidence level.
        method: ``"log-log"`` (default) or ``"linear"``.

    Returns:
        ``Interval(median, low, high)``.
    """
    sf = stats.ecdf(censored_data(times, censored)).sf
    estimate = _first_at_or_below_half(sf.quantiles, sf.probabilities)
    with warnings.catch_warnings():
        # "The confidence interval is undefined at some observations": where S is 0 or 1
        warnings.simplefilter("ignore", RuntimeWarning)
        band = sf.confidence_interval(level, method=method)
        low = np.where(np.isnan(band.low.probabilities), sf.probabilities,
                       band.low.probabilities)
        high = np.where(np.isnan(band.high.probabilities), sf.probabilities,
                        band.high.probabilities)
    return Interval(estimate, _first_at_or_below_half(sf.quantiles, low),
                    _first_at_or_below_half(sf.quantiles, high))


def _km_medians(times: np.ndarray, censored: np.ndarray) -> np.ndarray:
    """Kaplan-Meier medians of the rows of ``(B, n)`` times, vectorised (the bootstrap's).

    Rows are sorted by time, events before censorings at a tie; processing a tie's ``d`` events
    one at a time multiplies ``S`` by ``(r-1)/r * (r-2)/(r-1) ... = (r-d)/r``, the product-limit
    factor, so the first sorted position where ``S <= 1/2`` holds the median (the tests check it
    against :func:`km_median`).
    """
    order = np.argsort(censored, axis=1, kind="stable")
    t = np.take_along_axis(times, order, axis=1)
    order = np.take_along_axis(order, np.argsort(t, axis=1, kind="stable"), axis=1)
    t = np.take_along_axis(times, order, axis=1)
    event = ~np.take_along_axis(censored, order, axis=1)
    n = times.shape[1]
    at_risk = np.arange(n, 0, -1, dtype=np.float64)
    with np.errstate(divide="ignore"):
        log_s = np.cumsum(np.where(event, np.log1p(-1.0 / at_risk), 0.0), axis=1)
    below = log_s <= np.log(0.5) + _HALF_TOLERANCE
    first = np.argmax(below, axis=1)
    return np.where(below.any(axis=1), t[np.arange(t.shape[0]), first], np.inf)


def logrank_sooner(times_a: np.ndarray, censored_a: np.ndarray, times_b: np.ndarray,
                   censored_b: np.ndarray, *,
                   alternative: Literal["sooner", "later", "two-sided"] = "sooner") -> LogRank:
    """The log-rank test (Mantel 1966) of method A against baseline B, ``scipy.stats.logrank``.

    ``Z = sum_j (O_Aj - E_Aj) / sqrt(sum_j V_j)`` over the distinct event times ``t_j``: ``O_Aj``
    runs of A reach the bound at ``t_j``, ``E_Aj = O_j N_Aj / N_j`` are expected to under "same
    distribution", with ``V_j = E_Aj (1 - N_Aj / N_j)(N_j - O_j) / (N_j - 1)``; ``Z^2`` is the
    usual chi-square statistic with one degree of freedom. ``Z > 0``: A reaches the bound more
    often than expected, i.e. sooner.

    Args:
        times_a, censored_a: A's times to the bound and censoring flags.
        times_b, censored_b: B's.
        alternative: ``"sooner"`` (default: A reaches the bound sooner, one-sided, scipy's
            ``"greater"``: A's rate of reaching it is higher), ``"later"`` or ``"two-sided"``.

    Returns:
        ``LogRank(statistic=Z, pvalue)``; ``(0.0, 1.0)`` when the variance is 0 (no run of
        either reaches the bound, or only when nothing can tell the two apart: no evidence
        either way).
    """
    scipy_alternative = {"sooner": "greater", "later": "less", "two-sided": "two-sided"}
    if alternative not in scipy_alternative:
        raise TaskError(f"alternative must be one of {list(scipy_alternative)}, "
                        f"not {alternative!r}")
    a, b = censored_data(times_a, censored_a), censored_data(times_b, censored_b)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # 0 / 0, see below
        res = stats.logrank(a, b, alternative=scipy_alternative[alternative])
    if np.isnan(res.statistic):
        # sum V_j = 0: at every event time only one learner's runs are at risk, or all runs at
        # risk reach the bound; then O_Aj = E_Aj at each, the statistic is 0 / 0
        return LogRank(0.0, 1.0)
    return LogRank(float(res.statistic), float(res.pvalue))


def km_median_ratio(times_a: np.ndarray, censored_a: np.ndarray, times_b: np.ndarray,
                    censored_b: np.ndarray, *, level: float = 0.95, n_boot: int = 2000,
                    seed: int = 0) -> Interval:
    """A's Kaplan-Meier median time to the bound over B's, with a percentile-bootstrap CI.

    Each bootstrap sample draws A's runs and B's runs with replacement (independently; a run
    keeps its censoring flag, so a censored run stays censored) and recomputes both KM
    medians. A median of ``inf`` (never down to 1/2) makes a ratio ``inf`` (A's) or 0 (B's);
    ``inf / inf`` is undefined and counted as ``inf``, so a CI end of ``inf`` means "no bound".
    Without censoring this is :func:`adpart.learning.comparison.ratio_of_medians_ci` (same
    draws for the same seed).

    Returns:
        ``Interval(ratio, low, high)``; below 1 means A gets there sooner.
    """
    ta, ca = _event_arrays(times_a, censored_a)
    tb, cb = _event_arrays(times_b, censored_b)
    rng = np.random.default_rng(seed)
    ia = rng.integers(0, ta.size, size=(n_boot, ta.size))
    ib = rng.integers(0, tb.size, size=(n_boot, tb.size))
    boot = _ratio(_km_medians(ta[ia], ca[ia]), _km_medians(tb[ib], cb[ib]))
    estimate = _ratio(np.array([km_median(ta, ca).estimate]),
                      np.array([km_median(tb, cb).estimate]))[0]
    return _interval(float(estimate), boot, level)


def _ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        r = a / b
    return np.where(np.isnan(r), np.inf, r)


def _interval(estimate: float, boot: np.ndarray, level: float) -> Interval:
    if not 0.0 < level < 1.0:
        raise TaskError(f"level must be in (0, 1), got {level}")
    lo, hi = np.quantile(boot, [0.5 - level / 2, 0.5 + level / 2], method="inverted_cdf")
    return Interval(estimate, float(lo), float(hi))


# --------------------------------------------------------------------------- over cells

Scores = Sequence[np.ndarray] | np.ndarray


def _cells(scores: Scores) -> list[np.ndarray]:
    """Per cell, its runs' scores: a 2-D array is rliable's ``(runs, cells)``, a sequence has
    one 1-D array per cell (cells may differ in runs)."""
    if isinstance(scores, np.ndarray):
        if scores.ndim != 2:
            raise TaskError(f"a score array must be (runs, cells), got shape {scores.shape}")
        cells = [np.asarray(scores[:, j], dtype=np.float64) for j in range(scores.shape[1])]
    else:
        cells = [np.asarray(c, dtype=np.float64).reshape(-1) for c in scores]
    if not cells or any(c.size == 0 for c in cells):
        raise TaskError("need at least one cell, each with at least one run")
    if any(np.isnan(c).any() for c in cells):
        raise TaskError("scores must not be NaN")
    return cells


def _stratified(cells: list[np.ndarray], n_boot: int, rng: np.random.Generator) -> np.ndarray:
    """``(n_boot, total runs)``: per bootstrap sample, each cell's runs drawn with replacement
    from that cell (cell by cell, in order), then pooled."""
    return np.concatenate([c[rng.integers(0, c.size, size=(n_boot, c.size))] for c in cells],
                          axis=1)


def iqm(scores: Scores, *, level: float = 0.95, n_boot: int = 2000, seed: int = 0) -> Interval:
    """The interquartile mean of all runs of all cells (Agarwal et al., NeurIPS 2021, sec. 4)
    with a stratified-bootstrap CI.

    The IQM is ``scipy.stats.trim_mean(pooled, 0.25)``, rliable's ``aggregate_iqm``: the mean
    after dropping ``floor(n / 4)`` of the ``n`` pooled runs from each end (exactly the middle
    half when ``4 | n``). Runs are pooled, so a cell with more runs weighs more; rliable wants
    the same number in every cell. The CI resamples runs within each cell (rliable's
    ``StratifiedBootstrap``) and takes percentiles.

    Args:
        scores: a ``(runs, cells)`` array, or one array of run scores per cell.
        level, n_boot, seed: the CI's level, bootstrap samples and random seed.
    """
    cells = _cells(scores)
    estimate = float(stats.trim_mean(np.concatenate(cells), 0.25))
    boot = stats.trim_mean(_stratified(cells, n_boot, np.random.default_rng(seed)), 0.25,
                           axis=1)
    return _interval(estimate, boot, level)


def _improvement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per row of ``x`` (B, n) and ``y`` (B, m), the fraction of pairs with ``x > y``, ties
    counting one half: the Mann-Whitney ``U`` of x over ``n m``, from mid-ranks."""
    n, m = x.shape[1], y.shape[1]
    ranks = stats.rankdata(np.concatenate([x, y], axis=1), axis=1)
    return (ranks[:, :n].sum(axis=1) - n * (n + 1) / 2) / (n * m)


def probability_of_improvement(x: Scores, y: Scores, *,
                               better: Literal["higher", "lower"] = "higher",
                               level: float = 0.95, n_boot: int = 2000, seed: int = 0
                               ) -> Interval:
    """The average probability of improvement of X over Y (Agarwal et al., NeurIPS 2021, sec.
    4), with a stratified-bootstrap CI.

    Per cell ``c``, ``P(X_c > Y_c)``: the fraction of (run of X, run of Y) pairs where X's run
    scores higher, a tie counting 1/2 (the Mann-Whitney ``U / (n m)``, rliable's
    ``probability_of_improvement``); then the mean over cells, each cell weighing the same. The
    CI resamples X's and Y's runs independently within each cell (rliable's
    ``StratifiedIndependentBootstrap``).

    Args:
        x, y: the two learners' scores, cell for cell (see :func:`iqm`).
        better: ``"lower"`` for scores where lower is better (gaps, times, areas): then it is
            ``P(X_c < Y_c)``.
        level, n_boot, seed: the CI's level, bootstrap samples and random seed.
    """
    cx, cy = _cells(x), _cells(y)
    if len(cx) != len(cy):
        raise TaskError(f"x has {len(cx)} cells and y {len(cy)}; they must match")
    if better not in ("higher", "lower"):
        raise TaskError(f"better must be 'higher' or 'lower', not {better!r}")
    sign = 1.0 if better == "higher" else -1.0
    rng = np.random.default_rng(seed)
    estimate = np.mean([_improvement(sign * a[None, :], sign * b[None, :])[0]
                        for a, b in zip(cx, cy, strict=True)])
    boot = np.zeros(n_boot)
    for a, b in zip(cx, cy, strict=True):
        ia = rng.integers(0, a.size, size=(n_boot, a.size))
        ib = rng.integers(0, b.size, size=(n_boot, b.size))
        boot += _improvement(sign * a[ia], sign * b[ib])
    return _interval(float(estimate), boot / len(cx), level)


def performance_profile(scores: Scores, taus: np.ndarray, *, level: float = 0.95,
                        n_boot: int = 2000, seed: int = 0) -> Profile:
    """The run-score performance profile (Agarwal et al., NeurIPS 2021, sec. 4): per ``tau``,
    the fraction of all runs of all cells whose score is above ``tau`` (rliable's
    ``run_score_deviation``), with pointwise stratified-bootstrap CIs.

    For a lower-is-better score pass its negation and negated ``taus``.

    Args:
        scores: a ``(runs, cells)`` array, or one array of run scores per cell.
        taus: ``(T,)`` thresholds.
        level, n_boot, seed: the CI's level, bootstrap samples and random seed.
    """
    cells = _cells(scores)
    t = np.asarray(taus, dtype=np.float64).reshape(-1)
    pooled = np.concatenate(cells)
    fraction = (pooled[:, None] > t[None, :]).mean(axis=0)
    boot = _stratified(cells, n_boot, np.random.default_rng(seed))
    curves = np.stack([(boot > tau).mean(axis=1) for tau in t], axis=1)  # (n_boot, T)
    if not 0.0 < level < 1.0:
        raise TaskError(f"level must be in (0, 1), got {level}")
    lo, hi = np.quantile(curves, [0.5 - level / 2, 0.5 + level / 2], axis=0,
                         method="inverted_cdf")
    return Profile(t, fraction, lo, hi)
