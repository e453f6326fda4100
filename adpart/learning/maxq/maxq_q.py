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
import weakref
from bisect import bisect_right
from dataclasses import dataclass

import numpy as np

from adpart.errors import TaskError
from adpart.learning.curves import (
    LearningCurve,
    optimal_start_value,
    start_distribution,
    start_values,
)
from adpart.learning.knowledge import Knowledge, world
from adpart.learning.maxq.taskgraph import CompiledGraph
from adpart.learning.result import LearnResult
from adpart.learning.schedules import Schedule, parse_schedule
from adpart.learning.settings import Run, fresh_seed, require_mdp
from adpart.mdp.model import FiniteMDP

__all__ = ["MaxQResult", "MaxQTables", "decomposed_values", "greedy_hierarchical_policy",
           "hierarchical_rollouts", "maxq_q"]


@dataclass(eq=False)
class MaxQTables:
    """The learned tables of one run.

    Attributes:
        C: per composite, per child slot, the completion values ``C(i, ., a)`` (abstract index
            over the composite's rows, see :class:`CompiledGraph`).
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
        """``(n_slots, n_rows)`` ``C(i, s, a)`` (or ``C~``) of composite ``node`` over the states
        where it runs (``g.rows[node - A]``)."""
        j = node - g.n_primitives
        tables = self.Ct[j] if tilde else self.C[j]
        n = g.rows[j].size
        if not tables:
            return np.zeros((0, n))
        return np.stack([t[idx] for t, idx in zip(tables, g.c_index[j], strict=True)]).reshape(
            len(tables), n)


def _gather(V: np.ndarray, nodes: np.ndarray, states: np.ndarray) -> np.ndarray:
    """``V[nodes, states]`` with ``-inf`` where ``nodes < 0`` (slot unavailable)."""
    return np.where(nodes >= 0, V[np.maximum(nodes, 0), states[None, :]], -np.inf)


def decomposed_values(g: CompiledGraph, tables: MaxQTables) -> tuple[np.ndarray, list[np.ndarray]]:
    """Bottom-up, all states at once: ``V(i, s)`` of every node and the greedy child slots.

    Returns:
        ``(V, greedy)``: ``V`` is ``(n_nodes, S)`` (0 where a composite node has terminated,
        ``-inf`` where it is running but no child is available); ``greedy[j]`` is the
        ``(n_rows,)`` position of the ``C~ + V``-greedy slot of composite ``j`` in each of its
        row states (first in graph order on ties).
    """
    A, S = g.n_primitives, g.n_states
    V = np.zeros((A + g.n_composite, S))
    for a in range(A):
        V[a] = tables.V[a][g.v_index[a]]
    greedy: list[np.ndarray] = []
    for node in g.postorder():
        j = node - A
        rows, sn = g.rows[j], g.slot_node[j]
        base = _gather(V, sn, rows)
        qt = np.where(sn >= 0, base + tables.completion(g, node, tilde=True), -np.inf)
        best = np.argmax(qt, axis=0) if sn.shape[0] else np.zeros(rows.size, dtype=np.int64)
        greedy.append(best.astype(np.int64))
        cols = np.arange(rows.size)
        if sn.shape[0]:
            chosen = (base + tables.completion(g, node))[best, cols]
            none = ~(sn >= 0).any(axis=0)
        else:
            chosen = np.full(rows.size, -np.inf)
            none = np.ones(rows.size, dtype=bool)
        V[node] = 0.0
        V[node, rows] = np.where(none, -np.inf, chosen)
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
    cur = np.full(S, g.root, dtype=np.int64)
    for _ in range(g.n_composite + 1):
        comp = cur >= A
        if not comp.any():
            break
        nxt = np.full(S, -1, dtype=np.int64)
        for node in np.unique(cur[comp]):
            j = int(node) - A
            states = np.flatnonzero(cur == node)
            pos = np.searchsorted(g.rows[j], states)
            pos_c = np.minimum(pos, max(g.rows[j].size - 1, 0))
            running = (g.rows[j].size > 0) & (g.rows[j][pos_c] == states) if g.rows[j].size \
                else np.zeros(states.size, dtype=bool)
            if g.slot_node[j].shape[0] and running.any():
                picked = g.slot_node[j][greedy[j][pos_c], pos_c]
                nxt[states] = np.where(running, picked, -1)
        cur = np.where(comp, nxt, cur)
    cols = np.arange(S)
    ok = (cur >= 0) & (cur < A) & admissible[cols, np.clip(cur, 0, A - 1)]
    return np.where(ok, cur, np.argmax(admissible, axis=1)).astype(np.int64)


def root_q(g: CompiledGraph, tables: MaxQTables) -> np.ndarray:
    """``(S, A)``: per primitive ``a``, the best root-to-``a`` path value ``V(a,s) + sum C``.

    This flattens the decomposition into one action value per state and primitive (``-inf``
    where no path through available children reaches ``a``); with no pseudo-rewards its greedy
    action is the polled policy's (up to ties). Path values of a composite are kept over its
    rows only (the states where it can run).
    """
    A, S = g.n_primitives, g.n_states
    V, _ = decomposed_values(g, tables)
    all_states = np.arange(S)
    paths: dict[int, np.ndarray] = {}
    for a in range(A):
        p = np.full((A, S), -np.inf)
        p[a] = V[a]
        paths[a] = p

    def rows_of(node: int) -> np.ndarray:
        return all_states if node < A else g.rows[node - A]

    for node in g.postorder():
        j = node - A
        rows, sn = g.rows[j], g.slot_node[j]
        Cn = tables.completion(g, node)
        best = np.full((A, rows.size), -np.inf)
        for k in range(sn.shape[0]):
            for child in np.unique(sn[k][sn[k] >= 0]):
                sel = np.flatnonzero(sn[k] == child)
                crow = rows_of(int(child))
                pos = np.searchsorted(crow, rows[sel])
                ok = pos < crow.size
                ok[ok] = crow[pos[ok]] == rows[sel][ok]
                vals = np.full((A, sel.size), -np.inf)
                vals[:, ok] = paths[int(child)][:, pos[ok]] + Cn[k, sel[ok]]
                best[:, sel] = np.maximum(best[:, sel], vals)
        paths[node] = best
    out = np.full((S, A), -np.inf)
    out[g.rows[g.root - A]] = paths[g.root].T
    return out


@dataclass(frozen=True, eq=False)
class MaxQResult(LearnResult):
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

    policies: np.ndarray
    tables: list[MaxQTables]
    graph: CompiledGraph

    def greedy_policies(self) -> np.ndarray:
        return self.policies


class _Static:
    """The compiled graph as Python lists and dicts, built once and shared by all runs.

    Per composite ``j``: ``pos[j]`` maps a running state to its row position (a state not in it
    has terminated ``j``), ``slots[j][k]`` and ``cidx[j][k]`` are lists over row positions, and
    ``pseudo[j]`` maps termination states with a non-zero pseudo-reward to it.
    """

    def __init__(self, g: CompiledGraph) -> None:
        self.pos = [dict(zip(r.tolist(), range(r.size), strict=True)) for r in g.rows]
        self.slots = [[row.tolist() for row in sn] for sn in g.slot_node]
        self.cidx = [[idx.tolist() for idx in row] for row in g.c_index]
        self.vidx = [idx.tolist() for idx in g.v_index]
        self.pseudo = [{int(s): float(g.pseudo[j, s]) for s in np.flatnonzero(g.pseudo[j])}
                       for j in range(g.n_composite)]
        self.tilde = g.has_pseudo.tolist()


_STATIC: weakref.WeakKeyDictionary[CompiledGraph, _Static] = weakref.WeakKeyDictionary()


def _static(g: CompiledGraph) -> _Static:
    if g not in _STATIC:
        _STATIC[g] = _Static(g)
    return _STATIC[g]


class AgentRun:
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
        st = _static(g)
        self.pos, self.slots, self.cidx, self.vidx = st.pos, st.slots, st.cidx, st.vidx
        self.pseudo, self.tilde = st.pseudo, st.tilde
        zeros = MaxQTables.zeros(g)
        self.C = [[c.tolist() for c in row] for row in zeros.C]
        self.Ct = [[c.tolist() for c in row] if self.tilde[j] else self.C[j]
                   for j, row in enumerate(zeros.Ct)]
        self.nC = [[c.tolist() for c in row] for row in zeros.nC]
        self.V = [v.tolist() for v in zeros.V]
        self.nV = [v.tolist() for v in zeros.nV]
        self.n_decide = [[0] * r.size for r in g.rows]
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
        p = self.pos[j].get(s)
        if p is None:
            return 0.0
        k, v_child = self._best(j, p, s)
        if k < 0:
            return -math.inf
        return v_child + self.C[j][k][self.cidx[j][k][p]]

    def _best(self, j: int, p: int, s: int) -> tuple[int, float]:
        """The ``C~ + V``-greedy slot of composite ``j`` in state ``s`` (row position ``p``)
        and its child's ``V`` (first in graph order on ties: the ordered greedy policy)."""
        best_k, best_q, best_v = -1, -math.inf, 0.0
        Ct, cidx = self.Ct[j], self.cidx[j]
        for k, slot in enumerate(self.slots[j]):
            child = slot[p]
            if child < 0:
                continue
            v = self.value(child, s)
            q = v + Ct[k][cidx[k][p]]
            if q > best_q or best_k < 0:
                best_k, best_q, best_v = k, q, v
        return best_k, best_v

    def _choose(self, j: int, p: int, s: int) -> int:
        av = [k for k, slot in enumerate(self.slots[j]) if slot[p] >= 0]
        if not av:
            raise TaskError(
                f"subtask {self.g.names[self.A + j]!r} is running in state {s} but none of its "
                "children is available there; extend its children or its termination predicate"
            )
        self.n_decide[j][p] += 1
        if self.rng.random() < self._rate(self.eps, self.n_decide[j][p]):
            return av[int(self.rng.integers(len(av)))]
        return self._best(j, p, s)[0]

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
        pos, gamma = self.pos[j], self.gamma
        seq: list[int] = []
        p = pos.get(s)
        while p is not None and self.steps < self.horizon:
            k = self._choose(j, p, s)
            if node == self.root:
                self.decisions += 1
            slot = self.slots[j][k]
            child = slot[p]
            child_seq, s2 = self._maxq(child, s)
            p2 = pos.get(s2)
            if p2 is None:
                base_t, base = self.pseudo[j].get(s2, 0.0), 0.0
            else:
                kb, v = self._best(j, p2, s2)
                if kb < 0:
                    base_t = base = -math.inf
                else:
                    ci = self.cidx[j][kb][p2]
                    base_t = self.Ct[j][kb][ci] + v
                    base = self.C[j][kb][ci] + v
            if math.isfinite(base) and math.isfinite(base_t):
                idx, C, Ct, cnt = self.cidx[j][k], self.C[j][k], self.Ct[j][k], self.nC[j][k]
                tilde = self.tilde[j]
                discount = gamma
                for x in reversed(child_seq):
                    # all-states updating: x must be a state where j runs and where this slot
                    # invokes the very instance that ran (call-time bindings may differ)
                    px = pos.get(x)
                    if px is not None and slot[px] == child:
                        ci = idx[px]
                        n = cnt[ci] = cnt[ci] + 1
                        a = self._rate(self.alpha, n)
                        if tilde:
                            Ct[ci] += a * (discount * base_t - Ct[ci])
                        C[ci] += a * (discount * base - C[ci])
                    discount *= gamma
            seq.extend(child_seq)
            s, p = s2, p2
        return seq, s

    def episode_run(self, s0: int) -> tuple[int, int, float, float]:
        """One episode from ``s0``: ``(steps, root decisions, return, discounted return)``."""
        self.steps = self.decisions = 0
        self.ret = self.dret = 0.0
        self.disc = 1.0
        self.last_state = self._maxq(self.root, s0)[1]
        self.episode += 1
        return self.steps, self.decisions, self.ret, self.dret

