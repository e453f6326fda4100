"""Multi-time models of options (dissertation eqs. 3.1-3.2): exact, iterated, and sampled.

Semantics (see :mod:`adpart.options.option`): started in ``s`` in ``I`` the option takes action
``a ~ pi(s)``, the MDP moves to ``s'``, reward ``R(s, a)`` is collected, and the option ends in
``s'`` if ``s'`` is terminal in the MDP, else with probability ``beta(s')``; otherwise it acts
again from ``s'``. With the continuation probability ``c(x) = (1 - beta(x)) [x not terminal]``,
``C = diag(c)`` and the policy's one-step matrix ``P_pi`` and reward ``r_pi``, conditioning on the
first step gives, for every state ``x`` where the option may act,

    R(x)    = r_pi(x) + gamma sum_y P_pi(x, y) c(y) R(y)                            (eq. 3.1)
    F(z|x)  = gamma P_pi(x, z) (1 - c(z)) + gamma sum_y P_pi(x, y) c(y) F(z|y)      (eq. 3.2)
    D(x)    = 1 + sum_y P_pi(x, y) c(y) D(y)              (expected duration, undiscounted)

that is ``(I - gamma P_pi C) R = r_pi``, ``(I - gamma P_pi C) F = gamma P_pi (I - C)`` and
``(I - P_pi C) D = 1``. The first step is taken whatever ``beta(x)``, so the models of the start
states are rows of these systems. The systems are restricted to ``T``, the states reachable from
the (non-terminal) initiation states by continuing steps: ``P_pi C`` maps ``T`` into ``T``, and
rows outside ``T`` are never needed. :func:`option_model` factorises ``I - gamma P_pi C`` on
``T`` once (``scipy.sparse.linalg.splu``) and solves for ``R`` and for the columns of ``F``
that can be nonzero (the states where the option can end), 32 columns per call; the duration
needs a second factorisation, of ``I - P_pi C``.

An option that can stay in ``{c > 0}`` forever from some state of ``T`` would make
``I - P_pi C`` singular (infinite expected duration): that is checked on the transition graph
*before* factorising and reported with the option and the initiation state.

:func:`option_model_by_iteration` computes the same ``R`` and ``F`` by iterating the Bellman
equations above (the reference of the benchmark and an oracle in the tests);
:func:`sample_option_model` estimates them from vectorised rollouts, for environments without a
known model, with the same semantics.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse import csgraph

from adpart.errors import ModelError
from adpart.options.option import Option

if TYPE_CHECKING:
    from adpart.mdp.model import FiniteMDP

#: Entries of ``F`` below this (round-off of the LU solve) are dropped; negatives are clipped.
F_DROP_TOL = 1e-14
#: Column ordering of ``splu`` (SuperLU's default). ``MMD_AT_PLUS_A`` gave 44% less fill on the
#: 10^5-state grid option but made SuperLU's triangular solves fail (BLAS "illegal value") there.
LU_ORDERING = "COLAMD"
#: Right-hand-side columns per ``SuperLU.solve`` call of the ``F`` solve. Wider blocks go
#: through threaded BLAS ``trsm`` kernels that spin-wait; on the two-core reference machine a
#: 3,566-state option solved 10-50x slower with 64+ columns per call than with 32.
RHS_BLOCK_COLUMNS = 32


@dataclass(frozen=True, eq=False)
class OptionModel:
    """The multi-time model of one option, with rows for every state.

    Attributes:
        name: the option's name.
        R: ``(S,)`` expected discounted reward until termination (eq. 3.1); 0 outside
            ``admissible``.
        F: ``(S, S)`` CSR, ``F[s, s'] = sum_k gamma^k P(s_k = s', tau = k | s)`` (eq. 3.2).
        duration: ``(S,)`` expected number of primitive steps (NaN where not computed).
        admissible: ``(S,)`` bool, ``I`` minus the MDP's terminal states: the rows computed.
    """

    name: str
    R: np.ndarray
    F: sp.csr_array
    duration: np.ndarray
    admissible: np.ndarray

    @property
    def mass(self) -> np.ndarray:
        """``(S,)`` discounted mass ``sum_s' F(s'|s) = E[gamma^tau]`` of each row."""
        return np.asarray(self.F.sum(axis=1)).ravel()


@dataclass(frozen=True)
class _System:
    """An option's linear system restricted to the states ``T`` it can act in."""

    states: np.ndarray  # (n,) the states of T, sorted
    starts: np.ndarray  # positions in ``states`` of the non-terminal initiation states
    cont: sp.csr_array  # (n, n) P_pi(x, y) c(y) within T (probabilities, undiscounted)
    end: sp.csr_array  # (n, S) P_pi(x, z) (1 - c(z)) (probabilities, undiscounted)
    reward: np.ndarray  # (n,) r_pi


