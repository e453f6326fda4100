"""SQLAlchemy 2 typed declarative models of the knowledge base (metadata; payloads are artifacts).

These classes never leave :mod:`adpart.store`: :class:`~adpart.store.kb.KnowledgeBase` turns rows
into the frozen dataclasses of :mod:`adpart.store.entities`. Every record table carries the same
provenance columns (:class:`Provenance`); columns ending in ``_sha`` reference
``artifacts.sha256`` (content hashes), so a payload is shared by every record that has the same one.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any, ClassVar

from sqlalchemy import (
    JSON,
    BigInteger,
    CheckConstraint,
    Column,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    String,
    Table,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

PARTITION_KINDS = ("per-option", "intersected", "reward-refined", "learned", "hierarchy")
_SHA = String(64)


class Base(DeclarativeBase):
    type_annotation_map: ClassVar[dict[Any, Any]] = {
        dict[str, Any]: JSON, int: Integer, str: String(255)}


def _row_sha() -> Mapped[Any]:
    """The row's content hash (:mod:`adpart.store.integrity`), set in the inserting transaction."""
    return mapped_column(_SHA, nullable=True, default=None)


def _artifact_ref(nullable: bool = True) -> Mapped[Any]:
    return mapped_column(_SHA, ForeignKey("artifacts.sha256"), nullable=nullable, index=True)


class Provenance:
    """Columns every record carries: who made it, with what, when, under which schema."""

    adpart_version: Mapped[str] = mapped_column(String(64))
    plugin: Mapped[str] = mapped_column(String(255), default="")
    plugin_version: Mapped[str] = mapped_column(String(64), default="")
    parameters: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    schema_version: Mapped[int]
    row_sha: Mapped[str | None] = _row_sha()


class SqlSchema(Base):
    """One row: the schema version of this knowledge base and the adpart that last wrote it."""

    __tablename__ = "adpart_schema"
    id: Mapped[int] = mapped_column(primary_key=True)
    version: Mapped[int]
    written_by: Mapped[str] = mapped_column(String(64))


class SqlIdentity(Base):
    """One row: this knowledge base's identity, written when it is created (or, for one made
    before identities, at its first writable open). Its artifact root records the same id in
    its owner file, so a second knowledge base given that root is refused."""

    __tablename__ = "adpart_identity"
    id: Mapped[int] = mapped_column(primary_key=True)
    kb_id: Mapped[str] = mapped_column(String(36))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))


class SqlArtifact(Base):
    __tablename__ = "artifacts"
    id: Mapped[int] = mapped_column(primary_key=True)
    sha256: Mapped[str] = mapped_column(_SHA, unique=True)
    uri: Mapped[str] = mapped_column(String(512))
    format: Mapped[str] = mapped_column(String(32))
    bytes: Mapped[int] = mapped_column(BigInteger)
    file_sha256: Mapped[str] = mapped_column(_SHA)
    kind: Mapped[str] = mapped_column(String(64))
    dtype: Mapped[str | None] = mapped_column(String(16))
    shape: Mapped[list[int] | None] = mapped_column(JSON)
    adpart_version: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    schema_version: Mapped[int]
    row_sha: Mapped[str | None] = _row_sha()


class SqlEnvironment(Provenance, Base):
    __tablename__ = "environments"
    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(255), index=True)
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)
    model_hash: Mapped[str] = mapped_column(_SHA, unique=True)
    n_states: Mapped[int] = mapped_column(BigInteger)
    n_actions: Mapped[int]


class SqlTask(Provenance, Base):
    __tablename__ = "tasks"
    __table_args__ = (UniqueConstraint("environment_id", "spec_hash"),)
    id: Mapped[int] = mapped_column(primary_key=True)
    environment_id: Mapped[int] = mapped_column(ForeignKey("environments.id"), index=True)
    name: Mapped[str] = mapped_column(String(255))
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)
    spec_hash: Mapped[str] = mapped_column(_SHA)
    gamma: Mapped[float] = mapped_column(Float)


class SqlPolicy(Provenance, Base):
    __tablename__ = "policies"
    id: Mapped[int] = mapped_column(primary_key=True)
    task_id: Mapped[int] = mapped_column(ForeignKey("tasks.id"), index=True)
    learner: Mapped[str] = mapped_column(String(255))
    seed: Mapped[int | None] = mapped_column(BigInteger)
    episodes: Mapped[int | None] = mapped_column(BigInteger)
    steps: Mapped[int | None] = mapped_column(BigInteger)
    q_sha: Mapped[str | None] = _artifact_ref()
    pi_sha: Mapped[str | None] = _artifact_ref()


class SqlSubgoalSet(Provenance, Base):
    __tablename__ = "subgoal_sets"
    id: Mapped[int] = mapped_column(primary_key=True)
    environment_id: Mapped[int] = mapped_column(ForeignKey("environments.id"), index=True)
    policy_id: Mapped[int | None] = mapped_column(ForeignKey("policies.id"), index=True)
    detector: Mapped[str] = mapped_column(String(255))
    scores_sha: Mapped[str | None] = _artifact_ref()
    subgoals: Mapped[list[SqlSubgoal]] = relationship(
        back_populates="subgoal_set", order_by="SqlSubgoal.state", cascade="all, delete-orphan"
    )


