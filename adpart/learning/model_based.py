"""A flat learner that knows the true dynamics and observes the rewards: the baseline a layer
learner that reads the true model is compared with.

The layer learners of adpart read the environment's exact transition model (option policies and
models, the partition). A fair flat baseline knows the same dynamics, so this learner is given
``P`` and nothing of the task: it observes a reward when it takes the step that pays it, and a
terminal state when an episode ends in it. It is certainty-equivalent control (the model-based
agent of Sutton & Barto 2018, sec. 8.1, with the true ``P`` in place of a learned one):

* every step is epsilon-greedy on ``Q`` over the admissible actions (ties broken at random),
  with the run's exploration schedule (its visit count ``n(s)``);
* the reward model ``R_hat(s, a)`` is the mean of the rewards observed at the pair; a pair never
  tried is given the largest reward observed so far, and 0 before any (optimism in the face of
  uncertainty, so that planning leads to untried pairs);
* a state is known to be terminal once an episode has ended in it (worth 0 from then on);
* after every episode that changed the reward model or found a terminal, ``Q`` is re-planned by
  value iteration on ``(P, R_hat)``, warm-started from the last plan (Gauss-Seidel):
  ``Q(s, a) = R_hat(s, a) + gamma sum_s' P(s'|s, a) V(s')``, ``V(s') = 0`` at known terminals
  and ``max_a' Q(s', a')`` elsewhere, to a sup-norm change of at most 1e-9.

Drawing successor states, reading the reward of a step and ending an episode are the
environment's (:func:`adpart.learning.knowledge.world`); scoring the greedy policies against
``V*`` is for scoring only. The learner declares ``dynamics true-model, rewards observed``.
"""

from __future__ import annotations

import numpy as np

from adpart.errors import ModelError
from adpart.learning._kernels import njit_lazily, resolve_kernel
from adpart.learning.curves import (
    LearningCurve,
    StartValues,
    optimal_start_value,
    start_distribution,
)
from adpart.learning.knowledge import Knowledge, world
from adpart.learning.result import LearnResult
from adpart.learning.settings import Run, fresh_seed, require_mdp
from adpart.mdp._sampling import epsilon_greedy, first_above
from adpart.mdp.evaluation import greedy_policy
from adpart.mdp.experience import Experience
from adpart.mdp.model import FiniteMDP

__all__ = ["KNOWN_DYNAMICS", "estimated_dynamics_learning", "known_dynamics_learning"]

#: What the learner knows: the true dynamics, the rewards only as observed.
KNOWN_DYNAMICS = Knowledge("true-model", "observed",
                           ("value iteration on the true dynamics with the observed rewards",))

#: Value iteration stops when no Q-value moves by more than this (or after the sweep cap).
PLAN_TOLERANCE = 1e-9
PLAN_SWEEPS = 10_000


def _plan(indptr, indices, data, R_hat, terminal, admissible, Q, gamma, S, A):
    """Q-value iteration on the known dynamics (CSR rows ``a * S + s``) and ``R_hat``, in place
    from the warm start ``Q``, Gauss-Seidel over states (each backup reads the newest values), to
    a sup-norm change of at most :data:`PLAN_TOLERANCE` (or :data:`PLAN_SWEEPS` sweeps).
    Inadmissible pairs stay ``-inf``; a known terminal state is worth 0."""
    for _ in range(PLAN_SWEEPS):
        change = 0.0
        for s in range(S):
            for a in range(A):
                if not admissible[s, a]:
                    continue
                row = a * S + s
                total = 0.0
                for k in range(indptr[row], indptr[row + 1]):
                    s2 = indices[k]
                    if terminal[s2]:
                        continue
                    best = -np.inf
                    for b in range(A):
                        if admissible[s2, b] and Q[s2, b] > best:
                            best = Q[s2, b]
                    if best > -np.inf:
                        total += data[k] * best
                new = R_hat[s, a] + gamma * total
                diff = abs(new - Q[s, a])
                change = max(change, diff)
                Q[s, a] = new
        if change <= PLAN_TOLERANCE:
            return


