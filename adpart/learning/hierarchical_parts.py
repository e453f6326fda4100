"""The named parts of the hierarchical learner's driver (section 4.3.3).

:func:`adpart.learning.hierarchical.hierarchical_learning` is a short rule over these parts, each
built from its part of :class:`~adpart.learning.hierarchical_settings.HierarchicalSettings`:

* a :class:`ReferenceValues` - what the grounded flat value must beat by ``L`` (4.3.3's
  ``max_{o in O_B} Q_P(B, o)``, or one of the sounder values of the module docstring of
  :mod:`adpart.learning.hierarchical`): its arrays for the kernel, and their update after a
  refinement;
* a :class:`LayerRefiner` - what a firing does to run ``k``'s layer (``refine_block`` with the
  settings' rule and thresholds) and to the kernel's per-block arrays (children's values from
  :func:`~adpart.learning.hierarchical.child_values`);
* an :class:`OnlineSplits` - phase 3 online (:mod:`adpart.learning.online_phase3`): after every
  episode each run's observations read from the world, its layer split where they change its
  option models, and the kernel's arrays updated as after a firing;
* :func:`lifted_values` - what the greedy policy is greedy on (the layer's learned values, or
  its point model planned on each run's counts).

The numba kernel (:mod:`adpart.learning._smdp_kernels`) reads the arrays; nothing here runs per
step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from adpart.learning._rmax import counted_smdp
from adpart.learning._smdp_kernels import SMDPLockStepState
from adpart.learning.decision_layer import offered_values, refine_block
from adpart.learning.knowledge import world
from adpart.learning.online_phase3 import OnlinePhase3
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.mdp.solvers import q_from_v, solve
from adpart.partition.bpsmdp import point_model, point_policy
from adpart.partition.partition import Partition

__all__ = ["LayerRefiner", "OnlineSplits", "ReferenceValues", "lifted_values", "point_optima"]


def point_optima(partition: Partition, smdp: SMDPModel) -> np.ndarray:
    """``V*_P`` per block: the optimum of the layer's point model (section 4.2.2)."""
    return solve(point_model(partition, smdp), 1e-8).V


def _split_values(partition: Partition, values: np.ndarray) -> np.ndarray:
    """The reference for an action the state's block offers: ``values`` where the state shares
    its block, ``+inf`` (never fires) where it is a block of its own."""
    shared = np.bincount(partition.labels, minlength=partition.n_blocks) > 1
    return np.where(shared[partition.labels], values, np.inf)


@dataclass(frozen=True)
class ReferenceValues:
    """What the grounded flat value is compared with (``settings.test_reference``).

    ``learned``: the block's learned ``max_o Q_P(b, o)`` (4.3.3 as written; the kernel reads
    it, nothing to compute); ``model``: the block's ``V*_P(b)``; ``offered``: per state, the
    larger of that and the best the offered options achieve from the state; ``policy``: per
    state, the value of the layer's best block policy. Each is recomputed after every
    refinement of the run's layer. With ``split_offered`` (``policy`` only) an offered action is
    tested against the same values, ``+inf`` where the state is alone in its block.
    """

    name: str
    split_offered: bool
    mdp: FiniteMDP
    smdp: SMDPModel
    floor: float

    @property
    def per_block(self) -> bool:
        """Whether the kernel's reference table has a column per block (it grows with them)."""
        return self.name == "model"

    def state_values(self, partition: Partition) -> np.ndarray:
        """``(S,)`` the ``offered`` or ``policy`` reference of every state."""
        if self.name == "policy":
            return policy_evaluation(self.smdp, point_policy(partition, self.smdp, 1e-8),
                                     never=self.floor)
        return np.maximum(offered_values(partition, self.smdp, self.mdp.terminal, self.floor),
                          point_optima(partition, self.smdp)[partition.labels])

    def initial(self, partition: Partition) -> dict[str, np.ndarray | None]:
        """The kernel's ``block_values``, ``state_values`` and ``offered_values`` for the
        starting layer (:class:`~adpart.learning.smdp_q.InconsistencyArrays`)."""
        blocks = point_optima(partition, self.smdp) if self.name == "model" else None
        states = (self.state_values(partition) if self.name in ("offered", "policy")
                  else None)
        offered = (_split_values(partition, states)
                   if self.split_offered and states is not None else None)
        return {"block_values": blocks, "state_values": states, "offered_values": offered}

    def refresh(self, st: SMDPLockStepState, k: int, partition: Partition) -> None:
        """Run ``k``'s reference after its layer became ``partition``."""
        if self.name == "model":
            st.Vref[k, :partition.n_blocks] = point_optima(partition, self.smdp)
        elif self.name in ("offered", "policy"):
            st.Vref[k] = self.state_values(partition)
            if self.split_offered:
                st.Voff[k] = _split_values(partition, st.Vref[k])


