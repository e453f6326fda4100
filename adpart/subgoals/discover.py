"""Subgoal discovery with the count metric: exhaustive (4.1.1) and Monte Carlo (4.1.1.2).

Both pipelines: count metric -> gradient ratios -> the t-test threshold ``mu`` at level ``p``
(eq. 4.2) -> subgoals = states some path through which reaches ``mu``. The Monte Carlo version
estimates the counts from sampled trajectories in batches (definition 4.4) and requires
``ratio > mu + 2 eps / max(1, Delta_H(s_{t+1}))`` (theorem 4.3).

By default (``ratios="paths"``, the seed's procedure of Fig. 4.2) the ratios are taken along
``trajectories`` sampled paths, drawn first from ``rng``, so with the same seed both detectors
judge the same paths and differ only through the counts.

``ratios="all"`` (a choice, not the default) takes them over **every** path of the count's
walker, each weighted by its accumulated likelihood (:class:`~adpart.subgoals.ratios.PathRatios`):
section 4.1.1.1 takes ``nu`` and ``sigma`` from "the distribution of gradient ratios over the
entire space" and asks for "at least one path through s" reaching ``mu``; this is the limit of
ever more sampled paths, so the exhaustive set no longer depends on the seed (30 sampled paths on
three-floor-arm: ``mu`` from 10.5 to 17.5 and Jaccard 0.25-0.38 between seeds). It is not the
default because it changes the discovered sets the project's measured results rest on
(three-floor: 36 subgoals instead of about 8, urban: 336 instead of 0-3; docs/subgoals.md).
"""

from __future__ import annotations

import math
import time

import numpy as np

from adpart.mdp.model import FiniteMDP
from adpart.params import settings_dict
from adpart.subgoals.count import count_metric
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
    ALL_PATHS_N,
    PathRatios,
    PathStructure,
    RatioSamples,
    gradient_ratios,
    interior_triples,
    samples_per_state,
    t_test_threshold,
)
from adpart.subgoals.result import SubgoalResult
from adpart.subgoals.settings import (
    RATIO_MODES,
    STOP_RULES,
    CountSettings,
    MonteCarloSettings,
    given,
)

__all__ = ["BATCH_GROWTH", "MIN_PASSES", "PASS_AGREEMENT", "PREDICTED_AGREEMENT", "RATIO_MODES",
           "STOP_RULES", "discover_exhaustive", "discover_monte_carlo"]

#: The ``"passes"`` rule (default) stops when the subgoal sets of two consecutive full passes
#: over the start states agree to at least this Jaccard index.
PASS_AGREEMENT = 0.9
#: The ``"predicted"`` rule stops at the end of a full pass over the start states once the
#: Jaccard index the subgoal set is predicted to have with the exact one
#: (:func:`_predicted_jaccard`) reaches this. The prediction treats the margins as normal and
#: their per-pass spread as the only error, which is optimistic: over 20 seeds on
#: three-floor-arm (pure Gauss-Seidel's optimal policy, ratios over every path), 0.9 gave actual
#: indices of 0.82-0.98 after 3-4 passes, 0.95 gave 0.90-1.0 after 3-14 passes.
PREDICTED_AGREEMENT = 0.95
#: ... and after at least this many passes (the standard errors need replicates).
MIN_PASSES = 3
#: With ``ratios="all"`` and the ``"either"``, ``"stable"`` and ``"bernstein"`` rules a batch is
#: at least ``batch`` samples and at least this fraction of the samples drawn so far (each
#: judgement is then an ``O(nnz)`` pass over the walker). With ``ratios="paths"`` every batch
#: has ``batch`` samples.
BATCH_GROWTH = 0.1


