"""Successor features with generalised policy improvement (SF-GPI), tabular.

Barreto et al. (2017), "Successor Features for Transfer in Reinforcement Learning": when every
task's reward is linear in features, ``r(s, a) = phi(s, a) . w``, the value of a policy ``pi`` on
any task is ``Q^pi_w(s, a) = psi^pi(s, a) . w`` with the successor features

    psi^pi(s, a) = phi(s, a) + gamma sum_s' P(s'|s, a) psi^pi(s', pi(s')),

and generalised policy improvement acts greedily on ``max_i Q^{pi_i}_w``: a policy at least as
good as every ``pi_i`` on the task ``w`` (their Theorem 1). Transfer: the ``psi`` of the earlier
tasks' policies are reused on a new task whose ``w`` is learned from the rewards observed.

The interpretation here (docs/methods.md):

* **Features** are the indicators of the state-action pairs, ``phi(s, a) = e_(s, a)``, so every
  reward function ``R(s, a)`` is linear in them with ``w = R`` (every adpart task is such a task,
  and GPI's values are exact for it), and ``w`` is learned as the mean reward observed at each
  pair (the least-squares fit of the observed rewards; a pair never tried has ``w = 0``, the
  usual zero initialisation of ``w``).
* **psi is kept implicitly**: ``psi^pi . w`` is ``w(s, a) + gamma sum_s' P(s'|s, a) V(s')`` with
  ``V = (I - gamma P_pi)^{-1} w_pi``, so one sparse LU factor of ``I - gamma P_pi`` per policy
  stands for its ``(SA x SA)`` successor features, and re-weighting is one solve per policy
  (:class:`SuccessorFeatures`; the test checks it against the explicit ``psi``).
* **The dynamics** ``P`` the successor features are computed on: the counts model of the earlier
  runs (``N(s, a, s') / N(s, a)``; a pair never tried is a self-loop,
  :meth:`adpart.mdp.experience.Experience.estimate`), or the true model when none is given (then
  the learner declares it). With the self-loop an untried pair is worth ``w / (1 - gamma)``: 0
  until it is tried (optimism, as ``w``'s zero start), then its observed reward forever, so a
  pair the earlier runs never left (the earlier goal) stops attracting GPI once it is tried; a
  model where it had no successor instead promised the earlier goal as a free sink and GPI
  looped there (three-floor: 20 of 20 runs never reached the bound). The successor features
  are computed once: the new task's steps re-weight them and do not re-estimate them.
* **Terminal states** of the new task are learned when entered: from then on they are worth 0
  to every policy (their columns of ``P_pi`` are cut and the factors redone once).
* **The base policies** are the greedy policies of the earlier runs (``--model
  ENV@experience:run:N``: the same runs the dynamics are counted from), duplicates removed.
* **Learning the new task's own policy** (SFQL, their section 5): beside the base policies the
  agent keeps ``Q_new``, learned by Q-learning from the observed rewards (tabular features make
  ``psi_new . w`` a Q table), and GPI takes ``max(Q_new, max_i Q^{pi_i}_w)``. Behaviour is
  epsilon-greedy on that maximum over the admissible actions (ties at random); the evaluated
  policy is its greedy policy (ties to the lowest action).
* ``w`` is updated at every step; the GPI values of the base policies are recomputed at the end
  of every episode in which ``w`` moved or a terminal state was found.

Drawing successors, reading the reward of a step and ending an episode are the environment's
(:func:`adpart.learning.knowledge.world`); ``V*`` is for scoring only.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

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

__all__ = ["SuccessorFeatures", "sf_gpi_knowledge", "sf_gpi_learning"]


class SuccessorFeatures:
    """The successor features of ``policies`` (``(n, S)`` actions) on the dynamics ``P``
    (``(A*S, S)``, rows ``a*S + s``), with pair-indicator features, kept as one LU factor of
    ``I - gamma P_pi`` per policy (module docstring).

    :meth:`values` gives every ``Q^{pi_i}_w``; :meth:`gpi` their maximum. Factors are made for
    each terminal set asked for and kept (a run learns one or two terminal sets).
    """

    def __init__(self, P: sp.csr_array, policies: np.ndarray, gamma: float) -> None:
        if not 0.0 <= gamma < 1.0:
            raise ModelError(f"successor features need a discount below 1; gamma is {gamma} "
                             "(the values of a policy that never ends are unbounded)")
        self.P = sp.csr_array(P, dtype=np.float64)
        A_S, S = self.P.shape
        self.S, self.A = S, A_S // S
        self.policies = np.asarray(policies, dtype=np.int64).reshape(-1, S)
        if self.policies.size and (self.policies.min() < 0 or self.policies.max() >= self.A):
            raise ModelError(f"a base policy chooses an action outside [0, {self.A})")
        self.gamma = float(gamma)
        self._factors: dict[bytes, tuple[sp.csr_array, list]] = {}

    def _factored(self, terminal: np.ndarray) -> tuple[sp.csr_array, list]:
        key = np.packbits(terminal).tobytes()
        if key not in self._factors:
            keep = sp.diags_array((~terminal).astype(np.float64))
            cut = sp.csr_array(self.P @ keep)  # successors that are terminal are worth 0
            eye = sp.identity(self.S, format="csc")
            states = np.arange(self.S)
            lus = [splu(sp.csc_array(eye - self.gamma * cut[pi * self.S + states]))
                   for pi in self.policies]
            self._factors[key] = (cut, lus)
        return self._factors[key]

    def values(self, w: np.ndarray, terminal: np.ndarray) -> np.ndarray:
        """``(n, S, A)``: ``Q^{pi_i}_w(s, a) = psi^{pi_i}(s, a) . w`` for the reward weights
        ``w`` (``(S, A)``: the reward of each pair), terminal states worth 0."""
        n, S, A = len(self.policies), self.S, self.A
        if n == 0:
            return np.zeros((0, S, A))
        cut, lus = self._factored(np.asarray(terminal, dtype=bool))
        states = np.arange(S)
        V = np.column_stack([lu.solve(w[states, pi]) for lu, pi in
                              zip(lus, self.policies, strict=True)])
        after = (cut @ V).reshape(A, S, n)  # sum_s' P(s'|s, a) V_i(s'), rows a*S + s
        return w[None] + self.gamma * np.moveaxis(after, 2, 0).transpose(0, 2, 1)

    def gpi(self, w: np.ndarray, terminal: np.ndarray) -> np.ndarray:
        """``(S, A)``: ``max_i Q^{pi_i}_w`` (``-inf`` with no base policy)."""
        if len(self.policies) == 0:
            return np.full((self.S, self.A), -np.inf)
        return self.values(w, terminal).max(axis=0)


def sf_gpi_knowledge(experience: Experience | None, n_policies: int) -> Knowledge:
    """What the learner declares: the dynamics its successor features were computed on
    (estimated from the named runs, or the true model), rewards observed."""
    if n_policies == 0:
        return Knowledge("none", "observed", ("Q-learning; no base policy to transfer",))
    if experience is None:
        return Knowledge("true-model", "observed", (
            f"successor features of {n_policies} earlier policies on the true dynamics",))
    sources = ", ".join(experience.sources) or "earlier runs"
    return Knowledge("estimated", "observed", (
        f"successor features of {n_policies} policies of {sources} on their counts model",))


def _episode(s, Qn, Qb, admissible, keys, indptr, indices, env_R, env_terminal, r_sum, n_sa,
             n_s, terminal, eps, alpha, e, H, gamma, U):
    """One episode from ``s``: epsilon-greedy on ``max(Qn, Qb)`` (ties at random), the
    environment's step, the reward weights ``r_sum / n_sa`` updated, and Q-learning on ``Qn``.
    Three uniforms a step: explore?, which action, successor. Returns ``(steps, return,
    discounted return, w or the terminal set changed)``."""
    S, A = Qn.shape
    e_scale, e_rate, e_omega, e_floor = eps
    a_scale, a_rate, a_omega, a_floor = alpha
    steps = 0
    ret = 0.0
    dret = 0.0
    disc = 1.0
    changed = False
    while steps < H:
        epsilon = max(e_floor, e_scale * e_rate ** e * (n_s[s] + 1) ** (-e_omega))
        a = epsilon_greedy(U[steps, 0], U[steps, 1], epsilon, Qn[s], Qb[s], admissible[s])
        if a < 0:
            break
        row = a * S + s
        hi = indptr[row + 1]
        pos = min(first_above(keys, row + U[steps, 2], indptr[row], hi), hi - 1)
        s2 = indices[pos]
        r = env_R[s, a]
        before = r_sum[s, a] / n_sa[s, a] if n_sa[s, a] > 0 else 0.0
        n_s[s] += 1
        n_sa[s, a] += 1
        r_sum[s, a] += r
        if r_sum[s, a] / n_sa[s, a] != before:
            changed = True
        done = env_terminal[s2]
        target = r
        if not done:
            best2 = -np.inf
            for b in range(A):
                if admissible[s2, b] and Qn[s2, b] > best2:
                    best2 = Qn[s2, b]
            if best2 > -np.inf:
                target += gamma * best2
        step = max(a_floor, a_scale * a_rate ** e * n_sa[s, a] ** (-a_omega))
        Qn[s, a] += step * (target - Qn[s, a])
        steps += 1
        ret += r
        dret += disc * r
        disc *= gamma
        s = s2
        if done:
            if not terminal[s2]:
                terminal[s2] = True
                changed = True
            break
    return steps, ret, dret, changed


_KERNELS = {"numba": njit_lazily(_episode), "python": _episode}


def _base_policies(policies: np.ndarray | None, mdp: FiniteMDP) -> np.ndarray:
    """The distinct base policies, checked against ``mdp``'s states and admissible actions."""
    if policies is None:
        return np.zeros((0, mdp.n_states), dtype=np.int64)
    pis = np.asarray(policies)
    if pis.ndim == 1:
        pis = pis[None]
    if pis.ndim != 2 or pis.shape[1] != mdp.n_states or not np.issubdtype(pis.dtype, np.integer):
        raise ModelError(f"base policies must be (n, {mdp.n_states}) integer actions; got "
                         f"{pis.shape} {pis.dtype}")
    if pis.size and (pis.min() < 0 or pis.max() >= mdp.n_actions
                     or not mdp.admissible[np.arange(mdp.n_states)[None], pis].all()):
        raise ModelError("a base policy chooses an action that is not admissible in this "
                         "environment; the policies come from another environment")
    return np.unique(pis.astype(np.int64), axis=0)


