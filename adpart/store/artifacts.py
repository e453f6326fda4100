"""Content-addressed Parquet artifacts on any pyarrow filesystem.

An artifact is a numpy array or a table. Its name is the SHA-256 of a canonical encoding: a small
JSON header (format, dtype in little-endian form, shape; or the column names and Arrow types) and
the little-endian C-order bytes of the values. Identical content therefore gets one file whatever
process wrote it, and a read recomputes the hash and refuses anything that does not match.

Files live at ``<root>/<sha[:2]>/<sha>.parquet``, written zstd-compressed to a temporary name in
the same directory and renamed into place, so a reader never sees half a file: a writer killed
mid-way leaves at most a ``.tmp-*`` file, which ``adpart kb gc`` removes. Nothing is pickled: the
values are a single Parquet column (``values``) and the dtype/shape sit in the schema metadata, so
any Parquet reader can open an artifact.

Verification costs one disk read, one hash and one decode per read. A write encodes the Parquet
file in memory from the values whose content hash names the artifact and records the SHA-256 of
exactly those bytes (the *file hash*); an already present file is first decoded and compared with
the values, so a file hash is never recorded for damaged bytes. A read loads the file's bytes
once, hashes them on a second thread while pyarrow decodes the same buffer, and accepts the values
when the hash equals the recorded file hash: equal hashes mean the bytes are the ones the encoder
produced from those values, and the Parquet round trip is exact, so the content hash need not be
recomputed. Without a recorded file hash, and in ``verify`` (``adpart kb check``), the content
hash is recomputed as well. See docs/knowledge-base.md, "Why one hash is enough".
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import stat
import time
import uuid
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.fs as pafs
import pyarrow.parquet as pq

from adpart.store.errors import StoreError

ARRAY_FORMAT = "parquet-array/1"
TABLE_FORMAT = "parquet-table/1"
_META_KEY = b"adpart"
_ROW_GROUP = 1 << 20  # row groups of 1M values let pyarrow decode in parallel on read
_SUPPORTED_KINDS = "biuf"  # bool, signed/unsigned integers, floats
_TMP_PREFIX = ".tmp-"
#: Writes of one artifact file before giving up, when a concurrent gc removes its temporary.
_WRITE_ATTEMPTS = 5
_NAME = re.compile(r"^[0-9a-f]{2}/[0-9a-f]{64}\.parquet$")
_TMP_NAME = re.compile(r"^[0-9a-f]{2}/\.tmp-[0-9a-f]+\.parquet$")
_THREADED_HASH_BYTES = 1 << 20  # below this a second thread costs more than it saves
#: the file at the top of an artifact root naming the knowledge base that owns it
OWNER_FILE = "adpart-owner.json"


@dataclass(frozen=True)
class StoredArtifact:
    """What :meth:`ArtifactStore.put_array` / :meth:`ArtifactStore.put_table` wrote (or found)."""

    sha256: str
    uri: str  # path relative to the artifact root, ``ab/abcdef....parquet``
    format: str  # ARRAY_FORMAT or TABLE_FORMAT
    nbytes: int  # size of the Parquet file
    file_sha256: str  # SHA-256 of the file's bytes: catches damage that leaves the values intact
    dtype: str | None  # numpy dtype string of an array (None for tables)
    shape: tuple[int, ...] | None  # array shape (None for tables)


def _canonical_array(array: np.ndarray) -> np.ndarray:
    """Little-endian C-order copy (or view) of ``array``; refuses dtypes Parquet cannot hold."""
    if array.dtype.kind not in _SUPPORTED_KINDS:
        raise StoreError(
            f"cannot store an array of dtype {array.dtype}: artifacts hold bool, integer and float "
            "arrays; convert it (e.g. np.asarray(x, dtype=np.float64)) first"
        )
    return np.asarray(array, dtype=array.dtype.newbyteorder("<"), order="C")


def _header_digest(header: dict[str, Any]) -> hashlib._Hash:
    encoded = json.dumps(header, sort_keys=True, separators=(",", ":")).encode()
    digest = hashlib.sha256()
    digest.update(len(encoded).to_bytes(8, "little"))
    digest.update(encoded)
    return digest


def array_sha256(array: np.ndarray) -> str:
    """SHA-256 of an array: JSON header (dtype, shape), then its little-endian C-order bytes."""
    canon = _canonical_array(np.asarray(array))
    digest = _header_digest({"format": ARRAY_FORMAT, "dtype": canon.dtype.str,
                             "shape": canon.shape})
    digest.update(canon.reshape(-1).view(np.uint8))
    return digest.hexdigest()


def as_table(table: pa.Table | dict[str, Any]) -> pa.Table:
    """Convert a dict of 1-D columns to a pyarrow Table (a Table loses only its metadata)."""
    if isinstance(table, dict):
        try:
            table = pa.table({str(k): np.asarray(v) if not isinstance(v, pa.Array | pa.ChunkedArray)
                              else v for k, v in table.items()})
        except (pa.ArrowException, ValueError, TypeError) as exc:
            raise StoreError(f"cannot make a table of these columns ({exc}); pass 1-D columns "
                             "of equal length") from exc
    if not isinstance(table, pa.Table):
        raise StoreError("expected a pyarrow Table or a dict of columns, got "
                         f"{type(table).__name__}")
    return table.replace_schema_metadata(None)


def table_sha256(table: pa.Table) -> str:
    """SHA-256 of a table's canonical encoding: column names/types, validity masks and values."""
    table = as_table(table)
    digest = _header_digest({
        "format": TABLE_FORMAT,
        "rows": table.num_rows,
        "columns": [[f.name, str(f.type)] for f in table.schema],
    })
    for field, column in zip(table.schema, table.columns, strict=True):
        col = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
        valid = col.is_valid().to_numpy(zero_copy_only=False)
        digest.update(np.packbits(valid).tobytes())
        kind = field.type
        if pa.types.is_boolean(kind) or pa.types.is_integer(kind) or pa.types.is_floating(kind):
            values = col.fill_null(False if pa.types.is_boolean(kind) else 0)
            digest.update(_canonical_array(values.to_numpy(zero_copy_only=False)).view(np.uint8))
        elif pa.types.is_string(kind) or pa.types.is_large_string(kind):
            for text in col.fill_null("").to_pylist():
                raw = text.encode()
                digest.update(len(raw).to_bytes(8, "little"))
                digest.update(raw)
        else:
            raise StoreError(
                f"cannot store table column {field.name!r} of type {kind}: tables hold bool, "
                "integer, float and string columns"
            )
    return digest.hexdigest()


