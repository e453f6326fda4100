"""A method against its baseline over runs: episodes to the success bound, and the ratio of
median episodes with a bootstrap CI.

The claims of the pipeline and of the experiments ("the layer learns in a third of flat's
episodes") compare per-run episodes to the success bound of two learners run in the same
process; a run that never gets there counts as censored (the budget plus one, or ``inf``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from adpart.learning.curves import SUCCESS_FRACTION, LearningCurve, episodes_within
from adpart.learning.knowledge import Knowledge
from adpart.learning.transfer_metrics import (
    km_median,
    km_median_ratio,
    logrank_sooner,
    metrics_from_curve,
)

__all__ = ["SUCCESS_FRACTION", "TIE_TOLERANCE", "best_final_run", "best_observed_run",
           "episodes_to_bound", "interval_text", "measured", "per_run_to_bound",
           "ratio_of_medians_ci", "success_bound", "survival_sentence", "task_row", "time_ratio"]


#: Final gaps closer than this fraction of the value scale (``max(1, |V*(start)|)``) are a tie:
#: exact evaluations of equally good policies differ by rounding (1.8e-15 on three-floor), and
#: how they round depends on the machine and the linear-algebra libraries.
TIE_TOLERANCE = 1e-9


def ratio_of_medians_ci(a: np.ndarray, b: np.ndarray, *, level: float = 0.95,
                        n_boot: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """``median(a) / median(b)`` with a percentile-bootstrap CI (the two samples resampled
    independently); lower medians, so censored ``inf`` values are legal (an ``inf`` bound
    means "at least this large" cannot be excluded)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    rng = np.random.default_rng(seed)
    ma = np.quantile(rng.choice(a, size=(n_boot, a.size)), 0.5, axis=1, method="inverted_cdf")
    mb = np.quantile(rng.choice(b, size=(n_boot, b.size)), 0.5, axis=1, method="inverted_cdf")
    with np.errstate(divide="ignore", invalid="ignore"):
        r = ma / mb
    r = np.where(np.isnan(r), np.inf, r)  # inf / inf: undefined, counted as unbounded
    with np.errstate(divide="ignore", invalid="ignore"):
        est = (np.quantile(a, 0.5, method="inverted_cdf")
               / np.quantile(b, 0.5, method="inverted_cdf"))
    est = np.inf if np.isnan(est) else est
    lo, hi = np.quantile(r, [0.5 - level / 2, 0.5 + level / 2], method="inverted_cdf")
    return float(est), float(lo), float(hi)


def task_row(
    task: str, label: str, curve: LearningCurve, fraction: float, extra: dict[str, Any]
) -> dict[str, Any]:
    """One learner's summary row for a task: runs within the bound, median episodes to it
    (``inf`` when never within), final gaps, mean steps and decisions, the measured transfer
    metrics (:func:`measured`), then ``extra``."""
    v_star = float(curve.metadata.get("v_star_start", np.nan))
    bound = success_bound(curve, fraction)
    within = episodes_within(curve.matrix("value_gap"), curve.evaluated_episodes(), bound)
    to_bound = np.where(within < 0, np.inf, within)  # never within: inf (null in JSON)
    final = curve.matrix("value_gap")[:, -1]
    known = curve.metadata.get("knowledge")
    return {
        "task": task,
        "learner": label,
        # the learner's own record; a workflow that knows the run's inputs puts theirs on top
        "knowledge": Knowledge.from_dict(known).label if known else None,
        "runs": curve.n_runs,
        "v_star_start": v_star,
        "bound": bound,
        "final_gap_mean": float(np.mean(final)),
        "final_gap_max": float(np.max(final)),
        "runs_within_bound": int(np.sum(final <= bound)),
        "episodes_to_bound_median": float(np.median(to_bound)),
        "steps_total_mean": float(curve.matrix("steps").sum(axis=1).mean()),
        "decisions_total_mean": float(curve.matrix("decisions").sum(axis=1).mean()),
        **measured(curve, bound),
        **extra,
    }


