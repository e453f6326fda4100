"""Flat Q-learning: K independent runs advanced in lock-step, with exact learning curves.

The update is Watkins' Q-learning (dissertation section 2.x, eq. 2.4):

    Q(s, a) <- Q(s, a) + alpha_n(s, a) * (r + gamma * max_{a'} Q(s', a') - Q(s, a)),

with target ``r`` alone when ``s'`` is terminal (the episode ends on arrival and a terminal state
is worth 0). The exact per-step rule, including how the random numbers are used, is in
:mod:`adpart.learning._kernels`.

Design choices (documented in ``docs/learning.md``):

* **Lock-step by steps inside evaluation blocks.** Episodes are grouped in blocks that end at
  every ``eval_every``-th episode (and at the last). Within a block, one kernel iteration advances
  every agent that has not yet finished the block by one primitive step; an agent whose episode
  ends resets from ``mdp.initial`` and continues while the others do; an agent that has finished
  the block waits. At the block's end all K runs have completed the same number of episodes, so
  their greedy policies (kept current by the kernel as it updates Q) are scored together: one
  exact policy evaluation per distinct policy not scored before
  (:class:`adpart.learning.curves.StartValues`).
* **Randomness.** ``np.random.default_rng(seed).spawn(runs)`` gives each run its own stream; a run
  draws one uniform for its first start state and then exactly four per step. A run's trajectory
  therefore depends only on ``seed``, its index and the settings -- not on ``runs``, not on
  ``eval_every``, not on the kernel -- and the same seed gives bit-identical curves and Q.
* **Exploration** is epsilon-greedy over the *admissible* actions; greedy ties during learning
  are broken uniformly at random (so an untrained agent does not always bump into the same
  wall); the *evaluated* greedy policy breaks ties by the lowest action index
  (:func:`adpart.mdp.evaluation.greedy_policy`), so it is a deterministic function of Q.
* **Step limit.** An episode also ends after ``max_steps_per_episode`` steps; the last update
  still bootstraps from ``s'`` (the cut is a property of the experiment, not of the task).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from adpart.learning import _kernels
from adpart.learning.curves import (
    LearningCurve,
    StartValues,
    optimal_start_value,
    start_distribution,
)
from adpart.learning.knowledge import FLAT, world
from adpart.learning.result import LearnResult
from adpart.learning.schedules import Schedule
from adpart.learning.settings import Run, fresh_seed, require_mdp
from adpart.mdp.evaluation import greedy_policy
from adpart.mdp.experience import Experience
from adpart.mdp.model import FiniteMDP

__all__ = ["QLearningResult", "default_kernel", "q_learning"]

#: Rows of uniforms drawn per refill of one run's buffer (4 uniforms a row, 256 KiB a run).
#: Results do not depend on it (a run's stream is consumed in order); larger buffers mean fewer
#: rounds of the numba kernel (measured 10-15% faster at K = 50 than 2,048 rows).
BLOCK_ROWS = 8192


default_kernel = _kernels.default_kernel


@dataclass(frozen=True, eq=False)
class QLearningResult(LearnResult):
    """What :func:`q_learning` returns.

    Attributes:
        Q: ``(K, S, A)`` float64 action values of every run; ``-inf`` on inadmissible pairs.
        visits: ``(K, S, A)`` int64 number of updates of each pair.
        experience: the transitions every run took, counted and summed over the runs
            (:class:`~adpart.mdp.experience.Experience`): what a learner that estimates the dynamics
            from these runs may read.
        curve, seed, v_star_start, parameters: as :class:`~adpart.learning.result.LearnResult`
            (the seed is drawn from OS entropy and recorded when none was given).
    """

    visits: np.ndarray
    experience: Experience | None = None


def _policy_dtype(n_actions: int) -> np.dtype:
    """The smallest signed integer type that holds every action index (int8 for A <= 127)."""
    for dtype in (np.int8, np.int16, np.int32):
        if n_actions <= np.iinfo(dtype).max:
            return np.dtype(dtype)
    return np.dtype(np.int64)


_ADMISSIBLE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _admissible_arrays(mdp: FiniteMDP) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(adm_ptr, adm_idx, first)``: the admissible actions of every state in CSR form and the
    lowest admissible action of each (0 where none is), made once per model (the kernel only
    reads them)."""
    arrays = _ADMISSIBLE.get(mdp)
    if arrays is None:
        S = mdp.n_states
        rows, cols = np.nonzero(mdp.admissible)
        adm_ptr = np.zeros(S + 1, dtype=np.int64)
        np.cumsum(np.bincount(rows, minlength=S), out=adm_ptr[1:])
        adm_idx = cols.astype(np.int64)
        first = np.zeros(S, dtype=np.int64)
        some = adm_ptr[1:] > adm_ptr[:-1]
        first[some] = adm_idx[adm_ptr[:-1][some]]
        arrays = _ADMISSIBLE[mdp] = (adm_ptr, adm_idx, first)
    return arrays


