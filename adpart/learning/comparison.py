"""A method against its baseline over runs: the ratio of median episodes with a bootstrap CI.

The claims of the pipeline and of the experiments ("the layer learns in a third of flat's
episodes") compare per-run episodes to the success bound of two learners run in the same
process; a run that never gets there counts as censored (the budget plus one, or ``inf``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["ratio_of_medians_ci"]


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
