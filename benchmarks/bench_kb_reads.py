"""The cost of verifying every row a knowledge-base read returns, measured in the same run.

Every read compares each row it returns with its row hash (docs/reliability.md, "Reads verify
what they return"). This benchmark fills a SQLite knowledge base with 10^4 records (5,000
policies with a Q table and 5,000 runs with a curve, each its own artifact) and times, with
verification and without it (the reference: the same reads with the row hashes not compared):

- ``adpart kb ls --all`` as a user runs it: a new Python process each time (start-up, imports,
  the reads and the printed table), its CPU time taken from the children's resource usage. The
  processes may write and read compiled bytecode (``PYTHONDONTWRITEBYTECODE`` is dropped from
  their environment, and one untimed run of each writes it first), as an ordinary Python does:
  otherwise every start would recompile every imported module, seconds that would flatter the
  ratio;
- ``kb ls --all``: the command itself in this process (``records_table`` of every record, the
  table printed; without ``--all`` it prints a page of 50), and ``records_table()`` alone;
- ``get + load``: 500 policies read by id and their Q tables loaded (file hash on the bytes, as
  always);
- ``load``: the same 500 Q tables from records already in hand (the artifact row is verified).

Both sides alternate within each repeat, so a machine shared with other work loads both alike;
each call's CPU time (this process only) and wall time are kept, and the CPU-time ratio is the
steadier one where other jobs load the machine. Two ratios are printed: best over best, and the
median over the repeats of each repeat's verified / unverified time (the pair run back to back),
which one slow or lucky call moves less. The target is a ratio of at most 1.10.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from adpart.cli.kb import kb as kb_group
from adpart.store import KnowledgeBase
from adpart.store.queries import Queries
from benchmarks._timing import interleaved_times

N_RECORDS, N_LOADS, REPEATS = 10_000, 500, 9


def _verifying(on: bool, fn: Callable[[], object]) -> Callable[[], object]:
    def run() -> object:
        Queries._verify_rows = on
        try:
            return fn()
        finally:
            Queries._verify_rows = True

    return run


def _command(on: bool, where: Path) -> list[str]:
    """``adpart kb ls --all --kb WHERE`` in a new interpreter, row hashes compared or not."""
    code = ("import sys; from adpart.store.queries import Queries; "
            f"Queries._verify_rows = {on}; from adpart.cli import cli; "
            "cli(['kb', 'ls', '--all', '--kb', sys.argv[1]])")
    return [sys.executable, "-c", code, str(where)]


def _process_times(commands: dict[str, list[str]], repeats: int
                   ) -> dict[str, list[tuple[float, float]]]:
    """Every (wall, CPU) time of each command run in turn ``repeats`` times; CPU time is the
    finished child's (``RUSAGE_CHILDREN``, user + system)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    for command in commands.values():  # bytecode written, caches warm
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL, env=env)
    times: dict[str, list[tuple[float, float]]] = {name: [] for name in commands}
    for _ in range(repeats):
        for name, command in commands.items():
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            wall = time.perf_counter()
            subprocess.run(command, check=True, stdout=subprocess.DEVNULL, env=env)
            wall = time.perf_counter() - wall
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            times[name].append((wall, cpu))
    return times


def _fill(kb: KnowledgeBase, n: int) -> list:
    env = kb.put_environment("bench", model_hash="b" * 64, n_states=50, n_actions=4)
    task = kb.put_task(env, "bench", spec={"goal": [49]}, gamma=0.95)
    policies = []
    with kb.transaction():
        for i in range(n // 2):
            q = np.full((50, 4), float(i))
            policy = kb.put_policy(task, "q-learning", q=q, seed=i, episodes=100,
                                   parameters={"alpha": "0.5", "epsilon": "0.1"})
            kb.put_run(task, "q-learning", seed=i, curve={"episode": np.arange(10) + i},
                       metrics={"final_value_gap": {"mean": 0.01 * i}},
                       parameters={"policies": [policy.id], "alpha": "0.5"})
            policies.append(policy)
    return policies


def main(n_records: int = N_RECORDS, n_loads: int = N_LOADS,
         repeats: int = REPEATS) -> dict[str, float]:
    """Run the benchmark, print the figures and return them (seconds and ratios)."""
    with tempfile.TemporaryDirectory() as tmp:
        where = Path(tmp) / "kb"
        start = time.perf_counter()
        with KnowledgeBase.open(where) as kb:
            policies = _fill(kb, n_records)
        fill_s = time.perf_counter() - start
        runner = CliRunner()

        def kb_ls() -> None:
            result = runner.invoke(kb_group, ["ls", "--all", "--kb", str(where)])
            assert result.exit_code == 0, result.output

        with KnowledgeBase.open(where, read_only=True) as kb:
            chosen = policies[:: max(1, len(policies) // n_loads)][:n_loads]

            def table() -> None:
                assert kb.records_table().num_rows == n_records + 2  # and the env and task

            def get_load() -> None:
                for p in chosen:
                    kb.load(kb.get("policy", p.id), "q")

            def load() -> None:
                for p in chosen:
                    kb.load(p, "q")

            figures: dict[str, float] = {}
            timings = {"kb_ls_process": _process_times(
                {"verified": _command(True, where), "unverified": _command(False, where)},
                repeats)}
            for name, fn in (("kb_ls", kb_ls), ("records_table", table), ("get_load", get_load),
                             ("load", load)):
                timings[name] = interleaved_times({"verified": _verifying(True, fn),
                                                   "unverified": _verifying(False, fn)}, repeats)
            for name, times in timings.items():
                for i, clock in enumerate(("", "cpu_")):
                    on = [t[i] for t in times["verified"]]
                    off = [t[i] for t in times["unverified"]]
                    figures[f"{name}_verified_{clock}s"] = min(on)
                    figures[f"{name}_unverified_{clock}s"] = min(off)
                    figures[f"{name}_{clock}ratio"] = min(on) / min(off)
                    figures[f"{name}_{clock}median_ratio"] = float(np.median(
                        np.array(on) / np.array(off)))
    print(f"bench_kb_reads: {n_records} records (SQLite, filled in {fill_s:.1f} s), "
          f"{len(chosen)} loads, {repeats} repeats (best, and median of paired ratios)")
    labels = {"kb_ls_process": "adpart kb ls (process)", "kb_ls": "kb ls (in this process)",
              "records_table": "records_table()",
              "get_load": f"get + load x{len(chosen)}", "load": f"load x{len(chosen)}"}
    for clock, title in (("cpu_", "CPU time (this process)"), ("", "wall time")):
        print(f"  {title}:")
        for key, label in labels.items():
            print(f"    {label:24} verified {figures[f'{key}_verified_{clock}s']:.3f} s   "
                  f"unverified {figures[f'{key}_unverified_{clock}s']:.3f} s   ratio "
                  f"{figures[f'{key}_{clock}ratio']:.3f}, median "
                  f"{figures[f'{key}_{clock}median_ratio']:.3f} (target <= 1.10)")
    return figures


if __name__ == "__main__":
    main()
