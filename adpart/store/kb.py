"""The knowledge base: SQL metadata (SQLAlchemy 2) plus content-addressed Parquet artifacts.

:class:`KnowledgeBase` is the library API (DESIGN.md, "Knowledge base"; STYLE.md 8.6). Puts take
plain values (numpy arrays, dicts, scipy.sparse matrices) and return frozen records from
:mod:`adpart.store.entities`; the payloads are written first (temporary name, rename), then the
row that references them, so no row ever points at a missing file. Environments are get-or-put by
model hash and tasks by spec hash, so pipelines rerun without duplicating them.

Every write transaction holds the *store lock* from the moment it checks an artifact's row and
file until it commits (SQLite: ``BEGIN IMMEDIATE``; PostgreSQL: a shared advisory lock), and
garbage collection holds it exclusively, so a gc can never remove a file between a writer's
check and its commit (docs/reliability.md). :meth:`KnowledgeBase.transaction` groups several
puts into one transaction: a run and its policies are stored whole or not at all.

This module opens the database and writes records; reads and queries are the
:class:`~adpart.store.queries.Queries` mixin, the same reads as ``pyarrow`` tables the
:class:`~adpart.store.tables.Tables` mixin, audits and garbage collection the
:class:`~adpart.store.maintenance.Maintenance` mixin.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any, TypeVar

import numpy as np
import pyarrow as pa
import scipy.sparse as sp
from sqlalchemy import Engine, create_engine, event, select, text
from sqlalchemy.exc import IntegrityError, SQLAlchemyError
from sqlalchemy.orm import Session, sessionmaker

from adpart import __version__
from adpart.store import entities as E
from adpart.store.artifacts import ArtifactStore, StoredArtifact
from adpart.store.errors import StoreError
from adpart.store.location import MAKE_ONE, KBLocation
from adpart.store.maintenance import Maintenance
from adpart.store.models import (
    PARTITION_KINDS,
    Base,
    SqlArtifact,
    SqlEnvironment,
    SqlOption,
    SqlPartition,
    SqlPartitionOption,
    SqlPolicy,
    SqlRun,
    SqlSubgoal,
    SqlSubgoalSet,
    SqlTask,
)
from adpart.store.queries import Queries, _id
from adpart.store.schema import (
    SCHEMA_VERSION,
    identity_of,
    read_identity,
    read_version,
    upgrade_schema,
    verify_schema,
    verify_tables,
)
from adpart.store.tables import Tables
from adpart.store.values import (
    canonical_json_hash,
    discount,
    json_text,
    name_text,
    threshold,
    whole_number,
)

_BUSY_TIMEOUT_S = 60.0
#: what a damaged database raises: the driver's errors, and text SQLite returns undecoded (a
#: flipped bit in the schema makes even its error message invalid UTF-8)
DB_ERRORS = (SQLAlchemyError, UnicodeDecodeError)
R = TypeVar("R", bound=E.Record)



def _first(error: BaseException) -> str:
    """The first line of a driver's message (SQLAlchemy appends the SQL and a link)."""
    text = str(error)
    return text.splitlines()[0] if text else type(error).__name__


#: the name of the PostgreSQL advisory lock that orders writers and gc (per schema, so per KB)
_STORE_LOCK = "adpart-store:"
_SCHEMA_LOCK = "adpart-schema:"


def _pg_lock(session_or_conn: Any, name: str, *, shared: bool) -> None:
    """Take a transaction-scoped PostgreSQL advisory lock named for this KB's schema."""
    fn = "pg_advisory_xact_lock_shared" if shared else "pg_advisory_xact_lock"
    session_or_conn.execute(text(f"SELECT {fn}(hashtext(:name || current_schema()))"),
                            {"name": name})


