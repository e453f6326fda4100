"""MAXQ-Q against flat Q-learning on Dietterich's fickle Taxi (Dietterich 2000, sec. 7.1, Fig. 6).

Fickle Taxi (516 states, noisy moves, the destination may change after pickup), undiscounted
as in the paper (``gamma = 1``). Learners, all epsilon-greedy with epsilon = 0.1 and the same
seeds: MAXQ-Q with Dietterich's state abstractions, MAXQ-Q without them, and flat Q-learning.
Every ``eval_every`` episodes each run's greedy policy (for MAXQ-Q the hierarchically greedy,
polled policy) is scored exactly on the flat model. The figure is the number of **primitive
steps** a run has taken when its greedy policy first comes within ``GAP`` of ``V*`` at the start
distribution and stays there (median over runs). Reference (Dietterich): MAXQ-Q with
abstraction reaches the hierarchically optimal policy after about 40,000 primitive steps, flat Q
after about twice as many; MAXQ-Q without abstraction is slower than flat Q.

Run with ``python -m benchmarks bench_maxq`` or ``python benchmarks/bench_maxq.py``.
"""

from __future__ import annotations

import time

import numpy as np

from adpart.envs.domains.taxi import Taxi
from adpart.learning.maxq import maxq_q, taxi_graph
from adpart.learning.qlearning import q_learning

#: Value-gap threshold (reward units, averaged over the 300 start states).
GAP = 0.5


def steps_to_gap(curve, eval_every: int, gap: float = GAP) -> np.ndarray:
    """Per run: cumulative primitive steps at the first evaluation from which the gap stays
    ``<= gap`` (NaN if it never settles; a policy that never delivers scores NaN)."""
    n = curve.n_episodes
    eps = np.array(sorted({*range(eval_every, n + 1, eval_every), n}))
    ok = curve.matrix("value_gap")[:, eps - 1] <= gap  # NaN compares False
    stays = np.flip(np.logical_and.accumulate(np.flip(ok, axis=1), axis=1), axis=1)
    cum = np.cumsum(curve.matrix("steps"), axis=1)
    first = np.argmax(stays, axis=1)
    return np.where(stays.any(axis=1), cum[np.arange(len(first)), eps[first] - 1], np.nan)


def main(runs: int = 5, seed: int = 2000) -> dict[str, float]:
    mdp = Taxi(fickle=True, gamma=1.0).mdp()
    rows: dict[str, np.ndarray] = {}
    finals: dict[str, float] = {}
    timings: dict[str, float] = {}
    settings = {
        "MAXQ-Q, abstraction": {"abstraction": True, "episodes": 4000},
        "MAXQ-Q, no abstraction": {"abstraction": False, "episodes": 8000},
    }
    for label, cfg in settings.items():
        g = taxi_graph().compile(mdp, abstraction=cfg["abstraction"])
        t0 = time.process_time()
        res = maxq_q(mdp, g, runs=runs, episodes=cfg["episodes"], seed=seed, alpha="0.5",
                     epsilon="0.1", eval_every=25, max_steps_per_episode=1000)
        timings[label] = time.process_time() - t0
        rows[label] = steps_to_gap(res.curve, 25)
        finals[label] = float(np.nanmean(res.curve.matrix("value_gap")[:, -1]))
    t0 = time.process_time()
    res = q_learning(mdp, runs=runs, episodes=8000, seed=seed, alpha="0.5", epsilon="0.1",
                     eval_every=25, max_steps_per_episode=1000)
    timings["flat Q"] = time.process_time() - t0
    rows["flat Q"] = steps_to_gap(res.curve, 25)
    finals["flat Q"] = float(np.nanmean(res.curve.matrix("value_gap")[:, -1]))

    print(f"fickle Taxi (516 states, gamma = 1), {runs} runs, alpha = 0.5, epsilon = 0.1; "
          f"steps until the greedy policy stays within {GAP} of V*")
    print(f"{'learner':<26}{'median steps':>14}{'runs settled':>14}{'final gap':>11}{'cpu s':>8}")
    for label, steps in rows.items():
        med = np.nanmedian(steps) if np.isfinite(steps).any() else np.nan
        print(f"{label:<26}{med:>14,.0f}{int(np.isfinite(steps).sum()):>10}/{runs:<3}"
              f"{finals[label]:>11.3f}{timings[label]:>8.1f}")
    med = {k: float(np.nanmedian(v)) if np.isfinite(v).any() else float("nan")
           for k, v in rows.items()}
    ratio = med["flat Q"] / med["MAXQ-Q, abstraction"]
    ratio_no = med["MAXQ-Q, no abstraction"] / med["flat Q"]
    print(f"flat Q / MAXQ-Q (abstraction) = {ratio:.2f}   (Dietterich: about 2)")
    print(f"MAXQ-Q (no abstraction) / flat Q = {ratio_no:.2f}   (Dietterich: > 1)")
    return {**{f"steps[{k}]": v for k, v in med.items()}, "flat/maxq": ratio,
            "maxq-noabs/flat": ratio_no}


if __name__ == "__main__":
    main()
