"""``adpart learn``: learn a task with a learner plugin; write curve, policy, plot and summary.

Every learner plugin's declared parameters become options of this command (shown in ``--help``
with the learners that take them); an option that the chosen learner does not declare is an error.
The work itself is :func:`adpart.workflows.run_learning`.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from adpart.cli.common import (
    CLIError,
    dumps,
    echo_json,
    executor_options,
    kb_location_options,
    make_executor,
    plugin_options_command,
    progress_callback,
    registry,
    run_options,
    split_plugin_options,
)

if TYPE_CHECKING:
    from adpart.workflows.store import KnowledgeStore


@click.command(name="learn", cls=plugin_options_command("learner", "learner"))
@click.argument("env")
@click.option("--task", help="Task name (see `adpart envs`) or goal:FEATURE=VALUE,... .")
@click.option("--learner", default="q-learning", show_default=True, help="Learner plugin.")
@run_options()
@executor_options()
@click.option(
    "--runs-per-batch",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    help="Split runs into batches of this size for the executor (0 = one batch).",
)
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Output folder [default: adpart-learn/ENV_TASK_LEARNER_seedS].",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
@click.option(
    "--options",
    "options_ref",
    metavar="ID",
    help="Options for smdp-q/hierarchical: subgoal-set:N, option:1,option:2 or primitive.",
)
@click.option(
    "--partition",
    "partition_ref",
    metavar="ID",
    help="Decision layer for the hierarchical learner (partition:N, from the KB).",
)
@click.option(
    "--model",
    "model_ref",
    metavar="ENV@experience:run:N",
    help="The dynamics estimated from runs' experience, for hierarchical (its belief), "
    "estimated-dynamics (its prior counts), smdp-q (where its options were solved) or sf-gpi "
    "(those runs' policies and counts).",
)
@click.option("--no-store", is_flag=True, help="Do not record the run in the knowledge base.")
@click.option("--force", is_flag=True,
              help="Record the run again even if the knowledge base already holds it (e.g. to "
              "re-create a damaged record).")
@kb_location_options
def learn_cmd(
    env: str,
    task: str | None,
    learner: str,
    episodes: int,
    runs: int,
    seed: int,
    eval_every: int,
    executor: str,
    executor_opts: tuple[str, ...],
    ray_address: str | None,
    runs_per_batch: int,
    out: Path | None,
    as_json: bool,
    quiet: bool,
    options_ref: str | None,
    partition_ref: str | None,
    model_ref: str | None,
    no_store: bool,
    force: bool,
    kb_path: str | None,
    kb_artifacts: str | None,
    **plugin_options: str | None,
) -> None:
    """Learn a task of ENV with a learner plugin; write curve, policies, plot and summary.

    \b
    Writes to the output folder:
      curve.parquet   one row per (run, episode): steps, decisions, return, value gap
      policy.parquet  the greedy policy of every run: run, state, action, value
      curve.png       value gap of every run, their median and quartiles, the success bound
      summary.json    what was run and how it ended

    \b
    and records in the knowledge base (--kb, unless --no-store): the environment and task, one
    policy per run (Q and greedy policy) and one run with the curve; their ids are printed. A run
    is deterministic in its settings and seed, so one the knowledge base already holds is not
    recorded twice.

    Where the learner takes them, --alpha defaults to 1 on an environment whose every move is
    deterministic (else the learner's 1/n^0.8) and --max-steps to max(1000, 2 x states), as in
    `adpart pipeline`.
    """
    from adpart.store.location import KBLocation
    from adpart.workflows import (
        LearnRequest,
        find_learning,
        record_learning,
        run_learning,
        write_learning_outputs,
    )
    from adpart.workflows.pipeline import episode_defaults, learner_defaults
    from adpart.workflows.reports import folder_name
    from adpart.workflows.resolve import resolve_domain

    reg = registry()
    spec = reg.get("learner", learner)
    # the environment's defaults, as the pipeline's (alpha 1 where every move is deterministic,
    # episodes long enough to cross the map), under what the command line gives
    given = {**learner_defaults(learner, episode_defaults(env)),
             **split_plugin_options(spec, plugin_options)}
    spec.resolve_params(given)  # every value checked (nan, ranges, schedules) before any work
    request = LearnRequest(
        env=env,
        task=task,
        learner=learner,
        params=given,
        runs=runs,
        episodes=episodes,
        seed=seed,
        eval_every=eval_every,
        runs_per_batch=runs_per_batch,
        options=options_ref,
        partition=partition_ref,
        model=model_ref,
    )
    resolve_domain(env).task(task)  # an unknown environment or task: refused before any work
    single = len(request.batches()) == 1
    kb = None
    if not no_store or options_ref or partition_ref or model_ref:
        from adpart.store import KnowledgeBase

        kb = KnowledgeBase.open(KBLocation.resolve(kb_path, kb_artifacts))
    try:
        update, close = progress_callback(not quiet and single, episodes, f"{learner} on {env}")
        try:
            outcome = run_learning(
                request,
                executor=make_executor(executor, executor_opts, ray_address),
                progress=update,
                kb=kb,
            )
        finally:
            close()
        out = out or Path("adpart-learn") / folder_name(env, outcome.task_name, learner,
                                                         f"seed{seed}")
        summary = outcome.summary()
        summary["files"] = write_learning_outputs(out, outcome)
        if not no_store and kb is not None:
            # Runs are deterministic in their request: one already recorded is not stored twice.
            known = None if force else find_learning(kb, request)
            if known is not None:
                _check_stored(kb, known)
            summary["kb"] = (
                {**known, "already_stored": True} if known else record_learning(kb, outcome)
            )
    finally:
        if kb is not None:
            kb.close()
    summary["files"]["summary"] = str(out / "summary.json")
    (out / "summary.json").write_text(dumps(summary))
    if as_json:
        echo_json(summary)
        return
    gap = summary["final_value_gap"]
    click.echo(
        f"{learner} on {env}/{outcome.task_name}: {summary['runs']} runs x {episodes} episodes, "
        f"final value gap mean {gap['mean']:.3g} max {gap['max']:.3g} "
        f"({summary['optimal_runs']}/{summary['runs']} runs optimal)"
    )
    click.echo(f"wrote {out}/: curve.parquet policy.parquet curve.png summary.json")
    if "kb" in summary:
        ids = summary["kb"]
        verb = "already stored" if ids.get("already_stored") else "stored"
        click.echo(
            f"{verb} in {ids['location']}: {ids['run']}, {ids['task']}, policies "
            f"{ids['policies'][0]} .. {ids['policies'][-1]}"
        )


def _check_stored(kb: KnowledgeStore, known: dict[str, Any]) -> None:
    """Refuse to report a damaged stored run as "already stored": say how to re-create it."""
    from adpart.store import StoreError

    kind, _, rid = known["run"].partition(":")
    try:
        kb.load(kb.get(kind, int(rid)), "curve")
    except StoreError as exc:
        raise CLIError(
            f"{known['run']} is already stored but damaged ({exc}); re-create it with --force, "
            f"or remove it with `adpart kb rm {known['run']} --yes` and run again"
        ) from exc
