"""``doorways``: subgoals at the cut vertices of the transition graph.

A state is a *cut vertex* (articulation point) of the undirected transition graph when removing
it disconnects the graph: every path between the parts it separates passes through it, which is
what a doorway is. The detector

1. builds the graph with an edge ``s - s'`` wherever some admissible action moves from a
   non-terminal ``s`` to ``s' != s`` with positive probability (directions are ignored);
2. scores every state by the number of states its removal cuts off from the largest remaining
   part of its component (0 for a state that is not a cut vertex), by one depth-first search
   (Hopcroft & Tarjan 1973), linear in the size of the graph;
3. keeps the non-terminal states whose score is at least ``min-size`` (so a dead-end cell in
   front of a single goal cell is not a doorway);
4. with ``narrowest`` (default), of each chain of adjacent kept states - with four moves a door
   and the two cells in front of it are all cut vertices - keeps those with the fewest
   neighbours (the door itself).

It needs no policy (like adpart's ``betweenness``): the policy argument is only checked.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP
from adpart.params import Param
from adpart.plugins import hookimpl
from adpart.subgoals.result import SubgoalResult
from scipy.sparse import csgraph

__all__ = ["Doorways", "cut_off_sizes", "transition_graph"]


def transition_graph(mdp: FiniteMDP) -> sp.csr_array:
    """``(S, S)`` symmetric 0/1 adjacency: admissible moves out of non-terminal states."""
    S = mdp.n_states
    P = sp.coo_array(mdp.P)
    a, s = np.divmod(P.row, S)  # row a*S + s of P is P(. | s, a)
    keep = (P.data > 0) & mdp.admissible[s, a] & ~mdp.terminal[s] & (P.col != s)
    src, dst = s[keep], P.col[keep]
    graph = sp.coo_array((np.ones(2 * src.size), (np.r_[src, dst], np.r_[dst, src])),
                         shape=(S, S)).tocsr()
    graph.data[:] = 1.0  # duplicates summed; 0/1 is all we need
    return graph


def cut_off_sizes(graph: sp.csr_array) -> np.ndarray:
    """``(S,)`` int64: states cut off from the largest remaining part when ``s`` is removed.

    For a state in a component of ``n`` states whose removal leaves parts of sizes ``c_1..c_k``
    (``sum c_i = n - 1``) the value is ``n - 1 - max c_i``; 0 when the component stays
    connected. One iterative depth-first search: a child ``c`` of ``v`` in the search tree with
    ``low[c] >= disc[v]`` is a part of its own (its subtree); the rest of the component is one
    more part (empty at the root).
    """
    S = graph.shape[0]
    indptr, indices = graph.indptr, graph.indices
    disc = np.full(S, -1, dtype=np.int64)
    low = np.zeros(S, dtype=np.int64)
    size = np.ones(S, dtype=np.int64)  # subtree sizes
    parts: list[list[int]] = [[] for _ in range(S)]  # sizes of the parts v's removal separates
    out = np.zeros(S, dtype=np.int64)
    clock = 0
    for root in range(S):
        if disc[root] >= 0:
            continue
        disc[root] = low[root] = clock
        clock += 1
        order = [root]
        stack = [(root, -1, int(indptr[root]))]
        while stack:
            v, parent, i = stack[-1]
            if i < indptr[v + 1]:
                stack[-1] = (v, parent, i + 1)
                w = int(indices[i])
                if disc[w] < 0:
                    disc[w] = low[w] = clock
                    clock += 1
                    order.append(w)
                    stack.append((w, v, int(indptr[w])))
                elif w != parent:
                    low[v] = min(low[v], disc[w])
                continue
            stack.pop()
            if parent >= 0:
                size[parent] += size[v]
                low[parent] = min(low[parent], low[v])
                if low[v] >= disc[parent]:
                    parts[parent].append(int(size[v]))
        n = len(order)
        for v in order:
            sides = parts[v]
            if v != root:
                sides = [*sides, n - 1 - sum(sides)]
            if len([c for c in sides if c > 0]) > 1:
                out[v] = n - 1 - max(sides)
    return out


class Doorways:
    """Cut vertices of the transition graph cutting off >= ``min-size`` states (doorways)."""

    name = "doorways"
    description = "cut vertices of the transition graph (doorways), narrowest of each chain"
    params = (
        Param("min-size", "int", 2, "fewest states a doorway must cut off from the rest", min=1),
        Param("narrowest", "bool", True,
              "of adjacent doorway states keep those with the fewest neighbours"),
    )

    def __init__(self, min_size: int = 2, narrowest: bool = True) -> None:
        if int(min_size) < 1:
            raise TaskError(f"min_size = {min_size!r} must be >= 1")
        self.min_size, self.narrowest = int(min_size), bool(narrowest)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray | None,
               rng: np.random.Generator) -> SubgoalResult:
        t0 = time.perf_counter()
        if not isinstance(mdp, FiniteMDP):
            raise TaskError(f"doorways needs a FiniteMDP, got {type(mdp).__name__}")
        if policy is not None and np.shape(policy)[0] != mdp.n_states:
            raise TaskError(f"the policy has {np.shape(policy)[0]} rows; the MDP has "
                            f"{mdp.n_states} states")
        graph = transition_graph(mdp)
        scores = cut_off_sizes(graph)
        cut = (scores >= self.min_size) & ~mdp.terminal
        candidates = int(cut.sum())
        if self.narrowest and cut.any():
            cut = _narrowest(graph, cut)
        subgoals = np.flatnonzero(cut)
        stats = {"time_s": time.perf_counter() - t0, "cut_vertices": int((scores > 0).sum()),
                 "candidates": candidates, "edges": int(graph.nnz // 2)}
        return SubgoalResult(subgoals, scores.astype(np.float64), float(self.min_size), stats,
                             {"min_size": self.min_size, "narrowest": self.narrowest}, self.name)


def _narrowest(graph: sp.csr_array, mask: np.ndarray) -> np.ndarray:
    """Of each connected group of ``mask`` states keep those of least degree in ``graph``."""
    states = np.flatnonzero(mask)
    sub = graph[states][:, states]
    _, group = csgraph.connected_components(sub, directed=False)
    degree = np.diff(graph.indptr)[states]
    least = np.full(group.max() + 1, np.iinfo(np.int64).max)
    np.minimum.at(least, group, degree)
    out = np.zeros_like(mask)
    out[states[degree == least[group]]] = True
    return out


@hookimpl
def register_subgoal_detectors(register) -> None:  # type: ignore[no-untyped-def]
    register(Doorways)
