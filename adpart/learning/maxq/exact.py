"""The recursively optimal values of a compiled task graph, by an exact solve of every subtask.

Dietterich (2000, sec. 3-4; dissertation sec. 3.4.1) defines the **recursively optimal** policy
of a task graph bottom-up: every subtask ``i`` is an SMDP over the states where it runs, whose
actions are its children with *their* recursively optimal policies fixed; ``i``'s policy is
optimal for that SMDP including its pseudo-reward ``R~_i`` on its termination states, and the
value reported to the parent, ``V(i, s)``, is that policy's expected reward *without*
``R~_i``. MAXQ-Q converges to this policy (Dietterich, theorem 3), so it is the ceiling MAXQ-Q
is scored against, and an oracle for its learned decomposition that shares no code with it.

Per node ``c`` we build the multi-time model under its policy (sec. 3.4.1 / Sutton, Precup &
Singh 1999): ``R_c(s)`` the expected discounted reward until ``c`` terminates, ``F_c(s, s')``
the discounted probability that it terminates in ``s'``. Primitives: ``R_a = R(., a)``,
``F_a = gamma P_a``. For a composite ``i`` with greedy child ``c(s)`` in each running state:

    R_i = r + M R_i,    F_i = B + M F_i     (M = F_c restricted to running -> running states,
                                             r = R_c, B = F_c running -> termination states),

solved by a sparse LU (sparse models; the exits are few). The subtask's own SMDP is solved by
value iteration,

    V~_i(s) = max_k  R_{c_k(s)}(s) + sum_{s'} F_{c_k(s)}(s, s') W(s'),
    W(s') = V~_i(s') if i runs in s' else R~_i(s'),

with ties to the first child in graph order (MAXQ-Q's ordered greedy policy), and then
``V(i, s) = R_i(s)`` and ``C(i, s, k) = sum_{s' running} F_{c_k(s)}(s, s') V(i, s')``
(Dietterich's eq. 7; 0 past termination). A child is available in ``s`` only where the graph's
slot names it and it is not already terminated there; a primitive only where admissible.

Call-time parameters (Parr's graph) are handled as executed: a slot invokes, in the state it is
called from, the node the compiled graph binds there, which then runs its own policy to its own
termination. Models are sparse, so Parr's mini maze (1,988 states, 605 subtask instances) is
solved as well as Taxi.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from adpart.learning.maxq.taskgraph import CompiledGraph
from adpart.mdp.model import FiniteMDP

__all__ = ["RecursiveSolution", "polled_policy", "reachable_states", "recursively_optimal"]


@dataclass(frozen=True, eq=False)
class RecursiveSolution:
    """The exact recursively optimal decomposition.

    Attributes:
        V: ``(n_nodes, S)`` ``V(i, s)`` (primitives: ``R(s, a)``; a composite: its value
            without pseudo-reward where it runs, 0 where it has terminated, ``-inf`` where it
            runs but has no available child).
        C: per composite, ``(n_slots, n_rows)`` ``C(i, s, k)`` over its rows (``-inf`` where the
            slot is unavailable).
        policy: per composite, ``(n_rows,)`` the chosen slot position.
        sweeps: per composite, value-iteration sweeps used.
    """

    V: np.ndarray
    C: list[np.ndarray]
    policy: list[np.ndarray]
    sweeps: list[int]


def recursively_optimal(mdp: FiniteMDP, g: CompiledGraph, *, tol: float = 1e-10,
                        max_sweeps: int = 100_000) -> RecursiveSolution:
    """Solve every subtask of ``g`` exactly, children before parents (see the module text)."""
    A, S = g.n_primitives, g.n_states
    n_nodes = A + g.n_composite
    gamma = mdp.gamma
    Rm: list[np.ndarray] = []
    Fm: list[sp.csr_array] = []
    for a in range(A):
        Rm.append(np.asarray(mdp.R[:, a], dtype=np.float64))
        rows_a = a * S + np.arange(S)  # P stacks the actions: row a*S + s
        Fm.append(sp.csr_array(gamma * mdp.P[rows_a]))
    V = np.zeros((n_nodes, S))
    for a in range(A):
        V[a] = Rm[a]
    running = np.zeros((n_nodes, S), dtype=bool)
    running[:A] = np.asarray(mdp.admissible, dtype=bool).T & ~mdp.terminal[None, :]
    C_out: list[np.ndarray] = []
    pol_out: list[np.ndarray] = []
    sweeps_out: list[int] = []
    for node in g.postorder():
        j = node - A
        rows, sn = g.rows[j], g.slot_node[j]
        running[node, rows] = True
        n, K = rows.size, sn.shape[0]
        in_rows = np.zeros(S, dtype=bool)
        in_rows[rows] = True
        ok = np.zeros((K, n), dtype=bool)
        rew = np.full((K, n), -np.inf)
        F: list[sp.csr_array] = []  # per slot, (n, S): the child's exit distribution per row
        for k in range(K):
            parts, where = [], []
            for child in np.unique(sn[k][sn[k] >= 0]):
                sel = np.flatnonzero(sn[k] == child)
                sel = sel[running[int(child), rows[sel]]]
                ok[k, sel] = True
                rew[k, sel] = Rm[int(child)][rows[sel]]
                parts.append(Fm[int(child)][rows[sel]])
                where.append(sel)
            F.append(_place(parts, where, n, S))
        pseudo = np.where(in_rows, 0.0, g.pseudo[j])
        term = [Fk @ pseudo for Fk in F]
        Frun = [sp.csr_array(Fk[:, rows]) for Fk in F]

        def q_of(vt: np.ndarray, rew=rew, ok=ok, term=term, Frun=Frun) -> np.ndarray:
            q = np.stack([rew[k] + term[k] + Frun[k] @ vt for k in range(len(Frun))]) \
                if Frun else np.zeros((0, vt.size))
            return np.where(ok, q, -np.inf)

        vt = np.zeros(n)
        sweep = 0
        for sweep in range(1, max_sweeps + 1):  # noqa: B007 (reported)
            q = q_of(vt)
            new = q.max(axis=0) if K else np.full(n, -np.inf)
            new = np.where(np.isfinite(new), new, _FLOOR)
            if np.max(np.abs(new - vt), initial=0.0) <= tol:
                vt = new
                break
            vt = new
        q = q_of(vt)
        best = q.max(axis=0) if K else np.full(n, -np.inf)
        none = ~(best > _FLOOR / 2)
        scale = np.maximum(1.0, np.abs(np.where(none, 0.0, best)))
        choice = (np.argmax(q >= (best - 1e-9 * scale)[None], axis=0) if K
                  else np.zeros(n, dtype=np.int64))
        # the model of i under its policy: R_i = r + M R_i, F_i = B + M F_i
        pick = [sp.diags_array(((choice == k) & ~none).astype(np.float64)) for k in range(K)]
        Fc = sp.csr_array(sum((pick[k] @ F[k] for k in range(K)), sp.csr_array((n, S))))
        rc = np.where(none, 0.0, np.take_along_axis(rew, choice[None], 0)[0] if K else 0.0)
        exits = np.flatnonzero(~in_rows & (np.asarray(abs(Fc).sum(axis=0)).ravel() > 0))
        Fi = sp.csr_array((S, S))
        Ri = rc
        if n:
            lhs = sp.csc_array(sp.eye_array(n) - Fc[:, rows])
            rhs = np.column_stack([rc, Fc[:, exits].toarray()])
            sol = spla.splu(lhs).solve(rhs)
            Ri = sol[:, 0]
            X = sp.coo_array(sol[:, 1:])
            Fi = sp.csr_array((X.data, (rows[X.row], exits[X.col])), shape=(S, S))
        Rfull = np.zeros(S)
        Rfull[rows] = np.where(none, -np.inf, Ri)
        Rm.append(Rfull)
        Fm.append(Fi)
        V[node] = Rfull
        Vrun = np.where(none, 0.0, Ri)
        C_out.append(np.where(ok, np.stack([Fr @ Vrun for Fr in Frun]) if K
                              else np.zeros((0, n)), -np.inf))
        pol_out.append(choice.astype(np.int64))
        sweeps_out.append(sweep)
    return RecursiveSolution(V=V, C=C_out, policy=pol_out, sweeps=sweeps_out)


#: Stand-in for "no child available" inside value iteration (keeps the arithmetic finite).
_FLOOR = -1e300


def _place(parts: list[sp.csr_array], where: list[np.ndarray], n: int, S: int) -> sp.csr_array:
    """Stack row blocks ``parts[i]`` at row positions ``where[i]`` of an ``(n, S)`` matrix."""
    if not parts:
        return sp.csr_array((n, S))
    M = sp.coo_array(sp.vstack(parts, format="coo"))
    order = np.concatenate(where)
    return sp.csr_array((M.data, (order[M.row], M.col)), shape=(n, S))


def reachable_states(mdp: FiniteMDP) -> np.ndarray:
    """``(S,)`` states reachable from the start distribution (terminal states not expanded):
    where a learner's tables can be compared with an oracle at all."""
    from scipy.sparse import csgraph

    from adpart.learning.curves import start_distribution

    S = mdp.n_states
    P = mdp.P.tocoo()
    keep = ~mdp.terminal[P.row % S] & (P.data > 0)
    adj = sp.csr_array((np.ones(int(keep.sum())), (P.row[keep] % S, P.col[keep])),
                       shape=(S, S))
    out = np.zeros(S, dtype=bool)
    starts = np.flatnonzero(start_distribution(mdp) > 0)
    out[starts] = True
    dist = csgraph.shortest_path(adj, unweighted=True, indices=starts, directed=True)
    out |= np.isfinite(dist).any(axis=0)
    return out


