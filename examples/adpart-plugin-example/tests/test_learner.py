"""sarsa: the conformance check, and its values against hand-computed ones on tiny chains."""

from __future__ import annotations

import numpy as np
import pytest
from adpart.learning import LearnResult
from adpart.learning.curves import start_distribution
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.model import FiniteMDP
from adpart.testing import check_learner

from adpart_plugin_example import SarsaLearner, ThreeRoomsLine, sarsa


def chain(n: int = 4, gamma: float = 0.9) -> FiniteMDP:
    """States 0 -> 1 -> ... -> n-1 (terminal) by the only action, reward -1; start in 0."""
    P = np.zeros((n, 1, n))
    P[np.arange(n - 1), 0, np.arange(1, n)] = 1.0
    P[n - 1, 0, n - 1] = 1.0
    R = np.full((n, 1), -1.0)
    R[n - 1] = 0.0
    initial = np.eye(n)[0]
    return FiniteMDP.from_dense(P, R, gamma, terminal=np.arange(n) == n - 1, initial=initial)


def test_passes_adparts_learner_check():
    check_learner(SarsaLearner)  # on adpart's two-rooms
    check_learner(SarsaLearner, ThreeRoomsLine().mdp(), runs=3, episodes=4)


@pytest.mark.parametrize("episodes", [1, 2, 3, 5])
def test_alpha_one_epsilon_zero_on_a_chain_gives_the_known_q(episodes):
    # With alpha = 1 each update copies r + gamma Q(s', a') with the *old* Q(s', a') (s' is
    # updated later in the episode), so after n episodes the state d steps from the end holds
    # -(1 + g + ... + g^(min(d, n) - 1)): the values creep back one state per episode.
    mdp = chain(4, 0.9)
    res = sarsa(mdp, runs=2, episodes=episodes, seed=3, alpha="1", epsilon="0", eval_every=1)
    for d, s in ((3, 0), (2, 1), (1, 2)):
        k = min(d, episodes)
        expected = -sum(0.9**i for i in range(k))
        np.testing.assert_allclose(res.Q[:, s, 0], expected, rtol=0, atol=1e-12)
    assert res.Q[:, 3, 0].tolist() == [0.0, 0.0]  # the terminal state is never updated
    assert res.curve.matrix("steps").tolist() == [[3] * episodes] * 2
    np.testing.assert_allclose(res.curve.matrix("return"), -3.0)
    np.testing.assert_allclose(res.curve.matrix("discounted_return"), -(1 + 0.9 + 0.81))


def test_the_target_is_the_next_action_taken_not_the_best():
    # State 0 has one action to state 1 (-1); state 1 has two actions to the end, -1 and -5.
    # Acting uniformly at random (epsilon = 1) with sample-mean steps (alpha = 1/n), SARSA's
    # Q(0) tends to -1 + gamma * (-1 - 5) / 2 = -3.7 (the random policy's value), where
    # Q-learning's would be -1 + gamma * (-1) = -1.9.
    P = np.zeros((3, 2, 3))
    P[0, :, 1] = 1.0
    P[1, :, 2] = 1.0
    P[2, :, 2] = 1.0
    R = np.array([[-1.0, -1.0], [-1.0, -5.0], [0.0, 0.0]])
    admissible = np.array([[True, False], [True, True], [True, True]])
    mdp = FiniteMDP.from_dense(P, R, 0.9, terminal=[False, False, True], initial=[1.0, 0, 0],
                               admissible=admissible)
    res = sarsa(mdp, runs=3, episodes=4000, seed=0, alpha="1/n", epsilon="1", eval_every=4000)
    np.testing.assert_allclose(res.Q[:, 1], [[-1.0, -5.0]] * 3)
    np.testing.assert_allclose(res.Q[:, 0, 0], -3.7, atol=0.15)
    assert np.all(res.Q[:, 0, 1] == -np.inf)  # inadmissible


def test_stochastic_moves_are_sampled_with_their_probabilities():
    # One action: w.p. 0.5 to the end, else back to 0; reward -1. Q(0) = -1 / (1 - 0.5 gamma).
    P = np.array([[[0.5, 0.5]], [[0.0, 1.0]]])
    R = np.array([[-1.0], [0.0]])
    mdp = FiniteMDP.from_dense(P, R, 0.9, terminal=[False, True], initial=[1.0, 0.0])
    res = sarsa(mdp, runs=2, episodes=3000, seed=1, alpha="1/n", epsilon="0", eval_every=3000)
    np.testing.assert_allclose(res.Q[:, 0, 0], -1 / (1 - 0.45), atol=0.05)
    assert res.curve.matrix("steps").mean() == pytest.approx(2.0, abs=0.1)  # geometric, p = 1/2


def test_learns_three_rooms_line_and_scores_like_the_builtins():
    mdp = ThreeRoomsLine().mdp("reach-east")
    res = sarsa(mdp, runs=4, episodes=200, seed=0, alpha="0.5", epsilon="exp:0.3,0.97",
                eval_every=25)
    assert isinstance(res, LearnResult) and res.Q.shape == (4, 77, 4)
    gaps = res.curve.matrix("value_gap")
    evaluated = np.zeros(200, dtype=bool)
    evaluated[24::25] = True
    assert np.isnan(gaps[:, ~evaluated]).all() and np.isfinite(gaps[:, evaluated]).all()
    assert np.all(gaps[:, -1] < 1e-9)  # every run ends with an optimal greedy policy
    # the scored value is the exact value of the greedy policy at the start distribution
    mu = start_distribution(mdp)
    for k, pi in enumerate(res.greedy_policies()):
        value = float(mu @ policy_evaluation(mdp, pi))
        assert res.curve.matrix("eval_value")[k, -1] == pytest.approx(value, abs=1e-9)


def test_a_run_depends_on_its_seed_and_index_only():
    mdp = ThreeRoomsLine().mdp()
    two = sarsa(mdp, runs=2, episodes=20, seed=5, eval_every=5)
    three = sarsa(mdp, runs=3, episodes=20, seed=5, eval_every=10)
    np.testing.assert_array_equal(two.Q, three.Q[:2])
    np.testing.assert_array_equal(two.curve.matrix("steps"), three.curve.matrix("steps")[:2])
    other = sarsa(mdp, runs=2, episodes=20, seed=6, eval_every=5)
    assert not np.array_equal(two.curve.matrix("steps"), other.curve.matrix("steps"))


def test_bad_settings_are_refused():
    from adpart.errors import AdpartError

    mdp = chain()
    with pytest.raises(AdpartError, match="alpha schedule reaches 2"):
        sarsa(mdp, runs=1, episodes=1, alpha="2")
    with pytest.raises(AdpartError, match="episodes = 0"):
        sarsa(mdp, runs=1, episodes=0)
