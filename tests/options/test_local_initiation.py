"""Local initiation sets against an independent breadth-first search (issue: options too global).

In a deterministic domain ``"local"`` must equal "the basin's states whose shortest path to the
subgoal, through no other subgoal and no terminal state, has at most ``radius`` steps". The oracle
below is a plain BFS over a dict-of-lists graph read from the dense transition array; it shares no
code with :mod:`adpart.options.subgoal_options` (which reads the pseudo-reward value instead).
"""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.envs.registry import get_domain
from adpart.errors import ModelError
from adpart.mdp.generate import random_grid_mdp
from adpart.options import basin, subgoal_option, subgoal_options


def bfs_steps_to(mdp, subgoal: int, subgoals: set[int]) -> dict[int, int]:
    """Shortest number of steps from each state to ``subgoal``; other subgoals only as starts."""
    S, A = mdp.n_states, mdp.n_actions
    preds: dict[int, list[int]] = {s: [] for s in range(S)}
    for a in range(A):
        rows = mdp.P[a * S:(a + 1) * S].tocoo()
        for s, s2 in zip(rows.row.tolist(), rows.col.tolist(), strict=True):
            if mdp.admissible[s, a] and s != s2:
                preds[s2].append(s)
    dist = {subgoal: 0}
    queue = deque([subgoal])
    while queue:
        x = queue.popleft()
        if x != subgoal and (x in subgoals or mdp.terminal[x]):
            continue  # reached as a start state only; paths do not pass it
        for p in preds[x]:
            if p not in dist:
                dist[p] = dist[x] + 1
                queue.append(p)
    dist.pop(subgoal)
    return {s: d for s, d in dist.items() if not mdp.terminal[s]}


def oracle_initiation(mdp, subgoal: int, subgoals: set[int], radius: float) -> np.ndarray:
    mask = np.zeros(mdp.n_states, dtype=bool)
    for s, d in bfs_steps_to(mdp, subgoal, subgoals).items():
        mask[s] = d <= radius
    return mask


@pytest.mark.parametrize("radius", [1, 5, 12, 30])
def test_local_initiation_is_the_bfs_ball_on_three_floor(radius):
    mdp = get_domain("three-floor").mdp("reach-top-west")
    rng = np.random.default_rng(radius)
    subgoals = sorted(rng.choice(np.flatnonzero(~mdp.terminal), 5, replace=False).tolist())
    options = subgoal_options(mdp, subgoals, initiation="local", radius=radius, cover=False)
    for option in options:
        want = oracle_initiation(mdp, option.subgoal, set(subgoals), radius)
        np.testing.assert_array_equal(option.initiation, want, err_msg=option.name)
        # the option ends where it leaves I (and at the other subgoals, as the basin's does)
        assert (option.beta[~option.initiation] == 1.0).all()


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(12, 60), k=st.integers(1, 4),
       radius=st.integers(1, 9))
def test_local_initiation_matches_bfs_on_random_deterministic_grids(seed, n, k, radius):
    mdp = random_grid_mdp(n, slip=0.0, seed=seed)
    rng = np.random.default_rng(seed)
    subgoals = sorted(rng.choice(n, k, replace=False).tolist())
    for g in subgoals:
        want = oracle_initiation(mdp, g, set(subgoals), radius)
        if not want.any():
            with pytest.raises(ModelError, match="radius"):
                subgoal_option(mdp, g, subgoals=subgoals, initiation="local", radius=radius)
            continue
        got = subgoal_option(mdp, g, subgoals=subgoals, initiation="local", radius=radius)
        np.testing.assert_array_equal(got.initiation, want)


def test_infinite_radius_is_the_basin():
    mdp = get_domain("three-floor").mdp("reach-top-west")
    subgoals = [100, 500, 1000]
    for option in subgoal_options(mdp, subgoals, initiation="local", radius=np.inf,
                                  cover=False):
        np.testing.assert_array_equal(option.initiation, basin(mdp, option.subgoal, subgoals))


def test_a_long_unreliable_route_is_left_out_of_a_stochastic_ball():
    """With slip the local test reads E[gamma^(tau-1)], which a deterministic BFS cannot see."""
    mdp = random_grid_mdp(49, slip=0.4, seed=3)
    det = random_grid_mdp(49, slip=0.0, seed=3)
    g = 24
    slippery = subgoal_option(mdp, g, initiation="local", radius=4)
    exact = subgoal_option(det, g, initiation="local", radius=4)
    assert slippery.initiation.sum() < exact.initiation.sum()
    assert not (slippery.initiation & ~exact.initiation).any()


@pytest.mark.parametrize("radius", [0, 0.5, -3, float("nan"), "far"])
def test_bad_radius_names_the_option(radius):
    mdp = random_grid_mdp(16, slip=0.0, seed=0)
    with pytest.raises(ModelError, match="--radius"):
        subgoal_option(mdp, 5, initiation="local", radius=radius)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(12, 60), k=st.integers(1, 4),
       radius=st.integers(1, 6))
def test_covering_adds_each_far_state_to_its_nearest_subgoal(seed, n, k, radius):
    """cover=True: the balls as before, plus every state in no ball but in some basin, given to
    one option whose subgoal is nearest by the BFS (any of them on a tie)."""
    mdp = random_grid_mdp(n, slip=0.0, seed=seed)
    rng = np.random.default_rng(seed)
    subgoals = sorted(rng.choice(n, k, replace=False).tolist())
    options = subgoal_options(mdp, subgoals, initiation="local", radius=radius, cover=True)
    dist = {g: bfs_steps_to(mdp, g, set(subgoals)) for g in subgoals}
    for s in range(n):
        near = {g: d[s] for g, d in dist.items() if s in d}
        holders = [o.subgoal for o in options if o.initiation[s]]
        if not near:
            assert holders == []
            continue
        balls = sorted(g for g, d in near.items() if d <= radius)
        if balls:
            assert sorted(holders) == balls
        else:
            assert len(holders) == 1 and near[holders[0]] == min(near.values())
    for o in options:
        assert (o.beta[~o.initiation] == 1.0).all() and o.beta[o.subgoal] == 1.0
