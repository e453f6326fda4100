"""The evaluation protocol of chapter 6: ceilings, the scoring of unreachable loops, rows."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from adpart.envs.domains.taxi import Taxi
from adpart.experiments.protocol import absorb_unreachable, layer_ceiling, score
from adpart.learning.curves import start_distribution, start_values
from adpart.learning.maxq import polled_policy, recursively_optimal, taxi_graph
from adpart.mdp.solvers import value_iteration
from adpart.partition import Partition
from tests.learning.conftest import slippery_grid


def test_absorbing_unreachable_configurations_keeps_values_and_fixes_loop_scores() -> None:
    raw = Taxi(fickle=True, gamma=1.0).mdp()
    mdp = absorb_unreachable(raw)
    assert int(mdp.terminal.sum() - raw.terminal.sum()) == 100
    live = ~mdp.terminal
    np.testing.assert_allclose(value_iteration(mdp, epsilon=1e-10).V[live],
                               value_iteration(raw, epsilon=1e-10).V[live], atol=1e-8)
    # a good policy that loops forever in one configuration no episode can enter
    g = taxi_graph().compile(raw)
    pol = polled_policy(g, recursively_optimal(raw, g), raw.admissible)
    S = raw.n_states
    absorbed = np.flatnonzero(mdp.terminal & ~raw.terminal)
    stay = [(s, a) for s in absorbed for a in range(raw.n_actions)
            if raw.P[[a * S + s]].toarray()[0, s] == 1.0]  # an illegal Putdown stays put
    s, a = stay[0]
    pol[s] = a
    mu = start_distribution(raw)
    # start_values evaluates such a policy on the states it reaches: the same as on the
    # absorbed model (before, the loop made the whole system singular and the score NaN)
    absorbed_value = start_values(mdp, pol[None], mu)[0]
    assert np.isfinite(absorbed_value)
    assert start_values(raw, pol[None], mu)[0] == pytest.approx(absorbed_value, abs=1e-9)
    assert absorb_unreachable(mdp) is mdp


def test_layer_ceiling_of_the_finest_layer_is_v_star_and_coarse_is_below() -> None:
    mdp = slippery_grid(4)
    smdp = mdp.as_smdp()
    mu = start_distribution(mdp)
    v_star = float(mu @ value_iteration(mdp, epsilon=1e-12).V)
    finest = Partition(np.arange(mdp.n_states), np.ones((mdp.n_states, 4), dtype=bool))
    assert layer_ceiling(finest, smdp, mu) == pytest.approx(v_star, abs=1e-8)
    # two blocks (top half / bottom half): one action per block, so no better than V*
    coarse = Partition(np.repeat([0, 1], 8), np.ones((2, 4), dtype=bool))
    assert layer_ceiling(coarse, smdp, mu) < v_star - 1e-6


def test_score_own_ceiling_and_cannot_reach() -> None:
    gaps = np.full((3, 6), np.nan)
    ev = np.array([2, 4, 6])
    gaps[:, ev - 1] = [[9.0, 6.4, 6.2], [8.0, 7.0, 6.1], [6.3, 6.2, 6.1]]
    steps = np.full((3, 6), 10)
    row = score("layer", gaps, steps, ev, tol=0.5, ceiling_gap=6.0, cap=50.0,
                ceiling_name="point model", step_size="alpha", seed=0)
    assert not row["can_reach_v_star"] and row["v_star"]["reached"] == 0
    assert row["own"]["episodes"] == [4.0, 6.0, 2.0]
    assert row["own"]["steps"] == [40.0, 60.0, 20.0]
    assert row["auc"]["per_run"][2] == pytest.approx(np.trapezoid([6.3, 6.2, 6.1], ev) / 4)


def test_options_only_optimum_with_primitives_as_options_is_v_star() -> None:
    from adpart.experiments.protocol import options_only_optimum
    from adpart.mdp.model import SMDPModel

    mdp = slippery_grid(4)
    one = mdp.as_smdp()
    # the primitives stacked twice: columns 4-7 are "options" identical to the actions
    F = sp.vstack([one.F, one.F], format="csr")
    two = SMDPModel(R=np.hstack([one.R, one.R]), F=F,
                    admissible=np.hstack([one.admissible, one.admissible]))
    mu = start_distribution(mdp)
    v_star = float(mu @ value_iteration(mdp, epsilon=1e-12).V)
    assert options_only_optimum(two, 4, mu) == pytest.approx(v_star, abs=1e-8)


def test_option_chain_reach_on_a_corridor() -> None:
    """Options 0->2 and 2->4 chain to the goal; without the second the goal is never reached."""
    from adpart.experiments.protocol import option_chain_reach
    from adpart.mdp.model import SMDPModel

    S = 6  # corridor 0..5, 5 terminal; primitives: one "stay" action
    prim = sp.csr_array(np.eye(S) * 0.9)
    hop1 = sp.csr_array(([0.8, 0.8], ([0, 1], [2, 2])), shape=(S, S))
    hop2 = sp.csr_array(([0.8, 0.8, 0.8], ([2, 3, 4], [5, 5, 5])), shape=(S, S))
    adm = np.zeros((S, 3), dtype=bool)
    adm[:5, 0] = True
    adm[[0, 1], 1] = True
    adm[[2, 3, 4], 2] = True
    model = SMDPModel(R=-np.ones((S, 3)), F=sp.vstack([prim, hop1, hop2], format="csr"),
                      admissible=adm)
    mu = np.r_[1.0, np.zeros(S - 1)]
    terminal = np.r_[np.zeros(S - 1, dtype=bool), True]
    assert option_chain_reach(model, 1, mu, terminal) == (3, True)
    adm[:, 2] = False
    cut = SMDPModel(R=-np.ones((S, 3)), F=model.F, admissible=adm)
    assert option_chain_reach(cut, 1, mu, terminal) == (2, False)
