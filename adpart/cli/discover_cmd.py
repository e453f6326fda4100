"""``adpart discover``: subgoals of a stored policy, printed, plotted and kept in the KB."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from adpart.cli.common import (
    echo_json,
    kb_location_options,
    plugin_options_command,
    registry,
    split_plugin_options,
)
from adpart.errors import TaskError


@click.command(name="discover", cls=plugin_options_command("subgoal-detector", "detector"))
@click.argument("env")
@click.option(
    "--policy",
    "policy_ref",
    required=True,
    metavar="ID",
    help="The policy (policy:N or N), e.g. one stored by `adpart learn`.",
)
@click.option(
    "--detector",
    default="count-exhaustive",
    show_default=True,
    help="Subgoal detector plugin (see `adpart plugins --kind subgoal-detector`).",
)
@click.option(
    "--seed",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    help="Seed of the detector's sampling.",
)
@click.option(
    "--plot",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Draw the domain shaded by score (gradient ratio) with subgoals marked.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@kb_location_options
def discover_cmd(
    env: str,
    policy_ref: str,
    detector: str,
    seed: int,
    plot: Path | None,
    as_json: bool,
    kb_path: str | None,
    kb_artifacts: str | None,
    **plugin_options: Any,
) -> None:
    """Discover subgoals of ENV in a stored policy; print them with the threshold and statistics.

    \b
    The count-metric detectors follow section 4.1 of the dissertation: the count metric of
    eq. 4.1 (exhaustive, or sampled for count-mc), gradient ratios along sampled trajectories,
    and the one-sided t-test threshold mu of eq. 4.2. The subgoal set is stored in the
    knowledge base with its source policy; `adpart options ENV --subgoals ID` builds options.
    """
    from adpart.store import KBLocation, KnowledgeBase
    from adpart.workflows.discovery import discover_subgoals
    from adpart.workflows.refs import get_ref
    from adpart.workflows.resolve import resolve_domain

    spec = registry().get("subgoal-detector", detector)
    given = split_plugin_options(spec, plugin_options)
    kb = KnowledgeBase.open(KBLocation.resolve(kb_path, kb_artifacts))
    try:
        policy = get_ref(kb, policy_ref, "policy")
        task = kb.get("task", policy.task_id)
        env_rec = kb.get("environment", task.environment_id)
        if env_rec.name != env:
            raise TaskError(f"{policy.ref} belongs to environment {env_rec.name!r}, not {env!r}")
        found = discover_subgoals(kb, policy, detector=detector, params=given, seed=seed)
    finally:
        kb.close()
    result = found.result
    stats = dict(result.stats)
    out = {
        "env": env,
        "policy": policy.ref,
        "task": task.name,
        "detector": detector,
        "subgoal_set": found.record.ref,
        "subgoals": result.subgoals.tolist(),
        "threshold": result.threshold,
        "seconds": round(found.seconds, 4),
        "reused": found.reused,
        "params": dict(result.params),
        "stats": stats,
    }
    if plot is not None:
        plot.parent.mkdir(parents=True, exist_ok=True)
        resolve_domain(env).render(
            str(plot),
            values=result.scores,
            marked=result.mask,
            title=f"{env}: {detector} scores, subgoals marked",
            task=_drawable_task(env, task.name),
            value_label=f"{detector} score",
            mark_label="subgoals",
        )
        out["plot"] = str(plot)
    if as_json:
        echo_json(out)
        return
    mu = "n/a" if result.threshold is None else f"{result.threshold:.3g}"
    click.echo(
        f"{detector} on {env} ({policy.ref}, task {task.name}): "
        f"{result.subgoals.size} subgoals, mu = {mu}, {found.seconds:.3f} s"
        + (" (reused)" if found.reused else "")
    )
    click.echo(f"subgoals: {', '.join(map(str, result.subgoals.tolist())) or 'none'}")
    for key in ("ratio_mean", "ratio_sd", "n", "samples", "trajectories"):
        if key in stats:
            click.echo(f"{key}: {stats[key]}")
    click.echo(f"stored as {found.record.ref}")


def _drawable_task(env: str, name: str) -> str | None:
    """``name`` if ``env`` resolves it (a named task or ``goal:...``), so the map letters its
    goal; else None (the domain's default task)."""
    from adpart.errors import AdpartError
    from adpart.workflows.resolve import resolve_domain

    try:
        resolve_domain(env).task(name)
    except AdpartError:
        return None
    return name
