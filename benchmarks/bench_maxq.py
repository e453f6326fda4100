"""MAXQ-Q against flat Q-learning: fickle Taxi (Dietterich 2000 sec. 7.1, Fig. 6) and Parr's
maze (sec. 7.3; dissertation ch. 6).

**Fickle Taxi** (516 states, moves succeed 0.8, the destination may change after pickup),
undiscounted (``gamma = 1``) because Dietterich's state abstractions are exact only then. All
learners use GLIE schedules so their greedy policies settle: step size ``1/n^0.6`` (per table
entry resp. per state-action pair) and exploration ``1/n^0.5`` (per decision state). Every
``EVAL`` episodes each run's greedy policy - for MAXQ-Q the hierarchically greedy (polled)
policy - is evaluated **exactly** on the flat model (a greedy policy that never delivers has no
finite value with gamma = 1 and counts as not converged). The reference is ``V*`` of the flat
model: the polled policy of this hierarchy can express the optimum (it re-decides in every
state, so it can re-route after the destination changes), and the final gaps below show that
the learners reach it. Figure: primitive steps until the greedy policy comes within ``GAP``
(mean over the start states) of ``V*`` and stays there, median over ``RUNS`` runs.
Dietterich: MAXQ-Q with abstraction about 40,000 steps, flat Q about twice as many.

**Parr's maze** (mini version, 1,988 states, gamma = 0.99 as the domain defines it): the
``parr-maze`` task graph has call-time parameters, so its hierarchical policy is not a
function of the cell alone and the polled policy is not the policy MAXQ-Q learns (polling
re-binds BackOne's start cell every step). It is scored by executing the hierarchical greedy
policy with its call stack (:func:`adpart.learning.maxq.hierarchical_rollouts`, ``ROLLOUTS``
episodes from the start cell, Monte Carlo), flat Q's greedy policy exactly; the reference is
``V*`` of the start cell. Figure: primitive steps until the score stays within ``PARR_GAP``.
Dietterich: MAXQ-Q about 10x faster than flat Q.

Run with ``python -m benchmarks bench_maxq`` or ``python benchmarks/bench_maxq.py``.
"""

from __future__ import annotations

import time

import numpy as np

from adpart.envs.domains.parr_maze import ParrMaze
from adpart.envs.domains.taxi import Taxi
from adpart.experiments.maxq import evaluated, fmt_steps, median_ci, steps_to_tolerance
from adpart.experiments.protocol import absorb_unreachable
from adpart.learning.curves import start_distribution
from adpart.learning.maxq import get_graph, hierarchical_rollouts, maxq_q, taxi_graph
from adpart.learning.maxq.maxq_q import _Run
from adpart.learning.qlearning import q_learning
from adpart.learning.schedules import parse_schedule
from adpart.learning.settings import Run
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.solvers import solve

#: Value-gap tolerance on fickle Taxi (reward units, averaged over the start states).
GAP = 0.5
RUNS = 10
EVAL = 25
ALPHA, EPSILON = "1/n^0.6", "1/n^0.5"
#: Parr's maze: tolerance on the start cell's value, rollouts per MAXQ evaluation.
PARR_GAP = 2.0
ROLLOUTS = 20


def _curve_steps(curve, eval_every: int, gap: float) -> np.ndarray:
    """Per run: primitive steps until the greedy policy stays within ``gap``; inf if never."""
    ev = evaluated(curve.n_episodes, eval_every)
    return steps_to_tolerance(curve.matrix("value_gap"), curve.matrix("steps"), ev, gap)[0]


def _final(gaps: np.ndarray) -> float:
    """Median final gap over runs; an undefined value (never finishing) counts as inf."""
    return float(np.median(np.where(np.isnan(gaps), np.inf, gaps)))


def _table(title: str, rows: dict[str, np.ndarray], finals: dict[str, float],
           timings: dict[str, float], runs: int) -> dict[str, float]:
    print(title)
    print(f"{'learner':<26}{'median steps':>14}{'95% CI of median':>26}{'runs settled':>14}"
          f"{'final gap':>11}{'cpu s':>8}")
    med = {}
    for label, steps in rows.items():
        m, lo, hi = median_ci(steps)
        med[label] = m
        ci = f"[{fmt_steps(lo)}, {fmt_steps(hi)}]"
        print(f"{label:<26}{fmt_steps(m):>14}{ci:>26}{int(np.isfinite(steps).sum()):>10}/{runs:<3}"
              f"{finals[label]:>11.3f}{timings[label]:>8.1f}")
    return med


def _ratio(num: float, den: float, budget: float) -> str:
    """``num / den`` of medians; a censored (inf) numerator gives a lower bound via the budget."""
    if np.isfinite(num) and np.isfinite(den):
        return f"{num / den:.2f}"
    if not np.isfinite(num) and np.isfinite(den):
        return f"> {budget / den:.2f} (numerator censored at its mean budget)"
    return "undefined (denominator never settled)"