@dataclass(frozen=True)
class LayerRefiner:
    """What a firing at ``(s, b, a*)`` does (4.3.3): ``b`` refined for ``a*`` with ``rule``
    (``state``: ``s`` becomes a block of its own; ``block``: every state of ``b``; an offered
    ``a*`` - ``split_offered`` - always splits ``s`` off), the children's values and counts
    inherited or grounded (:func:`~adpart.learning.hierarchical.child_values`)."""

    rule: str
    delta: float
    epsilon: float | None
    model: SMDPModel
    floor: float
    child_values: Callable[..., tuple[np.ndarray, np.ndarray]]
    #: a run's own refinement model where phase 3 online has rebuilt it on what the run
    #: observed (:mod:`adpart.learning.online_phase3`); the others refine on :attr:`model`
    run_models: dict[int, SMDPModel] = field(default_factory=dict)

    def model_of(self, k: int) -> SMDPModel:
        """The model run ``k``'s refinements split by."""
        return self.run_models.get(k, self.model)

    def apply(self, st: SMDPLockStepState, k: int, old: Partition,
              reference: ReferenceValues) -> tuple[Partition, dict[str, int]]:
        """Refine run ``k``'s layer ``old`` where the kernel fired; update the kernel's arrays.

        Returns the new layer and the refinement's record.
        """
        s, b, a = (int(x) for x in st.fired[k])
        offered = bool(old.admissible[b, a])  # primitive a is column a; split_offered
        new = refine_block(old, b, [a], self.model_of(k), delta=self.delta,
                           epsilon=self.epsilon, at=s if self.rule == "state" or offered else None)
        self.install(st, k, old, new, b, reference)
        return new, {"run": k, "episode": int(st.episode[k]), "state": s, "block": b,
                     "action": a, "offered": offered, "blocks_before": old.n_blocks,
                     "blocks_after": new.n_blocks,
                     "offers": np.flatnonzero(old.admissible[b]).tolist()}

    def install(self, st: SMDPLockStepState, k: int, old: Partition, new: Partition,
                split: int | np.ndarray, reference: ReferenceValues) -> None:
        """Make ``new`` (``old`` with the blocks ``split`` refined) run ``k``'s layer in the
        kernel's arrays: the children's values and counts, admissibility, labels, reference."""
        B_old, B_new = old.n_blocks, new.n_blocks
        _grow(st, B_new, reference.per_block)
        parent = new.parent_map(old)
        Qn, n_on = self.child_values(st.Q[k, :B_old], st.n_o[k, :B_old], old, new, split,
                                     st.Ql[k], st.nf[k] > 0, self.floor, parent)
        st.Q[k, :B_new], st.Q[k, B_new:] = Qn, -np.inf
        st.n_o[k, :B_new], st.n_o[k, B_new:] = n_on, 0
        st.n_d[k, :B_new] = st.n_d[k, :B_old][parent]
        st.n_d[k, B_new:] = 0
        st.adm[k, :B_new], st.adm[k, B_new:] = new.admissible, False
        st.labels[k] = new.labels
        st.n_blocks[k] = B_new
        st.vr_on[k] = False  # virtual executions started in the old blocks are dropped
        reference.refresh(st, k, new)


