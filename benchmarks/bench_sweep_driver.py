"""A sweep driven from a user's script that imports adpart at the top, against the CLI's sweep.

The local pool's workers fork from a forkserver that preloads the driver's ``__main__``. The
CLI imports the learning stack lazily, so its workers import numba and numpy themselves, after
the pool's initializer has set one thread; a script with ``from adpart.workflows.sweep import
...`` at the top hands the workers numba and numpy already loaded, so only limits set in place
reach them (:func:`adpart.execution.one_thread_per_worker`). Three drivers run the same 40-cell
sweep (:data:`benchmarks.bench_sweep.CONFIG`) on a fresh pool and knowledge base, alternating,
each in a fresh interpreter with the environment's thread variables removed:

* **cli** -- ``adpart sweep grid.toml --executor local --json`` (the reference);
* **script** -- a script importing ``adpart.workflows.sweep`` at the top, ``run_sweep`` on a
  :class:`~adpart.execution.LocalExecutor`;
* **script, env only** -- the same script with the pool's initializer replaced by the earlier
  one, which only set the environment variables (what the workers got before). Its workers run
  numba with one thread per core, and a worker that compiles anything after its first parallel
  kernel fails: numba re-reads ``NUMBA_NUM_THREADS`` when it compiles and refuses a value
  other than its pool's (the cells' failures are printed, not hidden).

Figures: the mean compute time of a cell in the worker (the sweep report's ``seconds``), the
sweep's wall time as the driver saw it, and each worker's thread counts (numba's and the
loaded BLAS pools', asked of the pool after the sweep). Ratios are against the CLI, median over
the repeats; the target is script / cli <= 1.1 for the cells.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.bench_sweep import CONFIG

TARGET = 1.1

SCRIPT = '''
import json
import os
import sys

import adpart.execution
from adpart.execution import LocalExecutor, worker_threads
from adpart.store import KnowledgeBase
from adpart.workflows.sweep import load_config, plan_cells, run_sweep

if os.environ.get("BENCH_ENV_ONLY") == "1":  # the initializer before: environment only
    def env_only():
        os.environ.update(adpart.execution.WORKER_THREAD_ENV)

    adpart.execution.one_thread_per_worker = env_only

if __name__ == "__main__":
    cells = plan_cells(load_config(sys.argv[1]))
    with LocalExecutor() as pool, KnowledgeBase.open(sys.argv[2]) as kb:
        report = run_sweep(cells, kb, pool)
        threads = pool.map(worker_threads, range(8))
    print(json.dumps({**report.as_dict(), "threads": threads}))
'''

THREADS = '''
import json
import sys
from adpart.execution import LocalExecutor, worker_threads

if __name__ == "__main__":
    with LocalExecutor() as pool:
        print(json.dumps(pool.map(worker_threads, range(8))))
'''


def _toml(config: dict) -> str:
    lines = []
    for key, value in config.items():
        if isinstance(value, dict):
            continue
        lines.append(f"{key} = {json.dumps(value)}")
    for table, entries in ((k, v) for k, v in config.items() if isinstance(v, dict)):
        lines.append(f"[{table}]")
        lines.extend(f"{k} = {json.dumps(v)}" for k, v in entries.items())
    return "\n".join(lines) + "\n"


def _run(argv: list[str], env: dict[str, str]) -> Any:
    out = subprocess.run(argv, capture_output=True, text=True, env=env, check=True, timeout=1800)
    text = out.stdout.strip()
    try:
        return json.loads(text.splitlines()[-1])
    except json.JSONDecodeError:  # the CLI prints its report indented
        return json.loads(text[text.index("{"):])


def _cell_seconds(report: dict) -> float:
    times = [r["seconds"] for r in report["results"] if r.get("seconds") is not None]
    return sum(times) / len(times)


def main(repeats: int = 2) -> dict:
    """Run the three drivers ``repeats`` times each, alternating; print and return the figures."""
    python = sys.executable
    adpart_cli = str(Path(python).with_name("adpart"))
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                        "MKL_NUM_THREADS")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [os.getcwd(), env.get("PYTHONPATH")]))
    rows: dict[str, list[tuple[float, float]]] = {"cli": [], "script": [], "env-only": []}
    n_cells = 0
    failed: dict[str, list[str]] = {}
    threads: dict[str, list] = {}
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        grid = root / "grid.toml"
        grid.write_text(_toml(CONFIG))
        script = root / "driver.py"
        script.write_text(SCRIPT)
        (root / "threads.py").write_text(THREADS)
        for i in range(repeats):
            for label, seen_rows in rows.items():
                kb = root / f"kb-{label}-{i}"
                if label == "cli":
                    report = _run([adpart_cli, "sweep", str(grid), "--executor", "local",
                                   "--json", "-q", "--kb", str(kb)], env)
                else:
                    report = _run([python, str(script), str(grid), str(kb)],
                                  {**env, "BENCH_ENV_ONLY": "1" if label == "env-only" else "0"})
                    threads[label] = report["threads"]
                if report["stored"] != report["cells"] and label != "env-only":
                    raise RuntimeError(f"{label}: {report['stored']} of {report['cells']} stored")
                seen_rows.append((_cell_seconds(report), report["seconds"]))
                n_cells = report["cells"]
                failed[label] = [r["error"] for r in report["results"] if r["error"]]
                shutil.rmtree(kb, ignore_errors=True)
        threads["cli"] = _run([python, str(root / "threads.py")], env)  # the CLI's imports
    med = {label: (statistics.median(c for c, _ in r), statistics.median(w for _, w in r))
           for label, r in rows.items()}
    load = os.getloadavg()[0]
    print(f"bench_sweep_driver: {n_cells} cells ({CONFIG['runs']} runs x {CONFIG['episodes']} "
          f"episodes), local pool of {os.cpu_count()} workers, {repeats} alternating repeats, "
          f"load average {load:.1f} at the end")
    figures: dict = {"load": load}
    for label, (cell, wall) in med.items():
        ratio_cell, ratio_wall = cell / med["cli"][0], wall / med["cli"][1]
        per = ", ".join(f"{c * 1e3:.0f}" for c, _ in rows[label])
        seen = sorted({(t["numba"], tuple(t["pools"])) for t in threads.get(label, [])})
        print(f"  {label:<9} cell {cell * 1e3:6.1f} ms (per repeat {per})  sweep wall "
              f"{wall:6.2f} s   / cli: cell {ratio_cell:.2f}, wall {ratio_wall:.2f}   worker "
              f"threads (numba, BLAS pools): {seen}")
        if failed.get(label):
            print(f"            {len(failed[label])} of {n_cells} cells failed in the last "
                  f"repeat: {failed[label][0]}")
        figures[label] = {"cell_s": cell, "wall_s": wall, "cell_ratio": ratio_cell,
                          "wall_ratio": ratio_wall, "threads": seen,
                          "failed": len(failed.get(label, []))}
    ok = figures["script"]["cell_ratio"] <= TARGET
    print(f"  script / cli cells {figures['script']['cell_ratio']:.2f} (target <= {TARGET}: "
          f"{ok}); before (env only) / cli {figures['env-only']['cell_ratio']:.2f}")
    return figures


if __name__ == "__main__":
    main()