def _episode(s, Q, admissible, keys, indptr, indices, env_R, env_terminal, r_sum, n_sa, n_s,
             terminal, counts, eps, e, H, gamma, U):
    """One episode from ``s`` (the rule of the module docstring): epsilon-greedy on ``Q`` (ties
    at random), the environment's step (successor by ``keys``, reward ``env_R``, end at
    ``env_terminal``) observed into the reward model and counted in ``counts`` (one entry per
    CSR entry of the transitions). Three uniforms a step: explore?, which action, successor.
    Returns ``(steps, return, discounted return, model changed)``; the model changed when a
    pair's mean reward moved, a pair was counted for the first time, or a terminal was found."""
    S = Q.shape[0]
    scale, rate, omega, floor = eps
    steps = 0
    ret = 0.0
    dret = 0.0
    disc = 1.0
    changed = False
    while steps < H:
        epsilon = max(floor, scale * rate ** e * (n_s[s] + 1) ** (-omega))
        a = epsilon_greedy(U[steps, 0], U[steps, 1], epsilon, Q[s], Q[s], admissible[s])
        if a < 0:
            break
        row = a * S + s
        hi = indptr[row + 1]
        pos = min(first_above(keys, row + U[steps, 2], indptr[row], hi), hi - 1)
        s2 = indices[pos]
        counts[pos] += 1.0
        r = env_R[s, a]
        before = r_sum[s, a] / n_sa[s, a] if n_sa[s, a] > 0 else np.nan
        n_s[s] += 1
        n_sa[s, a] += 1
        r_sum[s, a] += r
        if r_sum[s, a] / n_sa[s, a] != before:  # a first visit: before is NaN
            changed = True
        steps += 1
        ret += r
        dret += disc * r
        disc *= gamma
        s = s2
        if env_terminal[s2]:
            if not terminal[s2]:
                terminal[s2] = True
                changed = True
            break
    return steps, ret, dret, changed


_KERNELS = {"numba": (njit_lazily(_plan), njit_lazily(_episode)), "python": (_plan, _episode)}


def known_dynamics_learning(mdp: FiniteMDP, run: Run | None = None) -> LearnResult:
    """Learn ``mdp`` with ``run.runs`` certainty-equivalent agents that know its dynamics.

    Args:
        mdp: the task; the learner reads its transition model and admissible actions, and
            samples it for steps and rewards.
        run: the run settings (:class:`~adpart.learning.settings.Run`): runs, episodes, seed,
            the exploration schedule ``epsilon``, the step limit, the evaluation schedule,
            ``kernel`` (``numba`` or ``python``, the same source; identical results) and
            progress; ``alpha`` and ``q_init`` do not apply.

    Returns:
        A :class:`~adpart.learning.result.LearnResult` with ``(K, S, A)`` planned ``Q``.

    Randomness: run ``k`` draws from ``default_rng(seed).spawn(K)[k]`` one uniform for each
    episode's start and ``3 H`` for its steps (used in order, three a step).
    """
    require_mdp("known_dynamics_learning", mdp)
    return _certainty_equivalent(mdp, Run() if run is None else run, None, KNOWN_DYNAMICS,
                                 "known-dynamics")


