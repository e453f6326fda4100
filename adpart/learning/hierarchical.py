"""Hierarchical learning on a decision layer with inconsistency refinement (section 4.3).

The agent decides on the *decision layer* (built and refined by
:mod:`adpart.learning.decision_layer`), a :class:`~adpart.partition.Partition` whose blocks
offer options (SMDP Q-learning over (block, option), :mod:`adpart.learning.smdp_q`), while every
primitive step also updates a flat Q over (state, action) (section 4.3.3). The option columns are
the primitive actions' one-step options ``0..A-1`` followed by the given options, so a primitive
action can join a block's options.

The modes (``mode=``): the three alternatives of section 4.3 the seed compares in 5.1.3, and
reward variation with the inconsistency test:

* ``inconsistency`` (4.3.3, Fig. 4.6): at a decision point in state ``s`` of block ``b``, with
  ``a*`` the action of the highest *lower confidence bound* ``LCB(s, a)`` of the flat value
  (below), if ``a*`` is not yet offered in ``b``, both the pair ``(s, a*)`` and the block have
  at least ``min_visits`` visits, and ``LCB(s, a*) - max_{o in O_b} Q_P(b, o) > L``, then ``a*``
  joins the option set and ``b`` is refined for the new sets (eqs. 4.6-4.7 with the learner's
  ``delta`` and ``epsilon``; only ``b`` is split, to a fixpoint, the other blocks stay). Where
  ``a*`` joins is ``refine=``: ``"state"`` (the default) adds it to the set of ``s`` alone, the
  state whose evidence fired - ``s`` becomes a block of its own offering ``O_b + {a*}`` and the
  rest of ``b`` is refined to stability for ``O_b``; ``"block"`` adds it to every state of ``b``,
  as 4.3.3 writes ``A_B <- A_B + {a*} for all s in B``. The seed's rule was measured to turn the
  layer into columns of the grid: a primitive move is deterministic, so stability for it splits a
  room into rows or columns, and one firing took the pipeline's 55-block three-floor layer to
  344 blocks (docs/hierarchical-learning.md). The children inherit ``b``'s option values and
  counts; their primitive columns start *grounded*, at the mean lower-bound flat value
  ``Q_low(s, a)`` over the child's states where ``a`` was tried (``a*`` tried in none: the lower
  bound; :func:`child_values` says why plain inheritance fails). Partitions are per run: runs
  refine independently.
* ``action-refinement`` (4.3.2): before learning, every block holding a state with a reward above
  the step reward (:func:`~adpart.learning.decision_layer.reward_level`, the minimum ``r_min``
  wherever every step pays the same) gets all primitive actions and is refined for them; the
  other blocks keep the options only. No test during learning.
* ``reward-variation`` (4.3.1): before partitioning, every such state becomes an extra subgoal
  (an option to it from every state that can reach it); the decision layer is then built by the
  multi-phase partitioner from the extended option set. Given a layer (one Algorithm 3 built),
  the extra options join each of its blocks where all its states may start them instead (blocks
  split by where they may start; not refined to delta-stability, which splits a block offering
  primitive actions into lines). No test during learning.
* ``reward-variation+inconsistency`` (the transfer pipeline's default): the layer of
  ``reward-variation``, learned with the test of ``inconsistency`` against the ``offered``
  reference (below), so a layer whose options cannot serve the task is still refined where the
  evidence shows it. On three-floor ``reach-goal -> reach-top-west`` the test never fires there
  (the goal option makes every state's best offered value optimal) and learning takes the
  episodes of ``reward-variation``; compared with the block's learned value instead, it fired
  about 230 times a run on block-internal value spread and took 16 times as many episodes
  (docs/hierarchical-learning.md, "Session 7").

**A sound test** (docs/hierarchical-learning.md has the measurements). The seed compares the flat
value with the block's. Compared with an *optimistic* flat table (Q = 0 against -1 a step), the
test fired 365-478 times a run on three-floor, right (against Q*) 45% of the time. The flat
values the test reads are therefore a table ``Q_low`` of their own, started at a true lower bound
``r_min / (1 - gamma)`` (0 when no reward is negative) and updated by the same transitions and step
sizes as the flat table. In a deterministic MDP every target ``r + gamma max Q_low(s', .)`` is
then at most ``Q*(s, a)``, so ``Q_low <= Q*`` at all times and a firing certifies
``Q*(s, a*) - Q_P(b) > L``. Where a pair has shown more than one successor the test subtracts
``lcb_z`` standard errors of its targets (a normal-approximation bound, one-sided level about
2.3% at the default z = 2; not a finite-sample guarantee). Exploration is separate (a strategy
of its own, ``explore``): with ``"optimistic-flat"``, the default, the agent, at a greedy
decision, takes the *optimistic* flat action where its value beats the block's best - that is
how a goal that is no subgoal is found - but the test never reads that table.
Epsilon-exploration draws among the primitive actions alone until the run first collects a reward
above ``r_min`` (``primitive_exploration="until-reward"``, the
default; ``"always"``, ``"never"``: over every column and primitive from the start, the former
rule): a random option carries the agent to a subgoal of the *earlier* task, and on the pipeline's
28-block three-floor layer such jumps delayed the first arrival at the new goal from episodes 10-24
to 53-103. Once a reward is found the options are explored too, which the layer's values need.

**Directed exploration** (``explore="r-max"``, ``known_after = m``,
:mod:`adpart.learning._rmax`). Neither
the optimistic flat table nor epsilon-exploration ever reached three-floor-arm ``deliver``'s goal
(docs/hierarchical-learning.md). With ``m`` the agent counts each flat pair's successors and
explores by R-max: at a greedy decision it takes the action of the optimistic model's optimum
(an unknown pair, tried fewer than ``m`` times, worth the value ceiling) where that beats the
block's best. The test's grounded values then come from the same counts: ``Q_low(s, a)`` is the
optimum of the empirical model in which an untried pair is worth the floor ``r_min / (1 -
gamma)``, re-planned incrementally after every step, and its lower confidence bound subtracts
``lcb_z`` standard errors of the successors' values. On a deterministic MDP every tried pair's
model is exact and an untried one is at the floor, so ``Q_low <= Q*`` as before; the Q-learning
bound it replaces rose too slowly to be read (on arm ``deliver``, after 800 episodes, it was
still at the floor in most route states). The layer's values then start at that floor too
(``q_init``): with optimistic zeros one three-floor run in 20 kept a greedy path into blocks it
had never visited (all their values still 0), a loop that never arrives (gap 27.9 from episode
100 to 1,000); started at the floor, 20 of 20 runs were exact by episode 200, the median
unchanged at 40 episodes. An unknown pair is worth ``value_ceiling``: by default the ceiling of
the task's own rewards; on a belief model (the learned-model regime) it must be given, and the
pipeline gives the ceiling of the rewards the first task paid (three-floor ``reach-top-west``: 29
episodes to the bound against flat Q-learning's 305, docs/learned-model.md).

**Planned layer values** (``layer_values="planned"``, with R-max). On arm ``deliver`` the
layer's SMDP Q-values, learned by step sizes over 1,400-1,600 blocks of a slip-0.5 domain, sit
8-22 above ``V*`` along the route with near-ties, and their greedy policy never delivers, even
after 2,500 episodes in which the counts pin down a flat policy 0.3-0.9 from ``V*``. Planned, the
layer's values are the optimum of its point model on the run's grounded model (the primitive
columns from the counts, untried pairs at the floor; the options' models as given): certainty
equivalence on the decision layer, scored like any greedy policy. The test's ``"policy"``
reference reads the same kind of value: what the layer's best block policy achieves from ``s``,
which the point model's ``V*_P(b)`` and the per-state best of the offered columns both
overstate on a layer whose blocks mix states that need different columns.

**An offered action the block's policy fails** (``split_offered``, with the ``"policy"``
reference). 4.3.3's test only adds an action the block does not offer. In 3 of 20 arm runs the
final layer's best block policy never delivered (gap 27.1) although at every state of its loop
the action the grounded values chose was already offered: blocks of two states (the same cell with
and without the object, or before and after delivery) whose point model picked a move one of
them needs and the other does not, and successor blocks whose averaged values pulled the policy
the wrong way. With ``split_offered`` the test also reads an offered ``a*``: where its lower
bound beats the value from ``s`` of the layer's best block policy by more than ``L``, ``s`` leaves
its block with the block's set (``refine_block(..., at=s)``) and the point model may choose for
it alone; a state that is already a block of its own is not tested that way. On the three
final layers, splitting such states one at a time in random order brought each within the bound
(0.95-3.06 from ``V*`` after 57-87 splits; docs/hierarchical-learning.md, session 13).

**Threshold.** Theorem 4.5 bounds ``||V* - V*_P||`` by ``2 (1 + gamma/(1-gamma) max(eps, delta))``;
the seed uses it as the inconsistency threshold. The bound mixes units: with the seed's own
``epsilon = 10-20`` and ``gamma >= 0.9`` it is 180-360, above the whole value range of its tasks, so
the test would never fire. The default ``L`` is calibrated to the task's value scale and sits
below the success tolerance: ``L = threshold_scale * |V*(start)|`` with ``threshold_scale =
0.025``, half of the 5% gap at which a run counts as learned (``V*`` is the exact value the
curves are scored against; a number given as ``threshold`` is used as is, for a learner without
a model). The former rule, half a reward span (50 on three-floor), could not fire on urban,
whose values lie in [-20, 0]. Theorem 4.5's bound is reported beside ``L``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np

from adpart.errors import TaskError
from adpart.learning._rmax import episodic_ceiling, reward_ceiling, value_ceiling
from adpart.learning.curves import (
    LearningCurve,
    StartValues,
    optimal_start_value,
    start_distribution,
)
from adpart.learning.decision_layer import (
    DecisionLayer,
    build_decision_layer,
    decision_layer,
    refine_block,
    refinement_model,
    reward_floor,
    reward_options,
    reward_states,
)
from adpart.learning.firing_audit import firing_audit, first_actions
from adpart.learning.hierarchical_parts import (
    LayerRefiner,
    OnlineSplits,
    ReferenceValues,
    lifted_values,
)
from adpart.learning.hierarchical_settings import (
    MODES,
    PRIMITIVE_EXPLORATION,
    REWARD_OPTION_MODES,
    TESTING_MODES,
    HierarchicalSettings,
)
from adpart.learning.knowledge import Knowledge, world
from adpart.learning.online_phase3 import OnlinePhase3
from adpart.learning.result import LearnResult
from adpart.learning.settings import Run, fresh_seed, require_mdp
from adpart.learning.smdp_q import (
    InconsistencyArrays,
    drive,
    kernel_function,
    make_state,
    option_set,
)
from adpart.mdp.evaluation import greedy_policy
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.options.models import OptionModel, option_models
from adpart.options.option import Option
from adpart.partition.bpsmdp import theorem_4_5_bound
from adpart.partition.partition import Partition, block_all, row_codes

__all__ = [
    "MODES",
    "REWARD_OPTION_MODES",
    "TESTING_MODES",
    "DecisionLayer",
    "HierarchicalResult",
    "HierarchicalSettings",
    "build_decision_layer",
    "child_values",
    "decision_layer",
    "default_threshold",
    "episodic_ceiling",
    "hierarchical_learning",
    "refine_block",
    "refinement_model",
    "reward_ceiling",
    "reward_states",
    "value_ceiling",
]



@dataclass(frozen=True, eq=False)
class HierarchicalResult(LearnResult):
    """What :func:`hierarchical_learning` returns.

    Attributes:
        Q: ``(K, S, O)`` the decision layer's values lifted to states (``Q_P(block(s), o)``).
        block_Q: per run, the ``(B_k, O)`` block values.
        partitions: per run, the final decision layer.
        Q_flat: ``(K, S, A)`` the flat values learned beside it.
        Q_grounded: ``(K, S, A)`` the grounded flat values the test read (with R-max
            the optimum of each run's empirical model, untried pairs at the floor), or ``None``
            when the test was off (threshold infinite, or a mode that does not test).
        curve: the :class:`LearningCurve`.
        blocks: ``(K, N)`` number of blocks at the end of each episode (Figs. 5.10, 5.13).
        refinements: one dict per refinement: run, episode (0-based, the one in progress),
            state, block, action, blocks before and after.
        seed, v_star_start, option_names, parameters: as :class:`SMDPQResult`.
    """

    block_Q: list[np.ndarray]
    partitions: list[Partition]
    Q_flat: np.ndarray
    blocks: np.ndarray
    refinements: list[dict[str, int]]
    option_names: tuple[str, ...]
    Q_grounded: np.ndarray | None = None

    @property
    def n_refinements(self) -> np.ndarray:
        """``(K,)`` refinements per run."""
        counts = np.zeros(self.runs, dtype=np.int64)
        for event in self.refinements:
            counts[event["run"]] += 1
        return counts

    def blocks_table(self) -> dict[str, np.ndarray]:
        """Blocks over time as columns ``run``, ``episode`` (1-based), ``blocks``."""
        K, N = self.blocks.shape
        return {"run": np.repeat(np.arange(K), N), "episode": np.tile(np.arange(1, N + 1), K),
                "blocks": self.blocks.reshape(-1)}


def child_values(Q_old: np.ndarray, n_old: np.ndarray, old: Partition, new: Partition,
                 block: int | np.ndarray, Q_low: np.ndarray, tried: np.ndarray,
                 lower_bound: float, parent: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Starting values and counts of the blocks of ``new``, ``old`` refined at ``block`` (4.3.3;
    an array of blocks when several were split at once, as phase 3 online does).

    Every block keeps its parent's values and counts, except the primitive columns ``0..A-1``
    (``A = Q_low.shape[1]``) of the split blocks' children, which start *grounded*, with a count
    of 0:
    at the mean of ``Q_low(s, a)`` over the child's states where ``a`` was ``tried``, and at
    ``lower_bound`` where it was tried in none of them - new to the child or inherited alike:
    a child's primitive values come from its own states' evidence only. Columns the child does
    not offer are ``-inf``. ``parent`` is ``new.parent_map(old)``, when the caller has it.

    Why not plain inheritance (the seed's "children inherit the values"): a parent's value of a
    primitive is learned in the states where the agent took it, and a child may hold only states
    where the same action hits a wall. On three-floor (20 runs, reach-top-west on the pipeline's
    27-block layer) such stale values, never corrected because the agent's optimistic flat
    exploration steers around them, made 4 runs lose a policy they had already learned (gap
    0 -> 66.5, a loop at the start); the optimistic flat mean that new columns started at
    before, and parent values kept where the child has no evidence, made other runs loop the
    same way (docs/hierarchical-learning.md has the counts).
    """
    A = Q_low.shape[1]
    if parent is None:
        parent = new.parent_map(old)
    Qn = Q_old[parent]
    n_new = n_old[parent]
    B = new.n_blocks
    split = np.atleast_1d(np.asarray(block, dtype=np.int64))
    members = np.flatnonzero(np.isin(old.labels, split))  # only split blocks' children are read
    kid = new.labels[members]
    hit = tried[members]
    cell = (kid[:, None] * A + np.arange(A)).ravel()  # (child, action) of every member entry
    sums = np.bincount(cell, weights=np.where(hit, Q_low[members], 0.0).ravel(),
                       minlength=B * A).reshape(B, A)
    counts = np.bincount(cell, weights=hit.ravel(), minlength=B * A).reshape(B, A)
    grounded = sums / np.maximum(counts, 1.0)
    fresh = new.admissible[:, :A] & np.isin(parent, split)[:, None]
    Qn[:, :A][fresh] = np.where(counts[fresh] > 0, grounded[fresh], lower_bound)
    n_new[:, :A][fresh] = 0
    Qn[~new.admissible] = -np.inf
    return Qn, n_new


def theorem_bound(mdp: FiniteMDP, *, epsilon: float | None, delta: float) -> float:
    """Theorem 4.5's bound for the layer's ``epsilon`` and ``delta`` (``inf`` when gamma = 1)."""
    if mdp.gamma >= 1.0:
        return float("inf")
    return float(theorem_4_5_bound(mdp.gamma, 0.0 if epsilon is None else epsilon, delta))


def default_threshold(v_star_start: float, *, scale: float) -> float:
    """``L = scale * |V*(start)|`` (module docstring)."""
    return float(scale * abs(v_star_start))


def flat_lower_bound(mdp: FiniteMDP, horizon: int) -> float:
    """A value no return of ``mdp`` can fall below: ``r_min / (1 - gamma)``, or 0 if ``r_min >= 0``.

    With ``gamma = 1`` the episode cap bounds the sum: ``horizon * r_min``.
    """
    r_min = reward_floor(mdp)
    if r_min >= 0.0:
        return 0.0
    return r_min / (1.0 - mdp.gamma) if mdp.gamma < 1.0 else r_min * horizon


def _offer(partition: Partition, columns: np.ndarray, admissible: np.ndarray) -> Partition:
    """``partition`` with ``columns`` offered in every block where all its states may start them:
    blocks are split by where the columns may start (children keep their parent's options), not
    refined to delta-stability for them - a layer that offers primitive actions would then split
    into lines, as one firing of the ``block`` rule does."""
    split = partition.refine_by(row_codes(admissible[:, columns]))
    adm = split.admissible.copy()
    adm[:, columns] = block_all(split.labels, split.n_blocks, admissible[:, columns])
    return split.with_admissible(adm)


def _with_empty_columns(partition: Partition, n: int) -> Partition:
    """``partition`` with ``n`` more option columns, offered nowhere (yet)."""
    if n == 0 or not isinstance(partition, Partition):
        return partition
    return partition.with_admissible(
        np.pad(partition.admissible, ((0, 0), (0, n)), constant_values=False))


def _pad_partition(partition: Partition, n_prim: int, n_total: int, model: SMDPModel,
                   terminal: np.ndarray) -> Partition:
    """The partition over the learner's columns (primitives first), checked against the model.

    A terminal state of the task may share a block whose options it cannot start: no decision is
    taken there (an episode ends on arrival), so a layer built before the task was known - the
    learned-model regime's phases 1-2 - need not have set the task's goal apart. For the same
    reason such a layer may hold the *earlier* task's terminal states in a block that offers
    every option (phases 1-2 make them one absorbing block): a live state whose block offers a
    column it cannot start becomes a block of its own, offering those of the block's columns it
    can start, or everything it can start (at least the primitive actions) if none, and the
    learner finds out the rest."""
    if not isinstance(partition, Partition):
        raise TaskError(f"partition must be an adpart Partition, got {type(partition).__name__}")
    if partition.n_states != model.n_states:
        raise TaskError(
            f"the partition covers {partition.n_states} states but the MDP has {model.n_states}; "
            "build the decision layer for this environment"
        )
    if partition.n_options == n_total - n_prim:
        adm = np.zeros((partition.n_blocks, n_total), dtype=bool)
        adm[:, n_prim:] = partition.admissible
        partition = partition.with_admissible(adm)
    elif partition.n_options != n_total:
        raise TaskError(
            f"the partition offers {partition.n_options} options; expected {n_total - n_prim} "
            f"(the given options) or {n_total} (primitive actions first, then the options)"
        )
    offers = partition.admissible[partition.labels]
    stranded = ~terminal & (offers & ~model.admissible).any(axis=1)
    if stranded.any():  # the earlier task's absorbing block, on a later task
        codes = np.where(stranded, np.arange(1, partition.n_states + 1), 0)
        split = partition.refine_by(codes)
        adm = split.admissible.copy()
        for s in np.flatnonzero(stranded):
            kept = offers[s] & model.admissible[s]
            adm[split.labels[s]] = kept if kept.any() else model.admissible[s]
        partition = split.with_admissible(adm)
    allowed = block_all(partition.labels, partition.n_blocks,
                        model.admissible | terminal[:, None])
    bad = np.argwhere(partition.admissible & ~allowed)
    if bad.size:
        b, o = bad[0]
        raise TaskError(
            f"block {int(b)} offers option column {int(o)}, which some of its states may not "
            "start; build the partition from the options' initiation sets"
        )
    empty = np.flatnonzero(~partition.admissible.any(axis=1))
    if empty.size:
        raise TaskError(
            f"block {int(empty[0])} offers no option, so no decision can be taken there; use a "
            "partition whose blocks all offer an option"
        )
    return partition


def starting_layer(mdp: FiniteMDP, options: Sequence[Option], partition: Partition | None,
                   settings: HierarchicalSettings, models: Sequence[OptionModel] | None
                   ) -> tuple[Partition, list[Option], SMDPModel, list[Option]]:
    """The layer learning starts on, its columns (primitives first), their model, and the
    reward-state options the mode added (module docstring: the four modes of section 4.3)."""
    A = mdp.n_actions
    options = list(options)
    delta, epsilon = settings.refinement.delta, settings.refinement.partition_epsilon
    extra: list[Option] = []
    if settings.reward_options:  # 4.3.1: the task's reward states become subgoals
        extra = reward_options(mdp)
        if models is not None:
            models = list(models) + option_models(mdp, extra, duration=False)
        options = options + extra
    if partition is None:
        part0, full, smdp = decision_layer(mdp, options, delta=delta, epsilon=epsilon,
                                           models=models)
    else:
        full, smdp = option_set(mdp, options, include_primitives=True, models=models)
        part0 = _with_empty_columns(partition, len(extra))
    part0 = _pad_partition(part0, A, len(full), smdp, mdp.terminal)
    if extra and partition is not None:  # the given layer, offered the reward-state options
        part0 = _offer(part0, np.arange(len(full) - len(extra), len(full)), smdp.admissible)
    if settings.mode == "action-refinement":  # 4.3.2: reward blocks get every primitive
        refiner, prims = refinement_model(mdp, smdp), np.arange(A)
        for s in np.flatnonzero(reward_states(mdp)):  # few reward states, each one block
            b = int(part0.labels[s])
            if not part0.admissible[b, :A].all():
                part0 = refine_block(part0, b, prims, refiner, delta=delta, epsilon=epsilon)
    return part0, full, smdp, extra


# --------------------------------------------------------------------------- the learner


def hierarchical_knowledge(settings: HierarchicalSettings, *, belief: bool = False
                           ) -> Knowledge:
    """What the hierarchical learner reads of the task it learns, by its settings (the
    :mod:`adpart.learning.knowledge` record; the options' and the layer's own come on top).

    Without a ``belief`` it reads the true dynamics in every mode - the exact option models
    refine the layer (eqs. 4.6-4.7) - and the task's rewards and terminals: the reward floor
    ``r_min`` bounds the grounded values and the refinement model's absorbing block is the
    task's terminal set. With one (the learned-model regime) it reads only that model: option
    models on the estimated dynamics, the earlier tasks' step reward as the floor, no terminal
    state until it enters one, and the threshold it is given.
    """
    if belief:
        uses = ["option models on the estimated dynamics for refinement",
                "the earlier tasks' step reward as the reward floor"]
        if settings.refinement.online_phase3:
            uses.append("phase 3 online: the rewards of the pairs tried and the terminal states "
                        "entered, as observed")
        if settings.directed:
            uses.append("R-max on the counts, unknown pairs at the given value ceiling")
        return Knowledge("estimated", "observed", tuple(uses))
    uses = ["option models for refinement", "reward floor r_min", "terminal states"]
    if settings.reward_options:
        uses.append("options to the task's reward states, solved on the true model")
    if settings.testing:
        if settings.test.threshold is None:
            uses.append("threshold L from V*")
        if settings.test_reference != "learned":
            uses.append(f"{settings.test_reference} reference from the option models")
    if settings.directed:
        uses.append("R-max on the counts")
    return Knowledge("true-model", "known", tuple(uses))


def belief_problem(settings: HierarchicalSettings) -> str | None:
    """Why the learner cannot learn on a belief model with ``settings`` (None: it can)."""
    if settings.mode != "inconsistency":
        return (f"mode {settings.mode} reads the task's rewards, which a learner on a belief "
                "model does not know; use mode inconsistency (--mode inconsistency)")
    if settings.directed and settings.exploration.value_ceiling is None:
        return ("R-max exploration (--explore r-max) values an unknown pair at the ceiling of "
                "the task's rewards, which a learner on a belief model does not know: give "
                "--value-ceiling V (the pipeline's learned-model regime gives the ceiling of the "
                "rewards its first task paid), or another --explore")
    if settings.layer_values == "planned":
        return ("planned layer values (--layer-values planned) plan on the counts over the "
                "true model's transition table; on a belief model give --layer-values learned")
    if settings.testing and settings.test_reference != "learned":
        return (f"reference {settings.test_reference} plans on the model's rewards, which on a "
                "belief model hold no goal (on two-rooms it made 1,771 firings, 36 % real, "
                "against 587 and 61 % with the learned reference): give --reference learned")
    return None


def _checked_belief(belief: FiniteMDP, mdp: FiniteMDP, settings: HierarchicalSettings
                    ) -> FiniteMDP:
    """``belief``, if the learner can learn ``mdp`` on it with ``settings``."""
    require_mdp("hierarchical_learning (belief)", belief)
    if (belief.n_states, belief.n_actions) != (mdp.n_states, mdp.n_actions):
        raise TaskError(f"the belief model has {belief.n_states} states and {belief.n_actions} "
                        f"actions; the task has {mdp.n_states} and {mdp.n_actions}")
    problem = belief_problem(settings)
    if problem is not None:
        raise TaskError(problem)
    if settings.testing and settings.test.threshold is None:
        raise TaskError("the default inconsistency threshold reads V* of the task; a learner on "
                        "a belief model needs a given threshold (--threshold L)")
    return belief


def hierarchical_learning(
    mdp: FiniteMDP,
    options: Sequence[Option],
    partition: Partition | None = None,
    settings: HierarchicalSettings | None = None,
    run: Run | None = None,
    models: Sequence[OptionModel] | None = None,
    belief: FiniteMDP | None = None,
) -> HierarchicalResult:
    """Learn ``mdp`` on a decision layer over ``options`` (section 4.3; module docstring).

    Args:
        mdp: the task.
        options: the (subgoal) options of the decision layer.
        partition: the decision layer, over ``options`` (``(B, len(options))`` admissibility) or
            over the primitives then the options; built by :func:`decision_layer` when omitted.
            In the ``reward-variation`` modes a given layer is offered the reward-state options
            (module docstring); without one they build their own.
        settings: the learner's settings (:class:`HierarchicalSettings`: the mode, exploration,
            the inconsistency test and its reference, refinement, the layer's values; every
            field documented there). Default: ``HierarchicalSettings()``.
        run: runs, episodes, seed, schedules (``epsilon`` is the exploration schedule), step
            limit, evaluation, ``q_init`` (default 0, or the lower bound ``r_min / (1 - gamma)``
            with R-max exploration: a block the agent never visited must not look better to
            the greedy policy than those it learned), kernel and progress
            (:class:`~adpart.learning.settings.Run`). Default: ``Run()``.
        models: exact models of ``options`` on ``mdp`` (computed when omitted; with a
            ``belief`` they serve the scoring only).
        belief: the model the learner may read instead of ``mdp``'s (the learned-model regime:
            dynamics estimated from earlier runs' experience, the earlier tasks' step reward, no
            terminal state; :func:`adpart.workflows.experience.belief_model`). Every model the
            learner plans or refines on is then built on it; ``mdp`` is only sampled and scored
            against (inside :func:`~adpart.learning.knowledge.world`). Needs the
            ``inconsistency`` mode (the others read the task's rewards) and a given
            ``threshold`` (the default reads ``V*``).

    Returns:
        A :class:`HierarchicalResult`.
    """
    settings = HierarchicalSettings() if settings is None else settings
    run = Run() if run is None else run
    if not isinstance(settings, HierarchicalSettings):
        raise TaskError(f"settings must be a HierarchicalSettings, got {type(settings).__name__}")
    test, refinement = settings.test, settings.refinement
    require_mdp("hierarchical_learning", mdp)
    K, N, S, H = run.runs, run.episodes, mdp.n_states, run.max_steps_per_episode
    seed = fresh_seed(run.seed)
    kernel_name, step_kernel = kernel_function(run.kernel)
    if refinement.online_phase3 and (belief is None or not settings.directed):
        raise TaskError("phase 3 online (online_phase3, --hier-opt online-phase3=true) splits a "
                        "belief's layer as the task's rewards are observed: it needs the "
                        "learned-model regime (--regime learned-model; the true-model layer was "
                        "built with the task's rewards) and R-max exploration (--explore r-max), "
                        "whose counts tell which states ended an episode")
    known = mdp if belief is None else _checked_belief(belief, mdp, settings)
    part0, full, smdp, extra = starting_layer(known, options, partition, settings,
                                              models if belief is None else None)
    with world():  # the start distribution and V* are the environment's, for scoring
        mu = start_distribution(mdp)
        v_star = optimal_start_value(mdp, mu, run.reference_values)
        # the world's own model of the columns scores the greedy policies
        world_smdp = smdp if belief is None else option_set(
            mdp, full[mdp.n_actions:], include_primitives=True, models=models)[1]
        # each distinct greedy policy solved once, warm-started from the last (issue 40)
        scorer = StartValues(world_smdp, mu, K)
    every_run = np.ones(K, dtype=bool)
    L = (default_threshold(v_star, scale=test.threshold_scale) if test.threshold is None
         else float(test.threshold))
    lower = flat_lower_bound(known, H)
    q0 = run.q_init if run.q_init is not None else lower if settings.directed else 0.0
    check = settings.testing
    reference = ReferenceValues(settings.test_reference, test.split_offered, known, smdp, lower)
    refine = LayerRefiner(refinement.refine, refinement.delta, refinement.partition_epsilon,
                          refinement_model(known, smdp), lower, child_values)
    arrays = InconsistencyArrays(
        threshold=L if check else np.inf, min_visits=test.min_visits,
        prim_opt=np.arange(mdp.n_actions), floor=lower, lcb_z=test.lcb_z,
        flat_explore=settings.flat_explore,
        prim_eps=PRIMITIVE_EXPLORATION[settings.exploration.primitive_exploration] if check
        else 0, r_min=reward_floor(known),
        **(reference.initial(part0) if check else
           {"block_values": None, "state_values": None, "offered_values": None}),
        explore_known=settings.exploration.known_after if settings.directed else 0,
        v_max=settings.exploration.value_ceiling,
    )
    B0 = part0.n_blocks
    with world():  # the simulator of the environment
        st = make_state(
            mdp, full, np.broadcast_to(part0.labels, (K, S)),
            np.broadcast_to(part0.admissible, (K, B0, len(full))), episodes=N, horizon=H,
            alpha=run.alpha, epsilon=run.epsilon, q_init=q0, mu=mu,
            capacity=min(S, max(2 * B0, B0 + 64)), intra=2 if settings.intra_option else 0,
            test=arrays,
        )
    parts = [part0] * K
    events: list[dict[str, int]] = []

    def on_fire(k: int) -> None:  # section 4.3.3: refine run k's layer where the test fired
        parts[k], event = refine.apply(st, k, parts[k], reference)
        events.append(event)

    online = (OnlineSplits(OnlinePhase3(known, full[mdp.n_actions:], refine.model,
                                        refinement.delta, refinement.partition_epsilon),
                           refine, mdp) if refinement.online_phase3 else None)

    def score() -> np.ndarray:
        Qs = lifted_values(settings.layer_values, st, parts, smdp, known, lower)
        policies = greedy_policy(Qs.reshape(K * S, -1)).reshape(K, S)
        with world():
            return scorer(policies, every_run.copy())

    eval_value = drive(st, step_kernel, seed, episodes=N, eval_every=run.eval_every,
                       score=score, progress=run.progress, on_fire=on_fire if check else None,
                       on_episode=None if online is None else  # phase 3 online
                       partial(online.after_episode, st, parts, reference))
    with world():  # an audit of the firings against the task's exact Q*: scoring, not learning
        audit = firing_audit(events, world_smdp, mdp, K,
                             first_actions(full[mdp.n_actions:], S, mdp.n_actions))
    names = tuple(o.name for o in full)
    delta, epsilon = refinement.delta, refinement.partition_epsilon
    parameters: dict[str, object] = {
        "runs": K, "episodes": N, "seed": seed, "mode": settings.mode,
        "delta": float(delta), "epsilon": None if epsilon is None else float(epsilon),
        "threshold": L, "threshold_rule": "given" if test.threshold is not None else
        f"{test.threshold_scale} x |V*(start)|",
        "theorem_4_5_bound": theorem_bound(known, epsilon=epsilon, delta=delta),
        "lcb_z": float(test.lcb_z), "flat_explore": settings.flat_explore,
        "test_reference": reference.name, "refine": refinement.refine,
        "primitive_exploration": settings.exploration.primitive_exploration if check
        else "never",
        "exploration": settings.exploration_rule,
        "known_after": settings.exploration.known_after if settings.directed else None,
        "layer_values": settings.layer_values, "split_offered": test.split_offered,
        "flat_lower_bound": lower, "min_visits": test.min_visits,
        "alpha": run.alpha.to_dict(), "epsilon_greedy": run.epsilon.to_dict(),
        "max_steps_per_episode": H, "eval_every": run.eval_every, "q_init": float(q0),
        "kernel": kernel_name, "intra_option": settings.intra_option, "options": list(names),
        "extra_subgoals": [o.subgoal for o in extra], "initial_blocks": B0,
        "reference": "given" if run.reference_values is not None else "solved",
        "knowledge": hierarchical_knowledge(settings, belief=belief is not None).to_dict(),
        "belief": None if belief is None else belief.name,
        "online_phase3": refinement.online_phase3,
        "phase3_events": [] if online is None else online.events,
    }
    curve = LearningCurve.from_matrices(
        steps=st.out_steps, decisions=st.out_dec, returns=st.out_ret,
        discounted_returns=st.out_dret, eval_value=eval_value, value_gap=v_star - eval_value,
        metadata={"learner": "hierarchical", "mdp": mdp.name, "mdp_hash": mdp.content_hash,
                  "gamma": mdp.gamma, "v_star_start": v_star, **parameters,
                  "final_blocks": st.out_blocks[:, -1].tolist(),
                  "firings": np.bincount([e["run"] for e in events], minlength=K).tolist(),
                  "phase3_blocks": [0] * K if online is None else online.blocks_added(K),
                  "real_firings": audit.real.tolist(), "tied_firings": audit.ties.tolist(),
                  "own_step_ties": audit.own_step.tolist()},
    )
    grounded = st.Ql.copy() if st.Ql.shape[1] == S else None  # a placeholder when not testing
    return HierarchicalResult(
        Q=lifted_values(settings.layer_values, st, parts, smdp, known, lower),
        block_Q=[st.Q[k, :parts[k].n_blocks].copy() for k in range(K)],
        partitions=parts, Q_flat=st.Qf.copy(), Q_grounded=grounded,
        curve=curve, blocks=st.out_blocks.copy(),
        refinements=events, seed=seed, v_star_start=v_star, option_names=names,
        parameters=parameters,
    )
