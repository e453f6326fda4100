"""A group-sequential permutation test for "is learner A faster than learner B?".

Our own design in the spirit of AdaStop (Mathieu et al. 2023, the test rlberry ships): runs
arrive in ``K`` interims of ``n`` runs per learner; after each interim the test either decides
(the two learners' per-run scores differ) and stops, or asks for the next interim. It therefore
spends the fewest runs when the difference is large, and never more than ``n * K`` per learner.

**Null hypothesis.** The per-run scores of A and B (episodes to tolerance, area under the gap
curve, ...) are draws from the *same* distribution. Under it the ``2n`` scores of every
interim are exchangeable, so relabelling them by a permutation of the interim's pooled sample
gives an equally likely data set - the permutation group is the *product* of the per-interim
permutation groups (AdaStop's construction: earlier interims keep their permuted values when
new runs arrive, so the joint law of the statistics over interims is available).

**Statistic.** ``T_k = | sum_{j<=k} (sum of A's scores - sum of B's scores in interim j) |``,
the two-sided difference of means times ``n k``.

**Boundaries (alpha spending).** ``M`` joint permutations are drawn (the identity is the first,
as a Monte Carlo permutation test needs); ``alpha_k = alpha * f(k / K)`` with ``f(t) = t``
(``"linear"``, Pocock-like: spends early, stops early) or ``f(t) = t^2`` (``"quadratic"``,
O'Brien-Fleming-like: keeps power for the end). At interim ``k`` the boundary ``B_k`` is the
smallest value such that the permutations not rejected earlier and with ``T_k > B_k`` number at
most ``floor(alpha_k M)`` minus those rejected earlier; the observed data are rejected at ``k``
when ``T_k(identity) > B_k``. By construction at most ``floor(alpha M)`` of the ``M``
permuted data sets are ever rejected, so the family-wise false-positive rate is ``<= alpha``
up to the Monte Carlo error of the ``M`` draws (ties are broken against rejection, which only
makes the test more conservative). The rate is measured in the tests on identical learners.

There is no early *acceptance*: after ``K`` interims without a rejection the answer is "no
difference detected with n*K runs each", which is not a proof of equality.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

SPENDING = {"linear": lambda t: t, "quadratic": lambda t: t * t}


@dataclass(frozen=True)
class SequentialDecision:
    """The outcome of :func:`sequential_test`.

    Attributes:
        label_a, label_b: the two learners.
        decision: ``"a smaller"``, ``"b smaller"`` or ``"no difference detected"``.
        interim: the interim (1-based) at which the test stopped.
        runs_used: runs per learner consumed (``n * interim``).
        runs_available: ``n * K``.
        statistics: observed ``T_k`` per interim reached.
        boundaries: ``B_k`` per interim reached.
        alpha, n_per_interim, interims, n_permutations, spending: the design.
    """

    label_a: str
    label_b: str
    decision: str
    interim: int
    runs_used: int
    runs_available: int
    statistics: tuple[float, ...]
    boundaries: tuple[float, ...]
    alpha: float
    n_per_interim: int
    interims: int
    n_permutations: int
    spending: str

    @property
    def rejected(self) -> bool:
        return self.decision != "no difference detected"

    def sentence(self, what: str) -> str:
        design = (f"group-sequential permutation test, level {self.alpha:g}, {self.interims} "
                  f"interims of {self.n_per_interim} runs, {self.spending} spending")
        if self.rejected:
            who = self.label_a if self.decision == "a smaller" else self.label_b
            return (f"{what}: {who} is smaller - decided after {self.runs_used} of "
                    f"{self.runs_available} runs per learner ({design})")
        return (f"{what}: {self.label_a} vs {self.label_b} - no difference detected with "
                f"{self.runs_used} runs per learner ({design})")

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def _spent(alpha: float, interims: int, spending: str) -> np.ndarray:
    if spending not in SPENDING:
        raise ValueError(f"spending must be one of {sorted(SPENDING)}, not {spending!r}")
    f = SPENDING[spending]
    return np.array([alpha * f((k + 1) / interims) for k in range(interims)])


def permutation_statistics(batches_a: np.ndarray, batches_b: np.ndarray, n_permutations: int,
                           rng: np.random.Generator) -> np.ndarray:
    """``(K, M)`` signed cumulative differences ``sum_{j<=k}(sum A_j - sum B_j)`` under ``M``
    joint permutations (column 0 is the identity, i.e. the observed data).

    Args:
        batches_a, batches_b: ``(K, n)`` scores per interim.
        n_permutations: ``M``.
        rng: source of the permutations.
    """
    K, n = batches_a.shape
    pooled = np.concatenate([batches_a, batches_b], axis=1)  # (K, 2n)
    # a uniformly random permutation per interim and draw: argsort of uniforms
    perm = np.argsort(rng.random((K, n_permutations, 2 * n)), axis=2)
    perm[:, 0] = np.arange(2 * n)
    vals = np.take_along_axis(pooled[:, None, :], perm, axis=2)  # (K, M, 2n)
    diff = vals[:, :, :n].sum(axis=2) - vals[:, :, n:].sum(axis=2)
    return np.cumsum(diff, axis=0)


def boundaries_from(stats_abs: np.ndarray, spent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boundaries ``B_k`` and the rejection interim of every permutation (``K`` = never).

    Args:
        stats_abs: ``(K, M)`` ``|T_k|`` per permutation.
        spent: ``(K,)`` cumulative alpha.
    """
    K, M = stats_abs.shape
    budget = np.floor(spent * M + 1e-9).astype(np.int64)
    alive = np.ones(M, dtype=bool)
    rejected_at = np.full(M, K, dtype=np.int64)
    bounds = np.full(K, np.inf)
    for k in range(K):
        allowed = budget[k] - int((~alive).sum())
        t = stats_abs[k, alive]
        if allowed > 0 and t.size:
            # the smallest b with #{t > b} <= allowed: the (allowed+1)-th largest value
            order = np.sort(t)[::-1]
            b = order[allowed] if allowed < order.size else -np.inf
            bounds[k] = b
            newly = alive & (stats_abs[k] > b)
            rejected_at[newly] = k
            alive &= ~newly
    return bounds, rejected_at


