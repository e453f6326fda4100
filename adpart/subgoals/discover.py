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
    StartStream,
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

STOP_RULES = ("passes", "either", "bernstein", "stable", "max")
#: The ``"passes"`` rule stops when the subgoal sets of two consecutive full passes over the
#: start states agree to at least this Jaccard index.
PASS_AGREEMENT = 0.9


def _positive_int(value: object, what: str, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise TaskError(f"{what} = {value!r} must be an integer >= {low}")
    return int(value)


def _sample_epsilon(counts: np.ndarray, rs: RatioSamples, n: int, epsilon: float,
                    confidence: float) -> np.ndarray:
    """Theorem 4.3's ``eps_N`` per ratio sample: the accuracy eq. 4.3 guarantees after ``n``
    samples with ``a = max(C_H(s_t), C_H(s_{t+1}))``, the largest count the sample's two
    states reach (the proof's ``max_t C_H(s_t)`` taken over the states the bound is used for),
    at most ``epsilon``. A global maximum would let one looping state's huge count raise
    every threshold."""
    c_t = counts[rs.states]
    a = np.maximum(c_t, c_t + rs.next_delta)
    cl = np.maximum(a, 0.0) * np.log(2.0 / (1.0 - confidence))
    eps = (cl + np.sqrt(cl * cl + 2.0 * n * cl)) / n
    return np.minimum(epsilon, eps)


def _jaccard(a: np.ndarray, b: np.ndarray) -> float:
    union = np.union1d(a, b).size
    return np.intersect1d(a, b).size / union if union else 1.0


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
    stop: str = "passes",
    max_samples: int = 50_000,
    horizon: int | None = None,
    on_loop: str = "error",
) -> SubgoalResult:
    """Subgoals from the sampled count metric (definition 4.4), batch by batch.

    The counts ``C_H`` add each sampled trajectory's accumulated likelihoods of arrival
    (:func:`adpart.subgoals._walkers.expected_arrivals`), and start states are drawn without
    replacement (:class:`~adpart.subgoals.montecarlo.StartStream`): after ``k |S|`` samples
    every state has started ``k`` trajectories. Both keep ``C_H`` unbiased and cut its variance;
    on deterministic dynamics one pass (``N = |S|``) gives ``C*`` exactly.

    After each batch of ``batch`` trajectories the counts ``C_H``, the threshold ``mu`` and the
    subgoal set are recomputed and recorded (the data of Figs. 5.7/5.12). Sampling stops by
    ``stop``: ``"passes"`` (default) at the end of a full pass over the start states (every
    ``|S|`` samples) once the subgoal sets of the last two passes have a Jaccard index of at
    least :data:`PASS_AGREEMENT`, or after one pass when the policy and dynamics are
    deterministic (the counts are then exact); a batch is then a pass. When those passes do not
    fit under ``max_samples`` (a large model, where the exhaustive count is what Monte Carlo is
    meant to avoid) the rule is ``"either"``; ``"bernstein"`` when the sample count meets eq.
    4.3 with the current ``max C_H`` and ``epsilon`` (the seed's rule; it stops after a few
    hundred samples, far too early for the counts to be accurate to ``epsilon``, because eq. 4.3
    bounds each trajectory's count by ``max C_H`` rather than by ``|S|``); ``"stable"`` when the
    subgoal set has not changed over ``stable_batches`` batches; ``"either"`` whichever of those
    two comes first; ``"max"`` only at ``max_samples``. A state is a subgoal when some path
    reaches ``mu + 2 eps_N / max(1, Delta_H(s_{t+1}))`` (theorem 4.3), with ``eps_N`` the
    accuracy the samples drawn so far guarantee by eq. 4.3 for the sample's two states
    (:func:`_sample_epsilon`; at most ``epsilon``).

    Args:
        epsilon: the count accuracy ``eps_N`` of theorems 4.2-4.3 the ``"bernstein"`` rule aims
            at, in standard count units (section 5.1.4 uses 5 for the a-priori bound and 2 for
            the raised threshold).
        confidence: the probability ``p`` of eq. 4.3 (section 5.1.4 uses 0.9).

    The other arguments are as in :func:`discover_exhaustive`.
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
    triples = interior_triples(ratio_paths)
    # deterministic dynamics and policy: one stratified pass of expected arrivals is C* itself
    deterministic = pol.ndim == 1 and bool(
        np.all(np.diff(mdp.P.indptr)[pol * S + np.arange(S)] <= 1))
    if stop == "passes" and (S if deterministic else 2 * S) > max_samples:
        stop = "either"  # the passes the rule needs do not fit under the cap: a large model
    starts = StartStream(S, rng)
    # the count samples are drawn apart from the ratio paths (stratified starts, expected
    # arrivals); the first batch is as large as the ratio paths were
    arrivals, truncated = sample_arrivals(mdp, pol, trajectories, rng, horizon, checked=True,
                                          starts=starts.take(trajectories), expected=True)
    n_samples = trajectories
    pass_sets: list[np.ndarray] = []
    history: list[dict[str, object]] = []
    sets: list[np.ndarray] = []
    reason = "max_samples"
    while True:
        size = min(batch, max_samples - n_samples) if n_samples < max_samples else 0
        if stop == "passes" and n_samples < max_samples:
            # one batch per pass over the start states: the rule looks only at pass ends
            size = min(max_samples - n_samples, S - n_samples % S)
        if size > 0:
            batch_arrivals, cut = sample_arrivals(mdp, pol, size, rng, horizon, checked=True,
                                                  starts=starts.take(size), expected=True)
            arrivals += batch_arrivals
            truncated += cut
            n_samples += size
        counts = S * arrivals / n_samples
        rs = gradient_ratios(counts, triples)
        mu, nu, sd, n_ps = _threshold(rs, S, p, n)
        max_c = float(counts.max())
        eps_n = _sample_epsilon(counts, rs, n_samples, epsilon, confidence)
        passed = rs.ratios > mu + 2.0 * eps_n / np.maximum(1.0, rs.next_delta)
        subgoals = np.unique(rs.states[passed])
        needed = bernstein_samples(max_c, epsilon, confidence)
        history.append({"samples": n_samples, "n_subgoals": int(subgoals.size),
                        "subgoals": subgoals.tolist(), "threshold": mu, "max_count": max_c,
                        "bernstein_samples": needed})
        sets.append(subgoals)
        stable = len(sets) > stable_batches and all(
            np.array_equal(s, subgoals) for s in sets[-stable_batches - 1:]
        )
        if stop == "passes" and n_samples % S == 0:
            pass_sets.append(subgoals)
            if deterministic or (len(pass_sets) >= 2
                            and _jaccard(pass_sets[-2], subgoals) >= PASS_AGREEMENT):
                reason = "passes"
                break
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
        "passes": n_samples / S,
        "trapped_states": int(trapped.size),
        "history": history,
        "time_s": time.perf_counter() - t0,
    }
    params = {"p": p, "trajectories": trajectories, "n": n, "batch": batch, "epsilon": epsilon,
              "confidence": confidence, "stable_batches": stable_batches, "stop": stop,
              "max_samples": max_samples, "horizon": horizon, "on_loop": on_loop}
    return SubgoalResult(subgoals, scores, mu, stats, params, "count-mc")
