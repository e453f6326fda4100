"""SMDP Q-learning over options: reduction to flat Q, four-rooms hallway options, kernels agree."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.envs.registry import get_domain
from adpart.errors import ModelError, TaskError
from adpart.learning import q_learning
from adpart.learning.curves import start_distribution, start_values
from adpart.learning.settings import Run
from adpart.learning.smdp_q import compile_options, option_set
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.solvers import solve
from adpart.options import Option, hallway_options, primitive_options
from tests.learning.conftest import corridor, slippery_grid
from tests.learning.hierarchical_run import smdp_q_run


@pytest.mark.parametrize("make", [corridor, slippery_grid])
def test_primitive_options_reproduce_flat_q_learning_bit_for_bit(make):
    mdp = make()
    flat = q_learning(mdp, Run(runs=3, episodes=25, seed=11, eval_every=5))
    smdp = smdp_q_run(mdp, primitive_options(mdp), runs=3, episodes=25, seed=11, eval_every=5)
    np.testing.assert_array_equal(smdp.Q, flat.Q)
    for col in ("steps", "return", "discounted_return"):
        np.testing.assert_array_equal(smdp.curve[col], flat.curve[col])
    np.testing.assert_array_equal(smdp.curve["decisions"], smdp.curve["steps"])
    np.testing.assert_allclose(smdp.curve["value_gap"], flat.curve["value_gap"], atol=1e-12)


def test_python_and_numba_kernels_agree_with_options():
    mdp = get_domain("four-rooms").mdp("G1")
    opts = hallway_options(mdp)
    a = smdp_q_run(mdp, opts, include_primitives=True, runs=2, episodes=15, seed=4,
                        eval_every=5, kernel="python")
    b = smdp_q_run(mdp, opts, include_primitives=True, runs=2, episodes=15, seed=4,
                        eval_every=5, kernel="numba")
    np.testing.assert_array_equal(a.Q, b.Q)
    np.testing.assert_array_equal(a.curve["decisions"], b.curve["decisions"])
    assert (a.curve["decisions"] <= a.curve["steps"]).all()
    assert (a.curve["decisions"] < a.curve["steps"]).any()  # options take several steps


def test_stochastic_option_policy_is_sampled_like_its_probabilities():
    mdp = corridor()
    probs = np.tile([0.25, 0.75], (mdp.n_states, 1))
    opt = Option("drift", np.ones(mdp.n_states, bool), probs, np.ones(mdp.n_states))
    pol_act, pol_cdf, _ = compile_options([opt], mdp.n_actions)
    assert (pol_act <= -2).all() and np.allclose(pol_cdf[:, 0], 0.25)
    assert (pol_cdf[:, 1] == 2.0).all()
    res = smdp_q_run(mdp, [opt], runs=2, episodes=5, seed=1, eval_every=5)
    assert np.isfinite(res.curve["value_gap"][-1])


def test_exact_optimum_over_hallway_options_plus_primitives_is_v_star():
    mdp = get_domain("four-rooms").mdp("G1")
    _, model = option_set(mdp, hallway_options(mdp), include_primitives=True)
    mu = start_distribution(mdp)
    v_star = mu @ policy_evaluation(mdp, solve(mdp, 1e-12).policy)
    assert start_values(model, solve(model, 1e-12).policy[None], mu)[0] == pytest.approx(v_star)


def test_options_converge_faster_in_decisions_than_flat_q():
    """Four-rooms G1 (goal = a hallway): decisions until the gap stays <= 0.12 (10 runs)."""
    mdp = get_domain("four-rooms").mdp("G1")
    opts = hallway_options(mdp)
    flat = q_learning(mdp, Run(runs=10, episodes=1000, seed=1, eval_every=10))
    over = smdp_q_run(mdp, opts, runs=10, episodes=1000, seed=1, eval_every=10)

    def decisions_to(result, gap):
        ep = result.curve.episodes_to_gap(gap)
        assert (ep > 0).all()
        cum = np.cumsum(result.curve.matrix("decisions"), axis=1)
        return cum[np.arange(ep.size), ep - 1]

    assert np.median(decisions_to(over, 0.12)) < 0.5 * np.median(decisions_to(flat, 0.12))


@pytest.mark.slow
def test_hallway_options_plus_primitives_reach_the_optimal_value():
    mdp = get_domain("four-rooms").mdp("G1")
    res = smdp_q_run(mdp, hallway_options(mdp), include_primitives=True, runs=3,
                          episodes=20_000, seed=2, eval_every=1000)
    assert res.curve.matrix("value_gap")[:, -1].max() < 0.01


def test_bad_inputs_raise_adpart_errors():
    mdp = corridor()
    with pytest.raises(ModelError, match="no options"):
        smdp_q_run(mdp, [])
    with pytest.raises(TaskError, match="kernel"):
        smdp_q_run(mdp, primitive_options(mdp), kernel="cuda")
    with pytest.raises(ModelError, match="Option objects"):
        smdp_q_run(mdp, ["left"])
