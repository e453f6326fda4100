"""Content hashes of metadata rows: a flipped bit in any row is named by ``adpart kb check``.

Artifacts carry their own hashes; this module gives every metadata row one too. Each table of
the schema has a ``row_sha`` column holding the SHA-256 of the table's name and hashed column
names followed by the text the *database* renders of the row's stored values, :class:`RowText`
(schema 5: SQLite's ``json_array``, PostgreSQL's ``json_build_array``, both exact and
independent of session settings). A verifying read selects that text with the row and hashes
one string, where schema 4 encoded every value in Python (:func:`row_digest_v4`, kept with
schema 3's :func:`row_digest_v3` for the migrations, which check every row against its old hash
before re-stamping it, so an upgrade never turns a damaged row into a valid one).

The hash is set by an ``after_insert``/``after_update`` mapper event inside the writing
transaction, so no committed row is ever without one; the same event puts the read-back values
and their text into the written object, so what a writer holds is what a reader will get. A
partition's hash also covers its parent links (the ``partition_parents`` association, which has
no row hash of its own): a changed link is named as a change of the child partition.

Every read compares the hash too (:func:`row_problem`, called by the knowledge base's readers on
each row they return, its subgoal and option-set rows included), so a changed value is refused on
read, not only by the audit.
"""

from __future__ import annotations

import hashlib
import json
import math
import operator
from collections.abc import Iterable, Mapping
from datetime import datetime, timedelta, timezone
from json.encoder import c_make_encoder, encode_basestring_ascii  # type: ignore[attr-defined]
from typing import Any

from sqlalchemy import Connection, DateTime, Float, String, Table, event, inspect, select, update
from sqlalchemy.ext.compiler import compiles
from sqlalchemy.orm import Mapper, column_property
from sqlalchemy.sql.compiler import SQLCompiler
from sqlalchemy.sql.functions import FunctionElement

from adpart.store.errors import StoreError

ROW_SHA = "row_sha"


def _plain(value: Any) -> Any:
    """Schema 2-3's canonical form of one value (kept for the 3 -> 4 migration, which checks
    every row against its schema-3 hash before re-stamping it)."""
    kind = type(value)
    if kind is str or kind is int or value is None or kind is bool:  # most values: as they are
        return value
    if kind is float:
        return {"float": repr(value) if math.isfinite(value) else str(value)}
    if kind is dict:
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, datetime):
        return {"datetime": _utc_text(value)}
    if isinstance(value, float):
        return {"float": repr(value) if math.isfinite(value) else str(value)}
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return {"other": str(value)}


def _utc_text(value: datetime) -> str:
    """A time as UTC ISO text; a naive one (SQLite's) is UTC already."""
    zone = value.tzinfo
    if zone is None:  # the same text as replace(tzinfo=timezone.utc).isoformat()
        return value.isoformat() + "+00:00"
    if zone is timezone.utc:
        return value.isoformat()
    return value.astimezone(timezone.utc).isoformat()


_EPOCH = datetime(1970, 1, 1)
_EPOCH_UTC = _EPOCH.replace(tzinfo=timezone.utc)
_MICROSECOND = timedelta(microseconds=1)


def _micros(value: Any) -> Any:
    """A time as whole microseconds since 1970-01-01 UTC (exact; a naive time, SQLite's, is
    UTC already; an aware one, PostgreSQL's in any session time zone, the same instant)."""
    if not isinstance(value, datetime):
        return value  # not a time (a damaged value): hashed as it is, so it cannot match
    return (value - (_EPOCH if value.tzinfo is None else _EPOCH_UTC)) // _MICROSECOND


def _non_json(value: Any) -> Any:
    """The canonical encoder's fallback for a value JSON has no form for: tagged text."""
    return {"other": f"{type(value).__name__}:{value}"}


#: the canonical encoding (schema 4): compact JSON with sorted keys, floats by ``repr``
#: (``NaN``/``Infinity`` as JSON's extensions); times are made whole microseconds first
#: (:func:`_micros`)
_json_encode = json.JSONEncoder(sort_keys=True, separators=(",", ":"), check_circular=False,
                                default=_non_json).encode
