"""CLI start-up against the interpreter and click alone, measured in the same run.

Times whole processes - ``python -c pass``, ``python -c 'import click'``, ``adpart --version``,
``adpart --help``, then ``--help`` of every command and sub-command (``adpart pipeline --help``,
``adpart kb ls --help``, ...) and, for scale, ``adpart envs --json``, which loads the plugins and
every environment - and reads each child's peak resident memory. The commands alternate within
each repeat and the best of ``repeats`` is kept, so a machine shared with other work loads every
command alike; each is printed as a ratio to ``python -c pass`` and to ``adpart --help`` of the
same run. Targets: ``--version`` and ``--help`` within 0.3 s and 60 MB; every command's
``--help`` within 0.3 s (about 2x ``adpart --help`` on a quiet machine).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

ADPART = [sys.executable, "-c", "from adpart.cli import cli; cli()"]
REFERENCES = {
    "python -c pass": [sys.executable, "-c", "pass"],
    "python -c 'import click'": [sys.executable, "-c", "import click"],
    "adpart --version": [*ADPART, "--version"],
    "adpart --help": [*ADPART, "--help"],
}
TARGET_S = 0.3


def command_paths() -> list[tuple[str, ...]]:
    """Every command and sub-command of ``adpart`` (imports them, in this process only)."""
    from adpart.cli import cli
    from adpart.cli.group import command_paths as walk

    return walk(cli)


def _run(argv: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MB) of one child process."""
    t0 = time.perf_counter()
    pid = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).pid
    _, status, usage = os.wait4(pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{argv} failed")
    return wall, usage.ru_maxrss / 1024


def main(repeats: int = 5) -> dict[str, tuple[float, float]]:
    commands = dict(REFERENCES)
    for path in command_paths():
        commands[f"adpart {' '.join(path)} --help"] = [*ADPART, *path, "--help"]
    commands["adpart envs --json"] = [*ADPART, "envs", "--json"]
    best = {name: (float("inf"), 0.0) for name in commands}
    for _ in range(repeats):
        for name, argv in commands.items():
            wall, rss = _run(argv)
            if wall < best[name][0]:
                best[name] = (wall, rss)
    base = best["python -c pass"][0]
    main_help = best["adpart --help"][0]
    print(f"best of {repeats}, commands alternated in each repeat")
    print(f"{'command':34s} {'best s':>7s} {'peak MB':>8s} {'/ python':>9s} {'/ --help':>9s}")
    for name, (wall, rss) in best.items():
        print(f"{name:34s} {wall:7.3f} {rss:8.1f} {wall / base:8.1f}x {wall / main_help:8.1f}x")
    helps = {n: w for n, (w, _) in best.items() if n.endswith(" --help") and n != "adpart --help"}
    slowest = max(helps, key=helps.__getitem__)
    print(f"slowest command --help: {slowest} {helps[slowest]:.3f} s = "
          f"{helps[slowest] / main_help:.1f}x adpart --help, {helps[slowest] / base:.1f}x python "
          f"(target {TARGET_S} s on a quiet machine: "
          f"{'met' if helps[slowest] <= TARGET_S else 'not met in this run'})")
    return best


if __name__ == "__main__":
    main()
