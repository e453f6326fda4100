"""Validation shared by the partition refiners, the checker and the multi-phase construction.

Everything a user can get wrong is checked here once, at the public boundary, and reported as an
:class:`adpart.errors.ModelError` naming the problem and the fix (ground rules; definition 4.4 fixes
``0 <= delta <= 1`` and ``epsilon >= 0``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from adpart.errors import ModelError
from adpart.mdp.model import SMDPModel
from adpart.partition.settings import DEFAULT_ATOL  # noqa: F401 (declared with the settings)


def as_model(model: object) -> SMDPModel:
    """The SMDP form of ``model`` (an SMDPModel, or anything with ``as_smdp()``), checked."""
    if model is None:
        raise ModelError(
            "no option models were given; pass an SMDPModel (options) or a FiniteMDP "
            "(primitive actions, via mdp.as_smdp())"
        )
    smdp = model.as_smdp() if hasattr(model, "as_smdp") else model
    if not isinstance(smdp, SMDPModel):
        raise ModelError(
            f"expected an SMDPModel or a FiniteMDP, got {type(model).__name__}; compute the "
            "options' models first (adpart.options) or pass mdp.as_smdp()"
        )
    S, n_opt = smdp.R.shape if smdp.R.ndim == 2 else (None, None)
    if S is None:
        raise ModelError(f"model rewards R must be (S, O); got shape {smdp.R.shape}")
    if not sp.issparse(smdp.F) or smdp.F.shape != (n_opt * S, S):
        raise ModelError(
            f"model F has shape {getattr(smdp.F, 'shape', None)}; expected a sparse "
            f"(O*S, S) = ({n_opt * S}, {S}) matrix with row o*S + s = F(. | s, o)"
        )
    if smdp.admissible.shape != (S, n_opt) or smdp.admissible.dtype != bool:
        raise ModelError(
            f"model admissible mask has dtype {smdp.admissible.dtype} and shape "
            f"{smdp.admissible.shape}; expected bool ({S}, {n_opt})"
        )
    return smdp


def check_delta(delta: object) -> float:
    """Definition 4.4: ``0 <= delta <= 1``."""
    if isinstance(delta, bool) or not isinstance(delta, (int, float, np.floating, np.integer)):
        raise ModelError(f"delta = {delta!r} must be a number in [0, 1]")
    d = float(delta)
    if not (np.isfinite(d) and 0.0 <= d <= 1.0):
        raise ModelError(
            f"delta = {delta!r} is outside [0, 1]; it bounds a difference of transition masses "
            "(eq. 4.6), so use e.g. 0 for exact lumping or 0.3"
        )
    return d


def check_epsilon(epsilon: object) -> float | None:
    """Definition 4.4: ``epsilon >= 0`` (None = ignore rewards)."""
    if epsilon is None:
        return None
    if isinstance(epsilon, bool) or not isinstance(epsilon, (int, float, np.floating, np.integer)):
        raise ModelError(f"epsilon = {epsilon!r} must be a number >= 0 (or None to ignore rewards)")
    e = float(epsilon)
    if not (np.isfinite(e) and e >= 0.0):
        raise ModelError(
            f"epsilon = {epsilon!r} is negative or not finite; it bounds a difference of rewards "
            "(eq. 4.7) and must be >= 0"
        )
    return e


def check_atol(atol: object) -> float:
    a = float(atol)  # type: ignore[arg-type]
    if not (np.isfinite(a) and a >= 0.0):
        raise ModelError(f"atol = {atol!r} must be a finite number >= 0")
    return a


def select_options(model: SMDPModel, options: Sequence[int] | np.ndarray | None) -> np.ndarray:
    """Sorted unique option indices (all options when None), each checked against the model."""
    n_opt = model.n_actions
    if options is None:
        return np.arange(n_opt, dtype=np.int64)
    sel = np.asarray(list(options) if not isinstance(options, np.ndarray) else options)
    if sel.dtype == bool:
        if sel.shape != (n_opt,):
            raise ModelError(f"an option mask must have shape ({n_opt},); got {sel.shape}")
        sel = np.flatnonzero(sel)
    if sel.size == 0:
        raise ModelError("the option set is empty; select at least one option")
    if not np.issubdtype(sel.dtype, np.integer):
        raise ModelError(
            f"options must be integer indices into the model's {n_opt} options; got {sel!r}"
        )
    bad = sel[(sel < 0) | (sel >= n_opt)]
    if bad.size:
        raise ModelError(
            f"option index {int(bad[0])} has no model: the model holds options 0..{n_opt - 1}; "
            "compute its model first or drop it from the option set"
        )
    return np.unique(sel).astype(np.int64)


def selected_admissible(model: SMDPModel, options: np.ndarray) -> np.ndarray:
    """``(S, O)`` the model's initiation sets with unselected options switched off.

    ``options`` are :func:`select_options`'s (sorted, distinct); when they are all the model's,
    this is the model's own table, not a copy: read it only.
    """
    if options.size == model.n_actions:
        return model.admissible
    adm = np.zeros_like(model.admissible)
    adm[:, options] = model.admissible[:, options]
    return adm


def require_cover(adm: np.ndarray, options: np.ndarray) -> None:
    """Every state needs an admissible option in the selected set (else no decision there)."""
    orphan = np.flatnonzero(~adm.any(axis=1))
    if orphan.size:
        raise ModelError(
            f"the option set {options.tolist()} leaves {orphan.size} state(s) with no admissible "
            f"option (first: state {int(orphan[0])}); add an option whose initiation set covers "
            "them, or the primitive actions"
        )


def check_rewards(rewards: object, model: SMDPModel) -> np.ndarray:
    R = np.asarray(rewards, dtype=np.float64)
    if R.shape != model.R.shape:
        raise ModelError(
            f"task rewards have shape {R.shape}; expected (S, O) = {model.R.shape}, one "
            "discounted reward R(s, o) per state and option"
        )
    if not np.all(np.isfinite(R)):
        raise ModelError("task rewards contain NaN or infinite values")
    return R


def check_partition_fits(labels: np.ndarray, n_states: int, what: str = "partition") -> None:
    if labels.shape != (n_states,):
        raise ModelError(
            f"{what} has {labels.size} states but the model has {n_states}; partition the "
            "model's own state space"
        )


def masked_rows(model: SMDPModel, options: np.ndarray, adm: np.ndarray,
                states: np.ndarray | None = None) -> sp.csr_array:
    """``(k*S, S)`` CSR of the selected options' rows, zero where the option is not admissible.

    With ``states`` only those states' rows are filled (the rest are empty): the rows one block
    needs when it alone is refined, gathered without stacking the options' whole tables.
    """
    S, n_opt = model.n_states, model.n_actions
    if states is not None:
        states = np.unique(np.asarray(states, dtype=np.int64))
        options = np.asarray(options, dtype=np.int64)
        return block_rows(model, options, states, adm[states][:, options])
    F = sp.csr_array(model.F)
    if not np.array_equal(options, np.arange(n_opt)):
        F = sp.csr_array(sp.vstack([F[int(o) * S:(int(o) + 1) * S] for o in options], format="csr"))
    if not adm[:, options].all():
        keep = adm[:, options].T.ravel()
        data = F.data * np.repeat(keep, np.diff(F.indptr))
        F = sp.csr_array((data, F.indices.copy(), F.indptr.copy()), shape=F.shape)
        F.eliminate_zeros()
    return F


def block_rows(model: SMDPModel, options: np.ndarray, states: np.ndarray,
               adm: np.ndarray) -> sp.csr_array:
    """:func:`masked_rows` restricted to ``states`` (sorted, distinct): row ``j*S + s`` is
    ``F[options[j]*S + s]`` for the ``i``-th of ``states`` where ``adm[i, j]`` (``(m, k)``, the
    states' own admissibility), every other row is empty."""
    F = model.F if isinstance(model.F, sp.csr_array) else sp.csr_array(model.F)
    S = model.n_states
    keep = np.asarray(adm, dtype=bool).T  # (k, m)
    src = (options[:, None] * S + states[None, :])[keep]
    dst = (np.arange(options.size, dtype=np.int64)[:, None] * S + states[None, :])[keep]
    # the source rows' entries, in the destination's order (one gather, no sparse indexing)
    starts = F.indptr[src].astype(np.int64)
    lengths = F.indptr[src + 1] - starts
    entries = np.repeat(starts - (np.cumsum(lengths) - lengths), lengths) + np.arange(
        int(lengths.sum()), dtype=np.int64)
    counts = np.zeros(options.size * S, dtype=np.int64)
    counts[dst] = lengths
    out = sp.csr_array((F.data[entries], F.indices[entries], np.r_[0, np.cumsum(counts)]),
                       shape=(options.size * S, F.shape[1]))
    out.eliminate_zeros()
    return out
