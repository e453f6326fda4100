from __future__ import annotations

import math

import numpy as np
import pytest

from adpart.errors import ModelError, TaskError
from adpart.learning import constant, exponential, q_learning, visit_count
from adpart.learning.settings import Run
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.generate import random_mdp
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import solve

from .conftest import corridor, slippery_grid

KERNELS = ("numba", "python")


def reference_q_learning(mdp: FiniteMDP, *, runs, episodes, seed, alpha, epsilon, horizon):
    """An independent per-agent implementation of the documented rule (docs/learning.md).

    Run k draws from ``default_rng(seed).spawn(runs)[k]``: one uniform for the first start, then
    four per step (explore?, which action, successor by inverse CDF, next start). Returns the
    runs' Q tables, their episode lengths and the transitions they took, ``counts[s, a, s']``.
    """
    S, A = mdp.n_states, mdp.n_actions
    counts = np.zeros((S, A, S), dtype=np.int64)
    mu = np.where(mdp.terminal, 0.0, mdp.initial)
    mu = mu / mu.sum()
    Qs, steps = [], []
    for rng in np.random.default_rng(seed).spawn(runs):
        Q = np.where(mdp.admissible, 0.0, -np.inf)
        n_sa = np.zeros((S, A), dtype=np.int64)
        n_s = np.zeros(S, dtype=np.int64)
        s = int(np.searchsorted(np.cumsum(mu), rng.random(), side="right"))
        ep_steps = []
        for e in range(episodes):
            t = 0
            while True:
                u = rng.random(4)
                n_s[s] += 1
                eps = epsilon.scale * epsilon.rate ** float(e)
                if epsilon.omega:
                    eps *= float(n_s[s]) ** -epsilon.omega
                eps = max(epsilon.floor, eps)
                if u[0] < eps:
                    allowed = np.flatnonzero(mdp.admissible[s])
                else:
                    allowed = np.flatnonzero(Q[s] == Q[s].max())
                a = int(allowed[int(u[1] * len(allowed))])
                succ, probs = mdp.transition_row(s, a)
                s2 = int(succ[min(np.searchsorted(np.cumsum(probs), u[2], side="right"),
                                  len(succ) - 1)])
                counts[s, a, s2] += 1
                r = mdp.R[s, a]
                n_sa[s, a] += 1
                lr = alpha.scale * alpha.rate ** float(e)
                if alpha.omega:
                    lr *= float(n_sa[s, a]) ** -alpha.omega
                lr = max(alpha.floor, lr)
                target = r if mdp.terminal[s2] else r + mdp.gamma * Q[s2].max()
                Q[s, a] = Q[s, a] + lr * (target - Q[s, a])
                t += 1
                if mdp.terminal[s2] or t == horizon:
                    s = int(np.searchsorted(np.cumsum(mu), u[3], side="right"))
                    break
                s = s2
            ep_steps.append(t)
        Qs.append(Q)
        steps.append(ep_steps)
    return np.array(Qs), np.array(steps), counts


def _final_gaps(result) -> np.ndarray:
    return result.curve.matrix("value_gap")[:, -1]


# ----------------------------------------------------------------------------- convergence


def test_corridor_all_runs_reach_optimal_policy(corridor_mdp):
    # Budget: 60 episodes with epsilon = 0.2, alpha = 1/n^0.8 (docs/learning.md).
    res = q_learning(corridor_mdp, Run(runs=8, episodes=60, seed=1, epsilon=0.2, eval_every=10))
    gaps = _final_gaps(res)
    assert np.all(np.abs(gaps) < 1e-6), gaps
    assert res.v_star_start == pytest.approx(0.9**4)
    assert np.all(res.greedy_policies()[:, :-1] == 1)  # always right


def test_slippery_grid_all_runs_reach_optimal_policy(grid_mdp):
    # Budget: 3,000 episodes of uniform exploration (epsilon = 1, off-policy), alpha = 1/n^0.8,
    # on the 4x4 grid with slip 0.2 (smallest non-zero optimal action gap 0.055).
    res = q_learning(grid_mdp, Run(runs=8, episodes=3000, seed=2, alpha="1/n^0.8", epsilon=1.0,
                                   eval_every=1000))
    gaps = _final_gaps(res)
    assert np.all(np.abs(gaps) < 1e-6), gaps
    v_star = policy_evaluation(grid_mdp, solve(grid_mdp, 1e-10).policy)[0]
    assert res.v_star_start == pytest.approx(v_star, abs=1e-9)


