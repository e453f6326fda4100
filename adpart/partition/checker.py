"""An independent checker of epsilon,delta-stability (definition 4.4, eqs. 4.6-4.7).

Deliberately simple and separate from the refiners: it shares none of their code paths (no
greedy cuts, no worklists, no sparse products with block indicators). For every block, every
option offered in it and every target block it sums the masses ``F(B_j | s, o)`` state by state
from the rows of ``F`` and compares the largest and smallest value; likewise for ``R(s, o)``. It
also checks that the block's options are admissible in all of its states. It is meant for tests and
for auditing stored partitions, not for speed (it loops over blocks and options).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from adpart.errors import ModelError
from adpart.partition._validate import (
    DEFAULT_ATOL,
    as_model,
    check_atol,
    check_delta,
    check_epsilon,
    check_partition_fits,
    check_rewards,
    select_options,
)
from adpart.partition.partition import Partition


@dataclass(frozen=True)
class Violation:
    """One broken inequality: ``kind`` is ``"mass"`` (eq. 4.6), ``"reward"`` (eq. 4.7) or
    ``"admissible"`` (an offered option not admissible in some state of the block)."""

    kind: str
    block: int
    option: int
    target: int
    span: float


@dataclass(frozen=True)
class StabilityReport:
    """The checker's verdict: ``ok`` and the violations found (the largest first)."""

    ok: bool
    max_mass_span: float
    max_reward_span: float
    violations: list[Violation] = field(default_factory=list)

    def __bool__(self) -> bool:
        return self.ok


def check_stability(
    partition: Partition,
    model: object,
    *,
    options: Sequence[int] | np.ndarray | None = None,
    delta: float,
    epsilon: float | None = None,
    rewards: np.ndarray | None = None,
    atol: float = DEFAULT_ATOL,
) -> StabilityReport:
    """Verify that every block of ``partition`` is delta-stable w.r.t. every block (eq. 4.6) and,
    when ``epsilon`` is given, reward homogeneous (eq. 4.7), for the given options.

    Only options offered in a block (``partition.admissible``) are checked there; an option offered
    in a block must be admissible (``model.admissible``) in each of its states.
    """
    smdp = as_model(model)
    d = check_delta(delta)
    e = check_epsilon(epsilon)
    tol = check_atol(atol)
    if not isinstance(partition, Partition):
        raise ModelError(f"partition must be a Partition, got {type(partition).__name__}")
    check_partition_fits(partition.labels, smdp.n_states)
    if partition.n_options != smdp.n_actions:
        raise ModelError(
            f"partition offers {partition.n_options} options but the model has {smdp.n_actions}"
        )
    sel = select_options(smdp, options)
    R = None if e is None else check_rewards(smdp.R if rewards is None else rewards, smdp)
    S = smdp.n_states
    F = smdp.F.tocsr()
    labels = partition.labels
    violations: list[Violation] = []
    max_mass = 0.0
    max_reward = 0.0
    for b in range(partition.n_blocks):
        members = np.flatnonzero(labels == b)
        for o in sel:
            if not partition.admissible[b, o]:
                continue
            if not smdp.admissible[members, o].all():
                violations.append(Violation("admissible", b, int(o), -1, np.inf))
                continue
            # mass of each member into each block, summed row by row
            masses = np.zeros((members.size, partition.n_blocks))
            for i, s in enumerate(members):
                row = int(o) * S + int(s)
                lo, hi = F.indptr[row], F.indptr[row + 1]
                for t, p in zip(F.indices[lo:hi], F.data[lo:hi], strict=True):
                    masses[i, labels[t]] += p
            spans = masses.max(axis=0) - masses.min(axis=0)
            max_mass = max(max_mass, float(spans.max()))
            for target in np.flatnonzero(spans > d + tol):
                violations.append(Violation("mass", b, int(o), int(target), float(spans[target])))
            if R is not None:
                span = float(R[members, o].max() - R[members, o].min())
                max_reward = max(max_reward, span)
                if span > e + tol:
                    violations.append(Violation("reward", b, int(o), -1, span))
    violations.sort(key=lambda v: -v.span)
    return StabilityReport(not violations, max_mass, max_reward, violations)
