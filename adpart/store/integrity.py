"""Content hashes of metadata rows: a flipped bit in any row is named by ``adpart kb check``.

Artifacts carry their own hashes; this module gives every metadata row one too. Each table of
the schema has a ``row_sha`` column holding the SHA-256 of a canonical encoding of the row's other
columns *as the database returns them*: the compact, sorted-key JSON of the values in the
model's column order (floats by ``repr``, times as whole microseconds since the epoch, UTC),
made by the json module's C encoder in one call per row. That is schema 4's encoding; schemas
2-3 wrapped each value in Python first, at about twice the cost per row, and the 3 -> 4
migration checks every row against its old hash before re-stamping it, so an upgrade never
turns a damaged row into a valid one. Hashing the read-back values rather than the Python
values handed to the ORM makes the hash independent of driver conversions: the audit re-reads
the row the same way and must get the same bytes.

The hash is set by an ``after_insert``/``after_update`` mapper event inside the writing
transaction, so no committed row is ever without one; the same event puts the read-back values
into the written object, so what a writer holds is what a reader will get. A partition's hash also
covers its parent links (the ``partition_parents`` association, which has no row hash of its own):
a changed link is named as a change of the child partition.

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

from sqlalchemy import Connection, DateTime, Table, event, inspect, select, update
from sqlalchemy.orm import Mapper

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


_LAYOUTS: dict[str, _Layout] = {}


def _layout(table: Table) -> _Layout:
    found = _LAYOUTS.get(table.name)
    if found is None:
        found = _LAYOUTS[table.name] = _Layout(table)
    return found


def row_digest(table: Table, row: Mapping[str, Any], parents: Iterable[int] | None = None) -> str:
    """SHA-256 of ``row`` (column name -> value as read back), all columns but ``row_sha``.

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


def values_digest(table: Table, values: tuple[Any, ...]) -> str:
    """:func:`row_digest` of a row given as the tuple of its :func:`hashed_columns` values (a
    plain ``select`` of those columns: no mapping built per row)."""
    return _layout(table).digest(values)


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
        keys = [(col.name, key) for key, col in mapper.columns.items() if col.table is table]
        _KEYS[table.name] = keys
        _SAME_NAMES[table.name] = all(name == key for name, key in keys)
    return keys


_KEYS: dict[str, list[tuple[str, str]]] = {}
_SAME_NAMES: dict[str, bool] = {}


def row_problem(obj: Any) -> str | None:
    """What is wrong with a loaded ORM row (its hash differs, or it has none), or None.

    The row's values are taken as the ORM loaded them (the same column types the audit reads
    with); a partition's parent links come from its loaded ``parents``.
    """
    table = type(obj).__table__
    state = obj.__dict__
    keys = _attribute_keys(table, obj)
    if _SAME_NAMES.get(table.name):
        values = state  # attributes named as their columns (every adpart table): no copy
    else:
        values = {name: state.get(key) for name, key in keys}
    stored = values.get(ROW_SHA)
    if stored is None:
        return unhashed_message(row_name(table, values), table.name)
    parents = [p.id for p in obj.parents] if table.name == "partitions" else None
    try:
        digest = row_digest(table, values, parents)
    except KeyError:  # an attribute not loaded: read as the columns map it
        digest = row_digest(table, {name: state.get(key) for name, key in keys}, parents)
    if digest != stored:
        return changed_message(row_name(table, values), table.name)
    return None


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
    row = connection.execute(select(table).where(where)).mappings().one()
    parents = None
    if table.name == "partitions":
        parents = [p.id for p in target.parents]
    digest = row_digest(table, row, parents)
    connection.execute(update(table).where(where).values({ROW_SHA: digest}))
    # keep the identity map in step without another flush: the object holds the values as read
    # back (a tuple given becomes the list stored), so a later read in the same transaction
    # verifies against the same bytes the hash was made of
    for name, key in _attribute_keys(table, target):
        target.__dict__[key] = row[name]
    target.__dict__[ROW_SHA] = digest


def install(base: type) -> None:
    """Stamp every row of ``base``'s mapped classes with its hash as it is inserted or updated."""
    event.listen(base, "after_insert", _stamp, propagate=True)
    event.listen(base, "after_update", _stamp, propagate=True)
