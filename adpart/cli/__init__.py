"""The ``adpart`` command line (click). One module per sub-command group; this one wires them."""

from __future__ import annotations

import click

from adpart import __version__


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="adpart")
def cli() -> None:
    """adpart: hierarchical RL through subgoals and action-dependent state partitions.

    \b
    Examples:
      adpart envs                       list the environments
      adpart env show two-rooms --out two-rooms.png
      adpart learn two-rooms --task reach-goal --runs 8 --episodes 300
    """
