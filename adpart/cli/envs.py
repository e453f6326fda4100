"""``adpart envs`` and ``adpart env show``: the environments and their maps."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from adpart.cli.common import echo_json, registry

if TYPE_CHECKING:
    from adpart.envs.base import Domain


def describe(name: str, domain: Domain) -> dict[str, object]:
    dyn = domain.dynamics()
    return {
        "name": name,
        "states": dyn.n_states,
        "actions": list(dyn.action_names),
        "tasks": list(domain.tasks()),
        "default_task": domain.default_task or next(iter(domain.tasks()), None),
        "description": domain.description,
        "source": domain.source,
    }


@click.command(name="envs")
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
def envs_cmd(as_json: bool) -> None:
    """List the installed environments with their sizes and tasks."""
    reg = registry()
    rows = [describe(spec.name, spec.create()) for spec in reg.all("environment")]
    if as_json:
        echo_json(rows)
        return
    width = max((len(r["name"]) for r in rows), default=4)
    for r in rows:
        click.echo(
            f"{r['name']:<{width}}  {r['states']:>6} states  {len(r['actions'])} actions  "
            f"tasks: {', '.join(r['tasks'])}"
        )
    click.echo("Gymnasium environments: gym:<id>, e.g. gym:Taxi-v4, gym:FrozenLake-v1")
    click.echo("MiniGrid layouts (extra minigrid): minigrid:<id>[seed=N], e.g. "
               "minigrid:MiniGrid-FourRooms-v0")


@click.group(name="env")
def env_group() -> None:
    """Inspect one environment."""


@env_group.command(name="show")
@click.argument("name")
@click.option(
    "--out", type=click.Path(dir_okay=False, path_type=Path), help="Write the map to this PNG."
)
@click.option("--task", help="Overlay this task's optimal values (V*) on the map.")
@click.option("--json", "as_json", is_flag=True, help="Print the description as JSON.")
def env_show(name: str, out: Path | None, task: str | None, as_json: bool) -> None:
    """Describe environment NAME and optionally render it (with V* of a task) to PNG."""
    from adpart.workflows.resolve import resolve_domain

    domain = resolve_domain(name)
    info = describe(name, domain)
    if task is not None:  # resolved even without --out: a bad task fails here, named
        info["task"] = domain.task(task).name
    if out is not None:
        values = None
        if task is not None:
            from adpart.mdp.solvers import solve

            values = solve(domain.mdp(task), 1e-6).V
        out.parent.mkdir(parents=True, exist_ok=True)
        title = f"{name}" + (f" - V* of {task}" if task else "")
        domain.render(str(out), values=values, title=title, task=task,
                      value_label=f"V* of {task} (optimal value)" if task else "value")
        info["png"] = str(out)
    if as_json:
        echo_json(info)
        return
    for key, value in info.items():
        click.echo(f"{key}: {', '.join(value) if isinstance(value, list) else value}")
