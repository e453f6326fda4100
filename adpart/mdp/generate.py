"""Generated MDPs for benchmarks and property tests: stochastic grids and random sparse MDPs.

Both generators are fully vectorised (no Python loop over states or transitions), draw every
random number from one seeded :class:`numpy.random.Generator`, and return a validated
:class:`~adpart.mdp.model.FiniteMDP` in the action-major layout of DESIGN.md ("Core data model"):
one CSR of shape ``(A*S, S)`` whose row ``a*S + s`` is ``P(. | s, a)``.

* :func:`random_grid_mdp` is the benchmark workload of ``benchmarks/bench_value_iteration.py``:
  a slippery grid world of any size (``10**6`` cells build in about a second), whose transition
  structure is that of the navigation domains of the dissertation (chapter 6) without walls.
* :func:`random_mdp` is a small dense-ish random MDP for property tests of the solvers.
* :func:`empirical_model` is a model estimated from ``n`` sampled successors of every pair: what a
  certainty-equivalent learner would plan on after that many tries (the arm's sample limit in
  docs/hierarchical-learning.md).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from adpart.errors import ModelError
from adpart.mdp.model import FiniteMDP

#: Grid moves as (row change, column change), in action order.
GRID_MOVES = ((-1, 0), (0, 1), (1, 0), (0, -1))
GRID_ACTION_NAMES = ("north", "east", "south", "west")


def _check_count(value: object, what: str, low: int = 1) -> int:
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < low:
        raise ModelError(f"{what} = {value!r} must be an integer >= {low}")
    return int(value)


def _check_gamma(gamma: float) -> float:
    if not (isinstance(gamma, (int, float, np.floating)) and 0.0 < float(gamma) <= 1.0):
        raise ModelError(f"gamma = {gamma!r} is outside (0, 1]; pass a discount such as 0.95")
    return float(gamma)


def grid_shape(n_states: int) -> tuple[int, int]:
    """``(height, width)`` of the square-ish grid holding exactly ``n_states`` cells.

    The width is ``ceil(sqrt(n_states))``; cells are numbered row-major, so the last row may be
    partial (its missing cells simply do not exist and act like walls).
    """
    n = _check_count(n_states, "n_states")
    width = math.isqrt(n - 1) + 1 if n > 1 else 1
    return -(-n // width), width


def _canonical_csr(cols: np.ndarray, probs: np.ndarray, n_cols: int) -> sp.csr_array:
    """CSR from ``k`` candidate ``(column, probability)`` pairs per row, duplicates merged.

    ``cols`` and ``probs`` are ``(rows, k)``. Sorting each row's columns and adding the mass of
    repeated columns onto their first occurrence yields sorted, duplicate-free rows directly, so
    the :class:`FiniteMDP` constructor's canonicalisation has nothing left to do.
    """
    n_rows, k = cols.shape
    order = np.argsort(cols, axis=1, kind="stable")
    cols = np.take_along_axis(cols, order, axis=1)
    probs = np.take_along_axis(probs, order, axis=1)
    first = np.ones((n_rows, k), dtype=bool)
    first[:, 1:] = cols[:, 1:] != cols[:, :-1]
    # Group id of each entry within its row: entries of one column share the first's slot.
    flat_first = first.ravel()
    group = np.cumsum(flat_first) - 1
    data = np.bincount(group, weights=probs.ravel(), minlength=int(flat_first.sum()))
    indices = cols.ravel()[flat_first].astype(np.int32)
    indptr = np.zeros(n_rows + 1, dtype=np.int64)
    np.cumsum(first.sum(axis=1), out=indptr[1:])
    if indptr[-1] < np.iinfo(np.int32).max:
        indptr = indptr.astype(np.int32)
    matrix = sp.csr_array((data, indices, indptr), shape=(n_rows, n_cols))
    matrix.has_canonical_format = True
    matrix.has_sorted_indices = True
    return matrix


def random_grid_mdp(
    n_states: int,
    *,
    n_actions: int = 4,
    slip: float = 0.2,
    gamma: float = 0.95,
    seed: int = 0,
    terminal_fraction: float = 0.0,
) -> FiniteMDP:
    """A slippery grid world with ``n_states`` cells and seeded random rewards.

    Dynamics: action ``a`` (the first ``n_actions`` of north, east, south, west) moves in its
    intended direction with probability ``1 - slip`` and to each of the two perpendicular
    directions with probability ``slip / 2``; a move off the grid (or onto a missing cell of the
    last row) leaves the agent where it is. Every row therefore has at most three successors.

    Rewards ``R[s, a]`` are i.i.d. standard normal; ``terminal_fraction`` of the states (chosen
    at random) are terminal, which ends the episode on arrival and makes the solvers use the
    sup-norm stopping rule instead of the span rule (the discount is no longer uniform).

    Args:
        n_states: number of cells (>= 1); the grid is :func:`grid_shape` of it.
        n_actions: 1 to 4 moves.
        slip: probability of slipping sideways, in ``[0, 1]``.
        gamma: discount factor in ``(0, 1]``.
        seed: seed of the :class:`numpy.random.Generator` drawing rewards and terminal states.
        terminal_fraction: fraction of terminal states, in ``[0, 1)``.

    Returns:
        A validated :class:`FiniteMDP` with features ``row`` and ``col``.
    """
    n = _check_count(n_states, "n_states")
    n_act = _check_count(n_actions, "n_actions")
    if n_act > len(GRID_MOVES):
        raise ModelError(f"n_actions = {n_act} but a grid has only 4 moves; use 1 to 4")
    if not (np.isfinite(slip) and 0.0 <= slip <= 1.0):
        raise ModelError(f"slip = {slip!r} must be a probability in [0, 1]")
    if not (np.isfinite(terminal_fraction) and 0.0 <= terminal_fraction < 1.0):
        raise ModelError(f"terminal_fraction = {terminal_fraction!r} must be in [0, 1)")
    g = _check_gamma(gamma)
    rng = np.random.default_rng(seed)
    height, width = grid_shape(n)
    states = np.arange(n, dtype=np.int64)
    row, col = states // width, states % width

    def step(move: int) -> np.ndarray:
        dr, dc = GRID_MOVES[move]
        r, c = row + dr, col + dc
        target = r * width + c
        inside = (r >= 0) & (r < height) & (c >= 0) & (c < width) & (target < n)
        return np.where(inside, target, states)

    successors = [step(m) for m in range(len(GRID_MOVES))]
    cols = np.empty((n_act, n, 3), dtype=np.int64)
    for a in range(n_act):  # loop over the <= 4 actions only; every state at once
        cols[a, :, 0] = successors[a]
        cols[a, :, 1] = successors[(a + 1) % 4]
        cols[a, :, 2] = successors[(a + 3) % 4]
    probs = np.broadcast_to(np.array([1.0 - slip, slip / 2.0, slip / 2.0]), (n_act * n, 3))
    P = _canonical_csr(cols.reshape(n_act * n, 3), np.ascontiguousarray(probs), n)
    R = rng.standard_normal((n, n_act))
    terminal = np.zeros(n, dtype=bool)
    n_term = round(terminal_fraction * n)
    if n_term:
        terminal[rng.choice(n, size=min(n_term, n - 1), replace=False)] = True
    return FiniteMDP(
        P,
        R,
        g,
        terminal=terminal,
        features={"row": row, "col": col},
        action_names=GRID_ACTION_NAMES[:n_act],
        name=f"random-grid-{n}",
    )


def random_mdp(
    n_states: int,
    n_actions: int,
    *,
    density: float,
    seed: int,
    gamma: float = 0.9,
) -> FiniteMDP:
    """A random sparse MDP for property tests.

    Each ``(s, a)`` row gets ``1 + Binomial(n_states - 1, density)`` successor draws (uniform
    columns, duplicates merged) with uniform(0.05, 1) weights normalised to one, so every row is a
    distribution with at least one successor. Rewards are i.i.d. standard normal.

    Args:
        n_states, n_actions: sizes (>= 1).
        density: expected fraction of extra successors per row, in ``[0, 1]``.
        seed: seed of the :class:`numpy.random.Generator`.
        gamma: discount factor in ``(0, 1]``.
    """
    n = _check_count(n_states, "n_states")
    n_act = _check_count(n_actions, "n_actions")
    if not (np.isfinite(density) and 0.0 <= density <= 1.0):
        raise ModelError(f"density = {density!r} must be in [0, 1]")
    g = _check_gamma(gamma)
    rng = np.random.default_rng(seed)
    n_rows = n_act * n
    counts = 1 + rng.binomial(n - 1, density, size=n_rows)
    rows = np.repeat(np.arange(n_rows), counts)
    cols = rng.integers(0, n, size=rows.size)
    weights = rng.uniform(0.05, 1.0, size=rows.size)
    P = sp.csr_array(sp.coo_array((weights, (rows, cols)), shape=(n_rows, n)))
    P.sum_duplicates()
    totals = np.asarray(P.sum(axis=1)).ravel()
    P = sp.csr_array(sp.diags_array(1.0 / totals) @ P)
    R = rng.standard_normal((n, n_act))
    return FiniteMDP(P, R, g, name=f"random-{n}x{n_act}")


def empirical_model(mdp: FiniteMDP, samples_per_pair: int, rng: np.random.Generator) -> FiniteMDP:
    """``mdp`` with each admissible, non-terminal pair's row replaced by the empirical distribution
    of ``samples_per_pair`` successors drawn from it (:meth:`FiniteMDP.sample_next`).

    Rewards, terminals, admissibility and the other rows are ``mdp``'s. The row of a
    deterministic pair is therefore exact for any count, and every estimated row's support lies
    in the true one.
    """
    n = _check_count(samples_per_pair, "samples_per_pair")
    S = mdp.n_states
    sampled = mdp.admissible & ~mdp.terminal[:, None]
    states, actions = np.nonzero(sampled)
    succ = mdp.sample_next(np.repeat(states, n), np.repeat(actions, n), rng)
    drawn = sp.coo_array((np.full(succ.size, 1.0 / n), (np.repeat(actions * S + states, n), succ)),
                         shape=mdp.P.shape)
    kept = sp.diags_array(np.where(sampled.T.reshape(-1), 0.0, 1.0)) @ mdp.P
    P = sp.csr_array(drawn.tocsr() + kept)
    P.sum_duplicates()
    return FiniteMDP(P, mdp.R, mdp.gamma, terminal=mdp.terminal, admissible=mdp.admissible,
                     initial=mdp.initial, features=mdp.features, action_names=mdp.action_names,
                     name=f"{mdp.name}-empirical-{n}")
