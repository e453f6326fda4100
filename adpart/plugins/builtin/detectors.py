"""Built-in subgoal detectors (section 4.1 and the literature): thin plugin classes over the
library functions of :mod:`adpart.subgoals`, registered like any third-party plugin.

Call signature (hookspec ``register_subgoal_detectors``): ``cls(**params).detect(mdp, policy,
rng) -> SubgoalResult`` where ``policy`` is ``(S,)`` action ids or ``(S, A)`` probabilities.
"""

from __future__ import annotations

import time

import numpy as np

from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP
from adpart.params import Param
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar
from adpart.subgoals.discover import discover_exhaustive, discover_monte_carlo
from adpart.subgoals.literature import (
    betweenness,
    local_maxima,
    top_states,
    transition_graph,
    visit_frequency,
)
from adpart.subgoals.policy import check_mdp, check_policy
from adpart.subgoals.result import SubgoalResult
from adpart.subgoals.reward import with_reward_variation

_P = Param("p", "float", 0.025, "level of the one-sided t-test (eq. 4.2), in (0, 1)", min=0.0)
_TRAJ = Param("trajectories", "int", 30, "sampled paths along which ratios are taken (--ratios "
              "paths); count-mc: also its first batch", min=1)
_N = Param("n", "int", 0, "N of eq. 4.2 (ratio samples per state); 0 = automatic (4 with "
           "--ratios all)", min=0)
_RATIOS = Param("ratios", "str", "paths", "gradient ratios along sampled paths (paths, the "
                "seed's Fig. 4.2) or over every path of the count's walker (all)",
                choices=("paths", "all"))
_LOOP = Param("on-loop", "str", "truncate", "a policy that never terminates: error or truncate",
              choices=("error", "truncate"))


class CountExhaustive:
    """Count metric by sparse mat-vecs (eq. 4.1), gradient ratios, t-test threshold."""

    name = "count-exhaustive"
    description = "count metric by sparse mat-vecs (eq. 4.1), gradient ratios, t-test threshold"
    params = (_P, _TRAJ, _N, _LOOP, _RATIOS)

    def __init__(self, p: float = 0.025, trajectories: int = 30, n: int = 0,
                 on_loop: str = "truncate", ratios: str = "paths") -> None:
        self.kw = {"p": p, "trajectories": trajectories, "n": n, "on_loop": on_loop,
                   "ratios": ratios}

    def detect(self, mdp: FiniteMDP, policy: np.ndarray, rng: np.random.Generator) -> SubgoalResult:
        return discover_exhaustive(mdp, policy, rng, **self.kw)


class CountMonteCarlo:
    """Sampled count metric in batches (def. 4.4), Bernstein/stability stops, raised threshold."""

    name = "count-mc"
    description = "Monte Carlo count metric in batches (def. 4.4, eq. 4.3, theorem 4.3)"
    params = (
        _P, _TRAJ, _N,
        Param("batch", "int", 50, "trajectories per batch", min=1),
        Param("count-epsilon", "float", 2.0, "count accuracy eps_N of eq. 4.3 / theorem 4.3",
              min=0.0),
        Param("confidence", "float", 0.9, "probability p of eq. 4.3, in (0, 1)", min=0.0),
        Param("stable-batches", "int", 3, "stop when the subgoals are unchanged this many batches",
              min=1),
        Param("stop", "str", "passes", "stopping rule (passes: two passes over the start "
              "states agree; predicted: passes until the predicted Jaccard index with the exact "
              "set is 0.95)", choices=("passes", "predicted", "either", "bernstein", "stable",
                                       "max")),
        Param("max-samples", "int", 50_000, "most trajectories sampled", min=1),
        _LOOP,
        _RATIOS,
    )

    def __init__(self, p: float = 0.025, trajectories: int = 30, n: int = 0, batch: int = 50,
                 count_epsilon: float = 2.0, confidence: float = 0.9, stable_batches: int = 3,
                 stop: str = "passes", max_samples: int = 50_000,
                 on_loop: str = "truncate", ratios: str = "paths") -> None:
        self.kw = {"p": p, "trajectories": trajectories, "n": n, "batch": batch,
                   "epsilon": count_epsilon, "confidence": confidence,
                   "stable_batches": stable_batches,
                   "stop": stop, "max_samples": max_samples, "on_loop": on_loop,
                   "ratios": ratios}

    def detect(self, mdp: FiniteMDP, policy: np.ndarray, rng: np.random.Generator) -> SubgoalResult:
        return discover_monte_carlo(mdp, policy, rng, **self.kw)


_BASES = {"count-exhaustive": CountExhaustive, "count-mc": CountMonteCarlo, "none": None}


