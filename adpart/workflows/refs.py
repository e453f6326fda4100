"""Record references as users type them: ``KIND:N`` (``subgoal-set:3``) or a bare number."""

from __future__ import annotations

import re
from typing import Any

from adpart.errors import AdpartError
from adpart.workflows.store import KnowledgeStore

_REF = re.compile(r"^(?:(?P<kind>[a-z][a-z-]*):)?(?P<id>[0-9]{1,18})$")


class ReferenceError_(AdpartError, ValueError):
    """A record reference that is malformed or names the wrong kind of record."""


def parse_ref(text: str, kind: str) -> int:
    """The id in ``text`` (``"kind:N"`` or ``"N"``), checking that the kind is ``kind``."""
    match = _REF.match(str(text).strip())
    if not match:
        raise ReferenceError_(f"{text!r} is not a {kind} id; write {kind}:N (e.g. {kind}:3) or N")
    given = match.group("kind")
    if given is not None and given != kind:
        raise ReferenceError_(f"{text!r} names a {given}, but a {kind} is needed here ({kind}:N)")
    return int(match.group("id"))


def get_ref(kb: KnowledgeStore, text: str, kind: str) -> Any:
    """The record of ``kind`` that ``text`` names (raises a StoreError when it does not exist)."""
    return kb.get(kind, parse_ref(text, kind))
