"""CLI start-up against the interpreter and click alone, measured in the same run.

Times whole processes (``python -c pass``, ``python -c 'import click'``, ``adpart --version``,
``adpart --help`` and, for scale, ``adpart envs --json``, which loads the plugins) and reads each
child's peak resident memory. The commands alternate within each repeat and the best of
``REPEATS`` is kept, so a machine shared with other work loads every command alike. Targets:
``--version`` and ``--help`` within 0.3 s and 60 MB.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

REPEATS = 7
ADPART = [sys.executable, "-c", "from adpart.cli import cli; cli()"]
COMMANDS = {
    "python -c pass": [sys.executable, "-c", "pass"],
    "python -c 'import click'": [sys.executable, "-c", "import click"],
    "adpart --version": [*ADPART, "--version"],
    "adpart --help": [*ADPART, "--help"],
    "adpart envs --json": [*ADPART, "envs", "--json"],
}


def _run(argv: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MB) of one child process."""
    t0 = time.perf_counter()
    pid = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).pid
    _, status, usage = os.wait4(pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{argv} failed")
    return wall, usage.ru_maxrss / 1024


def main() -> None:
    best = {name: (float("inf"), 0.0) for name in COMMANDS}
    for _ in range(REPEATS):
        for name, argv in COMMANDS.items():
            wall, rss = _run(argv)
            if wall < best[name][0]:
                best[name] = (wall, rss)
    base = best["python -c pass"][0]
    click_only = best["python -c 'import click'"][0]
    print(f"{'command':28s} {'best s':>7s} {'peak MB':>8s} {'/ python':>9s} {'/ click':>8s}")
    for name, (wall, rss) in best.items():
        print(f"{name:28s} {wall:7.3f} {rss:8.1f} {wall / base:8.1f}x {wall / click_only:7.1f}x")


if __name__ == "__main__":
    main()
