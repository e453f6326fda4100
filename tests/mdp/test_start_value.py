"""The start-value solver against one sparse LU per policy on every state (the exact solver).

Each path of :class:`adpart.mdp.start_value.StartValueSolver` is checked: the push from cold
and warm starts (the residual carried over when every state is a start), the search for the
reachable states when the start distribution is narrow, the LU fallback (over budget, and
undiscounted), and the stated tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.generate import random_grid_mdp, random_mdp
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.mdp.start_value import START_VALUE_TOL, StartValueSolver

EXACT = 1e-9  # agreement asked of every path (the iterative one promises START_VALUE_TOL)


def _exact(model, policy, mu) -> float:
    return float(policy_evaluation(model, policy) @ mu)


def _with_terminals(mdp: FiniteMDP, terminal: np.ndarray, initial: np.ndarray) -> FiniteMDP:
    return FiniteMDP(mdp.P, mdp.R, mdp.gamma, terminal=terminal, initial=initial)


def _policies(rng, S, A, n, flips):
    """``n`` policies, each the last with ``flips`` states changed (the learner's pattern),
    after a uniformly random first one."""
    pol = rng.integers(0, A, size=S)
    out = []
    for _ in range(n):
        out.append(pol.copy())
        where = rng.choice(S, size=flips, replace=False)
        pol[where] = rng.integers(0, A, size=flips)
    return out


@pytest.mark.parametrize("gamma", [0.5, 0.9, 0.99])
@pytest.mark.parametrize("flips", [1, 20, 300])
def test_every_start_equals_the_exact_solve(gamma, flips):
    rng = np.random.default_rng(int(gamma * 100) + flips)
    mdp = random_mdp(300, 4, density=0.01, seed=flips, gamma=gamma)
    mu = rng.dirichlet(np.ones(mdp.n_states))  # every state a start: no search, residual carried
    solver = StartValueSolver(mdp, mu)
    for pol in _policies(rng, mdp.n_states, 4, 25, flips):
        assert abs(solver(pol) - _exact(mdp, pol, mu)) <= EXACT
    assert solver.pushed + solver.factored == 25


def test_on_a_grid_warm_pushes_agree_whatever_the_budget():
    # the push from the last policy's values (budget unbounded) and the default budget, which
    # hands the policies whose change spreads far to the LU
    rng = np.random.default_rng(0)
    mdp = random_grid_mdp(900, gamma=0.9, seed=1)
    mu = np.full(mdp.n_states, 1.0 / mdp.n_states)
    pushing, default = StartValueSolver(mdp, mu, budget=1e9), StartValueSolver(mdp, mu)
    for pol in _policies(rng, mdp.n_states, 4, 30, 3):
        exact = _exact(mdp, pol, mu)
        assert abs(pushing(pol) - exact) <= EXACT
        assert abs(default(pol) - exact) <= EXACT
    assert pushing.pushed == 30 and pushing.factored == 0
    assert default.pushed + default.factored == 30


def test_a_narrow_start_solves_only_the_reachable_states():
    # terminal states and one start state: most states are never reached under a policy
    rng = np.random.default_rng(3)
    base = random_mdp(500, 3, density=0.002, seed=4, gamma=0.95)
    terminal = rng.random(base.n_states) < 0.1
    terminal[0] = False
    initial = np.zeros(base.n_states)
    initial[0] = 1.0
    mdp = _with_terminals(base, terminal, initial)
    mu = initial
    for budget in (1e9, 0.0):  # the push, and the LU of the reachable states
        solver = StartValueSolver(mdp, mu, budget=budget)
        for pol in _policies(rng, mdp.n_states, 3, 20, 25):
            assert abs(solver(pol) - _exact(mdp, pol, mu)) <= EXACT
            reached = solver.reached
            assert 0 < reached.size < mdp.n_states
            # the reachable set is closed under the policy and holds the start
            F_pi = mdp.as_smdp().F[pol * mdp.n_states + np.arange(mdp.n_states)]
            assert 0 in reached
            assert np.isin(F_pi[reached].indices, reached).all()
        assert solver.factored == (20 if budget == 0.0 else 0)


def test_options_models_with_uneven_discounts():
    # an SMDP: rows of F with different masses (multi-time models), rewards of any sign
    rng = np.random.default_rng(5)
    base = random_mdp(200, 5, density=0.02, seed=6)
    mass = rng.uniform(0.3, 0.97, size=base.P.shape[0])
    model = SMDPModel(R=rng.normal(0, 10, size=(200, 5)),
                      F=sp.csr_array(sp.diags_array(mass) @ base.P),
                      admissible=np.ones((200, 5), dtype=bool))
    mu = rng.dirichlet(np.ones(200) * 0.1)
    solver = StartValueSolver(model, mu)
    for pol in _policies(rng, 200, 5, 20, 10):
        assert abs(solver(pol) - _exact(model, pol, mu)) <= EXACT


def test_a_loose_tolerance_is_still_met():
    rng = np.random.default_rng(7)
    mdp = random_mdp(300, 4, density=0.01, seed=8, gamma=0.99)
    mu = np.full(mdp.n_states, 1.0 / mdp.n_states)
    for tol in (1e-2, 1e-5, START_VALUE_TOL):
        solver = StartValueSolver(mdp, mu, tol=tol, budget=1e9)  # the push answers all
        for pol in _policies(rng, mdp.n_states, 4, 10, 30):
            assert abs(solver(pol) - _exact(mdp, pol, mu)) <= tol
        assert solver.factored == 0


def test_undiscounted_policies_take_the_lu_and_a_reachable_loop_scores_nan():
    # gamma = 1: 0 -> 1 -> 2 (terminal); 3 <-> 4 a cycle no start reaches; "stay" loops
    S, A = 5, 2
    P = np.zeros((S, A, S))
    P[0, 0, 1] = P[1, 0, 2] = 1.0
    P[0, 1, 0] = P[1, 1, 1] = 1.0
    P[2, :, 2] = 1.0
    P[3, :, 4] = P[4, :, 3] = 1.0
    terminal = np.array([False, False, True, False, False])
    mu = np.array([1.0, 0, 0, 0, 0])
    mdp = FiniteMDP.from_dense(P, -np.ones((S, A)), 1.0, terminal=terminal, initial=mu)
    solver = StartValueSolver(mdp, mu)
    assert solver(np.zeros(S, dtype=np.int64)) == pytest.approx(-2.0)
    assert np.isnan(solver(np.array([0, 1, 0, 0, 0])))
    assert solver.factored == 2 and solver.pushed == 0


# ------------------------------------------------------------- against a dense solve, by chance


def _dense_start_value(mdp: FiniteMDP, policy: np.ndarray, mu: np.ndarray) -> float:
    """``mu . (I - gamma P_pi)^{-1} R_pi`` by a dense ``np.linalg.solve``, terminal states worth
    0 (their rows and rewards zeroed): an oracle that shares no code with the solver."""
    S = mdp.n_states
    P = mdp.P.toarray().reshape(mdp.n_actions, S, S)
    P_pi = P[policy, np.arange(S)] * ~mdp.terminal[:, None]
    R_pi = np.where(mdp.terminal, 0.0, mdp.R[np.arange(S), policy])
    return float(mu @ np.linalg.solve(np.eye(S) - mdp.gamma * P_pi, R_pi))


def _fresh_residual(solver: StartValueSolver, policy: np.ndarray) -> np.ndarray:
    """``R_pi + F_pi V - V`` of every state, each row summed in CSR order from 0 as the kernel
    sums it (plain Python floats: IEEE doubles, the same operations in the same order)."""
    L, V, S = solver._layout, solver.V, solver.V.size
    r = np.empty(S)
    for s in range(S):
        row = int(policy[s]) * S + s
        acc = 0.0
        for k in range(L.indptr[row], L.indptr[row + 1]):
            acc += float(L.data[k]) * float(V[L.indices[k]])
        r[s] = acc + float(solver._R_t[policy[s], s]) - float(V[s])
    return r


@settings(max_examples=60, deadline=None)
@given(S=st.integers(2, 25), A=st.integers(1, 4), gamma=st.floats(0.3, 0.99),
       density=st.floats(0.05, 0.6), narrow=st.booleans(),
       budget=st.sampled_from([0.0, 0.5, 8.0, 1e9]), int8=st.booleans(),
       seed=st.integers(0, 2**31 - 1))
def test_every_path_equals_a_dense_solve(S, A, gamma, density, narrow, budget, int8, seed):
    # random models with terminal states, every state a start or a few, policies that move
    # a few states or many between calls, and every budget from "always the LU" to "never"
    rng = np.random.default_rng(seed)
    base = random_mdp(S, A, density=density, seed=int(rng.integers(2**31)), gamma=gamma)
    terminal = rng.random(S) < 0.2
    terminal[0] = False
    if narrow:
        initial = np.zeros(S)
        initial[rng.choice(np.flatnonzero(~terminal), size=1)] = 1.0
    else:
        initial = np.where(terminal, 0.0, rng.uniform(0.1, 1.0, S))
    mu = initial / initial.sum()
    mdp = FiniteMDP(base.P, rng.normal(0, 5, size=(S, A)), gamma, terminal=terminal,
                    initial=mu)
    solver = StartValueSolver(mdp, mu, budget=budget)
    pol = rng.integers(0, A, size=S)
    for _ in range(8):
        value = solver(pol.astype(np.int8) if int8 else pol)
        assert abs(value - _dense_start_value(mdp, pol, mu)) <= EXACT
        if solver._carry:  # the residual carried to the next call is exact, bit for bit
            assert np.array_equal(solver._work[0], _fresh_residual(solver, pol))
        flips = rng.choice(S, size=int(rng.integers(0, S + 1)), replace=False)
        pol = pol.copy()
        pol[flips] = rng.integers(0, A, size=flips.size)


def _blocked_sum(mu: np.ndarray, V: np.ndarray) -> float:
    """``sum mu V`` as the solver adds it: blocks of 256 states, each in four partial sums
    (state ``i`` into sum ``i % 4``, the block's last ``len % 4`` into the first), the blocks'
    sums in order."""
    total = 0.0
    for lo in range(0, mu.size, 256):
        hi = min(lo + 256, mu.size)
        parts = [0.0, 0.0, 0.0, 0.0]
        for i in range(lo, hi - (hi - lo) % 4):
            parts[(i - lo) % 4] += float(mu[i]) * float(V[i])
        for i in range(hi - (hi - lo) % 4, hi):
            parts[0] += float(mu[i]) * float(V[i])
        total += (parts[0] + parts[1]) + (parts[2] + parts[3])
    return total


def test_the_carried_residual_is_recomputed_wherever_it_moved():
    # the check after a push recomputes the residual only where V (or a successor's V) moved,
    # and the start value's sum only the blocks where V moved; on a grid, where a push spreads
    # through many states, the residual left for the next call must still be the one computed
    # afresh on every state, and the value the sum of every block afresh, bit for bit
    rng = np.random.default_rng(0)
    mdp = random_grid_mdp(400, gamma=0.95, seed=1)
    mu = rng.dirichlet(np.ones(mdp.n_states))
    solver = StartValueSolver(mdp, mu, budget=1e9)
    for pol in _policies(rng, mdp.n_states, 4, 40, 5):
        value = solver(pol.astype(np.int8))
        assert abs(value - _exact(mdp, pol, mu)) <= EXACT
        assert solver._carry
        assert np.array_equal(solver._work[0], _fresh_residual(solver, pol))
        assert value == _blocked_sum(mu, solver.V)


def test_int8_policies_score_as_int64_ones():
    # the learners hand their int8 greedy policies over as they are: same values, bit for bit,
    # on both paths (the push, and the LU where the budget is spent)
    rng = np.random.default_rng(11)
    mdp = random_grid_mdp(400, gamma=0.95, seed=2)
    mu = np.full(mdp.n_states, 1.0 / mdp.n_states)
    for budget in (8.0, 0.0):
        wide, narrow = StartValueSolver(mdp, mu, budget=budget), StartValueSolver(mdp, mu,
                                                                                  budget=budget)
        for pol in _policies(rng, mdp.n_states, 4, 12, 20):
            assert wide(pol) == narrow(pol.astype(np.int8))
        assert wide.pushed == narrow.pushed and wide.factored == narrow.factored
    mixed = StartValueSolver(mdp, mu)  # int8 first, then int64: the same values as before
    pols = _policies(rng, mdp.n_states, 4, 6, 20)
    values = [mixed(p.astype(np.int8) if i % 2 == 0 else p) for i, p in enumerate(pols)]
    assert all(abs(v - _exact(mdp, p, mu)) <= EXACT for v, p in zip(values, pols, strict=True))
