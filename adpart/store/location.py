"""Where a knowledge base lives: a directory, or a SQLAlchemy URL plus an artifact root.

Resolution order for the location: the explicit argument (``--kb``), then ``$ADPART_KB``, then
``$ADPART_HOME/kb``, then ``$XDG_DATA_HOME/adpart/kb``, then ``~/.local/share/adpart/kb``. A
directory holds ``kb.sqlite`` and ``artifacts/`` and is created on first use. A database URL
(``sqlite:///...``, ``postgresql+psycopg://...``) takes its artifact root from the explicit
argument (``--kb-artifacts``) or ``$ADPART_KB_ARTIFACTS``; a ``sqlite:///`` file defaults to an
``artifacts/`` directory beside it.

A directory always keeps its own ``artifacts/``: ``$ADPART_KB_ARTIFACTS`` (meant for database
URLs) is ignored for it, so the directory reads the same whether or not the variable is set, and
an explicit ``--kb-artifacts`` elsewhere is refused. Every artifact root belongs to one knowledge
base (its owner file, :meth:`~adpart.store.artifacts.ArtifactStore.claim`).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

from adpart.store.errors import StoreError

DB_FILE = "kb.sqlite"
ARTIFACT_DIR = "artifacts"
_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+_.-]*://")


def default_location() -> str:
    """The per-user default location (see the module docstring for the order)."""
    if os.environ.get("ADPART_KB"):
        return os.environ["ADPART_KB"]
    if os.environ.get("ADPART_HOME"):
        return str(Path(os.environ["ADPART_HOME"]) / "kb")
    data = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return str(Path(data) / "adpart" / "kb")


def _make_dir(path: Path, what: str) -> None:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StoreError(
            f"cannot create the {what} {path}: {exc.strerror or exc}; choose a writable "
            "directory with --kb or ADPART_KB"
        ) from exc
    if not os.access(path, os.W_OK | os.X_OK):
        raise StoreError(f"the {what} {path} is not writable; choose a writable directory with "
                         "--kb or ADPART_KB")


#: how to get a knowledge base, for the messages of the reading commands
MAKE_ONE = ("make one with `adpart learn ENV --kb PATH`, or pass --kb / set ADPART_KB to an "
            "existing one")


def _must_exist(path: Path, what: str) -> None:
    if not path.is_dir():
        raise StoreError(f"there is no {what} {path}; check --kb / ADPART_KB (reading commands "
                         f"never create one): {MAKE_ONE}")


@dataclass(frozen=True)
class KBLocation:
    """A resolved location: the database URL, the artifact root and a label for messages."""

    db_url: str
    artifact_uri: str
    label: str

    @classmethod
    def resolve(cls, location: str | os.PathLike[str] | None = None,
                artifacts: str | None = None, *, create: bool = True) -> KBLocation:
        """Resolve ``location`` (directory or URL) and ``artifacts`` (module docstring).

        With ``create=False`` (the reading commands: ``kb info/ls/show/check/export``) nothing
        is made and nothing needs to be writable, but a directory must already hold a
        knowledge base.
        """
        make_dir = _make_dir if create else _must_exist
        where = str(location) if location is not None else default_location()
        given = artifacts or None
        if _URL.match(where) and not where.startswith("file://"):
            artifacts = given or os.environ.get("ADPART_KB_ARTIFACTS") or None
            from sqlalchemy.engine import make_url  # a URL only: --help never gets here
            from sqlalchemy.exc import ArgumentError

            try:
                url = make_url(where)
                url.get_backend_name()
                url.render_as_string(hide_password=True)
            except (ArgumentError, ValueError) as exc:
                raise StoreError(f"{where!r} is not a database URL or a directory ({exc}); pass "
                                 "--kb a directory or a URL such as sqlite:////path/kb.sqlite "
                                 "or postgresql+psycopg://user@host/db") from exc
            label = url.render_as_string(hide_password=True)
            if artifacts is None:
                on_disk = url.database not in (None, "", ":memory:")
                if url.get_backend_name() == "sqlite" and on_disk:
                    db_file = Path(url.database).expanduser().resolve()
                    make_dir(db_file.parent, "knowledge base directory")
                    artifacts = str(db_file.parent / ARTIFACT_DIR)
                else:
                    raise StoreError(f"the database URL {label} needs an artifact root: pass "
                                     "--kb-artifacts URI or set ADPART_KB_ARTIFACTS")
            return cls(where, artifacts, label)
        directory = Path(where.removeprefix("file://")).expanduser().resolve()
        own = directory / ARTIFACT_DIR
        if given is not None and not ("://" not in given
                                      and Path(given).expanduser().resolve() == own):
            raise StoreError(f"--kb-artifacts {given} is for a database URL: the knowledge base "
                             f"directory {directory} keeps its artifacts in {own}; drop "
                             "--kb-artifacts, or pass --kb a database URL")
        make_dir(directory, "knowledge base directory")
        if not create and not (directory / DB_FILE).is_file():
            raise StoreError(f"{directory} holds no knowledge base (no {DB_FILE}; reading "
                             f"commands never create one): {MAKE_ONE}")
        return cls(f"sqlite:///{directory / DB_FILE}", str(own), str(directory))