#: the json module's C encoder with the same settings, made once (``JSONEncoder.encode`` makes
#: one per call, about half the cost of a row's hash); None where the C speedups are missing
_c_encode = (None if c_make_encoder is None else
             c_make_encoder(None, _non_json, encode_basestring_ascii, None, ":", ",", True,
                            False, True))


def _encode(value: Any) -> str:
    """The canonical JSON text of ``value`` (the same text either way it is made)."""
    if _c_encode is None:
        return _json_encode(value)
    return "".join(_c_encode(value, 0))


_encode_v3 = json.JSONEncoder(sort_keys=True, separators=(",", ":")).encode


class _Layout:
    """A table's hashed columns (all but ``row_sha``, in the model's order), the positions of
    its time columns, and the digest of its name and column names, which every row's digest
    continues."""

    def __init__(self, table: Table) -> None:
        columns = [c for c in table.columns if c.name != ROW_SHA]
        self.names = [c.name for c in columns]
        self.values = operator.itemgetter(*self.names)
        self.times = [i for i, c in enumerate(columns) if isinstance(c.type, DateTime)]
        #: the digest's first bytes; a row's digest hashes them and the row's text in one call
        #: (the same digest as continuing a copy of their hash, and cheaper than copying one)
        self.head = _encode([table.name, self.names]).encode()

    def digest(self, values: Iterable[Any], parents: Iterable[int] | None = None) -> str:
        """The row hash of the hashed columns' ``values`` (in :attr:`names` order)."""
        row = list(values)
        for i in self.times:
            row[i] = _micros(row[i])
        if parents is not None:
            row.append(sorted(int(p) for p in parents))
        return hashlib.sha256(self.head + _encode(row).encode()).hexdigest()

    def text_digest(self, text: str, parents: Iterable[int] | None = None) -> str:
        """The row hash (schema 5) of a row whose :class:`RowText` the database rendered as
        ``text``; a partition's sorted parent ids follow it as a JSON list."""
        data = self.head + text.encode()
        if parents is not None:
            data += _encode(sorted(int(p) for p in parents)).encode()
        return hashlib.sha256(data).hexdigest()


_LAYOUTS: dict[str, _Layout] = {}


def _layout(table: Table) -> _Layout:
    found = _LAYOUTS.get(table.name)
    if found is None:
        found = _LAYOUTS[table.name] = _Layout(table)
    return found


class RowText(FunctionElement):  # type: ignore[type-arg]
    """SQL: the text of a row's hashed columns as the database itself renders it (schema 5).

    One JSON array per row, made by the database engine in C while it reads the row, so a
    verifying read hashes one string per row instead of encoding its values in Python:

    - SQLite: ``json_array(c1, c2, ...)`` of the stored values; text (JSON columns and times
      included) is embedded as the string stored, a REAL column as its ``quote()`` text, which
      round-trips exactly (``json_array`` itself prints 15 digits). A value SQLite cannot put in
      JSON (a BLOB, which no adpart column holds) fails the read, and the row is named
      unreadable.
    - PostgreSQL: ``json_build_array(...)::text``; JSON columns nest as stored, times are taken
      in UTC (``AT TIME ZONE 'UTC'``, ISO text independent of the session's time zone), a double
      as the hex of its eight bytes (``float8send``, independent of ``extra_float_digits``).

    The text is a function of the stored values alone, so a writer and every later reader of
    the same row on the same database make the same bytes.
    """

    type = String()
    name = "adpart_row_text"
    inherit_cache = True


def _row_text_parts(element: RowText, compiler: SQLCompiler, wrap: Any, **kw: Any) -> str:
    return ", ".join(wrap(column, compiler.process(column, **kw))
                     for column in element.clauses.clauses)


@compiles(RowText, "sqlite")
def _sqlite_row_text(element: RowText, compiler: SQLCompiler, **kw: Any) -> str:
    def wrap(column: Any, sql: str) -> str:
        return f"quote({sql})" if isinstance(column.type, Float) else sql

    return f"json_array({_row_text_parts(element, compiler, wrap, **kw)})"