def estimated_dynamics_learning(mdp: FiniteMDP, run: Run | None = None,
                                prior: Experience | None = None) -> LearnResult:
    """Learn ``mdp`` with ``run.runs`` certainty-equivalent agents on a *counts* model: the
    knowledge-matched baseline of a layer learner in the learned-model regime.

    The same agent as :func:`known_dynamics_learning` (module docstring), except that what it
    plans on is ``P^(s'|s, a) = N(s, a, s') / N(s, a)`` over the transitions of ``prior`` (the
    earlier runs whose experience the layer was built from) and its own steps, counted as it
    takes them; a pair neither has tried has no successor in the plan, so it is worth its
    optimistic reward alone (the largest reward observed, 0 before any), and planning leads to
    it. The plan is redone after every episode that moved the reward model (a pair's first
    try included) or found a terminal state, on the counts of that moment.

    Args:
        mdp: the task; sampled for steps, rewards and episode ends only.
        run: the run settings, as for :func:`known_dynamics_learning`.
        prior: the earlier experience (:class:`~adpart.mdp.experience.Experience`); None: the
            agent starts knowing nothing of the dynamics.
    """
    require_mdp("estimated_dynamics_learning", mdp)
    run = Run() if run is None else run
    sources = ", ".join(prior.sources) if prior is not None and prior.sources else None
    knowledge = Knowledge("estimated", "observed", (
        "value iteration on the counts model of "
        + (f"{sources} and its own steps" if sources else "its own steps")
        + " with the observed rewards",))
    return _certainty_equivalent(mdp, run, prior, knowledge, "estimated-dynamics")


def _prior_counts(mdp: FiniteMDP, prior: Experience | None) -> np.ndarray:
    """``prior``'s counts on the CSR entries of ``mdp``'s transitions (the layout the kernel
    counts in; a transition the environment cannot make is refused)."""
    P = mdp.P
    out = np.zeros(P.nnz)
    if prior is None or prior.counts.nnz == 0:
        return out
    if prior.counts.shape != P.shape:
        raise ModelError(f"the prior experience is of {prior.n_states} states and "
                         f"{prior.n_actions} actions; the task has {mdp.n_states} and "
                         f"{mdp.n_actions}")
    coo = prior.counts.tocoo()
    S = P.shape[1]  # key row * S + column: sorted over the whole CSR (FiniteMDP sorts indices)
    keys = np.repeat(np.arange(P.shape[0], dtype=np.int64), np.diff(P.indptr)) * S + P.indices
    wanted = coo.row.astype(np.int64) * S + coo.col
    pos = np.minimum(np.searchsorted(keys, wanted), P.nnz - 1)
    if not np.array_equal(keys[pos], wanted):
        raise ModelError("the prior experience holds a transition this environment cannot "
                         "make; it was gathered on another environment")
    np.add.at(out, pos, coo.data.astype(np.float64))
    return out


def _frequencies(counts: np.ndarray, row_of: np.ndarray, n_rows: int) -> np.ndarray:
    """``N(s, a, s') / N(s, a)`` per CSR entry (0 in rows never counted)."""
    total = np.bincount(row_of, weights=counts, minlength=n_rows)
    return np.divide(counts, total[row_of], out=np.zeros_like(counts), where=total[row_of] > 0)


