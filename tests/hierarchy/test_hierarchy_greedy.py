"""Algorithm 3 on random task sets: monotone, stops, agrees with the estimator and brute force."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.errors import TaskError
from adpart.hierarchy import LearnedTask, expected_time, greedy_hierarchy
from adpart.partition import Partition


@st.composite
def problems(draw):
    S = draw(st.integers(2, 9))
    K = draw(st.integers(1, 4))
    T = draw(st.integers(1, 3))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    tasks = []
    for i in range(T):
        Q = rng.normal(size=(S, K)).round(1)
        Q[rng.random((S, K)) < 0.15] = -np.inf
        Q[:, 0] = np.where(np.isfinite(Q).any(axis=1), Q[:, 0], 0.0)
        d = rng.random(S) * (rng.random(S) < 0.8)
        d[rng.integers(S)] += 0.1
        tasks.append(LearnedTask(f"t{i}", Q, d, float(rng.choice([0.0, 0.3, 1.0])),
                                 float(rng.integers(1, 4))))
    adm = rng.random((S, K)) < 0.7
    splits = rng.integers(0, 3, size=(K, S))
    A = draw(st.integers(0, K - 1))  # columns A.. are the candidate options
    return tasks, adm, splits, A


def candidates(partition: Partition, adm: np.ndarray, splits: np.ndarray, A: int):
    """Every layer one option-refinement away, built with Partition.split_block (brute force)."""
    for j in range(partition.n_blocks):
        members = partition.members(j)
        for o in range(A, partition.n_options):
            if partition.admissible[j, o]:
                continue
            sub = splits[o, members]
            child = partition.split_block(j, sub)
            new = child.admissible.copy()
            gets = False
            for b in np.unique(child.labels[members]):
                states = np.flatnonzero(child.labels == b)
                if adm[states, o].all():
                    new[b, o] = True
                    gets = True
            if gets:
                yield child.with_admissible(new)


@settings(max_examples=60, deadline=None)
@given(problems())
def test_greedy_is_monotone_stops_and_matches_the_estimator(problem):
    tasks, adm, splits, A = problem
    res = greedy_hierarchy(tasks, adm, splits=splits, n_primitives=A, c=1.0)
    S, K = adm.shape
    trace = np.asarray(res.trace)
    assert trace[-1] <= trace[0]
    assert np.all(np.diff(trace) < 0)
    assert len(res.steps) <= S * K
    assert not res.partition.admissible[:, :A].any()  # primitives join only by refinement
    start = Partition.trivial(np.zeros((S, K), dtype=bool))
    assert trace[0] == pytest.approx(expected_time(tasks, start, n_primitives=A, c=1.0).total,
                                     rel=1e-9)
    assert trace[-1] == pytest.approx(
        expected_time(tasks, res.partition, n_primitives=A, c=1.0).total, rel=1e-9)
    # the returned layer is a local optimum: no single refinement lowers E (brute force)
    floor = trace[-1] * (1 - 1e-9)
    for cand in candidates(res.partition, adm, splits, A):
        assert expected_time(tasks, cand, n_primitives=A, c=1.0).total >= floor - 1e-9


@settings(max_examples=40, deadline=None)
@given(problems())
def test_first_step_is_the_brute_force_argmin(problem):
    tasks, adm, splits, A = problem
    S, K = adm.shape
    start = Partition.trivial(np.zeros((S, K), dtype=bool))
    scores = [expected_time(tasks, c, n_primitives=A, c=1.0).total
              for c in candidates(start, adm, splits, A)]
    res = greedy_hierarchy(tasks, adm, splits=splits, max_steps=1, n_primitives=A, c=1.0)
    e0 = expected_time(tasks, start, n_primitives=A, c=1.0).total
    if scores and min(scores) < e0 * (1 - 1e-9):
        assert res.trace[1] == pytest.approx(min(scores), rel=1e-9)
    else:
        assert len(res.trace) == 1


def test_max_steps_and_bad_input():
    Q = np.array([[1.0, 0.0], [0.0, 1.0]])
    t = LearnedTask("t", Q, np.array([0.5, 0.5]), 0.1)
    adm = np.ones((2, 2), dtype=bool)
    res = greedy_hierarchy([t], adm, max_steps=0, n_primitives=1, c=1.0)
    assert res.stopped == "max-steps" and res.partition.n_blocks == 1
    with pytest.raises(TaskError, match="boolean"):
        greedy_hierarchy([t], adm.astype(int), n_primitives=1, c=1.0)
    with pytest.raises(TaskError, match="splits"):
        greedy_hierarchy([t], adm, splits=np.zeros((3, 2), dtype=int), n_primitives=1, c=1.0)
    with pytest.raises(TaskError, match="n_primitives"):
        greedy_hierarchy([t], adm, n_primitives=3, c=1.0)
    with pytest.raises(TaskError, match="per-state"):
        greedy_hierarchy([LearnedTask("t", Q, np.array([0.5, 0.5]), 0.1, labels=np.zeros(2,
                                                                                        int))], adm,
                         n_primitives=1, c=1.0)


def _layers(S: int, K: int, A: int):
    """Every layer over ``S`` states: set partitions times per-block option subsets."""
    from itertools import product

    def set_partitions(n):
        if n == 0:
            yield []
            return
        for rest in set_partitions(n - 1):
            m = max(rest, default=-1) + 1
            for b in range(m + 1):
                yield [*rest, b]

    for labels in set_partitions(S):
        B = max(labels) + 1
        for bits in product(range(2 ** (K - A)), repeat=B):
            adm = np.zeros((B, K), dtype=bool)
            for b, x in enumerate(bits):
                adm[b, A:] = [(x >> k) & 1 for k in range(K - A)]
            yield Partition(np.asarray(labels), adm)


def test_commitment_one_block_with_every_option_is_not_free():
    """The brute force over *all* layers of a 4-state problem: the optimum splits the states by
    their best option; the one block offering both options (free under the seed's any-column
    test) must be refined, since it commits to one column."""
    # states 0, 1 want option 1 (column 2), states 2, 3 option 2 (column 3); 2 primitives
    Q = np.array([[0.0, 0.0, 5.0, 1.0], [0.0, 0.0, 5.0, 1.0],
                  [0.0, 0.0, 1.0, 5.0], [0.0, 0.0, 1.0, 5.0]])
    t = LearnedTask("t", Q, np.full(4, 0.25), 0.5)
    one = Partition(np.zeros(4, dtype=np.int64), np.array([[False, False, True, True]]))
    est = expected_time([t], one, n_primitives=2, c=1.0)
    assert est.p_refine[0, 0] == 1.0  # committed to column 2, which loses 4 in states 2, 3
    assert est.total == pytest.approx(1 * 2 + 4**2 * (2 + 2))
    split = Partition(np.array([0, 0, 1, 1]), np.array([[False, False, True, False],
                                                        [False, False, False, True]]))
    assert expected_time([t], split, n_primitives=2, c=1.0).total == pytest.approx(2 * 2)
    best = min(expected_time([t], p, n_primitives=2, c=1.0).total for p in _layers(4, 4, 2))
    assert best == pytest.approx(4.0)
    splits = np.array([[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 1, 1], [1, 1, 0, 0]])
    res = greedy_hierarchy([t], np.ones((4, 4), dtype=bool), splits=splits, n_primitives=2, c=1.0)
    # the greedy only adds options: {0, 1} keeps option 1, {2, 3} offers both and commits to 2
    assert res.partition.n_blocks == 2
    final = expected_time([t], res.partition, n_primitives=2, c=1.0)
    assert not final.p_refine.any() and final.total == pytest.approx(2 * (1 + 2))
    assert best <= res.trace[-1]


@settings(max_examples=15, deadline=None)
@given(problems())
def test_greedy_never_beats_the_exhaustive_optimum(problem):
    """Exact oracle: the minimum of E over every layer of a small problem bounds the greedy's."""
    tasks, adm, splits, A = problem
    S, K = adm.shape
    if S > 5 or K - A > 2:
        return
    res = greedy_hierarchy(tasks, adm, splits=splits, n_primitives=A, c=1.0)
    best = np.inf
    for p in _layers(S, K, A):
        per_state = p.admissible[p.labels]
        if (per_state & ~adm).any():
            continue  # a block offers an option some state may not start
        best = min(best, expected_time(tasks, p, n_primitives=A, c=1.0).total)
    assert res.trace[-1] >= best * (1 - 1e-9)
