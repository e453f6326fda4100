"""Experience: the primitive transitions an agent took, counted, and the model they estimate.

Section 4.1 learns the options "off-line" from what the agent learned in earlier tasks, and 4.2
performs phases 1-2 "prior to having knowledge of the specific task". Without the environment's
true model the only dynamics an agent has are its own steps. :class:`Experience` holds them as
counts ``N(s, a, s')`` in the layout of :class:`~adpart.mdp.model.FiniteMDP`'s transitions (an
``(A*S, S)`` CSR, row ``a*S + s``), and :meth:`Experience.estimate` turns them into the
maximum-likelihood model

    P^(s' | s, a) = N(s, a, s') / N(s, a)            for every pair tried at least once.

A pair never tried is **unknown**, and the estimate assumes the least of it: a self-loop (the
action leaves the agent where it is). That keeps it out of every option: a self-loop never
brings an option closer to its subgoal (it is worth ``gamma V(s) < V(s)`` wherever the subgoal
can be reached), so no option policy takes it and no option model runs through it; the
learner that plans on the estimate may still try it, and a state where nothing was ever tried
is one no option can start in, where the layer offers the primitive actions
(:mod:`adpart.workflows.partitioning`). A learned policy that takes an unknown pair (its
initial value can beat the tried ones) loops there in the estimate, which the subgoal
detectors handle as they handle any loop of a policy.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import cache, cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp

from adpart.errors import ModelError

__all__ = ["EXPERIENCE_COLUMNS", "Experience"]

#: The columns of an experience table (as the knowledge base stores it).
EXPERIENCE_COLUMNS = ("state", "action", "next_state", "count")


@dataclass(frozen=True, eq=False)
class Experience:
    """Counts of the transitions taken, ``counts[a*S + s, s'] = N(s, a, s')`` (module docstring).

    Attributes:
        counts: ``(A*S, S)`` CSR int64, action-major as :attr:`FiniteMDP.P`; no explicit zeros.
        sources: what the counts came from (run references), for the record.
    """

    counts: sp.csr_array
    sources: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        counts = sp.csr_array(self.counts, dtype=np.int64)
        counts.sum_duplicates()
        counts.eliminate_zeros()
        counts.sort_indices()
        rows, cols = counts.shape
        if cols <= 0 or rows % cols:
            raise ModelError(f"experience counts have shape {counts.shape}; they must be "
                             "(n_actions * n_states, n_states)")
        if counts.nnz and counts.data.min() < 0:
            raise ModelError("experience counts must be >= 0")
        object.__setattr__(self, "counts", counts)
        object.__setattr__(self, "sources", tuple(self.sources))

    # ------------------------------------------------------------------ construction
    @classmethod
    def empty(cls, n_states: int, n_actions: int) -> Experience:
        return cls(sp.csr_array((n_actions * n_states, n_states), dtype=np.int64))

    @classmethod
    def from_positions(cls, P: sp.csr_array, counts: np.ndarray,
                       sources: Iterable[str] = ()) -> Experience:
        """Counts kept per CSR entry of the transitions ``P`` (``counts[..., k]`` for entry
        ``k``; a leading axis, of runs or of a kernel's threads, is summed): how the lock-step
        kernels count the successor they draw. ``P`` supplies the layout (which entry is which
        ``s'``), never a value.

        One compiled pass sums the leading axis and keeps only the entries taken, so neither
        the summed ``(nnz,)`` vector nor a matrix of ``P``'s every entry (zeros eliminated
        after) is made; the result is the same matrix.
        """
        counts = np.asarray(counts)
        if counts.ndim == 1:
            counts = counts[None, :]
        if counts.ndim != 2 or counts.shape[1] != P.nnz:
            shape = counts.shape[1:] if counts.ndim == 2 and counts.shape[0] == 1 else counts.shape
            raise ModelError(f"{shape} counts for a transition matrix of {P.nnz} entries")
        counts = np.ascontiguousarray(counts, dtype=np.int64)
        data, indices, indptr = _compact()(counts, P.indptr, P.indices)
        if data.size and data.min() < 0:
            raise ModelError("experience counts must be >= 0")
        matrix = sp.csr_array((data, indices, indptr), shape=P.shape)
        if P.has_canonical_format:  # a subset of canonical rows, without zeros, in order
            matrix.has_canonical_format = True
            return cls._canonical(matrix, tuple(sources))
        return cls(matrix, tuple(sources))

    @classmethod
    def _canonical(cls, counts: sp.csr_array, sources: tuple[str, ...]) -> Experience:
        """An experience of counts already as ``__post_init__`` leaves them (int64 CSR,
        canonical, sorted, no zeros, none negative, shape ``(A*S, S)``), unchecked."""
        rows, cols = counts.shape
        if cols <= 0 or rows % cols or counts.dtype != np.int64:
            return cls(counts, sources)
        experience = object.__new__(cls)
        object.__setattr__(experience, "counts", counts)
        object.__setattr__(experience, "sources", tuple(sources))
        return experience

    @classmethod
    def from_table(cls, table: Any, n_states: int, n_actions: int,
                   sources: Iterable[str] = ()) -> Experience:
        """From columns ``state, action, next_state, count`` (a mapping of arrays or a pyarrow
        table), as :meth:`to_table` writes them."""
        cols = {c: np.asarray(table[c] if isinstance(table, Mapping) else
                              table.column(c).to_numpy(), dtype=np.int64)
                for c in EXPERIENCE_COLUMNS}
        s, a, s2, n = (cols[c] for c in EXPERIENCE_COLUMNS)
        for name, values, bound in (("state", s, n_states), ("action", a, n_actions),
                                    ("next_state", s2, n_states)):
            if values.size and (values.min() < 0 or values.max() >= bound):
                raise ModelError(f"experience column {name} has values outside [0, {bound})")
        matrix = sp.csr_array((n, (a * n_states + s, s2)),
                              shape=(n_actions * n_states, n_states))
        return cls(matrix, tuple(sources))

    @classmethod
    def merge(cls, parts: Iterable[Experience]) -> Experience:
        """All of ``parts``' steps together (same state and action sets)."""
        parts = list(parts)
        if not parts:
            raise ModelError("no experience to merge")
        shapes = {p.counts.shape for p in parts}
        if len(shapes) != 1:
            raise ModelError(f"experience of different state spaces {sorted(shapes)}")
        total = parts[0].counts.copy()
        for p in parts[1:]:
            total = total + p.counts
        return cls(total, tuple(s for p in parts for s in p.sources))

    def to_table(self) -> dict[str, np.ndarray]:
        """The nonzero counts as columns ``state, action, next_state, count`` (int64)."""
        coo = self.counts.tocoo()
        S = self.n_states
        return {"state": (coo.row % S).astype(np.int64), "action": (coo.row // S).astype(np.int64),
                "next_state": coo.col.astype(np.int64), "count": coo.data.astype(np.int64)}

    # ------------------------------------------------------------------ what is known
    @property
    def n_states(self) -> int:
        return int(self.counts.shape[1])

    @property
    def n_actions(self) -> int:
        return int(self.counts.shape[0] // self.counts.shape[1])

    @cached_property
    def pair_counts(self) -> np.ndarray:
        """``(S, A)`` ``N(s, a)``: how often each pair was tried."""
        return np.asarray(self.counts.sum(axis=1)).reshape(self.n_actions, self.n_states).T

    @property
    def tried(self) -> np.ndarray:
        """``(S, A)`` bool: the pairs tried at least once (the known ones)."""
        return self.pair_counts > 0

    @property
    def steps(self) -> int:
        """Transitions counted."""
        return int(self.counts.data.sum())

    def summary(self) -> dict[str, Any]:
        tried = self.tried
        return {"steps": self.steps, "pairs_tried": int(tried.sum()),
                "pairs": int(tried.size), "states_visited": int(tried.any(axis=1).sum()),
                "states": self.n_states, "sources": list(self.sources)}

    # ------------------------------------------------------------------ the estimate
    def estimate(self) -> sp.csr_array:
        """The maximum-likelihood transitions, ``(A*S, S)`` CSR float64, each unknown pair a
        self-loop (module docstring)."""
        S = self.n_states
        n_sa = self.pair_counts.T.reshape(-1).astype(np.float64)  # row a*S + s
        counts = self.counts
        row_of = np.repeat(np.arange(counts.shape[0]), np.diff(counts.indptr))
        probs = counts.data / n_sa[row_of]
        untried = np.flatnonzero(n_sa == 0)
        rows = np.concatenate([row_of, untried])
        cols = np.concatenate([counts.indices.astype(np.int64), untried % S])
        data = np.concatenate([probs, np.ones(untried.size)])
        return sp.csr_array((data, (rows, cols)), shape=counts.shape)


@cache
def _compact():
    """The kernel of :meth:`Experience.from_positions`, compiled by numba on first use."""
    import numba

    @numba.njit(cache=True, nogil=True, boundscheck=False)
    def compact(counts, indptr, indices):
        """Sum ``counts`` (T, nnz) over its rows and keep the nonzero entries as a CSR
        ``(data, indices, indptr)`` of ``indptr``'s rows, entries in their order there."""
        n_rows = indptr.shape[0] - 1
        data = np.empty(counts.shape[1], dtype=np.int64)
        kept = np.empty(counts.shape[1], dtype=indices.dtype)
        out_ptr = np.empty(n_rows + 1, dtype=indptr.dtype)
        out_ptr[0] = 0
        m = 0
        for row in range(n_rows):
            for k in range(indptr[row], indptr[row + 1]):
                c = 0
                for t in range(counts.shape[0]):
                    c += counts[t, k]
                if c != 0:
                    data[m] = c
                    kept[m] = indices[k]
                    m += 1
            out_ptr[row + 1] = m
        return data[:m].copy(), kept[:m].copy(), out_ptr

    return compact
