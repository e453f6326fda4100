"""What a stored run knew: its learner's declared knowledge and that of the inputs it was given.

A learner declares its own knowledge (:mod:`adpart.learning.knowledge`), but a layer learner is
also handed things computed before it ran, and those carry knowledge of their own:

* every option adpart stores is a policy solved on a model of the environment (to its subgoal,
  with a pseudo-reward: section 4.1): the true dynamics, or in the learned-model regime the
  model estimated from earlier runs' experience (the options' environment is then named
  ``ENV@experience:run:N``, :mod:`adpart.workflows.experience`), and a layer over them was
  partitioned on the same model;
* a partition built for a task (``task_id`` set) was computed on that task's true model with its
  terminal states as one absorbing block (phases 1-2), and a ``reward-refined`` one was split by
  its rewards (phase 3, eq. 4.7): the task's rewards are known;
* a ``hierarchy`` layer (Algorithm 3) was built from the option models and the earlier tasks'
  learned values;
* a ``learned`` layer is one a learner ended on; it knows what that run knew.

:func:`run_knowledge` combines them; the workflows store the result on the run
(``metrics.knowledge``) and print it beside every comparison.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from adpart.learning.knowledge import (
    FLAT,
    OPTION_POLICIES,
    Knowledge,
    combine,
    estimated_option_policies,
)

__all__ = ["partition_knowledge", "run_knowledge"]


def partition_knowledge(kind: str, task_id: int | None, estimated_from: str | None = None
                        ) -> Knowledge:
    """What a layer of ``kind`` built for ``task_id`` (None: for no task) brings with it;
    ``estimated_from`` names the runs whose experience estimated the model it was built on
    (None: the true model)."""
    if estimated_from is not None and kind != "learned":
        uses = [f"layer partitioned on the model estimated from {estimated_from}"]
        if task_id is not None:
            uses[0] += " with the task's terminals"
        if kind == "reward-refined":
            uses.append("phase-3 split by the task's rewards")
        return Knowledge("estimated", "known" if task_id is not None else "observed",
                         tuple(uses))
    if kind == "hierarchy":
        return Knowledge("true-model", "observed",
                         ("layer built by Algorithm 3 from the option models",))
    if kind == "learned":
        return Knowledge("true-model", "known", ("a layer refined by an earlier run",))
    uses = ["layer partitioned on the true model"]
    rewards = "observed"
    if task_id is not None:
        uses[0] += " with the task's terminals"
        rewards = "known"
    if kind == "reward-refined":
        uses.append("phase-3 split by the task's rewards")
        rewards = "known"
    return Knowledge("true-model", rewards, tuple(uses))


def run_knowledge(learner: dict[str, Any] | None, option_ids: Sequence[int],
                  partition: Any = None, estimated_from: str | None = None) -> Knowledge | None:
    """The knowledge of a run: its learner's record (None: the learner declared none) with its
    options' and ``partition``'s (a stored partition record) on top; ``estimated_from`` names
    the runs whose experience estimated the model the options and the layer were built on
    (None: they were built on the true model)."""
    if learner is None:
        return None
    own = Knowledge.from_dict(learner)
    if option_ids and own == OPTION_POLICIES:
        # a learner that knows the dynamics only through its options (SMDP Q) declares the
        # usual case, options solved on the true dynamics; the options' own record below says
        # what they were solved on, and replaces that assumption
        own = FLAT
    parts = [own]
    if option_ids:
        parts.append(OPTION_POLICIES if estimated_from is None
                     else estimated_option_policies(estimated_from))
    if partition is not None:
        parts.append(partition_knowledge(partition.kind, partition.task_id, estimated_from))
    return combine(parts)
