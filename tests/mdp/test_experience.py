"""The counts model: what an agent's own steps say about the dynamics (adpart.mdp.experience)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.errors import ModelError
from adpart.learning import q_learning
from adpart.learning.settings import Run
from adpart.mdp.experience import Experience
from adpart.mdp.generate import random_mdp
from adpart.mdp.model import FiniteMDP


def _sampled(mdp: FiniteMDP, pairs: np.ndarray, draws: int, seed: int) -> Experience:
    """``draws`` successors of every (state, action) in ``pairs``, counted by hand."""
    S, A = mdp.n_states, mdp.n_actions
    counts = np.zeros((A * S, S), dtype=np.int64)
    rng = np.random.default_rng(seed)
    for s, a in pairs:
        nxt = mdp.sample_next(np.full(draws, s), np.full(draws, a), rng)
        np.add.at(counts[a * S + s], nxt, 1)
    import scipy.sparse as sp

    return Experience(sp.csr_array(counts))


def test_the_estimate_converges_to_the_true_model_on_tried_pairs():
    mdp = random_mdp(15, 3, density=0.3, seed=4)
    pairs = np.argwhere(np.ones((15, 3), bool))
    exp = _sampled(mdp, pairs, 20000, seed=1)
    P_hat = exp.estimate()
    # each entry is a binomial frequency: within 5 standard errors of P
    diff = np.abs(P_hat.toarray() - mdp.P.toarray())
    se = np.sqrt(mdp.P.toarray() * (1 - mdp.P.toarray()) / 20000)
    assert np.all(diff <= 5 * se + 1e-12)
    # and nothing off the true support
    assert np.all(P_hat.toarray()[mdp.P.toarray() == 0] == 0)


def test_unknown_pairs_are_self_loops():
    mdp = random_mdp(6, 2, density=0.5, seed=2)
    pairs = np.array([[0, 0], [0, 1], [1, 1], [3, 0]])  # states 2, 4, 5 never visited
    exp = _sampled(mdp, pairs, 50, seed=3)
    P_hat = exp.estimate()
    expect = np.zeros((6, 2), bool)
    expect[[0, 0, 1, 3], [0, 1, 1, 0]] = True
    assert np.array_equal(exp.tried, expect)
    dense = P_hat.toarray()
    for s, a in np.argwhere(~expect):  # untried: a self-loop
        assert dense[a * 6 + s, s] == 1.0 and dense[a * 6 + s].sum() == 1.0
    for s, a in pairs:  # tried: the observed frequencies, on the true support
        row = a * 6 + s
        assert dense[row].sum() == pytest.approx(1.0)
        assert np.all(mdp.P.toarray()[row][dense[row] > 0] > 0)
    est = FiniteMDP(P_hat, np.zeros((6, 2)), 0.9)  # a valid model
    assert est.n_states == 6


@settings(max_examples=30, deadline=None)
@given(st.integers(2, 9), st.integers(1, 4), st.integers(0, 10_000))
def test_the_table_round_trips(S, A, seed):
    rng = np.random.default_rng(seed)
    n = rng.integers(0, 20)
    table = {"state": rng.integers(0, S, n), "action": rng.integers(0, A, n),
             "next_state": rng.integers(0, S, n), "count": rng.integers(1, 5, n)}
    exp = Experience.from_table(table, S, A, sources=("run:1",))
    again = Experience.from_table(exp.to_table(), S, A)
    assert (exp.counts != again.counts).nnz == 0
    assert exp.steps == int(table["count"].sum())
    dense = np.zeros((S, A, S), np.int64)
    np.add.at(dense, (table["state"], table["action"], table["next_state"]), table["count"])
    assert np.array_equal(exp.pair_counts, dense.sum(axis=2))
    both = Experience.merge([exp, again])
    assert both.steps == 2 * exp.steps and both.sources == ("run:1",)


def test_bad_tables_are_refused():
    with pytest.raises(ModelError, match="next_state has values outside"):
        Experience.from_table({"state": [0], "action": [0], "next_state": [5], "count": [1]},
                              3, 2)
    with pytest.raises(ModelError, match=">= 0"):
        Experience.from_table({"state": [0], "action": [0], "next_state": [1], "count": [-1]},
                              3, 2)


def test_q_learning_records_what_its_runs_took():
    mdp = random_mdp(10, 2, density=0.4, seed=8)
    mdp = mdp.with_rewards(mdp.R, terminal=np.arange(10) == 9)
    res = q_learning(mdp, Run(runs=3, episodes=20, seed=5, max_steps_per_episode=30))
    exp = res.experience
    assert exp.steps == int(res.curve["steps"].sum())
    assert np.array_equal(exp.pair_counts, res.visits.sum(axis=0))
    # only transitions the model allows, and the kernels agree on them
    assert np.all(mdp.P.toarray()[exp.counts.toarray() > 0] > 0)
    ref = q_learning(mdp, Run(runs=3, episodes=20, seed=5, max_steps_per_episode=30,
                              kernel="python"))
    assert (ref.experience.counts != exp.counts).nnz == 0


def _positions_oracle(P, counts: np.ndarray) -> Experience:
    """The earlier :meth:`Experience.from_positions`: the leading axis summed, the counts put on
    every entry of ``P``'s layout, zeros eliminated by the constructor."""
    import scipy.sparse as sp

    counts = np.array(counts, dtype=np.int64)  # a copy: the constructor compacts it in place
    if counts.ndim == 2:
        counts = counts.sum(axis=0)
    return Experience(sp.csr_array((counts, P.indices.copy(), P.indptr.copy()), shape=P.shape))


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 12), st.integers(1, 4), st.floats(0.05, 1.0), st.integers(0, 3),
       st.sampled_from([np.int32, np.int64]), st.booleans(), st.integers(0, 10_000))
