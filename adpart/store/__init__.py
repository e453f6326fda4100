"""The knowledge base: SQLAlchemy 2 metadata plus content-addressed Parquet artifacts.

``KnowledgeBase.open()`` opens the per-user default (``$ADPART_KB``, ``$ADPART_HOME/kb`` or
``~/.local/share/adpart/kb``); see docs/knowledge-base.md for the records and the CLI.

For analysis, ``open_kb(path, read_only=True)`` and the table methods::

    from adpart.store import open_kb
    with open_kb("~/.local/share/adpart/kb", read_only=True) as kb:
        runs = kb.records_table("run", env="two-rooms", where={"alpha": 1}).to_pandas()
        curves = kb.curves_table(kb.records_table("run", env="two-rooms")).to_pandas()
        to_bound = kb.runs_table(env="three-floor").to_pandas()  # a row per run
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from adpart.lazy import lazy_exports

if TYPE_CHECKING:
    from adpart.store.entities import (
        Artifact,
        Environment,
        Option,
        Partition,
        Policy,
        Provenance,
        Record,
        Run,
        SubgoalSet,
        Task,
    )
    from adpart.store.errors import StoreError
    from adpart.store.kb import KnowledgeBase, open_kb
    from adpart.store.location import KBLocation, default_location
    from adpart.store.maintenance import CheckReport, GcReport
    from adpart.store.schema import SCHEMA_VERSION

lazy_exports(__name__, {
    "adpart.store.entities": (
        "Artifact", "Environment", "Option", "Partition", "Policy", "Provenance", "Record", "Run",
        "SubgoalSet", "Task",
    ),
    "adpart.store.errors": ("StoreError",),
    "adpart.store.kb": ("KnowledgeBase", "open_kb"),
    "adpart.store.location": ("KBLocation", "default_location"),
    "adpart.store.maintenance": ("CheckReport", "GcReport"),
    "adpart.store.schema": ("SCHEMA_VERSION",),
})

__all__ = [
    "SCHEMA_VERSION",
    "Artifact",
    "CheckReport",
    "Environment",
    "GcReport",
    "KBLocation",
    "KnowledgeBase",
    "Option",
    "Partition",
    "Policy",
    "Provenance",
    "Record",
    "Run",
    "StoreError",
    "SubgoalSet",
    "Task",
    "default_location",
    "open_kb",
]
