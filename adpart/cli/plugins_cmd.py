"""``adpart plugins``: what is installed, by kind and source package."""

from __future__ import annotations

import click

from adpart.cli.common import echo_json, registry
from adpart.plugins import KINDS


@click.command(name="plugins")
@click.option("--kind", type=click.Choice(list(KINDS)), help="Only plugins of this kind.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
def plugins_cmd(kind: str | None, as_json: bool) -> None:
    """List installed plugins: kind, name, source package and parameters."""
    reg = registry()
    rows = [
        {
            "kind": spec.kind,
            "name": spec.name,
            "package": spec.package,
            "version": spec.version,
            "description": spec.description,
            "params": [
                {"name": p.name, "type": p.type, "default": p.default, "help": p.help}
                for p in spec.params
            ],
        }
        for spec in reg.all(kind)
    ]
    if as_json:
        echo_json(rows)
        return
    if not rows:
        click.echo("no plugins" + (f" of kind {kind}" if kind else ""))
        return
    width = max(len(r["name"]) for r in rows)
    for k in KINDS if kind is None else (kind,):
        group = [r for r in rows if r["kind"] == k]
        if not group:
            continue
        click.echo(f"{k}:")
        for r in group:
            click.echo(f"  {r['name']:<{width}}  {r['package']} {r['version']}  {r['description']}")
