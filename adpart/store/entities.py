"""Frozen records the knowledge base hands out (never ORM objects, which stay inside the store).

Artifact fields hold the artifact's SHA-256 (or ``None``); read the payload with
``kb.load(record, "q")``, which names the record if the artifact turns out damaged. Every record
has a ``ref`` such as ``"policy:12"``, the id the CLI takes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from typing import Any, ClassVar


@dataclass(frozen=True)
class Provenance:
    """Who made a record, with which plugin and parameters, when, and under which schema version."""

    adpart_version: str
    plugin: str
    plugin_version: str
    parameters: dict[str, Any]
    created_at: datetime
    schema_version: int


@dataclass(frozen=True)
class Record:
    """Base of every record: a kind, an integer id and provenance."""

    KIND: ClassVar[str] = ""
    #: artifact fields: name -> "array" or "table"
    ARTIFACTS: ClassVar[dict[str, str]] = {}

    id: int

    @property
    def ref(self) -> str:
        return f"{self.KIND}:{self.id}"


@dataclass(frozen=True)
class Environment(Record):
    KIND: ClassVar[str] = "environment"
    name: str
    spec: dict[str, Any]
    model_hash: str
    n_states: int
    n_actions: int
    provenance: Provenance = field(repr=False, compare=False)


@dataclass(frozen=True)
class Task(Record):
    KIND: ClassVar[str] = "task"
    environment_id: int
    name: str
    spec: dict[str, Any]
    spec_hash: str
    gamma: float
    provenance: Provenance = field(repr=False, compare=False)


@dataclass(frozen=True)
class Policy(Record):
    """A learned policy: Q (S, A) float64 and greedy pi (S,) int64, either may be absent."""

    KIND: ClassVar[str] = "policy"
    ARTIFACTS: ClassVar[dict[str, str]] = {"q": "array", "pi": "array"}
    task_id: int
    learner: str
    seed: int | None
    episodes: int | None
    steps: int | None
    q: str | None
    pi: str | None
    provenance: Provenance = field(repr=False, compare=False)


@dataclass(frozen=True)
class SubgoalSet(Record):
    """Subgoals found by a detector: ``states`` sorted, ``subgoal_ids`` the matching subgoal ids."""

    KIND: ClassVar[str] = "subgoal-set"
    ARTIFACTS: ClassVar[dict[str, str]] = {"scores": "array"}
    environment_id: int
    policy_id: int | None
    detector: str
    scores: str | None
    states: tuple[int, ...]
    subgoal_ids: tuple[int, ...]
    provenance: Provenance = field(repr=False, compare=False)


@dataclass(frozen=True)
class Option(Record):
    """An option (I, pi, beta) with its multi-time model R (S,) and F (COO table row/col/value)."""

    KIND: ClassVar[str] = "option"
    ARTIFACTS: ClassVar[dict[str, str]] = {
        "initiation": "array", "policy": "array", "termination": "array", "reward": "array",
        "transitions": "table",
    }
    environment_id: int
    subgoal_id: int | None
    name: str
    gamma: float | None
    initiation: str
    policy: str
    termination: str
    reward: str | None
    transitions: str | None
    provenance: Provenance = field(repr=False, compare=False)


@dataclass(frozen=True)
class Partition(Record):
    """A state partition: labels (S,) int64, ordered option set, per-block action mask, parents."""

    KIND: ClassVar[str] = "partition"
    ARTIFACTS: ClassVar[dict[str, str]] = {"labels": "array", "block_actions": "array"}
    environment_id: int
    task_id: int | None
    kind: str
    option_ids: tuple[int, ...]
    includes_primitives: bool
    epsilon: float
    delta: float
    n_blocks: int
    labels: str
    block_actions: str | None
    parent_ids: tuple[int, ...]
    provenance: Provenance = field(repr=False, compare=False)


@dataclass(frozen=True)
class Run(Record):
    """One learning run of a task, optionally on a partition; ``curve`` is a table artifact,
    ``experience`` (schema 3) the counts of the primitive transitions its runs took, a table
    ``(state, action, next_state, count)``, when the learner recorded them."""

    KIND: ClassVar[str] = "run"
    ARTIFACTS: ClassVar[dict[str, str]] = {"curve": "table", "experience": "table"}
    task_id: int
    partition_id: int | None
    learner: str
    seed: int | None
    curve: str | None
    experience: str | None
    metrics: dict[str, Any]
    provenance: Provenance = field(repr=False, compare=False)


@dataclass(frozen=True)
class Artifact(Record):
    """An artifact row: content hash, URI relative to the artifact root, format and size."""

    KIND: ClassVar[str] = "artifact"
    sha256: str
    uri: str
    format: str
    bytes: int
    file_sha256: str
    kind: str
    dtype: str | None
    shape: tuple[int, ...] | None
    created_at: datetime

    @property
    def ref(self) -> str:
        return f"artifact:{self.sha256[:16]}"


RECORD_TYPES: dict[str, type[Record]] = {
    cls.KIND: cls
    for cls in (Environment, Task, Policy, SubgoalSet, Option, Partition, Run, Artifact)
}