def _initial_state(
    mdp: FiniteMDP, runs: int, episodes: int, horizon: int, alpha: Schedule, epsilon: Schedule,
    q_init: float, mu: np.ndarray,
) -> _kernels.LockStepState:
    S, A = mdp.n_states, mdp.n_actions
    keys, indptr, indices = mdp.sampler_arrays  # the keys FiniteMDP.sample_next searches
    adm = mdp.admissible
    adm_ptr, adm_idx, first = _admissible_arrays(mdp)
    start_cdf = np.cumsum(mu)
    # One (K, S, A) allocation, written only where it is not 0: np.zeros maps untouched pages
    # lazily, so with q_init = 0 the kernel pays only for the rows it visits.
    Q = np.zeros((runs, S, A))
    if q_init != 0.0:
        Q.fill(float(q_init))
    if not adm.all():
        Q[:, ~adm] = -np.inf
    st = _kernels.LockStepState(
        keys=keys,
        indptr=indptr,
        indices=indices,
        R=np.ascontiguousarray(mdp.R, dtype=np.float64),
        terminal=np.ascontiguousarray(mdp.terminal, dtype=bool),
        adm_ptr=adm_ptr,
        adm_idx=adm_idx,
        start_cdf=start_cdf,
        last_start=int(np.flatnonzero(mu > 0)[-1]),
        gamma=float(mdp.gamma),
        horizon=horizon,
        alpha=alpha.params(),
        eps=epsilon.params(),
        Q=Q,
        n_sa=np.zeros((runs, S, A), dtype=np.int64),
        n_s=np.zeros((runs, S), dtype=np.int64),
        # the experience, one row per kernel thread (not per run: the sum is what is kept)
        n_next=np.zeros((_kernels.experience_rows(), mdp.P.nnz), dtype=np.int64),
        state=np.zeros(runs, dtype=np.int64),
        episode=np.zeros(runs, dtype=np.int64),
        target=np.zeros(runs, dtype=np.int64),
        t_ep=np.zeros(runs, dtype=np.int64),
        ret=np.zeros(runs),
        dret=np.zeros(runs),
        gpow=np.ones(runs),
        alpha_ep=np.zeros(runs),
        eps_ep=np.zeros(runs),
        # written by the first refill before the kernel reads it (cursor at the end)
        U=np.empty((runs, BLOCK_ROWS, _kernels.UNIFORMS_PER_STEP)),
        cursor=np.full(runs, BLOCK_ROWS, dtype=np.int64),
        out_steps=np.zeros((runs, episodes), dtype=np.int64),
        out_ret=np.zeros((runs, episodes)),
        out_dret=np.zeros((runs, episodes)),
        # the kernel keeps these current from the greedy action of the initial row on
        policy=np.empty((runs, S), dtype=_policy_dtype(A)),
        changed=np.ones(runs, dtype=bool),
    )
    if q_init > -np.inf:  # every admissible entry equal and above -inf: the lowest one
        st.policy[:] = first
    else:
        st.policy[:] = greedy_policy(np.where(adm, float(q_init), -np.inf))
    st.episode_factors(np.arange(runs))
    return st


