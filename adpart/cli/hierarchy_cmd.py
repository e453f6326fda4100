"""``adpart hierarchy``: build the decision layer for the next task from the tasks learned so far.

A thin layer over :func:`adpart.workflows.hierarchy.build_hierarchy` (section 4.4, Algorithm 3),
which loads the learned tasks, calls the estimator plugin on them and stores the layer it returns
as a ``hierarchy`` partition: the command parses the arguments, opens the knowledge base and
prints the layer's blocks, the options it uses and the ``E[t_learn]`` trace (or JSON); ``--plot``
draws the layer on the domain's map and the trace beside it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from adpart.cli.common import (
    CLIError,
    echo_json,
    kb_location_options,
    plugin_options_command,
    registry,
    split_plugin_options,
)
from adpart.cli.pipeline_cmd import split_tasks
from adpart.errors import AdpartError


def _plot(env: str, result: Any, path: Path, task_names: list[str]) -> list[str]:
    """The layer on the map at ``path`` and, for Algorithm 3, the trace at ``<stem>_trace.png``."""
    import numpy as np

    from adpart.plotting import new_figure
    from adpart.workflows.partitioning import plot_partition

    title = (f"{env}: {result.estimator}, {result.n_blocks} blocks, "
             f"{len(result.option_ids)} options ({', '.join(task_names)})")
    written = [plot_partition(env, result.partition.labels, str(path), title=title)]
    if len(result.trace) > 1:
        trace_path = path.with_name(f"{path.stem}_trace{path.suffix or '.png'}")
        fig, ax = new_figure((6, 3.6))
        ax.semilogy(np.arange(len(result.trace)), result.trace, marker="o")
        ax.set_xlabel("accepted refinement (Algorithm 3)")
        ax.set_ylabel("E[t_learn | P]")
        ax.set_title(f"{env}: expected learning time while the layer grows")
        fig.tight_layout()
        try:
            fig.savefig(trace_path, dpi=110)
        except OSError as exc:
            raise CLIError(
                f"cannot write {trace_path}: {exc.strerror}; choose another --plot"
            ) from exc
        written.append(str(trace_path))
    return written


@click.command(name="hierarchy", cls=plugin_options_command("hierarchy-estimator", "estimator"))
@click.argument("env")
@click.option(
    "--estimator",
    default="expected-learning-time",
    show_default=True,
    help="hierarchy-estimator plugin (expected-learning-time, all-subgoals, ...).",
)
@click.option(
    "--tasks",
    metavar="T1,T2|task:N,...",
    help="Learned tasks to build from (names or task:N; default: every learned task).",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Draw the layer on the domain (PNG, a colour per block) and the trace (<FILE>_trace).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@kb_location_options
def hierarchy_cmd(
    env: str,
    estimator: str,
    tasks: str | None,
    plot_path: Path | None,
    as_json: bool,
    kb_path: str | None,
    kb_artifacts: str | None,
    **plugin_options: Any,
) -> None:
    """Build and store the decision layer for the next task of ENV (section 4.4, Algorithm 3).

    \b
    expected-learning-time starts from one block and no options and adds the (block, option)
    refinement that lowers the estimated learning time E[t_learn | P] over the learned tasks
    most, until it stops falling; all-subgoals offers every stored subgoal option (the seed's
    heuristic). The layer is stored as a `hierarchy` partition; learn a new task on it with
    `adpart transfer ENV --task T --partition partition:N`.
    """
    import numpy as np

    from adpart.store import KBLocation, KnowledgeBase
    from adpart.workflows.hierarchy import build_hierarchy

    try:
        params = split_plugin_options(registry().get("hierarchy-estimator", estimator),
                                      plugin_options)
    except AdpartError as exc:
        raise CLIError(str(exc)) from exc
    chosen = list(split_tasks(tasks)) if tasks is not None else None
    if chosen is not None and not chosen:
        raise CLIError("--tasks is empty; give task names or task:N refs separated by commas")
    kb = KnowledgeBase.open(KBLocation.resolve(kb_path, kb_artifacts))
    try:
        result = build_hierarchy(kb, env, estimator=estimator, tasks=chosen, params=params)
        names = [kb.get("task", i).name for i in result.task_ids]
    except AdpartError as exc:  # one line and exit 2, also when the command runs on its own
        raise CLIError(str(exc)) from exc
    finally:
        kb.close()
    summary = result.summary()
    labels = result.partition.labels
    sizes = np.bincount(labels, minlength=result.n_blocks)
    summary["task_names"] = names
    summary["env"] = env
    summary["option_names"] = result.column_names[len(result.column_names)
                                                  - len(result.option_ids):]
    summary["block_states"] = sizes.tolist()
    summary["block_columns"] = result.block_columns()
    if plot_path is not None:
        try:
            summary["plot"] = _plot(env, result, plot_path, names)
        except AdpartError as exc:
            raise CLIError(str(exc)) from exc
    if as_json:
        echo_json(summary)
        return
    _print(summary)


def _print(summary: dict[str, Any]) -> None:
    tasks = ", ".join(f"{r} ({n})" for r, n in zip(summary["tasks"], summary["task_names"],
                                                   strict=True))
    click.echo(
        f"{summary['env']}: {summary['partition'] or 'layer'} by {summary['estimator']} from "
        f"{tasks}: {summary['blocks']} blocks"
    )
    used = ", ".join(f"{r} ({n})" for r, n in zip(summary["options"], summary["option_names"],
                                                  strict=True))
    click.echo(f"  options used  {used or 'none (primitive actions only)'}")
    trace = summary["trace"]
    shown = " -> ".join(f"{v:.4g}" for v in trace) if len(trace) <= 12 else (
        " -> ".join(f"{v:.4g}" for v in trace[:6]) + " -> ... -> "
        + " -> ".join(f"{v:.4g}" for v in trace[-3:]))
    click.echo(f"  E[t_learn]    {shown}  ({summary['steps']} refinements)")
    if summary.get("flat_estimate") is not None:
        verdict = ("fall back to flat learning" if summary.get("fallback")
                   else "the layer is predicted to pay")
        click.echo(f"  flat MDP      {summary['flat_estimate']:.4g}  ({verdict})")
    secs = summary["seconds"]
    click.echo("  seconds       " + ", ".join(f"{k} {v:.2f}" for k, v in secs.items()))
    for b, (n, cols) in enumerate(zip(summary["block_states"], summary["block_columns"],
                                      strict=True)):
        click.echo(f"  block {b:<4} {n:>6} states  {', '.join(cols)}")
    for path in summary.get("plot", []):
        click.echo(f"  wrote {path}")
