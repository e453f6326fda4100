"""The group-sequential permutation test: its false-positive rate on identical learners (at or
below its stated level), its power on different ones, and the runs it needs."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.experiments.sequential import (
    boundaries_from,
    false_positive_rate,
    sequential_test,
)
from adpart.experiments.stats import gap_auc
from adpart.learning.qlearning import q_learning
from adpart.learning.settings import Run
from tests.learning.conftest import slippery_grid

ALPHA = 0.05


def _slack(trials: int) -> float:
    """Two binomial standard errors of a rate equal to ALPHA over ``trials`` comparisons."""
    return 2 * np.sqrt(ALPHA * (1 - ALPHA) / trials)


@pytest.mark.parametrize(("name", "draw"), [
    ("normal", lambda r, n: r.normal(0.0, 1.0, n)),
    ("censored", lambda r, n: np.minimum(r.exponential(100.0, n), 150.0)),  # budget-capped
])
def test_false_positive_rate_on_identical_distributions(name, draw) -> None:
    trials = 500
    fpr, used = false_positive_rate(draw, trials=trials, n_per_interim=5, interims=4,
                                    alpha=ALPHA, n_permutations=300, seed=3)
    assert fpr <= ALPHA + _slack(trials), (name, fpr)
    assert used > 0.9 * 20  # under H0 it rarely stops early


def test_a_clear_difference_is_decided_early_and_signed() -> None:
    rng = np.random.default_rng(0)
    decided = [sequential_test(rng.normal(0, 1, 20), rng.normal(3, 1, 20), n_per_interim=5,
                               interims=4, seed=s) for s in range(20)]
    assert all(d.decision == "a smaller" for d in decided)
    assert np.mean([d.runs_used for d in decided]) <= 10  # stops by the second interim
    swapped = sequential_test(rng.normal(3, 1, 20), rng.normal(0, 1, 20), n_per_interim=5,
                              interims=4, label_a="slow", label_b="fast")
    assert swapped.decision == "b smaller" and "fast is smaller" in swapped.sentence("steps")


def test_boundaries_spend_no_more_than_alpha() -> None:
    # oracle: count the permutations each boundary rejects directly
    rng = np.random.default_rng(1)
    stats_abs = np.abs(np.cumsum(rng.normal(size=(4, 1000)), axis=0))
    spent = ALPHA * np.arange(1, 5) / 4
    bounds, at = boundaries_from(stats_abs, spent)
    for k in range(4):
        assert (at <= k).sum() <= np.floor(spent[k] * 1000 + 1e-9)
        # a permutation still alive at k is rejected at k exactly when it exceeds B_k
        alive = at >= k
        assert np.array_equal(at[alive] == k, stats_abs[k, alive] > bounds[k])
    assert (at < 4).sum() >= 45  # and it spends (nearly) all of it


def test_identical_real_learners_with_different_seeds() -> None:
    """Flat Q on one slippery grid: 120 runs of one learner, split into 60 disjoint-at-a-time
    resampled pairs; and one pair launched with two different seeds."""
    mdp = slippery_grid(4)
    res = q_learning(mdp, Run(runs=120, episodes=40, seed=11, alpha="0.5", epsilon="0.2",
                              eval_every=4))
    ev = res.curve.evaluated_episodes()
    auc = gap_auc(res.curve.matrix("value_gap")[:, ev - 1], ev, cap=20.0)
    rng = np.random.default_rng(5)
    trials = 60
    rejections = 0
    for t in range(trials):
        idx = rng.permutation(auc.size)[:40]
        rejections += sequential_test(auc[idx[:20]], auc[idx[20:]], n_per_interim=5,
                                      interims=4, n_permutations=300, seed=t).rejected
    assert rejections / trials <= ALPHA + _slack(trials)
    other = q_learning(mdp, Run(runs=20, episodes=40, seed=12, alpha="0.5", epsilon="0.2",
                                eval_every=4))
    auc2 = gap_auc(other.curve.matrix("value_gap")[:, ev - 1], ev, cap=20.0)
    d = sequential_test(auc[:20], auc2, n_per_interim=5, interims=4)
    assert not d.rejected and d.runs_used == 20


def test_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="need 20 runs"):
        sequential_test(np.zeros(10), np.zeros(20), n_per_interim=5, interims=4)
    with pytest.raises(ValueError, match="finite"):
        sequential_test(np.r_[np.inf, np.zeros(19)], np.zeros(20), n_per_interim=5, interims=4)
    with pytest.raises(ValueError, match="spending"):
        sequential_test(np.zeros(20), np.zeros(20), n_per_interim=5, interims=4, spending="x")


def test_resolution_turns_negligible_differences_into_ties() -> None:
    a = np.full(10, 30.9223) - np.linspace(0, 1e-7, 10)
    b = np.full(10, 30.9223)
    assert sequential_test(a, b, n_per_interim=5, interims=2).rejected  # consistent, 1e-7
    assert not sequential_test(a, b, n_per_interim=5, interims=2, resolution=1e-3).rejected
