"""The learner's sampled successors follow P: visit counts of a one-step fan-out against P.

From the start state the only action leads to states 1, 2, 3 with probabilities 0.2, 0.3, 0.5;
each of those has one action into the terminal state 4. Every episode therefore visits exactly
one of 1, 2, 3, and the learner's visit counts there are the successor counts of (0, a). A
chi-square test against P (2 degrees of freedom) must not reject at the 0.1% level, for both
kernels, and the kernels must agree bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from adpart.learning import q_learning
from adpart.learning.settings import Run
from adpart.mdp.model import FiniteMDP

PROBS = np.array([0.2, 0.3, 0.5])


def fan_out() -> FiniteMDP:
    P = np.zeros((5, 1, 5))
    P[0, 0, 1:4] = PROBS
    P[1:4, 0, 4] = 1.0
    P[4, 0, 4] = 1.0
    terminal = np.array([False, False, False, False, True])
    initial = np.array([1.0, 0, 0, 0, 0])
    return FiniteMDP.from_dense(P, -np.ones((5, 1)), 0.9, terminal=terminal, initial=initial)


@pytest.mark.parametrize("kernel", ["python", "numba"])
def test_successor_counts_follow_the_transition_probabilities(kernel):
    runs, episodes = 4, 2000
    res = q_learning(fan_out(), Run(runs=runs, episodes=episodes, seed=11, eval_every=episodes,
                                    kernel=kernel))
    counts = res.visits.sum(axis=0)[1:4, 0]
    assert counts.sum() == runs * episodes  # one of the three per episode
    limit = stats.chi2.ppf(0.999, df=2)

    def chi2(probs: np.ndarray) -> float:
        expected = runs * episodes * probs
        return float(((counts - expected) ** 2 / expected).sum())

    assert chi2(PROBS) < limit, counts
    assert chi2(PROBS[[1, 0, 2]]) > limit  # the test can tell 0.2/0.3 from 0.3/0.2


def test_both_kernels_draw_the_same_successors():
    a, b = (q_learning(fan_out(), Run(runs=3, episodes=500, seed=2, eval_every=500,
                                      kernel=k)).visits
            for k in ("python", "numba"))
    assert np.array_equal(a, b)
