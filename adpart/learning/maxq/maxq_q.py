"""MAXQ-Q learning (Dietterich 2000, JAIR 13, sec. 4.2, Table 4; dissertation sec. 3.4.1, ch. 6).

The value of a hierarchical policy is decomposed over the task graph (dissertation sec. 3.4.1):

    Q(i, s, a) = V(a, s) + C(i, s, a),        V(i, s) = max_a Q(i, s, a)   (i composite),

with ``V(a, s)`` the expected one-step reward for a primitive ``a`` and ``C(i, s, a)`` the
*completion function*: the expected discounted reward for finishing subtask ``i`` after child
``a`` returns. The recursive procedure ``MAXQ-Q(i, s)`` (Table 4 with pseudo-rewards) learns:

* primitive ``a``: execute it, observe ``r`` and ``s'``; ``V(a, s) <- (1-alpha) V(a, s) + alpha r``;
* composite ``i``: until ``T_i(s)``: choose a child ``a`` (epsilon-greedy on ``C~ + V``, ties to the
  first child in graph order - Dietterich's ordered greedy policy), run ``MAXQ-Q(a, s)``, which
  returns the states it visited; with ``a* = argmax_a' [C~(i, s', a') + V(a', s')]`` update, for
  every state ``x`` of that sequence, ``N`` steps before ``s'`` ("all-states updating"),

      C~(i, x, a) <- (1-alpha) C~(i, x, a) + alpha gamma^N [R~_i(s') + C~(i, s', a*) + V(a*, s')]
      C(i, x, a)  <- (1-alpha) C(i, x, a)  + alpha gamma^N [C(i, s', a*) + V(a*, s')],

  where the bracket is ``R~_i(s')`` resp. 0 when ``s'`` terminates ``i``. ``C~`` (with the
  pseudo-reward) picks the subtask's internal policy; ``C`` (without) is the value reported to
  the parent, so pseudo-rewards never leak upwards. A node without pseudo-rewards keeps one table.

``V(i, s)`` of a composite node is ``V(a*, s) + C(i, s, a*)`` for the ``C~``-greedy child ``a*``,
evaluated recursively (one state) while learning and bottom-up over all states at once
(:func:`decomposed_values`) for scoring. The scored policy is the *hierarchically greedy*
(polled) policy of Dietterich sec. 6: in every state descend from the root along greedy children
to a primitive action - an ``(S,)`` action array, evaluated exactly on the flat model.

The hierarchy is traversed by Python recursion (it is a handful of nodes deep); tables are
numpy arrays indexed through the graph's abstraction maps. Runs are independent and each draws
from its own ``np.random.default_rng(seed).spawn(runs)[k]`` stream.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from adpart.errors import ModelError, TaskError
from adpart.learning.curves import (
    LearningCurve,
    optimal_start_value,
    start_distribution,
    start_values,
)
from adpart.learning.maxq.taskgraph import CompiledGraph
from adpart.learning.schedules import Schedule, parse_schedule
from adpart.mdp.model import FiniteMDP

__all__ = ["MaxQResult", "MaxQTables", "decomposed_values", "greedy_hierarchical_policy",
           "maxq_q"]


@dataclass(eq=False)
class MaxQTables:
    """The learned tables of one run.

    Attributes:
        C: per composite, per child, the completion values ``C(i, ., a)`` (abstract index).
        Ct: the same for ``C~`` (the very same arrays where a node has no pseudo-reward).
        V: per primitive, the one-step expected reward table ``V(a, .)``.
        nC: update counts of the ``C`` entries (the step-size visit counts).
        nV: update counts of the ``V`` entries.
    """

    C: list[list[np.ndarray]]
    Ct: list[list[np.ndarray]]
    V: list[np.ndarray]
    nC: list[list[np.ndarray]]
    nV: list[np.ndarray]

    @classmethod
    def zeros(cls, g: CompiledGraph) -> MaxQTables:
        C = [[np.zeros(n) for n in sizes] for sizes in g.c_size]
        Ct = [[np.zeros(n) for n in sizes] if g.has_pseudo[j] else C[j]
              for j, sizes in enumerate(g.c_size)]
        nC = [[np.zeros(n, dtype=np.int64) for n in sizes] for sizes in g.c_size]
        V = [np.zeros(n) for n in g.v_size]
        nV = [np.zeros(n, dtype=np.int64) for n in g.v_size]
        return cls(C=C, Ct=Ct, V=V, nC=nC, nV=nV)

    def completion(self, g: CompiledGraph, node: int, tilde: bool = False) -> np.ndarray:
        """``(n_children, S)`` ``C(i, s, a)`` (or ``C~``) of composite ``node`` over all states."""
        j = node - g.n_primitives
        tables = self.Ct[j] if tilde else self.C[j]
        return np.stack([t[idx] for t, idx in zip(tables, g.c_index[j], strict=True)])


def decomposed_values(g: CompiledGraph, tables: MaxQTables) -> tuple[np.ndarray, np.ndarray]:
    """Bottom-up, all states at once: ``V(i, s)`` of every node and the greedy child positions.

    Returns:
        ``(V, greedy)``: ``V`` is ``(n_nodes, S)`` (0 where a composite node has terminated,
        ``-inf`` where it is running but no child is available); ``greedy`` is
        ``(n_composite, S)`` int, the position in ``children[j]`` of the ``C~ + V``-greedy child
        (first in graph order on ties).
    """
    A, S = g.n_primitives, g.n_states
    V = np.zeros((A + g.n_composite, S))
    for a in range(A):
        V[a] = tables.V[a][g.v_index[a]]
    greedy = np.zeros((g.n_composite, S), dtype=np.int64)
    for node in g.postorder():
        j = node - A
        kids = g.children[j]
        base = V[kids]
        qt = np.where(g.available[j], base + tables.completion(g, node, tilde=True), -np.inf)
        best = np.argmax(qt, axis=0)
        greedy[j] = best
        q = base + tables.completion(g, node)
        chosen = q[best, np.arange(S)]
        none = ~g.available[j].any(axis=0)
        V[node] = np.where(g.terminal[j], 0.0, np.where(none, -np.inf, chosen))
    return V, greedy


def greedy_hierarchical_policy(
    g: CompiledGraph, tables: MaxQTables, admissible: np.ndarray
) -> np.ndarray:
    """The hierarchically greedy (polled) policy as an ``(S,)`` primitive-action array.

    In every state: start at the root, take the greedy child, repeat until a primitive action
    (Dietterich 2000, sec. 6, "hierarchical greedy execution"). Where the root has terminated or
    the descent ends on an inadmissible action, the first admissible action is used (the value of
    a terminal state does not depend on it).
    """
    A, S = g.n_primitives, g.n_states
    _, greedy = decomposed_values(g, tables)
    nxt = np.empty((A + g.n_composite, S), dtype=np.int64)
    nxt[:A] = np.arange(A)[:, None]
    for j in range(g.n_composite):
        nxt[A + j] = g.children[j][greedy[j]]
    cur = np.full(S, g.root, dtype=np.int64)
    cols = np.arange(S)
    for _ in range(g.n_composite + 1):
        cur = nxt[cur, cols]
    ok = (cur < A) & admissible[cols, np.minimum(cur, A - 1)]
    return np.where(ok, cur, np.argmax(admissible, axis=1)).astype(np.int64)


def root_q(g: CompiledGraph, tables: MaxQTables) -> np.ndarray:
    """``(S, A)``: per primitive ``a``, the best root-to-``a`` path value ``V(a,s) + sum C``.

    This flattens the decomposition into one action value per state and primitive (``-inf``
    where no path through available children reaches ``a``); with no pseudo-rewards its greedy
    action is the polled policy's (up to ties).
    """
    A, S = g.n_primitives, g.n_states
    V, _ = decomposed_values(g, tables)
    paths: dict[int, np.ndarray] = {}
    for a in range(A):
        p = np.full((A, S), -np.inf)
        p[a] = V[a]
        paths[a] = p
    for node in g.postorder():
        j = node - A
        Cn = tables.completion(g, node)
        best = np.full((A, S), -np.inf)
        for k, child in enumerate(g.children[j]):
            cand = np.where(g.available[j][k], paths[int(child)] + Cn[k], -np.inf)
            best = np.maximum(best, cand)
        paths[node] = best
    return paths[g.root].T.copy()


@dataclass(frozen=True, eq=False)
class MaxQResult:
    """What :func:`maxq_q` returns (the learner-result shape of :mod:`adpart.learning`).

    Attributes:
        Q: ``(K, S, A)`` root-path action values (:func:`root_q`) of every run.
        policies: ``(K, S)`` the final hierarchically greedy policies (as scored).
        tables: per run, the learned :class:`MaxQTables`.
        graph: the compiled task graph.
        curve: per-run, per-episode :class:`~adpart.learning.curves.LearningCurve`.
        seed: the seed used.
        v_star_start: ``sum_s mu(s) V*(s)`` of the flat model, the reference of the value gap.
        parameters: JSON-ready settings.
    """

    Q: np.ndarray
    policies: np.ndarray
    tables: list[MaxQTables]
    graph: CompiledGraph
    curve: LearningCurve
    seed: int
    v_star_start: float
    parameters: dict[str, object] = field(default_factory=dict)

    @property
    def runs(self) -> int:
        return self.Q.shape[0]

    def greedy_policies(self) -> np.ndarray:
        return self.policies


class _Run:
    """One MAXQ-Q agent: the recursive procedure of Dietterich's Table 4.

    The hot loop works on Python lists (scalar reads and writes on lists are several times
    faster than on numpy arrays); :meth:`tables` converts them to :class:`MaxQTables` for the
    vectorised scoring. Successors are drawn exactly as :meth:`FiniteMDP.sample_next` draws them
    (same keys, one uniform per step, ``bisect`` in place of ``searchsorted``).
    """

    def __init__(self, mdp: FiniteMDP, g: CompiledGraph, rng: np.random.Generator,
                 alpha: Schedule, epsilon: Schedule, horizon: int) -> None:
        self.mdp, self.g, self.rng = mdp, g, rng
        self.A = g.n_primitives
        self.alpha = alpha.params()
        self.eps = epsilon.params()
        self.horizon = horizon
        self.R = mdp.R.tolist()
        self.gamma = mdp.gamma
        self.root = g.root
        self.children = [ch.tolist() for ch in g.children]
        self.cidx = [[idx.tolist() for idx in row] for row in g.c_index]
        self.vidx = [idx.tolist() for idx in g.v_index]
        self.term = g.terminal.tolist()
        self.pseudo = g.pseudo.tolist()
        self.tilde = g.has_pseudo.tolist()
        self.avail = [[np.flatnonzero(row).tolist() for row in av.T] for av in g.available]
        zeros = MaxQTables.zeros(g)
        self.C = [[c.tolist() for c in row] for row in zeros.C]
        self.Ct = [[c.tolist() for c in row] if self.tilde[j] else self.C[j]
                   for j, row in enumerate(zeros.Ct)]
        self.nC = [[c.tolist() for c in row] for row in zeros.nC]
        self.V = [v.tolist() for v in zeros.V]
        self.nV = [v.tolist() for v in zeros.nV]
        self.n_decide = [[0] * g.n_states for _ in range(g.n_composite)]
        self.keys = mdp.sampler_keys.tolist()
        self.indptr = mdp.P.indptr.tolist()
        self.indices = mdp.P.indices.tolist()
        self.S = mdp.n_states
        self.episode = 0

    def tables(self) -> MaxQTables:
        """The current tables as numpy arrays."""
        C = [[np.array(c, dtype=np.float64) for c in row] for row in self.C]
        Ct = [[np.array(c, dtype=np.float64) for c in row] if self.tilde[j] else C[j]
              for j, row in enumerate(self.Ct)]
        return MaxQTables(
            C=C, Ct=Ct, V=[np.array(v, dtype=np.float64) for v in self.V],
            nC=[[np.array(c, dtype=np.int64) for c in row] for row in self.nC],
            nV=[np.array(v, dtype=np.int64) for v in self.nV],
        )

    def _rate(self, params: tuple[float, float, float, float], n: int) -> float:
        scale, rate, omega, floor = params
        v = scale * rate ** self.episode
        if omega != 0.0:
            v *= n ** (-omega)
        return max(floor, v)

    def _sample(self, s: int, a: int) -> int:
        """``FiniteMDP.sample_next`` for one pair, the same rule and the same uniform."""
        row = a * self.S + s
        k = bisect_right(self.keys, row + self.rng.random())
        return self.indices[min(k, self.indptr[row + 1] - 1)]

    # -------------------------------------------------------------------------- values
    def value(self, node: int, s: int) -> float:
        """``V(node, s)`` by the recursive decomposition (one state)."""
        if node < self.A:
            return self.V[node][self.vidx[node][s]]
        j = node - self.A
        if self.term[j][s]:
            return 0.0
        k, v_child = self._best(j, s)
        if k < 0:
            return -math.inf
        return v_child + self.C[j][k][self.cidx[j][k][s]]

    def _best(self, j: int, s: int) -> tuple[int, float]:
        """The ``C~ + V``-greedy child position of composite ``j`` in ``s`` and its ``V``
        (first in graph order on ties: the ordered greedy policy)."""
        best_k, best_q, best_v = -1, -math.inf, 0.0
        children, Ct, cidx = self.children[j], self.Ct[j], self.cidx[j]
        for k in self.avail[j][s]:
            v = self.value(children[k], s)
            q = v + Ct[k][cidx[k][s]]
            if q > best_q or best_k < 0:
                best_k, best_q, best_v = k, q, v
        return best_k, best_v

    def _choose(self, j: int, s: int) -> int:
        av = self.avail[j][s]
        if not av:
            raise TaskError(
                f"subtask {self.g.names[self.A + j]!r} is running in state {s} but none of its "
                "children is available there; extend its children or its termination predicate"
            )
        self.n_decide[j][s] += 1
        if self.rng.random() < self._rate(self.eps, self.n_decide[j][s]):
            return av[int(self.rng.integers(len(av)))]
        return self._best(j, s)[0]

    # ------------------------------------------------------------------------ learning
    def _maxq(self, node: int, s: int) -> tuple[list[int], int]:
        """``MAXQ-Q(node, s)``: run the subtask from ``s``; return its visited states and ``s'``."""
        if node < self.A:
            s2 = self._sample(s, node)
            r = self.R[s][node]
            vi = self.vidx[node][s]
            n = self.nV[node][vi] = self.nV[node][vi] + 1
            table = self.V[node]
            table[vi] += self._rate(self.alpha, n) * (r - table[vi])
            self.ret += r
            self.dret += self.disc * r
            self.disc *= self.gamma
            self.steps += 1
            return [s], s2
        j = node - self.A
        term, gamma = self.term[j], self.gamma
        seq: list[int] = []
        while not term[s] and self.steps < self.horizon:
            k = self._choose(j, s)
            if node == self.root:
                self.decisions += 1
            child_seq, s2 = self._maxq(self.children[j][k], s)
            if term[s2]:
                base_t, base = self.pseudo[j][s2], 0.0
            else:
                kb, v = self._best(j, s2)
                if kb < 0:
                    base_t = base = -math.inf
                else:
                    ci = self.cidx[j][kb][s2]
                    base_t = self.Ct[j][kb][ci] + v
                    base = self.C[j][kb][ci] + v
            if math.isfinite(base) and math.isfinite(base_t):
                idx, C, Ct, cnt = self.cidx[j][k], self.C[j][k], self.Ct[j][k], self.nC[j][k]
                tilde = self.tilde[j]
                discount = gamma
                for x in reversed(child_seq):
                    ci = idx[x]
                    n = cnt[ci] = cnt[ci] + 1
                    a = self._rate(self.alpha, n)
                    if tilde:
                        Ct[ci] += a * (discount * base_t - Ct[ci])
                    C[ci] += a * (discount * base - C[ci])
                    discount *= gamma
            seq.extend(child_seq)
            s = s2
        return seq, s

    def episode_run(self, s0: int) -> tuple[int, int, float, float]:
        """One episode from ``s0``: ``(steps, root decisions, return, discounted return)``."""
        self.steps = self.decisions = 0
        self.ret = self.dret = 0.0
        self.disc = 1.0
        self._maxq(self.root, s0)
        self.episode += 1
        return self.steps, self.decisions, self.ret, self.dret


