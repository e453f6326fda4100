"""The compiled solver kernels against the scipy/numpy path (an independent implementation).

Backups, greedy policies, gathered policy rows and Jacobi policy sweeps must agree bit for bit;
the adaptive MPI runs (Gauss-Seidel vs BiCGSTAB evaluations) must both carry the guarantee.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.errors import ModelError
from adpart.mdp import _kernels
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.generate import random_grid_mdp
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.mdp.solvers import _Backup, default_kernel, modified_policy_iteration, value_iteration

needs_numba = pytest.mark.skipif(not _kernels.numba_available(), reason="numba not installed")


def random_model(seed: int, S: int, A: int) -> FiniteMDP:
    rng = np.random.default_rng(seed)
    P = rng.random((S, A, S)) * (rng.random((S, A, S)) < 0.3)
    P[np.arange(S), :, rng.integers(0, S, S)] += 0.1
    P /= P.sum(axis=2, keepdims=True)
    terminal = rng.random(S) < 0.15
    admissible = rng.random((S, A)) < 0.7
    admissible[np.arange(S), rng.integers(0, A, S)] = True
    return FiniteMDP.from_dense(
        P, rng.normal(size=(S, A)), 0.9, terminal=terminal, admissible=admissible
    )


@needs_numba
def test_numba_is_the_default_when_available():
    assert default_kernel() == "numba"
    assert _kernels.load() is not None


@needs_numba
@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 30), st.integers(1, 5))
def test_backup_policy_rows_and_sweeps_are_bit_identical(seed, S, A):
    smdp = random_model(seed, S, A).as_smdp()
    fast, ref = _Backup(smdp, "numba"), _Backup(smdp, "numpy")
    V = np.random.default_rng(seed).normal(size=S)
    V_a, pol_a, hi_a, lo_a = fast.step(V, want_policy=True)
    V_b, pol_b, hi_b, lo_b = ref.step(V, want_policy=True)
    assert np.array_equal(V_a, V_b) and np.array_equal(pol_a, pol_b)
    assert (hi_a, lo_a) == (hi_b, lo_b)
    assert np.all(smdp.admissible[np.arange(S), pol_a])
    F_a, R_a = fast.policy_rows(pol_a)
    F_b, R_b = ref.policy_rows(pol_b)
    assert np.array_equal(F_a.toarray(), F_b.toarray()) and np.array_equal(R_a, R_b)
    assert np.array_equal(fast.policy_sweep(F_a, R_a, V), ref.policy_sweep(F_b, R_b, V))


@needs_numba
def test_value_iteration_and_fixed_sweep_mpi_agree_across_kernels():
    mdp = random_grid_mdp(400, gamma=0.9, seed=3, terminal_fraction=0.05)
    for run in (
        lambda k: value_iteration(mdp, 1e-6, kernel=k),
        lambda k: modified_policy_iteration(mdp, 1e-6, evaluation_sweeps=5, kernel=k),
    ):
        a, b = run("numba"), run("numpy")
        assert np.array_equal(a.V, b.V) and np.array_equal(a.policy, b.policy)
        assert (a.sweeps, a.evaluation_sweeps, a.residual) == (b.sweeps, b.evaluation_sweeps,
                                                                b.residual)


@needs_numba
@pytest.mark.parametrize("terminal_fraction", [0.0, 0.1])
def test_gauss_seidel_mpi_is_epsilon_optimal(terminal_fraction):
    mdp = random_grid_mdp(900, gamma=0.95, seed=1, terminal_fraction=terminal_fraction)
    V_star = policy_evaluation(mdp, modified_policy_iteration(mdp, 1e-10, kernel="numpy").policy)
    for kernel in ("numba", "numpy"):
        sol = modified_policy_iteration(mdp, 1e-6, kernel=kernel)
        assert sol.converged and sol.loss_bound < 1e-6
        assert np.max(V_star - policy_evaluation(mdp, sol.policy)) <= 1e-6
        assert np.max(np.abs(sol.V - V_star)) <= sol.value_error_bound + 1e-9


@needs_numba
def test_smdp_with_unequal_row_masses_and_v0_untouched():
    rng = np.random.default_rng(0)
    S, O = 40, 3  # noqa: E741 (the dissertation's name for the option count)
    F = rng.random((O, S, S)) * (rng.random((O, S, S)) < 0.2)
    F[:, np.arange(S), rng.integers(0, S, S)] += 0.1
    F *= rng.uniform(0.3, 0.95, size=(O, S, 1)) / F.sum(axis=2, keepdims=True)
    model = SMDPModel(
        R=rng.normal(size=(S, O)), F=sp.csr_array(F.reshape(O * S, S)),
        admissible=np.ones((S, O), bool),
    )
    V0 = np.zeros(S)
    a = modified_policy_iteration(model, 1e-8, V0=V0, kernel="numba")
    b = modified_policy_iteration(model, 1e-8, V0=V0, kernel="numpy")
    assert np.array_equal(V0, np.zeros(S))
    assert a.rule == "sup" and np.array_equal(a.policy, b.policy)
    np.testing.assert_allclose(a.V, b.V, atol=1e-7)


def test_unknown_kernel_is_reported():
    mdp = random_grid_mdp(10, seed=0)
    with pytest.raises(ModelError, match=r"unknown solver kernel 'cuda'"):
        value_iteration(mdp, kernel="cuda")


def test_numpy_fallback_is_selected_without_numba(monkeypatch):
    monkeypatch.setattr(_kernels, "numba_available", lambda: False)
    assert default_kernel() == "numpy"
    mdp = random_grid_mdp(100, seed=0)
    sol = modified_policy_iteration(mdp, 1e-6)
    assert sol.converged and sol.loss_bound < 1e-6
    with pytest.raises(ModelError, match=r"needs numba"):
        value_iteration(mdp, kernel="numba")
