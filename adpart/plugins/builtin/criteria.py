"""Built-in partition criteria (sections 3.2 and 4.2): bisimulation, reward, termination, lumping.

Call signature (``register_partition_criteria``): ``cls(**params).refine(partition, model,
**context) -> Partition`` where ``model`` is an :class:`~adpart.mdp.model.SMDPModel` of the options
(or a FiniteMDP) and ``context`` may carry ``options`` (indices the partition must respect),
``rewards`` (``(S, O)`` task rewards), ``phase`` (1-3, when the multi-phase partitioner calls),
``require_admissible`` and, for ``termination``, ``termination`` (``(S,)`` or ``(S, O)`` beta = 1
mask). Each class is a thin layer over :mod:`adpart.partition`. ``adpart partition`` and
``adpart pipeline`` take any of them (``--criterion NAME``) to refine every phase of the
multi-phase partitioner (:class:`~adpart.partition.multiphase.Criterion`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from adpart.errors import ModelError
from adpart.params import Param, build_settings, settings_params
from adpart.partition.settings import DEFAULT_ATOL, PartitionSettings, StabilityCriterion
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar

if TYPE_CHECKING:
    from adpart.partition import Partition


class BisimulationCriterion(StabilityCriterion):
    """epsilon,delta-approximate stochastic bisimulation homogeneity (definition 4.4).

    Its settings are :class:`~adpart.partition.settings.PartitionSettings` (the multi-phase
    partitioner's default criterion): delta-stability (eq. 4.6) in every phase, and eq. 4.7
    within ``reward-epsilon`` wherever the context carries ``rewards`` (phase 3).
    """

    name = "bisimulation"
    description = "refine to delta-stability (eq. 4.6) and epsilon reward homogeneity (eq. 4.7)"
    params = (
        *settings_params(PartitionSettings),
        Param("atol", "float", DEFAULT_ATOL, "rounding allowance added to both bounds", min=0),
    )

    def __init__(self, atol: float = DEFAULT_ATOL, **values: Any) -> None:
        super().__init__(build_settings(PartitionSettings, values), atol)


class RewardCriterion:
    """Split blocks so every option's reward varies by at most epsilon inside a block (eq. 4.7)."""

    name = "reward"
    description = "split blocks by the task's rewards within epsilon (eq. 4.7), no delta refinement"
    params = tuple(p for p in settings_params(PartitionSettings) if p.name == "reward-epsilon")

    def __init__(self, **values: Any) -> None:
        self.epsilon = build_settings(PartitionSettings, values).reward_epsilon

    def refine(self, partition: Partition, model: object, **context: Any) -> Partition:
        from adpart.partition import refine

        # delta = 1 makes every mass criterion hold (masses lie in [0, 1]), so only eq. 4.7 splits
        return refine(partition, model, options=context.get("options"), delta=1.0,
                      epsilon=self.epsilon, rewards=context.get("rewards"),
                      require_admissible=bool(context.get("require_admissible", True)))


class TerminationCriterion:
    """Phase-1 initial blocks: termination states / rest of the initiation set / outside it."""

    name = "termination"
    description = "split by termination (beta = 1) and initiation sets, per option (phase 1)"
    params = ()

    def refine(self, partition: Partition, model: object, **context: Any) -> Partition:
        import numpy as np

        from adpart.partition.multiphase import initial_termination_labels

        smdp = model.as_smdp() if hasattr(model, "as_smdp") else model
        term = context.get("termination")
        if term is None:
            raise ModelError(
                "the termination criterion needs context termination=(S,) or (S, O) mask"
            )
        term = np.asarray(term, dtype=bool)
        S, n_opt = smdp.admissible.shape
        if term.shape == (S,):
            term = np.repeat(term[:, None], n_opt, axis=1)
        if term.shape != (S, n_opt):
            raise ModelError(
                f"termination mask has shape {term.shape}; expected ({S},) or ({S}, {n_opt})"
            )
        options = context.get("options")
        cols = range(n_opt) if options is None else [int(o) for o in options]
        result = partition
        for o in cols:
            result = result.refine_by(initial_termination_labels(term[:, o], smdp.admissible[:, o]))
        return result


class ExactLumpingCriterion:
    """The coarsest exact lumping (delta = epsilon = 0) by a splitter worklist."""

    name = "exact-lumping"
    description = "coarsest exact lumping / stochastic bisimulation (delta = epsilon = 0), fast"
    params = (Param("rewards", "bool", True, "require equal rewards R(s, o) too"),)

    def __init__(self, rewards: bool = True) -> None:
        self.use_rewards = rewards

    def refine(self, partition: Partition, model: object, **context: Any) -> Partition:
        from adpart.partition import exact_lumping

        return exact_lumping(model, initial=partition, options=context.get("options"),
                             use_rewards=self.use_rewards, rewards=context.get("rewards"))


@hookimpl
def register_partition_criteria(register: Registrar) -> None:
    register(BisimulationCriterion)
    register(RewardCriterion)
    register(TerminationCriterion)
    register(ExactLumpingCriterion)
