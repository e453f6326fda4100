"""Generated MDPs against independent per-cell oracles (grid moves written out by hand)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.errors import ModelError
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.generate import empirical_model, grid_shape, random_grid_mdp, random_mdp
from adpart.mdp.solvers import modified_policy_iteration, value_iteration


def oracle_grid_row(n: int, s: int, a: int, slip: float) -> dict[int, float]:
    """P(. | s, a) of the slippery grid, computed one cell at a time in plain Python."""
    width = 1
    while width * width < n:
        width += 1
    height = (n + width - 1) // width
    r, c = divmod(s, width)
    moves = {0: (-1, 0), 1: (0, 1), 2: (1, 0), 3: (0, -1)}

    def land(m: int) -> int:
        nr, nc = r + moves[m][0], c + moves[m][1]
        t = nr * width + nc
        ok = 0 <= nr < height and 0 <= nc < width and t < n
        return t if ok else s

    out: dict[int, float] = {}
    for m, p in ((a, 1 - slip), ((a + 1) % 4, slip / 2), ((a + 3) % 4, slip / 2)):
        out[land(m)] = out.get(land(m), 0.0) + p
    return {k: v for k, v in out.items() if v > 0}


@given(st.integers(1, 60), st.integers(1, 4), st.sampled_from([0.0, 0.2, 0.5, 1.0]))
@settings(max_examples=30)
def test_grid_rows_match_cell_by_cell_oracle(n, n_actions, slip):
    mdp = random_grid_mdp(n, n_actions=n_actions, slip=slip, seed=3)
    assert mdp.n_states == n and mdp.n_actions == n_actions
    height, width = grid_shape(n)
    assert height * width >= n > (height - 1) * width
    for s in range(n):
        for a in range(n_actions):
            cols, probs = mdp.transition_row(s, a)
            got = {int(c): float(p) for c, p in zip(cols, probs, strict=True) if p > 0}
            expected = oracle_grid_row(n, s, a, slip)
            assert got.keys() == expected.keys()
            for k, v in expected.items():
                assert got[k] == pytest.approx(v, abs=1e-15)
    # Canonical CSR: sorted, duplicate-free column indices in every row.
    P = mdp.P
    for r in range(P.shape[0]):
        row = P.indices[P.indptr[r] : P.indptr[r + 1]]
        assert np.all(np.diff(row) > 0)


def test_grid_is_seeded_and_features_locate_cells():
    a = random_grid_mdp(500, seed=7)
    b = random_grid_mdp(500, seed=7)
    c = random_grid_mdp(500, seed=8)
    assert a.content_hash == b.content_hash != c.content_hash
    assert np.array_equal(a.P.toarray(), c.P.toarray())  # the seed only draws rewards/terminals
    _, width = grid_shape(500)
    np.testing.assert_array_equal(a.features["row"] * width + a.features["col"], np.arange(500))
    assert a.action_names == ("north", "east", "south", "west")


def test_terminal_fraction_and_solver_rule():
    mdp = random_grid_mdp(400, terminal_fraction=0.1, seed=1, gamma=0.9)
    assert mdp.terminal.sum() == 40
    sol = modified_policy_iteration(mdp, 1e-6)
    assert sol.rule == "sup"
    assert np.all(sol.V[mdp.terminal] == 0.0)
    plain = random_grid_mdp(400, seed=1, gamma=0.9)
    assert value_iteration(plain, 1e-6).rule == "span"


def test_grid_solution_is_epsilon_optimal_against_direct_policy_evaluation():
    """A 30x30 grid: VI's and MPI's policies are within epsilon of a tight solve's value."""
    mdp = random_grid_mdp(900, gamma=0.95, seed=2)
    V_star = policy_evaluation(mdp, modified_policy_iteration(mdp, 1e-11).policy)
    for sol in (value_iteration(mdp, 1e-4), modified_policy_iteration(mdp, 1e-4),
                modified_policy_iteration(mdp, 1e-4, evaluation_sweeps=5)):
        assert sol.converged and sol.loss_bound <= 1e-4
        assert np.max(V_star - policy_evaluation(mdp, sol.policy)) <= 1e-4 + 1e-9