@dataclass
class OnlineSplits:
    """Phase 3 online in the driver: what each run saw is read from the world after every
    episode (the rewards of the pairs it tried, the terminal successors R-max counted), given to
    :class:`~adpart.learning.online_phase3.OnlinePhase3`, and a refined layer installed in the
    kernel by the :class:`LayerRefiner`, which splits the run's later firings by its updated
    model."""

    phase3: OnlinePhase3
    refiner: LayerRefiner
    task: FiniteMDP
    #: one record per run whose belief changed: run, episode, blocks before and after
    events: list[dict[str, int]] = field(default_factory=list)

    def after_episode(self, st: SMDPLockStepState, parts: list[Partition],
                      reference: ReferenceValues) -> None:
        """Update every run's belief and layer (``parts`` in place) from what it saw."""
        S = self.task.n_states
        for k, old in enumerate(parts):
            tried = st.nf[k] > 0
            with world():  # what run k saw: the rewards it was paid, the episodes' ends
                paid = np.where(tried, self.task.R, 0.0)
                ended = np.zeros(S, dtype=bool)
                ended[st.indices[st.xc[k] > 0]] = True
                ended &= self.task.terminal
            found = self.phase3.observe(k, old, tried, paid, ended)
            if found is None:
                continue
            new, split = found
            self.refiner.run_models[k] = self.phase3.models[k]
            if new.n_blocks != old.n_blocks:
                self.refiner.install(st, k, old, new, split, reference)
            self.events.append({"run": k, "episode": int(st.episode[k]),
                                "blocks_before": old.n_blocks, "blocks_after": new.n_blocks})
            parts[k] = new

    def blocks_added(self, runs: int) -> list[int]:
        """The blocks phase 3 added to each run's layer."""
        added = np.zeros(runs, dtype=np.int64)
        for event in self.events:
            added[event["run"]] += event["blocks_after"] - event["blocks_before"]
        return added.tolist()


def _grow(st: SMDPLockStepState, needed: int, per_block_reference: bool) -> None:
    """Widen the kernel's per-block arrays to hold ``needed`` blocks (doubling, at most S)."""
    K, cap = st.Q.shape[:2]
    if needed <= cap:
        return
    new_cap = min(st.labels.shape[1], max(needed, 2 * cap))
    pad = new_cap - cap
    st.Q = np.concatenate([st.Q, np.full((K, pad, st.Q.shape[2]), -np.inf)], axis=1)
    st.adm = np.concatenate([st.adm, np.zeros((K, pad, st.adm.shape[2]), bool)], axis=1)
    st.n_o = np.concatenate([st.n_o, np.zeros((K, pad, st.n_o.shape[2]), np.int64)], axis=1)
    st.n_d = np.concatenate([st.n_d, np.zeros((K, pad), np.int64)], axis=1)
    if per_block_reference:  # the other references have no per-block column
        st.Vref = np.concatenate([st.Vref, np.zeros((K, pad))], axis=1)


def lifted_values(how: str, st: SMDPLockStepState, parts: list[Partition], smdp: SMDPModel,
                  mdp: FiniteMDP, floor: float) -> np.ndarray:
    """``(K, S, C)`` what the greedy policy is greedy on: the layer's learned values lifted to
    states (``learned``), or its point model planned on each run's grounded model - the
    primitive columns from the counts, untried pairs at the floor (``planned``; certainty
    equivalence on the decision layer)."""
    if how == "planned":
        out = []
        for k, part in enumerate(parts):
            model = point_model(part, counted_smdp(smdp, mdp, st.xc[k], floor))
            out.append(q_from_v(model, solve(model, 1e-8).V)[part.labels])
        return np.stack(out)
    return np.take_along_axis(st.Q, st.labels[:, :, None], axis=1)
