"""The main group starts light: sub-commands load on first use, their listing stays true."""

from __future__ import annotations

import importlib
import select
import signal
import subprocess
import sys

import click
from click.testing import CliRunner

from adpart.cli import COMMANDS, cli
from adpart.cli.group import INTERRUPTED, LazyGroup


def _loaded(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys; print(*sys.modules)"],
                         capture_output=True, text=True, check=True)
    return set(out.stdout.split())


def test_version_and_help_load_neither_numpy_nor_the_store_nor_the_plugins():
    for args in (["--version"], ["--help"]):
        code = ("from adpart.cli import cli\n"
                f"try:\n    cli.main({args!r}, standalone_mode=False)\nexcept SystemExit:\n"
                "    pass")
        loaded = _loaded(code)
        assert {"numpy", "sqlalchemy", "pluggy", "adpart.store", "adpart.plugins"}.isdisjoint(
            loaded), sorted(m for m in loaded if m.split(".")[0] in {"numpy", "sqlalchemy"})


def test_the_listing_is_each_commands_own_help_and_name():
    for name, (target, short) in COMMANDS.items():
        module, _, attribute = target.partition(":")
        command = getattr(importlib.import_module(module), attribute)
        assert isinstance(command, click.Command) and command.name == name
        assert short == command.get_short_help_str(limit=1000)


def test_help_lists_every_command_once_with_its_help():
    out = CliRunner().invoke(cli, ["--help"])
    assert out.exit_code == 0
    rows = [line.split(None, 1) for line in out.output.split("Commands:")[1].strip().splitlines()]
    assert [r[0] for r in rows] == sorted(COMMANDS)
    for name, listed in rows:
        assert COMMANDS[name][1].startswith(listed.removesuffix("...")), (name, listed)


def test_a_loaded_command_runs_and_an_unknown_one_is_refused():
    runner = CliRunner()
    assert runner.invoke(cli, ["envs", "--json"]).exit_code == 0
    bad = runner.invoke(cli, ["lern"])
    assert bad.exit_code == 2 and "No such command 'lern'" in bad.output


def test_ctrl_c_exits_130():
    @click.group(cls=LazyGroup)
    def group() -> None:
        pass

    @group.command()
    def slow() -> None:
        raise KeyboardInterrupt

    out = CliRunner().invoke(group, ["slow"])
    assert out.exit_code == INTERRUPTED == 128 + signal.SIGINT
    assert "Interrupted." in out.output


def test_output_to_a_pipe_arrives_line_by_line():
    """The first line is readable while the command still runs (not at exit, as with a block
    buffer; click.echo flushes every call, so commands use it): the child prints a line, then
    waits for our reply on stdin before it goes on."""
    code = ("import click, sys\nfrom adpart.cli.group import LazyGroup\n"
            "@click.group(cls=LazyGroup)\ndef g():\n    pass\n"
            "@g.command()\ndef talk():\n    click.echo('stage 1 done')\n    sys.stdin.readline()\n"
            "    click.echo('stage 2 done')\n"
            "g(['talk'])\n")
    with subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, text=True) as child:
        try:
            ready, _, _ = select.select([child.stdout], [], [], 30)
            assert ready, "no line within 30 s: the child's stdout is block-buffered"
            assert child.stdout.readline() == "stage 1 done\n"
            child.stdin.write("go\n")
            child.stdin.flush()
            assert child.stdout.readline() == "stage 2 done\n"
        finally:
            child.kill()


def test_pipeline_stage_lines_reach_a_log(capsys):
    from adpart.cli.pipeline_cmd import _say

    _say(False)("discover subgoals")  # pytest's stderr is not a terminal: a log line
    line = capsys.readouterr().err
    assert line.endswith(" discover subgoals\n") and line[2] == ":" and line[5] == ":"
    _say(True)("hidden")
    assert capsys.readouterr().err == ""
