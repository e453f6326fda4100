"""Every local-pool worker runs with one numba and one BLAS thread, whatever the driver imported.

The pool forks its workers from a forkserver that preloads the driver's ``__main__``; a driver
script that imports numba and numpy at the top hands them to the workers already loaded, with
their thread counts read from an environment that did not yet say one thread. The driver here
is such a script, run in a fresh interpreter with none of the thread variables set.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from adpart.execution import WORKER_THREAD_ENV

DRIVER = """
import json
import numba  # loaded at the top: the forkserver preloads this module
import numpy
from adpart.execution import LocalExecutor, worker_threads


def compile_and_count(item):
    # a compile re-reads numba's environment: it must not clash with the worker's setting
    numba.njit(lambda x: x + 1)(item)
    return worker_threads()

if __name__ == "__main__":
    with LocalExecutor(workers=2) as pool:
        seen = pool.map(worker_threads, range(4))
        seen += pool.map(compile_and_count, range(4))
    print(json.dumps({"driver": numba.get_num_threads(), "workers": seen}))
"""


@pytest.mark.skipif(sys.platform == "win32", reason="forkserver is a POSIX start method")
def test_workers_get_one_thread_when_the_driver_loaded_numba_first(tmp_path):
    script = tmp_path / "driver.py"
    script.write_text(DRIVER)
    env = {k: v for k, v in os.environ.items() if k not in WORKER_THREAD_ENV}
    env["NUMBA_NUM_THREADS"] = "2"  # what numba picks on two cores; the workers must not
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         env=env, timeout=300, check=True)
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["driver"] == 2  # the driver keeps its own setting
    for worker in report["workers"]:
        assert worker["numba"] == 1
        assert worker["pools"] == [1]  # every loaded BLAS / OpenMP pool limited to one
        del worker["env"]["NUMBA_NUM_THREADS"]  # numba's pool size, read at its import
        assert worker["env"] == {k: v for k, v in WORKER_THREAD_ENV.items()
                                 if k != "NUMBA_NUM_THREADS"}