class SqlSubgoal(Base):
    __tablename__ = "subgoals"
    __table_args__ = (UniqueConstraint("subgoal_set_id", "state"),)
    id: Mapped[int] = mapped_column(primary_key=True)
    subgoal_set_id: Mapped[int] = mapped_column(ForeignKey("subgoal_sets.id"), index=True)
    state: Mapped[int] = mapped_column(BigInteger)
    row_sha: Mapped[str | None] = _row_sha()
    subgoal_set: Mapped[SqlSubgoalSet] = relationship(back_populates="subgoals")


class SqlOption(Provenance, Base):
    __tablename__ = "options"
    id: Mapped[int] = mapped_column(primary_key=True)
    environment_id: Mapped[int] = mapped_column(ForeignKey("environments.id"), index=True)
    subgoal_id: Mapped[int | None] = mapped_column(ForeignKey("subgoals.id"), index=True)
    name: Mapped[str] = mapped_column(String(255))
    gamma: Mapped[float | None] = mapped_column(Float)
    initiation_sha: Mapped[str] = _artifact_ref(nullable=False)
    policy_sha: Mapped[str] = _artifact_ref(nullable=False)
    termination_sha: Mapped[str] = _artifact_ref(nullable=False)
    reward_sha: Mapped[str | None] = _artifact_ref()
    transitions_sha: Mapped[str | None] = _artifact_ref()


partition_parents = Table(
    "partition_parents",
    Base.metadata,
    Column("child_id", ForeignKey("partitions.id"), primary_key=True),
    Column("parent_id", ForeignKey("partitions.id"), primary_key=True),
)


class SqlPartitionOption(Base):
    """The ordered option set of a partition (position = index after the primitive actions)."""

    __tablename__ = "partition_options"
    partition_id: Mapped[int] = mapped_column(ForeignKey("partitions.id"), primary_key=True)
    option_id: Mapped[int] = mapped_column(ForeignKey("options.id"), primary_key=True, index=True)
    position: Mapped[int]
    row_sha: Mapped[str | None] = _row_sha()


class SqlPartition(Provenance, Base):
    __tablename__ = "partitions"
    __table_args__ = (
        CheckConstraint("kind IN (" + ", ".join(f"'{k}'" for k in PARTITION_KINDS) + ")",
                        name="partition_kind"),
    )
    id: Mapped[int] = mapped_column(primary_key=True)
    environment_id: Mapped[int] = mapped_column(ForeignKey("environments.id"), index=True)
    task_id: Mapped[int | None] = mapped_column(ForeignKey("tasks.id"), index=True)
    kind: Mapped[str] = mapped_column(String(32))
    includes_primitives: Mapped[bool]
    epsilon: Mapped[float] = mapped_column(Float)
    delta: Mapped[float] = mapped_column(Float)
    n_blocks: Mapped[int] = mapped_column(BigInteger)
    labels_sha: Mapped[str] = _artifact_ref(nullable=False)
    block_actions_sha: Mapped[str | None] = _artifact_ref()
    options: Mapped[list[SqlPartitionOption]] = relationship(
        order_by=SqlPartitionOption.position, cascade="all, delete-orphan"
    )
    parents: Mapped[list[SqlPartition]] = relationship(
        secondary=partition_parents,
        primaryjoin=id == partition_parents.c.child_id,
        secondaryjoin=id == partition_parents.c.parent_id,
        order_by="SqlPartition.id",
    )


class SqlRun(Provenance, Base):
    __tablename__ = "runs"
    id: Mapped[int] = mapped_column(primary_key=True)
    task_id: Mapped[int] = mapped_column(ForeignKey("tasks.id"), index=True)
    partition_id: Mapped[int | None] = mapped_column(ForeignKey("partitions.id"), index=True)
    learner: Mapped[str] = mapped_column(String(255))
    seed: Mapped[int | None] = mapped_column(BigInteger)
    curve_sha: Mapped[str | None] = _artifact_ref()
    # added by schema 3's ALTER TABLE: a plain column (no foreign key or index, which SQLite
    # cannot add to a table in place); gc and `kb check` follow it through ARTIFACT_COLUMNS
    experience_sha: Mapped[str | None] = mapped_column(_SHA, nullable=True)
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)


from adpart.store import integrity as _integrity  # noqa: E402  (needs Base)

_integrity.install(Base)

#: tables whose rows carry a content hash (every table but the schema row and the parent links)
HASHED_TABLES = tuple(t for t in Base.metadata.sorted_tables if "row_sha" in t.c)

#: record tables and the artifact columns each holds, for reference checks and garbage collection
ARTIFACT_COLUMNS: dict[type[Base], tuple[str, ...]] = {
    SqlPolicy: ("q_sha", "pi_sha"),
    SqlSubgoalSet: ("scores_sha",),
    SqlOption: ("initiation_sha", "policy_sha", "termination_sha", "reward_sha",
                "transitions_sha"),
    SqlPartition: ("labels_sha", "block_actions_sha"),
    SqlRun: ("curve_sha", "experience_sha"),
}