def _label(sha256: str, context: str) -> str:
    return f"artifact {sha256[:12]}" + (f" (referenced by {context})" if context else "")


def _hash_and_decode(buffer: pa.Buffer) -> tuple[str, pa.Table | None, Exception | None]:
    """SHA-256 of ``buffer`` and its Parquet decoding (or the decoding error), side by side.

    Large buffers are hashed on a second thread while pyarrow decodes: hashlib and the Parquet
    reader both release the GIL, so the hash costs little wall time on a multi-core machine.
    """
    def decode() -> tuple[pa.Table | None, Exception | None]:
        try:
            return pq.read_table(pa.BufferReader(buffer)), None
        except (pa.ArrowException, OSError, ValueError) as exc:
            return None, exc

    if buffer.size < _THREADED_HASH_BYTES:
        return hashlib.sha256(buffer).hexdigest(), *decode()
    with ThreadPoolExecutor(max_workers=1) as pool:
        digest = pool.submit(lambda: hashlib.sha256(buffer).hexdigest())
        table, problem = decode()
        return digest.result(), table, problem


def _table_meta(table: pa.Table) -> dict[str, Any]:
    """The adpart metadata of a decoded artifact file (raises KeyError/ValueError if absent)."""
    meta = json.loads((table.schema.metadata or {})[_META_KEY])
    if not isinstance(meta, dict):
        raise TypeError("adpart metadata is not an object")
    return meta


def _array_from_table(table: pa.Table) -> np.ndarray:
    """The array an array artifact's decoded file holds, in its stored (little-endian) dtype."""
    meta = _table_meta(table)
    if meta.get("format") != ARRAY_FORMAT:
        raise ValueError(f"format {meta.get('format')!r} is not an array")
    dtype = np.dtype(meta["dtype"])
    values = table.column("values").to_numpy(zero_copy_only=False)
    return np.asarray(values, dtype=dtype).reshape(tuple(meta["shape"]))


