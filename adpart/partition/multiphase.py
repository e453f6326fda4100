"""Multi-phase, action-dependent partitioning of the state space (section 4.2.1.2).

* **Phase 1** (per option, reward independent, computed once when the option is acquired): start
  from {termination states (beta = 1), the rest of the initiation set I_o, the states outside I_o}
  and refine to delta-stability for that option alone.
* **Phase 2** (per option *set*, still reward independent): intersect the selected options' phase-1
  partitions - a block is the vector of per-option block indices (the cross product Phi of section
  4.2.1.2, empty intersections dropped) - and refine to delta-stability for all of them.
* **Phase 3** (per task): split by the task's rewards within epsilon (eq. 4.7) and refine again.

Every phase runs on the *new* task's model (DESIGN.md; :mod:`adpart.partition.layer`): given the
task's ``terminal`` states, they start as one absorbing block in every phase and stay one; given
its ``start`` distribution, the states no policy over the selected options can reach are left out
of phases 2-3 (one block per admissibility pattern, reported apart); given a ``reward_baseline``,
phase 3 applies eq. 4.7 to the rewards beyond that constant step reward (the decision rewards of
:func:`adpart.partition.layer.decision_rewards`), not to ``R`` itself. Without them the phases run
as section 4.2.1.2 prints them, on the model as given.

:class:`MultiPhasePartitioner` caches phase-1 partitions per option, so changing the option set
re-runs phases 2-3 only. Storing the phases in the knowledge base is the caller's business (numeric
cores know nothing of the store).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from adpart.errors import ModelError
from adpart.mdp.model import SMDPModel
from adpart.partition._validate import (
    DEFAULT_ATOL,
    as_model,
    check_delta,
    check_epsilon,
    check_rewards,
    select_options,
)
from adpart.partition.layer import (
    as_mask,
    decision_rewards,
    decision_view,
    layer_counts,
    reachable_states,
    terminal_columns,
    zero_rows,
)
from adpart.partition.partition import Partition, canonical_labels, combine_labels
from adpart.partition.refine import refine

_mask = as_mask


@runtime_checkable
class Criterion(Protocol):
    """What refines a partition in each phase (a ``partition-criterion`` plugin's contract).

    ``refine(partition, model, *, options, phase, require_admissible, rewards=None)`` returns a
    refinement of ``partition`` on ``model`` (an :class:`SMDPModel`) for the option columns
    ``options``; ``phase`` is 1, 2 or 3, and phase 3 also passes the task's ``rewards`` (``(S,
    O)``, :meth:`MultiPhasePartitioner.decision_rewards`). ``require_admissible=False``: some
    states (left out of the layer) offer no option.
    """

    def refine(self, partition: Partition, model: SMDPModel, **context: object) -> Partition:
        ...


def initial_termination_labels(termination: np.ndarray, initiation: np.ndarray,
                               terminal: np.ndarray | None = None) -> np.ndarray:
    """Phase-1 initial blocks: 0 = termination states, 1 = rest of I_o, 2 = outside I_o.

    With the task's ``terminal`` mask, its states form block 3, whatever the option does there.
    """
    labels = np.where(termination, 0, np.where(initiation, 1, 2)).astype(np.int64)
    if terminal is not None:
        labels = np.where(terminal, 3, labels)
    return labels


def _one_block(labels: np.ndarray, states: np.ndarray | None) -> np.ndarray:
    """``labels`` with ``states`` moved into one new block (canonical)."""
    if states is None or not states.any():
        return labels
    return canonical_labels(np.where(states, int(labels.max()) + 1, labels))


def _terminal_model(smdp: SMDPModel, terminal: np.ndarray | None) -> SMDPModel:
    """Terminal states absorbing with zero reward, one admissibility pattern (module docstring)."""
    if terminal is None or not terminal.any():
        return smdp
    return zero_rows(smdp, terminal, admissible_row=terminal_columns(smdp.admissible, terminal))


def phase1(
    model: SMDPModel | object,
    option: int,
    termination: object,
    initiation: object | None = None,
    *,
    delta: float,
    atol: float = DEFAULT_ATOL,
    terminal: object | None = None,
) -> Partition:
    """Phase 1 for one option: termination / initiation blocks refined for that option alone.

    Args:
        model: the stacked option models (:class:`SMDPModel`), the new task's.
        option: the option's index in ``model``.
        termination: ``(S,)`` bool, states where the option terminates (beta = 1).
        initiation: ``(S,)`` bool, its initiation set (default: ``model.admissible[:, option]``;
            if given it must agree with it outside ``terminal``).
        delta: threshold of eq. 4.6.
        terminal: ``(S,)`` bool, the task's terminal states: one absorbing block (their rows are
            taken as zero). None: no terminal block.
    """
    smdp = as_model(model)
    S = smdp.n_states
    term_states = None if terminal is None else _mask(terminal, S, "terminal mask")
    return _phase1(_terminal_model(smdp, term_states), option, termination, initiation,
                   term_states, delta, atol)


def _phase1(smdp: SMDPModel, option: int, termination: object, initiation: object | None,
            terminal: np.ndarray | None, delta: float, atol: float,
            criterion: Criterion | None = None) -> Partition:
    S = smdp.n_states
    o = int(select_options(smdp, [option])[0])
    term = _mask(termination, S, f"termination mask of option {o}")
    init = smdp.admissible[:, o] if initiation is None else _mask(
        initiation, S, f"initiation mask of option {o}")
    differ = init != smdp.admissible[:, o]
    if terminal is not None:
        differ &= ~terminal
    if differ.any():
        raise ModelError(
            f"the initiation mask of option {o} disagrees with the model's admissible column "
            f"(first at state {int(np.flatnonzero(differ)[0])}); build the "
            "SMDPModel with admissible[:, o] = the option's initiation set"
        )
    init = smdp.admissible[:, o]
    start = Partition.from_labels(initial_termination_labels(term, init, terminal),
                                  smdp.admissible)
    if criterion is not None:
        return criterion.refine(start, smdp, options=[o], phase=1, require_admissible=False)
    return refine(start, smdp, options=[o], delta=delta, epsilon=None, atol=atol,
                  require_admissible=False)


def phase2(
    model: SMDPModel | object,
    phase1_partitions: Mapping[int, Partition],
    options: Sequence[int],
    *,
    delta: float,
    atol: float = DEFAULT_ATOL,
    unreachable: object | None = None,
) -> Partition:
    """Phase 2: intersect the selected options' phase-1 partitions, refine for all of them.

    ``unreachable`` (``(S,)`` bool, see :func:`adpart.partition.layer.reachable_states`): states
    left out of the refinement (their rows taken as zero), kept in one block per admissibility
    pattern.
    """
    smdp = as_model(model)
    unr = None if unreachable is None else _mask(unreachable, smdp.n_states, "unreachable mask")
    if unr is not None and unr.any():
        smdp = zero_rows(smdp, unr)
    return _phase2(smdp, phase1_partitions, options, delta, atol, unr)


def _phase2(smdp: SMDPModel, phase1_partitions: Mapping[int, Partition], options: Sequence[int],
            delta: float, atol: float, unreachable: np.ndarray | None,
            criterion: Criterion | None = None) -> Partition:
    sel = select_options(smdp, options)
    missing = [int(o) for o in sel if int(o) not in phase1_partitions]
    if missing:
        raise ModelError(
            f"no phase-1 partition for option(s) {missing}; run phase1 for every selected option"
        )
    labels = combine_labels(*(phase1_partitions[int(o)].labels for o in sel))
    start = Partition.from_labels(_one_block(labels, unreachable), smdp.admissible)
    if unreachable is not None:
        _require_cover_reachable(smdp, sel, unreachable)
    if criterion is not None:
        return criterion.refine(start, smdp, options=sel, phase=2,
                                require_admissible=unreachable is None)
    return refine(start, smdp, options=sel, delta=delta, epsilon=None, atol=atol,
                  require_admissible=unreachable is None)


def _require_cover_reachable(smdp: SMDPModel, sel: np.ndarray, unreachable: np.ndarray) -> None:
    """Every reachable state needs a selected admissible option (unreachable ones need not)."""
    orphan = np.flatnonzero(~smdp.admissible[:, sel].any(axis=1) & ~unreachable)
    if orphan.size:
        raise ModelError(
            f"the option set {sel.tolist()} leaves {orphan.size} reachable state(s) with no "
            f"admissible option (first: state {int(orphan[0])}); add an option whose initiation "
            "set covers them, or the primitive actions"
        )


def phase3(
    model: SMDPModel | object,
    partition: Partition,
    options: Sequence[int],
    *,
    epsilon: float,
    delta: float,
    rewards: np.ndarray | None = None,
    atol: float = DEFAULT_ATOL,
    require_admissible: bool = True,
) -> Partition:
    """Phase 3: split by the task's rewards within epsilon (eq. 4.7), refine to delta-stability.

    ``require_admissible=False`` allows states with no admissible option (unreachable states
    kept apart by phase 2).
    """
    if epsilon is None:
        raise ModelError("phase 3 needs the task's epsilon (a number >= 0)")
    return refine(partition, model, options=options, delta=delta, epsilon=epsilon,
                  rewards=rewards, atol=atol, require_admissible=require_admissible)


@dataclass
class PhaseResult:
    """The partitions of one multi-phase run, with block counts and seconds per phase.

    Attributes:
        phase1, phase2, phase3: the partitions (``phase3`` None without epsilon).
        seconds: wall time per phase (``reach``: the reachability search).
        terminal: ``(S,)`` the task's terminal states (None when not given).
        unreachable: ``(S,)`` the non-terminal states no policy over the options reaches from the
            start states (None when no start was given).
        rewards: ``(S, O)`` the rewards phase 3 compared (eq. 4.7), None without phase 3.
        baseline: the constant step reward taken out of them (None: the rewards as given).
    """

    phase1: dict[int, Partition]
    phase2: Partition
    phase3: Partition | None
    seconds: dict[str, float] = field(default_factory=dict)
    terminal: np.ndarray | None = None
    unreachable: np.ndarray | None = None
    rewards: np.ndarray | None = None
    baseline: float | None = None

    @property
    def final(self) -> Partition:
        """The last partition over all states (decision layer, terminal and unreachable blocks)."""
        return self.phase3 if self.phase3 is not None else self.phase2

    @property
    def decision_view(self) -> Partition:
        """``final`` with the unreachable blocks offering nothing (what the checker audits)."""
        return decision_view(self.final, self.unreachable)

    def block_counts(self) -> dict[str, object]:
        return {
            "phase1": {o: p.n_blocks for o, p in self.phase1.items()},
            "phase2": self.phase2.n_blocks,
            "phase3": None if self.phase3 is None else self.phase3.n_blocks,
        }

    def layer_counts(self) -> dict[str, object]:
        """Blocks per phase split into reachable (decision layer), terminal and unreachable."""
        sizes = [p.n_blocks for p in self.phase1.values()]
        return {
            "phase1": {"blocks_min": min(sizes), "blocks_max": max(sizes)},
            "phase2": layer_counts(self.phase2, self.terminal, self.unreachable),
            "phase3": None if self.phase3 is None
            else layer_counts(self.phase3, self.terminal, self.unreachable),
        }


class MultiPhasePartitioner:
    """Runs phases 1-3 over one set of option models, caching phase 1 per option.

    Args:
        model: the stacked models of all candidate options, computed on the new task's MDP.
        termination: ``(S, O)`` bool, ``termination[s, o]`` = option ``o`` terminates in ``s``
            (beta = 1). For primitive actions pass the terminal mask broadcast, or all False.
        delta: threshold of eq. 4.6 used in every phase.
        terminal: ``(S,)`` bool, the task's terminal states: one absorbing block with zero rows
            in every phase (module docstring). None: the model as given, no terminal block.
        criterion: a partition criterion (:class:`Criterion`, e.g. a ``partition-criterion``
            plugin) that refines every phase in place of delta-stability with ``delta`` and
            eq. 4.7 with ``epsilon``; None: those built-in rules.
    """

    def __init__(self, model: SMDPModel | object, termination: object, *, delta: float,
                 atol: float = DEFAULT_ATOL, terminal: object | None = None,
                 criterion: Criterion | None = None) -> None:
        self.model = as_model(model)
        term = np.asarray(termination)
        if term.shape != self.model.R.shape or term.dtype != bool:
            raise ModelError(
                f"termination must be a boolean (S, O) = {self.model.R.shape} mask; got dtype "
                f"{term.dtype} and shape {term.shape}"
            )
        self.termination = term
        self.delta = check_delta(delta)
        self.atol = atol
        self.criterion = criterion
        self.terminal = None if terminal is None else _mask(
            terminal, self.model.n_states, "terminal mask")
        #: the model the phases refine on: terminal rows zero, every column offered there
        self.layer_model = _terminal_model(self.model, self.terminal)
        self._phase1: dict[int, Partition] = {}
        self.phase1_runs = 0

    def phase1(self, option: int) -> Partition:
        """The cached phase-1 partition of one option (computed on first use)."""
        o = int(select_options(self.model, [option])[0])
        if o not in self._phase1:
            self._phase1[o] = _phase1(self.layer_model, o, self.termination[:, o], None,
                                      self.terminal, self.delta, self.atol, self.criterion)
            self.phase1_runs += 1
        return self._phase1[o]

    def add_phase1(self, option: int, partition: Partition) -> None:
        """Use a stored phase-1 partition of ``option`` (it must come from the same model)."""
        o = int(select_options(self.model, [option])[0])
        if not isinstance(partition, Partition) or partition.n_states != self.model.n_states:
            raise ModelError(f"the phase-1 partition of option {o} must be a Partition of "
                             f"{self.model.n_states} states")
        self._phase1[o] = partition

    def unreachable(self, options: Sequence[int], start: object, *,
                    through: SMDPModel | object | None = None) -> np.ndarray:
        """``(S,)`` non-terminal states no policy reaches from ``start``.

        Args:
            options: the layer's columns; without ``through`` their support is the graph.
            start: ``(S,)`` start distribution or mask.
            through: a model all of whose columns count, e.g. the task's MDP (its primitive
                actions): with inconsistency refinement any block may come to offer any
                primitive action, so what a learner can reach is what the task can reach.
        """
        sel = select_options(self.model, options)
        if through is None:
            reach = reachable_states(self.layer_model, start, sel)
        else:
            other = as_model(through)
            if other.n_states != self.model.n_states:
                raise ModelError(f"the reachability model has {other.n_states} states; the "
                                 f"options' model has {self.model.n_states}")
            reach = reachable_states(other, start)
        return ~reach if self.terminal is None else ~reach & ~self.terminal

    def _model_without(self, unreachable: np.ndarray | None) -> SMDPModel:
        """The layer model with the rows of ``unreachable`` zeroed (one-entry cache)."""
        if unreachable is None or not unreachable.any():
            return self.layer_model
        cached = getattr(self, "_cut", None)
        if cached is not None and np.array_equal(cached[0], unreachable):
            return cached[1]
        model = zero_rows(self.layer_model, unreachable)
        self._cut = (unreachable.copy(), model)
        return model

    def phase2(self, options: Sequence[int], *, unreachable: np.ndarray | None = None
               ) -> Partition:
        """Phase 2 for ``options`` from the cached phase-1 partitions (``unreachable``: left out,
        see :meth:`unreachable`)."""
        sel = select_options(self.model, options)
        unr = None if unreachable is None else _mask(unreachable, self.model.n_states,
                                                     "unreachable mask")
        p1 = {int(o): self.phase1(int(o)) for o in sel}
        return _phase2(self._model_without(unr), p1, sel, self.delta, self.atol, unr,
                       self.criterion)

    def decision_rewards(self, *, rewards: np.ndarray | None = None,
                         unreachable: np.ndarray | None = None,
                         reward_baseline: float | None = None,
                         gamma: float | None = None) -> np.ndarray:
        """``(S, O)`` the rewards phase 3 compares: beyond ``reward_baseline`` per step (when
        given), zero at terminal and unreachable states."""
        model = self._model_without(unreachable)
        R = model.R if rewards is None else check_rewards(rewards, model)
        if reward_baseline is not None:
            if gamma is None:
                raise ModelError("reward_baseline needs the task's gamma (gamma=mdp.gamma)")
            R = decision_rewards(SMDPModel(R=R, F=model.F, admissible=model.admissible),
                                 gamma, reward_baseline)
        zero = np.zeros(model.n_states, dtype=bool)
        if self.terminal is not None:
            zero |= self.terminal
        if unreachable is not None:
            zero |= unreachable
        return np.where(zero[:, None], 0.0, R) if zero.any() else R

    def phase3(self, partition: Partition, options: Sequence[int], *, epsilon: float,
               rewards: np.ndarray, unreachable: np.ndarray | None = None) -> Partition:
        """Phase 3 on the layer model: split ``partition`` by ``rewards`` (from
        :meth:`decision_rewards`) within ``epsilon``, refine again (with :attr:`criterion`, that
        criterion given the rewards)."""
        if self.criterion is not None:
            return self.criterion.refine(partition, self._model_without(unreachable),
                                         options=options, phase=3, rewards=rewards,
                                         require_admissible=unreachable is None)
        return phase3(self._model_without(unreachable), partition, options, epsilon=epsilon,
                      delta=self.delta, rewards=rewards, atol=self.atol,
                      require_admissible=unreachable is None)

    def run(self, options: Sequence[int], *, epsilon: float | None = None,
            rewards: np.ndarray | None = None, start: object | None = None,
            through: SMDPModel | object | None = None, reward_baseline: float | None = None,
            gamma: float | None = None) -> PhaseResult:
        """Phases 1 (cached), 2 and, when ``epsilon`` is given, 3 for an option set.

        Args:
            options: the selected columns (the layer's options).
            epsilon: eq. 4.7 threshold; None stops after phase 2.
            rewards: ``(S, O)`` task rewards (default: the model's ``R``).
            start: ``(S,)`` the task's start distribution (or bool mask). Given, the states no
                policy reaches from it are left out of phases 2-3 (one block per admissibility
                pattern); None keeps every state in.
            through: the model whose columns define reachability (:meth:`unreachable`; default
                the selected options).
            reward_baseline: the task's constant step reward ``c``: phase 3 compares
                ``R - c (1 - sum F) / (1 - gamma)``
                (:func:`adpart.partition.layer.decision_rewards`); None compares the rewards as
                given.
            gamma: the task's discount, needed with ``reward_baseline``.
        """
        sel = select_options(self.model, options)
        eps = check_epsilon(epsilon)
        if reward_baseline is not None and gamma is None:
            raise ModelError("reward_baseline needs the task's gamma (gamma=mdp.gamma)")
        seconds: dict[str, float] = {}
        t0 = time.perf_counter()
        p1 = {int(o): self.phase1(int(o)) for o in sel}
        t1 = time.perf_counter()
        unreachable = None if start is None else self.unreachable(sel, start, through=through)
        t2 = time.perf_counter()
        p2 = self.phase2(sel, unreachable=unreachable)
        t3 = time.perf_counter()
        p3, R = None, None
        if eps is not None:
            R = self.decision_rewards(rewards=rewards, unreachable=unreachable,
                                      reward_baseline=reward_baseline, gamma=gamma)
            p3 = self.phase3(p2, sel, epsilon=eps, rewards=R, unreachable=unreachable)
        t4 = time.perf_counter()
        seconds.update(phase1=t1 - t0, phase2=t3 - t2, phase3=t4 - t3)
        if start is not None:
            seconds["reach"] = t2 - t1
        return PhaseResult(p1, p2, p3, seconds, terminal=self.terminal, unreachable=unreachable,
                           rewards=R, baseline=reward_baseline)
