"""docs/knowledge.md's command blocks print what the page shows (numbers aside)."""

from __future__ import annotations

from pathlib import Path

from tests.plugins.test_example_package import _console_blocks, _run_documented, _shape

PAGE = Path(__file__).resolve().parents[1] / "docs" / "knowledge.md"


def test_the_pages_commands_print_what_it_shows(tmp_path, monkeypatch):
    blocks = _console_blocks(PAGE.read_text())
    assert len(blocks) == 2
    monkeypatch.chdir(tmp_path)
    for command, expected in blocks:
        assert _shape(_run_documented(command), tmp_path) == _shape(expected, tmp_path), command
