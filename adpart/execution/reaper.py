"""Stop the Ray processes a killed driver leaves behind (``python -m adpart.execution.reaper PID``).

A local Ray started by :class:`adpart.execution.ray.RayExecutor` shuts down with the executor,
and its GCS server and raylet fate-share with the driver process. But when the driver is killed
with SIGKILL, the raylet's children - the dashboard agent and the runtime-env agent - are
re-parented to init and stay alive (measured: both still running 8 s after the kill). The
executor therefore starts this reaper, in its own session, right after ``ray.init``. It watches
the driver: while the driver lives it records every descendant process whose command line is
Ray's (``ray::...`` or under ``.../ray/...``), with its start time; once the driver is gone it
sends SIGTERM to each recorded process still alive with the same start time (never to a process
that reused the pid), then SIGKILL to those left after :data:`GRACE_S`, and exits. It reads
``/proc`` and does nothing where there is none.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

#: Seconds between two looks at the driver.
POLL_S = 0.5
#: Seconds between SIGTERM and SIGKILL.
GRACE_S = 3.0
PROC = Path("/proc")


def _stat(pid: int) -> tuple[int, int] | None:
    """``(parent pid, start time)`` of ``pid`` from ``/proc/PID/stat``, or None if it is gone."""
    try:
        text = (PROC / str(pid) / "stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()  # after "pid (comm) "
    return int(fields[1]), int(fields[19])


def _is_ray(pid: int) -> bool:
    try:
        cmd = (PROC / str(pid) / "cmdline").read_bytes().replace(b"\0", b" ").decode(
            errors="replace")
    except OSError:
        return False
    return cmd.startswith("ray::") or "/ray/" in cmd


def ray_descendants(root: int) -> dict[int, int]:
    """``{pid: start time}`` of the Ray processes below ``root`` (one scan of ``/proc``)."""
    parent: dict[int, tuple[int, int]] = {}
    for entry in PROC.iterdir() if PROC.is_dir() else ():
        if entry.name.isdigit():
            info = _stat(int(entry.name))
            if info is not None:
                parent[int(entry.name)] = info
    children: dict[int, list[int]] = {}
    for pid, (ppid, _) in parent.items():
        children.setdefault(ppid, []).append(pid)
    found, stack = {}, list(children.get(root, []))
    while stack:
        pid = stack.pop()
        stack.extend(children.get(pid, []))
        if pid != os.getpid() and _is_ray(pid):
            found[pid] = parent[pid][1]
    return found


def _alive_as(pid: int, start: int) -> bool:
    info = _stat(pid)
    return info is not None and info[1] == start


def reap_after(driver: int) -> int:
    """Watch ``driver``; when it is gone, stop the Ray processes recorded below it.

    Returns the number of processes signalled.
    """
    driver_start = (_stat(driver) or (0, -1))[1]
    seen: dict[int, int] = {}
    while _alive_as(driver, driver_start):
        seen.update(ray_descendants(driver))
        time.sleep(POLL_S)
    left = {pid: start for pid, start in seen.items() if _alive_as(pid, start)}
    for pid in left:
        os.kill(pid, signal.SIGTERM)
    deadline = time.monotonic() + GRACE_S
    while time.monotonic() < deadline and any(_alive_as(p, s) for p, s in left.items()):
        time.sleep(0.1)
    for pid, start in left.items():
        if _alive_as(pid, start):
            os.kill(pid, signal.SIGKILL)
    return len(left)


if __name__ == "__main__":  # pragma: no cover - run as a process by the Ray executor
    reap_after(int(sys.argv[1]))