# ----------------------------------------------------------------------------- determinism


def test_same_seed_is_bit_identical_and_different_seeds_differ(grid_mdp):
    kw = {"runs": 3, "episodes": 20, "alpha": "1/n^0.7", "epsilon": "exp:0.5,0.9,0.05",
          "eval_every": 5}
    a = q_learning(grid_mdp, Run(seed=11, **kw))
    b = q_learning(grid_mdp, Run(seed=11, **kw))
    c = q_learning(grid_mdp, Run(seed=12, **kw))
    assert np.array_equal(a.Q, b.Q)
    for col in a.curve.columns:
        assert np.array_equal(a.curve[col], b.curve[col], equal_nan=True), col
    assert a.seed == b.seed == 11
    assert not np.array_equal(a.Q, c.Q)
    assert not np.array_equal(a.curve["steps"], c.curve["steps"])


def test_runs_differ_from_each_other(grid_mdp):
    res = q_learning(grid_mdp, Run(runs=4, episodes=10, seed=0))
    assert len({res.Q[k].tobytes() for k in range(4)}) == 4


def test_seed_none_is_recorded_and_reproduces(corridor_mdp):
    a = q_learning(corridor_mdp, Run(runs=2, episodes=5, seed=None))
    b = q_learning(corridor_mdp, Run(runs=2, episodes=5, seed=a.seed))
    assert np.array_equal(a.Q, b.Q)
    assert a.parameters["seed"] == a.curve.metadata["seed"] == a.seed


@pytest.mark.parametrize("kernel", KERNELS)
def test_kernels_are_bit_identical(kernel):
    mdp = random_mdp(12, 3, density=0.3, seed=5)
    mdp = mdp.with_rewards(mdp.R, terminal=np.arange(12) == 11)
    kw = {"runs": 4, "episodes": 25, "seed": 9, "alpha": "1/n^0.8", "epsilon": "0.3/n^0.5,0.05",
              "max_steps_per_episode": 40, "eval_every": 7}
    ref = q_learning(mdp, Run(kernel="python", **kw))
    res = q_learning(mdp, Run(kernel=kernel, **kw))
    assert np.array_equal(res.Q, ref.Q)
    assert np.array_equal(res.visits, ref.visits)
    for col in res.curve.columns:
        assert np.array_equal(res.curve[col], ref.curve[col], equal_nan=True), col


def test_unknown_kernel_names_the_valid_ones():
    with pytest.raises(TaskError, match=r"kernel = 'cuda' must be one of numba, python"):
        Run(episodes=2, kernel="cuda")


def test_the_removed_numpy_kernel_is_refused_naming_the_kernels():
    # an earlier third copy of the rule, removed: the name is refused, not silently mapped
    with pytest.raises(TaskError, match=r"kernel = 'numpy' must be one of numba, python"):
        Run(kernel="numpy")


def test_numba_kernel_past_its_power_table_matches_python():
    # Visit counts beyond POW_TABLE switch the rule from table look-ups to math.pow();
    # both must agree with the Python kernel bit for bit.
    from adpart.learning._kernels import POW_TABLE

    mdp = random_mdp(3, 2, density=0.6, seed=1)
    kw = {"runs": 2, "episodes": 3, "seed": 5, "alpha": "1/n^0.8", "epsilon": "0.5/n^0.3",
          "max_steps_per_episode": 6 * POW_TABLE, "eval_every": 3}
    ref = q_learning(mdp, Run(kernel="python", **kw))
    res = q_learning(mdp, Run(kernel="numba", **kw))
    assert ref.visits.max() > POW_TABLE
    assert np.array_equal(res.Q, ref.Q)


