"""Fast exact lumping (delta = epsilon = 0): the coarsest stochastic bisimulation, actions matched.

Two states share a block exactly when, for every selected option ``o`` (matched one to one, not
existentially), they agree on admissibility, on ``R(s, o)`` (unless rewards are ignored) and on the
mass ``F(B | s, o)`` into every block ``B`` - definition 4.4 with ``delta = epsilon = 0``, which is
stochastic bisimulation / ordinary lumpability (Dean & Givan; section 3.2.2).

The refinement is a splitter worklist in the style of Paige-Tarjan, Derisavi-Hermanns-Sanders and
Valmari-Franceschinis (2010, "Simple O(m log n) time Markov chain lumping"): popping a block ``C``
touches only the predecessors of ``C``; blocks are split by their accumulated masses into ``C``, and
a block that was not waiting enqueues all its parts but the largest. There are no full re-signing
rounds, so the cost does not grow with the diameter of the transition graph. The inner loop is the
numba kernel :func:`adpart.partition._kernels.lump`.

Masses within ``atol`` (default 1e-9) of each other count as equal; the result agrees with
:func:`adpart.partition.refine.refine` at ``delta = epsilon = 0`` and with Storm's bisimulation
(``benchmarks/bench_partition.py``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from adpart.errors import ModelError
from adpart.mdp.model import SMDPModel
from adpart.partition._kernels import index_labels, lump, predecessors_by_option
from adpart.partition._validate import (
    DEFAULT_ATOL,
    as_model,
    check_atol,
    check_partition_fits,
    check_rewards,
    require_cover,
    select_options,
    selected_admissible,
)
from adpart.partition.partition import (
    Partition,
    block_all,
    canonical_labels,
    combine_labels,
    row_codes,
)
from adpart.partition.refine import model_predecessors, reward_split


def exact_lumping(
    model: SMDPModel | object,
    *,
    initial: Partition | None = None,
    options: Sequence[int] | np.ndarray | None = None,
    use_rewards: bool = True,
    rewards: np.ndarray | None = None,
    atol: float = DEFAULT_ATOL,
    require_admissible: bool = True,
) -> Partition:
    """The coarsest exact lumping of ``model`` that refines ``initial``.

    Args:
        model: an :class:`SMDPModel` (options) or a FiniteMDP (primitive actions).
        initial: the partition to refine (default: one block).
        options: the options the lumping must respect (default: all).
        use_rewards: whether equal rewards ``R(s, o)`` are required (eq. 4.7 with epsilon = 0);
            False gives the reward-independent lumping of phases 1-2.
        rewards: ``(S, O)`` task rewards (default: the model's ``R``).
        atol: masses and rewards within ``atol`` count as equal.
        require_admissible: raise when a state has no selected admissible option.

    Returns:
        A canonical :class:`Partition`; ``admissible`` offers the selected options.
    """
    smdp = as_model(model)
    tol = check_atol(atol)
    S = smdp.n_states
    sel = select_options(smdp, options)
    adm = selected_admissible(smdp, sel)
    if require_admissible:
        require_cover(adm, sel)
    if initial is None:
        start = np.zeros(S, dtype=np.int64)
    elif isinstance(initial, Partition):
        check_partition_fits(initial.labels, S, "initial partition")
        start = initial.labels
    else:
        raise ModelError(f"initial must be a Partition or None, got {type(initial).__name__}")
    labels = combine_labels(start, row_codes(adm[:, sel]))
    if use_rewards:
        R = check_rewards(smdp.R if rewards is None else rewards, smdp)
        labels = canonical_labels(reward_split(labels, R, adm, sel, tol))
    # the masked rows' predecessor lists straight from the model (no masked copy of F)
    keep = adm[:, sel]
    keep = None if keep.all() else keep
    labels = lump_lists(labels, model_predecessors(smdp, sel, None, keep), sel.size, tol)
    n_blocks = int(labels.max()) + 1
    return Partition(labels, block_all(labels, n_blocks, adm))


def lump_labels(labels: np.ndarray, F: sp.csr_array, k: int, atol: float) -> np.ndarray:
    """Canonical labels of the coarsest lumping of stacked rows ``F`` (``(k*S, S)``).

    The result refines ``labels``.
    """
    F = sp.csr_array(F)
    return lump_lists(labels, predecessors_by_option(labels.size, k, F.indptr, F.indices, F.data),
                      k, atol)


def lump_lists(labels: np.ndarray, preds: tuple[np.ndarray, ...], k: int,
               atol: float) -> np.ndarray:
    """Canonical labels of the coarsest lumping of the ``k`` options whose predecessor lists
    (:func:`adpart.partition._kernels.predecessor_fill`) are ``preds``; it refines ``labels``."""
    out, _ = lump(labels.size, k, *preds, index_labels(labels), int(labels.max()) + 1,
                  float(atol))
    return canonical_labels(out)
