"""``sarsa``: on-policy TD(0) control (Rummery & Niranjan 1994; Sutton & Barto 2018, sec. 6.4).

Each of ``runs`` independent runs learns with

    Q(s, a) <- Q(s, a) + alpha * (r + gamma * Q(s', a') - Q(s, a)),

where ``a'`` is the epsilon-greedy action the run *will* take in ``s'`` (on-policy), and the
target is ``r`` alone when ``s'`` is terminal. ``alpha`` and ``epsilon`` are adpart schedules
(``"0.1"``, ``"1/n^0.8"``, ``"exp:0.5,0.99"``): the step size's visit count is ``n(s, a)``
(including this update), the exploration rate's ``n(s)`` (including this decision), and the
episode index ``e`` counts from 0, as for adpart's Q-learning. Exploration is over the
admissible actions; greedy ties during learning are broken uniformly at random. An episode is
cut after ``max_steps`` steps; the last update still bootstraps from ``Q(s', a')``.

The curve is scored like adpart's built-in learners: every ``eval_every``-th episode (and the
last), the greedy policy of every run (lowest action index on ties) is evaluated exactly on the
model and its value gap ``V*(mu) - V^pi(mu)`` recorded; the other episodes hold NaN.

Runs advance block by block (a block ends at each evaluated episode), so all runs are scored
together and ``progress`` can report episodes done by every run. Inside a run the episode is a
plain Python loop over steps - clear rather than fast (about 5 x 10^4 steps a second on one core,
a few hundred times slower than adpart's compiled Q-learning kernels).
Run ``k`` draws from ``np.random.default_rng(seed).spawn(runs)[k]``: the same seed gives the
same curve and Q.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from adpart.errors import TaskError
from adpart.learning import LearningCurve, LearnResult, parse_schedule
from adpart.learning.curves import optimal_start_value, start_distribution, start_values
from adpart.learning.knowledge import FLAT
from adpart.mdp.evaluation import greedy_policy
from adpart.mdp.model import FiniteMDP
from adpart.params import Param
from adpart.plugins import hookimpl

__all__ = ["SarsaLearner", "SarsaResult", "sarsa"]


@dataclass(frozen=True, eq=False, kw_only=True)
class SarsaResult(LearnResult):
    """What :func:`sarsa` returns: a :class:`LearnResult` plus the visit counts ``(K, S, A)``."""

    visits: np.ndarray


def _schedule(value: object, what: str):  # type: ignore[no-untyped-def]
    """A schedule from its spelling, in [0, 1] (a step size or an exploration rate)."""
    return parse_schedule(value).check_probability(what)  # type: ignore[arg-type]


def _count(value: object, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise TaskError(f"{what} = {value!r} must be an integer >= 1")
    return int(value)


class _Run:
    """One run's tables, random stream and per-episode records (Python lists for speed)."""

    def __init__(self, model: _Model, rng: np.random.Generator, episodes: int,
                 q_init: float) -> None:
        S, A = model.S, model.A
        self.model, self.rng = model, rng
        self.Q = [[q_init] * A for _ in range(S)]
        self.n_sa = [[0] * A for _ in range(S)]
        self.n_s = [0] * S
        self.episode = 0
        self.steps = np.zeros(episodes, dtype=np.int64)
        self.returns = np.zeros(episodes)
        self.discounted = np.zeros(episodes)

    def choose(self, s: int, e: int) -> int:
        """The epsilon-greedy action in ``s`` during episode ``e`` (counts the decision)."""
        m, rng = self.model, self.rng
        self.n_s[s] += 1
        actions = m.admissible[s]
        if rng.random() < m.epsilon(self.n_s[s], e):
            return actions[int(rng.integers(len(actions)))]
        row = self.Q[s]
        best = max(row[a] for a in actions)
        ties = [a for a in actions if row[a] == best]
        return ties[0] if len(ties) == 1 else ties[int(rng.integers(len(ties)))]

    def play_episode(self) -> None:
        """One episode from a start state, updating Q after every step."""
        m, rng, Q = self.model, self.rng, self.Q
        e = self.episode
        s = m.start(rng.random())
        a = self.choose(s, e)
        ret = dret = 0.0
        discount = 1.0
        t = 0
        while t < m.max_steps:
            t += 1
            r = m.R[s][a]
            s2 = m.step(s, a, rng)
            ret += r
            dret += discount * r
            discount *= m.gamma
            self.n_sa[s][a] += 1
            alpha = m.alpha(self.n_sa[s][a], e)
            if m.terminal[s2]:
                Q[s][a] += alpha * (r - Q[s][a])
                break
            a2 = self.choose(s2, e)
            Q[s][a] += alpha * (r + m.gamma * Q[s2][a2] - Q[s][a])
            s, a = s2, a2
        self.steps[e], self.returns[e], self.discounted[e] = t, ret, dret
        self.episode += 1