@pytest.mark.parametrize(("threads", "stride"), [(1, 1), (1, 7), (2, 1 << 30)])
def test_numba_kernel_does_not_depend_on_threads_or_stride(threads, stride, monkeypatch):
    numba = pytest.importorskip("numba")
    from adpart.learning import _kernels

    mdp = random_mdp(12, 3, density=0.3, seed=5)
    mdp = mdp.with_rewards(mdp.R, terminal=np.arange(12) == 11)
    kw = {"runs": 5, "episodes": 40, "seed": 3, "alpha": "1/n^0.8", "epsilon": 0.2,
          "max_steps_per_episode": 50, "eval_every": 40}
    ref = q_learning(mdp, Run(kernel="python", **kw))
    monkeypatch.setitem(_kernels.KERNELS, "numba",
                        lambda st: _kernels.numba_kernel(st, stride=stride))
    before = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        res = q_learning(mdp, Run(kernel="numba", **kw))
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(res.Q, ref.Q)
    assert np.array_equal(res.curve.matrix("steps"), ref.curve.matrix("steps"))
    # the experience, counted per thread and summed, is the same on any thread count
    assert (res.experience.counts != ref.experience.counts).nnz == 0
    assert np.array_equal(res.experience.pair_counts, res.visits.sum(axis=0))


def test_experience_rows_grow_when_the_thread_count_rises():
    numba = pytest.importorskip("numba")
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has one thread")
    from adpart.learning import _kernels
    from adpart.learning.curves import start_distribution
    from adpart.learning.qlearning import BLOCK_ROWS, _initial_state
    from adpart.mdp.experience import Experience

    mdp = slippery_grid(side=4, slip=0.3, gamma=0.9)
    kw = {"runs": 6, "episodes": 10, "seed": 2, "max_steps_per_episode": 20, "eval_every": 10}
    run = Run(**kw)
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        st = _initial_state(mdp, 6, 10, 20, run.alpha, run.epsilon, 0.0,
                            start_distribution(mdp))
    finally:
        numba.set_num_threads(before)
    assert st.n_next.shape == (1, mdp.P.nnz)
    numba.set_num_threads(2)
    try:
        rngs = np.random.default_rng(2).spawn(6)
        st.state[:] = [st.start_state(rng.random()) for rng in rngs]
        st.target[:] = 10
        while _kernels.numba_kernel(st):
            for k in np.flatnonzero((st.cursor == BLOCK_ROWS) & (st.episode < st.target)):
                rngs[k].random(out=st.U[k])
                st.cursor[k] = 0
    finally:
        numba.set_num_threads(before)
    assert st.n_next.shape == (2, mdp.P.nnz)
    ref = q_learning(mdp, Run(kernel="python", **kw))
    got = Experience.from_positions(mdp.P, st.n_next)
    assert (got.counts != ref.experience.counts).nnz == 0
    assert np.array_equal(st.Q, ref.Q)


def test_both_kernels_run_one_source_of_the_rule():
    # one function is the rule: the python kernel interprets it, the numba kernel compiles it
    from adpart.learning import _kernels, _smdp_kernels

    assert _kernels._compiled_lockstep.__wrapped__ is _kernels.lockstep
    assert _smdp_kernels._compiled_lockstep.__wrapped__ is _smdp_kernels.lockstep
    assert set(_kernels.KERNELS) == set(_smdp_kernels.KERNELS) == set(_kernels.KERNEL_NAMES)