def taxi(runs: int = RUNS, seed: int = 2000) -> dict[str, float]:
    # the 100 configurations no episode can enter are absorbing: a greedy policy that loops in
    # one of them would otherwise score NaN with gamma = 1 (docs/maxq.md, evaluation protocol)
    mdp = absorb_unreachable(Taxi(fickle=True, gamma=1.0).mdp())
    rows: dict[str, np.ndarray] = {}
    finals: dict[str, float] = {}
    timings: dict[str, float] = {}
    budgets: dict[str, float] = {}
    settings = {"MAXQ-Q, abstraction": (True, 3000), "MAXQ-Q, no abstraction": (False, 6000)}
    for label, (abstraction, episodes) in settings.items():
        g = taxi_graph().compile(mdp, abstraction=abstraction)
        t0 = time.process_time()
        res = maxq_q(mdp, g, Run(runs=runs, episodes=episodes, seed=seed, alpha=ALPHA,
                                 epsilon=EPSILON, eval_every=EVAL, max_steps_per_episode=1000))
        timings[label] = time.process_time() - t0
        rows[label] = _curve_steps(res.curve, EVAL, GAP)
        finals[label] = _final(res.curve.matrix("value_gap")[:, -1])
        budgets[label] = float(res.curve.matrix("steps").sum(axis=1).mean())
    t0 = time.process_time()
    res = q_learning(mdp, Run(runs=runs, episodes=30000, seed=seed, alpha=ALPHA, epsilon=EPSILON,
                              eval_every=EVAL, max_steps_per_episode=1000))
    timings["flat Q"] = time.process_time() - t0
    rows["flat Q"] = _curve_steps(res.curve, EVAL, GAP)
    finals["flat Q"] = _final(res.curve.matrix("value_gap")[:, -1])
    budgets["flat Q"] = float(res.curve.matrix("steps").sum(axis=1).mean())
    med = _table(f"fickle Taxi (516 states, gamma = 1), {runs} runs, alpha = {ALPHA}, "
                 f"epsilon = {EPSILON}; primitive steps until the greedy policy stays within "
                 f"{GAP} of V* (reference: V*, which the polled hierarchy reaches)",
                 rows, finals, timings, runs)
    ratio = med["flat Q"] / med["MAXQ-Q, abstraction"]
    ratio_no = med["MAXQ-Q, no abstraction"] / med["flat Q"]
    print(f"flat Q / MAXQ-Q (abstraction) = "
          f"{_ratio(med['flat Q'], med['MAXQ-Q, abstraction'], budgets['flat Q'])}"
          "   (Dietterich: about 2)")
    noabs = "MAXQ-Q, no abstraction"
    print(f"MAXQ-Q (no abstraction) / flat Q = "
          f"{_ratio(med[noabs], med['flat Q'], budgets[noabs])}"
          "   (Dietterich: > 1)")
    return {**{f"taxi steps[{k}]": v for k, v in med.items()}, "taxi flat/maxq": ratio,
            "taxi maxq-noabs/flat": ratio_no}


def parr(runs: int = RUNS, seed: int = 3000, episodes: int = 300,
         eval_every: int = 50) -> dict[str, float]:
    mdp = ParrMaze(mini=True).mdp()
    mu = start_distribution(mdp)
    v_star = float(mu @ policy_evaluation(mdp, solve(mdp, 1e-10).policy))
    g = get_graph("parr-maze").compile(mdp)
    eps_ = evaluated(episodes, eval_every)
    t0 = time.process_time()
    alpha_s, eps_s = parse_schedule(ALPHA), parse_schedule(EPSILON)
    rngs = np.random.default_rng(seed).spawn(runs)
    cdf = np.cumsum(mu)
    steps = np.zeros((runs, episodes), dtype=np.int64)
    gaps = np.full((runs, episodes), np.nan)
    for k in range(runs):
        agent = _Run(mdp, g, rngs[k], alpha_s, eps_s, 5000)
        i = 0
        for e in range(episodes):
            s0 = int(min(np.searchsorted(cdf, agent.rng.random(), side="right"),
                         mdp.n_states - 1))
            steps[k, e] = agent.episode_run(s0)[0]
            if e + 1 == eps_[i]:
                ret = hierarchical_rollouts(mdp, g, agent.tables(), ROLLOUTS,
                                            seed=seed + 7919 * k + e, max_steps=5000)
                gaps[k, e] = v_star - float(np.mean(ret[0])) if ret[2].all() else np.nan
                i += 1
    timings = {"MAXQ-Q": time.process_time() - t0}
    rows = {"MAXQ-Q": steps_to_tolerance(gaps, steps, eps_, PARR_GAP)[0]}
    finals = {"MAXQ-Q": _final(gaps[:, -1])}
    budget = float(steps.sum(axis=1).mean())
    t0 = time.process_time()
    flat_eps = episodes * 4
    res = q_learning(mdp, Run(runs=runs, episodes=flat_eps, seed=seed, alpha=ALPHA,
                              epsilon=EPSILON, eval_every=eval_every, max_steps_per_episode=5000))
    timings["flat Q"] = time.process_time() - t0
    rows["flat Q"] = _curve_steps(res.curve, eval_every, PARR_GAP)
    finals["flat Q"] = _final(res.curve.matrix("value_gap")[:, -1])
    flat_budget = float(res.curve.matrix("steps").sum(axis=1).mean())
    med = _table(f"Parr's mini maze (1,988 states, gamma = 0.99), {runs} runs, alpha = "
                 f"{ALPHA}, epsilon = {EPSILON}; primitive steps until the greedy policy stays "
                 f"within {PARR_GAP} of V*(start) = {v_star:.2f} (MAXQ-Q: hierarchical greedy "
                 f"execution, {ROLLOUTS} rollouts; flat Q: exact)", rows, finals, timings, runs)
    ratio = med["flat Q"] / med["MAXQ-Q"]
    print(f"flat Q / MAXQ-Q = {_ratio(med['flat Q'], med['MAXQ-Q'], flat_budget)}"
          "   (Dietterich, full maze: about 10)")
    print(f"mean primitive steps of the whole training: MAXQ-Q {budget:,.0f} over {episodes} "
          f"episodes, flat Q {flat_budget:,.0f} over {flat_eps} episodes")
    return {**{f"parr steps[{k}]": v for k, v in med.items()}, "parr flat/maxq": ratio}


def main(runs: int = RUNS) -> dict[str, float]:
    return {**taxi(runs), **parr(runs)}


if __name__ == "__main__":
    main()