def test_large_grid_builds_vectorised():
    mdp = random_grid_mdp(200_000, seed=0)
    assert mdp.P.shape == (800_000, 200_000)
    assert mdp.P.nnz <= 3 * 800_000
    np.testing.assert_allclose(mdp.P.sum(axis=1), 1.0, atol=1e-12)


@given(
    st.integers(0, 1000), st.integers(1, 30), st.integers(1, 4), st.sampled_from([0.0, 0.2, 1.0])
)
@settings(max_examples=30)
def test_random_mdp_rows_are_distributions(seed, S, A, density):
    mdp = random_mdp(S, A, density=density, seed=seed)
    assert mdp.P.shape == (A * S, S)
    counts = np.diff(mdp.P.indptr)
    assert counts.min() >= 1
    np.testing.assert_allclose(mdp.P.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(mdp.P.data > 0)
    again = random_mdp(S, A, density=density, seed=seed)
    assert again.content_hash == mdp.content_hash


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_states": 0}, "n_states"),
        ({"n_states": 10, "n_actions": 5}, "only 4 moves"),
        ({"n_states": 10, "slip": 1.5}, "slip"),
        ({"n_states": 10, "gamma": 0.0}, "gamma"),
        ({"n_states": 10, "terminal_fraction": 1.0}, "terminal_fraction"),
    ],
)
def test_grid_input_errors(kwargs, match):
    n = kwargs.pop("n_states")
    with pytest.raises(ModelError, match=match):
        random_grid_mdp(n, **kwargs)


def test_random_mdp_input_errors():
    with pytest.raises(ModelError, match="density"):
        random_mdp(5, 2, density=2.0, seed=0)
    with pytest.raises(ModelError, match="n_actions"):
        random_mdp(5, 0, density=0.5, seed=0)


@given(st.integers(0, 1000), st.integers(1, 12), st.integers(1, 3), st.integers(1, 6))
@settings(max_examples=30)
def test_an_empirical_model_counts_draws_inside_the_true_support(seed, S, A, n):
    mdp = random_mdp(S, A, density=0.5, seed=seed)
    est = empirical_model(mdp, n, np.random.default_rng(seed))
    np.testing.assert_allclose(est.P.sum(axis=1), 1.0, atol=1e-12)
    true, got = mdp.P.toarray(), est.P.toarray()
    assert np.all(got[true == 0] == 0)  # no successor outside the support
    np.testing.assert_allclose(got * n, np.round(got * n), atol=1e-9)  # whole counts of n draws
    assert est.content_hash == empirical_model(mdp, n, np.random.default_rng(seed)).content_hash


def test_an_empirical_model_converges_to_the_true_rows():
    """Frequencies of 20,000 draws lie within 5 standard errors of each true probability."""
    mdp = random_mdp(8, 2, density=0.6, seed=3)
    n = 20_000
    got, true = empirical_model(mdp, n, np.random.default_rng(0)).P.toarray(), mdp.P.toarray()
    assert np.all(np.abs(got - true) <= 5 * np.sqrt(true * (1 - true) / n) + 1e-12)


def test_an_empirical_model_of_a_deterministic_mdp_is_exact_and_keeps_terminals():
    mdp = random_grid_mdp(49, slip=0.0, terminal_fraction=0.1, seed=2)
    est = empirical_model(mdp, 1, np.random.default_rng(0))
    assert abs(est.P - mdp.P).max() == 0
    np.testing.assert_array_equal(est.terminal, mdp.terminal)
    np.testing.assert_array_equal(est.R, mdp.R)


@pytest.mark.parametrize("bad", [0, -1, 1.5, True])
def test_an_empirical_model_refuses_a_bad_sample_count(bad):
    with pytest.raises(ModelError, match="samples_per_pair"):
        empirical_model(random_mdp(4, 2, density=0.5, seed=0), bad, np.random.default_rng(0))