def _count(value: object, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise TaskError(f"{what} = {value!r} must be an integer >= 1")
    return int(value)


def maxq_q(
    mdp: FiniteMDP,
    graph: CompiledGraph,
    *,
    runs: int = 10,
    episodes: int = 500,
    seed: int | None = None,
    alpha: Schedule | str | float = "1/n^0.8",
    epsilon: Schedule | str | float = "0.1",
    max_steps_per_episode: int = 1000,
    eval_every: int = 10,
    reference_values: np.ndarray | None = None,
    progress: Callable[[int, int], object] | None = None,
) -> MaxQResult:
    """Learn ``mdp`` with ``runs`` independent MAXQ-Q agents over the compiled task ``graph``.

    Args:
        mdp: the flat task (its transitions are only *sampled*, via ``FiniteMDP.sample_next``;
            the exact model is used only to score the greedy policies).
        graph: ``TaskGraph.compile(mdp)``.
        runs, episodes, seed, eval_every, progress, reference_values: as in
            :func:`adpart.learning.qlearning.q_learning`.
        alpha: step-size schedule; its visit count is the table entry's update count.
        epsilon: exploration schedule; its visit count is the number of decisions the node has
            taken in the state. Decaying schedules give a GLIE policy.
        max_steps_per_episode: an episode is cut after this many primitive steps (the subtasks
            in progress stop after their last update).

    Returns:
        A :class:`MaxQResult`; its curve has one row per episode, ``decisions`` counting the
        root's choices.
    """
    if not isinstance(mdp, FiniteMDP):
        raise ModelError(f"maxq_q needs a FiniteMDP, got {type(mdp).__name__}")
    if not isinstance(graph, CompiledGraph) or graph.n_states != mdp.n_states or (
            graph.n_primitives != mdp.n_actions):
        raise TaskError("graph must be a task graph compiled on this MDP: "
                        "TaskGraph.compile(mdp)")
    K = _count(runs, "runs")
    N = _count(episodes, "episodes")
    M = _count(eval_every, "eval_every")
    H = _count(max_steps_per_episode, "max_steps_per_episode")
    if seed is None:
        root_seed = int(np.random.SeedSequence().entropy)  # type: ignore[arg-type]
    elif isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise TaskError(f"seed = {seed!r} must be a non-negative integer (or None)")
    else:
        root_seed = int(seed)
    alpha_s = parse_schedule(alpha).check_probability("alpha")
    eps_s = parse_schedule(epsilon).check_probability("epsilon")

    mu = start_distribution(mdp)
    v_star = optimal_start_value(mdp, mu, reference_values)
    cdf = np.cumsum(mu)
    rngs = np.random.default_rng(root_seed).spawn(K)
    agents = [_Run(mdp, graph, rngs[k], alpha_s, eps_s, H) for k in range(K)]
    out = {c: np.zeros((K, N), dtype=np.int64) for c in ("steps", "decisions")}
    out_r = {c: np.zeros((K, N)) for c in ("return", "discounted_return")}
    eval_value = np.full((K, N), np.nan)
    boundaries = sorted({*range(M, N + 1, M), N})
    done = 0
    for boundary in boundaries:
        for k, agent in enumerate(agents):
            for e in range(done, boundary):
                s0 = int(min(np.searchsorted(cdf, agent.rng.random(), side="right"),
                             mdp.n_states - 1))
                steps, dec, ret, dret = agent.episode_run(s0)
                out["steps"][k, e], out["decisions"][k, e] = steps, dec
                out_r["return"][k, e], out_r["discounted_return"][k, e] = ret, dret
        policies = np.stack([greedy_hierarchical_policy(graph, a.tables(), mdp.admissible)
                             for a in agents])
        eval_value[:, boundary - 1] = start_values(mdp, policies, mu)
        done = boundary
        if progress is not None:
            progress(boundary, N)

    parameters: dict[str, object] = {
        "runs": K, "episodes": N, "seed": root_seed, "alpha": alpha_s.to_dict(),
        "epsilon": eps_s.to_dict(), "max_steps_per_episode": H, "eval_every": M,
        "graph": graph.graph, "abstraction": graph.abstraction,
        "table_size": graph.table_size(),
        "reference": "given" if reference_values is not None else "solved",
    }
    metadata = {"learner": "maxq-q", "mdp": mdp.name, "mdp_hash": mdp.content_hash,
                "gamma": mdp.gamma, "v_star_start": v_star, **parameters}
    curve = LearningCurve.from_matrices(
        steps=out["steps"], decisions=out["decisions"], returns=out_r["return"],
        discounted_returns=out_r["discounted_return"], eval_value=eval_value,
        value_gap=v_star - eval_value, metadata=metadata,
    )
    tables = [a.tables() for a in agents]
    Q = np.stack([root_q(graph, t) for t in tables])
    policies = np.stack([greedy_hierarchical_policy(graph, t, mdp.admissible) for t in tables])
    Q.setflags(write=False)
    policies.setflags(write=False)
    return MaxQResult(Q=Q, policies=policies, tables=tables, graph=graph,
                      curve=curve, seed=root_seed, v_star_start=v_star, parameters=parameters)
