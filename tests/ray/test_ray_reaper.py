"""A SIGKILLed driver leaves no Ray process behind (the reaper, adpart/execution/reaper.py).

Without the reaper the raylet's dashboard and runtime-env agents outlive a killed driver
(re-parented to init); the test kills a real driver that started a local Ray and checks that every
Ray process recorded below it is gone. The oracle is a plain ``/proc`` scan by parent pid.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from adpart.execution.reaper import ray_descendants

pytest.importorskip("ray")
pytestmark = [pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc"),
              pytest.mark.processes]

DRIVER = textwrap.dedent(
    """
    import os, sys, time
    from adpart.execution.ray import RayExecutor
    RayExecutor(num_cpus=1).connect()
    print("ready", flush=True)
    time.sleep(300)
    """
)


def _wait(predicate, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.2)
    return predicate()


def test_a_killed_driver_leaves_no_ray_process():
    with subprocess.Popen([sys.executable, "-c", DRIVER], stdout=subprocess.PIPE,
                          stderr=subprocess.DEVNULL, text=True) as driver:
        try:
            assert driver.stdout.readline().strip() == "ready"
            # the agents start a moment after ray.init returns
            assert _wait(lambda: sum(_is_agent(p) for p in ray_descendants(driver.pid)) >= 2, 30)
            ray_pids = ray_descendants(driver.pid)
            time.sleep(1.0)  # the reaper looks every half second
            os.kill(driver.pid, signal.SIGKILL)
            driver.wait(10)
            assert _wait(lambda: not any(Path(f"/proc/{p}").exists() for p in ray_pids), 30), (
                "Ray processes outlived the killed driver")
        finally:
            if driver.poll() is None:
                driver.kill()


def _is_agent(pid: int) -> bool:
    try:
        return b"Agent" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False
