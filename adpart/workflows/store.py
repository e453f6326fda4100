"""What the workflows need from a knowledge base: the store boundary as a Protocol.

:class:`adpart.store.KnowledgeBase` is a facade of some seventy methods (maintenance, queries,
tables, ...); the workflows, experiments and CLI helpers call the few below. Typing their ``kb``
as :class:`KnowledgeStore` says which: these reads (records by id, kind, environment or task, and
verified artifact payloads), these get-or-put writes, one transaction, and the location's label.
Each method takes the parameters some workflow passes, with ``KnowledgeBase``'s names, kinds,
defaults and annotations; ``tests/test_store_boundary.py`` checks that ``KnowledgeBase`` has every
one with a compatible signature, so a workflow that starts calling something else must say so
here.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from contextlib import AbstractContextManager
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:
    import scipy.sparse as sp

    from adpart.store import entities as E

__all__ = ["KnowledgeStore"]


@runtime_checkable
class KnowledgeStore(Protocol):
    """The knowledge base as the workflows use it (module docstring)."""

    #: the location in messages (a directory, ``$ADPART_KB`` or a database URL)
    label: str

    # ------------------------------------------------------------------ reads
    def get(self, kind: str, record_id: int) -> Any:
        """The record of ``kind`` with id ``record_id``."""
        ...

    def records(self, kind: str, *, environment: E.Environment | int | None = None) -> list[Any]:
        """All records of ``kind``, oldest first, optionally of one environment."""
        ...

    def find_environment(self, name_or_hash: str) -> E.Environment:
        """The environment with this name (most recent) or model hash."""
        ...

    def options_for(self, environment: E.Environment | int) -> list[E.Option]:
        """Every option stored for an environment."""
        ...

    def partitions_using(self, options: Iterable[E.Option | int], *, exact: bool = True,
                         includes_primitives: bool | None = None) -> list[E.Partition]:
        """Partitions built from exactly this option set (``exact``) or from a superset of it."""
        ...

    def runs_for(self, task: E.Task | int) -> list[E.Run]:
        """Every run of a task, oldest first."""
        ...

    def learned_tasks(self, environment: E.Environment | int | None = None,
                      ) -> list[tuple[E.Task, list[E.Run]]]:
        """Tasks that have runs, with their runs."""
        ...

    def load(self, record: E.Record, field_name: str) -> Any:
        """The payload of one artifact field of a record, verified against its hash."""
        ...

    def option_transitions(self, option: E.Option) -> sp.csr_array | None:
        """An option's discounted transition model ``F_o`` as an ``(S, S)`` CSR array."""
        ...

    # ------------------------------------------------------------------ writes
    def transaction(self) -> AbstractContextManager[None]:
        """Group writes: they commit together at the end or not at all."""
        ...

    def put_environment(self, name: str, *, model_hash: str, n_states: int, n_actions: int,
                        spec: Mapping[str, Any] | None = None) -> E.Environment:
        """Get-or-put an environment by model hash."""
        ...

    def put_task(self, environment: E.Environment | int, name: str, *, spec: Mapping[str, Any],
                 gamma: float) -> E.Task:
        """Get-or-put a task by its spec and gamma."""
        ...

    def put_policy(self, task: E.Task | int, learner: str, *, q: Any = None, pi: Any = None,
                   seed: int | None = None, episodes: int | None = None, steps: int | None = None,
                   q_columns: Sequence[str] | None = None, plugin_version: str = "",
                   parameters: Mapping[str, Any] | None = None) -> E.Policy:
        """Store a learned policy (Q and/or greedy pi)."""
        ...

    def put_run(self, task: E.Task | int, learner: str, *, curve: Any = None,
                metrics: Mapping[str, Any] | None = None,
                partition: E.Partition | int | None = None,
                seed: int | None = None, plugin_version: str = "",
                parameters: Mapping[str, Any] | None = None, experience: Any = None) -> E.Run:
        """Store one learning run with its curve (and the transitions it took, a table)."""
        ...

    def put_subgoal_set(self, environment: E.Environment | int, detector: str, states: Any, *,
                        scores: Any = None, policy: E.Policy | int | None = None,
                        plugin: str = "", plugin_version: str = "",
                        parameters: Mapping[str, Any] | None = None) -> E.SubgoalSet:
        """Store the subgoals a detector found."""
        ...

    def put_option(self, environment: E.Environment | int, name: str, *, initiation: Any,
                   policy: Any, termination: Any, reward: Any = None, transitions: Any = None,
                   gamma: float | None = None, subgoal: int | None = None, plugin: str = "",
                   parameters: Mapping[str, Any] | None = None) -> E.Option:
        """Store an option with its multi-time model."""
        ...

    def put_partition(self, environment: E.Environment | int, kind: str, labels: Any, *,
                      options: Sequence[E.Option | int] = (), includes_primitives: bool = True,
                      epsilon: float, delta: float, block_actions: Any = None,
                      parents: Iterable[E.Partition | int] = (), task: E.Task | int | None = None,
                      plugin: str = "", parameters: Mapping[str, Any] | None = None,
                      ) -> E.Partition:
        """Store a partition with its option set, per-block actions and parents."""
        ...
