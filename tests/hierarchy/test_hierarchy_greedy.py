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
    return tasks, adm, splits


def candidates(partition: Partition, adm: np.ndarray, splits: np.ndarray):
    """Every layer one refinement away, built with Partition.split_block (the brute force)."""
    for j in range(partition.n_blocks):
        members = partition.members(j)
        for o in range(partition.n_options):
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
    tasks, adm, splits = problem
    res = greedy_hierarchy(tasks, adm, splits=splits)
    S, K = adm.shape
    trace = np.asarray(res.trace)
    assert trace[-1] <= trace[0]
    assert np.all(np.diff(trace) < 0)
    assert len(res.steps) <= S * K
    start = Partition.trivial(np.zeros((S, K), dtype=bool))
    assert trace[0] == pytest.approx(expected_time(tasks, start).total, rel=1e-9)
    assert trace[-1] == pytest.approx(expected_time(tasks, res.partition).total, rel=1e-9)
    # the returned layer is a local optimum: no single refinement lowers E (brute force)
    floor = trace[-1] * (1 - 1e-9)
    for cand in candidates(res.partition, adm, splits):
        assert expected_time(tasks, cand).total >= floor - 1e-9


@settings(max_examples=40, deadline=None)
@given(problems())
def test_first_step_is_the_brute_force_argmin(problem):
    tasks, adm, splits = problem
    S, K = adm.shape
    start = Partition.trivial(np.zeros((S, K), dtype=bool))
    scores = [expected_time(tasks, c).total for c in candidates(start, adm, splits)]
    res = greedy_hierarchy(tasks, adm, splits=splits, max_steps=1)
    e0 = expected_time(tasks, start).total
    if scores and min(scores) < e0 * (1 - 1e-9):
        assert res.trace[1] == pytest.approx(min(scores), rel=1e-9)
    else:
        assert len(res.trace) == 1


def test_max_steps_and_bad_input():
    Q = np.array([[1.0, 0.0], [0.0, 1.0]])
    t = LearnedTask("t", Q, np.array([0.5, 0.5]), 0.1)
    adm = np.ones((2, 2), dtype=bool)
    res = greedy_hierarchy([t], adm, max_steps=0)
    assert res.stopped == "max-steps" and res.partition.n_blocks == 1
    with pytest.raises(TaskError, match="boolean"):
        greedy_hierarchy([t], adm.astype(int))
    with pytest.raises(TaskError, match="splits"):
        greedy_hierarchy([t], adm, splits=np.zeros((3, 2), dtype=int))
    with pytest.raises(TaskError, match="per-state"):
        greedy_hierarchy([LearnedTask("t", Q, np.array([0.5, 0.5]), 0.1, labels=np.zeros(2,
                                                                                        int))], adm)
