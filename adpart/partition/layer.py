"""What the partition phases run on for one task: its terminal block, its reachable states, and
the rewards that matter for its decisions (section 4.2.1.2, eq. 4.7; DESIGN.md "Multi-phase
partitioning").

**Terminal states.** The new task's terminal states are absorbing with zero reward: their rows of
``F`` and ``R`` are zero and every column may be chosen there (as ``FiniteMDP.as_smdp`` and
``stack_models`` build them). They start as one block in every phase and stay one, since a block
whose rows are all zero is delta-stable and reward homogeneous. The option models themselves must
be the new task's (computed on its MDP). Merging the new terminal states on top of phases run on
another task's model would not do: the old models carry mass *through* those states, and phase 3
can only split blocks.

**Reachability.** A state is reachable when some policy over the layer's columns reaches it with
positive probability from the task's start distribution. That is a path in the graph with an edge
``s -> s'`` wherever ``F(s'|s, o) > 0`` for a column ``o`` offered in ``s`` (the support of eq.
3.2, the graph of theorem 4.4). :func:`reachable_states` finds it by one breadth-first search
(:func:`scipy.sparse.csgraph.breadth_first_order`) from a virtual source linked to the start
states. The reachable set is closed under ``F``, so no reachable state has mass on an unreachable
one, and refinement may leave the unreachable states out (their rows zeroed) without changing any
reachable block. They are kept in as few blocks as the partition invariant allows: one block per
pattern of admissible columns, because a block offers only columns that all its states may start.
That is usually one block. These blocks are reported apart and are not counted in the decision
layer.

**Decision rewards (eq. 4.7).** Let every primitive step pay ``c + r~``: a constant ``c`` and
a task-specific part ``r~``, e.g. the goal's bonus. Then an option's discounted reward (eq. 3.1)
splits, with ``m(s, o) = E[gamma^tau] = sum_s' F(s'|s, o)`` (eq. 3.2), into::

    R(s, o) = c (1 - m(s, o)) / (1 - gamma) + R~(s, o)

With ``b = c / (1 - gamma)`` (the value of paying ``c`` for ever) and ``U = V - b`` (so
``U = -b`` at a terminal state, where ``V = 0``)::

    Q(s, o) = R(s, o) + sum_s' F(s'|s, o) V(s') = b + R~(s, o) + sum_s' F(s'|s, o) U(s')

Every column in every state shares ``b``, so no decision depends on it. What a decision depends on
is ``R~`` plus the masses ``F``, and eq. 4.6 already bounds those, the mass into the terminal
block included. Applying eq. 4.7 to ``R`` itself bounds the duration a second time, and much more
finely: ``epsilon (1 - gamma) / |c|`` of mass, 0.1 at the seed's ``epsilon = 10``,
``gamma = 0.99``, ``c = -1``, against ``delta = 0.3``. That is what cuts blocks into bands about
ten steps long. adpart therefore applies eq. 4.7 to ``R~`` (:func:`decision_rewards`). The constant
``c`` is by default the step reward most admissible non-terminal pairs pay (:func:`step_baseline`,
``"mode"``). On every domain with one step cost that is the ``r_min`` of sections 4.3.1-4.3.2,
which the seed treats as rewards that "neither help finding a goal state nor make a significant
change" (``"min"`` selects it). Where a few actions are penalised (Taxi's -10 for an illegal
pick-up, under -1 a step), the mode keeps the penalty as a reward that matters. When ``c = 0``, as
in the seed's 5.1.3 reward model (no step cost), ``R~ = R`` and nothing changes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from adpart.errors import ModelError
from adpart.mdp.model import SMDPModel
from adpart.partition._validate import as_model, select_options
from adpart.partition.partition import Partition


def as_mask(value: object, S: int, what: str) -> np.ndarray:
    """``value`` as an ``(S,)`` bool array, or a :class:`ModelError` naming ``what``."""
    arr = np.asarray(value)
    if arr.shape != (S,) or arr.dtype != bool:
        raise ModelError(f"{what} must be a boolean mask of shape ({S},); got dtype {arr.dtype}, "
                         f"shape {arr.shape}")
    return arr


def start_mask(start: object, S: int) -> np.ndarray:
    """The start states: a bool mask as given, or the support of a distribution ``(S,)``."""
    arr = np.asarray(start)
    if arr.dtype == bool:
        mask = as_mask(arr, S, "start")
    else:
        if arr.shape != (S,) or not np.issubdtype(arr.dtype, np.number):
            raise ModelError(f"start must be a bool mask or a distribution of shape ({S},); got "
                             f"dtype {arr.dtype}, shape {arr.shape}")
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise ModelError("start distribution has negative or non-finite entries")
        mask = arr > 0
    if not mask.any():
        raise ModelError("the start distribution is empty; give the task's start states "
                         "(e.g. mdp.initial)")
    return mask


def reachable_states(model: SMDPModel | object, start: object,
                     options: Sequence[int] | np.ndarray | None = None,
                     admissible: np.ndarray | None = None) -> np.ndarray:
    """``(S,)`` bool: states some policy over ``options`` reaches from ``start`` (module doc).

    Args:
        model: the stacked models (``F`` row ``o*S + s``).
        start: ``(S,)`` start distribution or bool mask (the start states are reachable).
        options: the layer's columns (default all).
        admissible: ``(S, O)`` where each column is offered (default ``model.admissible``).
    """
    smdp = as_model(model)
    S = smdp.n_states
    src = start_mask(start, S)
    sel = select_options(smdp, options)
    adm = smdp.admissible if admissible is None else np.asarray(admissible, dtype=bool)
    if adm.shape != smdp.admissible.shape:
        raise ModelError(f"admissible has shape {adm.shape}; expected (S, O) = "
                         f"{smdp.admissible.shape}")
    F = sp.csr_array(smdp.F)
    rows = (sel[:, None] * S + np.arange(S)[None, :]).ravel()
    sub = F[rows]
    offered = adm[:, sel].T.ravel()  # (k*S,) row by row, like ``rows``
    counts = np.diff(sub.indptr)
    keep = np.repeat(offered, counts) & (sub.data > 0)
    tail = np.repeat(np.arange(rows.size) % S, counts)[keep]
    head = sub.indices[keep]
    # one extra node S: the virtual source, linked to every start state
    tail = np.r_[tail, np.full(int(src.sum()), S)]
    head = np.r_[head, np.flatnonzero(src)]
    # float weights: duplicate edges (several columns, s -> t) are summed, never wrap around
    graph = sp.csr_array((np.ones(tail.size), (tail, head)), shape=(S + 1, S + 1))
    order = csgraph.breadth_first_order(graph, S, directed=True, return_predecessors=False)
    out = np.zeros(S + 1, dtype=bool)
    out[order] = True
    return out[:S]


def step_baseline(R: np.ndarray, admissible: np.ndarray, terminal: np.ndarray, *,
                  rule: str = "mode") -> float:
    """The per-step constant ``c`` of :func:`decision_rewards`, from the primitive MDP's rewards.

    Over the admissible non-terminal pairs: ``rule="mode"``, the reward most pairs pay (ties to
    the smaller value); ``rule="min"``, ``r_min = min R(s, a)`` of sections 4.3.1-4.3.2. They agree
    on every domain with one step cost. Where a few actions are penalised (Taxi's -10 for an
    illegal pick-up), the mode keeps the penalty a reward that matters and the step the baseline.
    """
    R = np.asarray(R, dtype=np.float64)
    live = np.asarray(admissible, dtype=bool) & ~np.asarray(terminal, dtype=bool)[:, None]
    if not live.any():
        raise ModelError("no admissible non-terminal state-action pair: no step reward to take "
                         "as the baseline")
    if rule == "min":
        return float(R[live].min())
    if rule != "mode":
        raise ModelError(f"baseline rule {rule!r}; use 'mode' or 'min'")
    values, counts = np.unique(R[live], return_counts=True)
    return float(values[np.argmax(counts)])  # np.unique sorts: the first maximum is the smaller


#: The named choices of :func:`resolve_baseline`.
REWARD_BASELINES = ("mode", "min", "none")


def resolve_baseline(reward_baseline: object, R: np.ndarray, admissible: np.ndarray,
                     terminal: np.ndarray) -> float | None:
    """The constant step reward phase 3 takes out: ``"mode"`` or ``"min"`` (:func:`step_baseline`
    of the task's primitive ``R``), ``"none"``/None (compare ``R`` itself), or a number."""
    if reward_baseline is None or (isinstance(reward_baseline, str) and reward_baseline == "none"):
        return None
    if isinstance(reward_baseline, str) and reward_baseline in ("mode", "min"):
        return step_baseline(R, admissible, terminal, rule=reward_baseline)
    if isinstance(reward_baseline, (int, float, np.floating)) and not isinstance(
            reward_baseline, bool) and np.isfinite(reward_baseline):
        return float(reward_baseline)
    raise ModelError(
        f"reward_baseline = {reward_baseline!r}; use 'mode' (the step reward most pairs pay), "
        "'min' (the smallest, sections 4.3.1-4.3.2), 'none' (compare R(s, o) itself) or a "
        "finite number"
    )


def decision_rewards(model: SMDPModel | object, gamma: float, baseline: float,
                     terminal: np.ndarray | None = None) -> np.ndarray:
    """``(S, O)``: ``R~(s, o) = R(s, o) - c (1 - sum_s' F(s'|s, o)) / (1 - gamma)`` (module doc).

    The rewards beyond a constant per-step reward ``c = baseline``, which are the rewards eq. 4.7
    compares in phase 3. Inadmissible pairs and terminal states get 0.

    Raises:
        ModelError: ``gamma`` outside ``(0, 1)``: with ``gamma = 1`` the constant's share is the
            expected duration, which ``F`` does not carry. Pass rewards that are already
            relative instead (``rewards=``).
    """
    smdp = as_model(model)
    g = float(gamma)
    if not (0.0 < g < 1.0):
        raise ModelError(f"gamma = {gamma!r}: a reward baseline needs 0 < gamma < 1 (the "
                         "constant's share is c (1 - E[gamma^tau]) / (1 - gamma)); use "
                         "reward_baseline=None or pass relative rewards")
    c = float(baseline)
    if not np.isfinite(c):
        raise ModelError(f"reward baseline {baseline!r} must be a finite number")
    mass = smdp.row_discounts.T  # (S, O): m(s, o) = E[gamma^tau]
    rel = smdp.R - c * (1.0 - mass) / (1.0 - g)
    rel = np.where(smdp.admissible, rel, 0.0)
    if terminal is not None:
        rel[np.asarray(terminal, dtype=bool)] = 0.0
    return rel


def zero_rows(model: SMDPModel, states: np.ndarray, *, admissible_row: np.ndarray | None = None
              ) -> SMDPModel:
    """The model with zero ``F`` and ``R`` rows at ``states`` (every column's row).

    ``admissible_row`` (``(O,)`` bool), when given, becomes the admissibility of all ``states``, so
    that they share one admissibility pattern (the terminal block). Phases refine on this model
    (module doc); learners keep the real one.
    """
    n_cols = model.R.shape[1]
    states = np.asarray(states, dtype=bool)
    if not states.any():
        return model
    F = sp.csr_array(model.F)
    keep = np.tile(~states, n_cols)
    data = F.data * np.repeat(keep, np.diff(F.indptr))
    F = sp.csr_array((data, F.indices.copy(), F.indptr.copy()), shape=F.shape)
    F.eliminate_zeros()
    R = np.where(states[:, None], 0.0, model.R)
    adm = model.admissible.copy()
    if admissible_row is not None:
        adm[states] = np.asarray(admissible_row, dtype=bool)
    return SMDPModel(R=R, F=F, admissible=adm)


def terminal_columns(admissible: np.ndarray, terminal: np.ndarray) -> np.ndarray:
    """``(O,)`` the columns the terminal block offers: those every terminal state admits.

    ``stack_models`` admits every option at terminal states; a primitive MDP keeps its own
    admissibility there. If the terminal states admit no column in common, every column is offered
    (terminal rows are zero, so no value depends on it).
    """
    common = np.asarray(admissible, dtype=bool)[np.asarray(terminal, dtype=bool)].all(axis=0)
    return common if common.any() else np.ones_like(common)


def layer_counts(partition: Partition, terminal: np.ndarray | None = None,
                 unreachable: np.ndarray | None = None) -> dict[str, int]:
    """Blocks of ``partition`` split into decision-layer, terminal and unreachable blocks.

    ``reachable`` counts the blocks holding a reachable non-terminal state (the decision layer the
    learner sees); ``terminal`` the blocks holding a terminal state; ``unreachable`` the blocks of
    unreachable non-terminal states. With both masks None every block is ``reachable``.
    """
    S = partition.n_states
    term = np.zeros(S, dtype=bool) if terminal is None else np.asarray(terminal, dtype=bool)
    unr = np.zeros(S, dtype=bool) if unreachable is None else np.asarray(unreachable, dtype=bool)
    unr = unr & ~term
    live = ~term & ~unr
    lab = partition.labels
    return {
        "blocks": partition.n_blocks,
        "reachable": int(np.unique(lab[live]).size),
        "terminal": int(np.unique(lab[term]).size),
        "unreachable": int(np.unique(lab[unr]).size),
        "reachable_states": int(live.sum()),
        "terminal_states": int(term.sum()),
        "unreachable_states": int(unr.sum()),
        "singletons": int(np.sum(np.bincount(lab[live], minlength=partition.n_blocks) == 1)),
    }


def decision_view(partition: Partition, unreachable: np.ndarray | None) -> Partition:
    """The same blocks with the unreachable blocks offering nothing: the layer a checker audits.

    The unreachable blocks lump states that no policy of the layer visits, so they are not
    delta-stable and are not part of the decision layer. The checker (which checks only offered
    columns) then verifies the decision layer itself.
    """
    if unreachable is None or not np.any(unreachable):
        return partition
    adm = partition.admissible.copy()
    adm[np.unique(partition.labels[np.asarray(unreachable, dtype=bool)])] = False
    return partition.with_admissible(adm)


__all__ = [
    "REWARD_BASELINES",
    "as_mask",
    "decision_rewards",
    "decision_view",
    "layer_counts",
    "reachable_states",
    "resolve_baseline",
    "start_mask",
    "step_baseline",
    "terminal_columns",
    "zero_rows",
]