def _sample_epsilon(c_t: np.ndarray, next_delta: np.ndarray, n: int, epsilon: float,
                    confidence: float) -> np.ndarray:
    """Theorem 4.3's ``eps_N`` per ratio: the accuracy eq. 4.3 guarantees after ``n``
    samples with ``a = max(C_H(s_t), C_H(s_{t+1}))``, the largest count the ratio's two
    states reach (the proof's ``max_t C_H(s_t)`` taken over the states the bound is used for),
    at most ``epsilon``. A global maximum would let one looping state's huge count raise
    every threshold. ``c_t`` is ``C_H(s_t)``, ``next_delta`` ``Delta_H(s_{t+1})``."""
    a = np.maximum(c_t, c_t + next_delta)
    cl = np.maximum(a, 0.0) * np.log(2.0 / (1.0 - confidence))
    eps = (cl + np.sqrt(cl * cl + 2.0 * n * cl)) / n
    return np.minimum(epsilon, eps)


def _predicted_jaccard(decided: np.ndarray, margin: np.ndarray,
                       replicates: np.ndarray) -> float:
    """The Jaccard index the subgoal set ``decided`` is expected to have with the exact one.

    ``margin`` (``(S,)``) is each state's score minus ``mu`` (not raised; -inf without a ratio)
    under the counts of all ``K`` passes, ``replicates`` (``(K, S)``) the same under each pass's
    counts alone: the passes are independent, identically distributed estimates (stratified
    starts), so a state's margin has standard error ``se = sd / sqrt(K)`` over them, and it
    belongs to the exact set with probability ``q = Phi(margin / se)`` (normal errors; ``q`` is
    0 or 1 where ``se = 0``). ``decided`` (``(S,)`` bool) is the detector's set, theorem 4.3's
    raise included. The index is ``(|set| - sum_set (1 - q)) / (|set| + sum_rest q)``.
    """
    from scipy.special import ndtr

    k = replicates.shape[0]
    finite = np.isfinite(margin) & np.all(np.isfinite(replicates), axis=0)
    se = np.zeros_like(margin)
    se[finite] = replicates[:, finite].std(axis=0, ddof=1) / np.sqrt(k)
    q = (margin >= 0).astype(np.float64)
    live = finite & (se > 0)
    q[live] = ndtr(margin[live] / se[live])
    n_set = int(decided.sum())
    wrong_in = float((1.0 - q[decided]).sum())
    wrong_out = float(q[~decided].sum())
    return (n_set - wrong_in) / (n_set + wrong_out) if n_set + wrong_out > 0 else 1.0


def _jaccard(a: np.ndarray, b: np.ndarray) -> float:
    union = np.union1d(a, b).size
    return np.intersect1d(a, b).size / union if union else 1.0


def _threshold(rs: RatioSamples | PathRatios, S: int, p: float,
               n: int) -> tuple[float, float, float, int]:
    nu, sd = rs.summary()
    if n:
        n_ps = n
    else:
        n_ps = ALL_PATHS_N if isinstance(rs, PathRatios) else samples_per_state(rs, S)
    return t_test_threshold(nu, sd, n_ps, p), nu, sd, n_ps