def measured(curve: LearningCurve, bound: float) -> dict[str, Any]:
    """Taylor & Stone's metrics of the runs (:mod:`adpart.learning.transfer_metrics`): runs that
    never stay within ``bound`` are censored, not counted as the budget plus one; the time to
    the bound is the Kaplan-Meier median with its 95% CI, in episodes and in primitive steps;
    jumpstart, area under the gap curve and asymptotic gap are run means. Empty without a
    finite bound (a curve with no ``V*``)."""
    if not np.isfinite(bound):
        return {}
    m = metrics_from_curve(curve, bound)
    km = {unit: [float(x) for x in km_median(*m.event_times(unit))]
          for unit in ("episodes", "steps")}
    return {
        "censored_runs": int(m.censored.sum()),
        "time_to_bound_km": km,  # [median, low, high] per unit; inf: fewer than half get there
        "jumpstart_gap_mean": float(np.mean(m.jumpstart)),
        "gap_auc_episodes_mean": float(np.mean(m.auc_episodes)),
        "gap_auc_steps_mean": float(np.mean(m.auc_steps)),
        "asymptotic_gap_mean": float(np.mean(m.asymptotic_gap)),
    }


def success_bound(curve: LearningCurve, fraction: float) -> float:
    """The gap a run must stay within: ``fraction |V*(start)|`` (at least 1e-9; ``inf`` when the
    curve carries no ``V*``)."""
    v_star = float(curve.metadata.get("v_star_start", np.nan))
    return max(1e-9, fraction * abs(v_star)) if np.isfinite(v_star) else np.inf


def per_run_to_bound(curve: LearningCurve, fraction: float = SUCCESS_FRACTION
                     ) -> dict[str, Any] | None:
    """Each run's time to the success bound, as the pipeline's table and the comparisons
    measure it, in plain data (what a stored run keeps in ``metrics["per_run"]``).

    The bound is :func:`success_bound`; the times are those of :func:`~adpart.learning.
    transfer_metrics.metrics_from_curve` (the rule of :func:`~adpart.learning.curves.
    episodes_within`), the same numbers :func:`task_row`, :func:`time_ratio` and the
    comparisons' Kaplan-Meier medians are made of. Keys: ``fraction``, ``bound``, then one list
    entry per run: ``episodes_to_bound`` and ``steps_to_bound`` (the first evaluated episode from
    which the gap stays within the bound, and the primitive steps up to the end of it; for a
    ``censored`` run, one that never stays within it, the last evaluation and the steps up to
    it: a survival estimator's censoring time), ``censored`` and ``final_gap`` (the gap at the
    last episode; None where it is NaN). None when the curve carries no ``V*`` (no bound) or
    no evaluated episode.
    """
    bound = success_bound(curve, fraction)
    if not np.isfinite(bound) or curve.evaluated_episodes().size == 0:
        return None
    m = metrics_from_curve(curve, bound)
    final = curve.matrix("value_gap")[:, -1]
    return {
        "fraction": float(fraction),
        "bound": float(bound),
        "episodes_to_bound": [int(t) for t in m.time_episodes],
        "steps_to_bound": [int(t) for t in m.time_steps],
        "censored": [bool(c) for c in m.censored],
        "final_gap": [float(g) if np.isfinite(g) else None for g in final],
    }


def best_final_run(curve: LearningCurve) -> int:
    """The run whose final greedy policy has the smallest value gap, the lowest run index among
    those within :data:`TIE_TOLERANCE` of it (so the choice does not hang on rounding); runs
    whose final value is undefined (NaN) are passed over, and run 0 is taken when all are."""
    final = curve.matrix("value_gap")[:, -1]
    if not np.any(np.isfinite(final)):
        return 0
    v_star = float(curve.metadata.get("v_star_start", np.nan))
    scale = max(1.0, abs(v_star)) if np.isfinite(v_star) else 1.0
    best = float(np.nanmin(final))
    return int(np.flatnonzero(final <= best + TIE_TOLERANCE * scale)[0])


def best_observed_run(curve: LearningCurve, tail: float = 0.1) -> int:
    """The run whose episodes earned the most, by what the agent observed: the highest mean
    discounted return over the last ``tail`` of its episodes (at least one), the lowest run
    index among ties. Unlike :func:`best_final_run` it reads no ``V*``, so a learner may pick
    the policy it transfers from with it."""
    returns = curve.matrix("discounted_return")
    last = max(1, int(np.ceil(tail * returns.shape[1])))
    score = returns[:, -last:].mean(axis=1)
    return int(np.flatnonzero(score >= np.max(score))[0])


def episodes_to_bound(curve: LearningCurve, fraction: float) -> np.ndarray:
    """Per run, the episode after which the gap stays within :func:`success_bound`; a run never
    within it counts as censored at the curve's episodes + 1."""
    within = episodes_within(curve.matrix("value_gap"), curve.evaluated_episodes(),
                             success_bound(curve, fraction))
    episodes = int(curve.evaluated_episodes()[-1])
    return np.where(within < 0, episodes + 1.0, within.astype(np.float64))


