"""Subgoal discovery with the count metric: exhaustive (4.1.1) and Monte Carlo (4.1.1.2).

Both pipelines: count metric -> gradient ratios along ``trajectories`` sampled paths -> the
t-test threshold ``mu`` at level ``p`` (eq. 4.2) -> subgoals = states some sampled path through
which reaches ``mu``. The Monte Carlo version estimates the counts from sampled trajectories in
batches (definition 4.4) and requires ``ratio > mu + 2 eps / max(1, Delta_H(s_{t+1}))``
(theorem 4.3). Both draw their ratio paths first from ``rng``, so with the same seed they judge
the same paths and differ only through the counts.
"""

from __future__ import annotations

import time

import numpy as np

from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP
from adpart.subgoals.count import check_on_loop, count_metric
from adpart.subgoals.montecarlo import (
    arrival_counts,
    bernstein_epsilon,
    bernstein_samples,
    sample_arrivals,
    sample_trajectories,
)
from adpart.subgoals.policy import (
    check_mdp,
    check_policy,
    loop_error,
    trapped_states,
    walker_matrix,
)
from adpart.subgoals.ratios import (
    RatioSamples,
    check_level,
    gradient_ratios,
    interior_triples,
    samples_per_state,
    t_test_threshold,
)
from adpart.subgoals.result import SubgoalResult

STOP_RULES = ("either", "bernstein", "stable", "max")