def test_python_kernel_in_strict_lock_step_matches_numba(monkeypatch):
    # the interpreted rule one step per agent per round against the compiled whole-buffer rounds
    from adpart.learning import _kernels

    mdp = random_mdp(12, 3, density=0.3, seed=5)
    mdp = mdp.with_rewards(mdp.R, terminal=np.arange(12) == 11)
    kw = {"runs": 3, "episodes": 12, "seed": 8, "alpha": "0.9/n^0.6,0.01", "epsilon": 0.3,
          "max_steps_per_episode": 30, "eval_every": 4}
    ref = q_learning(mdp, Run(kernel="numba", **kw))
    monkeypatch.setitem(_kernels.KERNELS, "python",
                        lambda st: _kernels.python_kernel(st, stride=1))
    res = q_learning(mdp, Run(kernel="python", **kw))
    assert np.array_equal(res.Q, ref.Q)
    assert np.array_equal(res.visits, ref.visits)
    for col in res.curve.columns:
        assert np.array_equal(res.curve[col], ref.curve[col], equal_nan=True), col


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("q_init", [0.0, 1.0, -30.0])
def test_kernel_keeps_the_greedy_policy_of_all_of_q(kernel, q_init):
    # the kernel's policy must be greedy_policy (lowest index on ties) of the whole table after
    # every block: costs -1 with q_init 1 make greedy values fall (search again), q_init -30 makes
    # them rise, alpha 1 on a deterministic grid makes exact ties
    from adpart.learning import _kernels
    from adpart.learning.curves import start_distribution
    from adpart.learning.qlearning import BLOCK_ROWS, _initial_state
    from adpart.mdp.evaluation import greedy_policy

    for mdp, alpha in ((slippery_grid(side=3, slip=0.3, gamma=0.9), constant(0.5)),
                       (slippery_grid(side=3, slip=0.0, gamma=1.0), constant(1.0))):
        K, S, A = 3, mdp.n_states, mdp.n_actions
        st = _initial_state(mdp, K, 24, 30, alpha, constant(0.4), q_init,
                            start_distribution(mdp))
        rngs = np.random.default_rng(2).spawn(K)
        st.state[:] = [st.start_state(r.random()) for r in rngs]
        moved = 0
        for boundary in (1, 2, 5, 12, 24):
            st.changed[:] = False
            before = st.policy.copy()
            st.target[:] = boundary
            while _kernels.KERNELS[kernel](st):
                for k in np.flatnonzero((st.cursor == BLOCK_ROWS) & (st.episode < st.target)):
                    rngs[k].random(out=st.U[k])
                    st.cursor[k] = 0
            full = greedy_policy(st.Q.reshape(K * S, A)).reshape(K, S)
            assert np.array_equal(st.policy, full)
            # changed: set for every run whose policy moved (it may also be set if it moved back)
            assert np.all(st.changed[np.any(before != full, axis=1)])
            moved += int(st.changed.sum())
        assert moved > 0


def test_run_does_not_depend_on_number_of_runs_or_eval_blocks(grid_mdp):
    kw = {"episodes": 30, "seed": 4, "alpha": 0.3, "epsilon": 0.2}
    many = q_learning(grid_mdp, Run(runs=5, eval_every=3, **kw))
    one = q_learning(grid_mdp, Run(runs=1, eval_every=30, **kw))
    assert np.array_equal(many.Q[0], one.Q[0])
    assert np.array_equal(many.curve.matrix("steps")[0], one.curve.matrix("steps")[0])


# ----------------------------------------------------------------------------- oracle


@pytest.mark.parametrize(
    ("alpha", "epsilon"),
    [(constant(0.5), constant(0.2)), (visit_count(0.8), exponential(0.6, 0.9, floor=0.05)),
     (visit_count(0.6, scale=0.9, floor=0.01), visit_count(0.5, scale=0.5))],
)
def test_lockstep_matches_independent_per_agent_reference(alpha, epsilon):
    mdp = slippery_grid(side=3, slip=0.3, gamma=0.9)
    res = q_learning(mdp, Run(runs=3, episodes=15, seed=21, alpha=alpha, epsilon=epsilon,
                              max_steps_per_episode=30, eval_every=15))
    Q, steps, counts = reference_q_learning(mdp, runs=3, episodes=15, seed=21, alpha=alpha,
                                            epsilon=epsilon, horizon=30)
    assert np.array_equal(res.curve.matrix("steps"), steps)
    np.testing.assert_allclose(res.Q, Q, rtol=0, atol=1e-12)
    S, A = mdp.n_states, mdp.n_actions  # the experience is every step the runs took
    assert np.array_equal(res.experience.counts.toarray().reshape(A, S, S),
                          counts.transpose(1, 0, 2))
    assert res.experience.steps == steps.sum()


def test_admissible_actions_only():
    P = np.zeros((3, 3, 3))
    P[:, :, 2] = 1.0
    adm = np.array([[True, False, True], [False, True, False], [True, True, True]])
    R = np.zeros((3, 3))
    mdp = FiniteMDP.from_dense(P, R, 0.9, admissible=adm, terminal=np.array([False, False, True]),
                               initial=np.array([0.5, 0.5, 0.0]))
    res = q_learning(mdp, Run(runs=3, episodes=200, seed=0, epsilon=1.0))
    assert np.all(res.visits[:, ~adm] == 0)
    assert np.all(np.isneginf(res.Q[:, ~adm]))
    assert np.all(res.visits.sum(axis=0)[adm & ~mdp.terminal[:, None]] > 0)