def _certainty_equivalent(mdp: FiniteMDP, run: Run, prior: Experience | None,
                          knowledge: Knowledge, learner: str) -> LearnResult:
    """The driver both learners share: ``prior`` None and ``learner == "known-dynamics"`` plans
    on the true ``P``; otherwise on the counts (``prior``'s and the run's own)."""
    K, N, M, H = run.runs, run.episodes, run.eval_every, run.max_steps_per_episode
    seed = fresh_seed(run.seed)
    name = resolve_kernel(run.kernel, learner)
    plan, episode = _KERNELS[name]
    S, A, gamma = mdp.n_states, mdp.n_actions, float(mdp.gamma)
    known = learner == "known-dynamics"
    admissible = np.ascontiguousarray(mdp.admissible, dtype=bool)
    with world():  # the environment: its start distribution, simulator and V* for scoring
        mu = start_distribution(mdp)
        v_star = optimal_start_value(mdp, mu, run.reference_values)
        keys, indptr, indices = mdp.sampler_arrays  # the simulator and the counts' layout
        env_R = np.ascontiguousarray(mdp.R, dtype=np.float64)
        env_terminal = np.ascontiguousarray(mdp.terminal, dtype=bool)
        score = StartValues(mdp, mu, K)
        counts0 = None if known else _prior_counts(mdp, prior)
        row_of = np.repeat(np.arange(A * S), np.diff(indptr))
    if known:
        data = mdp.P.data.astype(np.float64)  # what it knows: the dynamics (rows a * S + s)
    start_cdf = np.cumsum(mu)
    eps = run.epsilon.params()
    boundaries = sorted({*range(M, N + 1, M), N})
    out = {name_: np.zeros((K, N)) for name_ in ("steps", "returns", "discounted")}
    eval_value = np.full((K, N), np.nan)
    Qs = np.zeros((K, S, A))
    model = [_RewardModel(S, A) for _ in range(K)]
    counts = [np.zeros(indices.size) if known else counts0.copy() for _ in range(K)]

    def replan(k: int) -> None:
        frequencies = data if known else _frequencies(counts[k], row_of, A * S)
        plan(indptr, indices, frequencies, model[k].R_hat(), model[k].terminal, admissible,
             Qs[k], gamma, S, A)

    for k in range(K):
        Qs[k][~admissible] = -np.inf
        replan(k)
    rngs = np.random.default_rng(seed).spawn(K)
    done = 0
    for boundary in boundaries:
        for k in range(K):
            m, rng, Q = model[k], rngs[k], Qs[k]
            for e in range(done, boundary):
                s = int(min(np.searchsorted(start_cdf, rng.random(), side="right"), S - 1))
                U = rng.random((H, 3))
                steps, ret, dret, changed = episode(
                    s, Q, admissible, keys, indptr, indices, env_R, env_terminal, m.r_sum,
                    m.n_sa, m.n_s, m.terminal, counts[k], eps, e, H, gamma, U)
                if changed:  # only a changed reward model or a new terminal moves the plan
                    replan(k)
                out["steps"][k, e], out["returns"][k, e] = steps, ret
                out["discounted"][k, e] = dret
        done = boundary
        policies = greedy_policy(Qs.reshape(K * S, A)).reshape(K, S)
        with world():
            eval_value[:, boundary - 1] = score(policies, np.ones(K, dtype=bool))
        if run.progress is not None:
            run.progress(boundary, N)
    parameters: dict[str, object] = {
        "runs": K, "episodes": N, "seed": seed, "epsilon": run.epsilon.to_dict(),
        "max_steps_per_episode": H, "eval_every": M, "kernel": name,
        "reference": "given" if run.reference_values is not None else "solved",
        "knowledge": knowledge.to_dict(),
    }
    if not known:
        parameters["prior_steps"] = 0 if prior is None else prior.steps
    curve = LearningCurve.from_matrices(
        steps=out["steps"].astype(np.int64), decisions=out["steps"].astype(np.int64),
        returns=out["returns"], discounted_returns=out["discounted"], eval_value=eval_value,
        value_gap=v_star - eval_value,
        metadata={"learner": learner, "mdp": mdp.name, "mdp_hash": mdp.content_hash,
                  "gamma": mdp.gamma, "v_star_start": v_star, **parameters},
    )
    return LearnResult(Q=Qs, curve=curve, seed=seed, v_star_start=v_star,
                       parameters=parameters)


class _RewardModel:
    """One run's observed rewards, visit counts and known terminal states."""

    def __init__(self, S: int, A: int) -> None:
        self.r_sum = np.zeros((S, A))
        self.n_sa = np.zeros((S, A), dtype=np.int64)
        self.n_s = np.zeros(S, dtype=np.int64)
        self.terminal = np.zeros(S, dtype=bool)

    def R_hat(self) -> np.ndarray:
        """The mean observed reward of every tried pair; an untried pair gets the largest
        reward observed so far, and 0 before any (optimism in the face of uncertainty)."""
        tried = self.n_sa > 0
        means = np.divide(self.r_sum, self.n_sa, out=np.zeros_like(self.r_sum), where=tried)
        best = max(0.0, float(means[tried].max())) if tried.any() else 0.0
        return np.where(tried, means, best)
