"""Fixtures that install throw-away plugin distributions the way pip would leave them on disk.

A directory holding a module and its ``*.dist-info`` (METADATA + entry_points.txt) is put on
``sys.path``: ``importlib.metadata`` then discovers the distribution and its ``adpart`` entry point
through exactly the code path a pip-installed third-party package takes.
"""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest

from adpart.plugins import reset_registry

FAKE_PLUGIN = '''
from adpart.plugins import Param, hookimpl
from adpart.execution import Executor


class ReversedSerial(Executor):
    """An executor that computes items back to front (results still in order)."""

    name = "reversed-serial"
    description = "serial, back to front (test plugin)"
    params = (Param("label", "str", "x", "a label"),)

    def __init__(self, label="x"):
        self.label = label

    def map(self, fn, items):
        items = list(items)
        return [fn(i) for i in items[::-1]][::-1]


@hookimpl
def register_executors(register):
    register(ReversedSerial)
'''


def install_fake_distribution(root: Path, dist: str, module: str, source: str) -> Path:
    """Write ``module.py`` and ``<dist>-0.1.dist-info`` with an ``adpart`` entry point."""
    root.mkdir(parents=True, exist_ok=True)
    (root / f"{module}.py").write_text(textwrap.dedent(source))
    info = root / f"{dist.replace('-', '_')}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[adpart]\n{module} = {module}\n")
    return root


@pytest.fixture
def plugin_site(tmp_path, monkeypatch):
    """A fresh site directory on sys.path; the registry is rebuilt before and after."""
    site = tmp_path / "site"
    site.mkdir()
    monkeypatch.syspath_prepend(str(site))
    reset_registry()
    yield site
    for name in [m for m in sys.modules if m.startswith("fake_adpart")]:
        del sys.modules[name]
    reset_registry()
