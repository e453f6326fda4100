"""Compiled (numba) kernels of the exact solvers in :mod:`adpart.mdp.solvers`; optional.

The solvers use these when numba imports and scipy/numpy otherwise (``kernel="numba"`` or
``"numpy"``; see ``docs/solvers.md``). Each kernel reads the action-major CSR ``F`` (row
``o*S + s`` = ``F(. | s, o)``, eq. 3.2 of the dissertation) in place:

* :func:`bellman_backup` -- the full Jacobi backup ``T V`` in one pass over the states: for each
  ``s`` the ``O`` rows ``o*S + s`` give ``Q(s, o) = R(s, o) + F(.|s,o) V`` one after another and
  only their running maximum and lowest-index argmax are kept (no ``(O, S)`` temporary and no
  separate greedy pass); the same pass returns ``max`` and ``min`` of ``T V - V``, all the
  stopping rules need.
* :func:`gather_policy` -- the policy's rows ``F_pi`` (row ``pi(s)*S + s`` of ``F``) and
  ``R_pi`` as a compact CSR, so that the evaluation sweeps stream through memory (reading the
  rows in place from ``F`` touches a cache line of each of the ``O`` blocks per state and measured
  4x slower per product on an optimal grid policy).
* :func:`policy_product` -- ``R_pi + F_pi V`` on that compact CSR (one Jacobi ``T_pi`` sweep).
* :func:`gauss_seidel_backup` -- one in-place Gauss-Seidel Bellman sweep in a given state order
  (:func:`adpart.mdp.solvers.gauss_seidel_value_iteration`), and :func:`backward_bfs_order`,
  the order it sweeps in: states by their distance to the sinks (terminal states or the states
  with the best rewards), so that one sweep carries value from the sinks outwards.
* :func:`greedy_rows` -- the lowest-index argmax of every row of a ``(N, A)`` table, in
  parallel (``np.argmax(axis=1)`` walks the short axis; 5x slower on the learners' (K*S, A) Q).
* :func:`gauss_seidel_evaluation` -- in-place Gauss-Seidel sweeps of ``T_pi`` (Puterman 6.3.3):
  each state's new value is used at once by the states after it, which halves the memory
  traffic of a Jacobi sweep (no second vector) and converges at least as fast on grid MDPs.

Accumulation order is scipy's ``csr_matvec`` (``acc = 0; acc += data[k] * x[indices[k]]``, then
the reward added), so :func:`bellman_backup`, :func:`gather_policy` and :func:`policy_product`
are bit-identical to the numpy path (tested in ``tests/mdp/test_solver_kernels.py``).

The kernels are compiled on first use with ``cache=True`` (a few seconds once per machine, then
loaded from ``__pycache__`` in well under a second).
"""

from __future__ import annotations

from types import SimpleNamespace

_LOADED: SimpleNamespace | None = None
_TRIED = False


