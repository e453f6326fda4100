"""Lock-step Q-learning throughput: K = 50 runs at once against a plain per-run Python loop.

Workload: ``random_grid_mdp(10_000)`` (a slippery 100x100 grid, at most three successors per row,
no terminal states) with a step limit of H = 200, so every episode is exactly 200 steps and every
kernel performs exactly ``K * N * H`` agent-steps. Both kernels run the one source of the rule
(:func:`adpart.learning._kernels.lockstep`) on the same per-run random streams and produce
bit-identical Q tables (checked here on the Python kernel's episodes), so the comparison is like
for like:

* ``python``  -- the reference: the rule run by the interpreter, one run after another (over a
  tenth of the episodes: it is slow, and its rate per agent-step does not depend on N);
* ``numba``   -- the same rule compiled with numba (the default kernel), once on one thread
  and once on all of numba's threads (one per core).

End to end: :func:`adpart.learning.q_learning` on the 10^5-state rooms grid
(``benchmarks._models.rooms_grid_mdp``, intended move 0.8, 0.1 to each side), K = 50 runs, 1 M
agent-steps, one evaluation at the end (50 policies scored), against the kernel alone driven the
same way (:func:`_kernel_alone`: same state, seeds and trajectories, timed around the kernel
calls). Both sides are measured in steady state: after a small call that loads the compiled code,
full-size calls of each side are made and discarded (a process's first full-size call pays
first-touch page faults that later calls do not), then the two sides alternate; the ratio is
printed as median / median and best / best. Each end-to-end call is split into the kernel, the
scoring (:class:`adpart.learning.curves.StartValues`), the experience
(:meth:`adpart.mdp.experience.Experience.from_positions`) and the rest. The final scores are
checked against one sparse LU per distinct policy (:func:`adpart.learning.curves.start_values`,
the exact reference): they must agree within 1e-9. ``repeated_evaluations()`` runs ``make
demo``'s two-rooms learning with today's evaluation step and the one of commit de831d6
(:class:`_BeforeStyle`) for the same comparison over many evaluations.

For scale, Gymnasium's Taxi-v4 is stepped through ``gymnasium.Env.step`` with random actions.
Figures are agent-steps per second of wall time, including the refills of the uniform buffers;
ratios are against the Python loop measured in the same run (best of ``repeats`` timings, after
one warm-up call that also loads numba's compiled cache). Run it on a quiet machine.
"""

from __future__ import annotations

import time

import numpy as np

from adpart.learning import _kernels
from adpart.learning.curves import start_distribution
from adpart.learning.qlearning import BLOCK_ROWS, _initial_state
from adpart.learning.schedules import constant, visit_count
from adpart.learning.settings import Run
from adpart.mdp.generate import random_grid_mdp


def _run_kernel(name: str, mdp, runs: int, episodes: int, horizon: int, seed: int = 0
                ) -> tuple[float, int, np.ndarray]:
    """Time one kernel on fresh state; returns (seconds, agent-steps, Q)."""
    st = _initial_state(mdp, runs, episodes, horizon, visit_count(0.8), constant(0.1), 0.0,
                        start_distribution(mdp))
    rngs = np.random.default_rng(seed).spawn(runs)
    st.state[:] = [st.start_state(rng.random()) for rng in rngs]
    st.target[:] = episodes
    kernel = _kernels.KERNELS[name]
    t0 = time.perf_counter()
    while kernel(st):
        for k in np.flatnonzero((st.cursor == BLOCK_ROWS) & (st.episode < st.target)):
            rngs[k].random(out=st.U[k])
            st.cursor[k] = 0
    seconds = time.perf_counter() - t0
    return seconds, int(st.out_steps.sum()), st.Q


def numba_threads() -> int:
    """numba's current thread count."""
    import numba

    return numba.get_num_threads()


def set_numba_threads(n: int) -> None:
    import numba

    numba.set_num_threads(n)


def _best(name: str, mdp, runs: int, episodes: int, horizon: int, repeats: int
          ) -> tuple[float, int, np.ndarray]:
    results = [_run_kernel(name, mdp, runs, episodes, horizon) for _ in range(repeats)]
    best = min(results, key=lambda r: r[0])
    return best


def _taxi_steps_per_second(n_steps: int = 100_000) -> float:
    import gymnasium

    env = gymnasium.make("Taxi-v4")
    rng = np.random.default_rng(0)
    actions = rng.integers(0, env.action_space.n, size=n_steps).tolist()
    env.reset(seed=0)
    t0 = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    seconds = time.perf_counter() - t0
    env.close()
    return n_steps / seconds