def q_learning(mdp: FiniteMDP, run: Run | None = None) -> QLearningResult:
    """Learn ``mdp`` with ``run.runs`` independent epsilon-greedy Q-learners in lock-step.

    Args:
        mdp: the task, a validated :class:`~adpart.mdp.model.FiniteMDP`.
        run: the run settings (:class:`~adpart.learning.settings.Run`; default ``Run()``):
            runs K and episodes N; the root seed (run k uses
            ``np.random.default_rng(seed).spawn(runs)[k]``); the step-size schedule ``alpha``
            (visit count ``n(s, a)``; default ``1/n(s,a)^0.8``, which meets the
            stochastic-approximation conditions) and the exploration schedule ``epsilon``
            (visit count ``n(s)``); the step limit H (a cut episode bootstraps through the
            cut); exact scoring every ``eval_every`` episodes (and after the last) against
            ``reference_values`` (``V*``, solved when omitted); ``q_init`` (auto: 0); the
            kernel, ``"numba"`` (:func:`default_kernel`) or ``"python"`` (the same rule
            interpreted: the reference), identical results; and ``progress``, called as
            ``progress(episodes_done_by_every_run, episodes)`` after each block.

    Returns:
        A :class:`QLearningResult`.

    Raises:
        TaskError: a setting is out of range (raised where the ``Run`` is built).
        UnknownNameError: ``kernel`` is not a kernel's name (the message lists them).
        ModelError: ``mdp`` is not a FiniteMDP, or no episode can start, or bad reference values.
    """
    run = Run() if run is None else run
    require_mdp("q_learning", mdp)
    K, N, M, H = run.runs, run.episodes, run.eval_every, run.max_steps_per_episode
    root_seed, q_init = fresh_seed(run.seed), run.start_q
    alpha_s, eps_s = run.alpha, run.epsilon
    reference_values, progress = run.reference_values, run.progress
    name = _kernels.resolve_kernel(run.kernel, "Q-learning")
    step_kernel = _kernels.KERNELS[name]

    # One BLAS thread while learning: the scoring's few BLAS calls gain nothing from more, and
    # OpenBLAS's idle threads spin after each call, slowing numba's kernel threads on the same
    # cores (10^5 states, K = 50, 2 cores: kernel 0.19 s inside the call against 0.14 s alone).
    with threadpool_limits(1, user_api="blas"):
        with world():  # the environment (its simulator) and the scoring, not knowledge
            mu = start_distribution(mdp)
            v_star = optimal_start_value(mdp, mu, reference_values)
            st = _initial_state(mdp, K, N, H, alpha_s, eps_s, q_init, mu)
            score = StartValues(mdp, mu, K)  # re-scores the runs whose greedy policy moved, once
        rngs = np.random.default_rng(root_seed).spawn(K)
        st.state[:] = [st.start_state(rng.random()) for rng in rngs]

        boundaries = sorted({*range(M, N + 1, M), N})
        eval_value = np.full((K, N), np.nan)
        for boundary in boundaries:
            st.target[:] = boundary
            while step_kernel(st):
                for k in np.flatnonzero((st.cursor == BLOCK_ROWS) & (st.episode < st.target)):
                    # no more rows than the run can still use (all its episodes at the step limit),
                    # at the buffer's end: a run's stream is consumed in order either way
                    rows = min(BLOCK_ROWS, int((N - st.episode[k]) * H - st.t_ep[k]))
                    rngs[k].random(out=st.U[k, BLOCK_ROWS - rows:])
                    st.cursor[k] = BLOCK_ROWS - rows
            with world():
                eval_value[:, boundary - 1] = score(st.policy, st.changed)
            if progress is not None:
                progress(boundary, N)

    parameters: dict[str, object] = {
        "runs": K,
        "episodes": N,
        "seed": root_seed,
        "alpha": alpha_s.to_dict(),
        "epsilon": eps_s.to_dict(),
        "max_steps_per_episode": H,
        "eval_every": M,
        "q_init": float(q_init),
        "kernel": name,
        "reference": "given" if reference_values is not None else "solved",
        "knowledge": FLAT.to_dict(),
    }
    metadata = {
        "learner": "q-learning",
        "mdp": mdp.name,
        "mdp_hash": mdp.content_hash,
        "gamma": mdp.gamma,
        "v_star_start": v_star,
        **parameters,
    }
    curve = LearningCurve.from_matrices(
        steps=st.out_steps,
        decisions=st.out_steps,
        returns=st.out_ret,
        discounted_returns=st.out_dret,
        eval_value=eval_value,
        value_gap=v_star - eval_value,
        metadata=metadata,
    )
    for arr in (st.Q, st.n_sa):
        arr.setflags(write=False)
    with world():  # the CSR layout the counts were kept in names each successor
        experience = Experience.from_positions(mdp.P, st.n_next)
    return QLearningResult(
        Q=st.Q, visits=st.n_sa, curve=curve, seed=root_seed, v_star_start=v_star,
        parameters=parameters, experience=experience,
    )
