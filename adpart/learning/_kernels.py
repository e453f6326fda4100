"""The lock-step Q-learning kernels: one rule, three implementations that agree bit for bit.

Every kernel advances K independent agents, each with its own Q table, visit counts and
pre-drawn uniforms, until every agent has completed ``target[k]`` episodes (then it returns 0)
or until some still-active agent has used up its uniforms (then it returns 1 and the driver in
:mod:`adpart.learning.qlearning` refills that agent's row from its own generator). The K runs
advance together in rounds: in each round every active agent takes its next steps, and no agent
starts a new round before all have finished the last one.

One agent-step (Watkins' Q-learning, dissertation eq. 2.4) consumes exactly four uniforms
``u = U[k, cursor[k]]``:

1. ``n(s) += 1``; ``epsilon = max(floor, eps_ep[k] * n(s)**-omega)`` (see
   :mod:`adpart.learning.schedules`; ``eps_ep[k] = scale * rate**episode`` is cached per episode);
2. if ``u[0] < epsilon`` the action is the ``floor(u[1] * m)``-th of the ``m`` admissible
   actions of ``s`` (uniform exploration restricted to admissible actions); otherwise it is the
   ``floor(u[1] * t)``-th of the ``t`` actions tied for ``max_a Q(s, a)`` (random tie-breaking;
   inadmissible entries hold ``-inf`` and never tie);
3. ``s'`` = the successor whose row-offset cumulative probability
   (``FiniteMDP.sampler_keys``) is the
   first to exceed ``a*S + s + u[2]`` -- exactly :meth:`FiniteMDP.sample_next` with ``u[2]``;
4. ``n(s, a) += 1``; ``alpha = max(floor, alpha_ep[k] * n(s, a)**-omega)``;
   ``target = r`` if ``s'`` is terminal (episode over on arrival, no bootstrap), else
   ``r + gamma * max_a' Q(s', a')``; ``Q(s, a) += alpha * (target - Q(s, a))``;
5. the episode ends on arrival in a terminal state or after ``H`` steps (then the target above
   still bootstraps: the cut is not part of the task); at its end the next start state is the
   first state whose cumulative start probability exceeds ``u[3]``. ``u[3]`` is drawn on every
   step and used only at an episode's end, so the stream position depends only on the number
   of steps taken.

Because each agent reads only its own uniforms, a run's trajectory is independent of the order
in which agents are advanced and of how many other agents run beside it; the three kernels
differ only in that order and in their speed:

* ``numba``: the round loop compiled with numba; in a round each active agent uses up the rest
  of its buffer of uniforms (:data:`NUMBA_STRIDE`), and the agents of a round run in parallel
  on numba's threads (``NUMBA_NUM_THREADS``; one per core by default). It is the default
  (benchmarks/bench_qlearning.py prints its rate against the Python loop).
* ``numpy``: strict lock-step (all active agents take step t, then step t+1), each step
  vectorised over the active agents; its
  cost is dominated by ~30 numpy calls per step, so it gains only a few times over Python at
  K = 50.
* ``python``: a plain per-agent Python loop; the reference implementation the tests compare
  the others against, and the benchmark's baseline.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

#: Uniforms per agent-step (explore?, which action, successor, next start).
UNIFORMS_PER_STEP = 4


@dataclass
class LockStepState:
    """All arrays a kernel reads and writes (the driver owns them; kernels mutate in place).

    Model (read-only): ``keys`` (nnz,) row-offset cumulative probabilities; ``indptr``
    (A*S+1,) and ``indices`` (nnz,) of the transition CSR; ``R`` (S, A); ``terminal`` (S,) bool;
    ``adm_ptr`` (S+1,) / ``adm_idx`` admissible actions of each state in CSR form;
    ``start_cdf`` (S,) cumulative start distribution; ``last_start`` the last state with
    positive start probability; ``gamma``; ``horizon`` (steps per episode).

    Per agent (K leading axis): ``Q`` (K, S, A) with ``-inf`` on inadmissible pairs; ``n_sa``
    (K, S, A) and ``n_s`` (K, S) visit counts; ``state``; ``episode`` (completed episodes);
    ``target`` (episodes to complete before returning); ``t_ep``, ``ret``, ``dret``, ``gpow``
    (steps, undiscounted and discounted return, ``gamma**t`` of the current episode);
    ``alpha_ep`` / ``eps_ep`` (``scale * rate**episode`` of each schedule); ``U`` (K, B, 4)
    uniforms and ``cursor`` (K,) the next unused row.

    Outputs (K, N): ``out_steps``, ``out_ret``, ``out_dret`` per completed episode.
    ``cache``: kernel-private lookup tables (the numpy kernel's power tables).
    """

    keys: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    R: np.ndarray
    terminal: np.ndarray
    adm_ptr: np.ndarray
    adm_idx: np.ndarray
    start_cdf: np.ndarray
    last_start: int
    gamma: float
    horizon: int
    alpha: tuple[float, float, float, float]
    eps: tuple[float, float, float, float]
    Q: np.ndarray
    n_sa: np.ndarray
    n_s: np.ndarray
    state: np.ndarray
    episode: np.ndarray
    target: np.ndarray
    t_ep: np.ndarray
    ret: np.ndarray
    dret: np.ndarray
    gpow: np.ndarray
    alpha_ep: np.ndarray
    eps_ep: np.ndarray
    U: np.ndarray
    cursor: np.ndarray
    out_steps: np.ndarray
    out_ret: np.ndarray
    out_dret: np.ndarray
    cache: dict = field(default_factory=dict)

    def start_state(self, u: float) -> int:
        """The start state drawn by uniform ``u`` (first cumulative probability above ``u``)."""
        return min(int(np.searchsorted(self.start_cdf, u, side="right")), self.last_start)

    def episode_factors(self, k: int | np.ndarray) -> None:
        """Cache ``scale * rate**episode`` of both schedules for agent(s) ``k``."""
        e = self.episode[k].astype(np.float64)
        self.alpha_ep[k] = self.alpha[0] * np.power(self.alpha[1], e)
        self.eps_ep[k] = self.eps[0] * np.power(self.eps[1], e)


# --------------------------------------------------------------------------- python reference


def python_kernel(st: LockStepState) -> int:
    """Plain per-agent Python loop (the reference and the benchmark baseline).

    It keeps list copies of the model and of each agent's tables in ``st.cache`` between calls
    and writes back only the rows it changed, so ``st.Q``, ``st.n_sa`` and ``st.n_s`` are
    current whenever it returns; nothing else may write them between calls.
    """
    S, A = st.R.shape
    B = st.U.shape[1]
    if "python_model" not in st.cache:  # convert the read-only model to lists once
        st.cache["python_model"] = tuple(x.tolist() for x in (
            st.keys, st.indptr, st.indices, st.R, st.terminal, st.adm_ptr, st.adm_idx,
            st.start_cdf))
        st.cache["python_agents"] = {}
    keys, indptr, indices, R, terminal, adm_ptr, adm_idx, cdf = st.cache["python_model"]
    agents = st.cache["python_agents"]
    gamma, horizon = st.gamma, st.horizon
    a_scale, a_rate, a_omega, a_floor = st.alpha
    e_scale, e_rate, e_omega, e_floor = st.eps
    needs_refill = 0
    for k in range(st.Q.shape[0]):
        if k not in agents:  # per-agent tables as lists, kept between calls
            agents[k] = (st.Q[k].tolist(), st.n_sa[k].tolist(), st.n_s[k].tolist())
        Qk, n_sa, n_s = agents[k]
        touched = set()
        U = st.U[k].tolist()
        c = int(st.cursor[k])
        s, ep, tgt = int(st.state[k]), int(st.episode[k]), int(st.target[k])
        t_ep, ret, dret, gpow = int(st.t_ep[k]), float(st.ret[k]), float(st.dret[k]), float(
            st.gpow[k])
        alpha_ep, eps_ep = float(st.alpha_ep[k]), float(st.eps_ep[k])
        while ep < tgt:
            if c == B:
                needs_refill = 1
                break
            u0, u1, u2, u3 = U[c]
            c += 1
            n_s[s] += 1
            eps = eps_ep * n_s[s] ** -e_omega if e_omega != 0.0 else eps_ep
            eps = max(e_floor, eps)
            q = Qk[s]
            touched.add(s)
            if u0 < eps:
                lo, m = adm_ptr[s], adm_ptr[s + 1] - adm_ptr[s]
                a = adm_idx[lo + min(int(u1 * m), m - 1)]
            else:
                best = max(q)
                ties = [b for b in range(A) if q[b] == best]
                a = ties[min(int(u1 * len(ties)), len(ties) - 1)]
            row = a * S + s
            j = bisect.bisect_right(keys, row + u2, indptr[row], indptr[row + 1])
            s2 = indices[min(j, indptr[row + 1] - 1)]
            r = R[s][a]
            n_sa[s][a] += 1
            alpha = alpha_ep * n_sa[s][a] ** -a_omega if a_omega != 0.0 else alpha_ep
            alpha = max(a_floor, alpha)
            done = terminal[s2]
            td_target = r if done else r + gamma * max(Qk[s2])
            q[a] = q[a] + alpha * (td_target - q[a])
            ret += r
            dret += gpow * r
            gpow *= gamma
            t_ep += 1
            if done or t_ep == horizon:
                st.out_steps[k, ep], st.out_ret[k, ep], st.out_dret[k, ep] = t_ep, ret, dret
                ep += 1
                t_ep, ret, dret, gpow = 0, 0.0, 0.0, 1.0
                s = min(bisect.bisect_right(cdf, u3), st.last_start)
                alpha_ep = a_scale * a_rate ** float(ep)
                eps_ep = e_scale * e_rate ** float(ep)
            else:
                s = s2
        rows = sorted(touched)  # write back only the rows this call changed
        if rows:
            st.Q[k, rows] = [Qk[s] for s in rows]
            st.n_sa[k, rows] = [n_sa[s] for s in rows]
            st.n_s[k, rows] = [n_s[s] for s in rows]
        st.cursor[k] = c
        st.state[k], st.episode[k], st.t_ep[k] = s, ep, t_ep
        st.ret[k], st.dret[k], st.gpow[k] = ret, dret, gpow
        st.alpha_ep[k], st.eps_ep[k] = alpha_ep, eps_ep
    return needs_refill


# --------------------------------------------------------------------------- numpy lock-step


def _pow_table(cache: dict, key: tuple, base: float | None, exponent: float | None, size: int
               ) -> np.ndarray:
    """``table[i] = base**i`` (or ``i**exponent``) computed with the C library's ``pow``.

    numpy's SIMD ``power`` may differ from libm's ``pow`` in the last bit; the compiled and the
    Python kernels call libm, so the numpy kernel looks powers up in tables built with
    :func:`math.pow` to stay bit-identical. Tables grow geometrically as counts grow.
    """
    table = cache.get(key)
    if table is None or len(table) < size:
        n = max(size, 2 * (0 if table is None else len(table)), 1024)
        if base is not None:
            table = np.array([math.pow(base, float(i)) for i in range(n)])
        else:
            table = np.array([math.pow(float(i), exponent) if i else 0.0 for i in range(n)])
        cache[key] = table
    return table


def numpy_kernel(st: LockStepState) -> int:
    """Lock-step loop, one vectorised step over all active agents per iteration."""
    _K, S, A = st.Q.shape
    B = st.U.shape[1]
    N = st.out_steps.shape[1]
    cache = st.cache
    a_rate_pow = _pow_table(cache, ("rate", st.alpha[1]), st.alpha[1], None, N + 1)
    e_rate_pow = _pow_table(cache, ("rate", st.eps[1]), st.eps[1], None, N + 1)
    # Within one call an agent takes at most B steps, so counts grow by at most B.
    bound = int(max(st.n_s.max(initial=0), st.n_sa.max(initial=0))) + B + 1
    a_visit_pow = _pow_table(cache, ("visits", -st.alpha[2]), None, -st.alpha[2], bound)
    e_visit_pow = _pow_table(cache, ("visits", -st.eps[2]), None, -st.eps[2], bound)
    Qf = st.Q.reshape(-1)
    nsa_f = st.n_sa.reshape(-1)
    nsf = st.n_s.reshape(-1)
    adm = np.zeros((S, A), dtype=bool)
    adm[np.repeat(np.arange(S), np.diff(st.adm_ptr)), st.adm_idx] = True
    a_scale, _, a_omega, a_floor = st.alpha
    e_scale, _, e_omega, e_floor = st.eps
    while True:
        act = np.flatnonzero(st.episode < st.target)
        if act.size == 0:
            return 0
        c = st.cursor[act]
        if np.any(c == B):
            return 1
        u = st.U[act, c]
        st.cursor[act] = c + 1
        s = st.state[act]
        ks = act * S + s
        nsf[ks] += 1
        eps = st.eps_ep[act]
        if e_omega != 0.0:
            eps = eps * e_visit_pow[nsf[ks]]
        eps = np.maximum(e_floor, eps)
        q = st.Q[act, s]  # (n, A)
        explore = u[:, 0] < eps
        mask = np.where(explore[:, None], adm[s], q == q.max(axis=1, keepdims=True))
        count = mask.sum(axis=1)
        j = np.minimum((u[:, 1] * count).astype(np.int64), count - 1)
        a = np.argmax(np.cumsum(mask, axis=1) > j[:, None], axis=1)
        row = a * S + s
        pos = np.searchsorted(st.keys, row + u[:, 2], side="right")
        s2 = st.indices[np.minimum(pos, st.indptr[row + 1] - 1)]
        r = st.R[s, a]
        ksa = ks * A + a
        nsa_f[ksa] += 1
        alpha = st.alpha_ep[act]
        if a_omega != 0.0:
            alpha = alpha * a_visit_pow[nsa_f[ksa]]
        alpha = np.maximum(a_floor, alpha)
        done = st.terminal[s2]
        best_next = st.Q[act, s2].max(axis=1)
        td_target = np.where(done, r, r + st.gamma * best_next)
        old = Qf[ksa]
        Qf[ksa] = old + alpha * (td_target - old)
        st.ret[act] += r
        st.dret[act] += st.gpow[act] * r
        st.gpow[act] *= st.gamma
        st.t_ep[act] += 1
        end = done | (st.t_ep[act] == st.horizon)
        st.state[act] = s2
        if end.any():
            ek = act[end]
            ep = st.episode[ek]
            st.out_steps[ek, ep] = st.t_ep[ek]
            st.out_ret[ek, ep] = st.ret[ek]
            st.out_dret[ek, ep] = st.dret[ek]
            st.episode[ek] += 1
            st.t_ep[ek] = 0
            st.ret[ek] = 0.0
            st.dret[ek] = 0.0
            st.gpow[ek] = 1.0
            starts = np.searchsorted(st.start_cdf, u[end, 3], side="right")
            st.state[ek] = np.minimum(starts, st.last_start)
            st.alpha_ep[ek] = a_scale * a_rate_pow[st.episode[ek]]
            st.eps_ep[ek] = e_scale * e_rate_pow[st.episode[ek]]


# --------------------------------------------------------------------------- numba lock-step

_NUMBA_KERNEL: Callable[..., int] | None = None


def numba_available() -> bool:
    """Whether numba can be imported (the ``numba`` kernel is then the default)."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def _compile_numba() -> Callable[..., int]:
    import numba

    from adpart.mdp._sampling import first_above, successor

    @numba.njit(cache=True, nogil=True)
    def advance(k, stride, keys, indptr, indices, R, terminal, adm_ptr, adm_idx, start_cdf,
                last_start, gamma, horizon, a_scale, a_rate, a_omega, a_floor, e_scale, e_rate,
                e_omega, e_floor, a_pow, e_pow, Q, n_sa, n_s, state, episode, target, t_ep, ret,
                dret, gpow, alpha_ep, eps_ep, U, cursor, out_steps, out_ret,
                out_dret):  # pragma: no cover
        """Agent ``k`` takes up to ``stride`` steps (it reads and writes only its own rows)."""
        S, A = R.shape
        B = U.shape[1]
        n_start = start_cdf.shape[0]
        n_pow = a_pow.shape[0]
        for _ in range(stride):
            if episode[k] >= target[k] or cursor[k] == B:
                break
            c = cursor[k]
            u0 = U[k, c, 0]
            u1 = U[k, c, 1]
            u2 = U[k, c, 2]
            u3 = U[k, c, 3]
            cursor[k] = c + 1
            s = state[k]
            n_s[k, s] += 1
            eps = eps_ep[k]
            if e_omega != 0.0:
                n = n_s[k, s]
                eps = eps * (e_pow[n] if n < n_pow else float(n) ** -e_omega)
            eps = max(e_floor, eps)
            if u0 < eps:
                lo = adm_ptr[s]
                m = adm_ptr[s + 1] - lo
                j = min(int(u1 * m), m - 1)
                a = adm_idx[lo + j]
            else:
                best = Q[k, s, 0]  # one pass: the maximum, its first action, the ties
                a = 0
                t = 1
                for b in range(1, A):
                    q = Q[k, s, b]
                    if q > best:
                        best = q
                        a = b
                        t = 1
                    elif q == best:
                        t += 1
                if t > 1:
                    j = min(int(u1 * t), t - 1)
                    for b in range(A):
                        if Q[k, s, b] == best:
                            if j == 0:
                                a = b
                                break
                            j -= 1
            s2 = successor(a * S + s, u2, keys, indptr, indices)
            r = R[s, a]
            n_sa[k, s, a] += 1
            alpha = alpha_ep[k]
            if a_omega != 0.0:
                n = n_sa[k, s, a]
                alpha = alpha * (a_pow[n] if n < n_pow else float(n) ** -a_omega)
            alpha = max(a_floor, alpha)
            done = terminal[s2]
            if done:
                td_target = r
            else:
                best_next = Q[k, s2, 0]
                for b in range(1, A):
                    best_next = max(best_next, Q[k, s2, b])
                td_target = r + gamma * best_next
            old = Q[k, s, a]
            Q[k, s, a] = old + alpha * (td_target - old)
            ret[k] += r
            dret[k] += gpow[k] * r
            gpow[k] *= gamma
            t_ep[k] += 1
            if done or t_ep[k] == horizon:
                ep = episode[k]
                out_steps[k, ep] = t_ep[k]
                out_ret[k, ep] = ret[k]
                out_dret[k, ep] = dret[k]
                ep += 1
                episode[k] = ep
                t_ep[k] = 0
                ret[k] = 0.0
                dret[k] = 0.0
                gpow[k] = 1.0
                state[k] = min(first_above(start_cdf, u3, 0, n_start), last_start)
                alpha_ep[k] = a_scale * a_rate ** float(ep)
                eps_ep[k] = e_scale * e_rate ** float(ep)
            else:
                state[k] = s2


    @numba.njit(cache=True, nogil=True, parallel=True)
    def lockstep(keys, indptr, indices, R, terminal, adm_ptr, adm_idx, start_cdf, last_start,
                 gamma, horizon, a_scale, a_rate, a_omega, a_floor, e_scale, e_rate, e_omega,
                 e_floor, stride, a_pow, e_pow, Q, n_sa, n_s, state, episode, target, t_ep, ret,
                 dret, gpow, alpha_ep, eps_ep, U, cursor, out_steps, out_ret,
                 out_dret):  # pragma: no cover
        K = Q.shape[0]
        B = U.shape[1]
        while True:
            any_active = False
            for k in range(K):
                if episode[k] < target[k]:
                    any_active = True
                    if cursor[k] == B:
                        return 1
            if not any_active:
                return 0
            for k in numba.prange(K):
                advance(k, stride, keys, indptr, indices, R, terminal, adm_ptr, adm_idx,
                        start_cdf, last_start, gamma, horizon, a_scale, a_rate, a_omega, a_floor,
                        e_scale, e_rate, e_omega, e_floor, a_pow, e_pow, Q, n_sa, n_s, state,
                        episode, target, t_ep, ret, dret, gpow, alpha_ep, eps_ep, U, cursor,
                        out_steps, out_ret, out_dret)

    return lockstep


#: Visit counts below this read ``n**-omega`` from a table (32 KiB, stays in L1/L2 cache)
#: instead of calling ``pow`` -- a third of the step's cost with visit-count schedules.
NUMBA_POW_TABLE = 4096

#: Steps each agent takes per round in the numba kernel. A whole buffer (the default) keeps one
#: agent's tables in cache for its whole stretch and needs one thread synchronisation per
#: buffer; measured at K = 50 on a 10^4-state grid, one thread: 7.8 M agent-steps/s with 16
#: steps a round, 10.1 M with a whole buffer.
NUMBA_STRIDE = 1 << 30


def numba_kernel(st: LockStepState, stride: int = NUMBA_STRIDE) -> int:
    """Lock-step loop compiled with numba (compiled once per process, cached on disk).

    In each round every active agent takes up to ``stride`` steps, the agents spread over
    numba's threads; ``stride = 1`` is strict lock-step. Results depend neither on the stride
    nor on the number of threads: each run reads only its own uniforms and writes only its own
    rows.
    """
    global _NUMBA_KERNEL
    if _NUMBA_KERNEL is None:
        _NUMBA_KERNEL = _compile_numba()
    a_pow = _pow_table(st.cache, ("visits", -st.alpha[2]), None, -st.alpha[2], NUMBA_POW_TABLE)
    e_pow = _pow_table(st.cache, ("visits", -st.eps[2]), None, -st.eps[2], NUMBA_POW_TABLE)
    return int(_NUMBA_KERNEL(
        st.keys, st.indptr, st.indices, st.R, st.terminal, st.adm_ptr, st.adm_idx, st.start_cdf,
        st.last_start, st.gamma, st.horizon, *st.alpha, *st.eps, stride,
        a_pow[:NUMBA_POW_TABLE], e_pow[:NUMBA_POW_TABLE], st.Q, st.n_sa, st.n_s, st.state,
        st.episode, st.target, st.t_ep, st.ret, st.dret, st.gpow, st.alpha_ep, st.eps_ep, st.U,
        st.cursor, st.out_steps, st.out_ret, st.out_dret,
    ))


KERNELS: dict[str, Callable[[LockStepState], int]] = {
    "numba": numba_kernel,
    "numpy": numpy_kernel,
    "python": python_kernel,
}
