"""Statistics for claims over runs: confidence intervals instead of eyeballed curves.

Issue texts ask for "a statistical statement for each pairwise claim". We compare per-run
quantities (e.g. episodes or primitive steps until the greedy policy's value gap falls below a
threshold) with a Welch t-interval on the difference of means and a bootstrap interval on the
ratio of means; both are reported with the run counts.

Per-learner numbers get bootstrap CIs (:func:`bootstrap_ci`): episodes (or primitive steps) to
tolerance, whose censored runs (``inf``) are legal values of a median, and the area under the
gap curve (:func:`gap_auc`), which is finite for every run. Decisions with the fewest runs come
from the group-sequential test in :mod:`adpart.experiments.sequential`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from adpart.learning.curves import episodes_within


@dataclass(frozen=True)
class Comparison:
    """``a`` vs ``b`` over runs: means, Welch CI of the difference, bootstrap CI of the ratio."""

    label_a: str
    label_b: str
    n_a: int
    n_b: int
    mean_a: float
    mean_b: float
    diff: float
    diff_ci: tuple[float, float]
    ratio: float
    ratio_ci: tuple[float, float]
    level: float

    @property
    def a_smaller(self) -> bool:
        """The difference ``a - b`` is below zero with the stated confidence."""
        return self.diff_ci[1] < 0

    def sentence(self, what: str) -> str:
        verdict = (
            f"{self.label_a} is smaller"
            if self.diff_ci[1] < 0
            else f"{self.label_b} is smaller"
            if self.diff_ci[0] > 0
            else "no significant difference"
        )
        pct = round(100 * self.level)
        return (
            f"{what}: {self.label_a} {self.mean_a:.4g} vs {self.label_b} {self.mean_b:.4g} "
            f"(n={self.n_a}/{self.n_b}); ratio {self.ratio:.3g} "
            f"[{pct}% CI {self.ratio_ci[0]:.3g}, {self.ratio_ci[1]:.3g}]; "
            f"difference {self.diff:.4g} [{pct}% CI {self.diff_ci[0]:.4g}, {self.diff_ci[1]:.4g}]"
            f" - {verdict}"
        )

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def compare(
    a: np.ndarray,
    b: np.ndarray,
    label_a: str,
    label_b: str,
    *,
    level: float = 0.95,
    n_boot: int = 2000,
    seed: int = 0,
) -> Comparison:
    """Welch CI for ``mean(a) - mean(b)`` and a percentile bootstrap CI for ``mean(a)/mean(b)``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ma, mb = float(a.mean()), float(b.mean())
    va = a.var(ddof=1) / a.size if a.size > 1 else 0.0
    vb = b.var(ddof=1) / b.size if b.size > 1 else 0.0
    se = float(np.sqrt(va + vb))
    if se > 0:
        dof = (va + vb) ** 2 / (
            (va**2 / (a.size - 1) if a.size > 1 else 0.0)
            + (vb**2 / (b.size - 1) if b.size > 1 else 0.0)
        )
        half = float(stats.t.ppf(0.5 + level / 2, dof)) * se
    else:
        half = 0.0
    rng = np.random.default_rng(seed)
    boot_a = rng.choice(a, size=(n_boot, a.size)).mean(axis=1)
    boot_b = rng.choice(b, size=(n_boot, b.size)).mean(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = boot_a / boot_b
    lo, hi = np.nanpercentile(ratios, [50 * (1 - level), 50 * (1 + level)])
    return Comparison(
        label_a,
        label_b,
        a.size,
        b.size,
        ma,
        mb,
        ma - mb,
        (ma - mb - half, ma - mb + half),
        ma / mb if mb else float("inf"),
        (float(lo), float(hi)),
        level,
    )


def episodes_to_threshold(
    value_gap: np.ndarray, evaluated: np.ndarray, threshold: float
) -> np.ndarray:
    """Per run, the first evaluated episode whose gap (and every later one) is <= ``threshold``.

    Args:
        value_gap: ``(K, N)`` gaps with NaN where not evaluated.
        evaluated: 1-based episode numbers that were evaluated (columns of ``value_gap`` - 1).
        threshold: the bound.

    Returns:
        ``(K,)`` float episodes; ``inf`` for runs that never stay below the threshold.

    The rule of :meth:`adpart.learning.curves.LearningCurve.episodes_to_gap`, computed by the
    same function (:func:`adpart.learning.curves.episodes_within`, ``-1`` mapped to ``inf``); it
    takes a bare matrix because MAXQ-Q on Parr's maze is scored outside a curve.
    """
    first = episodes_within(value_gap, evaluated, threshold)
    return np.where(first >= 0, first.astype(np.float64), np.inf)


def bootstrap_ci(x: np.ndarray, *, statistic: str = "median", level: float = 0.95,
                 n_boot: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """A statistic of ``x`` and its percentile-bootstrap CI.

    ``statistic`` is ``"median"`` (the lower median, ``inverted_cdf``, so censored ``inf``
    values are legal and a CI bound may be ``inf`` = "never") or ``"mean"`` (finite ``x``).
    """
    x = np.asarray(x, dtype=np.float64)
    rng = np.random.default_rng(seed)
    resampled = rng.choice(x, size=(n_boot, x.size))
    if statistic == "median":
        est = float(np.quantile(x, 0.5, method="inverted_cdf"))
        boot = np.quantile(resampled, 0.5, axis=1, method="inverted_cdf")
    elif statistic == "mean":
        est, boot = float(x.mean()), resampled.mean(axis=1)
    else:
        raise ValueError(f"statistic must be 'median' or 'mean', not {statistic!r}")
    lo, hi = np.quantile(boot, [0.5 - level / 2, 0.5 + level / 2], method="inverted_cdf")
    return est, float(lo), float(hi)


def gap_auc(gaps: np.ndarray, x: np.ndarray, cap: float) -> np.ndarray:
    """Per run, the area under the value-gap curve, normalised to a mean gap over ``x``.

    Args:
        gaps: ``(K, m)`` gaps at the evaluation points ``x``; NaN (a policy with no finite
            value: it does not finish from some start) and gaps above ``cap`` count as ``cap``,
            negative gaps (sampling noise of a Monte Carlo score) as 0.
        x: ``(m,)`` or ``(K, m)`` increasing evaluation points (episodes, or cumulative
            primitive steps per run).
        cap: the stated ceiling of a gap.

    Returns:
        ``(K,)`` trapezoidal area divided by the span of ``x`` (a time-averaged gap; smaller is
        faster learning). With one evaluation point, that gap.
    """
    g = np.clip(np.where(np.isnan(gaps), cap, gaps), 0.0, cap)
    x = np.broadcast_to(np.asarray(x, dtype=np.float64), g.shape)
    if g.shape[1] == 1:
        return g[:, 0].copy()
    area = (0.5 * (g[:, 1:] + g[:, :-1]) * np.diff(x, axis=1)).sum(axis=1)
    return area / (x[:, -1] - x[:, 0])


def gap_auc_steps(gaps: np.ndarray, cum_steps: np.ndarray, horizon: float,
                  cap: float, start: float = 0.0) -> np.ndarray:
    """Per run, the mean gap over primitive steps ``[start, horizon]`` of training.

    The gap at step ``t`` is that of the latest evaluation at or before ``t`` (the greedy
    policy the learner would hand over then), ``cap`` before the first one; NaN counts as
    ``cap``, negative gaps as 0. A run whose training ended before ``horizon`` keeps its last
    gap (choose ``horizon`` <= every run's total to avoid relying on that). Comparing learners
    whose first evaluations fall at different step counts, let ``start`` be the latest first
    evaluation of all their runs, so that none is charged ``cap`` for *when* it is first
    scored.

    Args:
        gaps: ``(K, m)`` gaps at the evaluation points.
        cum_steps: ``(K, m)`` cumulative primitive steps at those points (non-decreasing).
        horizon: the common step budget of the comparison.
        cap: ceiling of a gap.

    Returns:
        ``(K,)`` area / ``horizon``.
    """
    g = np.clip(np.where(np.isnan(gaps), cap, gaps), 0.0, cap)
    K = g.shape[0]
    if not 0.0 <= start < horizon:
        raise ValueError(f"need 0 <= start < horizon, got start={start}, horizon={horizon}")
    t = np.clip(np.asarray(cum_steps, dtype=np.float64), start, horizon)
    starts = np.concatenate([np.full((K, 1), float(start)), t], axis=1)  # segment starts
    ends = np.concatenate([t, np.full((K, 1), float(horizon))], axis=1)
    values = np.concatenate([np.full((K, 1), cap), g], axis=1)    # gap held on each segment
    return (values * (ends - starts)).sum(axis=1) / (horizon - start)
