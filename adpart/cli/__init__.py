"""The ``adpart`` command line (click). One module per sub-command group; this one lists them.

The sub-commands are loaded on first use (:class:`~adpart.cli.group.LazyGroup`), so that
``adpart --help`` and ``adpart --version`` start without numpy, the store or the plugins.
"""

from __future__ import annotations

import click

from adpart import __version__
from adpart.cli.group import DEBUG, LazyGroup

#: name -> (module:attribute, the one-line help ``adpart --help`` lists; tests check it).
COMMANDS: dict[str, tuple[str, str]] = {
    "discover": (
        "adpart.cli.discover_cmd:discover_cmd",
        ("Discover subgoals of ENV in a stored policy; print them with the threshold and "
        "statistics.")),
    "env": (
        "adpart.cli.envs:env_group",
        "Inspect one environment."),
    "envs": (
        "adpart.cli.envs:envs_cmd",
        "List the installed environments with their sizes and tasks."),
    "experiment": (
        "adpart.cli.experiment:experiment_cmd",
        ("Run experiment NAME (PNG figures, summary.json, summary.md in --out), or --list "
        "them.")),
    "hierarchy": (
        "adpart.cli.hierarchy_cmd:hierarchy_cmd",
        ("Build and store the decision layer for the next task of ENV (section 4.4, "
        "Algorithm 3).")),
    "kb": (
        "adpart.cli.kb:kb",
        "Inspect and maintain the knowledge base."),
    "learn": (
        "adpart.cli.learn:learn_cmd",
        ("Learn a task of ENV with a learner plugin; write curve, policies, plot and "
        "summary.")),
    "options": (
        "adpart.cli.options_cmd:options_cmd",
        ("Learn an option to every subgoal of a subgoal set of ENV; store options and "
        "models.")),
    "partition": (
        "adpart.cli.partition_cmd:partition_cmd",
        "Partition the states of ENV for an option set (phases 1-3 of section 4.2.1.2)."),
    "pipeline": (
        "adpart.cli.pipeline_cmd:pipeline_cmd",
        ("Learn the first task, discover subgoals, learn options, partition, transfer to "
        "the rest.")),
    "plugins": (
        "adpart.cli.plugins_cmd:plugins_cmd",
        "List installed plugins: kind, name, source package and parameters."),
    "report": (
        "adpart.cli.report_cmd:report_cmd",
        "Write one self-contained HTML page of the pipeline or experiment run in FOLDER."),
    "sweep": (
        "adpart.cli.sweep:sweep_cmd",
        ("Run the grid of experiments in CONFIG (TOML), storing each cell in the knowledge "
        "base.")),
    "transfer": (
        "adpart.cli.pipeline_cmd:transfer_cmd",
        ("Learn TASK of ENV on a stored decision layer with the hierarchical learner (last "
        "step).")),
}


@click.group(cls=LazyGroup, lazy=COMMANDS,
             context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="adpart")
@click.option("--debug", is_flag=True, envvar="ADPART_DEBUG",
              help="Print the traceback above a one-line error (e.g. a plugin's own failure) "
              "[env ADPART_DEBUG=1].")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """adpart: hierarchical RL through subgoals and action-dependent state partitions.

    \b
    Examples:
      adpart envs                       list the environments
      adpart env show two-rooms --out two-rooms.png --task reach-goal
      adpart learn two-rooms --task reach-goal --runs 8 --episodes 300
      adpart plugins --kind learner
    """
    ctx.meta[DEBUG] = debug