def _policy_selector(option: Option, rows: np.ndarray, S: int, A: int) -> sp.csr_array:
    """``(n, A*S)`` weights ``pi(x, a)`` at column ``a*S + x``; ``W @ P`` = ``P_pi`` on ``rows``."""
    n = rows.size
    if option.deterministic:
        cols = option.policy[rows] * S + rows
        return sp.csr_array((np.ones(n), (np.arange(n), cols)), shape=(n, A * S))
    probs = option.policy[rows]
    i, a = np.nonzero(probs)
    return sp.csr_array((probs[i, a], (i, a * S + rows[i])), shape=(n, A * S))


def _reachable(graph: sp.csr_array, sources: np.ndarray) -> np.ndarray:
    """Bool mask of nodes reachable from ``sources`` (a virtual root joins them all)."""
    n = graph.shape[0]
    root = sp.csr_array(
        (np.ones(sources.size), (np.zeros(sources.size, dtype=np.int64), sources)), shape=(1, n)
    )
    g = sp.vstack([sp.hstack([graph, sp.csr_array((n, 1))]),
                   sp.hstack([root, sp.csr_array((1, 1))])], format="csr")
    order = csgraph.breadth_first_order(g, n, directed=True, return_predecessors=False)
    mask = np.zeros(n + 1, dtype=bool)
    mask[order] = True
    return mask[:n]


def _build_system(P: sp.csr_array, R: np.ndarray, terminal: np.ndarray, option: Option) -> _System:
    """Restrict the option's equations to the states reachable from its initiation set."""
    S = P.shape[1]
    A = P.shape[0] // S
    cont_prob = np.where(terminal, 0.0, 1.0 - option.beta)
    acting = np.flatnonzero(option.acting_states(terminal))
    W = _policy_selector(option, acting, S, A)
    P_pi = sp.csr_array(W @ P)
    # Continuing transitions stay inside the acting states (c(y) > 0 implies y acts).
    pos = np.full(S, -1, dtype=np.int64)
    pos[acting] = np.arange(acting.size)
    cont_full = sp.csr_array(P_pi @ sp.diags_array(cont_prob))
    cont_full.eliminate_zeros()
    cont = sp.csr_array(cont_full[:, acting])
    start_pos = pos[np.flatnonzero(option.initiation & ~terminal)]
    keep = _reachable(cont, start_pos)
    kept = np.flatnonzero(keep)
    cont = sp.csr_array(cont[kept][:, kept])
    P_kept = P_pi[kept]
    end = sp.csr_array(P_kept @ sp.diags_array(1.0 - cont_prob))
    end.eliminate_zeros()
    R_sel = W[kept] @ R.T.reshape(-1)
    new_pos = np.cumsum(keep) - 1
    return _System(acting[kept], new_pos[start_pos], cont, end, np.asarray(R_sel, dtype=np.float64))


def _check_terminates(option: Option, system: _System) -> None:
    """Raise if some state reachable from ``I`` cannot end the option (singular ``I - P_pi C``)."""
    n = system.states.size
    exits = np.flatnonzero(np.asarray(system.end.sum(axis=1)).ravel() > 0)
    can_end = _reachable(sp.csr_array(system.cont.T), exits) if exits.size else np.zeros(n, bool)
    stuck = np.flatnonzero(~can_end)
    if not stuck.size:
        return
    feeds = _reachable(sp.csr_array(system.cont.T), stuck)
    start = system.states[system.starts[feeds[system.starts]][0]]
    raise ModelError(
        f"option {option.name!r} never terminates when started in state {int(start)}: its policy "
        f"can reach state {int(system.states[stuck[0]])}, from which it stays forever in states "
        "with beta < 1 (I - P_pi C is singular); fix the policy or set beta = 1 somewhere on "
        "that loop"
    )


