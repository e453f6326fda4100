"""The plugin contracts as types: one Protocol per plugin kind (the hooks in :mod:`hookspecs`).

Every implementation class carries ``name``, ``description`` and ``params`` (:class:`Plugin`) and
the one method of its kind. Environments subclass :class:`adpart.envs.base.Domain` and executors
:class:`adpart.execution.Executor` (both ABCs, since they share behaviour); the other kinds are
structural: any class with the right method is a plugin, no import of adpart's classes needed
except for the result types. ``adpart.testing`` checks an implementation against its contract by
calling it, the way Gymnasium's ``check_env`` checks an environment.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

    from adpart.hierarchy.layers import HierarchyInputs, HierarchyResult
    from adpart.learning.result import LearnResult
    from adpart.mdp.model import FiniteMDP, SMDPModel
    from adpart.options.option import Option
    from adpart.params import Param
    from adpart.partition.partition import Partition
    from adpart.subgoals.result import SubgoalResult

__all__ = [
    "LEARNER_CONTEXT",
    "HierarchyEstimator",
    "Learner",
    "PartitionCriterion",
    "Plugin",
    "SubgoalDetector",
]

#: What a learner may be given besides the MDP, when it declares it in ``accepts``: options, a
#: partition over them, and in the learned-model regime (``--model ENV@experience:run:N``) the
#: ``belief`` model it may read (a FiniteMDP) or the earlier runs' ``experience`` (counts), and
#: those runs' greedy ``policies`` (``(n, S)``, for a learner that transfers policies).
LEARNER_CONTEXT = frozenset({"options", "partition", "belief", "experience", "policies"})


@runtime_checkable
class Plugin(Protocol):
    """What every implementation class carries, whatever its kind."""

    name: ClassVar[str]  #: unique within its kind; stored with every result
    description: ClassVar[str]  #: one line for ``adpart plugins``
    params: ClassVar[tuple[Param, ...]]  #: declared parameters = constructor keywords


@runtime_checkable
class Learner(Plugin, Protocol):
    """``cls(**params).learn(mdp, *, runs, episodes, seed, eval_every, progress)``.

    Returns a :class:`~adpart.learning.result.LearnResult` over ``runs`` runs of ``episodes``
    episodes. A learner that learns over options or on a decision layer lists ``"options"``
    and/or ``"partition"`` in its class attribute ``accepts`` and then receives them as the
    keywords ``options`` (a list of :class:`~adpart.options.option.Option`) and ``partition``
    (a :class:`~adpart.partition.partition.Partition` over the options' columns); a learner
    without ``accepts`` is never passed them, and asking it to use them is refused up front.
    A learner without randomness sets ``single_run = True`` and returns one run whatever
    ``runs`` asks. A learner that only fits some environments names one it fits in
    ``example_environment`` (the conformance checks run it there).
    """

    def learn(
        self,
        mdp: FiniteMDP,
        *,
        runs: int,
        episodes: int,
        seed: int,
        eval_every: int,
        progress: Callable[[int, int], object] | None = None,
        options: Sequence[Option] | None = None,
        partition: Partition | None = None,
    ) -> LearnResult: ...


@runtime_checkable
class SubgoalDetector(Plugin, Protocol):
    """``cls(**params).detect(mdp, policy, rng)`` -> :class:`~adpart.subgoals.result.SubgoalResult`.

    ``policy`` is ``(S,)`` action ids or ``(S, A)`` probabilities; ``rng`` a numpy Generator
    (section 4.1).
    """

    def detect(
        self, mdp: FiniteMDP, policy: np.ndarray, rng: np.random.Generator
    ) -> SubgoalResult: ...


@runtime_checkable
class PartitionCriterion(Plugin, Protocol):
    """``cls(**params).refine(partition, model, **context)`` -> a refined Partition.

    ``model`` is the options' stacked :class:`~adpart.mdp.model.SMDPModel`; ``context`` may carry
    ``options``, ``rewards`` or ``termination`` (sections 3.2 and 4.2). The result refines
    ``partition``: every returned block lies inside one block of the input.
    """

    def refine(self, partition: Partition, model: SMDPModel, **context: Any) -> Partition: ...


@runtime_checkable
class HierarchyEstimator(Plugin, Protocol):
    """``cls(**params).build(inputs)`` -> :class:`~adpart.hierarchy.layers.HierarchyResult`.

    The decision layer for the next task from the tasks learned so far (section 4.4), as a pure
    function of ``inputs`` (:class:`~adpart.hierarchy.layers.HierarchyInputs`: the learned
    tasks' values over the primitive actions and the candidate options, their occupancies and
    weights, the options and their columns). An estimator reads no knowledge base and stores
    nothing, and leaves ``inputs`` as it found them (derive with ``inputs.with_threshold`` or
    ``inputs.select_options``). The result's partition is over the primitive actions followed by
    the options ``option_ids`` it offers somewhere (a subsequence of ``inputs.option_ids``), every
    block offers a column all its states may start, ``task_ids`` are ``inputs.task_ids`` and
    ``partition_id`` is None; :func:`adpart.hierarchy.layers.layer_result` builds such a result
    from a layer over all the input columns. The workflow
    (:func:`adpart.workflows.hierarchy.build_hierarchy`) loads the inputs and stores the layer.
    """

    def build(self, inputs: HierarchyInputs) -> HierarchyResult: ...
