"""The lock-step Q-learning kernel: one source of the rule, run interpreted or compiled.

:func:`lockstep` is the rule, written once as plain Python over numpy arrays. The ``python``
kernel runs it in the interpreter (the reference); the ``numba`` kernel (the default) runs the
identical function compiled by numba, its agents spread over numba's threads. Both use only scalar
IEEE operations and ``math.pow`` (directly or through a table built with it), so they agree bit
for bit. The helpers both lock-step learners share -- the kernel names, the start-state draw, the
per-episode schedule factors, the visit-count power tables, the lazy compilation -- live here too;
:mod:`adpart.learning._smdp_kernels` imports them.

What one call does: it advances K independent agents, each with its own Q table, visit counts and
pre-drawn uniforms, until every agent has completed ``target[k]`` episodes (then it returns 0) or
until some still-active agent has used up its uniforms (then it returns 1 and the driver in
:mod:`adpart.learning.qlearning` refills that agent's row from its own generator). The K runs
advance together in rounds: in each round every active agent takes up to ``stride`` steps, and no
agent starts a new round before all have finished the last one.

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

Beside the rule, the kernel keeps the *evaluated* greedy policy current: ``policy[k, s]`` is the
lowest-index ``argmax_a Q(s, a)`` of every row (:func:`adpart.mdp.evaluation.greedy_policy`; the
driver fills it from the initial Q), and ``changed[k]`` is set whenever an update moves one of
run ``k``'s greedy actions. Only the updated entry can move it: if ``a`` was the greedy action and
its value fell, the row's maximiser is searched again (``A`` reads of a row in cache); otherwise
``a`` takes over when its new value beats the greedy one's (or ties it from a lower index). The
scoring between evaluation blocks therefore reads no Q and re-scores only runs whose policy moved
(:class:`adpart.learning.curves.StartValues`); no random number and no value depends on it.

Because each agent reads only its own uniforms and writes only its own rows, a run's trajectory
is independent of the order in which agents are advanced, of the stride, of numba's thread count
and of how many other agents run beside it; the two kernels differ only in speed
(benchmarks/bench_qlearning.py prints both rates). The one array agents share is the experience
count ``n_next``: each thread adds the transitions of the agents it advances to its own row, and
only the rows' sum (integers: exact in any order) is read, so it too is the same for every
thread count and order (the runs' experience, :class:`adpart.mdp.experience.Experience`). It
replaces a (K, nnz) count per run, whose summing and first touch cost about half as much as the
kernel itself at 10^5 states (docs/learning.md).
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numba
import numpy as np
from numba import get_thread_id, prange

from adpart.errors import UnknownNameError
from adpart.mdp._sampling import first_above

#: Uniforms per agent-step (explore?, which action, successor, next start).
UNIFORMS_PER_STEP = 4

#: The kernels of both lock-step learners: the rule run by the interpreter or compiled.
KERNEL_NAMES = ("numba", "python")


def default_kernel() -> str:
    """``"numba"``: the compiled rule (numba is a dependency; 50-90x the interpreted rule in
    benchmarks/bench_qlearning.py)."""
    return "numba"


def resolve_kernel(kernel: str | None, learner: str, aliases: Mapping[str, str] | None = None
                   ) -> str:
    """The kernel name to run: ``kernel``, :func:`default_kernel` for ``None``, or an alias's.

    Raises:
        UnknownNameError: ``kernel`` is neither a kernel nor an alias; the message names the
            valid values.
    """
    if kernel is None:
        return default_kernel()
    if aliases and kernel in aliases:
        target = aliases[kernel]
        warnings.warn(
            f"{learner} kernel {kernel!r} no longer exists (it ran the same rule as the others, "
            f"bit for bit); running {target!r} instead. Choose one of {list(KERNEL_NAMES)}.",
            FutureWarning, stacklevel=3,
        )
        return target
    if kernel not in KERNEL_NAMES:
        raise UnknownNameError(
            f"unknown {learner} kernel {kernel!r}; choose one of {list(KERNEL_NAMES)}"
        )
    return kernel


def njit_lazily(fn: Callable, **options) -> Callable:
    """``fn`` compiled by ``numba.njit(cache=True, nogil=True, **options)`` on its first call.

    Compiling at import would cost every process that never learns; numba's on-disk cache makes
    the first call of a later process cheap.
    """

    @functools.cache
    def compiled() -> Callable:
        return numba.njit(cache=True, nogil=True, **options)(fn)

    def call(*args):
        return compiled()(*args)

    call.__wrapped__ = fn
    return call


@functools.cache
def visit_power_table(omega: float, size: int) -> np.ndarray:
    """``table[n] = n**-omega`` for ``n < size`` (``table[0] = 0``, never read), by ``math.pow``.

    The kernels look visit-count powers up here instead of calling ``pow`` every step (a third of
    a step's cost with visit-count schedules); ``math.pow`` is libm's ``pow``, which the compiled
    rule calls past the table's end, so look-up and call agree bit for bit. (numpy's SIMD
    ``power`` may differ from libm in the last bit, hence no ``np.power``.) Read-only, shared.
    """
    table = np.array([math.pow(float(n), -omega) if n else 0.0 for n in range(size)])
    table.setflags(write=False)
    return table


class ScheduledAgents:
    """What the flat and the SMDP kernel states share: start draws and per-episode factors.

    Needs the attributes ``start_cdf``, ``last_start``, ``alpha`` / ``eps`` (a schedule's
    ``(scale, rate, omega, floor)``), ``episode``, ``alpha_ep`` and ``eps_ep``.
    """

    start_cdf: np.ndarray
    last_start: int
    alpha: tuple[float, float, float, float]
    eps: tuple[float, float, float, float]
    episode: np.ndarray
    alpha_ep: np.ndarray
    eps_ep: np.ndarray

    def start_state(self, u: float) -> int:
        """The start state drawn by uniform ``u`` (first cumulative probability above ``u``),
        exactly as the kernels draw it at an episode's end."""
        cdf = self.start_cdf
        return min(int(first_above(cdf, float(u), 0, cdf.shape[0])), self.last_start)

    def episode_factors(self, k: int | np.ndarray) -> None:
        """Cache ``scale * rate**episode`` of both schedules for agent(s) ``k`` (``math.pow``,
        as the kernels compute them at an episode's end)."""
        ks = np.atleast_1d(k)
        e = self.episode[ks].astype(np.float64)
        self.alpha_ep[ks] = [self.alpha[0] * math.pow(self.alpha[1], x) for x in e]
        self.eps_ep[ks] = [self.eps[0] * math.pow(self.eps[1], x) for x in e]


