"""The one-read, one-hash, one-decode verified read and the write-time check it relies on.

A load trusts the recorded file hash instead of re-hashing the decoded values; these tests pin
down why that is safe: every byte of the file is covered by the file hash, the hash and the decoder
see the same bytes, an already present file is only blessed with a file hash after its decoding
was compared with the values, and ``kb check`` still recomputes the content hash as an audit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import text

from adpart.store import KnowledgeBase, StoreError
from adpart.store import artifacts as artifacts_mod
from adpart.store.artifacts import ArtifactStore, array_sha256


def _file(kb: KnowledgeBase, sha: str) -> Path:
    return Path(kb.artifacts.base) / kb.artifacts.uri_for(sha)


@pytest.fixture
def stored(kb):
    env = kb.put_environment("e", model_hash="a" * 64, n_states=3000, n_actions=4)
    task = kb.put_task(env, "t", spec={}, gamma=0.9)
    q = np.random.default_rng(1).standard_normal((3000, 4))
    q[5, 1] = np.nan
    policy = kb.put_policy(task, "q", q=q)
    run = kb.put_run(task, "r", curve={"episode": np.arange(50), "name": [f"e{i}" for i in
                                                                          range(50)]})
    return kb, policy, run, q


@pytest.mark.parametrize("offset", [0, 3, 4, 0.25, 0.5, 0.9, -9, -5, -1])
def test_a_flipped_byte_anywhere_is_reported_by_load_and_check(stored, offset):
    """Magic, page headers, data, footer (Thrift metadata), footer length, trailing magic."""
    kb, policy, _, _ = stored
    path = _file(kb, policy.q)
    data = bytearray(path.read_bytes())
    at = int(offset * len(data)) if isinstance(offset, float) else offset
    data[at] ^= 0x10
    path.write_bytes(bytes(data))
    with pytest.raises(StoreError, match=rf"{policy.q[:12]} \(referenced by "
                                         rf"policy:{policy.id} \(q\)\) is damaged"):
        kb.load(policy, "q")
    problems = kb.check().problems
    assert len(problems) == 1 and f"policy:{policy.id} (q)" in problems[0]


def test_load_trusts_a_matching_file_hash_and_check_recomputes_content(stored, monkeypatch):
    kb, policy, _, q = stored
    calls = []
    real = artifacts_mod.array_sha256
    monkeypatch.setattr(artifacts_mod, "array_sha256", lambda a: calls.append(1) or real(a))
    np.testing.assert_array_equal(kb.load(policy, "q"), q)  # NaN compares equal here
    assert calls == []
    assert kb.check().ok
    assert len(calls) >= 1


def test_another_valid_artifact_behind_a_hand_edited_row_is_refused(stored):
    """Row points at a different, intact artifact file and carries that file's hash."""
    kb, policy, run, _ = stored
    other = kb.put_array(np.arange(12000.0).reshape(3000, 4))
    with kb.engine.begin() as conn:
        conn.execute(text("UPDATE artifacts SET uri = :u, file_sha256 = :f WHERE sha256 = :s"),
                     {"u": other.uri, "f": other.file_sha256, "s": policy.q})
        conn.execute(text("UPDATE artifacts SET uri = :u, file_sha256 = :f WHERE sha256 = :s"),
                     {"u": other.uri, "f": other.file_sha256, "s": run.curve})
    with pytest.raises(StoreError, match=rf"policy:{policy.id} \(q\).*damaged"):
        kb.load(policy, "q")
    with pytest.raises(StoreError, match=rf"run:{run.id} \(curve\).*damaged"):
        kb.load(run, "curve")
    kb._verify_rows = False  # behind the row hash, the content hash refuses the other file
    with pytest.raises(StoreError, match=rf"policy:{policy.id} \(q\)\) is damaged"):
        kb.load(policy, "q")
    kb._verify_rows = True
    problems = kb.check().problems
    assert any(f"policy:{policy.id} (q)" in p for p in problems)
    assert any(f"run:{run.id} (curve)" in p for p in problems)


def test_a_wrong_recorded_file_hash_is_refused(stored):
    kb, policy, _, _ = stored
    with kb.engine.begin() as conn:
        conn.execute(text("UPDATE artifacts SET file_sha256 = :f WHERE sha256 = :s"),
                     {"f": "0" * 64, "s": policy.q})
    with pytest.raises(StoreError, match=r"policy:1 \(q\): .*row hash mismatch"):
        kb.load(policy, "q")  # the row hash refuses the edited row first
    kb._verify_rows = False
    with pytest.raises(StoreError, match="bytes changed since it was written"):
        kb.load(policy, "q")
    assert not kb.check().ok


def test_recorded_file_hash_is_the_hash_of_the_file(stored):
    """Independent oracle: hashlib over the bytes on disk, read by plain Python."""
    import hashlib

    kb, policy, run, _ = stored
    for sha in (policy.q, run.curve):
        row = kb.artifact(sha)
        assert row.file_sha256 == hashlib.sha256(_file(kb, sha).read_bytes()).hexdigest()
        assert row.bytes == _file(kb, sha).stat().st_size


def test_without_a_file_hash_the_content_hash_is_checked(tmp_path):
    store = ArtifactStore(str(tmp_path / "art"))
    a = np.arange(10.0)
    art = store.put_array(a)
    np.testing.assert_array_equal(store.get_array(art.sha256, art.uri), a)
    b = store.put_array(a + 1)
    # a file hash alone vouches for the bytes; without it, the content hash must name the file
    with pytest.raises(StoreError, match="damaged"):
        store.get_array(art.sha256, b.uri)
    assert array_sha256(store.get_array(b.sha256, b.uri)) == b.sha256


def test_a_foreign_file_at_the_artifact_path_is_replaced_not_blessed(tmp_path):
    """An intact Parquet file of other content sitting at the path is not taken as the artifact."""
    store = ArtifactStore(str(tmp_path / "art"))
    other = store.put_array(np.arange(5.0) + 1)
    path = tmp_path / "art" / ArtifactStore.uri_for(array_sha256(np.arange(5.0)))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes((tmp_path / "art" / other.uri).read_bytes())
    art = store.put_array(np.arange(5.0))
    assert art.file_sha256 != other.file_sha256
    np.testing.assert_array_equal(store.get_array(art.sha256, art.uri, file_sha256=art.file_sha256,
                                                  full=True), np.arange(5.0))


def test_putting_content_again_repairs_a_damaged_file(stored):
    kb, policy, _, q = stored
    path = _file(kb, policy.q)
    good = path.read_bytes()
    data = bytearray(good)
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    assert not kb.check().ok
    again = kb.put_policy(policy.task_id, "q", q=q)
    assert again.q == policy.q
    assert path.read_bytes() == good  # deterministic encoding: the same bytes as the first write
    assert kb.check().ok
    np.testing.assert_array_equal(kb.load(policy, "q"), q)


@pytest.mark.parametrize("size", [10, 300_000])  # inline hash and threaded hash paths
def test_round_trip_on_both_hash_paths(tmp_path, size):
    store = ArtifactStore(str(tmp_path / "art"))
    a = np.random.default_rng(size).standard_normal(size).astype(">f8")
    art = store.put_array(a)
    back = store.get_array(art.sha256, art.uri, file_sha256=art.file_sha256)
    assert back.dtype == np.float64 and back.tobytes() == a.astype("<f8").tobytes()
