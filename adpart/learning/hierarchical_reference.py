"""A plain, per-run reference of the hierarchical learner's rule (dissertation 3.1, 4.3.3).

:func:`adpart.learning.hierarchical.hierarchical_learning` advances K runs in lock-step through one
kernel (:mod:`adpart.learning._smdp_kernels`) that the interpreter and numba execute from the *same*
source, so the two kernels agreeing says nothing about the rule itself. This module states the rule
a second time, run by run, from the dissertation and the learner's documentation
(docs/hierarchical-learning.md, the docstrings of :mod:`adpart.learning.hierarchical` and of the
kernel), not from the kernel's code: one :class:`ReferenceAgent` per run owns its decision layer
(a :class:`~adpart.partition.Partition`), its tables and its two random streams, and runs its
episodes one primitive step at a time. ``tests/learning/test_hierarchical_reference.py`` checks
the numba kernel against it, firing for firing, on random small MDPs.

**What one run does.** Run ``k`` of ``runs`` draws from ``default_rng(seed).spawn(runs)[k]`` (the
*main* stream: one uniform for the first start state, then four per primitive step) and from that
generator's child ``.spawn(1)[0]`` (the *auxiliary* stream: two per primitive step). The learner
draws them in blocks of rows; consumed one row per primitive step, as here, they are the same
numbers. The row of a step is read only once the inconsistency test has passed: a firing refines
the layer and the test is repeated in the same state before the row is used.

At a **decision point** (no option running) in state ``s`` of block ``b``:

1. *The inconsistency test* (section 4.3.3, :meth:`ReferenceAgent.inconsistency`). The flat
   evidence is the grounded table ``Q_low`` (below). Among the actions admissible in ``s`` tried
   at least ``max(1, min_visits)`` times, ``a*`` has the highest lower confidence bound
   ``LCB(s, a) = Q_low(s, a) - lcb_z * se(s, a)`` (lowest index on ties), where ``se`` is the
   standard error of the pair's targets if it has shown more than one successor and 0 otherwise.
   If ``b`` has been decided in at least ``min_visits`` times, ``a*`` is not offered in ``b``
   and ``LCB(s, a*) - V_ref > L``, the test fires: ``a*`` joins the option set (4.3.3,
   ``A_B <- A_B + {a*}``) of ``s`` alone (``refine="state"``) or of all of ``b``
   (``refine="block"``), and ``b`` is refined by eqs. 4.6-4.7 to a fixpoint. ``V_ref`` is the
   learner's ``reference``: ``learned`` the block's ``max_o Q_P(b, o)``; ``model`` ``V*_P(b)``
   of the layer's point model; ``offered`` the larger of that and the best the layer's offered
   columns achieve from ``s``; ``policy`` the value from ``s`` of the layer's best block policy.
   With ``split_offered`` (reference ``policy``) an ``a*`` that ``b`` already offers is tested
   too, against the ``policy`` value where ``s`` shares its block with another state (never
   where it is a block of its own), and a firing splits ``s`` off with the block's set.
2. *The choice* (epsilon-greedy on the layer): ``n(b) += 1``, ``eps = schedule(n(b), episode)``;
   with ``u[0] < eps`` the ``floor(u[1] m)``-th (in column order) of the ``m`` columns offered in
   ``b`` together with the primitive actions admissible in ``s`` ("the agent has access to the
   original actions as well as to all options", 4.3.3) - only those primitive actions while
   ``primitive_exploration`` says so (``always``; ``until-reward``: until the run first arrives in
   a terminal state by a step paying more than ``r_min``); otherwise the ``floor(u[1] t)``-th of
   the ``t`` columns tied for ``max_o Q_P(b, o)``, replaced, with ``flat_explore``, by the
   optimistic flat table's best action in ``s`` where that value beats the chosen column's.

Every **primitive step** of the running option ``o`` (started in block ``b0``):

3. the action: ``o``'s deterministic action in ``s``, or for a stochastic policy the first action
   whose cumulative probability exceeds ``v[0]``; the successor ``s'`` by ``u[2]`` as
   :meth:`~adpart.mdp.model.FiniteMDP.sample_next` draws it; the reward ``r = R(s, a)``;
4. the flat tables learn from the step (:meth:`ReferenceAgent.learn_flat`): the optimistic flat
   ``Q`` by Watkins' Q-learning (eq. 2.4) and the grounded ``Q_low`` by the same update from its
   own values, with the pair's step size ``alpha(n(s, a), episode)``;
5. the option's return ``G`` accumulates ``gamma^t r``; it ends when ``s'`` is terminal, when the
   episode reaches ``max_steps_per_episode`` steps, or when ``v[1] < beta_o(s')``. Then, if ``b0``
   offers ``o`` (an exploratory primitive action it does not offer updates the flat tables only),
   the SMDP Q-learning update of section 3.1 on the layer,
   ``Q_P(b0, o) <- Q_P(b0, o) + alpha (G + gamma^tau max_o' Q_P(block(s'), o') - Q_P(b0, o))``,
   with target ``G`` alone when ``s'`` is terminal and ``alpha`` counted per ``(b0, o)``;
6. the episode ends on arrival in a terminal state or after ``max_steps_per_episode`` steps;
   the next episode starts in the first state whose cumulative start probability exceeds ``u[3]``.

The updates are written in the incremental form ``Q <- Q + alpha (target - Q)`` of eq. 2.4
(algebraically ``(1 - alpha) Q + alpha target``), the form the learner documents, so the tables
agree with the kernel's bit for bit; a schedule's value is ``max(floor, scale * rate**e *
n**-omega)`` (:mod:`adpart.learning.schedules`). The one quantity computed differently is the
standard error of the LCB: here by Welford's running mean and sum of squared deviations of the
targets, in the kernel from the running sums of the targets and their squares. The two differ in
the last bits, which moves a firing only at an exact tie of two actions' bounds (or of ``LCB -
V_ref`` with ``L``); but where all of a pair's targets are equal the standard error is 0 here and
a cancellation residue in the kernel (``2.7e-8`` for five targets of -5), and such ties occur:
``tests/learning/test_hierarchical_reference.py`` holds the smallest case, where the kernel's
residue turns the tie towards an action the block does not offer and fires where this rule does
not.

**The grounded table** ``Q_low`` (the learner's "sound test"): started at the floor
``r_min / (1 - gamma)`` (0 when no reward is negative; ``r_min * horizon`` when ``gamma = 1``), so
that in a deterministic MDP ``Q_low <= Q*`` at all times and a firing certifies
``Q*(s, a*) - V_ref > L``. The threshold ``L`` is ``threshold`` if given, else
``threshold_scale * |V*(start)|``.

**On a firing** the layer is refined by the library's own partition operations, which are checked
elsewhere: :func:`~adpart.learning.decision_layer.refine_block` (eqs. 4.6-4.7 on
:func:`~adpart.learning.decision_layer.refinement_model`), the children's starting values by
:func:`~adpart.learning.hierarchical.child_values` (inherited option values and counts, primitive
columns grounded in ``Q_low``), the decision counts inherited from the parent block, and the
reference values recomputed by the same functions the learner calls
(:func:`~adpart.partition.bpsmdp.point_model`, :func:`~adpart.partition.bpsmdp.point_policy`,
:func:`~adpart.learning.decision_layer.offered_values`,
:func:`~adpart.mdp.evaluation.policy_evaluation`). What this module writes independently is the
learning and testing rule above.

**Scope.** Modes ``inconsistency`` and ``reward-variation+inconsistency`` (the latter first offers
the reward states' options, section 4.3.1, in every block where all its states may start them,
splitting blocks by where they may), ``refine`` ``state`` and ``block``, all three
``primitive_exploration`` rules, ``flat_explore`` (``inconsistency`` mode only, as in the learner),
``min_visits``, ``lcb_z``, the four references and ``split_offered``. Left out, and refused with a
:class:`~adpart.errors.TaskError`: intra-option learning (``intra_option``), R-max exploration
(``explore="r-max"``) and planned layer values (``layer_values="planned"``, which needs R-max).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from adpart.errors import TaskError
from adpart.learning.curves import optimal_start_value, start_distribution
from adpart.learning.decision_layer import (
    decision_layer,
    offered_values,
    refine_block,
    refinement_model,
    reward_floor,
    reward_options,
)
from adpart.learning.hierarchical import child_values
from adpart.learning.hierarchical_settings import HierarchicalSettings
from adpart.learning.schedules import Schedule, parse_schedule
from adpart.learning.settings import Run
from adpart.learning.smdp_q import option_set
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.mdp.solvers import solve
from adpart.options.models import OptionModel, option_models
from adpart.options.option import Option
from adpart.partition.bpsmdp import point_model, point_policy
from adpart.partition.partition import Partition, block_all, row_codes

__all__ = ["Firing", "ReferenceAgent", "ReferenceResult", "hierarchical_reference"]

#: The modes this reference covers (the learner's testing modes).
MODES = ("inconsistency", "reward-variation+inconsistency")
#: Solver tolerance of the point model's optimum, as the learner solves it.
POINT_TOL = 1e-8


@dataclass(frozen=True)
class Firing:
    """One firing of the inconsistency test: where, when, and what it did to the layer."""

    run: int
    episode: int  #: 0-based, the episode in progress
    state: int
    block: int  #: the block of ``state`` before the refinement
    action: int  #: ``a*``
    offered: bool  #: whether the block already offered ``a*`` (``split_offered``)
    blocks_before: int
    blocks_after: int

    def key(self) -> tuple[int, int, int, int, int]:
        """``(run, episode, state, block, action)``."""
        return (self.run, self.episode, self.state, self.block, self.action)


@dataclass(frozen=True, eq=False)
class ReferenceResult:
    """What :func:`hierarchical_reference` returns (per run ``k`` of ``K``, ``N`` episodes).

    Attributes:
        firings: every firing, run by run, in the order it happened.
        partitions: per run, the final decision layer.
        block_Q: per run, the ``(B_k, C)`` layer values (``-inf`` where a column is not offered).
        Q_flat: ``(K, S, A)`` the optimistic flat values.
        Q_low: ``(K, S, A)`` the grounded flat values the test read (``None`` if it never ran).
        steps, decisions, returns, blocks: ``(K, N)`` primitive steps, option choices,
            undiscounted return and number of blocks of every episode (at its end).
        threshold: the inconsistency threshold ``L``.
        option_names: the ``C`` column names (primitive actions first).
    """

    firings: list[Firing]
    partitions: list[Partition]
    block_Q: list[np.ndarray]
    Q_flat: np.ndarray
    Q_low: np.ndarray | None
    steps: np.ndarray
    decisions: np.ndarray
    returns: np.ndarray
    blocks: np.ndarray
    threshold: float
    option_names: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class _Task:
    """What every run shares: the task, the learner's columns, the settings (read-only)."""

    mdp: FiniteMDP
    columns: list[Option]
    smdp: SMDPModel
    refiner: SMDPModel
    layer: Partition
    alpha: Schedule
    epsilon: Schedule
    q_init: float
    horizon: int
    threshold: float  #: ``L``; ``inf``: the test is off and ``Q_low`` is not kept
    floor: float  #: ``r_min / (1 - gamma)``, the grounded table's start
    r_min: float
    min_visits: int
    lcb_z: float
    flat_explore: bool
    primitive_exploration: str
    reference: str
    refine: str
    split_offered: bool
    delta: float
    epsilon_layer: float | None
    start_cdf: np.ndarray
    last_start: int


