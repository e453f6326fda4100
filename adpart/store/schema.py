"""Schema versioning: a one-row ``adpart_schema`` table, checked on every open.

adpart keeps a linear schema history (version 1, 2, ...) with one Python migration step per
version, in the manner of llm's migration list rather than Alembic (see docs/knowledge-base.md for
why). :func:`verify_schema` refuses a knowledge base written by a newer adpart, one that is older
than this adpart (``adpart kb upgrade`` migrates it), and a database that holds tables but no
adpart schema row (not a knowledge base).
"""

from __future__ import annotations

import uuid
from collections.abc import Callable
from datetime import datetime, timezone

from sqlalchemy import Connection, func, inspect, select, text, update

from adpart import __version__
from adpart.store.errors import StoreError
from adpart.store.integrity import (
    ROW_SHA,
    ROW_TEXT,
    row_digest_v3,
    row_digest_v4,
    row_name,
    row_text,
    text_digest,
)
from adpart.store.models import HASHED_TABLES, Base, SqlIdentity, SqlSchema, partition_parents

#: the schema version this adpart reads and writes
#: (2: every metadata row carries ``row_sha``, its content hash, checked by ``adpart kb check``;
#: 3: a run may reference its experience, the transitions its runs took: ``runs.experience_sha``;
#: 4: row hashes in the encoding the json module's C encoder makes in one call per row, about a
#: third of the cost of schema 3's per-value one: :func:`adpart.store.integrity.row_digest_v4`;
#: 5: row hashes over the text the database renders of the row, :class:`adpart.store.integrity.
#: RowText`, so that a verifying read hashes one string per row)
SCHEMA_VERSION = 5


def stamp_all_rows(conn: Connection, *, check: Callable[..., str] | None = None) -> list[str]:
    """(Re)compute the content hash of every row of every hashed table.

    With ``check`` (the row hash the database was written with), a row whose stored hash does
    not match it keeps that hash: it was damaged before the upgrade and stays named as damaged
    (by reads and ``adpart kb check``) instead of being stamped valid. Returns those rows' names.
    """
    kept: list[str] = []
    links: dict[int, list[int]] = {}
    for child, parent in conn.execute(select(partition_parents.c.child_id,
                                             partition_parents.c.parent_id)):
        links.setdefault(int(child), []).append(int(parent))
    for table in HASHED_TABLES:
        key = [c for c in table.primary_key.columns]
        for row in conn.execute(select(table, row_text(table))).mappings().all():
            parents = links.get(int(row["id"]), []) if table.name == "partitions" else None
            if check is not None and check(table, row, parents) != row[ROW_SHA]:
                kept.append(row_name(table, row))
                continue
            where = None
            for column in key:
                term = column == row[column.name]
                where = term if where is None else where & term
            conn.execute(update(table).where(where).values(
                {ROW_SHA: text_digest(table, row[ROW_TEXT], parents)}))
    return kept


def _add_row_hashes(conn: Connection) -> None:
    """Schema 1 -> 2: a ``row_sha`` column on every metadata table (filled once the last step
    has run: a row's hash covers the columns of the current schema)."""
    for table in HASHED_TABLES:
        conn.execute(text(f"ALTER TABLE {table.name} ADD COLUMN {ROW_SHA} VARCHAR(64)"))


def _add_run_experience(conn: Connection) -> None:
    """Schema 2 -> 3: ``runs.experience_sha``, empty for existing runs (their row hashes are
    recomputed over it once the last step has run)."""
    conn.execute(text("ALTER TABLE runs ADD COLUMN experience_sha VARCHAR(64)"))


def _reencode_row_hashes(conn: Connection) -> None:
    """Schema 3 -> 4 and 4 -> 5: the row hashes' encoding changed; no column did. Every row is
    re-stamped once the last step has run, after its hash of the version it was written with
    was checked (:data:`CHECKED_BY`)."""


#: MIGRATIONS[v] upgrades a version-v database to version v + 1 inside one transaction
MIGRATIONS: dict[int, Callable[[Connection], None]] = {1: _add_row_hashes,
                                                       2: _add_run_experience,
                                                       3: _reencode_row_hashes,
                                                       4: _reencode_row_hashes}

#: the row hash a database of version v was written with, over the current columns, checked
#: before its rows are re-stamped (versions 1-2 lack a column the hashes now cover: their rows
#: are re-stamped unchecked, as those upgrades always did)
CHECKED_BY: dict[int, Callable[..., str]] = {3: row_digest_v3, 4: row_digest_v4}


