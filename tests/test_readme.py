"""The README's first session runs as written on a fresh knowledge base, with the ids it names.

Each line of the README's ``sh`` block under "A first session" is run in order with click's
CliRunner in a fresh folder: ``export ADPART_KB=...`` sets the knowledge base, ``a ; b`` runs both,
and a ``# ... kind:N`` comment names an id the command must print. Only the last line (the whole
pipeline on three-floor, minutes as written) gets smaller settings appended, so the suite stays
fast; everything else is exactly the README's text.
"""

from __future__ import annotations

import os
import re
import shlex
from pathlib import Path

import pytest
from click.testing import CliRunner

from adpart.cli import cli

README = Path(__file__).resolve().parents[1] / "README.md"
#: appended to the pipeline line only (see the module docstring)
SMALLER = {"pipeline": ["--runs", "2", "--episodes", "30", "--first-episodes", "60",
                        "--eval-every", "10"]}
ID = re.compile(r"\b[a-z-]+:\d+\b")


def session_lines() -> list[tuple[str, str]]:
    """``(command, comment)`` of the first-session block, in order."""
    text = README.read_text()
    block = re.search(r"## A first session.*?```sh\n(.*?)```", text, re.DOTALL).group(1)
    out = []
    for line in block.splitlines():
        command, _, comment = line.partition(" # ")
        if command.strip():
            out.append((command.strip(), comment.strip()))
    return out


def test_the_readme_session_has_the_commands_the_mission_needs():
    verbs = [shlex.split(part)[1] for command, _ in session_lines()
             for part in command.split(" ; ") if part.startswith("adpart ")]
    for verb in ("learn", "discover", "options", "partition", "transfer", "hierarchy", "pipeline"):
        assert verb in verbs


@pytest.mark.extended
def test_the_readme_first_session_runs_as_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    for command, comment in session_lines():
        outputs = []
        for part in command.split(" ; "):
            words = shlex.split(part)
            if words[0] == "export":
                name, _, value = words[1].partition("=")
                monkeypatch.setenv(name, os.path.expandvars(value.replace("$PWD", str(tmp_path))))
                continue
            assert words[0] == "adpart", part
            args = words[1:] + SMALLER.get(words[1], [])
            result = runner.invoke(cli, args)
            assert result.exit_code == 0, f"{part}\n{result.output}"
            assert result.output.strip(), part
            outputs.append(result.output)
        for ref in ID.findall(comment):
            assert re.search(rf"\b{ref}\b", "".join(outputs)), f"{command}: {ref} not printed"
    assert (tmp_path / "first-session-kb").is_dir()
    for png in ("four-rooms.png", "subgoals.png", "blocks.png"):
        assert (tmp_path / png).read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("make_target", ["demo", "test"])
def test_the_readme_names_the_two_make_commands(make_target):
    assert f"make {make_target}" in README.read_text()


@pytest.mark.slow
def test_make_demos_pipeline_shows_what_the_readme_says(tmp_path) -> None:
    """The demo's pipeline (the Makefile's command, on a fresh knowledge base) gives the figures
    the README's "What the demo shows" states; they once drifted with the machine's rounding."""
    import json

    text = README.read_text()
    said = re.search(r"What the demo shows:.*?a\s+(\d+)-block layer.*?a Kaplan-Meier median of "
                     r"(\d+) episodes against\s+flat Q-learning's (\d+) \(ratio ([\d.]+)",
                     text, re.DOTALL)
    blocks, layer_median, flat_median, ratio = said.groups()
    make = (README.parent / "Makefile").read_text()
    line = re.search(r"\$\(ADPART\) (pipeline three-floor .*?)--out", make, re.DOTALL).group(1)
    args = shlex.split(line.replace("\\\n", " "))
    res = CliRunner().invoke(cli, [*args, "--kb", str(tmp_path / "kb"), "--out",
                                   str(tmp_path / "out"), "--json"])
    assert res.exit_code == 0, res.output
    rows = {r["learner"]: r for r in json.loads(res.output)["tasks"]
            if r["task"] == "reach-top-west"}
    layer, flat = rows["hierarchical"], rows["flat"]
    assert layer["initial_blocks"] == int(blocks)
    assert layer["runs_within_bound"] == layer["runs"] == 20
    layer_km = layer["time_to_bound_km"]["episodes"][0]
    flat_km = flat["time_to_bound_km"]["episodes"][0]
    assert (layer_km, flat_km) == (int(layer_median), int(flat_median))
    assert round(layer_km / flat_km, len(ratio.split(".")[1])) == float(ratio)
