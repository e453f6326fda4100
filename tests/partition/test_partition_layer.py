"""Partition hygiene (adpart.partition.layer): the terminal block, reachability, decision rewards.

Oracles, each independent of the code under test:

* reachability: a plain breadth-first search over Python adjacency lists built from the dense F;
* the terminal block: the absorbing-state construction - the new task's terminal states collapsed
  into *one* absorbing state with zero reward, lumped by the brute-force bisimulation of
  ``test_partition_properties``, lifted back to the original states;
* decision rewards: the options' models recomputed by the library's exact solver on the MDP whose
  step rewards are shifted by the baseline (no use of the formula R - c (1 - sum F) / (1 - gamma)).
"""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from adpart.errors import ModelError
from adpart.learning.curves import start_distribution
from adpart.learning.hierarchical import build_decision_layer
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.options.models import option_models
from adpart.options.smdp import stack_models
from adpart.options.subgoal_options import subgoal_option
from adpart.partition import MultiPhasePartitioner, check_stability
from adpart.partition.layer import (
    decision_rewards,
    layer_counts,
    reachable_states,
    resolve_baseline,
    step_baseline,
)
from adpart.partition.partition import canonical_labels
from tests.learning.hierarchical_run import hierarchical_run
from tests.partition.test_partition_properties import brute_force_bisimulation, planted_mdps

# --------------------------------------------------------------------------- reachability


