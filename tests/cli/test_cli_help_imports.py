"""``--help`` of every command starts light: no numpy, numba, scipy, SQLAlchemy, pyarrow,
matplotlib or pandas (nor gymnasium) is imported to show it - the settings the options come from
live in modules without them, the built-in plugins import their implementations when used, and
a built-in plugin's help reads adpart's own plugins only. Each help runs in a fresh interpreter
(``benchmarks/bench_cli_startup.py`` times them)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from adpart.cli import cli
from adpart.cli.group import command_paths as group_command_paths

HEAVY = ("numpy", "numba", "scipy", "sqlalchemy", "pyarrow", "matplotlib", "pandas", "gymnasium")


def command_paths() -> list[tuple[str, ...]]:
    """Every command and sub-command, e.g. ``("kb", "ls")``."""
    return group_command_paths(cli)


PROBE = """
import json, sys
from adpart.cli import cli
try:
    cli.main(sys.argv[1:], standalone_mode=False)
except SystemExit:
    pass
print(json.dumps(sorted({m.split(".")[0] for m in sys.modules})))
"""


def loaded_by_help(*args: str) -> tuple[str, set[str]]:
    out = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True,
                         check=True)
    *text, modules = out.stdout.rstrip().splitlines()
    return "\n".join(text), set(json.loads(modules))


def test_every_command_is_probed():
    paths = command_paths()
    assert {("pipeline",), ("learn",), ("kb", "ls"), ("env", "show"), ("sweep",)} <= set(paths)
    assert len(paths) >= 20


@pytest.mark.parametrize("path", command_paths(), ids=" ".join)
def test_help_imports_no_heavy_module(path):
    text, modules = loaded_by_help(*path, "--help")
    assert "Usage:" in text
    assert not modules & set(HEAVY), sorted(modules & set(HEAVY))


@pytest.mark.parametrize(("args", "takes"), [
    (("learn", "--learner", "maxq-q"), "learner 'maxq-q' takes --graph, --abstraction"),
    (("discover", "--detector", "count-mc"), "subgoal-detector 'count-mc' takes --"),
    (("hierarchy", "--estimator", "all-subgoals"), "hierarchy-estimator 'all-subgoals' takes --"),
])
def test_a_builtin_plugins_help_shows_its_parameters_without_loading_them(args, takes):
    text, modules = loaded_by_help(*args, "--help")
    assert not modules & set(HEAVY), sorted(modules & set(HEAVY))
    assert takes in " ".join(text.split())


def test_the_maxq_help_lists_its_graphs():
    text, _ = loaded_by_help("learn", "--learner", "maxq-q", "--help")
    assert "[taxi|parr-maze|auto]" in text


def test_graph_settings_name_the_graphs_the_library_builds():
    from adpart.learning.maxq.graphs import GRAPHS
    from adpart.learning.maxq.settings import GRAPH_NAMES

    assert tuple(GRAPHS) == GRAPH_NAMES