def _read_only_sqlite(db_url: str, connect_args: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """The URL of a SQLite file opened ``mode=ro``: no file, journal or directory is created."""
    from sqlalchemy.engine import make_url

    url = make_url(db_url)
    path = url.database or ""
    if path in ("", ":memory:") or not os.path.isfile(path):
        raise StoreError(f"there is no knowledge base database {path or db_url}; check --kb / "
                         f"ADPART_KB (reading commands never create one): {MAKE_ONE}")
    path = os.path.abspath(path)
    query = "mode=ro&uri=true"
    if not os.access(os.path.dirname(path), os.W_OK) and not os.path.exists(f"{path}-wal"):
        # nobody can write here (no -wal can be made), so SQLite need not make its -shm either
        query += "&immutable=1"
    return f"sqlite:///file:{path}?{query}", connect_args


@dataclass
class _Pending:
    """An artifact written for a record not yet committed, and how to write it again.

    ``rewrite`` puts the same content back in place; :meth:`KnowledgeBase._ensure_rows` calls it
    when the file is missing at commit time (removed by a gc that ran before this writer's
    transaction began), so a writer never commits a row for a missing file and never fails
    because of a concurrent gc.
    """

    stored: StoredArtifact
    kind: str
    rewrite: Callable[[], StoredArtifact]


def open_kb(location: str | os.PathLike[str] | KBLocation | None = None, *,
            read_only: bool = False, artifacts: str | None = None) -> KnowledgeBase:
    """Open the knowledge base at ``location`` (see :meth:`KnowledgeBase.open`).

    ``open_kb(path, read_only=True)`` is the way to read one from a script or notebook: nothing
    is created, a missing knowledge base is a :class:`StoreError` naming the fix, and the tables
    come from ``kb.records_table(...)``, ``kb.runs_table(...)``, ``kb.curves_table(...)`` and
    ``kb.partition_table(...)``.
    Use it as a context manager (``with open_kb(...) as kb:``) to close it when done.
    """
    return KnowledgeBase.open(location, artifacts=artifacts, read_only=read_only)


class KnowledgeBase(Queries, Tables, Maintenance):
    """Records of everything adpart learned: metadata in SQL, arrays and tables as Parquet.

    Open one with :meth:`open` (a directory, ``$ADPART_KB`` or the per-user default) or construct
    it from a SQLAlchemy URL and an artifact URI. The main API methods are:

    - ``put_environment`` / ``environment_for_mdp`` (get-or-put by model hash), ``put_task``
      (get-or-put by spec hash), ``put_policy``, ``put_subgoal_set``, ``put_option``,
      ``put_partition``, ``put_run``: write a record, return its frozen dataclass;
    - ``get(kind, id)``, ``artifact(sha_prefix)``, ``records(kind, environment=...)``,
      ``find_environment(name_or_hash)``;
    - ``load(record, field)``: an artifact's payload, verified against its hash;
    - queries: ``options_for``, ``partitions_using``, ``runs_for``, ``learned_tasks``, ``lineage``;
    - tables (``pyarrow.Table``, ``.to_pandas()``): ``records_table`` (``records_page``),
      ``runs_table`` (each run's time to the success bound), ``curves_table``,
      ``partition_table``;
    - maintenance: ``info``, ``check``, ``gc``, ``upgrade``.

    Every read verifies the row hash of each row it returns; a damaged row is a
    :class:`StoreError` naming the record, its table and (where one is at fault) the column.
    Every database error, and every value a put refuses (a name with NUL characters, a gamma
    outside [0, 1], a count below 1), surfaces as :class:`StoreError` too.
    """

    def __init__(self, db_url: str, artifact_uri: str, *, label: str | None = None,
                 verify: bool = True, read_only: bool = False) -> None:
        self.label = label or db_url
        self.db_url = db_url
        self.read_only = read_only
        self._tx: Session | None = None
        self.upgrade_damaged: list[str] = []
        try:
            self.engine = self._make_engine(db_url, read_only=read_only)
        except (SQLAlchemyError, ImportError) as exc:
            raise StoreError(f"cannot open the knowledge base database {self.label}: {exc}; "
                             "check the URL and that its driver is installed") from exc
        self._read = sessionmaker(self.engine, expire_on_commit=False)
        self._write = sessionmaker(self.engine.execution_options(adpart_write=True),
                                   expire_on_commit=False)
        try:
            # nothing is made before the database answers and the root is known to be free
            # for this knowledge base (_init_schema): then the root is made and claimed
            self.artifacts = ArtifactStore(artifact_uri, create=False)
            self.artifact_uri = artifact_uri
            self.schema_version = self._init_schema(verify)
        except BaseException:
            # a refused KB must not leave pooled connections for the garbage collector to close
            self.engine.dispose()
            raise

    @classmethod
    def open(cls, location: str | os.PathLike[str] | KBLocation | None = None, *,
             artifacts: str | None = None, verify: bool = True,
             read_only: bool = False) -> KnowledgeBase:
        """Open (creating on first use) the knowledge base at ``location``.

        Args:
            location: a directory (``kb.sqlite`` + ``artifacts/`` inside), a SQLAlchemy URL, or a
                :class:`KBLocation`; ``None`` means ``$ADPART_KB`` or the per-user default.
            artifacts: artifact root URI (any pyarrow filesystem URI) for a URL location.
            verify: refuse a schema this adpart cannot read (``False`` only for ``upgrade``).
            read_only: open an existing knowledge base for reading only: nothing is created (a
                missing one is an error) and a read-only directory or file is fine. Writes fail.
        """
        where = (location if isinstance(location, KBLocation)
                 else KBLocation.resolve(location, artifacts, create=not read_only))
        return cls(where.db_url, where.artifact_uri, label=where.label, verify=verify,
                   read_only=read_only)

    # ------------------------------------------------------------------ engine and sessions
    @property
    def is_postgresql(self) -> bool:
        return self.engine.dialect.name == "postgresql"

    @staticmethod
    def _make_engine(db_url: str, *, read_only: bool = False) -> Engine:
        if not db_url.startswith("sqlite"):
            return create_engine(db_url, pool_pre_ping=True)
        connect_args: dict[str, Any] = {"timeout": _BUSY_TIMEOUT_S}
        if read_only:
            db_url, connect_args = _read_only_sqlite(db_url, connect_args)
        engine = create_engine(db_url, connect_args=connect_args)

        @event.listens_for(engine, "connect")
        def _pragmas(dbapi_connection: Any, _record: Any) -> None:
            # transactions are begun by the "begin" listener below, not by pysqlite
            dbapi_connection.isolation_level = None
            cursor = dbapi_connection.cursor()
            cursor.execute(f"PRAGMA busy_timeout = {int(_BUSY_TIMEOUT_S * 1000)}")
            if not read_only:  # a reader changes nothing, not even the journal mode
                cursor.execute("PRAGMA journal_mode = WAL")
                cursor.execute("PRAGMA synchronous = NORMAL")
            cursor.execute("PRAGMA foreign_keys = ON")
            cursor.close()

        @event.listens_for(engine, "begin")
        def _begin(conn: Any) -> None:
            # writers take the write lock up front so WAL readers never have to upgrade a lock
            # (which SQLite reports as SQLITE_BUSY without waiting)
            write = conn.get_execution_options().get("adpart_write", False)
            conn.exec_driver_sql("BEGIN IMMEDIATE" if write else "BEGIN")

        return engine

    @contextmanager
    def _session(self, *, write: bool = False, exclusive: bool = False) -> Iterator[Session]:
        """Managed session: commit (writes) or rollback; database errors become StoreError.

        Inside :meth:`transaction` every session is that transaction's, and nothing commits
        until it ends. A write session holds the store lock for its whole transaction: shared
        for record writers, ``exclusive`` for gc. On SQLite the lock is the database's write
        lock (``BEGIN IMMEDIATE``: writers and gc run one at a time); on PostgreSQL it is an
        advisory lock, shared by writers and exclusive for gc, so gc never runs while a writer
        is between "the artifact file is there" and its commit.
        """
        if self._tx is not None:
            yield self._tx
            return
        if write and self.read_only:
            raise StoreError(f"the knowledge base {self.label} was opened read-only; open it "
                             "without read_only to write")
        session = (self._write if write else self._read)()
        try:
            if write and self.is_postgresql:
                _pg_lock(session, _STORE_LOCK, shared=not exclusive)
            yield session
            if write:
                session.commit()
        except DB_ERRORS as exc:
            session.rollback()
            orig = getattr(exc, "orig", None) or exc
            raise StoreError(f"knowledge base {self.label}: database error "
                             f"({type(orig).__name__}: {str(orig).splitlines()[0]}); check the "
                             "location is writable, or run `adpart kb check`") from exc
        except BaseException:
            session.rollback()
            raise
        finally:
            session.close()

    @contextmanager
    def transaction(self) -> Iterator[None]:
        """Group several puts into one transaction: all of them are stored, or none.

        ``with kb.transaction(): kb.put_policy(...); kb.put_run(...)`` commits once at the end;
        an error (or a kill) anywhere inside leaves no record of the group. Artifact files are
        written as each put runs; if the transaction is rolled back they are unreferenced files
        that ``adpart kb gc`` removes once they are older than its grace age. Nested calls join
        the outer transaction.
        """
        if self._tx is not None:
            yield
            return
        with self._session(write=True) as session:
            self._tx = session
            try:
                yield
            finally:
                self._tx = None

    def _init_schema(self, verify: bool) -> int:
        """Check (and on first use create) the schema and claim the artifact root.

        In one locked transaction: the schema version is read and verified, the tables checked
        against it, and this knowledge base's identity read (or made); the root's owner record
        must name no other knowledge base. Only then are the schema (for a new knowledge base),
        the root directory and its owner file made, so a refused open creates nothing.
        """
        if self.read_only:
            return self._read_schema(verify)
        try:
            with self.engine.execution_options(adpart_write=True).begin() as conn:
                if self.is_postgresql:
                    # concurrent first opens: one creates the schema, the others wait and see it
                    _pg_lock(conn, _SCHEMA_LOCK, shared=False)
                found = read_version(conn, self.label)
                owner = self.artifacts.owner()
                if found is None:  # a new knowledge base takes only a root nobody owns
                    self.artifacts.refuse_other_owner(None, self.label, owner)
                    self.artifacts.check_creatable()
                    upgrade_schema(conn, self.label)
                    version, kb_id = SCHEMA_VERSION, read_identity(conn)
                else:
                    version = found[0]
                    if verify:
                        verify_schema(found[0], found[1], self.label)
                    kb_id = None
                    if version == SCHEMA_VERSION:
                        verify_tables(conn, self.label)
                        kb_id = identity_of(conn)
                        self.artifacts.refuse_other_owner(kb_id, self.label, owner)
                        self.artifacts.check_creatable()
        except DB_ERRORS as exc:
            orig = getattr(exc, "orig", None) or exc
            raise StoreError(f"cannot open the knowledge base {self.label}: {_first(orig)}; "
                             "check the location exists and is writable (--kb / ADPART_KB)"
                             ) from exc
        if kb_id is not None:
            self.artifacts.claim(kb_id, self.label)
        self.kb_id = kb_id
        return version

    def _read_schema(self, verify: bool) -> int:
        try:
            with self.engine.connect() as conn:
                found = read_version(conn, self.label)
                if found is None:
                    raise StoreError(f"{self.label} holds no knowledge base (an empty database; "
                                     f"reading commands never create one): {MAKE_ONE}")
                if verify:
                    verify_schema(found[0], found[1], self.label)
                kb_id = None
                if found[0] == SCHEMA_VERSION:
                    verify_tables(conn, self.label)
                    kb_id = read_identity(conn)
        except DB_ERRORS as exc:
            orig = getattr(exc, "orig", None) or exc
            raise StoreError(f"cannot read the knowledge base {self.label}: {_first(orig)}; "
                             "check the location (--kb / ADPART_KB)") from exc
        if kb_id is not None:  # reading another knowledge base's root would misreport it
            self.artifacts.refuse_other_owner(kb_id, self.label)
        self.kb_id = kb_id
        return found[0]

    def upgrade(self) -> tuple[int, int]:
        """Migrate the database to this adpart's schema version; returns (from, to).

        Rows whose hash did not hold before the upgrade keep it (still damaged, named by reads
        and ``check``); their names are in ``upgrade_damaged`` afterwards."""
        try:
            with self.engine.execution_options(adpart_write=True).begin() as conn:
                if self.is_postgresql:
                    _pg_lock(conn, _SCHEMA_LOCK, shared=False)
                    _pg_lock(conn, _STORE_LOCK, shared=False)
                self.upgrade_damaged = []
                result = upgrade_schema(conn, self.label, self.upgrade_damaged)
                verify_tables(conn, self.label)
                kb_id = identity_of(conn)
                self.artifacts.refuse_other_owner(kb_id, self.label)
        except DB_ERRORS as exc:
            orig = getattr(exc, "orig", None) or exc
            raise StoreError(f"upgrading {self.label} failed ({type(orig).__name__}: "
                             f"{_first(orig)}): its tables do not match the schema version it "
                             "records, which was changed by hand or damaged; the database was "
                             "left unchanged: restore it from a backup") from exc
        self.artifacts.claim(kb_id, self.label)
        self.kb_id = kb_id
        self.schema_version = result[1]
        return result

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> KnowledgeBase:  # noqa: PYI034
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ provenance and artifacts
    @staticmethod
    def _prov(plugin: str, plugin_version: str, parameters: Mapping[str, Any] | None) -> dict:
        name_text(plugin, "plugin", empty=True)
        name_text(plugin_version, "plugin_version", longest=64, empty=True)
        params = dict(parameters or {})
        json_text(params, "parameters")
        return {"adpart_version": __version__, "plugin": plugin, "plugin_version": plugin_version,
                "parameters": params, "created_at": datetime.now(timezone.utc),
                "schema_version": SCHEMA_VERSION}

    def _array(self, value: Any, kind: str, *, dtype: Any = None,
               shape: tuple[int, ...] | None = None) -> _Pending | None:
        if value is None:
            return None
        array = np.asarray(value) if dtype is None else np.asarray(value, dtype=dtype)
        if shape is not None and array.shape != shape:
            raise StoreError(f"the {kind} array has shape {array.shape}, expected {shape}; "
                             "pass one value per state (and action) of the environment")
        return _Pending(self.artifacts.put_array(array), kind,
                        lambda: self.artifacts.put_array(array))

    def _table(self, value: Any, kind: str) -> _Pending | None:
        if value is None:
            return None
        return _Pending(self.artifacts.put_table(value), kind,
                        lambda: self.artifacts.put_table(value))

    def _ensure_rows(self, session: Session, *pending: _Pending | None) -> None:
        """Insert the artifact rows the new record will reference (deduplicated by hash)."""
        for item in pending:
            if item is None:
                continue
            art = item.stored
            if session.scalar(select(SqlArtifact.id).where(SqlArtifact.sha256 == art.sha256)):
                continue
            if not self.artifacts.exists(art.uri):
                # removed by a gc that ran before this transaction took the store lock: put it
                # back. The lock is held until commit, so no gc can remove it again before the
                # row that keeps it is committed.
                art = item.rewrite()
            try:
                with session.begin_nested():
                    session.add(SqlArtifact(
                        sha256=art.sha256, uri=art.uri, format=art.format, bytes=art.nbytes,
                        file_sha256=art.file_sha256,
                        kind=item.kind, dtype=art.dtype,
                        shape=list(art.shape) if art.shape is not None else None,
                        adpart_version=__version__, created_at=datetime.now(timezone.utc),
                        schema_version=SCHEMA_VERSION))
            except IntegrityError:
                continue  # another process inserted the same content first

    @staticmethod
    def _sha(item: _Pending | None) -> str | None:
        return None if item is None else item.stored.sha256

    def _get_or_add(self, session: Session, model: type[Base], where: Any, row: Base) -> Base:
        found = session.scalars(select(model).where(where)).first()
        if found is not None:
            return found
        try:
            with session.begin_nested():
                session.add(row)
        except IntegrityError:
            return session.scalars(select(model).where(where)).one()
        return row

    def _need(self, session: Session, model: type[Base], key: int | None, what: str) -> Any:
        row = session.get(model, key) if key is not None else None
        if row is None:
            raise StoreError(f"no {what} with id {key} in {self.label}; list them with "
                             f"`adpart kb ls {what}`")
        return row

    # ------------------------------------------------------------------ puts
    def put_environment(self, name: str, *, model_hash: str, n_states: int, n_actions: int,
                        spec: Mapping[str, Any] | None = None, plugin: str = "",
                        plugin_version: str = "", parameters: Mapping[str, Any] | None = None,
                        ) -> E.Environment:
        """Get-or-put an environment keyed by its model hash (e.g. ``FiniteMDP.content_hash``)."""
        name_text(name, "put_environment: name")
        name_text(model_hash, "put_environment: model_hash", longest=64)
        n_states = whole_number(n_states, "put_environment: n_states", 1)
        n_actions = whole_number(n_actions, "put_environment: n_actions", 1, 2**31 - 1)
        spec = dict(spec or {})
        json_text(spec, "environment spec")
        with self._session(write=True) as s:
            row = self._get_or_add(s, SqlEnvironment, SqlEnvironment.model_hash == model_hash,
                                   SqlEnvironment(name=name, spec=spec, model_hash=model_hash,
                                                  n_states=int(n_states), n_actions=int(n_actions),
                                                  **self._prov(plugin, plugin_version, parameters)))
            s.flush()
            return self._entity(row)

    def environment_for_mdp(self, mdp: Any, name: str, *, spec: Mapping[str, Any] | None = None,
                            **provenance: Any) -> E.Environment:
        """Get-or-put the environment of a :class:`~adpart.mdp.model.FiniteMDP`."""
        return self.put_environment(name, model_hash=mdp.content_hash, n_states=mdp.n_states,
                                    n_actions=mdp.n_actions, spec=spec, **provenance)

    def put_task(self, environment: E.Environment | int, name: str, *, spec: Mapping[str, Any],
                 gamma: float, plugin: str = "", plugin_version: str = "",
                 parameters: Mapping[str, Any] | None = None) -> E.Task:
        """Get-or-put a task keyed by (environment, hash of canonical JSON of spec and gamma)."""
        name_text(name, "put_task: name")
        gamma = discount(gamma, "put_task: gamma")
        spec = dict(spec)
        spec_hash = canonical_json_hash({"spec": spec, "gamma": float(gamma)})
        env_id = _id(environment)
        with self._session(write=True) as s:
            self._need(s, SqlEnvironment, env_id, "environment")
            row = self._get_or_add(
                s, SqlTask, (SqlTask.environment_id == env_id) & (SqlTask.spec_hash == spec_hash),
                SqlTask(environment_id=env_id, name=name, spec=spec, spec_hash=spec_hash,
                        gamma=float(gamma), **self._prov(plugin, plugin_version, parameters)))
            s.flush()
            return self._entity(row)

    def put_policy(self, task: E.Task | int, learner: str, *, q: Any = None, pi: Any = None,
                   seed: int | None = None, episodes: int | None = None, steps: int | None = None,
                   q_columns: Sequence[str] | None = None, plugin: str = "",
                   plugin_version: str = "",
                   parameters: Mapping[str, Any] | None = None) -> E.Policy:
        """Store a learned policy: ``q`` (S, A) float64 and/or ``pi`` (S,) int64.

        A learner over options stores ``q`` with one column per name in ``q_columns`` (e.g. the
        primitive actions, then ``option:7``, ...); ``pi`` then indexes those columns. The names
        are kept in the record's parameters as ``q_columns``.
        """
        name_text(learner, "put_policy: learner")
        seed = whole_number(seed, "put_policy: seed", optional=True)
        episodes = whole_number(episodes, "put_policy: episodes", 0, optional=True)
        steps = whole_number(steps, "put_policy: steps", 0, optional=True)
        task_id = _id(task)
        S, A = self._task_shape(task_id)
        if q_columns is not None:
            A = len(q_columns)
            parameters = {**dict(parameters or {}), "q_columns": list(q_columns)}
        q_art = self._array(q, "q", dtype=np.float64, shape=(S, A))
        pi_art = self._array(pi, "pi", dtype=np.int64, shape=(S,))
        with self._session(write=True) as s:
            self._ensure_rows(s, q_art, pi_art)
            row = SqlPolicy(task_id=task_id, learner=learner, seed=seed, episodes=episodes,
                            steps=steps, q_sha=self._sha(q_art), pi_sha=self._sha(pi_art),
                            **self._prov(plugin or learner, plugin_version, parameters))
            s.add(row)
            s.flush()
            return self._entity(row)

    def put_subgoal_set(self, environment: E.Environment | int, detector: str, states: Any, *,
                        scores: Any = None, policy: E.Policy | int | None = None,
                        plugin: str = "", plugin_version: str = "",
                        parameters: Mapping[str, Any] | None = None) -> E.SubgoalSet:
        """Store the subgoal states a detector found (and its per-state scores (S,) float64)."""
        name_text(detector, "put_subgoal_set: detector")
        env_id = _id(environment)
        S, _ = self._env_shape(env_id)
        ids = np.unique(np.asarray(states, dtype=np.int64).reshape(-1))
        if ids.size and (ids[0] < 0 or ids[-1] >= S):
            raise StoreError(f"subgoal state ids must lie in [0, {S}); got {ids[0]}..{ids[-1]}")
        scores_art = self._array(scores, "scores", dtype=np.float64, shape=(S,))
        with self._session(write=True) as s:
            self._ensure_rows(s, scores_art)
            row = SqlSubgoalSet(environment_id=env_id, policy_id=_id(policy), detector=detector,
                                scores_sha=self._sha(scores_art),
                                subgoals=[SqlSubgoal(state=int(x)) for x in ids],
                                **self._prov(plugin or detector, plugin_version, parameters))
            s.add(row)
            s.flush()
            return self._entity(row)

    def put_option(self, environment: E.Environment | int, name: str, *, initiation: Any,
                   policy: Any, termination: Any, reward: Any = None, transitions: Any = None,
                   gamma: float | None = None, subgoal: int | None = None, plugin: str = "",
                   plugin_version: str = "", parameters: Mapping[str, Any] | None = None,
                   ) -> E.Option:
        """Store an option (I (S,) bool, pi (S,) int64 or (S, A) float64, beta (S,) float64).

        ``reward`` is the model's R_o (S,) and ``transitions`` its discounted F_o (S, S), a
        scipy.sparse matrix stored as a COO table (row, col, value) sorted row-major.
        ``subgoal`` is a subgoal id (``SubgoalSet.subgoal_ids``).
        """
        name_text(name, "put_option: name")
        gamma = discount(gamma, "put_option: gamma", optional=True)
        env_id = _id(environment)
        S, A = self._env_shape(env_id)
        pol = np.asarray(policy)
        pol_art = self._array(pol, "option-policy", dtype=np.int64 if pol.ndim == 1 else np.float64,
                              shape=(S,) if pol.ndim == 1 else (S, A))
        init_art = self._array(initiation, "initiation", dtype=np.bool_, shape=(S,))
        beta_art = self._array(termination, "termination", dtype=np.float64, shape=(S,))
        r_art = self._array(reward, "option-reward", dtype=np.float64, shape=(S,))
        f_art = None
        if transitions is not None:
            F = sp.coo_array(sp.csr_array(transitions))
            if F.shape != (S, S):
                raise StoreError(f"option transitions have shape {F.shape}, expected ({S}, {S})")
            F.sum_duplicates()
            f_art = self._table({"row": F.row.astype(np.int64), "col": F.col.astype(np.int64),
                                 "value": F.data.astype(np.float64)}, "option-transitions")
        with self._session(write=True) as s:
            if subgoal is not None:
                self._need(s, SqlSubgoal, subgoal, "subgoal")
            self._ensure_rows(s, init_art, pol_art, beta_art, r_art, f_art)
            row = SqlOption(environment_id=env_id, subgoal_id=subgoal, name=name,
                            gamma=None if gamma is None else float(gamma),
                            initiation_sha=self._sha(init_art), policy_sha=self._sha(pol_art),
                            termination_sha=self._sha(beta_art), reward_sha=self._sha(r_art),
                            transitions_sha=self._sha(f_art),
                            **self._prov(plugin, plugin_version, parameters))
            s.add(row)
            s.flush()
            return self._entity(row)

    def put_partition(self, environment: E.Environment | int, kind: str, labels: Any, *,
                      options: Sequence[E.Option | int] = (), includes_primitives: bool = True,
                      epsilon: float, delta: float, block_actions: Any = None,
                      parents: Iterable[E.Partition | int] = (), task: E.Task | int | None = None,
                      plugin: str = "", plugin_version: str = "",
                      parameters: Mapping[str, Any] | None = None) -> E.Partition:
        """Store a partition: ``labels`` (S,) int64 with blocks 0..B-1 all used.

        The partition's action set is the primitive actions (when ``includes_primitives``)
        followed by ``options`` in order; ``block_actions`` is a (B, K) bool mask of the actions
        admissible in each block over that set.
        """
        if kind not in PARTITION_KINDS:
            raise StoreError(f"unknown partition kind {kind!r}; use one of "
                             f"{', '.join(PARTITION_KINDS)}")
        epsilon = threshold(epsilon, "put_partition: epsilon (eq. 4.7; inf: no reward split)",
                             math.inf)
        delta = threshold(delta, "put_partition: delta (eq. 4.6)", 1.0)
        env_id = _id(environment)
        S, A = self._env_shape(env_id)
        labels = np.asarray(labels, dtype=np.int64)
        if labels.shape != (S,):
            raise StoreError(f"partition labels have shape {labels.shape}, expected ({S},)")
        if labels.size and labels.min() < 0:
            raise StoreError("partition labels must be >= 0; relabel with np.unique(labels, "
                             "return_inverse=True)")
        n_blocks = int(labels.max()) + 1 if labels.size else 0
        if np.count_nonzero(np.bincount(labels, minlength=n_blocks)) != n_blocks:
            raise StoreError("partition labels must use every block 0..B-1; relabel with "
                             "np.unique(labels, return_inverse=True)")
        option_ids = [_id(o) for o in options]
        if len(set(option_ids)) != len(option_ids):
            raise StoreError("a partition's option set lists an option twice")
        K = (A if includes_primitives else 0) + len(option_ids)
        labels_art = self._array(labels, "labels")
        ba_art = self._array(block_actions, "block-actions", dtype=np.bool_, shape=(n_blocks, K))
        parent_ids = sorted({_id(p) for p in parents})
        with self._session(write=True) as s:
            for oid in option_ids:
                opt = self._need(s, SqlOption, oid, "option")
                if opt.environment_id != env_id:
                    raise StoreError(f"option:{oid} belongs to environment:{opt.environment_id}, "
                                     f"not environment:{env_id}")
            parent_rows = [self._need(s, SqlPartition, pid, "partition") for pid in parent_ids]
            self._ensure_rows(s, labels_art, ba_art)
            row = SqlPartition(
                environment_id=env_id, task_id=_id(task), kind=kind,
                includes_primitives=bool(includes_primitives), epsilon=float(epsilon),
                delta=float(delta), n_blocks=n_blocks, labels_sha=self._sha(labels_art),
                block_actions_sha=self._sha(ba_art),
                options=[SqlPartitionOption(option_id=oid, position=i)
                         for i, oid in enumerate(option_ids)],
                parents=parent_rows, **self._prov(plugin, plugin_version, parameters))
            s.add(row)
            s.flush()
            return self._entity(row)

    def put_run(self, task: E.Task | int, learner: str, *, curve: Any = None,
                metrics: Mapping[str, Any] | None = None,
                partition: E.Partition | int | None = None,
                seed: int | None = None, plugin: str = "", plugin_version: str = "",
                parameters: Mapping[str, Any] | None = None, experience: Any = None) -> E.Run:
        """Store a learning run: ``curve`` a table (episodes, steps, value gap, ...), metrics,
        and ``experience``, a table of the transitions its runs took (``state, action,
        next_state, count``), when the learner recorded them."""
        name_text(learner, "put_run: learner")
        seed = whole_number(seed, "put_run: seed", optional=True)
        metrics = dict(metrics or {})
        json_text(metrics, "metrics")
        task_id = _id(task)
        curve_art = self._table(curve, "curve")
        experience_art = self._table(experience, "experience")
        with self._session(write=True) as s:
            self._need(s, SqlTask, task_id, "task")
            self._ensure_rows(s, curve_art)
            self._ensure_rows(s, experience_art)
            row = SqlRun(task_id=task_id, partition_id=_id(partition), learner=learner, seed=seed,
                         curve_sha=self._sha(curve_art),
                         experience_sha=self._sha(experience_art), metrics=metrics,
                         **self._prov(plugin or learner, plugin_version, parameters))
            s.add(row)
            s.flush()
            return self._entity(row)

    def _env_shape(self, env_id: int | None) -> tuple[int, int]:
        with self._session() as s:
            env = self._need(s, SqlEnvironment, env_id, "environment")
            return int(env.n_states), int(env.n_actions)

    def _task_shape(self, task_id: int | None) -> tuple[int, int]:
        with self._session() as s:
            return self._env_shape(self._need(s, SqlTask, task_id, "task").environment_id)

    def put_array(self, array: Any, kind: str = "array") -> E.Artifact:
        """Store a bare array artifact (kept until ``gc`` finds nothing referencing it)."""
        pending = self._array(array, kind)
        with self._session(write=True) as s:
            self._ensure_rows(s, pending)
        return self._artifact_row(pending.stored.sha256)

    def put_table(self, table: pa.Table | dict[str, Any], kind: str = "table") -> E.Artifact:
        """Store a bare table artifact."""
        pending = self._table(table, kind)
        with self._session(write=True) as s:
            self._ensure_rows(s, pending)
        return self._artifact_row(pending.stored.sha256)