def plain_bfs(F: np.ndarray, adm: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Reachable states by a textbook BFS over adjacency lists (dense F, row o*S + s)."""
    S, n_opt = adm.shape
    succ = [[] for _ in range(S)]
    for s in range(S):
        for o in range(n_opt):
            if adm[s, o]:
                succ[s].extend(int(t) for t in np.flatnonzero(F[o * S + s] > 0))
    seen = [bool(x) for x in start]
    queue = deque(int(s) for s in np.flatnonzero(start))
    while queue:
        s = queue.popleft()
        for t in succ[s]:
            if not seen[t]:
                seen[t] = True
                queue.append(t)
    return np.array(seen)


@st.composite
def sparse_smdps(draw):
    S = draw(st.integers(2, 14))
    n_opt = draw(st.integers(1, 3))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    density = draw(st.sampled_from([0.05, 0.15, 0.3]))
    F = (rng.random((n_opt * S, S)) < density) * rng.uniform(0.1, 0.3, size=(n_opt * S, S))
    adm = rng.random((S, n_opt)) < 0.7
    start = rng.random(S) < 0.2
    start[rng.integers(S)] = True
    model = SMDPModel(R=np.zeros((S, n_opt)), F=sp.csr_array(F), admissible=adm)
    return model, start


@settings(max_examples=60, deadline=None)
@given(sparse_smdps())
def test_reachable_states_match_a_plain_bfs(case):
    model, start = case
    got = reachable_states(model, start)
    assert np.array_equal(got, plain_bfs(model.F.toarray(), model.admissible, start))
    # a distribution gives the same answer as its support
    mu = start / start.sum()
    assert np.array_equal(reachable_states(model, mu), got)
    # a column subset: only its support counts
    assert np.array_equal(
        reachable_states(model, start, options=[0]),
        plain_bfs(model.F.toarray()[: model.n_states], model.admissible[:, :1], start),
    )


def test_reachability_rejects_an_empty_start():
    model = SMDPModel(R=np.zeros((2, 1)), F=sp.csr_array((2, 2)), admissible=np.ones((2, 1), bool))
    with pytest.raises(ModelError, match="start distribution is empty"):
        reachable_states(model, np.zeros(2, dtype=bool))


# --------------------------------------------------------------------------- terminal block


def collapse_terminals(model: SMDPModel, terminal: np.ndarray) -> tuple[SMDPModel, np.ndarray]:
    """The absorbing-state construction: every terminal state becomes one absorbing state z.

    Returns the collapsed model (non-terminal states first, z last) and the index of each original
    state in it.
    """
    S, n_opt = model.n_states, model.n_actions
    live = np.flatnonzero(~terminal)
    where = np.full(S, live.size)
    where[live] = np.arange(live.size)
    n = live.size + 1
    F = model.F.toarray()
    Fc = np.zeros((n_opt * n, n))
    Rc = np.zeros((n, n_opt))
    adm = np.ones((n, n_opt), dtype=bool)
    for o in range(n_opt):
        for i, s in enumerate(live):
            for t in range(S):
                Fc[o * n + i, where[t]] += F[o * S + s, t]
            Rc[i, o] = model.R[s, o]
            adm[i, o] = model.admissible[s, o]
    return SMDPModel(R=Rc, F=sp.csr_array(Fc), admissible=adm), where


@st.composite
def stale_models(draw):
    """A random SMDP and a terminal set the model does not know about (rows left non-zero).

    That is the first task's model seen by a new task whose goals were ordinary states before.
    """
    model, rng = draw(planted_mdps())
    S = model.n_states
    assume(S >= 2)
    terminal = rng.random(S) < draw(st.sampled_from([0.2, 0.4]))
    terminal[rng.integers(S)] = True
    if terminal.all():
        terminal[np.flatnonzero(terminal)[0]] = False
    return model, terminal


@settings(max_examples=60, deadline=None)
@given(stale_models())
def test_terminal_block_matches_the_absorbing_state_construction(case):
    model, terminal = case
    S, n_opt = model.n_states, model.n_actions
    no_beta = np.zeros((S, n_opt), dtype=bool)
    mp = MultiPhasePartitioner(model, no_beta, delta=0.0, terminal=terminal)
    res = mp.run(np.arange(n_opt), epsilon=0.0)
    collapsed, where = collapse_terminals(model, terminal)
    # z (last) starts apart: a zero-row state of the old task that is not terminal in the new one
    # is bisimilar to z but is not one of the task's terminal states
    z_apart = (np.arange(collapsed.n_states) == collapsed.n_states - 1).astype(int)
    oracle = brute_force_bisimulation(collapsed, z_apart, rewards=True)
    assert np.array_equal(res.final.labels, canonical_labels(oracle[where]))
    for part in (res.phase2, res.final, *res.phase1.values()):
        assert np.unique(part.labels[terminal]).size == 1  # one terminal block in every phase
        assert not np.isin(part.labels[~terminal], part.labels[terminal]).any()
    assert res.layer_counts()["phase3"]["terminal"] == 1


def test_terminal_mask_is_checked():
    model = SMDPModel(R=np.zeros((3, 1)), F=sp.csr_array((3, 3)), admissible=np.ones((3, 1), bool))
    with pytest.raises(ModelError, match="terminal mask must be a boolean mask of shape"):
        MultiPhasePartitioner(model, np.zeros((3, 1), bool), delta=0.0, terminal=[0, 1, 0])


# --------------------------------------------------------------------------- decision rewards


def corridor(n: int = 30, gamma: float = 0.95, step: float = -1.0, goal: float = 100.0,
             island: int = 0) -> FiniteMDP:
    """A corridor 0..n-1 (left/right), goal n-1 terminal paying ``goal`` on arrival, start 0.

    ``island`` more states at the end form a loop no state of the corridor leads to.
    """
    S = n + island
    P = np.zeros((S, 2, S))
    R = np.full((S, 2), step)
    for s in range(n):
        P[s, 0, max(s - 1, 0)] = 1.0
        P[s, 1, min(s + 1, n - 1)] = 1.0
    R[n - 2, 1] = step + goal
    for i in range(island):
        s = n + i
        P[s, 0, n + (i - 1) % island] = 1.0
        P[s, 1, n + (i + 1) % island] = 1.0
    terminal = np.zeros(S, dtype=bool)
    terminal[n - 1] = True
    initial = np.zeros(S)
    initial[0] = 1.0
    return FiniteMDP.from_dense(P, R, gamma, terminal=terminal, initial=initial)


def test_decision_rewards_are_the_option_rewards_of_the_shifted_task():
    mdp = corridor()
    options = [subgoal_option(mdp, 10, initiation="reachable"),
               subgoal_option(mdp, 29, initiation="reachable")]
    smdp = stack_models(mdp, option_models(mdp, options, duration=False), include_primitives=True)
    c = step_baseline(mdp.R, mdp.admissible, mdp.terminal)
    assert c == -1.0
    got = decision_rewards(smdp, mdp.gamma, c, terminal=mdp.terminal)
    # oracle: the same options' models on the task whose every step pays c less
    live = mdp.admissible & ~mdp.terminal[:, None]
    shifted = mdp.with_rewards(np.where(live, mdp.R - c, 0.0))
    oracle = stack_models(shifted, option_models(shifted, options, duration=False),
                          include_primitives=True)
    keep = smdp.admissible & ~mdp.terminal[:, None]
    np.testing.assert_allclose(got[keep], oracle.R[keep], atol=1e-8)
    assert np.all(got[mdp.terminal] == 0.0)
    # the option to cell 10 never meets the goal: nothing in its rewards but the step cost
    np.testing.assert_allclose(got[smdp.admissible[:, 2], 2], 0.0, atol=1e-8)
    assert np.ptp(smdp.R[smdp.admissible[:, 2], 2]) > 5.0  # the raw R is path length


def test_a_constant_step_cost_no_longer_cuts_path_length_bands():
    mdp = corridor()
    options = [subgoal_option(mdp, 10, initiation="reachable"),
               subgoal_option(mdp, 20, initiation="reachable")]
    raw = build_decision_layer(mdp, options, delta=0.3, epsilon=1.0, reward_baseline="none")
    rel = build_decision_layer(mdp, options, delta=0.3, epsilon=1.0)
    assert raw.phases.phase2 == rel.phases.phase2
    # raw R(s, o) is -(1 - gamma^d) / (1 - gamma): bands of path length d
    assert raw.partition.n_blocks > raw.phases.phase2.n_blocks
    assert rel.partition.n_blocks == rel.phases.phase2.n_blocks
    for layer in (raw, rel):
        assert check_stability(layer.phases.decision_view, layer.model, delta=0.3, epsilon=1.0,
                               rewards=layer.phases.rewards, options=np.arange(2, 4)).ok


def test_baseline_choices():
    mdp = corridor()
    args = (mdp.R, mdp.admissible, mdp.terminal)
    assert resolve_baseline("min", *args) == -1.0 == resolve_baseline("mode", *args)
    assert resolve_baseline("none", *args) is None and resolve_baseline(None, *args) is None
    assert resolve_baseline(-2, *args) == -2.0
    with pytest.raises(ModelError, match="use 'mode'"):
        resolve_baseline("median", *args)
    # a few penalised pairs: the mode stays the step cost, the minimum is the penalty
    R = np.full((5, 2), -1.0)
    R[0, 1] = -10.0
    live = np.ones((5, 2), dtype=bool)
    none_terminal = np.zeros(5, dtype=bool)
    assert step_baseline(R, live, none_terminal) == -1.0
    assert step_baseline(R, live, none_terminal, rule="min") == -10.0
    smdp = mdp.as_smdp()
    with pytest.raises(ModelError, match="needs 0 < gamma < 1"):
        decision_rewards(smdp, 1.0, -1.0)


# --------------------------------------------------------------------------- the decision layer


def test_unreachable_states_are_one_block_outside_the_layer_and_learners_still_run():
    mdp = corridor(n=20, island=6)
    options = [subgoal_option(mdp, 8, initiation="reachable"),
               subgoal_option(mdp, 19, initiation="reachable")]
    # the island cannot reach the subgoals, so no option may start there: its block offers the
    # primitive actions (the learner never gets there)
    layer = build_decision_layer(mdp, options, delta=0.3, epsilon=10.0)
    island = np.arange(20, 26)
    oracle = ~plain_bfs(mdp.as_smdp().F.toarray(), mdp.as_smdp().admissible,
                        start_distribution(mdp) > 0)
    assert np.array_equal(layer.unreachable, oracle & ~mdp.terminal)
    assert set(np.flatnonzero(layer.unreachable)) == set(island)
    counts = layer.counts()["phase3"]
    assert counts["unreachable"] == np.unique(layer.partition.labels[island]).size
    assert counts["terminal"] == 1
    assert counts["reachable"] + counts["terminal"] + counts["unreachable"] == counts["blocks"]
    assert counts == layer_counts(layer.partition, mdp.terminal, layer.unreachable)
    # the island's states share their blocks with no corridor state
    assert not np.isin(layer.partition.labels[:20], layer.partition.labels[island]).any()
    assert layer.partition.admissible[layer.partition.labels[20], :2].all()
    assert check_stability(layer.phases.decision_view, layer.model, delta=0.3, epsilon=10.0,
                           rewards=layer.phases.rewards).ok
    result = hierarchical_run(mdp, options, layer.partition, delta=0.3, partition_epsilon=10.0,
                                   runs=1, episodes=3, seed=0, eval_every=3,
                                   max_steps_per_episode=200)
    assert result.curve.n_runs == 1


def new_task_model(model: SMDPModel, terminal: np.ndarray) -> SMDPModel:
    """The model with the new task's terminal states absorbing (zero rows), built densely."""
    S, n_opt = model.n_states, model.n_actions
    F = model.F.toarray()
    for o in range(n_opt):
        F[o * S + np.flatnonzero(terminal)] = 0.0
    R = model.R.copy()
    R[terminal] = 0.0
    adm = model.admissible.copy()
    adm[terminal] = True
    return SMDPModel(R=R, F=sp.csr_array(F), admissible=adm)


@settings(max_examples=40, deadline=None)
@given(stale_models(), st.sampled_from([0.0, 0.2, 0.5]), st.sampled_from([0.0, 0.5, 2.0]),
       st.integers(0, 2**31 - 1))
def test_every_phase_passes_the_checker_and_leaves_out_what_a_bfs_cannot_reach(
        case, delta, epsilon, seed):
    stale, terminal = case
    model = new_task_model(stale, terminal)
    S, n_opt = model.n_states, model.n_actions
    rng = np.random.default_rng(seed)
    start = (rng.random(S) < 0.3) & ~terminal
    start[np.flatnonzero(~terminal)[0]] = True
    mp = MultiPhasePartitioner(model, np.zeros((S, n_opt), bool), delta=delta, terminal=terminal)
    res = mp.run(np.arange(n_opt), epsilon=epsilon, start=start, reward_baseline=-1.0, gamma=0.9)
    oracle = ~plain_bfs(model.F.toarray(), model.admissible, start) & ~terminal
    assert np.array_equal(res.unreachable, oracle)
    assert check_stability(res.decision_view, model, delta=delta, epsilon=epsilon,
                           rewards=res.rewards).ok
    assert check_stability(_without(res.phase2, oracle), model, delta=delta).ok
    counts = res.layer_counts()
    for phase in ("phase2", "phase3"):
        assert counts[phase]["terminal"] == 1
        assert counts[phase]["unreachable"] <= max(1, 2 ** n_opt) * oracle.any()


def _without(partition, unreachable):
    adm = partition.admissible.copy()
    adm[np.unique(partition.labels[unreachable])] = False
    return partition.with_admissible(adm)