class _BeforeStyle:
    """The evaluation step of commit de831d6, swapped into :func:`q_learning` for a reference in
    the same run: the greedy policies recomputed from every visited row of Q into a fresh
    ``(K, S)`` int64 matrix, and :func:`adpart.learning.curves.start_values` of all K rows at
    every evaluation (row hashes, one solve per distinct policy). The kernel still keeps its
    greedy policies current (today's kernel), so only the evaluation step is the old one."""

    def __init__(self, qlearning) -> None:
        self.q = qlearning

    def __enter__(self):
        from adpart.learning import curves
        from adpart.mdp.evaluation import greedy_policy

        q = self.q
        self.saved = q._initial_state, q.StartValues
        make_state, held = q._initial_state, {}

        def initial_state(*args, **kwargs):
            st = make_state(*args, **kwargs)
            held["st"], held["unvisited"] = st, st.policy[0].astype(np.int64)
            return st

        class Score:
            def __init__(self, mdp, mu, runs):
                self.mdp, self.mu = mdp, mu

            def __call__(self, policies, changed):
                st = held["st"]
                K, S = st.n_s.shape
                pol = np.broadcast_to(held["unvisited"], (K, S)).copy()
                runs, states = np.nonzero(st.n_s)
                pol[runs, states] = greedy_policy(st.Q[runs, states])
                return curves.start_values(self.mdp, pol, self.mu)

        q._initial_state, q.StartValues = initial_state, Score
        return self

    def __exit__(self, *exc):
        self.q._initial_state, self.q.StartValues = self.saved


def _kernel_alone(mdp, run: Run) -> float:
    """The kernel's side of the end-to-end ratio: the lock-step kernel driven exactly as
    :func:`adpart.learning.q_learning` drives it (same state, settings, seeds and blocks, so the
    same trajectories), timed around the kernel calls only; no scoring, no result."""
    from adpart.learning import qlearning

    mu = start_distribution(mdp)
    st = qlearning._initial_state(mdp, run.runs, run.episodes, run.max_steps_per_episode,
                                  run.alpha, run.epsilon, run.start_q, mu)
    rngs = np.random.default_rng(run.seed).spawn(run.runs)
    st.state[:] = [st.start_state(rng.random()) for rng in rngs]
    kernel = _kernels.KERNELS[qlearning.default_kernel()]
    seconds = 0.0
    for boundary in sorted({*range(run.eval_every, run.episodes + 1, run.eval_every),
                            run.episodes}):
        st.target[:] = boundary
        while True:
            t0 = time.perf_counter()
            more = kernel(st)
            seconds += time.perf_counter() - t0
            if not more:
                break
            for k in np.flatnonzero((st.cursor == BLOCK_ROWS) & (st.episode < st.target)):
                rngs[k].random(out=st.U[k])
                st.cursor[k] = 0
    return seconds


