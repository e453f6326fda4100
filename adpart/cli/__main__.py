"""``python -m adpart.cli`` runs the command line (as the ``adpart`` script does)."""

from adpart.cli import cli

cli()