class RewardVariation:
    """A base detector's subgoals plus the states with above-minimum reward (4.3.1)."""

    name = "reward-variation"
    description = "base detector's subgoals plus states with reward above the minimum (4.3.1)"
    params = (
        Param("base", "str", "count-exhaustive", "detector whose subgoals are extended",
              choices=tuple(_BASES)),
        Param("level", "str", "min", "reward level to exceed: min (4.3.1) or a number (5.1.3: 0)"),
        Param("terminal-targets", "bool", True, "also add terminal states a rewarded pair reaches"),
    )

    def __init__(self, base: str = "count-exhaustive", level: str = "min",
                 terminal_targets: bool = True) -> None:
        if base not in _BASES:
            raise TaskError(f"base = {base!r}; use one of {', '.join(_BASES)}")
        try:
            self.level = None if str(level) == "min" else float(level)
        except ValueError:
            raise TaskError(f"level = {level!r}; use 'min' or a number such as 0") from None
        self.base, self.terminal_targets = base, bool(terminal_targets)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray, rng: np.random.Generator) -> SubgoalResult:
        t0 = time.perf_counter()
        factory = _BASES[self.base]
        if factory is None:
            mdp = check_mdp(mdp)
            check_policy(mdp, policy)
            base = SubgoalResult(np.zeros(0, np.int64), np.zeros(mdp.n_states), None)
        else:
            base = factory().detect(mdp, policy, rng)
        out = with_reward_variation(base, mdp, level=self.level,
                                    terminal_targets=self.terminal_targets)
        stats = dict(out.stats, time_s=time.perf_counter() - t0, base_detector=self.base)
        params = {"base": self.base, "level": "min" if self.level is None else self.level,
                  "terminal_targets": self.terminal_targets, "base_params": dict(base.params)}
        return SubgoalResult(out.subgoals, out.scores, out.threshold, stats, params, self.name)


#: How the betweenness detector turns scores into subgoals.
SELECT_RULES = ("local-maxima", "top")


class Betweenness:
    """Betweenness centrality of the policy-independent transition graph (Simsek & Barto 2008).

    Subgoals are the local maxima of betweenness (``select="local-maxima"``, the paper's rule:
    more central than every neighbour) or the ``top`` most central states (``select="top"``).
    """

    name = "betweenness"
    description = "local maxima (or top-k) of transition-graph betweenness (Simsek & Barto 2008)"
    params = (Param("select", "str", "local-maxima",
                    "local-maxima (higher than every neighbour, the paper's rule) or top",
                    choices=SELECT_RULES),
              Param("top", "int", 4, "number of subgoals with --select top", min=1),
              Param("sources", "int", 0, "sampled BFS sources; 0 = all (exact)", min=0))

    def __init__(self, select: str = "local-maxima", top: int = 4, sources: int = 0) -> None:
        if select not in SELECT_RULES:
            raise TaskError(f"select = {select!r}; use one of {', '.join(SELECT_RULES)}")
        self.select, self.top, self.sources = select, int(top), int(sources)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray | None, rng: np.random.Generator) -> (
        SubgoalResult
    ):
        t0 = time.perf_counter()
        mdp = check_mdp(mdp)
        S = mdp.n_states
        src = None
        if 0 < self.sources < S:
            src = np.sort(rng.choice(S, size=self.sources, replace=False))
        graph = transition_graph(mdp)
        scores = betweenness(graph, sources=src)
        subgoals = (local_maxima(graph, scores) if self.select == "local-maxima"
                    else top_states(scores, self.top))
        stats = {"time_s": time.perf_counter() - t0, "sources": S if src is None else src.size}
        return SubgoalResult(subgoals, scores, None, stats,
                             {"select": self.select, "top": self.top, "sources": self.sources},
                             self.name)


class VisitFrequency:
    """States visited by many successful random walks (Digney 1996, McGovern & Barto 2001)."""

    name = "visit-frequency"
    description = "top-k states on successful random walks (Digney 1996; McGovern & Barto 2001)"
    params = (Param("top", "int", 4, "number of subgoals (most visited)", min=1),
              Param("walks", "int", 500, "random walks sampled", min=1),
              Param("horizon", "int", 0, "step limit of a walk; 0 = 10 |S|", min=0))

    def __init__(self, top: int = 4, walks: int = 500, horizon: int = 0) -> None:
        self.top, self.walks, self.horizon = int(top), int(walks), int(horizon)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray | None, rng: np.random.Generator) -> (
        SubgoalResult
    ):
        t0 = time.perf_counter()
        scores, ok = visit_frequency(mdp, rng, walks=self.walks, horizon=self.horizon or None)
        stats = {"time_s": time.perf_counter() - t0, "successful_walks": ok, "walks": self.walks}
        return SubgoalResult(top_states(scores, self.top), scores, None, stats,
                             {"top": self.top, "walks": self.walks, "horizon": self.horizon},
                             self.name)


DETECTORS = (CountExhaustive, CountMonteCarlo, RewardVariation, Betweenness, VisitFrequency)


@hookimpl
def register_subgoal_detectors(register: Registrar) -> None:
    for cls in DETECTORS:
        register(cls)
