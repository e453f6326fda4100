"""adpart benchmarks: each ``bench_*.py`` module has a ``main()`` that prints its figures.

Run them all with ``python -m benchmarks``, or some with ``python -m benchmarks value_iteration``.
Every benchmark compares against a reference measured in the same run (DESIGN.md), so the
ratios it prints are meaningful on any machine; tests never assert on times.
"""
