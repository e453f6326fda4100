"""The decision layer the hierarchical learner starts from, and how a firing refines it.

* :func:`build_decision_layer` / :func:`decision_layer`: the multi-phase partition (section
  4.2.1.2) over the subgoal options for the learner's columns (the primitive actions first,
  offered nowhere; then the options), on the new task's model.
* :func:`refine_block`: one block refined for an added action (section 4.3.3, eqs. 4.6-4.7),
  for all its states or, with ``at``, for the state whose evidence fired
  (:mod:`adpart.learning.hierarchical` says why the second is its default);
  :func:`refinement_model` gives it the rewards the layer was split by.
* :func:`offered_values`: the best the layer's option sets achieve from each state, the
  reference of the ``offered`` inconsistency test.
* :func:`reward_states`, :func:`reward_level`, :func:`reward_floor` and :func:`reward_options`:
  the states "with a high reward" of section 4.3.1, the level they exceed, ``r_min``, and the
  options to them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from adpart.errors import ModelError
from adpart.learning.curves import start_distribution
from adpart.learning.smdp_q import option_set
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.mdp.solvers import solve
from adpart.options.models import OptionModel
from adpart.options.option import Option
from adpart.options.subgoal_options import subgoal_option
from adpart.partition import DEFAULT_ATOL
from adpart.partition.layer import (
    decision_rewards,
    reachable_states,
    resolve_baseline,
    step_baseline,
)
from adpart.partition.multiphase import MultiPhasePartitioner, PhaseResult
from adpart.partition.partition import (
    Partition,
    block_all,
    canonical_labels,
    row_codes,
)
from adpart.partition.refine import delta_refine_rows, regroup

__all__ = [
    "DecisionLayer",
    "build_decision_layer",
    "decision_layer",
    "refine_block",
    "refinement_model",
    "reward_floor",
    "reward_states",
]


def reward_floor(mdp: FiniteMDP) -> float:
    """``r_min``: the smallest reward of a live admissible pair (section 4.3.1; 0 if none), as
    :func:`adpart.partition.layer.step_baseline` with ``rule="min"`` takes it."""
    try:
        return step_baseline(mdp.R, mdp.admissible, mdp.terminal, rule="min")
    except ModelError:  # no admissible non-terminal pair
        return 0.0


def reward_level(mdp: FiniteMDP) -> float:
    """The step reward above which a pair counts as rewarding (section 4.3.1).

    The largest reward that at least half of the live (non-terminal) states pay for some
    admissible action. Section 4.3.1 takes ``r_min``, on tasks whose every step pays the same,
    where the two agree. Where some actions pay a little less (two-rooms' diagonal moves at -1.2
    beside -1) or a penalty (Taxi's -10 for an illegal pick-up), every state has a pair above
    ``r_min``, and the rule would make every state a subgoal; the rewards only a few states pay
    (a goal) stay above this level. Where no reward is paid by half of the live states (every
    state pays its own), the level is section 4.3.1's ``r_min``, the smallest reward.
    """
    live = mdp.admissible & ~mdp.terminal[:, None]
    s, _ = np.nonzero(live)
    values, inverse = np.unique(mdp.R[live], return_inverse=True)
    pairs = np.unique(inverse * mdp.n_states + s)  # each (value, state) once
    states_paying = np.bincount(pairs // mdp.n_states, minlength=values.size)
    n_live = np.count_nonzero(live.any(axis=1))
    common = np.flatnonzero(2 * states_paying >= n_live)
    return float(values[common[-1]] if common.size else values[0])


def reward_states(mdp: FiniteMDP, *, arrivals: bool = False) -> np.ndarray:
    """``(S,)`` bool: non-terminal states with some admissible ``R(s, a)`` above
    :func:`reward_level` (section 4.3.1's "states with a high reward").

    With ``arrivals=True`` also the terminal states such a rewarding pair can arrive in: adpart's
    domains pay a goal's reward on *arrival* in a terminal goal (the seed pays it on leaving the
    goal), so there the goal itself is the state "with a high reward" an option must capture.
    """
    live = mdp.admissible & ~mdp.terminal[:, None]
    if not live.any():
        return np.zeros(mdp.n_states, dtype=bool)
    rewarding = live & (mdp.R > reward_level(mdp))
    found = np.any(rewarding, axis=1)
    if arrivals and rewarding.any():
        s, a = np.nonzero(rewarding)
        reached = np.unique(mdp.P[a * mdp.n_states + s].indices)
        found[reached[mdp.terminal[reached]]] = True
    return found


def reward_options(mdp: FiniteMDP) -> list[Option]:
    """Section 4.3.1's extra subgoal options: one to each of :func:`reward_states` (with
    arrivals) that the task can reach from its start states, startable from every state that can
    reach it, named ``reward-S``. A reward no episode can collect needs no option (fickle Taxi's
    16 extra states pay a drop-off reward but no other state leads to them)."""
    reachable = reachable_states(mdp.as_smdp(), start_distribution(mdp))
    goals = np.flatnonzero(reward_states(mdp, arrivals=True) & reachable)
    return [subgoal_option(mdp, int(g), initiation="reachable", name=f"reward-{int(g)}")
            for g in goals]


@dataclass(frozen=True, eq=False)
class DecisionLayer:
    """What :func:`build_decision_layer` returns.

    Attributes:
        partition: every state's block, over the learner's columns (primitives first): the
            decision layer's blocks, the task's terminal states as one block, and the states the
            task cannot reach as one block per pattern of admissible options.
        options: the learner's columns (the primitive one-step options, then ``options``).
        model: their stacked models on the task's MDP.
        phases: the :class:`~adpart.partition.multiphase.PhaseResult` (masks, counts, seconds).
    """

    partition: Partition
    options: list[Option]
    model: SMDPModel
    phases: PhaseResult

    @property
    def unreachable(self) -> np.ndarray | None:
        """``(S,)`` the non-terminal states the task cannot reach from its start states."""
        return self.phases.unreachable

    def counts(self) -> dict[str, object]:
        """Blocks per phase: reachable (the decision layer), terminal and unreachable."""
        return self.phases.layer_counts()


def build_decision_layer(
    mdp: FiniteMDP, options: Sequence[Option], *, delta: float,
    epsilon: float | None, models: Sequence[OptionModel] | None = None,
    reward_baseline: str | float | None = "mode",
) -> DecisionLayer:
    """The multi-phase partition (section 4.2.1.2) over ``options`` for the learner's columns.

    Phase 1 starts each option from {beta = 1, rest of I, outside I}; phase 2 intersects and
    refines for all options; phase 3 (when ``epsilon`` is not None) splits by the options'
    rewards within ``epsilon``. Primitive actions are columns ``0..A-1`` of the result but offered
    nowhere. Every phase runs on ``mdp``'s model (:mod:`adpart.partition.layer`): its terminal
    states are one absorbing block, and the states it cannot reach from its start distribution
    (with any primitive action, since refinement may offer any of them) are left out. They form
    one block per pattern of admissible options, which the learner never visits; such a block
    that no option may start offers the primitive actions, so every block offers a column.
    Phase 3 compares the rewards beyond the constant step reward
    ``reward_baseline`` (``"mode"``: the step reward most pairs pay; ``"min"``: the smallest,
    section 4.3.1; ``"none"``: ``R`` itself; or a number), as
    :func:`adpart.partition.layer.decision_rewards` derives.

    ``models`` must be the options' models on ``mdp`` (the new task's), not another task's.
    """
    full, smdp = option_set(mdp, options, include_primitives=True, models=models)
    A = mdp.n_actions
    if len(full) == A:
        raise ModelError("a decision layer needs at least one option besides the primitives")
    termination = np.zeros(smdp.R.shape, dtype=bool)
    termination[:, A:] = np.stack([o.beta >= 1.0 for o in full[A:]], axis=1)
    baseline = resolve_baseline(reward_baseline, mdp.R, mdp.admissible, mdp.terminal)
    partitioner = MultiPhasePartitioner(smdp, termination, delta=delta, terminal=mdp.terminal)
    result = partitioner.run(np.arange(A, len(full)), epsilon=epsilon,
                             start=start_distribution(mdp), through=mdp,
                             reward_baseline=baseline, gamma=mdp.gamma)
    partition = result.final
    idle = ~partition.admissible.any(axis=1)
    if idle.any():  # unreachable states no option may start: offer the primitive actions
        adm = partition.admissible.copy()
        prims = block_all(partition.labels, partition.n_blocks, smdp.admissible[:, :A])
        adm[idle, :A] = prims[idle]
        partition = partition.with_admissible(adm)
    return DecisionLayer(partition, full, smdp, result)


def decision_layer(
    mdp: FiniteMDP, options: Sequence[Option], *, delta: float,
    epsilon: float | None, models: Sequence[OptionModel] | None = None,
    reward_baseline: str | float | None = "mode",
) -> tuple[Partition, list[Option], SMDPModel]:
    """:func:`build_decision_layer` as ``(partition, learner options, stacked model)``."""
    layer = build_decision_layer(mdp, options, delta=delta, epsilon=epsilon, models=models,
                                 reward_baseline=reward_baseline)
    return layer.partition, layer.options, layer.model


def refine_block(
    partition: Partition, block: int, new_options: Sequence[int], model: SMDPModel, *,
    delta: float, epsilon: float | None, atol: float = DEFAULT_ATOL, at: int | None = None,
) -> Partition:
    """Add ``new_options`` to ``block`` and refine that block alone for its option sets.

    The block is split by where the new options may start, then by the rewards of its options
    within ``epsilon`` (eq. 4.7) and to delta-stability (eq. 4.6) against the current blocks,
    to a fixpoint (section 4.3.3). Other blocks are unchanged; children inherit the block's
    options, except a new option in a child where some state may not start it.

    With ``at`` (a member state of ``block``) the new options join the option set of ``at``
    alone, the state whose evidence fired (the ``state`` rule of the module docstring): ``at``
    becomes a block of its own offering them, and the rest of ``block`` is refined to stability
    for its unchanged set. An option ``block`` already offers stays offered in all of it, so with
    options it already offers ``at`` is split off with the block's set (the test's reply to a
    state its block's policy fails, :func:`~adpart.learning.hierarchical.hierarchical_learning`).

    Every block of ``partition`` must offer only columns all its states may start (every layer
    the learner builds or accepts does); only the refined block's children are checked.
    """
    S = partition.n_states
    new_options = list(new_options)
    added = [o for o in new_options if not partition.admissible[block, o]]
    labels = partition.labels
    adm_rows = partition.admissible.copy()
    adm_rows[block, new_options] = True
    inside = np.flatnonzero(labels == block)  # only the block's states are split
    if at is not None and labels[at] != block:
        raise ModelError(f"state {at} is not in block {block}")
    sel = np.flatnonzero(adm_rows[block])
    adm_in = model.admissible[inside][:, sel]  # (members, offered columns)
    if at is not None:
        adm_in[:, np.searchsorted(sel, added)] &= (inside == at)[:, None]
    # the block's split by where its columns may start (and ``at`` from the rest), then by their
    # rewards (eq. 4.7), on the members alone (the groups reward_split forms on the whole labelling)
    keys = adm_in[:, ~adm_in.all(axis=0)]  # columns every member may start split none
    local = row_codes(keys if at is None else np.column_stack([keys, inside == at]))
    if epsilon is not None:
        every = np.arange(inside.size)
        n_local = int(local.max()) + 1
        values = np.where(adm_in, model.R[inside][:, sel], 0.0)
        # a column whose rewards span at most epsilon over the whole block splits no group of it
        for j in np.flatnonzero(values.max(axis=0) - values.min(axis=0) > epsilon + atol):
            local, n_local, _ = regroup(local, n_local, every, values[:, j], epsilon + atol)
    work = labels.copy()
    work[inside] = partition.n_blocks + local
    work, _ = delta_refine_rows(canonical_labels(work), model, sel, inside, adm_in, delta, atol)
    new = canonical_labels(work)  # refines the partition: only the block was split
    n_new = int(new.max()) + 1
    if n_new > S:  # pragma: no cover - a partition never has more blocks than states
        raise ModelError("refinement produced more blocks than states")
    parent = np.empty(n_new, dtype=np.int64)
    parent[new] = labels
    # the other blocks are unchanged, and offer only columns all their states may start (every
    # layer the learner builds or accepts does): only the block's children need the check
    # (block_all is vacuously true on the blocks with no member in the block; the children's
    # columns outside ``sel`` are not offered, whatever they allow)
    allowed = np.ones((n_new, model.admissible.shape[1]), dtype=bool)
    allowed[:, sel] = block_all(new[inside], n_new, adm_in)
    if at is not None:  # the other children of the block keep its former option set
        others = (parent == block) & (np.arange(n_new) != new[at])
        allowed[np.ix_(others, added)] = False
    return Partition.from_canonical(new, adm_rows[parent] & allowed)  # canonical_labels made it


def offered_values(partition: Partition, smdp: SMDPModel, terminal: np.ndarray,
                   floor: float) -> np.ndarray:
    """``(S,)`` the best value the layer's options achieve from each state, choosing per state.

    The optimum of the SMDP whose state ``s`` may choose only the columns its block offers
    (``admissible[labels[s]]``), solved exactly over the columns' models (eqs. 3.1-3.2): what the
    layer can do from ``s`` at best, with no block average in it. A non-terminal state whose
    block offers nothing it may start gets ``floor`` (the agent has no decision there), a terminal
    one 0.
    """
    adm = smdp.admissible & partition.admissible[partition.labels]
    R, F = smdp.R, smdp.F
    stuck = np.flatnonzero(~adm.any(axis=1))
    if stuck.size:  # one column whose whole value is the floor makes their Bellman rows defined
        adm = adm.copy()
        adm[stuck, 0] = True
        R = R.copy()
        R[stuck, 0] = np.where(terminal[stuck], 0.0, floor)
        keep = np.ones(F.shape[0])
        keep[stuck] = 0.0  # rows 0*S + s of column 0
        F = sp.csr_array(sp.diags_array(keep) @ F)
    model = SMDPModel(R=R, F=F, admissible=adm)
    return solve(model, 1e-8).V


def refinement_model(mdp: FiniteMDP, smdp: SMDPModel,
                     reward_baseline: str | float | None = "mode") -> SMDPModel:
    """``smdp`` with the decision rewards ``R~`` that phase 3 split by (eq. 4.7 on the rewards
    beyond the constant step reward, :func:`adpart.partition.layer.decision_rewards`), so that a
    refinement during learning splits by the same criterion as the layer was built with."""
    baseline = resolve_baseline(reward_baseline, mdp.R, mdp.admissible, mdp.terminal)
    if baseline is None or not 0.0 < mdp.gamma < 1.0:
        return smdp
    rewards = decision_rewards(smdp, mdp.gamma, baseline, mdp.terminal)
    return SMDPModel(R=rewards, F=smdp.F, admissible=smdp.admissible)
