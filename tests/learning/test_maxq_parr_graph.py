"""The ``parr-maze`` task graph (dissertation ch. 6): compilation, call-time parameters,
termination of every subtask, and learning on the mini maze."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from adpart.envs.domains.parr_maze import ParrMaze
from adpart.errors import TaskError
from adpart.learning.maxq import (
    Subtask,
    TaskGraph,
    get_graph,
    graph_for,
    hierarchical_rollouts,
    maxq_q,
)
from adpart.learning.settings import Run

MOVES = {"N": 0, "E": 1, "S": 2, "W": 3}


@pytest.fixture(scope="module")
def mini():
    mdp = ParrMaze(mini=True).mdp()
    return mdp, get_graph(graph_for(mdp)).compile(mdp)


def test_graph_compiles_with_call_time_instances(mini):
    mdp, g = mini
    A = g.n_primitives
    kinds = {n.split("(")[0] for n in g.names[A:]}
    assert kinds == {"Root", "Go", "ExitInter", "ExitHall", "Sniff", "ToWall", "FollowWall",
                     "BackOne", "PerpThree"}
    assert g.slot_names[g.root - A] == ("Go(d=N,r=@)", "Go(d=E,r=@)", "Go(d=S,r=@)",
                                        "Go(d=W,r=@)")
    y = mdp.features["y"]
    start = int(np.argmax(mdp.initial))
    # in the start room (a corner with doors E and S) only Go(E) and Go(S) exist
    root = g.slot_nodes(g.root - A)[:, start]
    assert [g.names[n] for n in root if n >= 0] == ["Go(d=E,r=0)", "Go(d=S,r=0)"]
    # BackOne(d=N, c) is invoked with c = the row it is called in, and ends one row up
    j = g.names.index("ExitInter(d=S,r=0)") - A
    sn = g.slot_nodes(j)
    k = g.slot_names[j].index("BackOne(d=S,c=@)")
    s = int(np.flatnonzero(sn[k] >= 0)[0])
    back = int(sn[k, s])
    assert g.names[back] == f"BackOne(d=S,c={y[s]})"
    term = g.terminal[back - A]
    assert not term[s] and np.all(term[y != y[s]])


@pytest.mark.slow
def test_every_subtask_terminates(mini):
    """From every state where an instance runs, every greedy-free way of running it - here:
    every child choice - can reach its termination set: no instance has a closed region of
    running states (checked on the support graph of 'any available child, any outcome')."""
    mdp, g = mini
    A, S = g.n_primitives, mdp.n_states
    P = mdp.P.tocsr()
    ends: dict[int, np.ndarray] = {}
    # one-step support of each primitive
    for node in g.postorder():
        j = node - A
        rows, sn = g.rows[j], g.slot_nodes(j)
        assert sn[:, rows].max(axis=0).min() >= 0, g.names[node]  # some child everywhere
        src, dst = [], []
        for k in range(sn.shape[0]):
            for s in rows[sn[k, rows] >= 0]:
                c = int(sn[k, s])
                if c < A:
                    nxt = P[[c * S + s]].indices
                else:
                    nxt = ends[c][s]
                src.extend([s] * len(nxt))
                dst.extend(nxt.tolist())
        G = sp.csr_array((np.ones(len(src)), (dst, src)), shape=(S, S))  # reversed edges
        done = g.terminal[j]
        reach = np.zeros(S, dtype=bool)
        for t in np.flatnonzero(done):
            if not reach[t]:
                reach[breadth_first_order(G, t, return_predecessors=False)] = True
        assert reach[rows].all(), f"{g.names[node]} can get stuck"
        # where can this instance end, started from each running state (support only)
        if node != g.root:
            fwd = sp.csr_array((np.ones(len(src)), (src, dst)), shape=(S, S))
            ends[node] = {}
            for s in np.flatnonzero(g.active[j]):
                seen = breadth_first_order(fwd, int(s), return_predecessors=False)
                ends[node][int(s)] = seen[done[seen]]


def test_bad_call_time_parameters():
    never = lambda f, **_: np.zeros(f["x"].shape, dtype=bool)  # noqa: E731
    mdp = ParrMaze(mini=True).mdp()
    with pytest.raises(TaskError, match="both in params and in call_params"):
        TaskGraph("g", "Root", (Subtask("Root", ("GoNorth",), terminal=never,
                                        params={"r": (1,)}, call_params={"r": "x"}),))
    g = TaskGraph("g", "Root", (
        Subtask("Root", ("B(r=3)",), terminal=never),
        Subtask("B", ("GoNorth",), terminal=never, call_params={"r": "x"}),
    ))
    with pytest.raises(TaskError, match="binds itself from the state at call time"):
        g.compile(mdp)
    g = TaskGraph("g", "Root", (
        Subtask("Root", ("B",), terminal=never),
        Subtask("B", ("GoNorth",), terminal=never, call_params={"r": "colour"}),
    ))
    with pytest.raises(TaskError, match="feature 'colour'"):
        g.compile(mdp)


@pytest.mark.slow
def test_learned_hierarchical_policy_reaches_the_goal_on_the_mini_maze(mini):
    mdp, g = mini
    res = maxq_q(mdp, g, Run(runs=1, episodes=1000, seed=0, alpha="0.5", epsilon="0.1",
                             eval_every=1000, max_steps_per_episode=5000))
    _, steps, done = hierarchical_rollouts(mdp, g, res.tables[0], 20, seed=1,
                                              max_steps=5000)
    assert done.mean() >= 0.9
    assert np.median(steps) < 600           # V*(start) = -69 is about 110 steps
    # the tables only cover the states where each instance runs
    assert g.table_size() < 4 * mdp.n_states * (g.n_composite + 1)