class _Model:
    """The MDP as Python lists: successors and cumulative probabilities of every (s, a)."""

    def __init__(self, mdp: FiniteMDP, mu: np.ndarray, alpha, epsilon,  # type: ignore[no-untyped-def]
                 max_steps: int) -> None:
        S, A = mdp.n_states, mdp.n_actions
        self.S, self.A, self.gamma, self.max_steps = S, A, float(mdp.gamma), max_steps
        self.R = mdp.R.tolist()
        self.terminal = mdp.terminal.tolist()
        self.admissible = [np.flatnonzero(row).tolist() for row in mdp.admissible]
        P = mdp.P  # (A*S, S) CSR, row a*S + s
        self.successors = [P.indices[P.indptr[r]:P.indptr[r + 1]].tolist() for r in range(A * S)]
        self.cumulative = [np.cumsum(P.data[P.indptr[r]:P.indptr[r + 1]]).tolist()
                           for r in range(A * S)]
        self.start_cdf = np.cumsum(mu).tolist()
        self.first_start = int(np.flatnonzero(mu > 0)[0])
        self.last_start = int(np.flatnonzero(mu > 0)[-1])
        self._alpha, self._epsilon = alpha.params(), epsilon.params()

    @staticmethod
    def _value(params: tuple[float, float, float, float], n: int, e: int) -> float:
        scale, rate, omega, floor = params  # Schedule.value: rate**e first, then n**(-omega)
        v = scale * rate**e
        if omega != 0.0:
            v = v * n ** (-omega)
        return max(floor, v)

    def alpha(self, n: int, e: int) -> float:
        return self._value(self._alpha, n, e)

    def epsilon(self, n: int, e: int) -> float:
        return self._value(self._epsilon, n, e)

    def start(self, u: float) -> int:
        """The start state at uniform ``u``: the first ``s`` with ``cdf(s) > u * total``."""
        s = bisect.bisect_right(self.start_cdf, u * self.start_cdf[-1])
        return min(max(s, self.first_start), self.last_start)

    def step(self, s: int, a: int, rng: np.random.Generator) -> int:
        row = a * self.S + s
        succ = self.successors[row]
        if len(succ) == 1:
            return succ[0]
        cum = self.cumulative[row]
        i = bisect.bisect_right(cum, rng.random() * cum[-1])
        return succ[min(i, len(succ) - 1)]