def read_version(conn: Connection, location: str) -> tuple[int, str] | None:
    """The (version, written_by) of the database, or None when it holds no tables at all."""
    tables = set(inspect(conn).get_table_names())
    if not tables:
        return None
    if SqlSchema.__tablename__ not in tables:
        raise StoreError(
            f"{location} holds tables ({', '.join(sorted(tables)[:5])}) but no adpart schema "
            "record: it is not an adpart knowledge base (unknown schema); point --kb / ADPART_KB "
            "at an empty or adpart location"
        )
    rows = conn.execute(select(SqlSchema.version, SqlSchema.written_by).limit(2)).all()
    if len(rows) > 1:
        raise StoreError(
            f"{location} has {conn.scalar(select(func.count()).select_from(SqlSchema))} adpart "
            "schema rows where there is exactly one: the database was edited by hand or is "
            "damaged; restore it from a backup (or point --kb / ADPART_KB elsewhere)"
        )
    row = rows[0] if rows else None
    if row is None or not isinstance(row[0], int) or row[0] < 1:
        raise StoreError(
            f"{location} has an unknown adpart schema version ({row[0] if row else 'none'}); it "
            "was not written by adpart or is damaged: point --kb / ADPART_KB elsewhere"
        )
    return int(row[0]), str(row[1])


def verify_schema(version: int, written_by: str, location: str) -> None:
    """Refuse a schema this adpart cannot read, naming the fix."""
    if version > SCHEMA_VERSION:
        raise StoreError(
            f"knowledge base {location} has schema version {version} and was written by a newer "
            f"adpart ({written_by}); this adpart ({__version__}) reads schema version "
            f"{SCHEMA_VERSION}: upgrade adpart"
        )
    if version < SCHEMA_VERSION:
        raise StoreError(
            f"knowledge base {location} has schema version {version}, older than this adpart's "
            f"{SCHEMA_VERSION}: back it up, then run `adpart kb upgrade`"
        )


def verify_tables(conn: Connection, location: str) -> None:
    """Refuse a current-version database whose tables lack a column this adpart writes (e.g.
    ``row_sha`` dropped): it would open and then fail at the first write or read."""
    found = inspect(conn)
    tables = set(found.get_table_names())
    columns = {name: cols for (_, name), cols in found.get_multi_columns().items()}
    for table in Base.metadata.sorted_tables:
        if table.name == SqlIdentity.__tablename__:
            continue  # added at the first writable open when missing (identity_of)
        if table.name not in tables:
            raise StoreError(f"knowledge base {location} has no table {table.name}, which schema "
                             f"version {SCHEMA_VERSION} has: it is damaged or was edited by "
                             "hand; restore it from a backup")
        have = {c["name"] for c in columns.get(table.name, [])}
        missing = [c.name for c in table.columns if c.name not in have]
        if missing:
            raise StoreError(f"knowledge base {location}: table {table.name} has no column "
                             f"{', '.join(missing)}, which schema version {SCHEMA_VERSION} has: "
                             "it is damaged or was edited by hand; restore it from a backup")


def read_identity(conn: Connection) -> str | None:
    """This knowledge base's id, or None when it has none yet (made before identities)."""
    if SqlIdentity.__tablename__ not in inspect(conn).get_table_names():
        return None
    ids = conn.execute(select(SqlIdentity.kb_id).limit(2)).scalars().all()
    if len(ids) > 1:
        raise StoreError("the knowledge base has two identity rows where there is one: it was "
                         "edited by hand or is damaged; restore it from a backup")
    return str(ids[0]) if ids else None


def identity_of(conn: Connection) -> str:
    """This knowledge base's id, made (table and row) if it has none yet; needs the write lock."""
    found = read_identity(conn)
    if found is not None:
        return found
    SqlIdentity.__table__.create(conn, checkfirst=True)
    kb_id = str(uuid.uuid4())
    conn.execute(SqlIdentity.__table__.insert().values(id=1, kb_id=kb_id,
                                                       created_at=datetime.now(timezone.utc)))
    return kb_id


def create_schema(conn: Connection) -> None:
    """Create every table of the current schema in an empty database and record its version
    and a fresh identity."""
    Base.metadata.create_all(conn)
    conn.execute(SqlSchema.__table__.insert().values(id=1, version=SCHEMA_VERSION,
                                                     written_by=__version__))
    identity_of(conn)


def upgrade_schema(conn: Connection, location: str, damaged: list[str] | None = None,
                   ) -> tuple[int, int]:
    """Apply the migration steps from the stored version up to :data:`SCHEMA_VERSION`.

    Returns (from_version, to_version). An empty database is created at the current version.
    Rows found damaged before the upgrade (:func:`stamp_all_rows`) are named in ``damaged``.
    """
    found = read_version(conn, location)
    if found is None:
        create_schema(conn)
        return SCHEMA_VERSION, SCHEMA_VERSION
    version, written_by = found
    if version > SCHEMA_VERSION:
        verify_schema(version, written_by, location)
    start = version
    while version < SCHEMA_VERSION:
        step = MIGRATIONS.get(version)
        if step is None:
            raise StoreError(f"no migration from schema version {version} of {location}; "
                             "upgrade adpart to a release that can migrate it")
        step(conn)
        version += 1
        conn.execute(SqlSchema.__table__.update().values(version=version, written_by=__version__))
    if version != start:  # every row's hash, over the columns of the schema it now has
        kept = stamp_all_rows(conn, check=CHECKED_BY.get(start))
        if damaged is not None:
            damaged.extend(kept)
    return start, version