def _factorise(matrix: sp.csr_array, option: Option, what: str) -> spla.SuperLU:
    try:
        return spla.splu(sp.csc_array(matrix), permc_spec=LU_ORDERING)
    except RuntimeError as exc:  # "Factor is exactly singular"
        raise ModelError(
            f"option {option.name!r}: {what} is singular ({exc}); the option cannot terminate "
            "from some state of its initiation set"
        ) from exc


def _solve_end_columns(lu: spla.SuperLU, rhs: sp.csr_array, rows: np.ndarray) -> sp.coo_array:
    """``(len(rows), S)`` rows of ``lu^{-1} rhs``, solving only the nonzero columns, in blocks."""
    _, S = rhs.shape
    cols = np.unique(rhs.indices)
    rhs_c = sp.csc_array(rhs[:, cols])
    block = RHS_BLOCK_COLUMNS
    r_idx, c_idx, vals = [], [], []
    for lo in range(0, cols.size, block):  # blocks of end columns (see RHS_BLOCK_COLUMNS)
        dense = lu.solve(rhs_c[:, lo:lo + block].toarray())[rows]
        i, j = np.nonzero(dense > F_DROP_TOL)
        r_idx.append(i)
        c_idx.append(cols[lo + j])
        vals.append(dense[i, j])
    if not vals:
        return sp.coo_array((rows.size, S))
    return sp.coo_array(
        (np.concatenate(vals), (np.concatenate(r_idx), np.concatenate(c_idx))),
        shape=(rows.size, S),
    )


def _assemble(
    option: Option, system: _System, S: int, R_T: np.ndarray, F_rows: sp.coo_array,
    D_T: np.ndarray | None, terminal: np.ndarray,
) -> OptionModel:
    start_states = system.states[system.starts]
    R_full = np.zeros(S)
    R_full[start_states] = R_T[system.starts]
    F = sp.csr_array(
        (F_rows.data, (start_states[F_rows.row], F_rows.col)), shape=(S, S)
    )
    duration = np.full(S, np.nan)
    if D_T is not None:
        duration[start_states] = D_T[system.starts]
    admissible = option.initiation & ~terminal
    return OptionModel(option.name, R_full, F, duration, admissible)


def _exact_model(
    P: sp.csr_array, R: np.ndarray, gamma: float, terminal: np.ndarray, option: Option,
    duration: bool,
) -> OptionModel:
    """The kernel of :func:`option_model` on raw arrays (inputs already validated)."""
    S = P.shape[1]
    system = _build_system(P, R, terminal, option)
    _check_terminates(option, system)
    n = system.states.size
    eye = sp.eye_array(n, format="csr")
    lu = _factorise(eye - gamma * system.cont, option, "I - gamma P_pi C")
    R_T = lu.solve(system.reward)
    F_rows = _solve_end_columns(lu, sp.csr_array(gamma * system.end), system.starts)
    D_T = None
    if duration:
        D_T = _factorise(eye - system.cont, option, "I - P_pi C").solve(np.ones(n))
    return _assemble(option, system, S, R_T, F_rows, D_T, terminal)


def option_model(mdp: FiniteMDP, option: Option, *, duration: bool = True) -> OptionModel:
    """Exact multi-time model of ``option`` (eqs. 3.1-3.2) by one sparse LU factorisation.

    Args:
        mdp: the core MDP (its rewards define ``R``; ``F`` is reward-independent).
        option: checked against ``mdp`` first (:meth:`Option.check`).
        duration: also compute the expected duration (a second factorisation, undiscounted).

    Raises:
        ModelError: bad option, or an option that can run forever from its initiation set.
    """
    option.check(mdp)
    return _exact_model(mdp.P, mdp.R, mdp.gamma, mdp.terminal, option, duration)


class ItemMapper(Protocol):
    """What :func:`option_models` needs of an executor: ``map`` in order, and whether it is
    ``parallel`` (an executor that is not gets the options in one chunk). Every
    :class:`adpart.execution.Executor` is one; the core names only this shape."""

    parallel: bool

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any]) -> list[Any]: ...