def schedule_value(schedule: Schedule, visits: int, episode: int) -> float:
    """``max(floor, scale * rate**episode * visits**-omega)`` (:mod:`adpart.learning.schedules`)."""
    per_episode = schedule.scale * schedule.rate ** float(episode)
    return max(schedule.floor, per_episode * float(visits) ** -schedule.omega)


def pick(u: float, m: int) -> int:
    """The index ``floor(u m)`` of one of ``m`` candidates drawn by the uniform ``u``."""
    return min(int(u * m), m - 1)


class _Streams:
    """One run's two random streams, read one row per primitive step (module docstring)."""

    def __init__(self, main: np.random.Generator, aux: np.random.Generator) -> None:
        self.main, self.aux = main, aux

    def first(self) -> float:
        """The uniform of the first start state."""
        return float(self.main.random())

    def row(self) -> tuple[np.ndarray, np.ndarray]:
        """``u`` (explore?, which column, successor, next start), ``v`` (stochastic action,
        termination)."""
        return self.main.random(4), self.aux.random(2)


class ReferenceAgent:
    """One run of the hierarchical learner, stated plainly (module docstring, steps 1-6).

    Attributes:
        layer: the decision layer; ``Q``, ``n_o`` its ``(B, C)`` values and update counts,
            ``n_d`` its ``(B,)`` decision counts.
        Q_flat, n_flat: the optimistic flat values and the pairs' visit counts ``(S, A)``.
        Q_low: the grounded flat values (``None`` when the test is off); ``t_mean``/``t_m2``
            the running mean and sum of squared deviations of each pair's targets, ``seen`` the
            successors each pair has shown.
        rewarded: whether the run has arrived in a terminal state by a step paying more than
            ``r_min`` (``primitive_exploration="until-reward"``).
        firings: this run's firings, in order.
    """

    def __init__(self, task: _Task, run: int, streams: _Streams) -> None:
        self.task, self.run, self.streams = task, run, streams
        mdp = task.mdp
        S, A = mdp.n_states, mdp.n_actions
        self.layer = task.layer
        self.Q = np.where(self.layer.admissible, task.q_init, -np.inf)
        self.n_o = np.zeros(self.layer.admissible.shape, dtype=np.int64)
        self.n_d = np.zeros(self.layer.n_blocks, dtype=np.int64)
        self.Q_flat = np.where(mdp.admissible, task.q_init, -np.inf)
        self.n_flat = np.zeros((S, A), dtype=np.int64)
        self.testing = bool(np.isfinite(task.threshold))
        self.Q_low = np.where(mdp.admissible, task.floor, -np.inf) if self.testing else None
        self.t_mean = np.zeros((S, A))
        self.t_m2 = np.zeros((S, A))
        self.seen: list[list[set[int]]] = [[set() for _ in range(A)] for _ in range(S)]
        self.rewarded = False
        self.firings: list[Firing] = []
        self.V_block: np.ndarray | None = None  # V*_P per block (references model, offered)
        self.V_state: np.ndarray | None = None  # per state (references offered, policy)
        self._reference_values()
        self.steps: list[int] = []
        self.decisions: list[int] = []
        self.returns: list[float] = []
        self.blocks: list[int] = []

    # ------------------------------------------------------------------ the episodes

    def start_state(self, u: float) -> int:
        """The first state whose cumulative start probability exceeds ``u``."""
        s = int(np.searchsorted(self.task.start_cdf, u, side="right"))
        return min(s, self.task.last_start)

    def learn(self, episodes: int) -> None:
        """Run ``episodes`` episodes (module docstring, steps 1-6)."""
        s = self.start_state(self.streams.first())
        for e in range(episodes):
            s = self.episode(e, s)

    def episode(self, e: int, s: int) -> int:
        """Episode ``e`` from ``s``; returns the next episode's start state."""
        task, mdp = self.task, self.task.mdp
        t, n_decisions, ret = 0, 0, 0.0
        option, b0, G, discount = -1, -1, 0.0, 1.0
        while True:
            if option < 0:  # a decision point: the test first, then the choice
                while (found := self.inconsistency(s)) is not None:
                    self.refine(e, s, *found)
            u, v = self.streams.row()
            if option < 0:
                option, b0 = self.choose(s, e, float(u[0]), float(u[1]))
                G, discount = 0.0, 1.0
                n_decisions += 1
            a = self.action(option, s, float(v[0]))
            s2 = self.successor(s, a, float(u[2]))
            r = float(mdp.R[s, a])
            done = bool(mdp.terminal[s2])
            if done and r > task.r_min:
                self.rewarded = True
            self.learn_flat(e, s, a, r, s2, done)
            G += discount * r
            discount *= mdp.gamma
            ret += r
            t += 1
            cut = t == task.horizon
            if done or cut or float(v[1]) < self.task.columns[option].beta[s2]:
                if self.layer.admissible[b0, option]:
                    self.learn_layer(e, b0, option, G, discount, s2, done)
                option = -1
            if done or cut:
                self.steps.append(t)
                self.decisions.append(n_decisions)
                self.returns.append(ret)
                self.blocks.append(self.layer.n_blocks)
                return self.start_state(float(u[3]))
            s = s2

    # ------------------------------------------------------------------ decisions

    def primitives_only(self) -> bool:
        """Whether epsilon-exploration draws among the primitive actions alone."""
        rule = self.task.primitive_exploration
        return rule == "always" or (rule == "until-reward" and not self.rewarded)

    def choose(self, s: int, e: int, u0: float, u1: float) -> tuple[int, int]:
        """Epsilon-greedy on the layer (step 2); returns the column and the block it starts in."""
        task, mdp = self.task, self.task.mdp
        b = int(self.layer.labels[s])
        self.n_d[b] += 1
        actions = np.flatnonzero(mdp.admissible[s])
        if u0 < schedule_value(task.epsilon, int(self.n_d[b]), e):
            if self.primitives_only():
                pool = actions
            else:
                pool = np.union1d(np.flatnonzero(self.layer.admissible[b]), actions)
            return int(pool[pick(u1, pool.size)]), b
        row = self.Q[b]
        ties = np.flatnonzero(row == row.max())
        o = int(ties[pick(u1, ties.size)])
        if task.flat_explore:
            best = int(actions[np.argmax(self.Q_flat[s, actions])])  # lowest index on ties
            if self.Q_flat[s, best] > row[o]:
                o = best  # the optimistic flat action beats the block's best
        return o, b

    def action(self, option: int, s: int, v0: float) -> int:
        """The running option's action in ``s`` (step 3)."""
        policy = self.task.columns[option].policy
        if policy.ndim == 1:
            return int(policy[s])
        probs = policy[s]
        last = int(np.flatnonzero(probs > 0)[-1])
        above = np.flatnonzero(np.cumsum(probs) > v0)
        return min(int(above[0]), last) if above.size else last

    def successor(self, s: int, a: int, u: float) -> int:
        """``s'`` drawn by ``u`` exactly as :meth:`FiniteMDP.sample_next` draws it (step 3)."""
        mdp = self.task.mdp
        row = a * mdp.n_states + s
        lo, hi = int(mdp.P.indptr[row]), int(mdp.P.indptr[row + 1])
        k = lo + int(np.searchsorted(mdp.sampler_keys[lo:hi], row + u, side="right"))
        return int(mdp.P.indices[min(k, hi - 1)])

    # ------------------------------------------------------------------ learning

    def learn_flat(self, e: int, s: int, a: int, r: float, s2: int, done: bool) -> None:
        """Watkins' update (eq. 2.4) of the optimistic flat ``Q`` and of ``Q_low`` (step 4)."""
        task = self.task
        self.n_flat[s, a] += 1
        n = int(self.n_flat[s, a])
        alpha = schedule_value(task.alpha, n, e)
        target = r if done else r + task.mdp.gamma * float(self.Q_flat[s2].max())
        old = float(self.Q_flat[s, a])
        self.Q_flat[s, a] = old + alpha * (target - old)
        if self.Q_low is None:
            return
        target = r if done else r + task.mdp.gamma * float(self.Q_low[s2].max())
        old = float(self.Q_low[s, a])
        self.Q_low[s, a] = old + alpha * (target - old)
        mean = float(self.t_mean[s, a])  # Welford: the targets' mean and squared deviations
        delta = target - mean
        mean += delta / n
        self.t_mean[s, a] = mean
        self.t_m2[s, a] += delta * (target - mean)
        self.seen[s][a].add(s2)

    def learn_layer(self, e: int, b0: int, option: int, G: float, discount: float, s2: int,
                    done: bool) -> None:
        """SMDP Q-learning (section 3.1) of ``Q_P(b0, option)`` at the option's end (step 5)."""
        self.n_o[b0, option] += 1
        alpha = schedule_value(self.task.alpha, int(self.n_o[b0, option]), e)
        if done:
            target = G
        else:
            target = G + discount * float(self.Q[self.layer.labels[s2]].max())
        old = float(self.Q[b0, option])
        self.Q[b0, option] = old + alpha * (target - old)

    # ------------------------------------------------------------------ the test (4.3.3)

    def lower_confidence_bound(self, s: int, a: int) -> float:
        """``Q_low(s, a)`` less ``lcb_z`` standard errors of its targets where the pair has shown
        more than one successor."""
        value = float(self.Q_low[s, a])
        if len(self.seen[s][a]) > 1:
            n = int(self.n_flat[s, a])
            variance = float(self.t_m2[s, a]) / (n - 1)
            value -= self.task.lcb_z * math.sqrt(max(variance, 0.0) / n)
        return value

    def reference_value(self, s: int, b: int, offered: bool) -> float:
        """What the grounded value of ``a*`` must beat by ``L`` (step 1)."""
        task = self.task
        if offered:  # split_offered: the layer's policy value, where s shares its block
            shared = self.layer.sizes[b] > 1
            return float(self.V_state[s]) if shared else math.inf
        if task.reference == "learned":
            return float(self.Q[b][self.layer.admissible[b]].max())
        if task.reference == "model":
            return float(self.V_block[b])
        return float(self.V_state[s])

    def inconsistency(self, s: int) -> tuple[int, int, bool] | None:
        """``(block, a*, offered)`` if the test fires in ``s`` (step 1), else ``None``."""
        task = self.task
        if not self.testing:
            return None
        b = int(self.layer.labels[s])
        if self.n_d[b] < task.min_visits:
            return None
        best, a_star = -math.inf, -1
        for a in np.flatnonzero(task.mdp.admissible[s]):
            n = int(self.n_flat[s, a])
            if n == 0 or n < task.min_visits:
                continue
            bound = self.lower_confidence_bound(s, int(a))
            if bound > best:
                best, a_star = bound, int(a)
        if a_star < 0:
            return None
        offered = bool(self.layer.admissible[b, a_star])  # primitive a is column a
        if offered and not task.split_offered:
            return None
        if best - self.reference_value(s, b, offered) > task.threshold:
            return b, a_star, offered
        return None

    def refine(self, e: int, s: int, b: int, a: int, offered: bool) -> None:
        """``a*`` joins the layer at ``s`` (``refine="state"``, or ``split_offered``) or in all of
        ``b``, which is refined by eqs. 4.6-4.7; the children start as
        :func:`~adpart.learning.hierarchical.child_values` says."""
        task = self.task
        old = self.layer
        at = s if task.refine == "state" or offered else None
        new = refine_block(old, b, [a], task.refiner, delta=task.delta,
                           epsilon=task.epsilon_layer, at=at)
        parent = new.parent_map(old)
        self.Q, self.n_o = child_values(self.Q, self.n_o, old, new, b, self.Q_low,
                                        self.n_flat > 0, task.floor, parent)
        self.n_d = self.n_d[parent]
        self.layer = new
        self._reference_values()
        self.firings.append(Firing(self.run, e, s, b, a, offered, old.n_blocks, new.n_blocks))

    def _reference_values(self) -> None:
        """The reference values of the current layer (recomputed after every refinement)."""
        task = self.task
        if not self.testing:
            return
        smdp, layer = task.smdp, self.layer
        if task.reference in ("model", "offered"):
            self.V_block = solve(point_model(layer, smdp), POINT_TOL).V
        if task.reference == "offered":
            best = offered_values(layer, smdp, task.mdp.terminal, task.floor)
            self.V_state = np.maximum(best, self.V_block[layer.labels])
        elif task.reference == "policy":
            self.V_state = policy_evaluation(smdp, point_policy(layer, smdp, POINT_TOL),
                                             never=task.floor)


