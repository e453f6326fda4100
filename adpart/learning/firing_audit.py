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

A tie is counted again as an **own step** when the added action is what an option the block
offered would itself do first at ``s`` (its policy's action there): the firing then added no new
first move, only a decision point after it. On two-rooms 227 of 230 ties were such steps, and a
test that refused them was sounder (86 % real) but learned worse (docs/learned-model.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.mdp.solvers import solve

__all__ = ["FiringAudit", "firing_audit", "first_actions"]


@dataclass(frozen=True)
class FiringAudit:
    """Per run ``(runs,)`` int64 counts: ``real`` inconsistencies, ``ties``, and the ties that
    were an offered option's ``own_step`` (module docstring)."""

    real: np.ndarray
    ties: np.ndarray
    own_step: np.ndarray


def first_actions(columns: Sequence, n_states: int, n_actions: int) -> np.ndarray:
    """``(columns, S)`` int64: the primitive action each column takes first at each state
    (primitive columns ``0..A-1`` first, then the options ``columns``; ``-1`` where an option
    is undefined or stochastic there)."""
    out = np.full((n_actions + len(columns), n_states), -1, dtype=np.int64)
    out[:n_actions] = np.arange(n_actions)[:, None]
    for j, option in enumerate(columns):
        policy = np.asarray(option.policy)
        if policy.ndim == 1:
            out[n_actions + j] = policy
        else:  # a deterministic row of probabilities is that action; a mixed one is none
            sure = policy.max(axis=1) >= 1.0
            out[n_actions + j] = np.where(sure, policy.argmax(axis=1), -1)
    return out


def firing_audit(events: Sequence[dict], smdp: SMDPModel, mdp: FiniteMDP, runs: int,
                 first: np.ndarray | None = None) -> FiringAudit:
    """Per run, how many of its firings (``events``: ``run``, ``state``, ``action`` and the
    block's ``offers`` at the firing) were real inconsistencies, how many were ties, and how many
    ties an offered option's own first step (``first``: :func:`first_actions` of the columns;
    None: not counted). One solve for ``V*`` and one product ``F V*`` for every column's
    ``Q*``."""
    real, ties = np.zeros(runs, dtype=np.int64), np.zeros(runs, dtype=np.int64)
    own = np.zeros(runs, dtype=np.int64)
    if not events:
        return FiringAudit(real, ties, own)
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
    tie = (gap <= tol) & (gap >= -tol)
    np.add.at(real, run[gap > tol], 1)
    np.add.at(ties, run[tie], 1)
    if first is not None:  # some offered column's first move at s is the added action
        own_step = (offered & (first[:, state].T == action[:, None])).any(axis=1)
        np.add.at(own, run[tie & own_step], 1)
    return FiringAudit(real, ties, own)