def time_ratio(method: LearningCurve, baseline: LearningCurve, fraction: float, seed: int
               ) -> dict[str, Any]:
    """The method's time to the bound over a baseline's (flat Q-learning, known-dynamics, or
    another learner on the same task), measured as survival analysis does.

    Runs that never stay within the bound are censored at their last evaluation (not counted
    as the budget plus one). For each unit, episodes and primitive steps: the ratio of the
    Kaplan-Meier medians with a 95 % bootstrap CI over runs
    (:func:`~adpart.learning.transfer_metrics.km_median_ratio`; a CI end of ``inf`` means no
    bound) and the one-sided log-rank test that the method reaches the bound sooner
    (:func:`~adpart.learning.transfer_metrics.logrank_sooner`). The episodes' figures are at
    the top level, the steps' under ``"steps"``.

    Where fewer than half of the baseline's runs reach the bound its median is beyond the
    budget, and a ratio to it is no number: ``ratio`` is then None and ``at_most`` the bound the
    runs give, the method's median over the latest time a baseline run was still censored
    (likewise ``at_least`` where the method's median is beyond its budget and the baseline's
    is not).
    """
    bound = success_bound(baseline, fraction)
    a, b = metrics_from_curve(method, bound), metrics_from_curve(baseline, bound)
    out: dict[str, dict[str, Any]] = {}
    for unit in ("episodes", "steps"):
        ta, ca = a.event_times(unit)
        tb, cb = b.event_times(unit)
        r = km_median_ratio(ta, ca, tb, cb, seed=seed)
        test = logrank_sooner(ta, ca, tb, cb)
        ma, mb = km_median(ta, ca).estimate, km_median(tb, cb).estimate
        entry: dict[str, Any] = {"ratio": r.estimate, "ci95": [r.low, r.high],
                                 "logrank_z": test.statistic, "p_sooner": test.pvalue}
        if not np.isfinite(mb) or not np.isfinite(ma):
            entry["ratio"] = None
            if np.isfinite(ma):
                entry["at_most"] = float(ma / np.max(tb[cb]))
            elif np.isfinite(mb):
                entry["at_least"] = float(np.max(ta[ca]) / mb)
        out[unit] = entry
    return {**out["episodes"], "steps": out["steps"],
            "censored": [int(a.censored.sum()), int(b.censored.sum())],
            "first_evaluation": int(method.evaluated_episodes()[0])}


#: What an interval of zero width is called: every bootstrap resample gave the estimate (for a
#: run mean, every run has the same value; for a median, the runs tie at it).
ZERO_WIDTH = "all resamples equal"


def interval_text(estimate: float, low: float, high: float, *, inf: str = "inf",
                  style: str = "brackets") -> str:
    """An estimate and its CI as the tables and sentences print them, three significant digits.

    ``style`` ``"brackets"``: ``161 [156, 166]``; ``"sentence"``: ``0.528 (95% CI 0.51-0.541)``.
    An infinite value prints as ``inf`` (``"never"`` for a time no run reached). A CI of zero
    width is said as such (``66.5 (all resamples equal)``), not drawn as ``[66.5, 66.5]``, and
    an estimate whose whole interval is infinite prints alone (``never``, not ``never [never,
    never]``).
    """
    def f(x: float) -> str:
        return inf if x == float("inf") else f"{x:.3g}"

    if f(low) == f(high) == f(estimate):
        return f(estimate) if estimate == float("inf") else f"{f(estimate)} ({ZERO_WIDTH})"
    if style == "sentence":
        return f"{f(estimate)} (95% CI {f(low)}-{f(high)})"
    return f"{f(estimate)} [{f(low)}, {f(high)}]"


def survival_sentence(a: str, b: str, q: dict[str, Any]) -> str:
    """One sentence of :func:`time_ratio`'s figures for ``a`` against ``b``."""

    def ratio(entry: dict[str, Any]) -> str:
        if entry["ratio"] is not None:
            return interval_text(entry["ratio"], *entry["ci95"], style="sentence")
        if "at_most" in entry:
            return f"at most {entry['at_most']:.3g} ({b}'s median is beyond its budget)"
        if "at_least" in entry:
            return f"at least {entry['at_least']:.3g} ({a}'s median is beyond its budget)"
        return "undefined (neither median is within the budget)"

    return (f"Kaplan-Meier median time to the bound, {a} / {b} = {ratio(q)} episodes (log-rank "
            f"p = {q['p_sooner']:.2g}), {ratio(q['steps'])} primitive steps; censored runs "
            f"{q['censored'][0]} and {q['censored'][1]}")
