"""The lock-step SMDP Q-learning kernel over options on a (per-run) decision layer.

One rule, two executions of the *same source*: :func:`lockstep` is plain Python over numpy arrays
(the ``python`` kernel, the reference) and the identical function compiled by numba (the ``numba``
kernel, the default). Both use only scalar IEEE operations and ``math.pow``, so they agree bit for
bit. The helpers it shares with the flat kernel (kernel names, start-state draw, per-episode
schedule factors, lazy compilation) are :mod:`adpart.learning._kernels`'.

What one call does: it advances K independent agents until every agent has completed
``target[k]`` episodes (returns 0), or some still-active agent has used up its pre-drawn uniforms
(returns 1; the driver refills that agent's buffers from its own generators), or some agent met an
inconsistency (returns 2; ``fired[k] = (state, block, action)`` and the driver refines that run's
partition, section 4.3.3, before calling again).

**Decision layer.** Run ``k`` decides on blocks: ``labels[k, s]`` is the block of state ``s`` and
``adm[k, b, o]`` says whether option ``o`` is offered in block ``b``; ``Q[k, b, o]`` is its SMDP
Q-value (``-inf`` where not offered). Plain SMDP Q-learning over states is the identity partition
(``labels[k] = arange(S)``, ``adm[k] =`` the initiation sets).

**One primitive step** of agent ``k`` reads one row of four uniforms ``u = U[k, c]`` and one row of
two auxiliary uniforms ``v = W[k, c]`` (a separate stream, so that the four-uniform stream is the
flat learner's exactly, :mod:`adpart.learning._kernels`):

0. (hierarchical only, at a decision point in state ``s`` of block ``b``) the inconsistency test:
   with ``a*`` the flat greedy action of ``s`` (lowest index on ties), if ``a*`` is not yet
   offered in ``b``, ``n_flat(s, a*) >= min_visits``, ``n(b) >= min_visits`` and
   ``Q_flat(s, a*) - max_o Q(b, o) > threshold``, the agent stops *before* using its row and the
   kernel returns 2 (with ``split_offered``, also where ``a*`` is offered in ``b`` and
   ``Q_flat(s, a*) - Voff[k, s] > threshold``);
1. at a decision point: ``n(b) += 1``; ``epsilon = max(floor, eps_ep * n(b)**-omega)``; if
   ``u[0] < epsilon`` the option is the ``floor(u[1] m)``-th of the ``m`` options offered in ``b``
   (in index order; hierarchical: also every primitive action admissible in ``s`` - "the agent
   has access to the original actions as well as to all options", 4.3.3 - whose step updates the
   flat Q only, as it is not an option of ``b``; with ``prim_eps`` 1, or 2 while the run has not
   yet arrived in a terminal state with a reward above ``r_min`` (``rewarded[k]``), among those
   primitive actions alone), else the ``floor(u[1] t)``-th of the ``t``
   options tied for ``max_o Q(b, o)``;
   the option starts: ``s0 = s``, ``b0 = b``, ``G = 0``, ``g = 1``;
2. the option's action in ``s``: its deterministic action, or for a stochastic policy the first
   action whose cumulative probability exceeds ``v[0]``;
3. ``s'`` = the successor drawn with ``u[2]`` exactly as :meth:`FiniteMDP.sample_next`;
4. (hierarchical only) the flat Watkins update of ``Q_flat(s, a)`` with its own visit count;
5. ``G += g r``; ``g *= gamma``;
6. the option ends if ``s'`` is terminal (no bootstrap: ``target = G``), if the episode's step
   limit is hit (the cut bootstraps), or if ``v[1] < beta_o(s')``; then, with ``n(b0, o) += 1`` and
   ``alpha = max(floor, alpha_ep * n(b0, o)**-omega)``,
   ``Q(b0, o) += alpha (G + g max_o' Q(block(s'), o') - Q(b0, o))`` (section 3.1, SMDP Q-learning);
7. the episode ends on arrival in a terminal state or after ``horizon`` steps; the next start
   state is the first whose cumulative start probability exceeds ``u[3]``.

**Intra-option learning** (``intra``; Sutton, Precup & Singh 1999, section 5, "intra-option
Q-learning"), after step 4: every option ``o'`` offered in the block ``d`` of ``s`` whose policy is
deterministic and takes ``a`` in ``s`` (so it is *consistent* with the step; the primitive one-step
option of ``a`` always is) gets the one-step update

    Q(d, o') += alpha (r + gamma U(s', o') - Q(d, o')),
    U(s', o') = (1 - beta_o'(s')) Q(block(s'), o') + beta_o'(s') max_o'' Q(block(s'), o''),

with ``U = 0`` when ``s'`` is terminal, ``n(d, o') += 1`` for its step size, and no update when
``o'`` would continue in ``s'`` (``beta < 1``) but is not offered in ``block(s')`` (a block-level
layer may drop it there: no valid one-step target). The running option's SMDP update of step 6 is
then skipped if every one of its steps got such an update (they already chain its value); an
option that was not updated at some step (stochastic policy, or the missing target) keeps its
step-6 update. The random streams are untouched, so ``intra=0`` is the rule above exactly.

**Directed exploration** (``explore_m = m > 0``, hierarchical; :mod:`adpart.learning._rmax`):
after step 4 the step is counted in the run's empirical model, R-max's optimistic plan ``Qx`` is
re-planned when the pair becomes known (its ``m``-th try), and the grounded values ``Ql`` are
re-planned on every sample in place of their Watkins update; the optimistic flat action a greedy
decision may take is ``argmax Qx`` in place of ``argmax Q_flat``, and the test's lower confidence
bound subtracts ``lcb_z`` standard errors of the successors' grounded values. With ``m = 0`` none of
this runs and the rule is the one above exactly.

``intra`` is 0 (off), 1 (the one-step rule above: SMDP Q over states, where it is exact) or 2
(a decision layer). On a block layer a multi-step option's one-step target is not its value: a step
that stays inside the block gives ``Q(d, o) = r + gamma Q(d, o)``, which drives ``Q(d, o)`` to
``r / (1 - gamma)`` (measured: the pipeline's 49-block three-floor layer, 0 of 10 runs within the
bound with it). Mode 2 therefore runs *virtual executions*: every option offered in the block of
``s`` whose deterministic policy takes ``a`` there, and that is not already running (actually or
virtually), starts one at ``(block(s), G = 0, g = 1)``; each step it stays consistent with adds
``g r`` to ``G`` and multiplies ``g`` by ``gamma``; where the option would end (``beta = 1``, a
terminal state, the step cap) it gets the SMDP update of step 6 from its start block,
``Q(b0, o) += alpha (G + g max Q(block(s'), .) - Q(b0, o))``; a step off its policy, or a
termination probability strictly between 0 and 1, drops it. For a deterministic option this is
exactly the update the option would have had had it been chosen in ``b0`` - off-policy, without
importance weights. The running option keeps its own step-6 update.

With every option a primitive action (``beta = 1``, deterministic) and the identity partition this
is the flat kernel's rule operation for operation: ``G + g * best = (0 + 1 * r) + gamma * best``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from adpart.learning._kernels import ScheduledAgents, njit_lazily
from adpart.learning._rmax import model_spread, observe, sweep
from adpart.mdp._sampling import compiled, first_above, successor

#: Uniforms per agent-step in the main stream (explore?, which option, successor, next start).
UNIFORMS_PER_STEP = 4
#: Uniforms per agent-step in the auxiliary stream (stochastic action, termination draw).
AUX_PER_STEP = 2


@dataclass
class SMDPLockStepState(ScheduledAgents):
    """All arrays the kernel reads and writes (the driver owns them; the kernel mutates in place).

    :meth:`args` hands them to the kernel in ten tuples, one per role below, in this order and
    each in the order its paragraph names its fields. Everything the kernel writes is an array:
    a tuple holds the state's arrays themselves, so the writes land here; the scalars
    (``gamma``, ``check_on``, ``explore_m``, ...) are read only, and a new value set on the state
    reaches the next call, whose tuples are built afresh.

    1. Model: ``keys``/``indptr``/``indices`` (the transition CSR and its sampler keys), ``R``
       (S, A), ``terminal`` (S,), ``start_cdf`` (S,), ``last_start``, ``gamma``, ``horizon``.
    2. Schedules: ``alpha`` then ``eps``, each ``(scale, rate, omega, floor)``, as one flat
       8-tuple.
    3. Options: ``pol_act`` (O, S) int64: the action, ``-1`` undefined, ``-2 - m`` = stochastic
       row ``m`` of ``pol_cdf`` (M, A) (cumulative, 2.0 from the last positive entry on);
       ``beta`` (O, S).
    4. Decision layer per run: ``labels`` (K, S), ``adm`` (K, Bcap, O) bool, ``Q`` (K, Bcap, O),
       ``n_o`` (K, Bcap, O) and ``n_d`` (K, Bcap) counts, ``n_blocks`` (K,).
    5. Flat layer (hierarchical): ``track_flat``, ``Qf``/``nf`` (K, S, A); ``prim_adm`` (S, A)
       where each action may be taken; primitive exploration ``prim_eps`` (0 never, 1 always, 2
       until the run's first reward), ``rewarded`` (K,) whether run ``k`` has arrived in a
       terminal state by a step paying more than ``r_min``, then ``r_min``; ``flat_explore``:
       take the optimistic flat action where it beats the block.
    6. Sound inconsistency test (hierarchical): ``check_on``, ``threshold``, ``min_visits``,
       ``prim_opt`` (A,) option index of each primitive action (-1: none), ``fired`` (K, 3);
       ``Ql`` (K, S, A) the grounded lower bound of the flat values, ``tmean``/``tm2``
       (K, S, A) the running mean of its targets and their summed squared deviations (Welford's
       update, so that equal targets have a standard error of exactly 0), ``succ0`` (K, S, A)
       the first successor seen (-1 none yet, -2 more than one), ``lcb_z`` the z of its lower
       confidence bound;
       ``ref_model``: what the grounded flat value is compared with - 0 the block's learned
       ``max_o Q``, 1 ``Vref[k, block]`` (K, Bcap) the block's point-model value, 2
       ``Vref[k, state]`` (K, S) the optimum of the options offered in the state's block, from
       the state itself; then ``Vref``; ``split_offered``: the test also reads an action the
       block already offers, against ``Voff[k, state]`` (K, S) (+inf where the state's block
       cannot be split), and a firing then splits the state from its block; then ``Voff``;
       ``Vl`` (K, S) the grounded values and ``floor`` their untried pairs' value, re-planned on
       the count model when ``explore_m > 0``.
    7. Intra-option learning: ``intra`` (0, 1 or 2); ``chained`` (K,) whether every step of the
       running option so far got its one-step update; ``vr_on``/``vr_b0``/``vr_G``/``vr_g``
       (K, O) the virtual executions of mode 2 (running?, start block, return, discount).
    8. R-max count model (:mod:`adpart.learning._rmax`): ``explore_m``, ``xc``/``xm`` (K, nnz)
       successor counts, ``Qx`` (K, S, A)/``Vx`` (K, S) the optimistic plan, ``pred_ptr``/
       ``pred_idx`` the predecessor CSR, ``xqueue``/``xinq`` (K, S) the sweeps' FIFO,
       ``v_max``, ``sweep_tol``.
    9. Agents: ``state``, ``episode``, ``target``, ``t_ep``, ``d_ep``, ``ret``, ``dret``,
       ``gpow``, ``cur`` (running option or -1), ``s0``, ``b0``, ``G``, ``g``, ``alpha_ep``,
       ``eps_ep``; uniforms ``U`` (K, B, 4), ``W`` (K, B, 2), ``cursor`` (K,).
    10. Outputs (K, N): ``out_steps``, ``out_dec``, ``out_ret``, ``out_dret``, ``out_blocks``.
    """

    keys: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    R: np.ndarray
    terminal: np.ndarray
    start_cdf: np.ndarray
    last_start: int
    gamma: float
    horizon: int
    alpha: tuple[float, float, float, float]
    eps: tuple[float, float, float, float]
    pol_act: np.ndarray
    pol_cdf: np.ndarray
    beta: np.ndarray
    labels: np.ndarray
    adm: np.ndarray
    Q: np.ndarray
    n_o: np.ndarray
    n_d: np.ndarray
    n_blocks: np.ndarray
    track_flat: bool
    Qf: np.ndarray
    nf: np.ndarray
    check_on: bool
    threshold: float
    min_visits: int
    prim_opt: np.ndarray
    prim_adm: np.ndarray
    fired: np.ndarray
    intra: int
    chained: np.ndarray
    Ql: np.ndarray
    tmean: np.ndarray
    tm2: np.ndarray
    succ0: np.ndarray
    lcb_z: float
    flat_explore: bool
    prim_eps: int
    rewarded: np.ndarray
    r_min: float
    vr_on: np.ndarray
    vr_b0: np.ndarray
    vr_G: np.ndarray
    vr_g: np.ndarray
    ref_model: int
    Vref: np.ndarray
    split_offered: bool
    Voff: np.ndarray
    explore_m: int
    xc: np.ndarray
    xm: np.ndarray
    Qx: np.ndarray
    Vx: np.ndarray
    pred_ptr: np.ndarray
    pred_idx: np.ndarray
    xqueue: np.ndarray
    xinq: np.ndarray
    v_max: float
    sweep_tol: float
    Vl: np.ndarray
    floor: float
    state: np.ndarray
    episode: np.ndarray
    target: np.ndarray
    t_ep: np.ndarray
    d_ep: np.ndarray
    ret: np.ndarray
    dret: np.ndarray
    gpow: np.ndarray
    cur: np.ndarray
    s0: np.ndarray
    b0: np.ndarray
    G: np.ndarray
    g: np.ndarray
    alpha_ep: np.ndarray
    eps_ep: np.ndarray
    U: np.ndarray
    W: np.ndarray
    cursor: np.ndarray
    out_steps: np.ndarray
    out_dec: np.ndarray
    out_ret: np.ndarray
    out_dret: np.ndarray
    out_blocks: np.ndarray

    def args(self) -> tuple:
        """The kernel's arguments: the groups of the class docstring, in its order. The tuples
        hold the state's arrays themselves, so what the kernel writes lands in the state."""
        return (
            (self.keys, self.indptr, self.indices, self.R, self.terminal, self.start_cdf,
             self.last_start, self.gamma, self.horizon),
            (*self.alpha, *self.eps),
            (self.pol_act, self.pol_cdf, self.beta),
            (self.labels, self.adm, self.Q, self.n_o, self.n_d, self.n_blocks),
            (self.track_flat, self.Qf, self.nf, self.prim_adm, self.prim_eps, self.rewarded,
             self.r_min, self.flat_explore),
            (self.check_on, self.threshold, self.min_visits, self.prim_opt, self.fired, self.Ql,
             self.tmean, self.tm2, self.succ0, self.lcb_z, self.ref_model, self.Vref,
             self.split_offered, self.Voff, self.Vl, self.floor),
            (self.intra, self.chained, self.vr_on, self.vr_b0, self.vr_G, self.vr_g),
            (self.explore_m, self.xc, self.xm, self.Qx, self.Vx, self.pred_ptr, self.pred_idx,
             self.xqueue, self.xinq, self.v_max, self.sweep_tol),
            (self.state, self.episode, self.target, self.t_ep, self.d_ep, self.ret, self.dret,
             self.gpow, self.cur, self.s0, self.b0, self.G, self.g, self.alpha_ep, self.eps_ep,
             self.U, self.W, self.cursor),
            (self.out_steps, self.out_dec, self.out_ret, self.out_dret, self.out_blocks),
        )


@compiled
def watkins_target(table, k, s2, r, gamma, done):  # pragma: no cover - compiled
    """``r`` if ``done`` else ``r + gamma max_b table[k, s2, b]`` (Watkins' Q-learning target)."""
    if done:
        return r
    best = table[k, s2, 0]
    for b in range(1, table.shape[2]):
        best = max(best, table[k, s2, b])
    return r + gamma * best


def lockstep(model, schedules, options, layer, flat, check, intra_opt, rmax, agents, outputs):
    """The rule of the module docstring; returns 0 (all done), 1 (refill) or 2 (inconsistency).

    The arguments are the groups of :meth:`SMDPLockStepState.args`, unpacked here into the names
    the rule is written with."""
    keys, indptr, indices, R, terminal, start_cdf, last_start, gamma, horizon = model
    a_scale, a_rate, a_omega, a_floor, e_scale, e_rate, e_omega, e_floor = schedules
    pol_act, pol_cdf, beta = options
    labels, adm, Q, n_o, n_d, n_blocks = layer
    track_flat, Qf, nf, prim_adm, prim_eps, rewarded, r_min, flat_explore = flat
    (check_on, threshold, min_visits, prim_opt, fired, Ql, tmean, tm2, succ0, lcb_z, ref_model,
     Vref, split_offered, Voff, Vl, floor) = check
    intra, chained, vr_on, vr_b0, vr_G, vr_g = intra_opt
    explore_m, xc, xm, Qx, Vx, pred_ptr, pred_idx, xqueue, xinq, v_max, sweep_tol = rmax
    (state, episode, target, t_ep, d_ep, ret, dret, gpow, cur, s0, b0, G, g, alpha_ep, eps_ep,
     U, W, cursor) = agents
    out_steps, out_dec, out_ret, out_dret, out_blocks = outputs
    # the count model's groups for :func:`observe`, built once: a tuple built in the loop would
    # take and drop a reference to each of its arrays on every step
    x_task = (R, terminal, indptr, indices, prim_adm)
    x_counts = (nf, xc, xm)
    x_plan = (Qx, Vx)
    x_fifo = (pred_ptr, pred_idx, xqueue, xinq)
    K = Q.shape[0]
    O = Q.shape[2]  # noqa: E741 (the thesis' symbol)
    S = R.shape[0]
    A = R.shape[1]
    B = U.shape[1]
    n_start = start_cdf.shape[0]
    neg_inf = -math.inf
    while True:
        any_active = False
        for k in range(K):
            if episode[k] < target[k]:
                any_active = True
                if cursor[k] == B:
                    return 1
        if not any_active:
            return 0
        for k in range(K):
            if episode[k] >= target[k]:
                continue
            c = cursor[k]
            s = state[k]
            if cur[k] < 0:
                d = labels[k, s]
                if check_on and n_d[k, d] >= min_visits:
                    best_a = -1
                    vl = neg_inf
                    for a in range(A):
                        n = nf[k, s, a]
                        if not prim_adm[s, a] or n < min_visits or n == 0:
                            continue
                        lb = Ql[k, s, a]
                        if explore_m > 0:
                            lb -= lcb_z * model_spread(k, s, a, terminal, indptr, indices, nf,
                                                       xc, Vl)
                        elif succ0[k, s, a] == -2 and n > 1:  # more than one successor seen
                            var = tm2[k, s, a] / (n - 1)  # Welford: 0 for equal targets
                            lb -= lcb_z * math.sqrt(var / n)
                        if lb > vl:
                            vl = lb
                            best_a = a
                    if best_a >= 0:
                        oa = prim_opt[best_a]
                        offered = oa >= 0 and adm[k, d, oa]
                        if oa >= 0 and (not offered or split_offered):
                            vp = neg_inf
                            if offered:
                                vp = Voff[k, s]
                            elif ref_model == 1:
                                vp = Vref[k, d]
                            elif ref_model == 2:
                                vp = Vref[k, s]
                            else:
                                for o in range(O):
                                    if adm[k, d, o] and Q[k, d, o] > vp:
                                        vp = Q[k, d, o]
                            if vl - vp > threshold:
                                fired[k, 0] = s
                                fired[k, 1] = d
                                fired[k, 2] = best_a
                                return 2
                n_d[k, d] += 1
                eps = eps_ep[k]
                if e_omega != 0.0:
                    eps = eps * math.pow(float(n_d[k, d]), -e_omega)
                eps = max(e_floor, eps)
                u0 = U[k, c, 0]
                u1 = U[k, c, 1]
                o_sel = -1
                if u0 < eps:
                    only_prim = track_flat and (
                        prim_eps == 1 or (prim_eps == 2 and not rewarded[k]))
                    m = 0
                    for o in range(O):
                        if ((adm[k, d, o] and not only_prim)
                                or (track_flat and o < A and prim_adm[s, o])):
                            m += 1
                    j = min(int(u1 * m), m - 1)
                    for o in range(O):
                        if ((adm[k, d, o] and not only_prim)
                                or (track_flat and o < A and prim_adm[s, o])):
                            if j == 0:
                                o_sel = o
                                break
                            j -= 1
                else:
                    best = Q[k, d, 0]
                    for o in range(1, O):
                        best = max(best, Q[k, d, o])
                    t = 0
                    for o in range(O):
                        if Q[k, d, o] == best:
                            t += 1
                    j = min(int(u1 * t), t - 1)
                    for o in range(O):
                        if Q[k, d, o] == best:
                            if j == 0:
                                o_sel = o
                                break
                            j -= 1
                if flat_explore and u0 >= eps:
                    vf = neg_inf
                    af = -1
                    for a in range(A):
                        if not prim_adm[s, a]:
                            continue
                        qa = Qx[k, s, a] if explore_m > 0 else Qf[k, s, a]
                        if qa > vf:
                            vf = qa
                            af = a
                    if af >= 0 and vf > Q[k, d, o_sel]:
                        o_sel = af  # the optimistic flat action beats the block's best
                cur[k] = o_sel
                s0[k] = s
                b0[k] = d
                G[k] = 0.0
                g[k] = 1.0
                chained[k] = True
                d_ep[k] += 1
            o = cur[k]
            p = pol_act[o, s]
            if p >= 0:
                a = p
            else:
                row_m = -p - 2
                v0 = W[k, c, 0]
                a = 0
                while pol_cdf[row_m, a] <= v0:
                    a += 1
            s2 = successor(a * S + s, U[k, c, 2], keys, indptr, indices)
            cursor[k] = c + 1
            r = R[s, a]
            done = terminal[s2]
            if done and r > r_min:
                rewarded[k] = True
            if track_flat:
                nf[k, s, a] += 1
                alpha = alpha_ep[k]
                if a_omega != 0.0:
                    alpha = alpha * math.pow(float(nf[k, s, a]), -a_omega)
                alpha = max(a_floor, alpha)
                tdf = watkins_target(Qf, k, s2, r, gamma, done)
                old = Qf[k, s, a]
                Qf[k, s, a] = old + alpha * (tdf - old)
                if explore_m > 0:
                    observe(k, s, a, s2, explore_m, v_max, sweep_tol, gamma, x_task, x_counts,
                            x_plan, x_fifo)
                if check_on and explore_m > 0:
                    sweep(k, s, 1, floor, False, sweep_tol, gamma, R, terminal, indptr, indices,
                          prim_adm, nf, xc, Ql, Vl, pred_ptr, pred_idx, xqueue, xinq)
                elif check_on:
                    tdl = watkins_target(Ql, k, s2, r, gamma, done)
                    old = Ql[k, s, a]
                    Ql[k, s, a] = old + alpha * (tdl - old)
                    dev = tdl - tmean[k, s, a]  # Welford's running mean and squared deviations
                    tmean[k, s, a] += dev / nf[k, s, a]
                    tm2[k, s, a] += dev * (tdl - tmean[k, s, a])
                    if succ0[k, s, a] == -1:
                        succ0[k, s, a] = s2
                    elif succ0[k, s, a] != s2:
                        succ0[k, s, a] = -2
            if intra == 2:
                d = labels[k, s]
                d2 = labels[k, s2]
                best2 = 0.0
                if not done:
                    best2 = Q[k, d2, 0]
                    for oo in range(1, O):
                        best2 = max(best2, Q[k, d2, oo])
                ends = done or t_ep[k] + 1 == horizon
                for oo in range(O):
                    if vr_on[k, oo]:
                        if pol_act[oo, s] != a:
                            vr_on[k, oo] = False  # the step left the option's policy
                            continue
                    elif oo != cur[k] and adm[k, d, oo] and pol_act[oo, s] == a:
                        vr_on[k, oo] = True
                        vr_b0[k, oo] = d
                        vr_G[k, oo] = 0.0
                        vr_g[k, oo] = 1.0
                    else:
                        continue
                    vr_G[k, oo] += vr_g[k, oo] * r
                    vr_g[k, oo] *= gamma
                    bt = beta[oo, s2]
                    if ends or bt >= 1.0:
                        b = vr_b0[k, oo]
                        n_o[k, b, oo] += 1
                        alpha = alpha_ep[k]
                        if a_omega != 0.0:
                            alpha = alpha * math.pow(float(n_o[k, b, oo]), -a_omega)
                        alpha = max(a_floor, alpha)
                        tdv = vr_G[k, oo] + (0.0 if done else vr_g[k, oo] * best2)
                        old = Q[k, b, oo]
                        Q[k, b, oo] = old + alpha * (tdv - old)
                        vr_on[k, oo] = False
                    elif bt > 0.0:
                        vr_on[k, oo] = False  # a random termination: no single outcome
                chained[k] = False
            elif intra == 1:
                d = labels[k, s]
                d2 = labels[k, s2]
                best2 = neg_inf
                if not done:
                    best2 = Q[k, d2, 0]
                    for oo in range(1, O):
                        best2 = max(best2, Q[k, d2, oo])
                updated = False
                for oo in range(O):
                    if not adm[k, d, oo] or pol_act[oo, s] != a:
                        continue
                    if done:
                        tdi = r
                    else:
                        bt = beta[oo, s2]
                        if bt >= 1.0:
                            tdi = r + gamma * best2
                        elif adm[k, d2, oo]:
                            tdi = r + gamma * ((1.0 - bt) * Q[k, d2, oo] + bt * best2)
                        else:
                            continue
                    n_o[k, d, oo] += 1
                    alpha = alpha_ep[k]
                    if a_omega != 0.0:
                        alpha = alpha * math.pow(float(n_o[k, d, oo]), -a_omega)
                    alpha = max(a_floor, alpha)
                    old = Q[k, d, oo]
                    Q[k, d, oo] = old + alpha * (tdi - old)
                    if oo == cur[k]:
                        updated = True
                if not updated:
                    chained[k] = False
            G[k] += g[k] * r
            g[k] *= gamma
            ret[k] += r
            dret[k] += gpow[k] * r
            gpow[k] *= gamma
            t_ep[k] += 1
            cut = t_ep[k] == horizon
            if (done or cut or W[k, c, 1] < beta[o, s2]) and not adm[k, b0[k], o]:
                cur[k] = -1  # an exploratory primitive action not offered in the block
            elif (done or cut or W[k, c, 1] < beta[o, s2]) and intra and chained[k]:
                cur[k] = -1  # its value was updated at every step (intra-option)
            elif done or cut or W[k, c, 1] < beta[o, s2]:
                b = b0[k]
                n_o[k, b, o] += 1
                alpha = alpha_ep[k]
                if a_omega != 0.0:
                    alpha = alpha * math.pow(float(n_o[k, b, o]), -a_omega)
                alpha = max(a_floor, alpha)
                if done:
                    tdo = G[k]
                else:
                    d2 = labels[k, s2]
                    bn = Q[k, d2, 0]
                    for oo in range(1, O):
                        bn = max(bn, Q[k, d2, oo])
                    tdo = G[k] + g[k] * bn
                old = Q[k, b, o]
                Q[k, b, o] = old + alpha * (tdo - old)
                cur[k] = -1
            if done or cut:
                ep = episode[k]
                out_steps[k, ep] = t_ep[k]
                out_dec[k, ep] = d_ep[k]
                out_ret[k, ep] = ret[k]
                out_dret[k, ep] = dret[k]
                out_blocks[k, ep] = n_blocks[k]
                ep += 1
                episode[k] = ep
                t_ep[k] = 0
                d_ep[k] = 0
                ret[k] = 0.0
                dret[k] = 0.0
                gpow[k] = 1.0
                cur[k] = -1
                state[k] = min(first_above(start_cdf, U[k, c, 3], 0, n_start), last_start)
                alpha_ep[k] = a_scale * math.pow(a_rate, float(ep))
                eps_ep[k] = e_scale * math.pow(e_rate, float(ep))
            else:
                state[k] = s2


_compiled_lockstep = njit_lazily(lockstep)


def numba_kernel(st: SMDPLockStepState) -> int:
    """:func:`lockstep` compiled with numba (compiled once per process, cached on disk)."""
    return int(_compiled_lockstep(*st.args()))


def python_kernel(st: SMDPLockStepState) -> int:
    """:func:`lockstep` run by the interpreter (the reference; slow but identical)."""
    return int(lockstep(*st.args()))


KERNELS: dict[str, Callable[[SMDPLockStepState], int]] = {
    "numba": numba_kernel,
    "python": python_kernel,
}