def sequential_test(a: np.ndarray, b: np.ndarray, *, n_per_interim: int, interims: int,
                    alpha: float = 0.05, n_permutations: int = 2000,
                    spending: str = "linear", seed: int = 0, label_a: str = "a",
                    label_b: str = "b", resolution: float = 0.0) -> SequentialDecision:
    """Run the group-sequential permutation test on runs given in the order they were made.

    ``a`` and ``b`` hold at least ``n_per_interim * interims`` finite per-run scores each (runs
    are independent, so using the first ``n k`` runs is exactly what a test that launched them
    interim by interim would have seen). The test stops at the first rejection.
    ``resolution > 0`` rounds every score to a multiple of it first: differences below it are
    ties (a permutation test otherwise "detects" a consistent 1e-7 between two nearly constant
    learners); the same map on both sides, so the level is unaffected.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    need = n_per_interim * interims
    if n_per_interim < 1 or interims < 1:
        raise ValueError("n_per_interim and interims must be >= 1")
    if a.size < need or b.size < need:
        raise ValueError(f"need {need} runs per learner ({interims} interims x "
                         f"{n_per_interim}), got {a.size} and {b.size}")
    if not (np.isfinite(a[:need]).all() and np.isfinite(b[:need]).all()):
        raise ValueError("scores must be finite (set censored runs to the budget first)")
    if resolution > 0:
        a, b = np.round(a / resolution) * resolution, np.round(b / resolution) * resolution
    spent = _spent(alpha, interims, spending)
    rng = np.random.default_rng(seed)
    T = permutation_statistics(a[:need].reshape(interims, n_per_interim),
                               b[:need].reshape(interims, n_per_interim), n_permutations, rng)
    bounds, rejected_at = boundaries_from(np.abs(T), spent)
    k_stop = int(rejected_at[0])
    stop = min(k_stop, interims - 1)
    decision = ("no difference detected" if k_stop >= interims
                else "a smaller" if T[k_stop, 0] < 0 else "b smaller")
    return SequentialDecision(
        label_a, label_b, decision, stop + 1, n_per_interim * (stop + 1), need,
        tuple(float(x) for x in np.abs(T[: stop + 1, 0])),
        tuple(float(x) for x in bounds[: stop + 1]), alpha, n_per_interim, interims,
        n_permutations, spending)


def false_positive_rate(draw, *, trials: int, n_per_interim: int, interims: int,
                        alpha: float = 0.05, n_permutations: int = 500,
                        spending: str = "linear", seed: int = 0) -> tuple[float, float]:
    """Measured rejection rate of :func:`sequential_test` on identical learners.

    Args:
        draw: ``draw(rng, size) -> (size,)`` scores of one learner; both sides use it.
        trials: number of simulated comparisons.

    Returns:
        ``(rate, mean runs used per learner)``.
    """
    rng = np.random.default_rng(seed)
    need = n_per_interim * interims
    rejections, used = 0, 0
    for t in range(trials):
        d = sequential_test(draw(rng, need), draw(rng, need), n_per_interim=n_per_interim,
                            interims=interims, alpha=alpha, n_permutations=n_permutations,
                            spending=spending, seed=seed + 1 + t)
        rejections += d.rejected
        used += d.runs_used
    return rejections / trials, used / trials
