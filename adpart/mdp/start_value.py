"""Start values ``sum_s mu(s) V^pi(s)`` of many deterministic policies of one model.

A learner's curve scores one greedy policy per run at every evaluation; only the start value is
asked for, and successive policies differ in few states. :class:`StartValueSolver` therefore
answers each policy by what is asked:

1. **Reachable states only.** ``V^pi`` on the states reachable from ``supp(mu)`` under ``pi``
   depends on those states alone (the set is closed under ``F_pi``), so nothing else is solved
   (a breadth-first search over ``F_pi``'s nonzeros; skipped when ``mu`` covers every
   non-terminal state).
2. **Warm start.** Values start from the last policy's values (a state seen for the first time
   starts from ``R_pi(s) / (1 - m_s)``, ``m_s`` its row's discounted mass: the value of earning
   its own reward forever, exact where every state earns the same).
3. **Residual push** (Southwell's relaxation; the "push" form of Andersen, Chung and Lang 2006):
   with the residual ``r = R_pi + F_pi V - V`` computed exactly on the reachable states, the
   state with a residual above the threshold ``theta`` takes ``V(s) += r(s) / (1 - F_pi(s, s))``
   (its own equation solved), which zeroes ``r(s)`` and adds ``F_pi(p, s)`` times the change to
   each predecessor's residual. Work follows the states the policy change affects, not ``S``.
   When no residual exceeds ``theta`` the residual is computed afresh (no rounding carried
   over) and the push resumes from any state still above it. "Afresh" is done where it can
   change: on the states whose value, or a successor's value, moved since their residual was
   last computed (tracked as the push goes); every other state's residual would come out the
   same bits from the same inputs. So a check costs the states the push touched, not a pass
   over all reachable states (the work counted for the budget is still one pass per check).
   Likewise every row's residual is kept once computed (``(S, O)``, state-major), until a value
   it reads moves: when every non-terminal state is a start, the first call (and the first
   after an LU) computes all rows' in one pass in memory order, and a later policy's changed
   states read theirs from the table instead of gathering their rows one by one (a policy of a
   learner differs from the last one scored in thousands of scattered states).
4. **A stated error.** With ``rho`` the largest row mass of ``F_pi`` on the reachable states,
   ``V^pi - V = (I - F_pi)^{-1} r``, so ``|V^pi(s) - V(s)| <= max|r| / (1 - rho)`` there and the
   start value is within ``tol`` of the exact one once ``max|r| <= theta = tol (1 - rho)``
   (default ``tol`` = :data:`START_VALUE_TOL`).
5. **Exact fallback.** Undiscounted evaluations (``rho = 1``: the bound says nothing), or pushes
   beyond ``budget`` times the reachable rows' nonzeros, are solved by one sparse LU of the
   reachable states' system (:func:`adpart.mdp.evaluation.policy_evaluation` on it); a policy
   that never ends from a reachable state (``gamma = 1``) scores NaN. The LU's values seed the
   next warm start.

The start value itself is summed by blocks of 256 states in four partial sums each (a single
running sum over ``S`` terms both waits on every addition and rounds off about 4e-11 of a start
value near -20 at 10^5 states); when every state is a start, each block's sum is kept until a
value in it moves. Policies come as int8 (the learners' greedy policies) or any integer type,
and a policy is compared with the last one eight bytes at a time. The compiled kernel loads
with numba on the first call (``cache=True``).
"""

from __future__ import annotations

import functools
import weakref

import numpy as np
import scipy.sparse as sp

from adpart.errors import ModelError
from adpart.mdp.model import HasSMDP, SMDPModel

__all__ = ["PUSH_BUDGET", "START_VALUE_TOL", "StartValueSolver"]

#: Absolute error allowed on a start value by the iterative path (the bound of step 4).
START_VALUE_TOL = 1e-10

#: Push work allowed per policy, in units of its reachable rows' nonzeros, before the LU solves.
PUSH_BUDGET = 8.0

#: Row masses at least this close to 1 count as undiscounted (the LU then solves).
_UNDISCOUNTED = 1e-12

#: Kernel status codes.
_DONE, _OVER_BUDGET = 0, 1

#: States per block of the start value's sum (the kernel's blocks: it shifts state ids by 8).
_BLOCK = 256