#: MAXQ-Q samples the environment; its task graph, designed by hand for the task, is knowledge of
#: the task's structure (the subtasks' termination predicates include the task's own goal).
MAXQ_KNOWLEDGE = Knowledge("none", "known", ("hand-designed task graph of the task",))


def _count(value: object, what: str) -> int:
    """``value`` as an int >= 1, else TaskError naming ``what``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise TaskError(f"{what} = {value!r} must be an integer >= 1")
    return int(value)


def hierarchical_rollouts(
    mdp: FiniteMDP, graph: CompiledGraph, tables: MaxQTables, episodes: int, *,
    seed: int = 0, max_steps: int = 10_000, start: int | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Execute the learned **hierarchical** greedy policy (with its call stack) ``episodes``
    times: ``(discounted returns, steps, reached a terminal state)``, each ``(episodes,)``.

    Unlike the polled policy (:func:`greedy_hierarchical_policy`), a subtask runs until its own
    termination predicate holds, with the call-time parameters bound when it was called - the
    policy MAXQ-Q actually learns (Dietterich 2000 sec. 3.2). With call-time parameters this
    policy is not a function of the state alone, so it is scored by Monte Carlo rollouts:
    episodes start from ``start`` or from the start distribution, children are chosen greedily
    on ``C~ + V`` (ties to the first), and the tables are not changed.
    """
    n, H = _count(episodes, "episodes"), _count(max_steps, "max_steps")
    rng = np.random.default_rng(seed)
    agent = AgentRun(mdp, graph, rng, parse_schedule(0.0), parse_schedule(0.0), H)
    agent.C = [[t.tolist() for t in row] for row in tables.C]
    agent.Ct = [[t.tolist() for t in row] if agent.tilde[j] else agent.C[j]
                for j, row in enumerate(tables.Ct)]
    agent.V = [t.tolist() for t in tables.V]
    cdf = np.cumsum(start_distribution(mdp))
    rets, steps, done = np.zeros(n), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool)
    for e in range(n):
        s0 = start if start is not None else int(
            min(np.searchsorted(cdf, rng.random(), side="right"), mdp.n_states - 1))
        agent.last_state = s0
        k, _, _, dret = agent.episode_run(s0)
        rets[e], steps[e] = dret, k
        done[e] = bool(mdp.terminal[agent.last_state])
    return rets, steps, done