def _positive_int(value: object, what: str, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise TaskError(f"{what} = {value!r} must be an integer >= {low}")
    return int(value)


def _threshold(rs: RatioSamples, S: int, p: float, n: int) -> tuple[float, float, float, int]:
    nu, sd = rs.summary()
    n_ps = samples_per_state(rs, S) if n == 0 else n
    return t_test_threshold(nu, sd, n_ps, p), nu, sd, n_ps


def discover_exhaustive(
    mdp: FiniteMDP,
    policy: np.ndarray,
    rng: np.random.Generator,
    *,
    p: float = 0.025,
    trajectories: int = 30,
    n: int = 0,
    horizon: int | None = None,
    on_loop: str = "error",
) -> SubgoalResult:
    """Subgoals from the exhaustive count metric (eq. 4.1) and the t-test threshold (eq. 4.2).

    Args:
        p: level of the one-sided t-test, in (0, 1).
        trajectories: paths sampled under the policy along which ratios are evaluated (30: with
            the automatic N this finds exactly the doorway of two-rooms for every seed tried;
            the seed's example, Fig. 4.2, uses 10).
        n: the ``N`` of eq. 4.2; 0 = automatic (:func:`samples_per_state`).
        horizon: step cap of the sampled paths (default ``|S|``).
        on_loop: ``"error"`` or ``"truncate"`` for a policy that never terminates.
    """
    t0 = time.perf_counter()
    mdp = check_mdp(mdp)
    pol = check_policy(mdp, policy)
    p = check_level(p)
    trajectories = _positive_int(trajectories, "trajectories")
    n = _positive_int(n, "n", 0)
    cm = count_metric(mdp, pol, on_loop=check_on_loop(on_loop))
    t_count = time.perf_counter() - t0
    S = mdp.n_states
    traj = sample_trajectories(mdp, pol, trajectories, rng, horizon, checked=True)
    rs = gradient_ratios(cm.standard, traj)
    mu, nu, sd, n_ps = _threshold(rs, S, p, n)
    scores = rs.per_state_max(S)
    subgoals = np.flatnonzero((scores >= mu) & (scores > 0))
    stats = {
        "ratio_mean": nu,
        "ratio_sd": sd,
        "samples_per_state": n_ps,
        "ratio_samples": rs.n,
        "trajectories": trajectories,
        "count_iterations": cm.iterations,
        "count_remaining_mass": cm.remaining,
        "max_count": float(cm.standard.max()),
        "trapped_states": int(cm.trapped.size),
        "count_time_s": t_count,
        "time_s": time.perf_counter() - t0,
    }
    params = {"p": p, "trajectories": trajectories, "n": n, "horizon": horizon, "on_loop": on_loop}
    return SubgoalResult(subgoals, scores, mu, stats, params, "count-exhaustive")


def discover_monte_carlo(
    mdp: FiniteMDP,
    policy: np.ndarray,
    rng: np.random.Generator,
    *,
    p: float = 0.025,
    trajectories: int = 30,
    n: int = 0,
    batch: int = 50,
    epsilon: float = 2.0,
    confidence: float = 0.9,
    stable_batches: int = 3,
    stop: str = "either",
    max_samples: int = 20000,
    horizon: int | None = None,
    on_loop: str = "error",
) -> SubgoalResult:
    """Subgoals from the sampled count metric (definition 4.4), batch by batch.

    After each batch of ``batch`` trajectories the counts ``C_H``, the threshold ``mu`` and the
    subgoal set are recomputed and recorded (the data of Figs. 5.7/5.12). Sampling stops by
    ``stop``: ``"bernstein"`` when the sample count meets eq. 4.3 with the current
    ``max C_H`` and ``epsilon``; ``"stable"`` when the subgoal set has not changed over
    ``stable_batches`` batches; ``"either"`` (default) whichever comes first; ``"max"`` only at
    ``max_samples``. A state is a subgoal when some path reaches
    ``mu + 2 epsilon / max(1, Delta_H(s_{t+1}))`` (theorem 4.3).

    Args:
        epsilon: the count accuracy ``eps_N`` of theorems 4.2-4.3, in standard count units
            (section 5.1.4 uses 5 for the a-priori bound and 2 for the raised threshold).
        confidence: the probability ``p`` of eq. 4.3 (section 5.1.4 uses 0.9).
        Other arguments as in :func:`discover_exhaustive`.
    """
    t0 = time.perf_counter()
    mdp = check_mdp(mdp)
    pol = check_policy(mdp, policy)
    p = check_level(p)
    trajectories = _positive_int(trajectories, "trajectories")
    n = _positive_int(n, "n", 0)
    batch = _positive_int(batch, "batch")
    stable_batches = _positive_int(stable_batches, "stable_batches")
    max_samples = _positive_int(max_samples, "max_samples")
    bernstein_samples(1.0, epsilon, confidence)  # validates epsilon and confidence
    if stop not in STOP_RULES:
        raise TaskError(f"stop = {stop!r}; use one of {', '.join(STOP_RULES)}")
    check_on_loop(on_loop)
    S = mdp.n_states
    trapped = trapped_states(walker_matrix(mdp, pol))
    if trapped.size and on_loop == "error":
        raise loop_error(trapped, "the sampled count metric")

    ratio_paths = sample_trajectories(mdp, pol, trajectories, rng, horizon, checked=True)
    arrivals = arrival_counts(ratio_paths, S)
    triples = interior_triples(ratio_paths)
    n_samples = trajectories
    truncated = int(ratio_paths.truncated.sum())
    history: list[dict[str, object]] = []
    sets: list[np.ndarray] = []
    reason = "max_samples"
    while True:
        size = min(batch, max_samples - n_samples) if n_samples < max_samples else 0
        if size > 0:
            batch_arrivals, cut = sample_arrivals(mdp, pol, size, rng, horizon, checked=True)
            arrivals += batch_arrivals
            truncated += cut
            n_samples += size
        counts = S * arrivals / n_samples
        rs = gradient_ratios(counts, triples)
        mu, nu, sd, n_ps = _threshold(rs, S, p, n)
        passed = rs.ratios > mu + 2.0 * epsilon / np.maximum(1.0, rs.next_delta)
        subgoals = np.unique(rs.states[passed])
        max_c = float(counts.max())
        needed = bernstein_samples(max_c, epsilon, confidence)
        history.append({"samples": n_samples, "n_subgoals": int(subgoals.size),
                        "subgoals": subgoals.tolist(), "threshold": mu, "max_count": max_c,
                        "bernstein_samples": needed})
        sets.append(subgoals)
        stable = len(sets) > stable_batches and all(
            np.array_equal(s, subgoals) for s in sets[-stable_batches - 1:]
        )
        if stop in ("either", "bernstein") and n_samples >= needed:
            reason = "bernstein"
            break
        if stop in ("either", "stable") and stable:
            reason = "stable"
            break
        if n_samples >= max_samples:
            break
    scores = rs.per_state_max(S)
    stats = {
        "ratio_mean": nu,
        "ratio_sd": sd,
        "samples_per_state": n_ps,
        "ratio_samples": rs.n,
        "trajectories": trajectories,
        "samples": n_samples,
        "batches": len(history),
        "stop_reason": reason,
        "truncated_trajectories": truncated,
        "max_count": max_c,
        "epsilon": epsilon,
        "confidence": confidence,
        "bernstein_a_priori": bernstein_samples(float(S), epsilon, confidence),
        "bernstein_empirical": needed,
        "epsilon_achieved": bernstein_epsilon(n_samples, max_c, confidence),
        "trapped_states": int(trapped.size),
        "history": history,
        "time_s": time.perf_counter() - t0,
    }
    params = {"p": p, "trajectories": trajectories, "n": n, "batch": batch, "epsilon": epsilon,
              "confidence": confidence, "stable_batches": stable_batches, "stop": stop,
              "max_samples": max_samples, "horizon": horizon, "on_loop": on_loop}
    return SubgoalResult(subgoals, scores, mu, stats, params, "count-mc")