# --------------------------------------------------------------------------- set-up


def grounded_floor(mdp: FiniteMDP, horizon: int) -> float:
    """``r_min / (1 - gamma)`` (0 if no reward is negative; ``r_min * horizon`` if ``gamma = 1``):
    no return of ``mdp`` falls below it."""
    r_min = reward_floor(mdp)
    if r_min >= 0.0:
        return 0.0
    return r_min / (1.0 - mdp.gamma) if mdp.gamma < 1.0 else r_min * horizon


def initial_layer(mdp: FiniteMDP, options: Sequence[Option], partition: Partition | None, *,
                  mode: str, delta: float, epsilon: float | None,
                  models: Sequence[OptionModel] | None
                  ) -> tuple[Partition, list[Option], SMDPModel]:
    """The layer learning starts from, over the learner's columns (primitives, options, and in
    ``reward-variation+inconsistency`` mode the reward states' options, section 4.3.1)."""
    options = list(options)
    extra = reward_options(mdp) if mode == "reward-variation+inconsistency" else []
    if extra and models is not None:
        models = list(models) + option_models(mdp, extra, duration=False)
    if partition is None:
        layer, columns, smdp = decision_layer(mdp, options + extra, delta=delta,
                                              epsilon=epsilon, models=models)
        return layer, columns, smdp
    columns, smdp = option_set(mdp, options + extra, include_primitives=True, models=models)
    A, C = mdp.n_actions, len(columns)
    offered = np.zeros((partition.n_blocks, C), dtype=bool)
    given = partition.admissible
    if given.shape[1] == len(options):  # given over the options alone
        offered[:, A:A + len(options)] = given
    else:  # over the primitive actions, then the options
        offered[:, :A + len(options)] = given
    layer = Partition(partition.labels, offered)
    if extra:  # each block offers them where all its states may start them (4.3.1)
        new = np.arange(C - len(extra), C)
        starts = smdp.admissible[:, new]
        layer = layer.refine_by(row_codes(starts))
        offered = layer.admissible.copy()
        offered[:, new] = block_all(layer.labels, layer.n_blocks, starts)
        layer = layer.with_admissible(offered)
    return layer, columns, smdp


