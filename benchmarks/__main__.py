"""Run every ``benchmarks/bench_*.py`` module's ``main()`` in turn, or those named.

Usage: ``python -m benchmarks [NAME ...]`` where NAME is ``value_iteration`` or
``bench_value_iteration`` (the module name with or without its ``bench_`` prefix).
"""

from __future__ import annotations

import importlib
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def available() -> list[str]:
    """Module names of the benchmarks, sorted: every ``bench_*.py`` beside this file."""
    return sorted(p.stem for p in HERE.glob("bench_*.py"))


def resolve(names: list[str]) -> list[str]:
    """Map command-line names to module names; exit with the list of choices on a typo."""
    known = available()
    chosen = []
    for name in names:
        stem = name.removesuffix(".py")
        stem = stem if stem.startswith("bench_") else f"bench_{stem}"
        if stem not in known:
            choices = ", ".join(k.removeprefix("bench_") for k in known)
            sys.exit(f"unknown benchmark {name!r}; choose from: {choices}")
        chosen.append(stem)
    return chosen or known


def main(argv: list[str] | None = None) -> int:
    modules = resolve(list(sys.argv[1:] if argv is None else argv))
    for stem in modules:
        print(f"=== {stem} ===", flush=True)
        t0 = time.perf_counter()
        importlib.import_module(f"benchmarks.{stem}").main()
        print(f"=== {stem}: {time.perf_counter() - t0:.1f} s ===\n", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
