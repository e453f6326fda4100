"""Compile time of every numba kernel the test suite's warm-up compiles, slowest first.

``make test`` first fills numba's on-disk cache (``tests/warm_kernels.py``: the library's own
entry points on small problems). Here that warm-up runs in a fresh interpreter with an empty
cache (``NUMBA_CACHE_DIR`` set to a new directory), with a recorder on numba's ``numba:compile``
events, so that every compilation of every kernel is timed where it happens. Nested compiles
(a kernel calling another compiled function compiles the callee inside its own compile) are
reported inclusively and marked; the self time subtracts them. The reference, in the same run:
the same warm-up again with the cache now full (loading, not compiling), and the sum of all
compile times against the warm-up's wall time.

Prints the kernels by compile time (seconds, share of all compiling, signatures compiled), the
warm-up's wall time cold and warm, and their ratio. Run it on a quiet machine: compile times
scale with the load.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

CHILD = r'''
import json
import sys
import time

from numba.core import event

from tests import warm_kernels

records = []
start = time.perf_counter()
with event.install_recorder("numba:compile") as rec:
    warm_kernels.main([])
wall = time.perf_counter() - start
stack = []
for ts, ev in rec.buffer:
    name = ev.data["dispatcher"].py_func
    label = f"{name.__module__}.{name.__qualname__}"
    if ev.is_start:
        stack.append([label, ts, 0.0])
    else:
        label_, t0, nested = stack.pop()
        duration = ts - t0
        if stack:
            stack[-1][2] += duration
        records.append({"kernel": label_, "seconds": duration, "self": duration - nested,
                        "nested": len(stack) > 0})
print(json.dumps({"wall": wall, "records": records}))
'''


def _run(cache: str, code: str) -> tuple[float, str]:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache, "OMP_NUM_THREADS": "1",
           "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [os.getcwd(), env.get("PYTHONPATH")]))
    start = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         check=True, timeout=3600)
    return time.perf_counter() - start, out.stdout


def main(top: int = 15) -> dict:
    """Compile the warm-up's kernels into an empty cache, then load them; print the table."""
    with tempfile.TemporaryDirectory() as cache:
        cold_wall, out = _run(cache, CHILD)
        report = json.loads(out.strip().splitlines()[-1])
        warm_wall, _ = _run(cache, "from tests import warm_kernels; warm_kernels.main([])")
    by_kernel: dict[str, dict] = {}
    for r in report["records"]:
        row = by_kernel.setdefault(r["kernel"], {"seconds": 0.0, "self": 0.0, "signatures": 0,
                                                 "nested": False})
        row["seconds"] += r["seconds"]
        row["self"] += r["self"]
        row["signatures"] += 1
        row["nested"] |= r["nested"]
    compiling = sum(r["self"] for r in report["records"])
    ranked = sorted(by_kernel.items(), key=lambda kv: -kv[1]["self"])
    load = os.getloadavg()[0]
    print(f"bench_compile: tests/warm_kernels.py (learning + structure, one process) into an "
          f"empty numba cache, load average {load:.1f}")
    print(f"  warm-up wall: cold cache {cold_wall:.1f} s (process), {report['wall']:.1f} s "
          f"(warm-up alone); full cache {warm_wall:.1f} s; cold / warm {cold_wall / warm_wall:.1f}")
    print(f"  compiling (self times summed) {compiling:.1f} s = "
          f"{compiling / report['wall']:.0%} of the cold warm-up; {len(by_kernel)} kernels, "
          f"{len(report['records'])} signatures")
    print(f"  {'kernel':<72} {'self s':>7} {'incl s':>7} {'share':>6} {'sigs':>4}")
    for name, row in ranked[:top]:
        mark = " (nested)" if row["nested"] else ""
        print(f"  {(name + mark)[:72]:<72} {row['self']:7.2f} {row['seconds']:7.2f} "
              f"{row['self'] / compiling:6.1%} {row['signatures']:4d}")
    return {"cold_wall_s": cold_wall, "warm_wall_s": warm_wall, "compiling_s": compiling,
            "kernels": {k: v for k, v in ranked}}


if __name__ == "__main__":
    main()