def discover_exhaustive(
    mdp: FiniteMDP,
    policy: np.ndarray,
    rng: np.random.Generator,
    settings: CountSettings | None = None,
    *,
    horizon: int | None = None,
) -> SubgoalResult:
    """Subgoals from the exhaustive count metric (eq. 4.1) and the t-test threshold (eq. 4.2).

    By default (``ratios="paths"``) the ratios are taken along ``trajectories`` paths sampled
    from ``rng`` (Fig. 4.2). With ``ratios="all"`` the result does not depend on ``rng``: ``nu``,
    ``sigma`` and each state's largest ratio are taken over every path of the count's walker,
    weighted by likelihood (:class:`~adpart.subgoals.ratios.PathRatios`), and ``N`` defaults to
    :data:`~adpart.subgoals.ratios.ALL_PATHS_N`.

    Args:
        settings: the level ``p``, the ratio paths ``trajectories``, ``N`` of eq. 4.2 (``n``,
            0 = automatic: :data:`~adpart.subgoals.ratios.ALL_PATHS_N` over every path,
            :func:`samples_per_state` over sampled paths), ``ratios`` and ``on_loop``
            (:class:`~adpart.subgoals.settings.CountSettings`, checked there; None: its
            defaults).
        horizon: step cap of the sampled paths (default ``|S|``; ``ratios="paths"`` only).
    """
    t0 = time.perf_counter()
    s = given(CountSettings, settings)
    p, n, trajectories, ratios = s.p, s.n, s.trajectories, s.ratios
    mdp = check_mdp(mdp)
    pol = check_policy(mdp, policy)
    cm = count_metric(mdp, pol, s)
    t_count = time.perf_counter() - t0
    S = mdp.n_states
    if ratios == "all":
        rs = PathStructure(walker_matrix(mdp, pol)).ratios(cm.standard)
        mu, nu, sd, n_ps = _threshold(rs, S, p, n)
        scores, n_ratios = rs.scores, rs.n_triples
    else:
        traj = sample_trajectories(mdp, pol, trajectories, rng, horizon, checked=True)
        rs = gradient_ratios(cm.standard, traj)
        mu, nu, sd, n_ps = _threshold(rs, S, p, n)
        scores, n_ratios = rs.per_state_max(S), rs.n
    subgoals = np.flatnonzero((scores >= mu) & (scores > 0))
    stats = {
        "ratio_mean": nu,
        "ratio_sd": sd,
        "samples_per_state": n_ps,
        "ratio_samples": n_ratios,
        "ratios": ratios,
        "trajectories": trajectories if ratios == "paths" else 0,
        "count_iterations": cm.iterations,
        "count_remaining_mass": cm.remaining,
        "max_count": float(cm.standard.max()),
        "trapped_states": int(cm.trapped.size),
        "count_time_s": t_count,
        "time_s": time.perf_counter() - t0,
    }
    params = {**settings_dict(s), "horizon": horizon}
    return SubgoalResult(subgoals, scores, mu, stats, params, "count-exhaustive")