def polled_policy(g: CompiledGraph, solution: RecursiveSolution,
                  admissible: np.ndarray) -> np.ndarray:
    """``(S,)`` the hierarchically greedy (polled) policy of the exact solution: in every state
    descend from the root along the chosen children to a primitive (Dietterich sec. 6) - what
    MAXQ-Q's scored policy becomes when its tables are exact."""
    A, S = g.n_primitives, g.n_states
    cur = np.full(S, g.root, dtype=np.int64)
    for _ in range(g.n_composite + 1):
        comp = np.flatnonzero(cur >= A)
        if comp.size == 0:
            break
        for node in np.unique(cur[comp]):
            j = int(node) - A
            states = comp[cur[comp] == node]
            pos = np.searchsorted(g.rows[j], states)
            pos_c = np.minimum(pos, max(g.rows[j].size - 1, 0))
            running = (g.rows[j].size > 0) & (g.rows[j][pos_c] == states)
            picked = np.full(states.size, -1, dtype=np.int64)
            if g.slot_node[j].shape[0]:
                picked = g.slot_node[j][solution.policy[j][pos_c], pos_c]
            cur[states] = np.where(running, picked, -1)
    cols = np.arange(S)
    ok = (cur >= 0) & (cur < A) & admissible[cols, np.clip(cur, 0, A - 1)]
    return np.where(ok, cur, np.argmax(admissible, axis=1)).astype(np.int64)
