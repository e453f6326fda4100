"""Directed exploration by R-max and the grounded model values (``adpart.learning._rmax``).

The oracles are independent value iterations, in numpy, of the models the counts define: R-max's
optimistic model (an unknown pair worth the ceiling, a known one its first ``m`` samples) and the
grounded one (an untried pair worth the floor, a tried one all its samples).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.errors import TaskError
from adpart.learning._rmax import (
    counted_smdp,
    predecessors,
    rmax_observe,
    sweep,
    value_ceiling,
)
from adpart.learning.hierarchical import flat_lower_bound
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.mdp.solvers import q_from_v, solve
from adpart.partition.bpsmdp import point_model

from .hierarchical_run import hierarchical_run
from .test_hierarchical import DELTA, SETTINGS, final_gap, goal_grid, setup  # noqa: F401

TOL = 1e-11


def optimal_q(mdp: FiniteMDP) -> np.ndarray:
    """``Q*`` of ``mdp`` from value iteration's ``V*``."""
    V = solve(mdp, 1e-12).V
    return mdp.R + mdp.gamma * (mdp.P @ np.where(mdp.terminal, 0.0, V)).reshape(
        mdp.n_actions, mdp.n_states).T


def random_mdp(seed: int, S: int = 7, A: int = 3, *, deterministic: bool = False) -> FiniteMDP:
    rng = np.random.default_rng(seed)
    P = np.zeros((S, A, S))
    for s in range(S):
        for a in range(A):
            if deterministic:
                P[s, a, rng.integers(S)] = 1.0
            else:
                support = rng.choice(S, size=rng.integers(1, 4), replace=False)
                P[s, a, support] = rng.dirichlet(np.ones(support.size))
    R = rng.uniform(-1.0, 0.0, size=(S, A))
    terminal = np.zeros(S, dtype=bool)
    terminal[S - 1] = True
    R[:, 0] = np.where(P[:, 0, S - 1] > 0, 1.0, R[:, 0])
    return FiniteMDP.from_dense(P, R, 0.9, terminal=terminal)


def empirical_values(mdp: FiniteMDP, counts: np.ndarray, n: np.ndarray, unknown: np.ndarray,
                     unknown_value: float) -> np.ndarray:
    """Q of the model ``counts / n`` (per CSR entry), ``unknown`` pairs at ``unknown_value``."""
    _, indptr, indices = mdp.sampler_arrays
    S, A = mdp.n_states, mdp.n_actions
    rows = np.repeat(np.arange(S * A), np.diff(indptr))
    P = np.zeros((S * A, S))
    np.add.at(P, (rows, indices), counts)
    P /= np.maximum(n.T.reshape(-1), 1)[:, None]
    P = P.reshape(A, S, S).transpose(1, 0, 2)
    V = np.zeros(S)
    for _ in range(5000):
        Q = np.where(unknown, unknown_value, mdp.R + mdp.gamma * P @ np.where(mdp.terminal, 0, V))
        Q = np.where(mdp.admissible, Q, -np.inf)
        V_new = np.where(mdp.terminal, 0.0, Q.max(axis=1))
        if np.max(np.abs(V_new - V)) < 1e-13:
            break
        V = V_new
    return Q


def observe(mdp: FiniteMDP, m: int, steps: int, seed: int) -> dict[str, np.ndarray]:
    """Feed ``steps`` sampled transitions of random non-terminal pairs to both planners."""
    rng = np.random.default_rng(seed)
    _, indptr, indices = mdp.sampler_arrays
    S, A = mdp.n_states, mdp.n_actions
    ptr, idx = predecessors(mdp)
    v_max, floor = value_ceiling(mdp, 100), flat_lower_bound(mdp, 100)
    a_ = {"nf": np.zeros((1, S, A), np.int64), "xc": np.zeros((1, indices.size), np.int64),
          "xm": np.zeros((1, indices.size), np.int64),
          "Qx": np.where(mdp.admissible, v_max, -np.inf)[None].copy(),
          "Vx": np.where(mdp.terminal, 0.0, v_max)[None].copy(),
          "Ql": np.where(mdp.admissible, floor, -np.inf)[None].copy(),
          "Vl": np.where(mdp.terminal, 0.0, floor)[None].copy()}
    queue, inq = np.zeros((1, S), np.int64), np.zeros((1, S), bool)
    adm = np.ascontiguousarray(mdp.admissible)
    R = np.ascontiguousarray(mdp.R)
    live = np.flatnonzero(~mdp.terminal)
    for _ in range(steps):
        s, a = int(rng.choice(live)), int(rng.integers(A))
        s2 = int(mdp.sample_next(np.array([s]), np.array([a]), rng)[0])
        a_["nf"][0, s, a] += 1
        rmax_observe(0, s, a, s2, m, v_max, TOL, mdp.gamma, R, mdp.terminal, indptr, indices,
                     adm, a_["nf"], a_["xc"], a_["xm"], a_["Qx"], a_["Vx"], ptr, idx, queue, inq)
        sweep(0, s, 1, floor, False, TOL, mdp.gamma, R, mdp.terminal, indptr, indices, adm,
              a_["nf"], a_["xc"], a_["Ql"], a_["Vl"], ptr, idx, queue, inq)
    return {**a_, "v_max": v_max, "floor": floor}