class StartValueSolver:
    """``sum_s mu(s) V^pi(s)`` of deterministic policies of one model, each solved from the
    last one's values (see the module docstring).

    Args:
        model: the true model (anything with ``as_smdp()``).
        mu: ``(S,)`` start distribution.
        tol: absolute error allowed on a start value by the iterative path.
        budget: push work per policy (in reachable nonzeros) before falling back to the LU.
    """

    def __init__(self, model: HasSMDP, mu: np.ndarray, *, tol: float = START_VALUE_TOL,
                 budget: float = PUSH_BUDGET) -> None:
        smdp = model.as_smdp()
        S = smdp.n_states
        self._smdp = smdp
        self._mu = np.ascontiguousarray(mu, dtype=np.float64)
        self._tol, self._budget = float(tol), float(budget)
        self._layout = _layout(smdp)
        self._R_t = self._layout.R_t
        self._reached = np.empty(0, dtype=np.int64)
        self._rho = smdp.modulus  # every row's discounted mass is at most this
        self._full = bool(np.all(self._mu[self._layout.live] > 0))
        self.V = np.zeros(S)  #: the last policy's values (on its reachable states)
        self._known = np.zeros(S, dtype=np.bool_)
        self._last = np.zeros(S, dtype=np.int64)  # the policy the residual ``r`` is exact for
        self._carry = False  # whether it is (on every state)
        self._fresh = False  # whether every state has a value (after a call on all states)
        # r, reach, members, fifo, queued, dirty, dirty list, rank (position in members)
        self._work = (np.zeros(S), np.zeros(S, dtype=np.bool_), np.empty(S, dtype=np.int64),
                      np.empty(S, dtype=np.int64), np.zeros(S, dtype=np.bool_),
                      np.zeros(S, dtype=np.bool_), np.empty(S, dtype=np.int64),
                      np.empty(S, dtype=np.int64))
        # each row's residual as last computed afresh, NaN where it is not (module docstring,
        # step 3), state-major: a state's rows share a cache line, and the states a policy
        # change touches lie close together
        self._row_residual = np.full((S, smdp.n_actions), np.nan)
        # sum_s mu(s) V(s) of every block of _BLOCK states, NaN where V moved since (with full)
        self._block_sums = np.full(-(-S // _BLOCK), np.nan)
        self.pushed = 0  #: policies answered by the push (the others by the LU)
        self.factored = 0  #: policies answered by the LU of their reachable states
        self.work = 0.0  #: push work so far, in units of the reachable rows' nonzeros

    def __call__(self, policy: np.ndarray) -> float:
        """The start value of one deterministic policy ``(S,)`` (admissible actions; int8, as
        the learners keep their greedy policies, or any integer type)."""
        pol = np.ascontiguousarray(policy)
        if pol.dtype != self._last.dtype:  # int8 policies compare with int8 ones
            if pol.dtype == np.int8 and not self._known.any():
                self._last = self._last.astype(np.int8)
            else:
                pol = pol.astype(np.int64)
                self._last = self._last.astype(np.int64, copy=False)
        L = self._layout
        if self._rho < 1.0 - _UNDISCOUNTED:
            value, status, n, work = _kernel()(
                (L.indptr, L.indices, L.data, self._R_t),
                (L.col_ptr, L.col_row, L.col_val, L.diag), pol, self._last, self._mu,
                (self.V, self._known, self._work[0], self._row_residual, self._block_sums),
                self._work[1:],
                (self._carry, self._fresh, self._full), self._tol * (1.0 - self._rho),
                self._budget)
            self.work += work
            self._carry = self._full and status == _DONE
            self._fresh = self._full
            self._reached = self._work[2][:n]
            if status == _DONE:
                self.pushed += 1
                return float(value)
            members = np.sort(self._reached)
        else:
            members = self._reached = _reachable(L, pol.astype(np.int64), self._mu)
        self.factored += 1
        return self._factor(pol.astype(np.int64), members)

    @property
    def reached(self) -> np.ndarray:
        """Sorted ids of the states the last policy reaches from ``supp(mu)`` (all states
        when every non-terminal state is a start)."""
        return np.sort(self._reached)

    def _factor(self, policy: np.ndarray, members: np.ndarray) -> float:
        """The start value by one sparse LU of the reachable states' system; NaN if ``pi``
        never ends from one of them. Its values seed the next warm start."""
        from adpart.mdp.evaluation import policy_evaluation

        smdp, S = self._smdp, self._smdp.n_states
        rows = policy[members] * S + members
        F_sub = smdp.F[rows][:, members]  # a closed set: no mass leaves it
        n = members.size
        sub = SMDPModel(R=self._R_t[policy[members], members][:, None],
                        F=sp.csr_array(F_sub), admissible=np.ones((n, 1), dtype=bool))
        try:
            V = policy_evaluation(sub, np.zeros(n, dtype=np.int64))
        except ModelError:
            return float("nan")
        self.V[members] = V
        self._known[members] = True
        self._row_residual.fill(np.nan)  # every row that reads these values is stale
        self._block_sums.fill(np.nan)
        # einsum, not BLAS ddot: a threaded ddot spin-waits on a loaded machine (solvers._dot)
        return float(np.einsum("i,i->", V, self._mu[members]))


class _Layout:
    """A model's transitions as the push reads them: rows (CSR, int64), each state's
    predecessor entries (rows ``o*S + p`` with ``F(s | p, o)``), each row's self-loop mass, the
    states with any transition (the non-terminal ones), and the rewards ``(O, S)`` (0 where
    inadmissible). Read-only by use."""

    def __init__(self, smdp: SMDPModel) -> None:
        F = smdp.F
        self.R_t = np.ascontiguousarray(np.where(smdp.admissible, smdp.R, 0.0).T)
        self.indptr, self.indices, self.data = (F.indptr.astype(np.int64),
                                                F.indices.astype(np.int64), F.data)
        self.col_ptr, self.col_row, self.col_val, self.diag, self.live = _prepare()(
            self.indptr, self.indices, self.data, smdp.n_states)


_LAYOUTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _layout(smdp: SMDPModel) -> _Layout:
    """The model's :class:`_Layout`, built once per model object."""
    layout = _LAYOUTS.get(smdp)
    if layout is None:
        layout = _LAYOUTS[smdp] = _Layout(smdp)
    return layout


def _reachable(layout: _Layout, policy: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Sorted ids of the states reachable from ``supp(mu)`` under ``policy``."""
    from scipy.sparse import csgraph

    S = mu.size
    rows = policy * S + np.arange(S)
    F_pi = sp.csr_array((np.ones(layout.indices.size), layout.indices, layout.indptr),
                        shape=(layout.indptr.size - 1, S))[rows]
    starts = np.flatnonzero(mu > 0)
    source = sp.csr_array((np.ones(starts.size), (np.full(starts.size, S), starts)),
                          shape=(S + 1, S + 1))
    graph = sp.csr_array(sp.block_diag((F_pi, sp.csr_array((1, 1)))) + source)
    order = csgraph.breadth_first_order(graph, S, directed=True, return_predecessors=False)
    return np.sort(order[order < S]).astype(np.int64)


@functools.cache
def _prepare():
    """The layout kernel (one pass over ``F``), compiled by numba on first use."""
    import numba

    @numba.njit(cache=True, nogil=True, boundscheck=False)
    def prepare(indptr, indices, data, S):
        n_rows = indptr.shape[0] - 1
        col_ptr = np.zeros(S + 1, dtype=np.int64)
        for k in range(indices.shape[0]):
            col_ptr[indices[k] + 1] += 1
        for t in range(S):
            col_ptr[t + 1] += col_ptr[t]
        fill = col_ptr[:S].copy()
        col_row = np.empty(indices.shape[0], dtype=np.int64)
        col_val = np.empty(indices.shape[0])
        diag = np.zeros(n_rows)
        live = np.zeros(S, dtype=np.bool_)
        for row in range(n_rows):
            s = row % S
            if indptr[row + 1] > indptr[row]:
                live[s] = True
            for k in range(indptr[row], indptr[row + 1]):
                t = indices[k]
                col_row[fill[t]] = row
                col_val[fill[t]] = data[k]
                fill[t] += 1
                if t == s:
                    diag[row] += data[k]
        return col_ptr, col_row, col_val, diag, live

    return prepare


@functools.cache
def _kernel():
    """The push kernel, compiled by numba on first use (``cache=True``; one function calling no
    other compiled one, so that numba's cache can hold it)."""
    import numba

    @numba.njit(cache=True, nogil=True, boundscheck=False)
    def start_value_push(model, preds, policy, last, mu, values, work_arrays, flags, theta,
                         budget):
        """Steps 1-4 of the module docstring; returns ``(value, status, n_reachable, work)``
        with the reachable states in ``members[:n]`` (status 0 done, 1 over budget) and the
        push work in units of the reachable rows' nonzeros. With ``carry``, ``r`` is exact for
        ``V`` and the policy ``last`` on every state (the last call ended done, with every
        state reachable) and only the states whose action changed are recomputed; ``last``
        becomes ``policy`` when done. ``fresh``: every state has a value already (``known``),
        and with ``full`` the identity ``members`` / ``rank`` are in place from the last call.
        Arrays by role: ``model`` = (indptr, indices, data, R_t), ``preds`` = (col_ptr, col_row,
        col_val, diag), ``values`` = (V, known, r, row_r, block_sums), ``work_arrays`` = (reach,
        members, fifo, queued, dirty, dirty_list, rank), ``flags`` = (carry, fresh, full).

        The residual "computed afresh" of step 3 is recomputed on the *dirty* states only: those
        whose ``V`` or whose successor's ``V`` (under ``policy``) changed since their residual
        was last computed. Every other state's ``r`` was computed by the same expression from
        the same ``V`` entries and the same row, so recomputing it would give the same bits;
        the dirty ones are recomputed in ``members`` order, so the states queued, their order
        and every value are those of a pass over all reachable states. The work counted stays
        one pass's worth per check (``nnz``), so the push-or-LU choice is unchanged.

        Every residual computed afresh is kept per row (``row_r[s, o]``; NaN where none is)
        until a value it reads moves (``V(s)`` or a successor's: the push resets the rows it
        affects to NaN, the LU all of them; a residual that is itself NaN is recomputed); with
        ``full`` and no carry (the first call, or the first after an LU) every row's is computed
        in one pass in memory order, so a policy change reads its residuals instead of its
        rows. With ``full``, ``block_sums[b]`` keeps ``mu . V`` over states ``256 b ..`` (NaN once
        one of their values moves), so the start value re-adds only the blocks that changed.
        """
        indptr, indices, data, R_t = model
        col_ptr, col_row, col_val, diag = preds
        V, known, r, row_r, block_sums = values
        reach, members, fifo, queued, dirty, dirty_list, rank = work_arrays
        carry, fresh, full = flags
        S = R_t.shape[1]
        n_opts = R_t.shape[0]
        n = 0
        if full:
            if not fresh:  # the identity, written once: ``full`` never changes
                for s in range(S):
                    reach[s] = True
                    members[s] = s
                    rank[s] = s
            n = S
        else:
            reach[:] = False
            for s in range(S):
                if mu[s] > 0.0:
                    reach[s] = True
                    members[n] = s
                    rank[s] = n
                    n += 1
            head = 0
            while head < n:
                s = members[head]
                head += 1
                row = policy[s] * S + s
                for k in range(indptr[row], indptr[row + 1]):
                    t = indices[k]
                    if not reach[t]:
                        reach[t] = True
                        members[n] = t
                        rank[t] = n
                        n += 1
        if full and fresh:  # every state seen before: only the work unit to count
            nnz = S + (indptr[indptr.shape[0] - 1] * S) // (indptr.shape[0] - 1)
        else:
            nnz = 0
            for i in range(n):
                s = members[i]
                row = policy[s] * S + s
                nnz += indptr[row + 1] - indptr[row] + 1
                if not known[s]:  # first visit: the value of its own reward forever
                    mass = 0.0
                    for k in range(indptr[row], indptr[row + 1]):
                        mass += data[k]
                    V[s] = R_t[policy[s], s] / (1.0 - mass)
                    known[s] = True
                    block_sums[s >> 8] = np.nan
        if full and not carry:  # every row's residual, in one pass in memory order
            for o in range(n_opts):
                for s in range(S):
                    if np.isnan(row_r[s, o]):
                        row = o * S + s
                        acc = 0.0
                        for k in range(indptr[row], indptr[row + 1]):
                            acc += data[k] * V[indices[k]]
                        row_r[s, o] = acc + R_t[o, s] - V[s]
        allowed = budget * nnz
        work = 0
        head = 0
        tail = 0
        count = 0
        n_dirty = 0
        n_todo = n  # the residual: of the changed rows (with carry, which implies full), or afresh
        if carry:
            n_todo = 0
            # a tight scan first (the loop below is too big to run fast), eight bytes at a time
            per_word = 8 // policy.itemsize
            n_words = S // per_word
            policy_words = policy[:n_words * per_word].view(np.uint64)
            last_words = last[:n_words * per_word].view(np.uint64)
            for w in range(n_words):
                if policy_words[w] != last_words[w]:
                    for s in range(w * per_word, (w + 1) * per_word):
                        if policy[s] != last[s]:
                            dirty_list[n_todo] = s
                            n_todo += 1
            for s in range(n_words * per_word, S):
                if policy[s] != last[s]:
                    dirty_list[n_todo] = s
                    n_todo += 1
        for i in range(n_todo):
            s = dirty_list[i] if carry else members[i]
            row = policy[s] * S + s
            o = policy[s]
            x = row_r[s, o]
            if np.isnan(x):
                acc = 0.0
                for k in range(indptr[row], indptr[row + 1]):
                    acc += data[k] * V[indices[k]]
                x = acc + R_t[o, s] - V[s]
                row_r[s, o] = x
            r[s] = x
            last[s] = policy[s]
            if abs(r[s]) > theta:
                fifo[tail] = s
                tail += 1
                queued[s] = True
                count += 1
        if not carry:
            work += nnz
        while True:
            if tail == S:
                tail = 0
            while count > 0:
                s = fifo[head]
                head += 1
                if head == S:
                    head = 0
                count -= 1
                queued[s] = False
                change = r[s] / (1.0 - diag[policy[s] * S + s])
                V[s] += change
                block_sums[s >> 8] = np.nan
                r[s] = 0.0
                if not dirty[s]:
                    dirty[s] = True
                    dirty_list[n_dirty] = s
                    n_dirty += 1
                for o in range(n_opts):  # every row of s reads V(s)
                    row_r[s, o] = np.nan
                for k in range(col_ptr[s], col_ptr[s + 1]):
                    q = col_row[k]
                    p = q % S
                    row_r[p, q // S] = np.nan  # a row with s as successor
                    if p == s or not reach[p] or q != policy[p] * S + p:
                        continue
                    r[p] += col_val[k] * change
                    if not dirty[p]:
                        dirty[p] = True
                        dirty_list[n_dirty] = p
                        n_dirty += 1
                    if not queued[p] and abs(r[p]) > theta:
                        queued[p] = True
                        fifo[tail] = p
                        tail += 1
                        if tail == S:
                            tail = 0
                        count += 1
                work += col_ptr[s + 1] - col_ptr[s] + 1
                if work > allowed:
                    while count > 0:  # leave the flags clear for the next call
                        queued[fifo[head]] = False
                        head += 1
                        if head == S:
                            head = 0
                        count -= 1
                    for j in range(n_dirty):
                        dirty[dirty_list[j]] = False
                    return 0.0, 1, n, work / nnz
            # the residual computed afresh (no rounding carried over), the bound's input: on
            # the dirty states, in members order (the others' would come out the same)
            head = 0
            tail = 0
            order = np.empty(n_dirty, dtype=np.int64)
            for j in range(n_dirty):
                order[j] = rank[dirty_list[j]]
            order.sort()
            for j in range(n_dirty):
                s = members[order[j]]
                dirty[s] = False
                row = policy[s] * S + s
                o = policy[s]
                x = row_r[s, o]
                if np.isnan(x):
                    acc = 0.0
                    for k in range(indptr[row], indptr[row + 1]):
                        acc += data[k] * V[indices[k]]
                    x = acc + R_t[o, s] - V[s]
                    row_r[s, o] = x
                r[s] = x
                last[s] = policy[s]
                if abs(r[s]) > theta:
                    fifo[tail] = s
                    tail += 1
                    queued[s] = True
                    count += 1
            n_dirty = 0
            work += nnz
            if count == 0:
                # sum mu V by blocks of 256 terms, each in four interleaved partial sums: one
                # running sum waits on every addition (1 ms per ten policies at 10^5 states)
                # and its rounding grows with S (3.7e-11 of a start value near -20 at 10^5);
                # with every state a start, a block's sum is kept until one of its values moves
                total = 0.0
                for block in range((n + 255) >> 8):
                    if full and not np.isnan(block_sums[block]):
                        total += block_sums[block]  # no value in it moved: the same bits
                        continue
                    lo = block << 8
                    hi = min(lo + 256, n)
                    part0 = 0.0
                    part1 = 0.0
                    part2 = 0.0
                    part3 = 0.0
                    if full:
                        for i in range(lo, hi - 3, 4):
                            part0 += mu[i] * V[i]
                            part1 += mu[i + 1] * V[i + 1]
                            part2 += mu[i + 2] * V[i + 2]
                            part3 += mu[i + 3] * V[i + 3]
                    else:
                        for i in range(lo, hi - 3, 4):
                            part0 += mu[members[i]] * V[members[i]]
                            part1 += mu[members[i + 1]] * V[members[i + 1]]
                            part2 += mu[members[i + 2]] * V[members[i + 2]]
                            part3 += mu[members[i + 3]] * V[members[i + 3]]
                    for i in range(hi - (hi - lo) % 4, hi):
                        s = i if full else members[i]
                        part0 += mu[s] * V[s]
                    block_total = (part0 + part1) + (part2 + part3)
                    if full:
                        block_sums[block] = block_total
                    total += block_total
                return total, 0, n, work / nnz

    return start_value_push
