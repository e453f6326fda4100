"""Knowledge-base artifact throughput against raw pyarrow.parquet, measured in the same run.

Puts and gets a 10^6-state, 8-action float64 Q table through ``KnowledgeBase.put_policy`` /
``KnowledgeBase.load`` (put: content hash, Parquet zstd encoding in memory, file hash on a second
thread while the bytes go to a temporary name + rename, metadata row; get: one read of the file,
its hash on a second thread while the same bytes are decoded) and writes/reads the same array
with plain ``pyarrow.parquet`` (zstd, default options). The target is a ratio within 1.5x of raw.

The kb and raw operations alternate within each repeat and the best time of each is kept, so a
machine shared with other work loads both sides alike.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from adpart.store import KnowledgeBase
from benchmarks._timing import interleaved_best

N_STATES, N_ACTIONS, REPEATS = 1_000_000, 8, 5


def main() -> dict[str, float]:
    """Run the benchmark, print the figures and return them (seconds and MB/s)."""
    rng = np.random.default_rng(0)
    q = rng.standard_normal((N_STATES, N_ACTIONS))
    mb = q.nbytes / 1e6
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        raw_path = root / "raw.parquet"

        def raw_write() -> None:
            pq.write_table(pa.table({"values": q.reshape(-1)}), raw_path, compression="zstd")

        def raw_read() -> None:
            pq.read_table(raw_path).column("values").to_numpy().reshape(q.shape)

        with KnowledgeBase.open(root / "kb") as kb:
            env = kb.put_environment("bench", model_hash="0" * 64, n_states=N_STATES,
                                     n_actions=N_ACTIONS)
            task = kb.put_task(env, "bench", spec={}, gamma=0.9)
            policies = []

            def kb_put() -> None:
                # a fresh value each time so the content-addressed store really writes
                q[0, 0] = len(policies)
                policies.append(kb.put_policy(task, "bench", q=q))

            def kb_get() -> None:
                kb.load(policies[-1], "q")

            figures = interleaved_best({"raw_write_s": raw_write, "kb_put_s": kb_put}, REPEATS)
            figures |= interleaved_best({"raw_read_s": raw_read, "kb_get_s": kb_get}, REPEATS)
            np.testing.assert_array_equal(kb.load(policies[-1], "q"), q)
    figures["put_ratio"] = figures["kb_put_s"] / figures["raw_write_s"]
    figures["get_ratio"] = figures["kb_get_s"] / figures["raw_read_s"]
    print(f"bench_store: Q table {N_STATES}x{N_ACTIONS} float64 ({mb:.0f} MB), best of {REPEATS}")
    for op, kb_key, raw_key, ratio in (("write", "kb_put_s", "raw_write_s", "put_ratio"),
                                       ("read", "kb_get_s", "raw_read_s", "get_ratio")):
        print(f"  {op:5}  kb {figures[kb_key]:.3f} s ({mb / figures[kb_key]:7.1f} MB/s)   "
              f"raw pyarrow.parquet {figures[raw_key]:.3f} s ({mb / figures[raw_key]:7.1f} MB/s)"
              f"   ratio {figures[ratio]:.2f} (target <= 1.5)")
    return figures


if __name__ == "__main__":
    main()