@pytest.mark.parametrize("q_init", [0.0, -3.5, 7.0, np.inf, -np.inf])
def test_the_initial_policy_is_the_greedy_one_of_the_initial_q(q_init):
    # the kernel starts from the lowest admissible action of every state (kept per model), which
    # must be the evaluated greedy policy of the initial table (greedy_policy, computed here)
    from adpart.learning.curves import start_distribution
    from adpart.learning.qlearning import _initial_state
    from adpart.mdp.evaluation import greedy_policy

    rng = np.random.default_rng(4)
    base = random_mdp(40, 4, density=0.2, seed=3)
    adm = rng.random((40, 4)) < 0.6
    adm[np.arange(40), rng.integers(0, 4, 40)] = True
    mdp = FiniteMDP(base.P, base.R, 0.9, admissible=adm)
    run = Run()
    for _ in range(2):  # a fresh model's arrays, then the kept ones
        st = _initial_state(mdp, 3, 2, 5, run.alpha, run.epsilon, q_init,
                            start_distribution(mdp))
        want = greedy_policy(np.where(adm, q_init, -np.inf))
        assert np.array_equal(st.policy, np.broadcast_to(want, (3, 40)))
        assert np.array_equal(st.adm_idx[st.adm_ptr[:-1]], np.argmax(adm, axis=1))


# ----------------------------------------------------------------------------- episode rules


def test_terminal_target_does_not_bootstrap_and_cut_does():
    # s0 --a0--> s1 (terminal, reward 2); s0 --a1--> s0 (reward 1). alpha = 1, epsilon = 1.
    P = np.zeros((2, 2, 2))
    P[0, 0, 1] = 1.0
    P[0, 1, 0] = 1.0
    P[1, :, 1] = 1.0
    R = np.array([[2.0, 1.0], [0.0, 0.0]])
    mdp = FiniteMDP.from_dense(P, R, 0.5, terminal=np.array([False, True]),
                               initial=np.array([1.0, 0.0]))
    res = q_learning(mdp, Run(runs=2, episodes=50, seed=1, alpha=1.0, epsilon=1.0,
                              max_steps_per_episode=3))
    # Arrival in the terminal state: target r = 2 exactly (its own Q row stays 0).
    assert np.all(res.Q[:, 0, 0] == 2.0)
    assert np.all(res.Q[:, 1, :] == 0.0)
    # The self-loop bootstraps (also through the 3-step cut): Q(s0, a1) = 1 + 0.5 * 2 = 2.
    assert np.allclose(res.Q[:, 0, 1], 2.0)
    steps = res.curve.matrix("steps")
    assert steps.max() <= 3
    assert (steps == 3).any()


def test_episode_columns(corridor_mdp):
    res = q_learning(corridor_mdp, Run(runs=3, episodes=40, seed=5, epsilon=0.3,
                                       max_steps_per_episode=50))
    c = res.curve
    assert np.array_equal(c["decisions"], c["steps"])
    ended = c.matrix("steps") < 50
    # Corridor: the only reward is +1 on arrival at the goal, on the last step.
    assert np.all(c.matrix("return")[ended] == 1.0)
    expected = 0.9 ** (c.matrix("steps")[ended] - 1)
    np.testing.assert_allclose(c.matrix("discounted_return")[ended], expected, rtol=1e-12)
    assert np.all(c.matrix("return")[~ended] == 0.0)
    assert list(c.evaluated_episodes()) == [10, 20, 30, 40]


def test_progress_is_called_per_block(corridor_mdp):
    calls = []
    q_learning(corridor_mdp, Run(runs=2, episodes=25, seed=0, eval_every=10, progress=lambda done,
                                 total: calls.append((done, total))))
    assert calls == [(10, 25), (20, 25), (25, 25)]