@compiles(RowText, "postgresql")
def _postgresql_row_text(element: RowText, compiler: SQLCompiler, **kw: Any) -> str:
    def wrap(column: Any, sql: str) -> str:
        if isinstance(column.type, Float):
            return f"encode(float8send({sql}), 'hex')"
        if isinstance(column.type, DateTime):
            return f"({sql} AT TIME ZONE 'UTC')"
        return sql

    return f"json_build_array({_row_text_parts(element, compiler, wrap, **kw)})::text"


@compiles(RowText)
def _unsupported_row_text(element: RowText, compiler: SQLCompiler, **kw: Any) -> str:
    raise StoreError(f"row hashes are made on SQLite and PostgreSQL only, not on "
                     f"{compiler.dialect.name}")


#: the attribute (and result label) every hashed model's :class:`RowText` is read under
ROW_TEXT = "row_text"


def _row_text_of(table: Table) -> RowText:
    return RowText(*(table.c[n] for n in _layout(table).names))


def row_text(table: Table) -> Any:
    """The :class:`RowText` of ``table``'s hashed columns, labelled :data:`ROW_TEXT`."""
    return _row_text_of(table).label(ROW_TEXT)


def text_digest(table: Table, text: str, parents: Iterable[int] | None = None) -> str:
    """The row hash of a row of ``table`` whose :func:`row_text` the database returned."""
    return _layout(table).text_digest(text, parents)


def row_digest_v4(table: Table, row: Mapping[str, Any],
                  parents: Iterable[int] | None = None) -> str:
    """The row hash schema 4 wrote: SHA-256 of ``row`` (column name -> value as read back),
    all columns but ``row_sha``; read only by the 4 -> 5 migration.

    The bytes hashed: the compact JSON of ``[table, [column names]]``, then that of the list of
    the row's values in the same order, times as whole microseconds since the epoch (UTC), a
    partition's sorted parent ids appended. Values are hashed as the database returns them, so
    the hash is that of what a reader gets.
    """
    layout = _layout(table)
    return layout.digest(layout.values(row), parents)


def hashed_columns(table: Table) -> list[str]:
    """The names of the columns a row hash of ``table`` covers, in the order it takes them."""
    return list(_layout(table).names)


def row_digest_v3(table: Table, row: Mapping[str, Any],
                  parents: Iterable[int] | None = None) -> str:
    """The row hash schema versions 2 and 3 wrote (each value through :func:`_plain`, then one
    sorted-key JSON object); read only by the 3 -> 4 migration."""
    names = _layout(table).names
    payload: dict[str, Any] = {"table": table.name,
                               "columns": {n: _plain(row[n]) for n in names}}
    if parents is not None:
        payload["parents"] = sorted(int(p) for p in parents)
    return hashlib.sha256(_encode_v3(payload).encode()).hexdigest()


#: table name -> the record kind its rows are named by in messages
KIND_OF_TABLE = {"environments": "environment", "tasks": "task", "policies": "policy",
                 "subgoal_sets": "subgoal-set", "subgoals": "subgoal", "options": "option",
                 "partitions": "partition", "partition_options": "partition-option",
                 "runs": "run", "artifacts": "artifact"}


def row_name(table: Table, row: Mapping[str, Any]) -> str:
    """How a row is named in messages: ``run:3``, ``artifact:<16 hex>``, ``subgoal:4 (of ...)``."""
    if table.name == "artifacts":
        return f"artifact:{str(row['sha256'])[:16]}"
    if table.name == "partition_options":
        return f"partition:{row['partition_id']}'s option link to option:{row['option_id']}"
    if table.name == "subgoals":
        return f"subgoal:{row['id']} (of subgoal-set:{row['subgoal_set_id']})"
    return f"{KIND_OF_TABLE.get(table.name, table.name)}:{row['id']}"


def changed_message(name: str, table: str) -> str:
    """The one message for a row whose content no longer matches its hash."""
    return (f"{name} is damaged: its metadata row (table {table}) changed since it was written "
            "(row hash mismatch); re-create the record (`adpart kb rm`, then run it again) or "
            "restore from a backup")


def unhashed_message(name: str, table: str) -> str:
    return (f"{name} has no row hash (table {table}); run `adpart kb upgrade`, or re-create the "
            "record")


