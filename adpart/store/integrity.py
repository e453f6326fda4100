"""Content hashes of metadata rows: a flipped bit in any row is named by ``adpart kb check``.

Artifacts carry their own hashes; this module gives every metadata row one too. Each table of
the schema has a ``row_sha`` column holding the SHA-256 of a canonical encoding of the row's other
columns *as the database returns them* (floats by ``repr``, datetimes in UTC ISO form, JSON as
sorted-key compact JSON). Hashing the read-back values rather than the Python values handed to
the ORM makes the hash independent of driver conversions: the audit re-reads the row the same way
and must get the same bytes.

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
from collections.abc import Iterable, Mapping
from datetime import datetime, timezone
from typing import Any

from sqlalchemy import Connection, Table, event, inspect, select, update
from sqlalchemy.orm import Mapper

ROW_SHA = "row_sha"


def _plain(value: Any) -> Any:
    kind = type(value)
    if kind is str or kind is int or value is None or kind is bool:  # most values: as they are
        return value
    if kind is float:
        return {"float": repr(value) if math.isfinite(value) else str(value)}
    if kind is dict:
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, datetime):
        zone = value.tzinfo
        if zone is None:  # the same text as replace(tzinfo=timezone.utc).isoformat()
            return {"datetime": value.isoformat() + "+00:00"}
        if zone is timezone.utc:
            return {"datetime": value.isoformat()}
        return {"datetime": value.astimezone(timezone.utc).isoformat()}
    if isinstance(value, float):
        return {"float": repr(value) if math.isfinite(value) else str(value)}
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return {"other": str(value)}


_HASHED_COLUMNS: dict[str, list[str]] = {}
#: the canonical encoding: ``json.dumps(..., sort_keys=True, separators=(",", ":"))``, its encoder
#: made once (every read hashes the rows it returns)
_encode = json.JSONEncoder(sort_keys=True, separators=(",", ":")).encode


def row_digest(table: Table, row: Mapping[str, Any], parents: Iterable[int] | None = None) -> str:
    """SHA-256 of ``row`` (column name -> value as read back), all columns but ``row_sha``."""
    names = _HASHED_COLUMNS.get(table.name)
    if names is None:
        names = _HASHED_COLUMNS[table.name] = [c.name for c in table.columns if c.name != ROW_SHA]
    payload = {"table": table.name, "columns": {n: _plain(row[n]) for n in names}}
    if parents is not None:
        payload["parents"] = sorted(int(p) for p in parents)
    return hashlib.sha256(_encode(payload).encode()).hexdigest()


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
    if _SAME_NAMES.get(table.name) and all(name in state for name, _ in keys):
        values = state  # attributes named as their columns (every adpart table): no copy
    else:
        values = {name: state.get(key) for name, key in keys}
    stored = values.get(ROW_SHA)
    if stored is None:
        return unhashed_message(row_name(table, values), table.name)
    parents = [p.id for p in obj.parents] if table.name == "partitions" else None
    if row_digest(table, values, parents) != stored:
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