def sarsa(
    mdp: FiniteMDP,
    *,
    runs: int = 10,
    episodes: int = 300,
    seed: int = 0,
    alpha: object = "0.1",
    epsilon: object = "0.1",
    max_steps: int = 1000,
    q_init: float = 0.0,
    eval_every: int = 10,
    progress: Callable[[int, int], object] | None = None,
) -> SarsaResult:
    """Learn ``mdp`` with ``runs`` independent SARSA agents (see the module docstring).

    Returns a :class:`SarsaResult`: ``Q`` ``(runs, S, A)`` with ``-inf`` on inadmissible pairs,
    the exactly scored :class:`LearningCurve`, the seed and ``V*(mu)``.
    """
    if not isinstance(mdp, FiniteMDP):
        raise TaskError(f"sarsa needs an adpart FiniteMDP, got {type(mdp).__name__}")
    K, N, M = _count(runs, "runs"), _count(episodes, "episodes"), _count(eval_every, "eval_every")
    H = _count(max_steps, "max_steps")
    if seed is None or isinstance(seed, bool) or int(seed) < 0:
        raise TaskError(f"seed = {seed!r} must be an integer >= 0")
    seed = int(seed)
    alpha_s, eps_s = _schedule(alpha, "alpha"), _schedule(epsilon, "epsilon")
    if not np.isfinite(q_init):
        raise TaskError(f"q_init = {q_init!r} must be a finite number")

    mu = start_distribution(mdp)
    v_star = optimal_start_value(mdp, mu)
    model = _Model(mdp, mu, alpha_s, eps_s, H)
    agents = [_Run(model, rng, N, float(q_init))
              for rng in np.random.default_rng(seed).spawn(K)]

    eval_value = np.full((K, N), np.nan)
    for boundary in sorted({*range(M, N + 1, M), N}):
        for agent in agents:
            while agent.episode < boundary:
                agent.play_episode()
        Q = _q_array(agents, mdp)
        policies = greedy_policy(Q.reshape(K * mdp.n_states, -1)).reshape(K, mdp.n_states)
        eval_value[:, boundary - 1] = start_values(mdp, policies, mu)
        if progress is not None:
            progress(boundary, N)

    parameters: dict[str, object] = {
        "runs": K, "episodes": N, "seed": seed, "alpha": alpha_s.to_dict(),
        "epsilon": eps_s.to_dict(), "max_steps_per_episode": H, "eval_every": M,
        "q_init": float(q_init),
        "knowledge": FLAT.to_dict(),  # what it read of the task: samples and observed rewards
    }
    steps = np.stack([a.steps for a in agents])
    curve = LearningCurve.from_matrices(
        steps=steps,
        decisions=steps,
        returns=np.stack([a.returns for a in agents]),
        discounted_returns=np.stack([a.discounted for a in agents]),
        eval_value=eval_value,
        value_gap=v_star - eval_value,
        metadata={"learner": "sarsa", "mdp": mdp.name, "mdp_hash": mdp.content_hash,
                  "gamma": mdp.gamma, "v_star_start": v_star, **parameters},
    )
    Q = _q_array(agents, mdp)
    visits = np.array([a.n_sa for a in agents], dtype=np.int64)
    for arr in (Q, visits):
        arr.setflags(write=False)
    return SarsaResult(Q=Q, visits=visits, curve=curve, seed=seed, v_star_start=v_star,
                       parameters=parameters)


def _q_array(agents: list[_Run], mdp: FiniteMDP) -> np.ndarray:
    """``(K, S, A)`` float64 Q of every run, ``-inf`` where an action is not admissible."""
    Q = np.array([a.Q for a in agents], dtype=np.float64)
    return np.where(mdp.admissible[None], Q, -np.inf)


def _probability_schedule(what: str) -> Callable[[str], object]:
    return lambda value: _schedule(value, what)


class SarsaLearner:
    """The learner plugin: ``SarsaLearner(**params).learn(mdp, ...)`` runs :func:`sarsa`."""

    name = "sarsa"
    description = "on-policy TD(0) control (SARSA), epsilon-greedy, K independent runs"
    params = (
        Param("alpha", "str", "0.1", "step-size schedule: 0.1 | 1/n^0.8 | exp:0.5,0.99",
              check=_probability_schedule("alpha")),
        Param("epsilon", "str", "0.1", "exploration schedule, same forms as --alpha",
              check=_probability_schedule("epsilon")),
        Param("max-steps", "int", 1000, "primitive-step limit of one episode", min=1),
        Param("q-init", "float", 0.0, "initial value of every Q(s, a)"),
    )

    def __init__(self, alpha: str = "0.1", epsilon: str = "0.1", max_steps: int = 1000,
                 q_init: float = 0.0) -> None:
        self.alpha, self.epsilon = _schedule(alpha, "alpha"), _schedule(epsilon, "epsilon")
        self.max_steps, self.q_init = int(max_steps), float(q_init)

    def learn(self, mdp: FiniteMDP, *, runs: int, episodes: int, seed: int, eval_every: int,
              progress: Callable[[int, int], object] | None = None) -> SarsaResult:
        return sarsa(mdp, runs=runs, episodes=episodes, seed=seed, alpha=self.alpha,
                     epsilon=self.epsilon, max_steps=self.max_steps, q_init=self.q_init,
                     eval_every=eval_every, progress=progress)


@hookimpl
def register_learners(register) -> None:  # type: ignore[no-untyped-def]
    register(SarsaLearner)
