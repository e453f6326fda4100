"""The ``adpart`` command line (click). One module per sub-command group; this one wires them."""

from __future__ import annotations

import click

from adpart import __version__
from adpart.cli.common import AdpartGroup
from adpart.cli.discover_cmd import discover_cmd
from adpart.cli.envs import env_group, envs_cmd
from adpart.cli.experiment import experiment_cmd
from adpart.cli.hierarchy_cmd import hierarchy_cmd
from adpart.cli.kb import kb
from adpart.cli.learn import learn_cmd
from adpart.cli.options_cmd import options_cmd
from adpart.cli.partition_cmd import partition_cmd
from adpart.cli.pipeline_cmd import pipeline_cmd, transfer_cmd
from adpart.cli.plugins_cmd import plugins_cmd
from adpart.cli.sweep import sweep_cmd


@click.group(cls=AdpartGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="adpart")
def cli() -> None:
    """adpart: hierarchical RL through subgoals and action-dependent state partitions.

    \b
    Examples:
      adpart envs                       list the environments
      adpart env show two-rooms --out two-rooms.png --task reach-goal
      adpart learn two-rooms --task reach-goal --runs 8 --episodes 300
      adpart plugins --kind learner
    """


cli.add_command(plugins_cmd)
cli.add_command(envs_cmd)
cli.add_command(env_group)
cli.add_command(learn_cmd)
cli.add_command(kb)
cli.add_command(experiment_cmd)
cli.add_command(options_cmd)
cli.add_command(discover_cmd)
cli.add_command(pipeline_cmd)
cli.add_command(transfer_cmd)
cli.add_command(partition_cmd)
cli.add_command(sweep_cmd)
cli.add_command(hierarchy_cmd)