@given(seed=st.integers(0, 2**16), deterministic=st.booleans())
@settings(max_examples=20, deadline=None)
def test_predecessors_are_the_support_read_backwards(seed, deterministic):
    mdp = random_mdp(seed, deterministic=deterministic)
    ptr, idx = predecessors(mdp)
    P = mdp.P.toarray().reshape(mdp.n_actions, mdp.n_states, mdp.n_states)
    for y in range(mdp.n_states):
        assert idx[ptr[y]:ptr[y + 1]].tolist() == np.flatnonzero(P[:, :, y].any(axis=0)).tolist()


@given(seed=st.integers(0, 2**16), m=st.integers(1, 4), steps=st.integers(0, 150))
@settings(max_examples=25, deadline=None)
def test_the_incremental_plans_are_the_optima_of_the_models_the_counts_define(seed, m, steps):
    mdp = random_mdp(seed)
    got = observe(mdp, m, steps, seed + 1)
    n = got["nf"][0]
    live = ~mdp.terminal[:, None] & mdp.admissible
    optimistic = empirical_values(mdp, got["xm"][0], np.minimum(n, m), n < m, got["v_max"])
    grounded = empirical_values(mdp, got["xc"][0], n, n == 0, got["floor"])
    np.testing.assert_allclose(got["Qx"][0][live], optimistic[live], atol=1e-8)
    np.testing.assert_allclose(got["Ql"][0][live], grounded[live], atol=1e-8)
    assert (got["xm"][0].sum() == np.minimum(n, m).sum()) and got["xc"][0].sum() == steps


@given(seed=st.integers(0, 2**16), steps=st.integers(0, 200))
@settings(max_examples=25, deadline=None)
def test_on_a_deterministic_mdp_the_grounded_values_never_exceed_q_star(seed, steps):
    mdp = random_mdp(seed, deterministic=True)
    got = observe(mdp, 1, steps, seed + 1)
    Q_star = optimal_q(mdp)
    live = ~mdp.terminal[:, None] & mdp.admissible
    assert (got["Ql"][0][live] <= Q_star[live] + 1e-9).all()


def test_with_directed_exploration_refinement_reaches_the_goal_and_kernels_agree(setup):  # noqa: F811
    mdp, opts, part, smdp = setup
    kw = dict(SETTINGS, episodes=300, explore="r-max")
    on = hierarchical_run(mdp, opts, part, **kw)
    off = hierarchical_run(mdp, opts, part, threshold=np.inf, **kw)
    np.testing.assert_allclose(final_gap(off), off.v_star_start)  # still never arrives
    assert (on.n_refinements > 0).all()
    assert (final_gap(on) <= 0.05 * on.v_star_start).all()
    assert on.parameters["exploration"] == "r-max" and on.parameters["known_after"] == 1
    # every pair tried in 300 episodes of R-max: the grounded values are the task's Q*
    Q_star = optimal_q(mdp)
    live = ~mdp.terminal
    for run in on.Q_grounded:
        np.testing.assert_allclose(run[live], Q_star[live], atol=1e-6)
    assert off.Q_grounded is None  # no test, no grounded values
    # planned on the grounded model, the refined layer's greedy policy is its exact optimum
    plan = hierarchical_run(mdp, opts, part, layer_values="planned", **kw)
    assert plan.parameters["layer_values"] == "planned"
    for k, layer in enumerate(plan.partitions):
        exact = point_model(layer, smdp)
        best = q_from_v(exact, solve(exact, 1e-10).V)[layer.labels]
        np.testing.assert_allclose(plan.Q[k], best, atol=1e-6)
    assert (final_gap(plan) <= 0.05 * plan.v_star_start).all()
    # exploration is R-max's: the layer starts at the lower bound, not at optimistic zeros
    costly = mdp.with_rewards(mdp.R - 0.1)  # a step costs 0.1: the bound is -0.1 / (1 - 0.9)
    quick = dict(SETTINGS, episodes=1, runs=1)
    assert hierarchical_run(costly, opts, part, explore="r-max", **quick
                                 ).parameters["q_init"] == pytest.approx(-0.1 / (1 - 0.9))
    assert hierarchical_run(costly, opts, part, **quick).parameters["q_init"] == 0.0
    assert hierarchical_run(costly, opts, part, explore="r-max", q_init=-3.0, **quick
                                 ).parameters["q_init"] == -3.0
    small = dict(kw, runs=2, episodes=60, eval_every=20)
    a = hierarchical_run(mdp, opts, part, kernel="numba", **small)
    b = hierarchical_run(mdp, opts, part, kernel="python", **small)
    np.testing.assert_array_equal(a.Q, b.Q)
    np.testing.assert_array_equal(a.Q_flat, b.Q_flat)
    assert a.refinements == b.refinements


