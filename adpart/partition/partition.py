"""The Partition of a state space into blocks, with per-block admissible options.

A partition (dissertation section 3.2.2, definition 3.2; section 4.2) is stored as one int64 label
per state, ``labels[s] = b`` in ``0..B-1``, in *canonical* form: blocks are numbered in the order of
their smallest state, so two partitions are equal exactly when their label arrays are equal.

Each block also carries the options that may be chosen in it, ``admissible`` of shape ``(B, O)``:
the decision layer of section 4.3.3 learns Q over (block, option) pairs and may add an option to one
block when flat and abstract values disagree, so admissibility is a property of the block, not only
of its states. Built from a model it is the AND over the block's states of the model's initiation
sets (an option is offered in a block when every state of the block may start it).

Operations (DESIGN.md, "Partition"): :meth:`Partition.intersect` (the phase-2 product of
section 4.2.1.2: a block is the vector of the operands' block indices), :meth:`Partition.refine_by`
(intersect with any labelling), :meth:`Partition.split_block` (replace one block by sub-blocks),
:meth:`Partition.is_refinement_of`, and :meth:`Partition.map_values` (move Q or V tables from a
coarser partition to this one: every child block inherits its parent's values).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adpart.errors import ModelError
from adpart.partition._kernels import first_seen_labels


def canonical_labels(labels: np.ndarray) -> np.ndarray:
    """Relabel blocks ``0..B-1`` in the order of their smallest state (vectorised).

    Any integer labelling (or any array whose equal entries mean "same block") is accepted.
    """
    labels = np.asarray(labels)
    if labels.size == 0:
        return np.zeros(0, dtype=np.int64)
    flat = labels.reshape(-1)
    if flat.dtype.kind in "iu" and flat.min() >= 0 and flat.max() < 4 * flat.size:
        # small non-negative ints: one compiled pass in state order, no sort of S
        return first_seen_labels(flat, int(flat.max()) + 1)
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(first.size, dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(first.size, dtype=np.int64)
    return rank[inverse.reshape(-1)]


def combine_labels(*columns: np.ndarray) -> np.ndarray:
    """Canonical labels of the intersection of several labellings (the product partition).

    States share a block of the result exactly when they share a block in every column.
    """
    if not columns:
        raise ModelError("combine_labels needs at least one labelling")
    out = canonical_labels(np.asarray(columns[0]).reshape(-1))
    for col in columns[1:]:
        other = canonical_labels(np.asarray(col).reshape(-1))
        out = canonical_labels(out * (int(other.max()) + 1) + other)
    return out


def row_codes(mask: np.ndarray) -> np.ndarray:
    """Canonical labels of the distinct rows of a boolean ``(S, k)`` matrix (e.g. admissibility)."""
    mask = np.asarray(mask, dtype=bool)
    if mask.shape[1] == 0:
        return np.zeros(mask.shape[0], dtype=np.int64)
    if mask.shape[1] <= 62:
        code = mask.astype(np.int64) @ (np.int64(1) << np.arange(mask.shape[1], dtype=np.int64))
        return canonical_labels(code)
    packed = np.packbits(mask, axis=1)
    return canonical_labels(np.unique(packed, axis=0, return_inverse=True)[1].reshape(-1))


def block_all(labels: np.ndarray, n_blocks: int, mask: np.ndarray) -> np.ndarray:
    """``(B, O)``: whether ``mask[s, o]`` holds for every state ``s`` of each block."""
    mask = np.asarray(mask, dtype=bool)
    labels = np.asarray(labels)
    counts = np.bincount(labels, minlength=n_blocks)
    out = np.ones((n_blocks, mask.shape[1]), dtype=bool)  # an empty block: vacuously all
    full = np.flatnonzero(counts)
    if full.size and mask.shape[1]:
        # one AND-reduction per block over its rows, the rows grouped by block (no np.add.at,
        # which costs ~1 s for 10^6 states x 20 options)
        starts = (np.cumsum(counts) - counts)[full]
        order = np.argsort(labels, kind="stable")
        out[full] = np.logical_and.reduceat(mask[order], starts, axis=0)
    return out


@dataclass(frozen=True, eq=False)
class Partition:
    """A partition of ``S`` states into ``B`` blocks with per-block admissible options.

    Attributes:
        labels: ``(S,)`` int64 canonical block index of every state.
        admissible: ``(B, O)`` bool, the options offered in each block.
    """

    labels: np.ndarray
    admissible: np.ndarray

    def __init__(self, labels: object, admissible: object) -> None:
        lab = np.asarray(labels)
        if lab.ndim != 1 or lab.size == 0:
            raise ModelError(
                f"partition labels must be a non-empty 1-D array; got shape {lab.shape}"
            )
        if not np.issubdtype(lab.dtype, np.integer):
            raise ModelError(f"partition labels must be integers, got dtype {lab.dtype}")
        canon = canonical_labels(lab)
        if not np.array_equal(canon, lab):
            raise ModelError(
                "partition labels are not canonical (blocks numbered 0..B-1 by first state); "
                "build partitions with Partition.from_labels"
            )
        n_blocks = int(canon.max()) + 1
        adm = np.asarray(admissible)
        if adm.dtype != bool or adm.ndim != 2 or adm.shape[0] != n_blocks:
            raise ModelError(
                f"admissible must be a boolean (n_blocks, n_options) = ({n_blocks}, O) array; "
                f"got dtype {adm.dtype} and shape {adm.shape}"
            )
        canon.setflags(write=False)
        adm = adm.copy()
        adm.setflags(write=False)
        object.__setattr__(self, "labels", canon)
        object.__setattr__(self, "admissible", adm)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_canonical(cls, labels: np.ndarray, admissible: np.ndarray) -> Partition:
        """A partition from labels the caller computed canonically, unchecked (the learner's
        per-firing refinement: the check would relabel every state once more)."""
        part = object.__new__(cls)
        labels = np.array(labels, dtype=np.int64)
        labels.setflags(write=False)
        adm = np.array(admissible, dtype=bool)
        adm.setflags(write=False)
        object.__setattr__(part, "labels", labels)
        object.__setattr__(part, "admissible", adm)
        return part

    @classmethod
    def from_labels(cls, labels: object, state_admissible: object) -> Partition:
        """A partition from any labelling; block admissibility = AND of ``state_admissible``.

        Args:
            labels: ``(S,)`` integer labels (any values; equal values = same block).
            state_admissible: ``(S, O)`` bool, e.g. ``model.admissible`` (initiation sets).
        """
        lab = np.asarray(labels)
        adm = np.asarray(state_admissible)
        if lab.ndim != 1 or lab.size == 0 or not np.issubdtype(lab.dtype, np.integer):
            raise ModelError(
                f"labels must be a non-empty 1-D integer array; got dtype {lab.dtype}, shape "
                f"{lab.shape}"
            )
        if adm.dtype != bool or adm.ndim != 2 or adm.shape[0] != lab.size:
            raise ModelError(
                f"state_admissible must be a boolean (S, O) array with S = {lab.size}; got dtype "
                f"{adm.dtype} and shape {adm.shape}"
            )
        canon = canonical_labels(lab)
        n_blocks = int(canon.max()) + 1
        return cls(canon, block_all(canon, n_blocks, adm))

    @classmethod
    def trivial(cls, state_admissible: object) -> Partition:
        """One block holding every state."""
        adm = np.asarray(state_admissible)
        if adm.ndim != 2:
            raise ModelError(f"state_admissible must be (S, O); got shape {adm.shape}")
        return cls.from_labels(np.zeros(adm.shape[0], dtype=np.int64), adm)

    # ------------------------------------------------------------------ properties
    @property
    def n_states(self) -> int:
        return self.labels.size

    @property
    def n_blocks(self) -> int:
        return self.admissible.shape[0]

    @property
    def n_options(self) -> int:
        return self.admissible.shape[1]

    @property
    def sizes(self) -> np.ndarray:
        """``(B,)`` number of states per block."""
        return np.bincount(self.labels, minlength=self.n_blocks)

    def members(self, block: int) -> np.ndarray:
        """The states of one block, ascending."""
        self._check_block(block)
        return np.flatnonzero(self.labels == block)

    def state_admissible(self) -> np.ndarray:
        """``(S, O)`` the block admissibility broadcast to every state."""
        return self.admissible[self.labels]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Partition):
            return NotImplemented
        return (
            np.array_equal(self.labels, other.labels)
            and self.admissible.shape == other.admissible.shape
            and np.array_equal(self.admissible, other.admissible)
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return (
            f"Partition(n_states={self.n_states}, n_blocks={self.n_blocks}, "
            f"n_options={self.n_options})"
        )

    def _check_block(self, block: int) -> None:
        if not (isinstance(block, (int, np.integer)) and 0 <= block < self.n_blocks):
            raise ModelError(f"block {block!r} does not exist; blocks are 0..{self.n_blocks - 1}")

    def _check_same_states(self, other: Partition, what: str) -> None:
        if other.n_states != self.n_states:
            raise ModelError(
                f"cannot {what} partitions of {self.n_states} and {other.n_states} states; "
                "both must partition the same state space"
            )

    # ------------------------------------------------------------------ operations
    def with_admissible(self, admissible: object) -> Partition:
        """The same blocks with another ``(B, O)`` admissibility table."""
        return Partition(self.labels, admissible)

    def refine_by(self, labels: object) -> Partition:
        """Intersect with another labelling of the same states; children keep parents' options."""
        lab = np.asarray(labels)
        if lab.shape != self.labels.shape:
            raise ModelError(
                f"refining labels have shape {lab.shape}; expected ({self.n_states},)"
            )
        new = combine_labels(self.labels, lab)
        return Partition(new, self._inherit(new))

    def intersect(self, *others: Partition) -> Partition:
        """The product partition (section 4.2.1.2): blocks are the non-empty intersections.

        A block of the result is the vector of the operands' block indices; it offers an option
        when every operand's block does (they are all the same when built from one model).
        """
        for other in others:
            self._check_same_states(other, "intersect")
            if other.n_options != self.n_options:
                raise ModelError(
                    f"cannot intersect partitions over {self.n_options} and {other.n_options} "
                    "options; build both from the same option set"
                )
        new = combine_labels(self.labels, *(o.labels for o in others))
        adm = self._inherit(new)
        for other in others:
            adm &= other._inherit(new)
        return Partition(new, adm)

    def split_block(self, block: int, sub_labels: object) -> Partition:
        """Replace one block by sub-blocks given by ``sub_labels`` (one label per member state).

        Sub-blocks inherit the block's admissible options; other blocks keep theirs.
        """
        self._check_block(block)
        members = self.members(block)
        sub = np.asarray(sub_labels)
        if sub.shape != members.shape or not np.issubdtype(sub.dtype, np.integer):
            raise ModelError(
                f"split of block {block} needs {members.size} integer sub-labels (one per member "
                f"state, ascending state order); got shape {sub.shape}"
            )
        work = self.labels.copy()
        local = canonical_labels(sub)
        work[members] = np.where(local == 0, block, self.n_blocks + local - 1)
        new = canonical_labels(work)
        return Partition(new, self._inherit(new))

    def is_refinement_of(self, coarser: Partition) -> bool:
        """Definition 3.2: every block of ``self`` lies inside one block of ``coarser``."""
        self._check_same_states(coarser, "compare")
        parent = self.parent_map(coarser)
        return parent is not None

    def parent_map(self, coarser: Partition) -> np.ndarray | None:
        """``(B,)`` the block of ``coarser`` holding each block of ``self``, or None."""
        self._check_same_states(coarser, "compare")
        parent = np.full(self.n_blocks, -1, dtype=np.int64)
        parent[self.labels] = coarser.labels
        if not np.array_equal(parent[self.labels], coarser.labels):
            return None
        return parent

    def map_values(self, values: object, source: Partition) -> np.ndarray:
        """Move a per-block table (``V`` ``(B_src,)`` or ``Q`` ``(B_src, O)``) to ``self``.

        ``self`` must refine ``source``: every child block inherits its parent's row, which is how
        the decision layer keeps what it learned when a block is split (section 4.3.3). Mapping from
        a finer to a coarser partition is ambiguous and raises.
        """
        table = np.asarray(values)
        if table.ndim not in (1, 2) or table.shape[0] != source.n_blocks:
            raise ModelError(
                f"values have shape {table.shape}; expected ({source.n_blocks},) or "
                f"({source.n_blocks}, O) for the source partition"
            )
        parent = self.parent_map(source)
        if parent is None:
            raise ModelError(
                "cannot map values: the target partition does not refine the source partition "
                "(values flow from a coarser partition to its refinement only)"
            )
        return table[parent].copy()

    def _inherit(self, new_labels: np.ndarray) -> np.ndarray:
        """Admissibility of the blocks of ``new_labels`` (a refinement): each from its parent."""
        n_new = int(new_labels.max()) + 1
        parent = np.empty(n_new, dtype=np.int64)
        parent[new_labels] = self.labels
        return self.admissible[parent].copy()
