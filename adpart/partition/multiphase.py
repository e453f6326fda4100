"""Multi-phase, action-dependent partitioning of the state space (section 4.2.1.2).

* **Phase 1** (per option, reward independent, computed once when the option is acquired): start
  from {termination states (beta = 1), the rest of the initiation set I_o, the states outside I_o}
  and refine to delta-stability for that option alone.
* **Phase 2** (per option *set*, still reward independent): intersect the selected options' phase-1
  partitions - a block is the vector of per-option block indices (the cross product Phi of section
  4.2.1.2, empty intersections dropped) - and refine to delta-stability for all of them.
* **Phase 3** (per task): split by the task's rewards within epsilon (eq. 4.7) and refine again.

:class:`MultiPhasePartitioner` caches phase-1 partitions per option, so changing the option set
re-runs phases 2-3 only. Storing the phases in the knowledge base is the caller's business (numeric
cores know nothing of the store).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from adpart.errors import ModelError
from adpart.mdp.model import SMDPModel
from adpart.partition._validate import (
    DEFAULT_ATOL,
    as_model,
    check_delta,
    check_epsilon,
    select_options,
)
from adpart.partition.partition import Partition, combine_labels
from adpart.partition.refine import refine


def _mask(value: object, S: int, what: str) -> np.ndarray:
    arr = np.asarray(value)
    if arr.shape != (S,) or arr.dtype != bool:
        raise ModelError(f"{what} must be a boolean mask of shape ({S},); got dtype {arr.dtype}, "
                         f"shape {arr.shape}")
    return arr


def initial_termination_labels(termination: np.ndarray, initiation: np.ndarray) -> np.ndarray:
    """Phase-1 initial blocks: 0 = termination states, 1 = rest of I_o, 2 = outside I_o."""
    return np.where(termination, 0, np.where(initiation, 1, 2)).astype(np.int64)


def phase1(
    model: SMDPModel | object,
    option: int,
    termination: object,
    initiation: object | None = None,
    *,
    delta: float = 0.0,
    atol: float = DEFAULT_ATOL,
) -> Partition:
    """Phase 1 for one option: termination / initiation blocks refined for that option alone.

    Args:
        model: the stacked option models (:class:`SMDPModel`).
        option: the option's index in ``model``.
        termination: ``(S,)`` bool, states where the option terminates (beta = 1).
        initiation: ``(S,)`` bool, its initiation set (default: ``model.admissible[:, option]``;
            if given it must agree with it).
        delta: threshold of eq. 4.6.
    """
    smdp = as_model(model)
    S = smdp.n_states
    o = int(select_options(smdp, [option])[0])
    term = _mask(termination, S, f"termination mask of option {o}")
    init = smdp.admissible[:, o] if initiation is None else _mask(
        initiation, S, f"initiation mask of option {o}")
    if not np.array_equal(init, smdp.admissible[:, o]):
        raise ModelError(
            f"the initiation mask of option {o} disagrees with the model's admissible column "
            f"(first at state {int(np.flatnonzero(init != smdp.admissible[:, o])[0])}); build the "
            "SMDPModel with admissible[:, o] = the option's initiation set"
        )
    start = Partition.from_labels(initial_termination_labels(term, init), smdp.admissible)
    return refine(start, smdp, options=[o], delta=delta, epsilon=None, atol=atol,
                  require_admissible=False)


def phase2(
    model: SMDPModel | object,
    phase1_partitions: Mapping[int, Partition],
    options: Sequence[int],
    *,
    delta: float = 0.0,
    atol: float = DEFAULT_ATOL,
) -> Partition:
    """Phase 2: intersect the selected options' phase-1 partitions, refine for all of them."""
    smdp = as_model(model)
    sel = select_options(smdp, options)
    missing = [int(o) for o in sel if int(o) not in phase1_partitions]
    if missing:
        raise ModelError(
            f"no phase-1 partition for option(s) {missing}; run phase1 for every selected option"
        )
    labels = combine_labels(*(phase1_partitions[int(o)].labels for o in sel))
    start = Partition.from_labels(labels, smdp.admissible)
    return refine(start, smdp, options=sel, delta=delta, epsilon=None, atol=atol)


def phase3(
    model: SMDPModel | object,
    partition: Partition,
    options: Sequence[int],
    *,
    epsilon: float,
    delta: float = 0.0,
    rewards: np.ndarray | None = None,
    atol: float = DEFAULT_ATOL,
) -> Partition:
    """Phase 3: split by the task's rewards within epsilon (eq. 4.7), refine to delta-stability."""
    if epsilon is None:
        raise ModelError("phase 3 needs the task's epsilon (a number >= 0)")
    return refine(partition, model, options=options, delta=delta, epsilon=epsilon,
                  rewards=rewards, atol=atol)


@dataclass
class PhaseResult:
    """The partitions of one multi-phase run, with block counts and seconds per phase."""

    phase1: dict[int, Partition]
    phase2: Partition
    phase3: Partition | None
    seconds: dict[str, float] = field(default_factory=dict)

    @property
    def final(self) -> Partition:
        return self.phase3 if self.phase3 is not None else self.phase2

    def block_counts(self) -> dict[str, object]:
        return {
            "phase1": {o: p.n_blocks for o, p in self.phase1.items()},
            "phase2": self.phase2.n_blocks,
            "phase3": None if self.phase3 is None else self.phase3.n_blocks,
        }


class MultiPhasePartitioner:
    """Runs phases 1-3 over one set of option models, caching phase 1 per option.

    Args:
        model: the stacked models of all candidate options.
        termination: ``(S, O)`` bool, ``termination[s, o]`` = option ``o`` terminates in ``s``
            (beta = 1). For primitive actions pass the terminal mask broadcast, or all False.
        delta: threshold of eq. 4.6 used in every phase.
    """

    def __init__(self, model: SMDPModel | object, termination: object, *, delta: float = 0.0,
                 atol: float = DEFAULT_ATOL) -> None:
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
        self._phase1: dict[int, Partition] = {}
        self.phase1_runs = 0

    def phase1(self, option: int) -> Partition:
        """The cached phase-1 partition of one option (computed on first use)."""
        o = int(select_options(self.model, [option])[0])
        if o not in self._phase1:
            self._phase1[o] = phase1(self.model, o, self.termination[:, o], delta=self.delta,
                                     atol=self.atol)
            self.phase1_runs += 1
        return self._phase1[o]

    def run(self, options: Sequence[int], *, epsilon: float | None = None,
            rewards: np.ndarray | None = None) -> PhaseResult:
        """Phases 1 (cached), 2 and, when ``epsilon`` is given, 3 for an option set."""
        sel = select_options(self.model, options)
        eps = check_epsilon(epsilon)
        seconds: dict[str, float] = {}
        t0 = time.perf_counter()
        p1 = {int(o): self.phase1(int(o)) for o in sel}
        t1 = time.perf_counter()
        p2 = phase2(self.model, p1, sel, delta=self.delta, atol=self.atol)
        t2 = time.perf_counter()
        p3 = None
        if eps is not None:
            p3 = phase3(self.model, p2, sel, epsilon=eps, delta=self.delta, rewards=rewards,
                        atol=self.atol)
        t3 = time.perf_counter()
        seconds.update(phase1=t1 - t0, phase2=t2 - t1, phase3=t3 - t2)
        return PhaseResult(p1, p2, p3, seconds)
