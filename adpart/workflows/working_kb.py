"""The knowledge base an experiment works in: the one given, or a temporary one removed after.

``with working_kb(location, purpose) as kb:`` opens ``location`` when given (results stay there,
and a rerun reuses them) and otherwise a knowledge base in a fresh temporary directory that is
removed, with everything in it, when the block ends. Experiments open their knowledge base only
through here, so they never import the store.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from pathlib import Path

from adpart.store import KnowledgeBase

__all__ = ["working_kb"]


@contextmanager
def working_kb(location: str | Path | None, purpose: str) -> Iterator[KnowledgeBase]:
    """The knowledge base at ``location``, or a temporary one named after ``purpose``."""
    place = (tempfile.TemporaryDirectory(prefix=f"adpart-{purpose}-") if location is None
             else nullcontext(location))
    with place as where:
        kb = KnowledgeBase.open(where)
        try:
            yield kb
        finally:
            kb.close()