@dataclass
class LockStepState(ScheduledAgents):
    """All arrays the kernel reads and writes (the driver owns them; the kernel mutates in place).

    :meth:`args` passes them grouped as the paragraphs below, each tuple in the order named.

    Model (read-only): ``keys`` (nnz,) row-offset cumulative probabilities; ``indptr``
    (A*S+1,) and ``indices`` (nnz,) of the transition CSR; ``R`` (S, A); ``terminal`` (S,) bool;
    ``adm_ptr`` (S+1,) / ``adm_idx`` admissible actions of each state in CSR form;
    ``start_cdf`` (S,) cumulative start distribution; ``last_start`` the last state with
    positive start probability; ``gamma``; ``horizon`` (steps per episode).

    Per agent (K leading axis), the table: ``Q`` (K, S, A) with ``-inf`` on inadmissible pairs;
    ``n_sa`` (K, S, A) and ``n_s`` (K, S) visit counts; ``n_next`` (T, nnz) the agents'
    experience, how often each transition (CSR entry ``a*S + s -> s'``) was taken, summed over
    the agents each of the kernel's ``T`` threads advanced (row ``numba.get_thread_id()``; ``T``
    at least numba's thread count, see :func:`experience_rows`; the sum over the rows is the
    runs' experience whatever agent ran on which thread); the agents:
    ``state``; ``episode`` (completed episodes); ``target`` (episodes to complete before
    returning); ``t_ep``, ``ret``, ``dret``, ``gpow`` (steps, undiscounted and discounted
    return, ``gamma**t`` of the current episode); ``alpha_ep`` / ``eps_ep`` (``scale *
    rate**episode`` of each schedule); ``U`` (K, B, 4) uniforms and ``cursor`` (K,) the next
    unused row.

    Outputs (K, N): ``out_steps``, ``out_ret``, ``out_dret`` per completed episode. Evaluated
    greedy policies: ``policy`` (K, S), any signed integer dtype, lowest-index argmax of each row
    of Q (kept current by the kernel), and ``changed`` (K,) bool, set by the kernel when one of
    the run's greedy actions moves (cleared by the scorer).
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
    n_next: np.ndarray
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
    policy: np.ndarray
    changed: np.ndarray

    def args(self, stride: int) -> tuple:
        """:func:`lockstep`'s arguments, grouped as the class docstring's paragraphs: the model;
        the schedules ``(*alpha, *eps, a_pow, e_pow)`` with their visit-power tables; ``stride``;
        the table ``(Q, n_sa, n_s)``; the agents; the outputs. The tuples hold the state's arrays
        themselves, so what the kernel writes lands in the state."""
        return (
            (self.keys, self.indptr, self.indices, self.R, self.terminal, self.adm_ptr,
             self.adm_idx, self.start_cdf, self.last_start, self.gamma, self.horizon),
            (*self.alpha, *self.eps, visit_power_table(self.alpha[2], POW_TABLE),
             visit_power_table(self.eps[2], POW_TABLE)),
            stride,
            (self.Q, self.n_sa, self.n_s, self.n_next),
            (self.state, self.episode, self.target, self.t_ep, self.ret, self.dret, self.gpow,
             self.alpha_ep, self.eps_ep, self.U, self.cursor),
            (self.out_steps, self.out_ret, self.out_dret, self.policy, self.changed),
        )


def lockstep(model, schedules, stride, table, agents, outputs):
    """The rule of the module docstring; returns 0 (all done) or 1 (some agent needs uniforms).

    The arguments are the groups of :meth:`LockStepState.args`, unpacked here into the names the
    rule is written with."""
    (keys, indptr, indices, R, terminal, adm_ptr, adm_idx, start_cdf, last_start, gamma,
     horizon) = model
    a_scale, a_rate, a_omega, a_floor, e_scale, e_rate, e_omega, e_floor, a_pow, e_pow = schedules
    Q, n_sa, n_s, n_next = table
    (state, episode, target, t_ep, ret, dret, gpow, alpha_ep, eps_ep, U, cursor) = agents
    out_steps, out_ret, out_dret, policy, changed = outputs
    K = Q.shape[0]
    S = R.shape[0]
    A = R.shape[1]
    B = U.shape[1]
    n_start = start_cdf.shape[0]
    n_pow = a_pow.shape[0]
    while True:
        any_active = False
        for k in range(K):
            if episode[k] < target[k]:
                any_active = True
                if cursor[k] == B:
                    return 1
        if not any_active:
            return 0
        for k in prange(K):  # agents are independent: each reads and writes only its own rows
            tid = get_thread_id()  # ... but the experience counts, one row per thread
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
                    eps = eps * (e_pow[n] if n < n_pow else math.pow(float(n), -e_omega))
                eps = max(e_floor, eps)
                if u0 < eps:  # explore: the floor(u1 m)-th admissible action
                    lo = adm_ptr[s]
                    m = adm_ptr[s + 1] - lo
                    a = adm_idx[lo + min(int(u1 * m), m - 1)]
                else:  # greedy: one pass for the maximum, its first action and the ties
                    best = Q[k, s, 0]
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
                    if t > 1:  # the floor(u1 t)-th of the tied actions
                        j = min(int(u1 * t), t - 1)
                        for b in range(A):
                            if Q[k, s, b] == best:
                                if j == 0:
                                    a = b
                                    break
                                j -= 1
                row = a * S + s  # the successor: FiniteMDP.sample_next with u2
                hi = indptr[row + 1]
                pos = min(first_above(keys, row + u2, indptr[row], hi), hi - 1)
                s2 = indices[pos]
                n_next[tid, pos] += 1
                r = R[s, a]
                n_sa[k, s, a] += 1
                alpha = alpha_ep[k]
                if a_omega != 0.0:
                    n = n_sa[k, s, a]
                    alpha = alpha * (a_pow[n] if n < n_pow else math.pow(float(n), -a_omega))
                alpha = max(a_floor, alpha)
                done = terminal[s2]
                if done:  # eq. 2.4 without bootstrap: the episode is over on arrival
                    td_target = r
                else:
                    best_next = Q[k, s2, 0]
                    for b in range(1, A):
                        best_next = max(best_next, Q[k, s2, b])
                    td_target = r + gamma * best_next
                old = Q[k, s, a]
                new = old + alpha * (td_target - old)
                Q[k, s, a] = new
                g = policy[k, s]  # the evaluated greedy action (lowest index on ties)
                if a == g:
                    if new < old:  # the greedy value fell: search the row's maximiser again
                        best = Q[k, s, 0]
                        g2 = 0
                        for b in range(1, A):
                            if Q[k, s, b] > best:
                                best = Q[k, s, b]
                                g2 = b
                        if g2 != g:
                            policy[k, s] = g2
                            changed[k] = True
                elif new > Q[k, s, g] or (new == Q[k, s, g] and a < g):
                    policy[k, s] = a
                    changed[k] = True
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
                    alpha_ep[k] = a_scale * math.pow(a_rate, float(ep))
                    eps_ep[k] = e_scale * math.pow(e_rate, float(ep))
                else:
                    state[k] = s2


#: Visit counts below this read ``n**-omega`` from :func:`visit_power_table` (32 KiB, stays in
#: L1/L2 cache) instead of calling ``pow``.
POW_TABLE = 4096

#: Steps each agent takes per round. A whole buffer (the default) keeps one agent's tables in
#: cache for its whole stretch and needs one thread synchronisation per buffer; measured at
#: K = 50 on a 10^4-state grid, one thread: 7.8 M agent-steps/s with 16 steps a round, 10.1 M
#: with a whole buffer.
NUMBA_STRIDE = 1 << 30

_compiled_lockstep = njit_lazily(lockstep, parallel=True)


def experience_rows() -> int:
    """Rows of a kernel state's ``n_next``: one per thread the numba kernel may run on now
    (``numba.get_num_threads()``, which :func:`numba_kernel` checks before every call)."""
    return int(numba.get_num_threads())


def numba_kernel(st: LockStepState, stride: int = NUMBA_STRIDE) -> int:
    """:func:`lockstep` compiled with numba (once per process, cached on disk), the agents of a
    round on numba's threads (``NUMBA_NUM_THREADS``; one per core by default). ``stride = 1`` is
    strict lock-step; results depend neither on the stride nor on the number of threads. If the
    thread count rose since ``st`` was made, ``st.n_next`` gains a zero row per new thread."""
    missing = experience_rows() - st.n_next.shape[0]
    if missing > 0:
        st.n_next = np.concatenate([st.n_next, np.zeros((missing, st.n_next.shape[1]),
                                                        dtype=st.n_next.dtype)])
    return int(_compiled_lockstep(*st.args(stride)))


def python_kernel(st: LockStepState, stride: int = NUMBA_STRIDE) -> int:
    """:func:`lockstep` run by the interpreter (the reference and the benchmark's baseline;
    slow, identical). ``prange`` is plain ``range`` outside numba, so agents run in order."""
    return int(lockstep(*st.args(stride)))


KERNELS: dict[str, Callable[[LockStepState], int]] = {
    "numba": numba_kernel,
    "python": python_kernel,
}