def test_reference_values_are_used(corridor_mdp):
    V = np.zeros(corridor_mdp.n_states)
    V[0] = 5.0
    res = q_learning(corridor_mdp, Run(runs=2, episodes=10, seed=0, reference_values=V))
    assert res.v_star_start == 5.0
    gap = res.curve.matrix("value_gap")[:, -1]
    np.testing.assert_allclose(gap, 5.0 - res.curve.matrix("eval_value")[:, -1])


def test_start_mass_on_terminal_states_is_conditioned_away():
    mdp = corridor()
    initial = np.zeros(mdp.n_states)
    initial[[0, -1]] = 0.5
    mdp2 = mdp.with_rewards(mdp.R, initial=initial)
    res = q_learning(mdp2, Run(runs=2, episodes=30, seed=3, epsilon=0.2))
    assert res.curve.matrix("steps").min() >= 1
    assert res.v_star_start == pytest.approx(0.9**4)


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("kwargs", "error", "needle"),
    [
        ({"runs": 0}, TaskError, "runs"),
        ({"episodes": 2.5}, TaskError, "episodes"),
        ({"eval_every": -1}, TaskError, "eval_every"),
        ({"max_steps_per_episode": 0}, TaskError, "max_steps_per_episode"),
        ({"seed": -3}, TaskError, "seed"),
        ({"alpha": 1.5}, TaskError, "alpha"),
        ({"epsilon": "sometimes"}, TaskError, "schedule"),
        ({"kernel": "cuda"}, TaskError, "kernel"),
        ({"reference_values": np.zeros(3)}, ModelError, "reference_values"),
        ({"q_init": math.inf}, TaskError, "q_init"),
    ],
)
def test_bad_settings_raise_clear_errors(corridor_mdp, kwargs, error, needle):
    with pytest.raises(error, match=needle):
        q_learning(corridor_mdp, Run(**{"episodes": 2, **kwargs}))


def test_needs_a_finite_mdp(corridor_mdp):
    with pytest.raises(ModelError, match="FiniteMDP"):
        q_learning(corridor_mdp.as_smdp())


def test_all_start_mass_on_terminal_raises():
    mdp = corridor()
    initial = np.zeros(mdp.n_states)
    initial[-1] = 1.0
    with pytest.raises(ModelError, match="terminal"):
        q_learning(mdp.with_rewards(mdp.R, initial=initial), Run(episodes=2))


def test_results_are_those_of_the_earlier_implementation():
    """Pinned from the code before the overhead work (issue 22): learning is bit-identical;
    scoring now factorises each distinct policy separately, equal to 1e-12."""
    import hashlib

    from adpart.mdp.generate import random_grid_mdp

    mdp = random_grid_mdp(400, gamma=0.9, seed=3, terminal_fraction=0.01)
    r = q_learning(mdp, Run(runs=6, episodes=30, max_steps_per_episode=60, eval_every=10, seed=11))
    h = hashlib.sha256()
    for a in (r.Q, r.visits, r.curve["steps"], r.curve["return"], r.curve["discounted_return"]):
        h.update(np.ascontiguousarray(a).tobytes())
    assert h.hexdigest() == "b8b0ae66cf8b57ee3d87c9d9e4270807b32fb1cb211a12e33fa98421ade4b11c"
    before = [[2.434251553194, 4.669481864786, 5.769917762326],
              [2.472732993001, 3.9965789589, 4.531746132432],
              [3.385135009131, 4.596945841007, 5.307166972714],
              [4.005795949364, 4.723730815892, 5.453789330237],
              [3.611944170513, 4.814882460393, 5.60995692602],
              [3.679443899153, 4.24413835384, 4.883998102898]]
    np.testing.assert_allclose(r.curve.matrix("eval_value")[:, [9, 19, 29]], before, atol=1e-11)
    assert r.v_star_start == 12.815058797257256


def test_scored_policy_is_the_greedy_policy_of_all_of_q(grid_mdp):
    # the learner reads only visited rows of Q; the full-table greedy policy must score the same
    from adpart.learning.curves import start_distribution, start_values

    r = q_learning(grid_mdp, Run(runs=4, episodes=6, seed=5, eval_every=6, q_init=1.0))
    mu = start_distribution(grid_mdp)
    np.testing.assert_array_equal(r.curve.matrix("eval_value")[:, -1],
                                  start_values(grid_mdp, r.greedy_policies(), mu))
