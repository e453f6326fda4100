"""Every ``$ adpart ...`` command shown in docs/ runs, and prints output of the shape shown.

A page's fenced blocks are read in order; each ``$ adpart`` line (with ``\\`` continuations) is
run with click's CliRunner in one fresh folder per page (a ``| grep WORD`` keeps the lines with
WORD, as the shell would), whose default knowledge base is fresh
too, so a page's commands build on each other as the page says. The output shown under a command
is its *shape*: the leading word of each shown line (``learn-flat``, ``wrote``, ``Error:``...)
must be printed, in that order; numbers and ids may differ. A shown ``Error:`` line means exit
status 2, anything else 0.

Two allowances keep the suite fast, and are the only differences from the pages: run counts above
:data:`CAPS` are lowered to it (episodes are kept: fewer of them would change what a pipeline
decides), and commands that need a Ray cluster are left to tests/ray.
"""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest
from click.testing import CliRunner

from adpart.cli import cli

DOCS = Path(__file__).resolve().parents[1] / "docs"
CAPS = {"--runs": 3}
LEAD = re.compile(r"^\s*([A-Za-z][A-Za-z:-]*[A-Za-z:])(?=\s|$)")


def commands(page: Path) -> list[tuple[str, list[str]]]:
    """``(command, shown output lines)`` of every ``$ adpart`` line of ``page``, in order."""
    out: list[tuple[str, list[str]]] = []
    for block in re.findall(r"^```[a-z]*\n(.*?)^```", page.read_text(), re.MULTILINE | re.DOTALL):
        lines = block.splitlines()
        i = 0
        while i < len(lines):
            if lines[i].startswith("$ adpart "):
                command = lines[i][2:]
                while command.endswith("\\"):
                    i += 1
                    command = command[:-1] + " " + lines[i].strip()
                shown = []
                i += 1
                while i < len(lines) and not lines[i].startswith("$ "):
                    shown.append(lines[i])
                    i += 1
                out.append((command.split("  # ")[0].strip(), shown))
            else:
                i += 1
    return out


def capped(args: list[str]) -> list[str]:
    out = list(args)
    for k, word in enumerate(out[:-1]):
        if word in CAPS and out[k + 1].isdigit():
            out[k + 1] = str(min(int(out[k + 1]), CAPS[word]))
    return out


def shape(lines: list[str]) -> list[str]:
    """The leading words of the shown lines (table rules, numbers and ellipses have none)."""
    return [m.group(1) for line in lines if (m := LEAD.match(line))]


PAGES = sorted(p for p in DOCS.rglob("*.md") if commands(p))


def test_the_pages_with_commands_are_found():
    names = {p.name for p in PAGES}
    assert {"learning.md", "hierarchy.md", "pipeline.md", "index.md", "plugins.md"} <= names


@pytest.mark.extended
@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(DOCS)))
def test_every_documented_command_runs_with_the_shown_shape(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("ADPART_KB", str(tmp_path / "default-kb"))
    runner = CliRunner()
    for command, shown in commands(page):
        command, _, grep = command.partition(" | grep ")  # `adpart ... | grep WORD`
        args = shlex.split(command)[1:]
        if "ray" in args:
            continue
        result = runner.invoke(cli, capped(args))
        error = any(line.startswith("Error:") for line in shown)
        assert result.exit_code == (2 if error else 0), f"{command}\n{result.output}"
        lines = result.output.splitlines()
        if grep:
            lines = [line for line in lines if shlex.split(grep)[0] in line]
        printed = shape(lines)
        position = 0
        for word in shape(shown):
            assert word in printed[position:], (
                f"{page.name}: `{command}` should print a line starting {word!r}:\n"
                f"{result.output}")
            position = printed.index(word, position) + 1


@pytest.mark.extended
def test_the_sweep_pages_config_and_commands_run(tmp_path, monkeypatch):
    """docs/scale-out.md: its TOML is a sweep of 3 alphas x 3 seeds x 3 (environment, task) pairs.
    The page's commands run in its order, but for the two that need a Ray cluster (tests/ray):
    the dry run lists 27 pending cells and creates no knowledge base, the sweep on the local pool
    stores all 27, and the JSON report of a second sweep finds every cell stored."""
    page = (DOCS / "scale-out.md").read_text()
    (tmp_path / "grid.toml").write_text(
        re.search(r"```toml\n(.*?)```", page, re.DOTALL).group(1))
    block = re.search(r"```\n(adpart sweep grid.toml --dry-run.*?)```", page, re.DOTALL).group(1)
    shown = [line.split("  #")[0].strip() for line in block.splitlines()]
    assert [s for s in shown if "ray" not in s] == [
        "adpart sweep grid.toml --dry-run", "adpart sweep grid.toml",
        "adpart sweep grid.toml --json"]
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("ADPART_KB", str(tmp_path / "kb"))
    runner = CliRunner()
    dry = runner.invoke(cli, ["sweep", "grid.toml", "--dry-run"])
    assert dry.exit_code == 0, dry.output
    assert "27 cells - would run 27, skipped 0" in dry.output
    assert not (tmp_path / "kb").exists()
    run = runner.invoke(cli, ["sweep", "grid.toml"])
    assert run.exit_code == 0, run.output
    assert "27 cells - stored 27, skipped 0" in run.output
    again = runner.invoke(cli, ["sweep", "grid.toml", "--json"])
    assert again.exit_code == 0, again.output
    report = json.loads(again.stdout)
    assert report["name"] == "alpha-grid" and len(report["results"]) == 27
    assert {r["status"] for r in report["results"]} == {"skipped"}