@pytest.mark.parametrize("bad", [0, -1, 1.5, True])
def test_a_bad_known_count_is_refused(setup, bad):  # noqa: F811
    mdp, opts, part, _ = setup
    with pytest.raises(TaskError, match="known_after"):
        hierarchical_run(mdp, opts, part, explore="r-max", known_after=bad, **SETTINGS)


def test_a_bad_exploration_rule_is_refused_naming_the_rules(setup):  # noqa: F811
    mdp, opts, part, _ = setup
    with pytest.raises(TaskError, match="optimistic-flat"):
        hierarchical_run(mdp, opts, part, explore="ucb", **SETTINGS)


def test_each_exploration_rule_is_recorded_and_without_epsilon_only_r_max_finds_the_goal(
        setup):  # noqa: F811
    """The three rules are one setting and the run records the one in force. Without epsilon
    (the options go to the corners, the goal is the centre and pays 1, every other step 0):
    the block's columns never leave the options' routes, the optimistic flat table (zeros) is no
    more optimistic than a step that pays 0, and R-max's unknown pairs draw the agent to the
    goal - every run ends on V* (measured: gaps 0.86, 0.86, 0)."""
    mdp, opts, part, _ = setup
    kw = dict(SETTINGS, episodes=300, epsilon=0.0)
    got = {rule: hierarchical_run(mdp, opts, part, explore=rule, **kw)
           for rule in ("optimistic-flat", "r-max", "columns")}
    assert {rule: r.parameters["exploration"] for rule, r in got.items()} == {
        rule: rule for rule in got}
    for rule in ("optimistic-flat", "columns"):
        np.testing.assert_allclose(final_gap(got[rule]), got[rule].v_star_start)
    np.testing.assert_allclose(final_gap(got["r-max"]), 0.0, atol=1e-9)
    other = hierarchical_run(mdp, opts, part, explore="r-max", mode="action-refinement",
                             **dict(kw, episodes=2))
    assert other.parameters["exploration"] == "columns"  # the other modes explore by columns


@given(st.integers(0, 500), st.booleans())
@settings(max_examples=20, deadline=None)
def test_the_counted_layer_model_is_the_task_model_where_counts_are_its_probabilities(seed, gap):
    """Counts proportional to ``P`` give the task's primitive columns; an untried pair is worth
    the floor with no successor; the option columns are the given ones."""
    mdp = random_mdp(seed, S=6, A=2)
    smdp = mdp.as_smdp()
    S, A = mdp.n_states, mdp.n_actions
    option_R = np.random.default_rng(seed).random((S, 1))
    stacked = SMDPModel(R=np.hstack([smdp.R, option_R]),
                        F=sp.csr_array(sp.vstack([smdp.F, 0.5 * sp.eye_array(S)], format="csr")),
                        admissible=np.hstack([mdp.admissible, np.ones((S, 1), bool)]))
    untried = np.zeros(A * S, bool)
    untried[1] = gap  # pair (s=1, a=0) never tried
    row = np.repeat(np.arange(A * S), np.diff(mdp.P.indptr))
    xc = np.where(untried[row], 0, np.round(mdp.P.data * 1e9)).astype(np.int64)
    got = counted_smdp(stacked, mdp, xc, floor=-7.0)
    tried = ~untried & np.tile(~mdp.terminal, A)
    np.testing.assert_allclose(got.F.toarray()[:A * S][tried], smdp.F.toarray()[tried],
                               atol=1e-8)
    assert not got.F.toarray()[:A * S][untried].any()
    R_want = np.where(untried.reshape(A, S).T, -7.0, smdp.R)
    np.testing.assert_allclose(got.R[:, :A], np.where(mdp.terminal[:, None], 0.0, R_want))
    np.testing.assert_array_equal(got.R[:, A:], option_R)
    assert abs(got.F[A * S:] - stacked.F[A * S:]).max() == 0


def test_planned_layer_values_need_directed_exploration(setup):  # noqa: F811
    mdp, opts, part, _ = setup
    with pytest.raises(TaskError, match="explore = r-max"):
        hierarchical_run(mdp, opts, part, layer_values="planned", **SETTINGS)
    with pytest.raises(TaskError, match="layer_values"):
        hierarchical_run(mdp, opts, part, layer_values="guessed", explore="r-max",
                              **SETTINGS)