def end_to_end(n_states: int = 100_000, runs: int = 50, agent_steps: int = 1_000_000,
               horizon: int = 200, repeats: int = 7, warm: int = 2, evaluations: int = 1
               ) -> dict:
    """``q_learning()`` end to end against its kernel alone, both in steady state.

    A small call loads the compiled code; then ``warm`` full-size calls of each side are made
    and discarded (the first full-size call of a process pays first-touch page faults and
    allocator growth that later calls do not); then ``repeats`` rounds alternate one end-to-end
    call and one kernel-alone run (:func:`_kernel_alone`), so both see the same machine load.
    Each call is split into the kernel, the scoring (``curves.StartValues``), the experience
    (``Experience.from_positions``) and the rest. The ratio is printed as median / median and
    best / best over the rounds, and per call against the call's own kernel time. The final
    evaluation's scores are checked against the one-LU-per-policy reference
    (:func:`adpart.learning.curves.start_values` of the returned greedy policies), which is
    timed once."""
    from adpart.learning import curves, qlearning
    from adpart.mdp.evaluation import policy_evaluation
    from adpart.mdp.experience import Experience
    from adpart.mdp.solvers import solve
    from benchmarks._models import rooms_grid_mdp

    mdp = rooms_grid_mdp(n_states, slip=0.2)  # 0.8 intended move, 0.1 to each side
    V = policy_evaluation(mdp, solve(mdp, 1e-10).policy)
    episodes = max(1, agent_steps // (runs * horizon))
    eval_every = max(1, episodes // evaluations)
    run = Run(runs=runs, episodes=episodes, max_steps_per_episode=horizon,
              eval_every=eval_every, reference_values=V, seed=0)
    parts = ("kernel", "scoring", "experience")
    timers = dict.fromkeys(parts, 0.0)

    def timed(f, key):
        def g(*args, **kwargs):
            t = time.perf_counter()
            out = f(*args, **kwargs)
            timers[key] += time.perf_counter() - t
            return out
        return g

    def call():
        timers.update(dict.fromkeys(parts, 0.0))
        t0 = time.perf_counter()
        result = qlearning.q_learning(mdp, run)
        total = time.perf_counter() - t0
        row = {"total_s": total, **{f"{k}_s": v for k, v in timers.items()}}
        row["rest_s"] = total - sum(timers.values())
        return row, result

    name = qlearning.default_kernel()
    kernel, score = _kernels.KERNELS[name], curves.StartValues.__call__
    from_positions = Experience.__dict__["from_positions"]
    rows: list[dict] = []
    alone: list[float] = []
    _kernels.KERNELS[name] = timed(kernel, "kernel")
    curves.StartValues.__call__ = timed(score, "scoring")
    Experience.from_positions = classmethod(timed(from_positions.__func__, "experience"))
    try:
        qlearning.q_learning(mdp, Run(runs=2, episodes=1, max_steps_per_episode=5,
                                      reference_values=V, seed=0))  # loads compiled code
        for _ in range(warm):  # discarded: first full-size calls
            _, result = call()
            _kernels.KERNELS[name] = kernel
            _kernel_alone(mdp, run)
            _kernels.KERNELS[name] = timed(kernel, "kernel")
        for _ in range(repeats):  # alternate, so both sides see the same machine load
            row, result = call()
            rows.append(row)
            _kernels.KERNELS[name] = kernel
            alone.append(_kernel_alone(mdp, run))
            _kernels.KERNELS[name] = timed(kernel, "kernel")
    finally:
        _kernels.KERNELS[name], curves.StartValues.__call__ = kernel, score
        Experience.from_positions = from_positions
    mu = curves.start_distribution(mdp)
    t0 = time.perf_counter()
    reference = curves.start_values(mdp, result.greedy_policies(), mu)
    reference_s = time.perf_counter() - t0
    scores = result.curve.matrix("eval_value")[:, -1]
    difference = float(np.max(np.abs(scores - reference)))
    same = difference <= 1e-9
    steps = int(result.curve["steps"].sum())
    n_distinct = curves.distinct_rows(result.greedy_policies())[0].size
    totals = np.array([r["total_s"] for r in rows])
    alone_a = np.array(alone)
    med = {k: float(np.median([r[k] for r in rows]))
           for k in ("total_s", "kernel_s", "scoring_s", "experience_s", "rest_s")}
    ratio_median = float(np.median(totals) / np.median(alone_a))
    ratio_best = float(totals.min() / alone_a.min())
    per_call = [r["total_s"] / r["kernel_s"] for r in rows]
    print(f"bench_qlearning end to end: q_learning() on rooms_grid_mdp({n_states:_}) "
          f"({mdp.n_states:,} states, slip 0.8/0.1/0.1), K={runs}, {steps:,} agent-steps, "
          f"{len(result.curve.evaluated_episodes())} evaluation(s) of {runs} policies "
          f"({n_distinct} distinct); steady state: {warm} discarded full-size call(s) of each "
          f"side, then {repeats} alternating rounds")
    print(f"  end to end (s):   median {np.median(totals):.3f}, best {totals.min():.3f}; "
          f"per call {[round(float(x), 3) for x in totals]}")
    print(f"  kernel alone (s): median {np.median(alone_a):.3f}, best {alone_a.min():.3f}; "
          f"per run {[round(float(x), 3) for x in alone_a]}")
    print(f"  end to end / kernel alone = {ratio_median:.2f} (median / median), "
          f"{ratio_best:.2f} (best / best)  (target <= 1.5)")
    print(f"  per call, end to end / its own kernel: {[round(float(x), 2) for x in per_call]}")
    print(f"  parts, median over calls (s): kernel {med['kernel_s']:.3f}, scoring "
          f"{med['scoring_s']:.3f}, experience {med['experience_s']:.3f}, rest {med['rest_s']:.3f}"
          f"  (of {med['total_s']:.3f})")
    print(f"  scores: largest |eval_value - one LU per policy| = {difference:.1e} (must be <= "
          f"1e-9: {same}); the reference scoring took {reference_s:.3f} s")
    return {"rows": rows, "kernel_alone_s": alone, "ratio_median": ratio_median,
            "ratio_best": ratio_best, "per_call_ratios": per_call, "parts_median": med,
            "agent_steps": steps, "difference": difference, "identical": same,
            "reference_s": reference_s, "total_per_kernel": ratio_median}


def repeated_evaluations(runs: int = 10, episodes: int = 300, eval_every: int = 25) -> dict:
    """``make demo``'s two-rooms learning (alpha 1, epsilon 0.5): how many of the scored
    policies needed a solve, and the call's time with today's and the before-style evaluation
    step (same curve)."""
    from adpart.envs.registry import get_domain
    from adpart.learning import curves, qlearning

    mdp = get_domain("two-rooms").mdp()
    kw = {"runs": runs, "episodes": episodes, "seed": 0, "alpha": 1.0, "epsilon": 0.5,
          "eval_every": eval_every}
    made = []

    class Counting(curves.StartValues):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)

    qlearning.q_learning(mdp, Run(**kw))  # warm-up
    times: dict[str, float] = {"today": np.inf, "before": np.inf}
    out = {}
    for _ in range(3):
        qlearning.StartValues = Counting
        try:
            t0 = time.perf_counter()
            out["today"] = qlearning.q_learning(mdp, Run(**kw)).curve["eval_value"]
            times["today"] = min(times["today"], time.perf_counter() - t0)
        finally:
            qlearning.StartValues = curves.StartValues
        with _BeforeStyle(qlearning):
            t0 = time.perf_counter()
            out["before"] = qlearning.q_learning(mdp, Run(**kw)).curve["eval_value"]
            times["before"] = min(times["before"], time.perf_counter() - t0)
    scored = runs * len(range(eval_every, episodes + 1, eval_every))
    difference = float(np.nanmax(np.abs(out["today"] - out["before"])))
    same = difference <= 1e-9
    solver = made[-1]._solver
    print(f"bench_qlearning repeated evaluations: two-rooms, K={runs} x {episodes} episodes, "
          f"evaluated every {eval_every}: {made[-1].solves} solves for {scored} scored policies "
          f"({solver.pushed} warm pushes, {solver.factored} LUs); call "
          f"{times['today'] * 1e3:.0f} ms (before-style {times['before'] * 1e3:.0f} ms); largest "
          f"|difference| {difference:.1e} (<= 1e-9: {same})")
    return {"solves": made[-1].solves, "scored": scored, "today_s": times["today"],
            "before_s": times["before"], "identical": same}


def main(runs: int = 50, episodes: int = 100, horizon: int = 200, repeats: int = 3) -> dict:
    """Print agent-steps/s of each kernel and the ratios; return the figures."""
    mdp = random_grid_mdp(10_000, gamma=0.95, seed=0)
    # Warm-up: load (or compile) the numba kernel outside the timings.
    _run_kernel("numba", mdp, 2, 1, 10)
    py_episodes = max(1, episodes // 10)
    t_py, n_py, q_py = _best("python", mdp, runs, py_episodes, horizon, 1)
    _, _, q_same = _best("numba", mdp, runs, py_episodes, horizon, 1)
    threads = numba_threads()
    set_numba_threads(1)
    t_n1, n_n1, q_n1 = _best("numba", mdp, runs, episodes, horizon, 3 * repeats)
    set_numba_threads(threads)
    t_nb, n_nb, q_nb = _best("numba", mdp, runs, episodes, horizon, 3 * repeats)
    assert n_n1 == n_nb == runs * episodes * horizon and n_py == runs * py_episodes * horizon
    identical = np.array_equal(q_py, q_same) and np.array_equal(q_n1, q_nb)
    rates = {"python": n_py / t_py, "numba-1-thread": n_n1 / t_n1,
             f"numba-{threads}-threads": n_nb / t_nb}
    taxi = _taxi_steps_per_second()
    print(f"bench_qlearning: random_grid_mdp(10_000), K={runs} runs x {episodes} episodes x "
          f"{horizon} steps = {n_nb:,} agent-steps per numba kernel ({n_py:,} for python)")
    for name, rate in rates.items():
        print(f"  {name:<16} {rate / 1e6:8.2f} M agent-steps/s   "
              f"x{rate / rates['python']:6.1f} the Python loop")
    print(f"  gymnasium Taxi-v4 Env.step: {taxi / 1e6:8.3f} M steps/s   "
          f"x{taxi / rates['python']:6.2f} the Python loop")
    print(f"  kernels bit-identical: {identical}; default kernel: {_kernels.default_kernel()}")
    e2e = end_to_end()
    repeated = repeated_evaluations()
    return {
        "end_to_end": e2e,
        "repeated_evaluations": repeated,
        "agent_steps": n_py,
        "steps_per_second": rates,
        "ratio_numba_1_thread_vs_python": rates["numba-1-thread"] / rates["python"],
        "ratio_numba_vs_python": rates[f"numba-{threads}-threads"] / rates["python"],
        "taxi_gymnasium_steps_per_second": taxi,
        "identical": identical,
    }


if __name__ == "__main__":
    main()