def test_from_positions_is_the_summed_counts_on_p_layout(S, A, density, rows, index_dtype,
                                                         shuffled, seed):
    import scipy.sparse as sp

    rng = np.random.default_rng(seed)
    dense = rng.random((A * S, S)) * (rng.random((A * S, S)) < density)
    P = sp.csr_array(dense)
    P.indices, P.indptr = P.indices.astype(index_dtype), P.indptr.astype(index_dtype)
    if shuffled and P.nnz:  # the same entries, each row's in another order (not canonical)
        order = np.concatenate([rng.permutation(np.arange(P.indptr[r], P.indptr[r + 1]))
                                for r in range(A * S)]).astype(np.int64)
        P = sp.csr_array((P.data[order], P.indices[order], P.indptr), shape=P.shape)
        P.has_sorted_indices = False
    shape = (P.nnz,) if rows == 0 else (rows, P.nnz)
    counts = rng.integers(0, 4, size=shape) * (rng.random(shape) < 0.5)
    kept = counts.copy()
    got = Experience.from_positions(P, counts, sources=("run:1",))
    assert np.array_equal(counts, kept)  # the caller's counts are left as they were
    want = _positions_oracle(P, counts)
    for attr in ("data", "indices", "indptr"):
        a, b = getattr(got.counts, attr), getattr(want.counts, attr)
        assert a.dtype == b.dtype and np.array_equal(a, b), attr
    assert got.counts.shape == want.counts.shape and got.counts.has_canonical_format
    assert got.sources == ("run:1",) and got.steps == int(counts.sum())
    assert np.array_equal(got.pair_counts, want.pair_counts)
    narrow = Experience.from_positions(P, counts.astype(np.int32))  # any integer dtype
    assert (narrow.counts != want.counts).nnz == 0


def test_from_positions_refuses_bad_counts():
    mdp = random_mdp(5, 2, density=0.5, seed=1)
    counts = np.zeros((3, mdp.P.nnz), dtype=np.int64)
    counts[1, 2] = -1
    with pytest.raises(ModelError, match=">= 0"):
        Experience.from_positions(mdp.P, counts)
    with pytest.raises(ModelError, match="counts for a transition matrix"):
        Experience.from_positions(mdp.P, np.zeros(mdp.P.nnz + 1, dtype=np.int64))
    with pytest.raises(ModelError, match="counts for a transition matrix"):
        Experience.from_positions(mdp.P, np.zeros((2, 2, mdp.P.nnz), dtype=np.int64))
