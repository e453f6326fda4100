"""Stack options and their models into one :class:`~adpart.mdp.model.SMDPModel` (section 3.1).

The SMDP over a set of options ``O`` has the Bellman equation
``V(s) = max_{o in O, s in I_o} [R(s, o) + sum_s' F(s'|s, o) V(s')]`` with the discount inside
``F`` (eq. 3.2), which is exactly the form the core solvers work on: ``R`` becomes the ``(S, O)``
reward table, the option models' ``F`` rows are stacked option-major into ``(O*S, S)``, and the
admissible mask is the initiation sets. Primitive actions may be put in front (columns
``0..A-1``, the MDP's own one-step models), so that ``adpart.mdp.solvers.solve`` solves either
set unchanged.

Terminal states of the MDP get zero rows - ``R`` *and* ``F``, in every column - and every option
admissible (value 0, as in :meth:`FiniteMDP.as_smdp`). Zeroing ``F`` matters when the models were
computed under another task, whose terminal states differ: a row left there would let the value
of the new goal depend on the column a policy picks at it. Models for a new task should be that
task's (:func:`adpart.options.models.option_models` on the new MDP); the zeroing is the guard.
A non-terminal state where no option is admissible would get the value ``-inf``; stacking
refuses it and names the state.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from adpart.errors import ModelError
from adpart.mdp.model import SMDPModel
from adpart.mdp.solvers import q_from_v
from adpart.options.models import ItemMapper, OptionModel, option_models

if TYPE_CHECKING:
    from adpart.mdp.model import FiniteMDP
    from adpart.options.option import Option


def stack_models(
    mdp: FiniteMDP, models: list[OptionModel], *, include_primitives: bool | str
) -> SMDPModel:
    """The SMDP whose actions are the primitive actions (optionally) followed by ``models``.

    Args:
        include_primitives: ``False`` (options only), ``True`` (every primitive action wherever
            the MDP admits it) or ``"uncovered"``: primitive columns admissible only in the
            non-terminal states that no option's initiation set covers - the decision layer's
            fallback there (a subgoal is not in its own option's initiation set, so with few
            subgoals some states, the subgoals themselves, have no option to start). Offering
            primitives only there keeps them from refining the rest of the partition.

    Raises:
        ModelError: a model of the wrong size, or a non-terminal state with no admissible option.
    """
    if include_primitives not in (False, True, "uncovered"):
        raise ModelError(
            f"include_primitives must be False, True or 'uncovered'; got {include_primitives!r}"
        )
    S = mdp.n_states
    for m in models:
        if m.R.shape != (S,) or m.F.shape != (S, S):
            raise ModelError(
                f"model of option {m.name!r} covers {m.R.shape[0]} states; the MDP has {S}"
            )
    R_cols, F_blocks, adm_cols = [], [], []
    if include_primitives:
        prim = mdp.as_smdp()
        prim_adm = prim.admissible
        if include_primitives == "uncovered":
            covered = (
                np.stack([m.admissible for m in models], axis=1).any(axis=1)
                if models
                else np.zeros(S, dtype=bool)
            )
            prim_adm = prim_adm & ~(covered | mdp.terminal)[:, None]
        R_cols.append(np.where(prim_adm, prim.R, 0.0))
        F_blocks.append(sp.csr_array(sp.diags_array(prim_adm.T.reshape(-1).astype(float)) @ prim.F))
        adm_cols.append(prim_adm)
    if models:
        R_cols.append(np.stack([m.R for m in models], axis=1))
        F_blocks.extend(m.F for m in models)
        adm_cols.append(np.stack([m.admissible for m in models], axis=1))
    if not R_cols:
        raise ModelError("no options to stack; give option models or include_primitives=True")
    R = np.concatenate(R_cols, axis=1)
    live = sp.diags_array(np.tile(~mdp.terminal, R.shape[1]).astype(np.float64))
    F = sp.csr_array(live @ sp.vstack(F_blocks, format="csr"))
    F.eliminate_zeros()
    admissible = np.concatenate(adm_cols, axis=1)
    admissible[mdp.terminal] = True
    R[mdp.terminal] = 0.0
    uncovered = np.flatnonzero(~admissible.any(axis=1))
    if uncovered.size:
        raise ModelError(
            f"state {int(uncovered[0])} ({uncovered.size} in all) is in no option's initiation "
            "set; its value would be -inf. Add the primitive actions (include_primitives=True "
            "or 'uncovered') or options whose initiation sets cover it"
        )
    R.setflags(write=False)
    admissible.setflags(write=False)
    return SMDPModel(R=R, F=F, admissible=admissible)


def options_smdp(
    mdp: FiniteMDP,
    options: list[Option],
    *,
    include_primitives: bool,
    executor: ItemMapper | None = None,
) -> tuple[SMDPModel, list[OptionModel]]:
    """Exact models of ``options`` (through ``executor``) stacked into an SMDP."""
    models = option_models(mdp, options, executor=executor, duration=False)
    return stack_models(mdp, models, include_primitives=include_primitives), models


def sweeps_to_accuracy(
    model: SMDPModel, V_star: np.ndarray, *, rel_tol: float = 0.01, max_sweeps: int = 10_000
) -> tuple[int, list[np.ndarray]]:
    """Jacobi value-iteration sweeps from ``V = 0`` until ``|V - V*| <= rel_tol |V*|`` everywhere.

    This is the measure of Sutton, Precup & Singh (1999), Fig. 4: how many synchronous backups
    ``V <- max_o [R + F V]`` a model needs before every state's value is within ``rel_tol`` of
    its final value.

    Returns:
        ``(sweeps, [V_0, V_1, ..., V_sweeps])``.

    Raises:
        ModelError: if the accuracy is not reached within ``max_sweeps``.
    """
    V_star = np.asarray(V_star, dtype=np.float64)
    V = np.zeros(model.n_states)
    trace = [V]
    for k in range(1, max_sweeps + 1):  # sweeps, each vectorised over all states
        V = q_from_v(model, V).max(axis=1)
        trace.append(V)
        if np.all(np.abs(V - V_star) <= rel_tol * np.abs(V_star)):
            return k, trace
    raise ModelError(f"values not within {rel_tol:.0%} of V* after {max_sweeps} sweeps")