def _model_worker(item: tuple) -> list[OptionModel]:
    """Executor work item: exact models of a chunk of options on one MDP's raw arrays."""
    P, R, gamma, terminal, options, duration = item
    return [_exact_model(P, R, gamma, terminal, o, duration) for o in options]


def option_models(
    mdp: FiniteMDP,
    options: list[Option],
    *,
    executor: ItemMapper | None = None,
    duration: bool = True,
    chunks: int | None = None,
) -> list[OptionModel]:
    """Exact models of many options, computed through ``executor`` (in this process by default).

    Every option is validated here, in the calling process; the workers receive the MDP's
    arrays and ``chunks`` groups of options (default: two per core, at most one per option).
    Results are in the order of ``options``.
    """
    for o in options:
        o.check(mdp)
    if not options:
        return []
    parallel = executor is not None and getattr(executor, "parallel", True)
    n_chunks = chunks or (2 * (os.cpu_count() or 1) if parallel else 1)
    n_chunks = max(1, min(n_chunks, len(options)))
    size = math.ceil(len(options) / n_chunks)
    items = [
        (mdp.P, mdp.R, mdp.gamma, mdp.terminal, options[i:i + size], duration)
        for i in range(0, len(options), size)
    ]
    done = executor.map(_model_worker, items) if executor is not None else map(_model_worker, items)
    return [m for chunk in done for m in chunk]


def option_model_by_iteration(
    mdp: FiniteMDP, option: Option, *, tol: float = 1e-10, max_iter: int = 1_000_000,
) -> tuple[OptionModel, int]:
    """``R`` and ``F`` by iterating the option's Bellman equations (the reference method).

    ``R <- r_pi + gamma P_pi C R`` and ``F <- gamma P_pi (I - C) + gamma P_pi C F`` from zero, on
    the same restricted system as :func:`option_model` (``F`` dense over the columns where the
    option can end), until the contraction bound ``gamma/(1-gamma) * change`` is below ``tol``
    (or, for ``gamma = 1``, the change itself). Duration is not computed (NaN).

    Returns:
        The model and the number of iterations.
    """
    option.check(mdp)
    S, gamma = mdp.n_states, mdp.gamma
    system = _build_system(mdp.P, mdp.R, mdp.terminal, option)
    _check_terminates(option, system)
    cols = np.unique(system.end.indices)
    G = sp.csr_array(gamma * system.cont)
    end = (gamma * system.end[:, cols]).toarray()
    r = system.reward
    Rk, Fk = np.zeros_like(r), np.zeros_like(end)
    scale = gamma / (1.0 - gamma) if gamma < 1.0 else 1.0
    it = 0
    while it < max_iter:
        R_new = r + G @ Rk
        F_new = end + G @ Fk
        it += 1
        change = max(float(np.abs(R_new - Rk).max(initial=0.0)),
                     float(np.abs(F_new - Fk).max(initial=0.0)))
        Rk, Fk = R_new, F_new
        if scale * change < tol:
            break
    rows = Fk[system.starts]
    i, j = np.nonzero(rows > F_DROP_TOL)
    F_rows = sp.coo_array((rows[i, j], (i, cols[j])), shape=(system.starts.size, S))
    return _assemble(option, system, S, Rk, F_rows, None, mdp.terminal), it


@dataclass(frozen=True, eq=False)
class SampledOptionModel:
    """Monte Carlo estimate of an option's model from ``n_rollouts`` rollouts per start state.

    Attributes:
        name: the option's name.
        starts: ``(k,)`` the start states sampled.
        n_rollouts: rollouts per start state.
        R, R_se: ``(k,)`` mean discounted return until termination and its standard error.
        mass, mass_se: ``(k,)`` mean of ``gamma^tau`` (the row mass of ``F``) and its
            standard error.
        duration, duration_se: ``(k,)`` mean number of steps and its standard error.
        F: ``(k, S)`` CSR, mean of ``gamma^tau [s_tau = s']`` (eq. 3.2 estimated).
        truncated: rollouts stopped at ``max_steps`` before the option ended.
    """

    name: str
    starts: np.ndarray
    n_rollouts: int
    R: np.ndarray
    R_se: np.ndarray
    mass: np.ndarray
    mass_se: np.ndarray
    duration: np.ndarray
    duration_se: np.ndarray
    F: sp.csr_array
    truncated: int