def numba_available() -> bool:
    """Whether numba can be imported (the compiled kernels are then the solvers' default)."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def load() -> SimpleNamespace | None:
    """The compiled kernels, or ``None`` when numba cannot be imported.

    numba is imported here, on the first exact solve that wants it, not when
    :mod:`adpart.mdp.solvers` is imported, so importing adpart stays fast.
    """
    global _LOADED, _TRIED
    if not _TRIED:
        _TRIED = True
        if numba_available():
            _LOADED = _compile()
    return _LOADED


def _compile() -> SimpleNamespace:  # pragma: no cover - compiled code is invisible to coverage
    import numba
    import numpy as np

    jit = numba.njit(cache=True, nogil=True, boundscheck=False)

    @jit
    def bellman_backup(indptr, indices, data, R_t, V, V_new, policy):
        """``V_new = T V`` and its lowest-index greedy ``policy``; returns ``(max, min)`` of
        ``V_new - V``. Inadmissible pairs have ``R_t = -inf`` and so never win the maximum
        (skipping them with a branch measured 2x slower than computing them)."""
        n_opt, S = R_t.shape
        dmax = -np.inf
        dmin = np.inf
        for s in range(S):
            best = -np.inf
            arg = 0
            for o in range(n_opt):
                row = o * S + s
                acc = 0.0
                for k in range(indptr[row], indptr[row + 1]):
                    acc += data[k] * V[indices[k]]
                q = acc + R_t[o, s]
                if q > best:
                    best = q
                    arg = o
            V_new[s] = best
            policy[s] = arg
            d = best - V[s]
            dmax = max(dmax, d)
            dmin = min(dmin, d)
        return dmax, dmin

    @jit
    def gather_policy(indptr, indices, data, R_t, policy):
        """``(indptr_pi, indices_pi, data_pi, R_pi)``: rows ``pi(s)*S + s`` as a compact CSR."""
        S = R_t.shape[1]
        ptr = np.empty(S + 1, dtype=indptr.dtype)
        ptr[0] = 0
        for s in range(S):
            row = policy[s] * S + s
            ptr[s + 1] = ptr[s] + indptr[row + 1] - indptr[row]
        idx = np.empty(ptr[S], dtype=indices.dtype)
        val = np.empty(ptr[S], dtype=data.dtype)
        R_pi = np.empty(S)
        for s in range(S):
            row = policy[s] * S + s
            j = ptr[s]
            for k in range(indptr[row], indptr[row + 1]):
                idx[j] = indices[k]
                val[j] = data[k]
                j += 1
            R_pi[s] = R_t[policy[s], s]
        return ptr, idx, val, R_pi

    @jit
    def policy_product(ptr, idx, val, R_pi, V, out):
        """``out = R_pi + F_pi V`` (one Jacobi sweep of ``T_pi``)."""
        for s in range(V.shape[0]):
            acc = 0.0
            for k in range(ptr[s], ptr[s + 1]):
                acc += val[k] * V[idx[k]]
            out[s] = acc + R_pi[s]

    @jit
    def gauss_seidel_evaluation(ptr, idx, val, R_pi, V, target, max_sweeps, span):
        """In-place Gauss-Seidel sweeps ``V(s) <- R_pi(s) + F_pi(.|s) V`` until the sweep's
        changes have span (``span``) or sup norm at most ``target``, or ``max_sweeps``;
        returns the number of sweeps."""
        S = V.shape[0]
        sweeps = 0
        while sweeps < max_sweeps:
            lo = np.inf
            hi = -np.inf
            for s in range(S):
                acc = 0.0
                for k in range(ptr[s], ptr[s + 1]):
                    acc += val[k] * V[idx[k]]
                v_s = acc + R_pi[s]
                d = v_s - V[s]
                V[s] = v_s
                hi = max(hi, d)
                lo = min(lo, d)
            sweeps += 1
            stat = hi - lo if span else max(hi, -lo)
            if not stat > target:  # also stops on NaN (a diverging undiscounted evaluation)
                break
        return sweeps

    @numba.njit(cache=True, nogil=True, parallel=True)
    def greedy_rows(Q, out):
        """``out[i] = argmax_a Q[i, a]``, lowest index on ties (as ``np.argmax``; Q has no NaN)."""
        n, A = Q.shape
        for i in numba.prange(n):
            best = Q[i, 0]
            arg = 0
            for a in range(1, A):
                if Q[i, a] > best:
                    best = Q[i, a]
                    arg = a
            out[i] = arg

    @jit
    def gauss_seidel_backup(indptr, indices, data, R_t, V, order, policy):
        """One in-place Gauss-Seidel Bellman sweep over the states in ``order``: each
        ``V(s) <- max_o R(s, o) + F(.|s, o) V`` uses the values already updated in this sweep
        (Puterman 6.3.3); ``policy`` gets the lowest-index argmax. Returns ``(max, min)`` of
        the changes."""
        n_opt, S = R_t.shape
        dmax = -np.inf
        dmin = np.inf
        for i in range(order.shape[0]):
            s = order[i]
            best = -np.inf
            arg = 0
            for o in range(n_opt):
                row = o * S + s
                acc = 0.0
                for k in range(indptr[row], indptr[row + 1]):
                    acc += data[k] * V[indices[k]]
                q = acc + R_t[o, s]
                if q > best:
                    best = q
                    arg = o
            d = best - V[s]
            V[s] = best
            policy[s] = arg
            dmax = max(dmax, d)
            dmin = min(dmin, d)
        return dmax, dmin

    @jit
    def predecessors(indptr, indices, S):
        """CSR (int64 pointers, int32 states) of the predecessors of every state under any
        option of the action-major ``F`` (duplicates kept: only reachability is read)."""
        ptr = np.zeros(S + 1, dtype=np.int64)
        for k in range(indices.shape[0]):
            ptr[indices[k] + 1] += 1
        for t in range(S):
            ptr[t + 1] += ptr[t]
        fill = ptr[:S].copy()
        idx = np.empty(indices.shape[0], dtype=np.int32)
        for row in range(indptr.shape[0] - 1):
            s = row % S
            for k in range(indptr[row], indptr[row + 1]):
                t = indices[k]
                idx[fill[t]] = s
                fill[t] += 1
        return ptr, idx

    @jit
    def index_order_agreement(indptr, indices, rank, S):
        """Among transitions ``s -> t`` towards the sinks (``rank[t] < rank[s]``), the share
        with ``t < s`` (the forward index order sweeps ``t`` first); 0.5 if there are none."""
        toward = 0
        forward = 0
        for row in range(indptr.shape[0] - 1):
            s = row % S
            for k in range(indptr[row], indptr[row + 1]):
                t = indices[k]
                if rank[t] < rank[s]:
                    toward += 1
                    if t < s:
                        forward += 1
        return forward / toward if toward > 0 else 0.5

    @jit
    def backward_bfs_order(pred_ptr, pred_idx, sources, S):
        """States by increasing number of steps to reach a source (multi-source BFS over the
        predecessor lists); states that reach none follow in index order."""
        order = np.empty(S, dtype=np.int64)
        seen = np.zeros(S, dtype=np.bool_)
        n = 0
        for i in range(sources.shape[0]):
            s = sources[i]
            if not seen[s]:
                seen[s] = True
                order[n] = s
                n += 1
        head = 0
        while head < n:
            t = order[head]
            head += 1
            for k in range(pred_ptr[t], pred_ptr[t + 1]):
                s = pred_idx[k]
                if not seen[s]:
                    seen[s] = True
                    order[n] = s
                    n += 1
        for s in range(S):
            if not seen[s]:
                order[n] = s
                n += 1
        return order

    return SimpleNamespace(
        gauss_seidel_backup=gauss_seidel_backup,
        backward_bfs_order=backward_bfs_order,
        predecessors=predecessors,
        index_order_agreement=index_order_agreement,
        greedy_rows=greedy_rows,
        bellman_backup=bellman_backup,
        gather_policy=gather_policy,
        policy_product=policy_product,
        gauss_seidel_evaluation=gauss_seidel_evaluation,
    )