def _holds_array(table: pa.Table, canon: np.ndarray) -> bool:
    """Whether a decoded array artifact holds ``canon`` bit for bit (NaN payloads included).

    Compared row group by row group against slices of ``canon``, so no full-size copy or mask
    is made.
    """
    meta = _table_meta(table)
    if (meta.get("format") != ARRAY_FORMAT or np.dtype(meta["dtype"]) != canon.dtype
            or tuple(meta["shape"]) != canon.shape):
        return False
    flat = canon.reshape(-1).view(np.uint8).reshape(-1, canon.dtype.itemsize)
    start = 0
    for chunk in table.column("values").chunks:
        values = np.asarray(chunk.to_numpy(zero_copy_only=False), dtype=canon.dtype)
        stop = start + len(values)
        if stop > len(flat) or not np.array_equal(
                values.view(np.uint8).reshape(-1, canon.dtype.itemsize), flat[start:stop]):
            return False
        start = stop
    return start == len(flat)


def check_relative_uri(uri: str) -> str:
    """Refuse an artifact URI that is not a plain ``ab/<sha>.parquet`` path under the root."""
    parts = uri.replace("\\", "/").split("/")
    if (not uri or uri.startswith(("/", "\\")) or re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:", uri)
            or any(p in ("", ".", "..") for p in parts)):
        raise StoreError(
            f"artifact uri {uri!r} would escape the artifact root (absolute path, scheme or '..'); "
            "the knowledge base was edited by hand or damaged: run `adpart kb check`"
        )
    if not _NAME.match(uri):
        raise StoreError(f"artifact uri {uri!r} is not of the form 'ab/<sha256>.parquet'; "
                         "run `adpart kb check`")
    return uri