def _mean_se(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-row mean and standard error of a ``(k, N)`` sample."""
    n = x.shape[1]
    sd = x.std(axis=1, ddof=1) if n > 1 else np.zeros(x.shape[0])
    return x.mean(axis=1), sd / math.sqrt(n)


def sample_option_model(
    mdp: FiniteMDP,
    option: Option,
    rng: np.random.Generator,
    *,
    starts: np.ndarray | None = None,
    n_rollouts: int = 1000,
    max_steps: int = 100_000,
) -> SampledOptionModel:
    """Estimate ``R``, ``F``, the mass of ``F`` and the duration from rollouts of the option.

    All ``len(starts) * n_rollouts`` rollouts advance together, one vectorised step at a time
    (:meth:`FiniteMDP.sample_next`); only the mean reward ``R(s, a)`` of the MDP is collected
    (FiniteMDP rewards are expected rewards). Same semantics as :func:`option_model`: the first
    step is always taken, ``beta`` is drawn on arrival, terminal states end the option.

    Args:
        rng: the only source of randomness.
        starts: states to start from (default: every non-terminal state of ``I``); each must be
            in the initiation set.
        n_rollouts: rollouts per start state (>= 2 for standard errors).
        max_steps: rollouts still running after this many steps are cut (counted in ``truncated``).
    """
    option.check(mdp)
    S = mdp.n_states
    if starts is None:
        starts = np.flatnonzero(option.initiation & ~mdp.terminal)
    starts = np.asarray(starts, dtype=np.int64)
    if starts.ndim != 1 or starts.size == 0 or starts.min() < 0 or starts.max() >= S:
        raise ModelError(f"starts must be a non-empty list of states 0..{S - 1}")
    outside = starts[~option.initiation[starts] | mdp.terminal[starts]]
    if outside.size:
        raise ModelError(
            f"option {option.name!r} is not admissible in state {int(outside[0])} (outside its "
            "initiation set, or terminal); sample only from its initiation set"
        )
    if not isinstance(n_rollouts, (int, np.integer)) or n_rollouts < 1:
        raise ModelError(f"n_rollouts = {n_rollouts!r} must be a positive integer")
    gamma = mdp.gamma
    K = starts.size * int(n_rollouts)
    state = np.repeat(starts, n_rollouts)
    ret = np.zeros(K)
    disc_end = np.zeros(K)
    steps = np.zeros(K, dtype=np.int64)
    end_state = np.full(K, -1, dtype=np.int64)
    live = np.arange(K)
    disc = 1.0
    cum = None if option.deterministic else np.cumsum(option.policy, axis=1)
    t = 0
    while live.size and t < max_steps:
        s = state[live]
        if cum is None:
            a = option.policy[s]
        else:
            u = rng.random(s.size)
            a = np.minimum((cum[s] <= u[:, None]).sum(axis=1), mdp.n_actions - 1)
        s_next = mdp.sample_next(s, a, rng)
        ret[live] += disc * mdp.R[s, a]
        disc *= gamma
        t += 1
        state[live] = s_next
        stop = mdp.terminal[s_next] | (rng.random(s_next.size) < option.beta[s_next])
        ended = live[stop]
        disc_end[ended] = disc
        steps[ended] = t
        end_state[ended] = s_next[stop]
        live = live[~stop]
    steps[live] = t
    k, N = starts.size, int(n_rollouts)
    R_mean, R_se = _mean_se(ret.reshape(k, N))
    mass, mass_se = _mean_se(disc_end.reshape(k, N))
    dur, dur_se = _mean_se(steps.reshape(k, N).astype(np.float64))
    done = end_state >= 0
    row = np.repeat(np.arange(k), N)[done]
    F = sp.csr_array((disc_end[done] / N, (row, end_state[done])), shape=(k, S))
    F.sum_duplicates()
    return SampledOptionModel(
        option.name, starts, N, R_mean, R_se, mass, mass_se, dur, dur_se, F, int(live.size)
    )