def sf_gpi_learning(mdp: FiniteMDP, run: Run | None = None, *,
                    policies: np.ndarray | None = None,
                    experience: Experience | None = None) -> LearnResult:
    """Learn ``mdp`` with ``run.runs`` SF-GPI agents over the base ``policies``.

    Args:
        mdp: the task; sampled for steps, rewards and episode ends (and read for its dynamics
            only when ``experience`` is None and there are base policies: declared).
        run: the run settings: runs, episodes, seed, ``alpha`` (``Q_new``'s step size, visit
            count ``n(s, a)``), ``epsilon`` (visit count ``n(s)``), ``q_init`` (``Q_new``'s
            start, auto 0), the step limit, scoring, ``kernel`` (numba or python, the same
            source) and progress.
        policies: ``(n, S)`` the earlier policies whose successor features are transferred.
        experience: the earlier runs' counts the successor features are computed on; None:
            the true model.

    Returns:
        A :class:`~adpart.learning.result.LearnResult` whose ``Q`` is the GPI values
        ``max(Q_new, max_i Q^{pi_i}_w)`` at the end.

    Randomness: run ``k`` draws from ``default_rng(seed).spawn(K)[k]`` one uniform for each
    episode's start and ``3 H`` for its steps.
    """
    require_mdp("sf_gpi_learning", mdp)
    run = Run() if run is None else run
    K, N, M, H = run.runs, run.episodes, run.eval_every, run.max_steps_per_episode
    seed = fresh_seed(run.seed)
    name = resolve_kernel(run.kernel, "SF-GPI")
    episode = _KERNELS[name]
    S, A, gamma = mdp.n_states, mdp.n_actions, float(mdp.gamma)
    bases = _base_policies(policies, mdp)
    knowledge = sf_gpi_knowledge(experience, len(bases))
    if experience is not None and experience.counts.shape != (A * S, S):
        raise ModelError(f"the experience is of {experience.n_states} states and "
                         f"{experience.n_actions} actions; the task has {S} and {A}")
    admissible = np.ascontiguousarray(mdp.admissible, dtype=bool)
    with world():  # the environment: its start distribution, simulator and V* for scoring
        mu = start_distribution(mdp)
        v_star = optimal_start_value(mdp, mu, run.reference_values)
        keys, indptr, indices = mdp.sampler_arrays
        env_R = np.ascontiguousarray(mdp.R, dtype=np.float64)
        env_terminal = np.ascontiguousarray(mdp.terminal, dtype=bool)
        score = StartValues(mdp, mu, K)
    if len(bases) == 0:
        features = None
    elif experience is not None:
        features = SuccessorFeatures(experience.estimate(), bases, gamma)
    else:
        features = SuccessorFeatures(mdp.P, bases, gamma)  # declared: true-model dynamics
    start_cdf = np.cumsum(mu)
    eps, alpha = run.epsilon.params(), run.alpha.params()
    boundaries = sorted({*range(M, N + 1, M), N})
    out = {k: np.zeros((K, N)) for k in ("steps", "returns", "discounted")}
    eval_value = np.full((K, N), np.nan)
    Qn = np.where(admissible, run.start_q, -np.inf)[None].repeat(K, axis=0)
    Qb = np.full((K, S, A), -np.inf)
    r_sum, n_sa = np.zeros((K, S, A)), np.zeros((K, S, A), dtype=np.int64)
    n_s, terminal = np.zeros((K, S), dtype=np.int64), np.zeros((K, S), dtype=bool)
    refreshes = np.zeros(K, dtype=np.int64)

    def refresh(k: int) -> None:
        if features is not None:
            w = np.divide(r_sum[k], n_sa[k], out=np.zeros((S, A)), where=n_sa[k] > 0)
            Qb[k] = np.where(admissible, features.gpi(w, terminal[k]), -np.inf)
            refreshes[k] += 1

    for k in range(K):
        refresh(k)
    rngs = np.random.default_rng(seed).spawn(K)
    done = 0
    for boundary in boundaries:
        for k in range(K):
            rng = rngs[k]
            for e in range(done, boundary):
                s = int(min(np.searchsorted(start_cdf, rng.random(), side="right"), S - 1))
                U = rng.random((H, 3))
                steps, ret, dret, changed = episode(
                    s, Qn[k], Qb[k], admissible, keys, indptr, indices, env_R, env_terminal,
                    r_sum[k], n_sa[k], n_s[k], terminal[k], eps, alpha, e, H, gamma, U)
                if changed:
                    refresh(k)
                out["steps"][k, e], out["returns"][k, e] = steps, ret
                out["discounted"][k, e] = dret
        done = boundary
        G = np.maximum(Qn, Qb)
        with world():
            eval_value[:, boundary - 1] = score(greedy_policy(G.reshape(K * S, A)).reshape(K, S),
                                                np.ones(K, dtype=bool))
        if run.progress is not None:
            run.progress(boundary, N)
    parameters: dict[str, object] = {
        "runs": K, "episodes": N, "seed": seed, "alpha": run.alpha.to_dict(),
        "epsilon": run.epsilon.to_dict(), "q_init": run.start_q, "max_steps_per_episode": H,
        "eval_every": M, "kernel": name, "base_policies": len(bases),
        "reference": "given" if run.reference_values is not None else "solved",
        "knowledge": knowledge.to_dict(),
    }
    curve = LearningCurve.from_matrices(
        steps=out["steps"].astype(np.int64), decisions=out["steps"].astype(np.int64),
        returns=out["returns"], discounted_returns=out["discounted"], eval_value=eval_value,
        value_gap=v_star - eval_value,
        metadata={"learner": "sf-gpi", "mdp": mdp.name, "mdp_hash": mdp.content_hash,
                  "gamma": mdp.gamma, "v_star_start": v_star,
                  "gpi_refreshes": refreshes.tolist(), **parameters},
    )
    return LearnResult(Q=np.maximum(Qn, Qb), curve=curve, seed=seed, v_star_start=v_star,
                       parameters=parameters)