def hierarchical_reference(
    mdp: FiniteMDP,
    options: Sequence[Option],
    partition: Partition | None = None,
    settings: HierarchicalSettings | None = None,
    run: Run | None = None,
    models: Sequence[OptionModel] | None = None,
) -> ReferenceResult:
    """Run the rule of the module docstring for ``run.runs`` runs, one after the other.

    It takes what :func:`~adpart.learning.hierarchical.hierarchical_learning` takes, the same
    settings objects (already checked when they were built); the learner's output-only settings
    (``eval_every``, ``progress``, ``kernel``) have no place here.

    Raises:
        TaskError: a setting outside this reference's scope (``intra_option``,
            ``explore="r-max"``, ``layer_values="planned"``, a mode that does not test).
    """
    settings = HierarchicalSettings() if settings is None else settings
    run = Run() if run is None else run
    if settings.intra_option:
        raise TaskError("the plain reference leaves out intra-option learning "
                        "(intra_option=True); compare with intra_option=False")
    if settings.directed:
        raise TaskError("the plain reference leaves out R-max exploration (explore r-max); "
                        "compare with another explore")
    if settings.layer_values != "learned":
        raise TaskError("the plain reference leaves out planned layer values "
                        f"(layer_values={settings.layer_values!r}); compare with 'learned'")
    if settings.mode not in MODES:
        raise TaskError(f"mode = {settings.mode!r}: the plain reference covers the testing modes "
                        f"{list(MODES)}")
    test, refinement = settings.test, settings.refinement
    mode, reference = settings.mode, settings.test_reference
    delta, epsilon, refine = refinement.delta, refinement.partition_epsilon, refinement.refine
    threshold, threshold_scale = test.threshold, test.threshold_scale
    min_visits, lcb_z, split_offered = test.min_visits, test.lcb_z, test.split_offered
    flat_explore = settings.flat_explore
    primitive_exploration = settings.exploration.primitive_exploration
    runs, episodes, seed = run.runs, run.episodes, 0 if run.seed is None else run.seed
    alpha, epsilon_greedy, q_init = run.alpha, run.epsilon, run.q_init
    max_steps_per_episode, reference_values = run.max_steps_per_episode, run.reference_values
    horizon = int(max_steps_per_episode)
    mu = start_distribution(mdp)
    if threshold is None:
        threshold = threshold_scale * abs(optimal_start_value(mdp, mu, reference_values))
    layer, columns, smdp = initial_layer(mdp, options, partition, mode=mode, delta=delta,
                                         epsilon=epsilon, models=models)
    task = _Task(
        mdp=mdp, columns=columns, smdp=smdp, refiner=refinement_model(mdp, smdp), layer=layer,
        alpha=parse_schedule(alpha), epsilon=parse_schedule(epsilon_greedy),
        q_init=0.0 if q_init is None else float(q_init), horizon=horizon,
        threshold=float(threshold), floor=grounded_floor(mdp, horizon), r_min=reward_floor(mdp),
        min_visits=int(min_visits), lcb_z=float(lcb_z),
        flat_explore=bool(flat_explore) and mode == "inconsistency",
        primitive_exploration=primitive_exploration, reference=reference, refine=refine,
        split_offered=bool(split_offered), delta=float(delta), epsilon_layer=epsilon,
        start_cdf=np.cumsum(mu), last_start=int(np.flatnonzero(mu > 0)[-1]),
    )
    agents = []
    for k, main in enumerate(np.random.default_rng(seed).spawn(runs)):
        agent = ReferenceAgent(task, k, _Streams(main, main.spawn(1)[0]))
        agent.learn(episodes)
        agents.append(agent)
    testing = agents[0].testing
    return ReferenceResult(
        firings=[f for agent in agents for f in agent.firings],
        partitions=[agent.layer for agent in agents],
        block_Q=[agent.Q for agent in agents],
        Q_flat=np.stack([agent.Q_flat for agent in agents]),
        Q_low=np.stack([agent.Q_low for agent in agents]) if testing else None,
        steps=np.array([agent.steps for agent in agents], dtype=np.int64),
        decisions=np.array([agent.decisions for agent in agents], dtype=np.int64),
        returns=np.array([agent.returns for agent in agents]),
        blocks=np.array([agent.blocks for agent in agents], dtype=np.int64),
        threshold=float(threshold),
        option_names=tuple(o.name for o in columns),
    )