class ArtifactStore:
    """Parquet artifacts named by content hash under one root on a pyarrow filesystem.

    Args:
        root: a local directory or any URI ``pyarrow.fs.FileSystem.from_uri`` understands
            (``file:///...``, ``s3://bucket/prefix``, ...). A local directory is created
            unless ``create`` is false (a read-only open).
    """

    def __init__(self, root: str, *, create: bool = True) -> None:
        try:
            if "://" in root:
                self.fs, base = pafs.FileSystem.from_uri(root)
            else:
                self.fs, base = pafs.LocalFileSystem(), os.path.abspath(os.path.expanduser(root))
        except (pa.ArrowException, OSError, ValueError) as exc:
            raise StoreError(f"cannot use artifact root {root!r}: {exc}; choose a writable "
                             "directory or filesystem URI") from exc
        self.root = root
        self.base = base.rstrip("/")
        if create:
            self.create()

    def create(self) -> None:
        """Make the root directory (a no-op when it exists)."""
        try:
            self.fs.create_dir(self.base, recursive=True)
        except (pa.ArrowException, OSError, ValueError) as exc:
            raise StoreError(f"cannot use artifact root {self.root!r}: {exc}; choose a writable "
                             "directory or filesystem URI") from exc

    def check_creatable(self) -> None:
        """Refuse, before anything is made, a local root that could not be created or written:
        its nearest existing ancestor must be a writable directory."""
        if not self.local:
            return
        path = self.base
        while not os.path.lexists(path):
            parent = os.path.dirname(path)
            if parent == path:
                break
            path = parent
        if not os.path.isdir(path) or not os.access(path, os.W_OK | os.X_OK):
            what = "is not a directory" if not os.path.isdir(path) else "is not writable"
            raise StoreError(f"cannot use artifact root {self.root!r}: {path} {what}; choose a "
                             "writable directory or filesystem URI")

    # ------------------------------------------------------------------ ownership
    def owner(self) -> dict[str, Any] | None:
        """The owner record of the root (``kb_id``, ``database``, ...), or None if it has none.

        A file that is not an owner record is an error: the root cannot be told apart from
        another program's directory.
        """
        path = f"{self.base}/{OWNER_FILE}"
        try:
            if self.fs.get_file_info(path).type != pafs.FileType.File:
                return None
            with self.fs.open_input_stream(path) as source:
                data = json.loads(source.read().decode())
        except (pa.ArrowException, OSError, ValueError) as exc:
            raise StoreError(f"artifact root {self.root!r}: its owner file {OWNER_FILE} cannot "
                             f"be read ({exc}); restore it, or give this knowledge base another "
                             "root with --kb-artifacts / ADPART_KB_ARTIFACTS") from exc
        if not isinstance(data, dict) or not isinstance(data.get("kb_id"), str):
            raise StoreError(f"artifact root {self.root!r}: {OWNER_FILE} is not an adpart owner "
                             "record; give this knowledge base another root with --kb-artifacts "
                             "/ ADPART_KB_ARTIFACTS")
        return data

    def refuse_other_owner(self, kb_id: str | None, label: str,
                           owner: dict[str, Any] | None = None) -> None:
        """Raise if the root is owned by a knowledge base other than ``kb_id`` (None: a
        knowledge base about to be created, which owns no root yet)."""
        owner = self.owner() if owner is None else owner
        if owner is None or owner["kb_id"] == kb_id:
            return
        raise StoreError(
            f"the artifact root {self.root} belongs to another knowledge base "
            f"({owner.get('database', 'unknown database')}, id {owner['kb_id']}), not to "
            f"{label}; two knowledge bases sharing a root would delete each other's artifacts in "
            "`adpart kb gc`: give this one its own root with --kb-artifacts / ADPART_KB_ARTIFACTS"
        )

    def claim(self, kb_id: str, label: str) -> None:
        """Make the root (if needed) and record ``kb_id`` as its owner, unless it has one.

        On a local root the owner file appears whole or not at all and only once (a complete
        temporary file is hard-linked to its name, which fails if it exists); then the record
        found is checked, so a second knowledge base racing for a fresh root is refused too.
        """
        self.create()
        record = json.dumps({"kb_id": kb_id, "database": label, "written_by": "adpart",
                             "created_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())},
                            indent=2).encode()
        final = f"{self.base}/{OWNER_FILE}"
        try:
            if self.local:
                tmp = f"{self.base}/.owner-{uuid.uuid4().hex}"
                with open(tmp, "wb") as out:
                    out.write(record)
                try:
                    os.link(tmp, final)
                except FileExistsError:
                    pass
                finally:
                    os.unlink(tmp)
            elif self.fs.get_file_info(final).type != pafs.FileType.File:
                with self.fs.open_output_stream(final) as out:
                    out.write(record)
        except (pa.ArrowException, OSError) as exc:
            raise StoreError(f"cannot write the owner file of artifact root {self.root!r}: "
                             f"{exc}; check the root is writable") from exc
        self.refuse_other_owner(kb_id, label)

    # ------------------------------------------------------------------ paths
    def path(self, uri: str) -> str:
        """Filesystem path of a relative artifact URI, refusing anything that escapes the root."""
        return f"{self.base}/{check_relative_uri(uri)}"

    @staticmethod
    def uri_for(sha256: str) -> str:
        return f"{sha256[:2]}/{sha256}.parquet"

    def exists(self, uri: str) -> bool:
        return self.fs.get_file_info(self.path(uri)).type == pafs.FileType.File

    # ------------------------------------------------------------------ writes
    def put_array(self, array: np.ndarray) -> StoredArtifact:
        """Store ``array`` (any shape, incl. 0-d and empty) bit-exactly; returns hash and URI."""
        canon = _canonical_array(np.asarray(array))
        sha = array_sha256(canon)
        uri = self.uri_for(sha)

        def holds_canon(table: pa.Table) -> bool:
            return _holds_array(table, canon)

        file_sha = self._existing(uri, holds_canon)
        if file_sha is None:
            meta = {"format": ARRAY_FORMAT, "dtype": canon.dtype.str,
                    "shape": list(canon.shape), "sha256": sha}
            table = pa.table({"values": pa.array(canon.reshape(-1))})
            table = table.replace_schema_metadata({_META_KEY: json.dumps(meta)})
            file_sha = self._write(uri, table, dictionary=canon.dtype.kind != "f")
        return StoredArtifact(sha, uri, ARRAY_FORMAT, self._size(uri), file_sha,
                              canon.dtype.str, tuple(canon.shape))

    def put_table(self, table: pa.Table | dict[str, Any]) -> StoredArtifact:
        """Store a table (pyarrow Table or dict of 1-D columns); returns its hash and URI."""
        table = as_table(table)
        sha = table_sha256(table)
        uri = self.uri_for(sha)

        def holds_table(decoded: pa.Table) -> bool:
            return table_sha256(decoded.replace_schema_metadata(None)) == sha

        file_sha = self._existing(uri, holds_table)
        if file_sha is None:
            meta = {_META_KEY: json.dumps({"format": TABLE_FORMAT, "sha256": sha})}
            file_sha = self._write(uri, table.replace_schema_metadata(meta), dictionary=True)
        return StoredArtifact(sha, uri, TABLE_FORMAT, self._size(uri), file_sha, None, None)

    def _existing(self, uri: str, holds: Callable[[pa.Table], bool]) -> str | None:
        """File hash of an already stored artifact whose decoded content passes ``holds``.

        ``None`` if there is no such file, or if it is damaged (the caller then writes it again):
        the file hash about to be recorded must only ever vouch for verified bytes.
        """
        if not self.exists(uri):
            return None
        try:
            digest, table, _ = _hash_and_decode(self._read_bytes(uri))
            return digest if table is not None and holds(table) else None
        except (StoreError, KeyError, ValueError, TypeError, pa.ArrowException):
            return None

    def _write(self, uri: str, table: pa.Table, *, dictionary: bool) -> str:
        """Encode ``table`` in memory and store the bytes (temporary name + rename); the file hash.

        The file hash is taken of the very buffer that is written, on a second thread while the
        bytes go to disk, so it vouches for exactly what the encoder produced from the values.
        """
        try:
            sink = pa.BufferOutputStream()
            pq.write_table(table, sink, compression="zstd", use_dictionary=dictionary,
                           row_group_size=_ROW_GROUP)
            encoded = sink.getvalue()
        except (pa.ArrowException, OSError) as exc:
            raise StoreError(f"cannot encode artifact {uri} as Parquet: {exc}") from exc
        final = self.path(uri)
        directory = final.rsplit("/", 1)[0]
        with ThreadPoolExecutor(max_workers=1) as pool:
            digest = pool.submit(lambda: hashlib.sha256(encoded).hexdigest())
            for attempt in range(_WRITE_ATTEMPTS):
                tmp = f"{directory}/{_TMP_PREFIX}{uuid.uuid4().hex}.parquet"
                try:
                    self.fs.create_dir(directory, recursive=True)
                    with self.fs.open_output_stream(tmp) as out:
                        out.write(encoded)
                    self.fs.move(tmp, final)
                    break
                except (pa.ArrowException, OSError) as exc:
                    # a gc with no temporary age may take the temporary before the rename:
                    # then it is written again; any other failure is the writer's to report
                    taken = isinstance(exc, FileNotFoundError) and self._missing(tmp)
                    with contextlib.suppress(pa.ArrowException, OSError):  # may never have been
                        self.fs.delete_file(tmp)
                    if not (taken and attempt + 1 < _WRITE_ATTEMPTS):
                        raise StoreError(f"cannot write artifact {uri} under {self.root!r}: "
                                         f"{exc}; check the artifact root is writable and has "
                                         "space") from exc
            return digest.result()

    def _missing(self, path: str) -> bool:
        """Whether ``path`` does not exist (False when that cannot be told)."""
        try:
            return self.fs.get_file_info(path).type == pafs.FileType.NotFound
        except (pa.ArrowException, OSError):
            return False

    def _size(self, uri: str) -> int:
        return int(self.fs.get_file_info(self.path(uri)).size or 0)

    # ------------------------------------------------------------------ reads
    def _read_bytes(self, uri: str, label: str = "") -> pa.Buffer:
        """The whole file in memory (one read: the hash and the decoder see the same bytes)."""
        label = label or f"artifact {uri}"
        path = self.path(uri)
        if self.fs.get_file_info(path).type != pafs.FileType.File:
            raise StoreError(f"{label} is missing from {self.root!r}; run `adpart kb check` "
                             "to list the damage")
        try:
            with self.fs.open_input_file(path) as source:
                return source.read_buffer()
        except (pa.ArrowException, OSError) as exc:
            raise StoreError(f"{label} cannot be read from {self.root!r} ({exc}); check the "
                             "artifact root, then run `adpart kb check`") from exc

    def _read(self, sha256: str, uri: str, context: str, file_sha256: str | None) -> pa.Table:
        """Decoded table of an artifact file whose bytes hash to ``file_sha256`` (if given)."""
        label = _label(sha256, context)
        digest, table, problem = _hash_and_decode(self._read_bytes(uri, label))
        if file_sha256 is not None and digest != file_sha256:
            raise StoreError(f"{label} is damaged: the file's bytes changed since it was "
                             "written; run `adpart kb check` and re-create the record")
        if table is None:
            raise StoreError(f"{label} is damaged and cannot be decoded ({problem}); run "
                             "`adpart kb check` and re-create the record") from problem
        return table

    @staticmethod
    def _mismatch(sha256: str, actual: str, context: str) -> StoreError:
        return StoreError(f"{_label(sha256, context)} is damaged: its content hashes to "
                          f"{actual[:12]}; run `adpart kb check` and re-create the record")

    def get_array(self, sha256: str, uri: str, *, context: str = "",
                  file_sha256: str | None = None, full: bool = False) -> np.ndarray:
        """Read an array artifact, verified (see the module docstring for what is checked).

        With ``file_sha256`` (the hash recorded at write time) a matching file hash is the proof;
        without it, or with ``full=True``, the decoded values are hashed against ``sha256`` too.
        ``context`` names the referencing record(s) for the error message.
        """
        table = self._read(sha256, uri, context, file_sha256)
        try:
            if _table_meta(table).get("sha256") != sha256:
                raise ValueError("the file names another artifact")
            array = _array_from_table(table)
        except (KeyError, ValueError, TypeError, pa.ArrowException) as exc:
            raise self._mismatch(sha256, "<undecodable>", context) from exc
        if full or file_sha256 is None:
            actual = array_sha256(array)
            if actual != sha256:
                raise self._mismatch(sha256, actual, context)
        return array.astype(array.dtype.newbyteorder("="), copy=False)

    def get_table(self, sha256: str, uri: str, *, context: str = "",
                  file_sha256: str | None = None, full: bool = False) -> pa.Table:
        """Read a table artifact, verified like :meth:`get_array`."""
        table = self._read(sha256, uri, context, file_sha256)
        try:
            claimed = _table_meta(table).get("sha256")
        except (KeyError, ValueError, TypeError) as exc:
            raise self._mismatch(sha256, "<undecodable>", context) from exc
        table = table.replace_schema_metadata(None)
        if claimed != sha256:
            raise self._mismatch(sha256, f"<a file of artifact {claimed}>", context)
        if full or file_sha256 is None:
            try:
                actual = table_sha256(table)
            except StoreError as exc:
                raise self._mismatch(sha256, "<undecodable>", context) from exc
            if actual != sha256:
                raise self._mismatch(sha256, actual, context)
        return table

    def verify(self, sha256: str, uri: str, fmt: str, *, context: str = "",
               file_sha256: str | None = None) -> None:
        """Read and check one artifact fully (file hash and content hash); raises on damage.

        This is ``adpart kb check``'s audit: unlike a load it also recomputes the content hash,
        so a recorded file hash that was itself wrong (a row edited by hand) is caught too.
        """
        read = self.get_array if fmt == ARRAY_FORMAT else self.get_table
        read(sha256, uri, context=context, file_sha256=file_sha256, full=True)

    # ------------------------------------------------------------------ listing / deletion
    @property
    def local(self) -> bool:
        return isinstance(self.fs, pafs.LocalFileSystem)

    def scan(self) -> Scan:
        """What lies under the root, sorted into artifact files, temporaries, strays and links.

        On a local root nothing is followed: the walk uses ``lstat`` semantics
        (``os.walk(followlinks=False)``), so a symlinked directory or file inside the root is
        reported in ``skipped`` and never listed, let alone deleted. Only ``ab/<sha>.parquet``
        files and ``ab/.tmp-*`` temporaries inside a two-hex-digit directory are adpart's; any
        other file is a stray, reported and left alone.
        """
        files: list[tuple[str, int, float]] = []
        temporary: list[tuple[str, int, float]] = []
        strays: list[str] = []
        skipped: list[str] = []
        for rel, size, mtime, is_link in self._walk():
            if rel == OWNER_FILE and not is_link:
                continue  # the root's owner record: adpart's, never listed or deleted
            if is_link:
                skipped.append(rel)
            elif _NAME.match(rel):
                files.append((rel, size, mtime))
            elif _TMP_NAME.match(rel):
                temporary.append((rel, size, mtime))
            else:
                strays.append(rel)
        return Scan(sorted(files), sorted(temporary), sorted(strays), sorted(skipped))

    def _walk(self) -> list[tuple[str, int, float, bool]]:
        """(relative path, bytes, mtime, is a symlink) of every entry that is not a directory."""
        out: list[tuple[str, int, float, bool]] = []
        if not self.local:  # object stores have no symlinks
            selector = pafs.FileSelector(self.base, recursive=True, allow_not_found=True)
            for info in self.fs.get_file_info(selector):
                if info.type == pafs.FileType.File:
                    mtime = info.mtime.timestamp() if info.mtime is not None else 0.0
                    out.append((info.path.removeprefix(self.base + "/"), int(info.size or 0),
                                mtime, False))
            return out
        for top, dirs, names in os.walk(self.base, followlinks=False):
            rel_top = os.path.relpath(top, self.base)
            prefix = "" if rel_top == "." else rel_top.replace(os.sep, "/") + "/"
            for name in dirs + names:
                try:
                    st = os.lstat(os.path.join(top, name))
                except FileNotFoundError:  # a writer renamed its temporary file meanwhile
                    continue
                if stat.S_ISLNK(st.st_mode):
                    out.append((prefix + name, 0, st.st_mtime, True))
                elif stat.S_ISREG(st.st_mode):
                    out.append((prefix + name, int(st.st_size), st.st_mtime, False))
        return out

    def files(self) -> list[tuple[str, int, float]]:
        """Every artifact and temporary file under the root as (relative path, bytes, mtime)."""
        scan = self.scan()
        return sorted(scan.files + scan.temporary)

    @staticmethod
    def is_temporary(rel: str) -> bool:
        return rel.rsplit("/", 1)[-1].startswith(_TMP_PREFIX)

    def delete(self, rel: str) -> None:
        """Delete one adpart file (``ab/<sha>.parquet`` or ``ab/.tmp-*``) under the root.

        Anything else is refused. On a local root the file and its directory are checked with
        ``lstat`` first: a symlink (or a directory that resolves outside the root) is never
        deleted through.
        """
        if not (_NAME.match(rel) or _TMP_NAME.match(rel)):
            raise StoreError(f"refusing to delete {rel!r}: not an adpart artifact file")
        path = f"{self.base}/{rel}"
        if self.local:
            directory = os.path.dirname(path)
            try:
                if (stat.S_ISLNK(os.lstat(directory).st_mode)
                        or os.path.realpath(os.path.dirname(directory))
                        != os.path.realpath(self.base)
                        or not stat.S_ISREG(os.lstat(path).st_mode)):
                    raise StoreError(f"refusing to delete {rel!r}: it is a symlink or lies "
                                     "outside the artifact root")
                os.unlink(path)
            except FileNotFoundError:
                return
            except OSError as exc:
                raise StoreError(f"cannot delete {rel} under {self.root!r}: {exc}") from exc
            return
        try:
            self.fs.delete_file(path)
        except FileNotFoundError:
            return
        except (pa.ArrowException, OSError) as exc:
            raise StoreError(f"cannot delete {rel} under {self.root!r}: {exc}") from exc


@dataclass(frozen=True)
class Scan:
    """The artifact root sorted by :meth:`ArtifactStore.scan` (paths relative to the root)."""

    files: list[tuple[str, int, float]]  # ab/<sha>.parquet: (path, bytes, mtime)
    temporary: list[tuple[str, int, float]]  # ab/.tmp-*: a write in progress or abandoned
    strays: list[str]  # anything else (notes.txt, ...): reported, never deleted
    skipped: list[str]  # symlinks: never followed, never deleted

