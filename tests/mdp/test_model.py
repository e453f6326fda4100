"""FiniteMDP: validation messages, layout, hashing and vectorised sampling."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from adpart.errors import ModelError
from adpart.mdp.model import FiniteMDP


def chain(n: int = 4, gamma: float = 0.9) -> tuple[np.ndarray, np.ndarray]:
    """A two-action chain: action 0 moves right, action 1 stays."""
    P = np.zeros((n, 2, n))
    P[np.arange(n), 0, np.minimum(np.arange(n) + 1, n - 1)] = 1.0
    P[np.arange(n), 1, np.arange(n)] = 1.0
    R = np.zeros((n, 2))
    R[n - 2, 0] = 1.0
    return P, R


def test_action_major_layout():
    P, R = chain()
    m = FiniteMDP.from_dense(P, R, 0.9, action_names=("Right", "Stay"))
    assert m.P.shape == (8, 4)
    dense = m.P.toarray()
    for a in range(2):
        np.testing.assert_array_equal(dense[a * 4 : (a + 1) * 4], P[:, a, :])
    succ, prob = m.transition_row(1, 0)
    assert succ.tolist() == [2] and prob.tolist() == [1.0]


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda P, R: P.__setitem__((2, 1, 2), 0.5), r"state 2, action 'Stay' \(1\) sums to 0.5"),
        (
            lambda P, R: P.__setitem__((1, 0, 0), -0.25),
            r"P\(s'=0 \| s=1, a='Right' \(0\)\) = -0.25 is negative",
        ),
        (
            lambda P, R: P.__setitem__((3, 1, 3), np.nan),
            r"s=3, a='Stay' \(1\)\) = nan is not a finite",
        ),
        (lambda P, R: R.__setitem__((0, 1), np.nan), r"reward R\[s=0, a='Stay' \(1\)\] = nan"),
        (lambda P, R: R.__setitem__((2, 0), np.inf), r"reward R\[s=2, a='Right' \(0\)\] = inf"),
    ],
)
def test_bad_model_messages_name_state_action_value(mutate, message):
    P, R = chain()
    mutate(P, R)
    with pytest.raises(ModelError, match=message):
        FiniteMDP.from_dense(P, R, 0.9, action_names=("Right", "Stay"))


def test_shape_mismatch_messages():
    P, R = chain()
    with pytest.raises(ModelError, match=r"rewards have shape \(4, 3\).*\(4, 2\)"):
        FiniteMDP.from_dense(P, np.zeros((4, 3)), 0.9)
    with pytest.raises(ModelError, match=r"shape \(7, 4\).*\(n_actions \* n_states, n_states\)"):
        FiniteMDP(sp.csr_array(np.ones((7, 4)) / 4), np.zeros((4, 1)), 0.9)
    with pytest.raises(ModelError, match=r"different shapes"):
        FiniteMDP([sp.eye_array(3), sp.eye_array(4)], np.zeros((3, 2)), 0.9)
    with pytest.raises(ModelError, match=r"terminal mask has shape \(3,\)"):
        FiniteMDP.from_dense(P, R, 0.9, terminal=np.zeros(3, bool))
    with pytest.raises(ModelError, match=r"action_names has 3 entries"):
        FiniteMDP.from_dense(P, R, 0.9, action_names=("a", "b", "c"))
    with pytest.raises(ModelError, match=r"gamma = 1.5 is outside \(0, 1\]"):
        FiniteMDP.from_dense(P, R, 1.5)
    with pytest.raises(ModelError, match=r"expected \(S, A, S\)"):
        FiniteMDP.from_dense(np.ones((2, 2)), R, 0.9)


def test_state_without_admissible_action_is_named():
    P, R = chain()
    adm = np.ones((4, 2), bool)
    adm[3] = False
    with pytest.raises(ModelError, match=r"state 3 has no admissible action"):
        FiniteMDP.from_dense(P, R, 0.9, admissible=adm)


def test_inadmissible_rows_may_be_empty():
    P, R = chain()
    P[0, 1, :] = 0.0
    adm = np.ones((4, 2), bool)
    adm[0, 1] = False
    m = FiniteMDP.from_dense(P, R, 0.9, admissible=adm)
    assert m.as_smdp().modulus == pytest.approx(0.9)


def test_arrays_are_read_only():
    P, R = chain()
    m = FiniteMDP.from_dense(P, R, 0.9)
    with pytest.raises(ValueError, match=r"read-only"):
        m.R[0, 0] = 5.0


def test_content_hash_tracks_content_not_labels():
    P, R = chain()
    a = FiniteMDP.from_dense(P, R, 0.9, name="a", action_names=("x", "y"))
    b = FiniteMDP.from_dense(P, R, 0.9, name="b")
    assert a.content_hash == b.content_hash
    R2 = R.copy()
    R2[0, 0] = 1e-12
    assert FiniteMDP.from_dense(P, R2, 0.9).content_hash != a.content_hash
    assert FiniteMDP.from_dense(P, R, 0.95).content_hash != a.content_hash


def test_terminal_rows_vanish_from_smdp_view():
    P, R = chain()
    term = np.zeros(4, bool)
    term[3] = True
    smdp = FiniteMDP.from_dense(P, R + 1.0, 0.9, terminal=term).as_smdp()
    assert np.all(smdp.R[3] == 0.0)
    assert np.all(smdp.row_discounts[:, 3] == 0.0)
    assert not smdp.uniform_discount


def test_sample_next_matches_transition_probabilities():
    rng = np.random.default_rng(3)
    S, A = 6, 3
    P = rng.random((S, A, S)) * (rng.random((S, A, S)) < 0.6)
    P[:, :, 0] += 0.05
    P /= P.sum(axis=2, keepdims=True)
    m = FiniteMDP.from_dense(P, np.zeros((S, A)), 0.9)
    n = 200_000
    for s, a in [(0, 0), (5, 2), (3, 1)]:
        nxt = m.sample_next(np.full(n, s), np.full(n, a), rng)
        freq = np.bincount(nxt, minlength=S) / n
        np.testing.assert_allclose(freq, P[s, a], atol=4e-3)
        assert set(np.flatnonzero(freq)) <= set(np.flatnonzero(P[s, a]))


def test_sample_next_is_reproducible_and_keeps_shape():
    P, R = chain()
    m = FiniteMDP.from_dense(P, R, 0.9)
    states = np.array([[0, 1], [2, 3]])
    out1 = m.sample_next(states, np.zeros_like(states), np.random.default_rng(7))
    out2 = m.sample_next(states, np.zeros_like(states), np.random.default_rng(7))
    assert out1.shape == (2, 2)
    np.testing.assert_array_equal(out1, [[1, 2], [3, 3]])
    np.testing.assert_array_equal(out1, out2)
