"""How sound the inconsistency test was: its firings checked against the task's exact ``Q*``.

Section 4.3.3 adds a primitive action to a block where its grounded value beats the block's by
more than ``L``. A firing is a **real** inconsistency when, at the firing state ``s``, the added
action ``a`` is worth more under the task's exact ``Q*`` than every column ``c`` the block offered
there,

    Q*(s, a) > max_c Q*(s, c) + tol,    Q*(s, c) = R(s, c) + sum_s' F(s' | s, c) V*(s'),

on the world's exact model of the columns (primitives first), ``tol = 1e-9 (1 + |V*(s)|)``; a
**tie** when it is worth as much within ``tol`` (the block already offered as good a column).
The audit reads the true model, so the learner calls it inside
:func:`~adpart.learning.knowledge.world` after learning: a score, never an input.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.mdp.solvers import solve

__all__ = ["firing_audit"]


def firing_audit(events: Sequence[dict], smdp: SMDPModel, mdp: FiniteMDP, runs: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Per run, how many of its firings (``events``: ``run``, ``state``, ``action`` and the
    block's ``offers`` at the firing) were real inconsistencies and how many were ties (module
    docstring). One solve for ``V*`` and one product ``F V*`` for every column's ``Q*``."""
    real, ties = np.zeros(runs, dtype=np.int64), np.zeros(runs, dtype=np.int64)
    if not events:
        return real, ties
    V = solve(mdp, 1e-10).V
    S, n_cols = smdp.R.shape
    Q = smdp.R + np.asarray(smdp.F @ V).reshape(n_cols, S).T  # (S, columns): Q*(s, c)
    run = np.array([e["run"] for e in events], dtype=np.int64)
    state = np.array([e["state"] for e in events], dtype=np.int64)
    action = np.array([e["action"] for e in events], dtype=np.int64)
    offered = np.zeros((len(events), n_cols), dtype=bool)
    for i, e in enumerate(events):
        offered[i, e["offers"]] = True
    best = np.where(offered, Q[state], -np.inf).max(axis=1)
    gap = Q[state, action] - best
    tol = 1e-9 * (1.0 + np.abs(V[state]))
    np.add.at(real, run[gap > tol], 1)
    np.add.at(ties, run[(gap <= tol) & (gap >= -tol)], 1)
    return real, ties
