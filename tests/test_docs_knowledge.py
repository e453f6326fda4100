"""docs/knowledge.md's, docs/learning.md's and docs/learned-model.md's command blocks print what
the pages show (numbers aside)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.plugins.test_example_package import _console_blocks, _run_documented, _shape

DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.mark.parametrize(("page", "n"), [("knowledge.md", 2), ("learning.md", 1),
                                         ("learned-model.md", 2)])
def test_the_pages_commands_print_what_it_shows(page, n, tmp_path, monkeypatch):
    blocks = _console_blocks((DOCS / page).read_text())
    assert len(blocks) == n
    monkeypatch.chdir(tmp_path)
    for command, expected in blocks:
        assert _shape(_run_documented(command), tmp_path) == _shape(expected, tmp_path), command
