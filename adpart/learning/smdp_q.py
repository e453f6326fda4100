"""SMDP Q-learning over options, K runs in lock-step in the real environment (section 3.1).

The update (Bradtke & Duff 1995; Sutton, Precup & Singh 1999; dissertation section 3.1) is applied
when an option ``o`` started in ``s`` terminates in ``s'`` after ``tau`` primitive steps:

    Q(s, o) <- Q(s, o) + alpha (G + gamma^tau max_{o' in O(s')} Q(s', o') - Q(s, o)),
    G = r_1 + gamma r_2 + ... + gamma^(tau-1) r_tau,

with target ``G`` alone when ``s'`` is terminal (the episode ends on arrival; value 0). The option
runs step by step in the environment, sampled exactly like the flat learner samples
(:attr:`FiniteMDP.sampler_keys`); the exact per-step rule, including how every uniform is used, is
in :mod:`adpart.learning._smdp_kernels`. Choices (docs/hierarchical-learning.md):

* **Options and order.** The learner's option set is ``options`` preceded, with
  ``include_primitives=True``, by the one-step options of the primitive actions (columns ``0..A-1``,
  as :func:`adpart.options.stack_models` orders them). An option is chosen only where it may start
  (its initiation set); a non-terminal state where none may start is an error.
* **Lock-step, randomness, exploration** as the flat learner (:mod:`adpart.learning.qlearning`):
  run ``k`` uses ``np.random.default_rng(seed).spawn(runs)[k]`` for its start state and its rows of
  four uniforms per primitive step, and a child of that generator (``.spawn(1)[0]``) for the two
  uniforms per step an option needs beyond a primitive action (stochastic policy, termination).
  With options = the primitive actions the run is therefore *bit-identical* to
  :func:`~adpart.learning.qlearning.q_learning` with the same seed and settings (tested).
  The exploration count of the epsilon schedule is the number of decisions taken in the state,
  the step-size count the number of updates of the pair ``(s, o)``.
* **Step limit.** An episode ends after ``max_steps_per_episode`` *primitive* steps; an option cut
  there is updated with a bootstrap from where it stands (the cut is not part of the task).
* **Counts.** The curve's ``steps`` are primitive steps and ``decisions`` option choices.
* **Exact scoring.** The greedy option policy ``mu(s) = argmax_o Q(s, o)`` (lowest index on ties)
  is an SMDP policy; its value is the fixed point of ``V = R_mu + F_mu V`` on the options' exact
  multi-time models (eqs. 3.1-3.2), i.e. the value of executing it in the MDP. The models are
  stacked into one :class:`~adpart.mdp.model.SMDPModel` and every run's policy is evaluated by
  :class:`adpart.learning.curves.StartValues` (each distinct policy solved once, on the states it
  reaches from the start, warm-started from the last one; within 1e-10 of a sparse LU), against
  the flat MDP's ``V*`` - so a set of options that cannot express the optimal policy shows a gap.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from adpart.errors import ModelError
from adpart.learning import _smdp_kernels as kernels
from adpart.learning._kernels import resolve_kernel
from adpart.learning._rmax import SWEEP_TOL, predecessors, value_ceiling
from adpart.learning.curves import (
    LearningCurve,
    StartValues,
    optimal_start_value,
    start_distribution,
)
from adpart.learning.knowledge import FLAT, OPTION_POLICIES, world
from adpart.learning.qlearning import BLOCK_ROWS
from adpart.learning.result import LearnResult
from adpart.learning.schedules import Schedule
from adpart.learning.settings import Run, SMDPQSettings, fresh_seed, require_mdp
from adpart.mdp.evaluation import greedy_policy
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.options.models import OptionModel, option_models
from adpart.options.option import Option, primitive_options
from adpart.options.smdp import stack_models

__all__ = ["SMDPQResult", "SMDPQSettings", "compile_options", "option_set", "smdp_q_learning"]


@dataclass(frozen=True, eq=False)
class SMDPQResult(LearnResult):
    """What :func:`smdp_q_learning` returns.

    Attributes:
        Q: ``(K, S, O)`` option values of every run; ``-inf`` where the option may not start.
        visits: ``(K, S, O)`` number of updates of each pair.
        option_names: the ``O`` option names, in column order.
        curve, seed, v_star_start, parameters: as :class:`~adpart.learning.result.LearnResult`
            (the curve's ``steps`` are primitive steps, ``decisions`` option choices; the value
            gap is taken against the flat MDP's ``V*``).
    """

    visits: np.ndarray
    option_names: tuple[str, ...]


def option_set(
    mdp: FiniteMDP, options: Sequence[Option], *, include_primitives: bool,
    models: Sequence[OptionModel] | None = None,
) -> tuple[list[Option], SMDPModel]:
    """The learner's options (primitive one-step options first, if asked) and their stacked model.

    Args:
        models: exact models of ``options`` in the same order (computed when omitted).

    Raises:
        ModelError: an invalid option, mismatched models, or a state no option may start in.
    """
    options = list(options)
    if not options and not include_primitives:
        raise ModelError("no options given; pass options or include_primitives=True")
    for o in options:
        if not isinstance(o, Option):
            raise ModelError(
                f"expected adpart.options.Option objects, got {type(o).__name__}; build options "
                "with adpart.options (subgoal_options, hallway_options, ...)"
            )
    if models is None:
        models = option_models(mdp, options, duration=False)
    models = list(models)
    if len(models) != len(options) or any(
            m.name != o.name for m, o in zip(models, options, strict=True)):
        raise ModelError(
            "the option models do not match the options (one model per option, same order and "
            "names); compute them with adpart.options.option_models(mdp, options)"
        )
    smdp = stack_models(mdp, models, include_primitives=include_primitives)
    full = (primitive_options(mdp) if include_primitives else []) + options
    return full, smdp


def compile_options(options: Sequence[Option], n_actions: int) -> tuple[
    np.ndarray, np.ndarray, np.ndarray
]:
    """Kernel arrays of the options: ``pol_act`` (O, S), ``pol_cdf`` (M, A), ``beta`` (O, S).

    ``pol_act[o, s]`` is the deterministic action, ``-1`` where undefined, or ``-2 - m`` to use
    row ``m`` of ``pol_cdf``: the cumulative action probabilities of a stochastic policy in that
    state, set to 2.0 from its last positive action on (so a draw never lands past it).
    """
    O = len(options)  # noqa: E741 (the thesis' symbol)
    S = options[0].n_states
    pol_act = np.full((O, S), -1, dtype=np.int64)
    beta = np.ones((O, S))
    cdf_rows: list[np.ndarray] = []
    n_rows = 0
    for i, opt in enumerate(options):  # one vectorised conversion per option
        beta[i] = opt.beta
        if opt.deterministic:
            pol_act[i] = opt.policy
            continue
        probs = opt.policy
        defined = np.flatnonzero(probs.sum(axis=1) > 0)
        cdf = np.cumsum(probs[defined], axis=1)
        last = (n_actions - 1) - np.argmax((probs[defined] > 0)[:, ::-1], axis=1)
        cdf[np.arange(n_actions)[None, :] >= last[:, None]] = 2.0
        pol_act[i, defined] = -2 - (n_rows + np.arange(defined.size))
        n_rows += defined.size
        cdf_rows.append(cdf)
    pol_cdf = np.concatenate(cdf_rows) if cdf_rows else np.full((1, n_actions), 2.0)
    return pol_act, np.ascontiguousarray(pol_cdf), beta


def kernel_function(kernel: str | None) -> tuple[str, Callable[[kernels.SMDPLockStepState], int]]:
    """The kernel by name (``numba`` / ``python``; default :func:`_kernels.default_kernel`)."""
    name = resolve_kernel(kernel, "SMDP Q-learning")
    return name, kernels.KERNELS[name]


def _reference_table(K: int, S: int, capacity: int, block_values: np.ndarray | None,
                     state_values: np.ndarray | None) -> np.ndarray:
    """The test's reference per run: ``(K, S)`` per state, ``(K, capacity)`` per block (padded
    for the blocks refinement adds), zeros when the test reads the learned values."""
    if state_values is not None:
        return np.broadcast_to(state_values, (K, S)).astype(np.float64)
    if block_values is not None:
        B = block_values.shape[-1]
        return np.pad(np.broadcast_to(block_values, (K, B)),
                      ((0, 0), (0, capacity - B))).astype(np.float64)
    return np.zeros((K, capacity))


def _rmax_arrays(mdp: FiniteMDP, K: int, m: int, horizon: int, *, floor: float,
                 grounded: bool, v_max: float | None = None) -> dict[str, object]:
    """The kernel's count model for K runs, all pairs unknown: R-max's plan (an unknown pair
    worth ``v_max``; None: the ceiling of ``mdp``'s rewards) and, when the test is on
    (``grounded``), the grounded values ``Vl`` at ``floor`` (placeholders when ``m = 0``)."""
    S, A = mdp.n_states, mdp.n_actions
    if m == 0:
        one = np.zeros((1, 1), dtype=np.int64)
        return {"explore_m": 0, "xc": one, "xm": one, "Qx": np.zeros((1, 1, 1)),
                "Vx": np.zeros((1, 1)),
                "pred_ptr": np.zeros(1, dtype=np.int64), "pred_idx": np.zeros(1, dtype=np.int64),
                "xqueue": one, "xinq": np.zeros((1, 1), dtype=bool), "v_max": 0.0,
                "sweep_tol": 0.0, "Vl": np.zeros((1, 1)), "floor": floor}
    v_max = value_ceiling(mdp, horizon) if v_max is None else float(v_max)
    ptr, idx = predecessors(mdp)
    nnz = mdp.sampler_arrays[2].size
    return {"explore_m": m, "xc": np.zeros((K, nnz), dtype=np.int64),
            "xm": np.zeros((K, nnz), dtype=np.int64),
            "Qx": np.broadcast_to(np.where(mdp.admissible, v_max, -np.inf), (K, S, A)).copy(),
            "Vx": np.broadcast_to(np.where(mdp.terminal, 0.0, v_max), (K, S)).copy(),
            "pred_ptr": ptr, "pred_idx": idx, "xqueue": np.zeros((K, S), dtype=np.int64),
            "xinq": np.zeros((K, S), dtype=bool), "v_max": v_max,
            "sweep_tol": SWEEP_TOL * max(1.0, v_max), "floor": floor,
            "Vl": np.broadcast_to(np.where(mdp.terminal, 0.0, floor), (K, S)).copy()
            if grounded else np.zeros((1, 1))}


@dataclass(frozen=True)
class InconsistencyArrays:
    """What the hierarchical learner adds to the kernel state (section 4.3.3).

    Attributes:
        threshold: ``L``; ``inf`` keeps the flat table but never tests.
        min_visits: visits of the flat pair and of the block before the test may fire.
        prim_opt: ``(A,)`` the layer's column of each primitive action (-1: none).
        floor: the grounded values' lower bound ``r_min / (1 - gamma)``.
        lcb_z: standard errors off a stochastic pair's grounded value.
        flat_explore: take the optimistic flat action where it beats the block's best.
        prim_eps: epsilon draws among primitive actions: 0 never, 1 always, 2 until the first
            reward above ``r_min``.
        r_min: the step reward (:func:`~adpart.learning.decision_layer.reward_floor`).
        block_values: ``(B,)`` the reference per block, or ``state_values`` ``(S,)`` per state
            (at most one; neither: the block's learned values).
        offered_values: ``(S,)`` the reference an action the block already offers must beat
            (``+inf`` where the state cannot be split from its block), or None: not tested.
        explore_known: R-max's m (0: off; with ``flat_explore`` the action explored is the
            optimistic model's, :mod:`adpart.learning._rmax`).
        v_max: R-max's value of an unknown pair (None: :func:`~adpart.learning._rmax.
            value_ceiling` of the simulated task's rewards).
    """

    threshold: float
    min_visits: int
    prim_opt: np.ndarray
    floor: float
    lcb_z: float
    flat_explore: bool
    prim_eps: int
    r_min: float
    block_values: np.ndarray | None
    state_values: np.ndarray | None
    offered_values: np.ndarray | None
    explore_known: int
    v_max: float | None = None

    def __post_init__(self) -> None:
        if self.block_values is not None and self.state_values is not None:
            raise ValueError("give block_values or state_values, not both")

    @classmethod
    def off(cls, n_actions: int) -> InconsistencyArrays:
        """No flat table and no test (plain SMDP Q-learning)."""
        return cls(np.inf, 0, np.full(n_actions, -1, dtype=np.int64), -np.inf, 0.0, False, 0,
                   np.inf, None, None, None, 0)


def make_state(
    mdp: FiniteMDP, options: Sequence[Option], labels: np.ndarray, block_adm: np.ndarray,
    *, episodes: int, horizon: int, alpha: Schedule, epsilon: Schedule, q_init: float,
    mu: np.ndarray, capacity: int, intra: int, test: InconsistencyArrays | None = None,
) -> kernels.SMDPLockStepState:
    """Kernel state for K runs on decision layers ``labels`` (K, S) / ``block_adm`` (K, B, O).

    ``test`` (the hierarchical learner's): the flat table beside the layer, the inconsistency
    test and its reference, exploration by the flat values (:class:`InconsistencyArrays`);
    None for plain SMDP Q-learning.
    """
    track_flat = test is not None
    t = test if test is not None else InconsistencyArrays.off(mdp.n_actions)
    threshold, min_visits, prim_opt, lower_bound = t.threshold, t.min_visits, t.prim_opt, t.floor
    lcb_z, flat_explore, primitive_epsilon, r_min = t.lcb_z, t.flat_explore, t.prim_eps, t.r_min
    block_values, state_values, offered_values = t.block_values, t.state_values, t.offered_values
    explore_known = t.explore_known
    K, S = labels.shape
    A = mdp.n_actions
    O = len(options)  # noqa: E741 (the thesis' symbol)
    pol_act, pol_cdf, beta = compile_options(options, A)
    adm = np.zeros((K, capacity, O), dtype=bool)
    adm[:, :block_adm.shape[1]] = block_adm
    Q = np.where(adm, float(q_init), -np.inf)
    flat_shape = (K, S, A) if track_flat else (K, 1, A)
    check = bool(track_flat and np.isfinite(threshold))
    m_known = int(explore_known) if flat_explore and track_flat else 0
    Qf = np.where(mdp.admissible, float(q_init), -np.inf) if track_flat else np.zeros((1, A))
    st = kernels.SMDPLockStepState(
        keys=mdp.sampler_arrays[0],
        indptr=mdp.sampler_arrays[1],
        indices=mdp.sampler_arrays[2],
        R=np.ascontiguousarray(mdp.R, dtype=np.float64),
        terminal=np.ascontiguousarray(mdp.terminal, dtype=bool),
        start_cdf=np.cumsum(mu),
        last_start=int(np.flatnonzero(mu > 0)[-1]),
        gamma=float(mdp.gamma),
        horizon=int(horizon),
        alpha=alpha.params(),
        eps=epsilon.params(),
        pol_act=pol_act,
        pol_cdf=pol_cdf,
        beta=beta,
        labels=np.array(labels, dtype=np.int64, order="C", copy=True),
        adm=adm,
        Q=Q,
        n_o=np.zeros((K, capacity, O), dtype=np.int64),
        n_d=np.zeros((K, capacity), dtype=np.int64),
        n_blocks=np.full(K, block_adm.shape[1], dtype=np.int64),
        track_flat=bool(track_flat),
        Qf=np.broadcast_to(Qf, flat_shape).copy(),
        nf=np.zeros(flat_shape, dtype=np.int64),
        check_on=check,
        threshold=float(threshold),
        min_visits=int(min_visits),
        prim_opt=np.asarray(prim_opt, dtype=np.int64),
        prim_adm=np.ascontiguousarray(mdp.admissible, dtype=bool),
        fired=np.full((K, 3), -1, dtype=np.int64),
        intra=int(intra),
        chained=np.ones(K, dtype=bool),
        vr_on=np.zeros((K, O), dtype=bool),
        vr_b0=np.zeros((K, O), dtype=np.int64),
        vr_G=np.zeros((K, O)),
        vr_g=np.ones((K, O)),
        ref_model=1 if block_values is not None else 2 if state_values is not None else 0,
        Vref=_reference_table(K, S, capacity, block_values, state_values),
        split_offered=offered_values is not None,
        Voff=np.zeros((1, 1)) if offered_values is None
        else np.broadcast_to(offered_values, (K, S)).astype(np.float64),
        **_rmax_arrays(mdp, K, m_known, horizon, floor=float(lower_bound), grounded=check,
                       v_max=t.v_max),
        Ql=np.broadcast_to(np.where(mdp.admissible, float(lower_bound), -np.inf)
                           if check else np.zeros((1, A)), flat_shape if check else (1, 1, A)
                           ).copy(),
        tmean=np.zeros(flat_shape if check else (1, 1, A)),
        tm2=np.zeros(flat_shape if check else (1, 1, A)),
        succ0=np.full(flat_shape if check else (1, 1, A), -1, dtype=np.int64),
        lcb_z=float(lcb_z),
        flat_explore=bool(flat_explore and track_flat),
        prim_eps=int(primitive_epsilon) if track_flat else 0,
        rewarded=np.zeros(K, dtype=bool),
        r_min=float(r_min),
        state=np.zeros(K, dtype=np.int64),
        episode=np.zeros(K, dtype=np.int64),
        target=np.zeros(K, dtype=np.int64),
        t_ep=np.zeros(K, dtype=np.int64),
        d_ep=np.zeros(K, dtype=np.int64),
        ret=np.zeros(K),
        dret=np.zeros(K),
        gpow=np.ones(K),
        cur=np.full(K, -1, dtype=np.int64),
        s0=np.zeros(K, dtype=np.int64),
        b0=np.zeros(K, dtype=np.int64),
        G=np.zeros(K),
        g=np.ones(K),
        alpha_ep=np.zeros(K),
        eps_ep=np.zeros(K),
        U=np.zeros((K, BLOCK_ROWS, kernels.UNIFORMS_PER_STEP)),
        W=np.zeros((K, BLOCK_ROWS, kernels.AUX_PER_STEP)),
        cursor=np.full(K, BLOCK_ROWS, dtype=np.int64),
        out_steps=np.zeros((K, episodes), dtype=np.int64),
        out_dec=np.zeros((K, episodes), dtype=np.int64),
        out_ret=np.zeros((K, episodes)),
        out_dret=np.zeros((K, episodes)),
        out_blocks=np.zeros((K, episodes), dtype=np.int64),
    )
    st.episode_factors(np.arange(K))
    return st


def drive(
    st: kernels.SMDPLockStepState,
    step_kernel: Callable[[kernels.SMDPLockStepState], int],
    seed: int,
    *,
    episodes: int,
    eval_every: int,
    score: Callable[[], np.ndarray],
    progress: Callable[[int, int], object] | None = None,
    on_fire: Callable[[int], None] | None = None,
    on_episode: Callable[[], None] | None = None,
) -> np.ndarray:
    """Run the kernel through all evaluation blocks; returns ``eval_value`` (K, N), NaN between.

    Run ``k`` draws its first start state and its main uniforms from
    ``default_rng(seed).spawn(K)[k]`` and its auxiliary uniforms from that generator's child. On
    an inconsistency (kernel code 2) ``on_fire(k)`` is called for each run that fired. With
    ``on_episode`` the runs stop after every episode, and it is called before any scoring (the
    kernel resumes where it stopped, so stopping more often changes nothing else).
    """
    K, N = st.out_steps.shape
    rngs = np.random.default_rng(seed).spawn(K)
    aux = [r.spawn(1)[0] for r in rngs]
    st.state[:] = [st.start_state(r.random()) for r in rngs]
    B = st.U.shape[1]
    eval_value = np.full((K, N), np.nan)
    scored = {*range(eval_every, episodes + 1, eval_every), episodes}
    stops = range(1, episodes + 1) if on_episode is not None else sorted(scored)
    for boundary in stops:
        st.target[:] = boundary
        while True:
            code = step_kernel(st)
            if code == 0:
                break
            if code == 1:
                for k in np.flatnonzero((st.cursor == B) & (st.episode < st.target)):
                    rngs[k].random(out=st.U[k])
                    aux[k].random(out=st.W[k])
                    st.cursor[k] = 0
                continue
            if on_fire is None:  # pragma: no cover - the kernel fires only when checks are on
                raise ModelError("the kernel reported an inconsistency but no refiner is set")
            for k in np.flatnonzero(st.fired[:, 0] >= 0):
                on_fire(int(k))
                st.fired[k] = -1
        if on_episode is not None:
            on_episode()
            if boundary not in scored:
                continue
        eval_value[:, boundary - 1] = score()
        if progress is not None:
            progress(boundary, episodes)
    return eval_value


def smdp_q_learning(
    mdp: FiniteMDP,
    options: Sequence[Option] = (),
    settings: SMDPQSettings | None = None,
    run: Run | None = None,
    models: Sequence[OptionModel] | None = None,
) -> SMDPQResult:
    """Learn ``mdp`` over ``options`` with ``run.runs`` independent SMDP Q-learners in lock-step.

    Args:
        mdp: the task.
        options: the options (section 3.1); see ``settings.include_primitives``.
        settings: :class:`SMDPQSettings` (default ``SMDPQSettings()``).
        run: runs, episodes, seed, schedules (``alpha`` counts updates of ``(s, o)``,
            ``epsilon`` decisions in ``s``), step limit, evaluation, ``q_init`` (default 0),
            kernel (``numba`` or ``python``, identical results) and progress
            (:class:`~adpart.learning.settings.Run`; default ``Run()``).
        models: exact models of ``options`` (same order), for scoring; computed when omitted.

    Returns:
        An :class:`SMDPQResult`.

    Raises:
        TaskError: a setting out of range. ModelError: bad options or MDP.
    """
    settings = SMDPQSettings() if settings is None else settings
    run = Run() if run is None else run
    include_primitives, intra_option = settings.include_primitives, settings.intra_option
    require_mdp("smdp_q_learning", mdp)
    q_init, reference_values, progress = run.start_q, run.reference_values, run.progress
    K, N, M, H = run.runs, run.episodes, run.eval_every, run.max_steps_per_episode
    root_seed, alpha_s, eps_s = fresh_seed(run.seed), run.alpha, run.epsilon
    name, step_kernel = kernel_function(run.kernel)
    with world():  # the options' exact models score the greedy policies; nothing else reads them
        full, smdp = option_set(mdp, options, include_primitives=include_primitives,
                                models=models)
        mu = start_distribution(mdp)
        v_star = optimal_start_value(mdp, mu, reference_values)
        # each distinct greedy policy solved once, warm-started from the last (issue 40)
        scorer = StartValues(smdp, mu, K)
    every_run = np.ones(K, dtype=bool)
    S = mdp.n_states
    state_adm = smdp.admissible  # terminal rows: every option, never chosen (episode over)
    labels = np.broadcast_to(np.arange(S, dtype=np.int64), (K, S))
    with world():  # the simulator of the environment
        st = make_state(mdp, full, labels, np.broadcast_to(state_adm, (K, S, len(full))),
                        episodes=N, horizon=H, alpha=alpha_s, epsilon=eps_s, q_init=q_init,
                        mu=mu, capacity=S, intra=1 if intra_option else 0)

    def score() -> np.ndarray:
        policies = greedy_policy(st.Q.reshape(K * S, -1)).reshape(K, S)
        with world():
            return scorer(policies, every_run.copy())

    eval_value = drive(st, step_kernel, root_seed, episodes=N, eval_every=M, score=score,
                       progress=progress)
    names = tuple(o.name for o in full)
    parameters: dict[str, object] = {
        "runs": K, "episodes": N, "seed": root_seed, "alpha": alpha_s.to_dict(),
        "epsilon": eps_s.to_dict(), "max_steps_per_episode": H, "eval_every": M,
        "q_init": float(q_init), "kernel": name, "include_primitives": bool(include_primitives),
        "intra_option": bool(intra_option),
        "options": list(names), "reference": "given" if reference_values is not None else "solved",
        "knowledge": (OPTION_POLICIES if options else FLAT).to_dict(),
    }
    curve = LearningCurve.from_matrices(
        steps=st.out_steps, decisions=st.out_dec, returns=st.out_ret,
        discounted_returns=st.out_dret, eval_value=eval_value, value_gap=v_star - eval_value,
        metadata={"learner": "smdp-q", "mdp": mdp.name, "mdp_hash": mdp.content_hash,
                  "gamma": mdp.gamma, "v_star_start": v_star, **parameters},
    )
    for arr in (st.Q, st.n_o):
        arr.setflags(write=False)
    return SMDPQResult(Q=st.Q, visits=st.n_o, curve=curve, seed=root_seed, v_star_start=v_star,
                       option_names=names, parameters=parameters)
