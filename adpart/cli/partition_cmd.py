"""``adpart partition``: multi-phase epsilon,delta-partitioning over stored options (section 4.2).

A thin layer over :func:`adpart.workflows.partitioning.partition_environment`: it parses the
arguments, opens the knowledge base, prints blocks and seconds per phase (or JSON) and draws the
final partition on the domain with ``--plot``.
"""

from __future__ import annotations

from pathlib import Path

import click

from adpart.cli.common import (
    check_criterion,
    echo_json,
    kb_location_options,
    key_values,
    registry,
    settings_options,
)
from adpart.partition.settings import DEFAULT_CRITERION, PartitionSettings


@click.command(name="partition")
@click.argument("env")
@click.option(
    "--options",
    "options_ref",
    required=True,
    metavar="ID|primitive",
    help="subgoal-set:N (its stored options), option:1,option:2, or primitive (the primitive "
    "actions as one-step options).",
)
@settings_options(PartitionSettings, "settings")
@click.option(
    "--criterion",
    default=DEFAULT_CRITERION,
    show_default=True,
    metavar="NAME",
    help="Partition-criterion plugin that refines every phase (`adpart plugins --kind "
    "partition-criterion`); the default is delta-stability with --delta and --reward-epsilon.",
)
@click.option(
    "--criterion-opt",
    multiple=True,
    metavar="KEY=VALUE",
    help="A parameter of the criterion (repeatable), e.g. --criterion-opt size=8.",
)
@click.option("--task", help="Task for phase 3 (reward refinement); omitted: phases 1-2 only. "
              "Every phase then runs on this task's model (its terminal and start states).")
@click.option(
    "--reward-baseline",
    default="mode",
    show_default=True,
    metavar="mode|min|none|NUMBER",
    help="Constant step reward taken out of R(s, o) before eq. 4.7: mode (the step reward most "
    "state-action pairs pay), min (the smallest), none (compare R itself) or a number.",
)
@click.option(
    "--executor",
    default="serial",
    show_default=True,
    help="Executor plugin for option models recomputed for the task.",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Draw the final partition on the domain (PNG, a colour per block).",
)
@click.option("--no-check", is_flag=True, help="Skip the independent stability checker.")
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@kb_location_options
def partition_cmd(
    env: str,
    options_ref: str,
    settings: PartitionSettings,
    criterion: str,
    criterion_opt: tuple[str, ...],
    task: str | None,
    reward_baseline: str,
    executor: str,
    plot_path: Path | None,
    no_check: bool,
    as_json: bool,
    kb_path: str | None,
    kb_artifacts: str | None,
) -> None:
    """Partition the states of ENV for an option set (phases 1-3 of section 4.2.1.2).

    \b
    Phase 1 (per option, reward independent) is reused from the knowledge base when it holds one
    for the same option and delta; phase 2 intersects and refines for the whole set; phase 3
    (with --task) splits by the task's rewards within epsilon. Every phase is stored
    (kinds per-option, intersected, reward-refined); the final partition is verified by the
    independent checker and, with a task, theorem 4.5's bound is shown next to the measured
    ||V* - V*_P||. Export the labels with `adpart kb export partition:N --field labels`.
    """
    from adpart.store import KBLocation, KnowledgeBase
    from adpart.workflows.partitioning import partition_environment, plot_partition

    baseline = _baseline_value(reward_baseline)
    criterion_params = key_values(criterion_opt, "--criterion-opt")
    check_criterion(criterion, criterion_params, settings)
    kb = KnowledgeBase.open(KBLocation.resolve(kb_path, kb_artifacts))
    try:
        with registry().get("executor", executor).create() as ex:
            outcome = partition_environment(
                kb,
                env,
                options_ref,
                settings,
                task=task,
                criterion=criterion,
                criterion_params=criterion_params,
                executor=ex,
                check=not no_check,
                reward_baseline=baseline,
            )
    finally:
        kb.close()
    summary = outcome.summary()
    if plot_path is not None:
        title = f"{env}: {outcome.final.n_blocks} blocks (delta={outcome.delta:g}" + (
            f", epsilon={outcome.epsilon:g}, {outcome.task})" if outcome.task else ")"
        )
        summary["plot"] = plot_partition(env, outcome.final.labels, str(plot_path), title=title,
                                         task=task)
    if as_json:
        echo_json(summary)
        return
    _print(summary)


def _baseline_value(text: str) -> str | float:
    if text in ("mode", "min", "none"):
        return text
    try:
        return float(text)
    except ValueError:
        raise click.BadParameter(
            f"{text!r}; use mode, min, none or a number", param_hint="--reward-baseline"
        ) from None


def _split(layer: dict | None) -> str:
    """``N reachable + 1 terminal + M unreachable`` for one phase's layer counts."""
    if not layer:
        return ""
    return (f" ({layer['reachable']} reachable + {layer['terminal']} terminal + "
            f"{layer['unreachable']} unreachable, {layer['unreachable_states']} states)")


def _print(summary: dict) -> None:
    p1, secs = summary["phase1"], summary["seconds"]
    task = f", task {summary['task']}" if summary["task"] else ""
    click.echo(
        f"{summary['env']}: {summary['states']} states, options {summary['options']}, "
        f"delta {summary['delta']:g}, epsilon {summary['epsilon']:g}{task}"
    )
    click.echo(
        f"  phase 1  {len(p1['partitions'])} per-option partitions, {p1['blocks_min']}-"
        f"{p1['blocks_max']} blocks each ({p1['computed']} computed, {p1['reused']} reused)"
        f"  {secs['phase1']:.2f} s"
    )
    layer = summary.get("layer") or {}
    click.echo(
        f"  phase 2  {summary['phase2']['blocks']} blocks{_split(layer.get('phase2'))}  "
        f"{secs['phase2']:.2f} s  {summary['phase2']['id']}"
    )
    if summary["phase3"] is not None:
        p3 = summary["phase3"]
        note = " (option models recomputed for the task)" if p3["recomputed_option_models"] else ""
        click.echo(f"  phase 3  {p3['blocks']} blocks{_split(layer.get('phase3'))}  "
                   f"{secs['phase3']:.2f} s  {p3['id']}{note}")
        base = summary.get("reward_baseline")
        if base is not None:
            click.echo(f"  eq. 4.7 on the rewards beyond a step reward of {base:g}")
    check = summary["check"]
    if check["ran"]:
        verdict = "stable" if check["ok"] else f"NOT stable ({check['violations']} violations)"
        click.echo(
            f"  checker  {verdict}: max mass spread {check['max_mass_span']:.3g}, max reward "
            f"spread {check['max_reward_span']:.3g}"
        )
    gap = summary["value_gap"]
    if gap is not None:
        click.echo(
            f"  ||V* - V*_P|| = {gap['measured']:.4g} (theorem 4.5 bound {gap['bound']:.4g}, "
            f"gamma {gap['gamma']:.4g}; V* inside the interval values in "
            f"{100 * gap['inside_interval']:.0f}% of states)"
        )
    if "plot" in summary:
        click.echo(f"  wrote {summary['plot']}")