def maxq_q(mdp: FiniteMDP, graph: CompiledGraph, run: Run | None = None) -> MaxQResult:
    """Learn ``mdp`` with ``runs`` independent MAXQ-Q agents over the compiled task ``graph``.

    Args:
        mdp: the flat task (its transitions are only *sampled*, via ``FiniteMDP.sample_next``;
            the exact model is used only to score the greedy policies).
        graph: ``TaskGraph.compile(mdp)``.
        run: the run settings (:class:`~adpart.learning.settings.Run`, as in
            :func:`adpart.learning.qlearning.q_learning`): ``alpha``'s visit count is the table
            entry's update count; ``epsilon``'s is the number of decisions the node has taken
            in the state (decaying schedules give a GLIE policy); an episode is cut after
            ``max_steps_per_episode`` primitive steps (the subtasks in progress stop after
            their last update). ``q_init`` and ``kernel`` do not apply.

    Returns:
        A :class:`MaxQResult`; its curve has one row per episode, ``decisions`` counting the
        root's choices.
    """
    run = Run() if run is None else run
    require_mdp("maxq_q", mdp)
    K, N, M, H = run.runs, run.episodes, run.eval_every, run.max_steps_per_episode
    root_seed, alpha_s, eps_s = fresh_seed(run.seed), run.alpha, run.epsilon
    reference_values, progress = run.reference_values, run.progress
    if not isinstance(graph, CompiledGraph) or graph.n_states != mdp.n_states or (
            graph.n_primitives != mdp.n_actions):
        raise TaskError("graph must be a task graph compiled on this MDP: "
                        "TaskGraph.compile(mdp)")

    rngs = np.random.default_rng(root_seed).spawn(K)
    with world():  # the environment: start distribution, V* for scoring, each agent's simulator
        mu = start_distribution(mdp)
        v_star = optimal_start_value(mdp, mu, reference_values)
        agents = [AgentRun(mdp, graph, rngs[k], alpha_s, eps_s, H) for k in range(K)]
    cdf = np.cumsum(mu)
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
        with world():
            eval_value[:, boundary - 1] = start_values(mdp, policies, mu)
        done = boundary
        if progress is not None:
            progress(boundary, N)

    parameters: dict[str, object] = {
        "runs": K, "episodes": N, "seed": root_seed, "alpha": alpha_s.to_dict(),
        "epsilon": eps_s.to_dict(), "max_steps_per_episode": H, "eval_every": M,
        "graph": graph.graph, "abstraction": graph.abstraction,
        "knowledge": MAXQ_KNOWLEDGE.to_dict(),
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