def _attribute_keys(table: Table, obj: Any) -> list[tuple[str, str]]:
    keys = _KEYS.get(table.name)
    if keys is None:
        mapper = inspect(type(obj))
        keys = [(col.name, key) for key, col in mapper.columns.items()
                if getattr(col, "table", None) is table]
        _KEYS[table.name] = keys
    return keys


_KEYS: dict[str, list[tuple[str, str]]] = {}


def row_problem(obj: Any) -> str | None:
    """What is wrong with a loaded ORM row (its hash differs, or it has none), or None.

    The row's :class:`RowText` is the one read with it (verifying readers undefer it); where
    it was not, reading the attribute loads it. A partition's parent links come from its
    loaded ``parents``. A row read with its text and found whole takes one SHA-256 and a
    few dictionary lookups (a listing verifies every row it reads).
    """
    state = obj.__dict__
    head = _HEADS.get(type(obj))
    if head is not None:
        stored, text = state.get(ROW_SHA), state.get(ROW_TEXT)
        if text is not None and stored is not None and _sha256(head + text.encode()
                                                               ).hexdigest() == stored:
            return None
    return _row_problem(obj)


def _row_problem(obj: Any) -> str | None:
    """:func:`row_problem` of any row: no hash, no text read yet, a partition, a mismatch."""
    table = type(obj).__table__
    state = obj.__dict__
    if table.name != "partitions":  # a partition's digest adds its parent links
        _HEADS[type(obj)] = _layout(table).head
    stored = state.get(ROW_SHA)
    if stored is None:
        keys = _attribute_keys(table, obj)
        return unhashed_message(row_name(table, {name: state.get(key) for name, key in keys}),
                                table.name)
    text = state.get(ROW_TEXT)
    if text is None:
        text = getattr(obj, ROW_TEXT)
    parents = [p.id for p in obj.parents] if table.name == "partitions" else None
    if _layout(table).text_digest(text, parents) != stored:
        keys = _attribute_keys(table, obj)
        return changed_message(row_name(table, {name: state.get(key) for name, key in keys}),
                               table.name)
    return None


#: model class -> its digest's first bytes (:attr:`_Layout.head`), for :func:`row_problem`'s
#: one-hash path; partitions are left out (their digest adds the parent links)
_HEADS: dict[type, bytes] = {}
_sha256 = hashlib.sha256


def _key_clause(table: Table, mapper: Mapper, target: Any) -> Any:
    clause = None
    for column, value in zip(mapper.primary_key, mapper.primary_key_from_instance(target),
                             strict=True):
        term = table.c[column.name] == value
        clause = term if clause is None else clause & term
    return clause


def _stamp(mapper: Mapper, connection: Connection, target: Any) -> None:
    table = mapper.local_table
    if ROW_SHA not in table.c:
        return
    where = _key_clause(table, mapper, target)
    row = connection.execute(select(table, row_text(table)).where(where)).mappings().one()
    parents = None
    if table.name == "partitions":
        parents = [p.id for p in target.parents]
    digest = text_digest(table, row[ROW_TEXT], parents)
    connection.execute(update(table).where(where).values({ROW_SHA: digest}))
    # keep the identity map in step without another flush: the object holds the values as read
    # back (a tuple given becomes the list stored) and their text, so a later read in the same
    # transaction verifies against the same bytes the hash was made of
    for name, key in _attribute_keys(table, target):
        target.__dict__[key] = row[name]
    target.__dict__[ROW_TEXT] = row[ROW_TEXT]
    target.__dict__[ROW_SHA] = digest


def install(base: type) -> None:
    """Give every hashed model of ``base`` its :class:`RowText` (a deferred attribute
    :data:`ROW_TEXT`, read by verifying readers), and stamp every row with its hash as it is
    inserted or updated."""
    for mapper in list(base.registry.mappers):  # type: ignore[attr-defined]
        table = mapper.local_table
        if ROW_SHA in table.c and ROW_TEXT not in mapper.attrs:
            setattr(mapper.class_, ROW_TEXT, column_property(_row_text_of(table), deferred=True))
    event.listen(base, "after_insert", _stamp, propagate=True)
    event.listen(base, "after_update", _stamp, propagate=True)
