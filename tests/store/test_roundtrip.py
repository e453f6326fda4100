"""Round trips of every record kind and of arrays/tables of every supported dtype and shape."""

from __future__ import annotations

import dataclasses
from datetime import timezone

import hypothesis.extra.numpy as hnp
import numpy as np
import pyarrow as pa
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from adpart.store import SCHEMA_VERSION, KnowledgeBase, StoreError
from adpart.store.artifacts import array_sha256

DTYPES = [np.bool_, np.int8, np.int16, np.int32, np.int64, np.uint8, np.uint16, np.uint32,
          np.uint64, np.float16, np.float32, np.float64]


def test_every_record_kind_round_trips(populated):
    kb, rec = populated
    for key, record in rec.items():
        again = kb.get(record.KIND, record.id)
        assert again == record, key
        assert again.provenance == record.provenance
        assert again.provenance.created_at.tzinfo is not None
        assert again.provenance.schema_version == SCHEMA_VERSION
    assert rec["policy"].provenance.parameters == {"alpha": 0.1}
    assert rec["environment"].provenance.plugin == "builtin"
    np.testing.assert_array_equal(kb.load(rec["policy"], "q"),
                                  np.arange(10.0).reshape(5, 2))
    assert kb.load(rec["policy"], "pi").dtype == np.int64
    assert rec["subgoal-set"].states == (1, 3)
    assert kb.load(rec["option"], "initiation").dtype == np.bool_
    np.testing.assert_array_equal(kb.option_transitions(rec["option"]).toarray(), np.eye(5) * 0.9)
    assert rec["partition"].n_blocks == 4
    assert rec["partition"].option_ids == (rec["option"].id,)
    curve = kb.load(rec["run"], "curve")
    assert curve.column("gap").to_pylist() == [3.0, 1.0, 0.5, 0.25]


def test_get_or_put_environment_and_task(populated):
    kb, rec = populated
    env = kb.put_environment("renamed", model_hash="e" * 64, n_states=5, n_actions=2)
    assert env.id == rec["environment"].id
    assert kb.put_task(env, "other-name", spec={"goal": [4]}, gamma=0.9).id == rec["task"].id
    assert kb.put_task(env, "goal-4", spec={"goal": [4]}, gamma=0.95).id != rec["task"].id


def test_queries(populated):
    kb, rec = populated
    assert [o.id for o in kb.options_for(rec["environment"])] == [rec["option"].id]
    assert [p.id for p in kb.partitions_using([rec["option"]])] == [rec["p1"].id,
                                                                     rec["partition"].id]
    assert kb.partitions_using([rec["option"]], includes_primitives=False) == []
    [(task, runs)] = kb.learned_tasks(rec["environment"])
    assert task == rec["task"] and runs == [rec["run"]]
    assert kb.runs_for(rec["task"]) == [rec["run"]]
    assert [p.id for p in kb.lineage(rec["partition"])] == [rec["p1"].id]
    grand = kb.put_partition(rec["environment"], "learned", [0, 1, 2, 3, 4],
                             parents=[rec["partition"]], epsilon=0.0, delta=0.0)
    assert [p.id for p in kb.lineage(grand)] == [rec["partition"].id, rec["p1"].id]
    assert kb.partitions_using([]) == [grand]


def test_identical_content_is_stored_once(kb):
    a = kb.put_array(np.arange(100, dtype=np.int32))
    b = kb.put_array(np.arange(100, dtype=np.int32))
    c = kb.put_array(np.arange(100, dtype=np.int64))
    assert a.sha256 == b.sha256 != c.sha256
    assert kb.counts()["artifact"] == 2
    assert array_sha256(np.arange(6).reshape(2, 3)) != array_sha256(np.arange(6).reshape(3, 2))


def test_bad_inputs_are_store_errors(populated):
    kb, rec = populated
    with pytest.raises(StoreError, match="shape"):
        kb.put_policy(rec["task"], "x", q=np.zeros((4, 2)))
    with pytest.raises(StoreError, match="every block"):
        kb.put_partition(rec["environment"], "learned", [0, 2, 2, 2, 2], epsilon=0.0, delta=0.0)
    with pytest.raises(StoreError, match="unknown partition kind"):
        kb.put_partition(rec["environment"], "bogus", [0, 0, 0, 0, 0], epsilon=0.0, delta=0.0)
    with pytest.raises(StoreError, match="no task"):
        kb.put_run(999, "x")
    with pytest.raises(StoreError, match="dtype"):
        kb.put_array(np.array(["a", "b"]))
    with pytest.raises(StoreError, match="JSON"):
        kb.put_run(rec["task"], "x", metrics={"f": object()})


@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(array=st.sampled_from(DTYPES).flatmap(
    lambda dt: hnp.arrays(dt, hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=5),
                          elements=None if dt is not np.float64 else st.floats(allow_nan=True))),
       big_endian=st.booleans())
def test_arrays_round_trip_bit_exact(tmp_path, array, big_endian):
    kb = _shared_kb(tmp_path)
    if big_endian:
        array = array.astype(array.dtype.newbyteorder(">"))
    art = kb.put_array(array)
    back = kb.read_artifact(art)
    assert back.shape == array.shape
    assert back.dtype == array.dtype.newbyteorder("=")
    assert back.tobytes() == array.astype(back.dtype).tobytes()
    assert art.shape == array.shape


_KBS: dict[str, KnowledgeBase] = {}


def _shared_kb(tmp_path) -> KnowledgeBase:
    # hypothesis reruns the body with one tmp_path: reuse one real SQLite KB per test
    key = str(tmp_path)
    if key not in _KBS:
        _KBS.clear()
        _KBS[key] = KnowledgeBase.open(tmp_path / "kb")
    return _KBS[key]


@settings(max_examples=30, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(n=st.integers(0, 20), data=st.data())
def test_tables_round_trip(tmp_path, n, data):
    kb = _shared_kb(tmp_path)
    ints = data.draw(hnp.arrays(np.int64, n))
    floats = data.draw(hnp.arrays(np.float64, n))
    texts = data.draw(st.lists(st.text(max_size=5), min_size=n, max_size=n))
    table = pa.table({"i": ints, "f": floats, "s": pa.array(texts, pa.string())})
    art = kb.put_table(table)
    back = kb.read_artifact(art)
    assert back.schema == table.schema
    assert back.column("i").to_pylist() == ints.tolist()
    np.testing.assert_array_equal(back.column("f").to_numpy().view(np.uint64),
                                  floats.view(np.uint64))
    assert back.column("s").to_pylist() == texts


def test_entities_are_frozen(populated):
    _, rec = populated
    with pytest.raises(dataclasses.FrozenInstanceError):
        rec["policy"].learner = "other"
    assert rec["run"].provenance.created_at.tzinfo == timezone.utc