def discover_monte_carlo(
    mdp: FiniteMDP,
    policy: np.ndarray,
    rng: np.random.Generator,
    settings: MonteCarloSettings | None = None,
    *,
    horizon: int | None = None,
) -> SubgoalResult:
    """Subgoals from the sampled count metric (definition 4.4), batch by batch.

    The counts ``C_H`` add each sampled trajectory's accumulated likelihoods of arrival
    (:func:`adpart.subgoals._walkers.expected_arrivals`), and start states are drawn without
    replacement (:class:`~adpart.subgoals.montecarlo.StartStream`): after ``k |S|`` samples
    every state has started ``k`` trajectories. Both keep ``C_H`` unbiased and cut its variance;
    on deterministic dynamics one pass (``N = |S|``) gives ``C*`` exactly.

    After each batch the counts ``C_H``, the threshold ``mu`` and the subgoal set are
    recomputed and recorded (the data of Figs. 5.7/5.12). Sampling stops by ``stop``:
    ``"passes"`` (default) at the end of a full pass over the start states (every ``|S|``
    samples) once the subgoal sets of the last two passes have a Jaccard index of at least
    :data:`PASS_AGREEMENT`, or after one pass when the policy and dynamics are deterministic
    (the counts are then exact); a batch is then a pass. ``"predicted"`` (a choice) also stops
    only at pass ends, after at least :data:`MIN_PASSES` passes, once the Jaccard index the set
    is predicted to have with the exact one reaches :data:`PREDICTED_AGREEMENT`
    (:func:`_predicted_jaccard`: the passes are independent replicates of the counts, so their
    spread gives each state's chance of being on the other side of ``mu``), or after one pass
    on deterministic dynamics. When the passes a pass rule needs do not fit under
    ``max_samples`` (a large model, where the exhaustive count is what Monte Carlo is meant to
    avoid) the rule is ``"either"``; ``"bernstein"`` when the sample count meets eq. 4.3 with
    the current ``max C_H`` and ``count_epsilon`` (the seed's rule; it stops after a few
    hundred samples, far too early for the counts to be accurate to ``count_epsilon``, because
    eq. 4.3 bounds each trajectory's count by ``max C_H`` rather than by ``|S|``); ``"stable"``
    when the subgoal set has not changed over ``stable_batches`` batches; ``"either"`` whichever
    of those two comes first; ``"max"`` only at ``max_samples``. Batches other than passes have
    ``batch`` samples; with ``ratios="all"`` and ``"either"``, ``"stable"`` or ``"bernstein"``
    at least ``batch`` and :data:`BATCH_GROWTH` of the samples so far (not past eq. 4.3's
    count), so the set is judged ``O(log N)`` times. A state is a subgoal when some path reaches
    ``mu + 2 eps_N / max(1, Delta_H(s_{t+1}))`` (theorem 4.3), with ``eps_N`` the accuracy the
    samples drawn so far guarantee by eq. 4.3 for the ratio's two states
    (:func:`_sample_epsilon`; at most ``count_epsilon``).

    Args:
        settings: :class:`~adpart.subgoals.settings.MonteCarloSettings` (None: its defaults):
            its ``count`` group as in :func:`discover_exhaustive`; ``batch``, ``stop``,
            ``stable_batches``, ``max_samples``; ``count_epsilon``, the count accuracy
            ``eps_N`` of theorems 4.2-4.3 the ``"bernstein"`` rule aims at, in standard count
            units (section 5.1.4 uses 5 for the a-priori bound and 2 for the raised threshold);
            ``confidence``, the probability ``p`` of eq. 4.3 (section 5.1.4 uses 0.9).
        horizon: step cap of every sampled trajectory (default ``|S|``).

    With ``ratios="paths"`` (default) the ``trajectories`` ratio paths are sampled first, as the
    exhaustive detector samples them. With ``ratios="all"`` the ratios are those of every path of
    the walker under ``C_H`` (:class:`~adpart.subgoals.ratios.PathRatios`: the walker's edges
    only, ``O(nnz)`` per batch, no exhaustive count), so ``C_H -> C*`` makes the result the
    exhaustive one; the first batch has ``trajectories`` samples.

    The stored ``params`` are the settings; ``stats["stop"]`` is the rule applied (``"either"``
    when the passes the requested rule needs do not fit under ``max_samples``).
    """
    t0 = time.perf_counter()
    s = given(MonteCarloSettings, settings)
    p, n, trajectories, ratios = s.count.p, s.count.n, s.count.trajectories, s.count.ratios
    batch, stable_batches, max_samples, stop = s.batch, s.stable_batches, s.max_samples, s.stop
    epsilon, confidence = s.count_epsilon, s.confidence
    mdp = check_mdp(mdp)
    pol = check_policy(mdp, policy)
    S = mdp.n_states
    walker = walker_matrix(mdp, pol)
    trapped = trapped_states(walker)
    if trapped.size and s.count.on_loop == "error":
        raise loop_error(trapped, "the sampled count metric")

    if ratios == "all":
        structure = PathStructure(walker)
    else:
        ratio_paths = sample_trajectories(mdp, pol, trajectories, rng, horizon, checked=True)
        triples = interior_triples(ratio_paths)
    # deterministic dynamics and policy: one stratified pass of expected arrivals is C* itself
    deterministic = pol.ndim == 1 and bool(
        np.all(np.diff(mdp.P.indptr)[pol * S + np.arange(S)] <= 1))
    passes_needed = {"passes": 2, "predicted": MIN_PASSES}.get(stop, 0)
    predict = stop == "predicted"
    if passes_needed and (S if deterministic else passes_needed * S) > max_samples:
        stop = "either"  # the passes the rule needs do not fit under the cap: a large model
    by_pass = stop in ("passes", "predicted")
    starts = StartStream(S, rng)
    # the count samples are drawn apart from the ratio paths (stratified starts, expected
    # arrivals); the first batch is as large as the ratio paths were
    def judge(counts: np.ndarray, n_drawn: int) -> tuple:
        """``(subgoals, ratios, mu, nu, sd, N, margin)`` of counts from ``n_drawn`` samples;
        ``margin`` is ``(S,)`` each state's score minus ``mu`` (-inf without a ratio); the
        subgoals pass the threshold raised by theorem 4.3."""
        if ratios == "all":
            rs = structure.ratios(counts)
            mu, nu, sd, n_ps = _threshold(rs, S, p, n)
            eps_n = _sample_epsilon(counts, rs.next_delta, n_drawn, epsilon, confidence)
            raised = rs.scores - 2.0 * eps_n / np.maximum(1.0, rs.next_delta)
            has = rs.scores > 0
            subgoals = np.flatnonzero(has & (raised > mu))
            margin = np.where(has, rs.scores - mu, -np.inf)
            return subgoals, rs, mu, nu, sd, n_ps, margin
        rs = gradient_ratios(counts, triples)
        mu, nu, sd, n_ps = _threshold(rs, S, p, n)
        eps_n = _sample_epsilon(counts[rs.states], rs.next_delta, n_drawn, epsilon, confidence)
        passed = rs.ratios > mu + 2.0 * eps_n / np.maximum(1.0, rs.next_delta)
        margin = np.full(S, -np.inf)
        np.maximum.at(margin, rs.states, rs.ratios - mu)
        return np.unique(rs.states[passed]), rs, mu, nu, sd, n_ps, margin

    arrivals, truncated = sample_arrivals(mdp, pol, trajectories, rng, horizon, checked=True,
                                          starts=starts.take(trajectories), expected=True)
    n_samples = trajectories
    # the "predicted" rule: each full pass is an independent replicate of the counts; its margins
    pass_arrivals, pass_n = arrivals.copy(), trajectories
    pass_margins: list[np.ndarray] = []
    pass_sets: list[np.ndarray] = []
    history: list[dict[str, object]] = []
    sets: list[np.ndarray] = []
    reason = "max_samples"
    needed = 0
    while True:
        rest = max_samples - n_samples
        if rest <= 0:
            size = 0
        elif by_pass:
            # one batch per pass over the start states: the rule looks only at pass ends
            size = min(rest, S - n_samples % S)
        elif stop == "max" or ratios == "paths":
            size = min(rest, batch)
        else:
            # batches grow with the sample, so the sets are judged O(log N) times, each in O(nnz)
            size = max(batch, math.ceil(BATCH_GROWTH * n_samples))
            if stop != "stable" and needed > n_samples:
                size = min(size, needed - n_samples)  # do not overshoot eq. 4.3's count
            size = min(rest, size)
        if size > 0:
            batch_arrivals, cut = sample_arrivals(mdp, pol, size, rng, horizon, checked=True,
                                                  starts=starts.take(size), expected=True)
            arrivals += batch_arrivals
            pass_arrivals += batch_arrivals
            pass_n += size
            truncated += cut
            n_samples += size
        counts = S * arrivals / n_samples
        max_c = float(counts.max())
        subgoals, rs, mu, nu, sd, n_ps, margin = judge(counts, n_samples)
        predicted = None
        if stop == "predicted" and n_samples % S == 0 and not deterministic:
            pass_margins.append(judge(S * pass_arrivals / pass_n, pass_n)[6])
            pass_arrivals, pass_n = np.zeros(S), 0
            if len(pass_margins) >= MIN_PASSES:
                inside = np.zeros(S, dtype=bool)
                inside[subgoals] = True
                predicted = _predicted_jaccard(inside, margin, np.stack(pass_margins))
        needed = bernstein_samples(max_c, epsilon, confidence)
        history.append({"samples": n_samples, "n_subgoals": int(subgoals.size),
                        "subgoals": subgoals.tolist(), "threshold": mu, "max_count": max_c,
                        "bernstein_samples": needed})
        if predict:
            history[-1]["predicted_jaccard"] = predicted
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
        if stop == "predicted" and n_samples % S == 0 and (
                deterministic or (predicted is not None and predicted >= PREDICTED_AGREEMENT)):
            reason = "predicted"
            break
        if stop in ("either", "bernstein") and n_samples >= needed:
            reason = "bernstein"
            break
        if stop in ("either", "stable") and stable:
            reason = "stable"
            break
        if n_samples >= max_samples:
            break
    scores = rs.scores if ratios == "all" else rs.per_state_max(S)
    stats = {
        "ratio_mean": nu,
        "ratio_sd": sd,
        "samples_per_state": n_ps,
        "ratio_samples": rs.n_triples if ratios == "all" else rs.n,
        "ratios": ratios,
        "trajectories": trajectories,
        "stop": stop,
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
    params = {**settings_dict(s), "horizon": horizon}
    return SubgoalResult(subgoals, scores, mu, stats, params, "count-mc")
