"""``adpart pipeline`` and ``adpart transfer``: the mission in one command, and its last step."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import click

from adpart.cli.common import (
    CLIError,
    check_criterion,
    dumps,
    echo_json,
    kb_location_options,
    key_values,
    registry,
    run_options,
    settings_options,
    stage_bars,
)
from adpart.errors import AdpartError
from adpart.learning.knowledge import REGIMES
from adpart.options.settings import InitiationSettings
from adpart.partition.settings import DEFAULT_CRITERION, PartitionSettings


def _check_plugin_params(kind: str, name: str, params: dict[str, Any], option: str,
                         name_option: str) -> None:
    """Validate ``params`` against plugin ``name`` now, naming ``option`` in the message.

    The pipeline stores a run, policies, subgoals and options before it reaches the later
    steps; building every step's plugin here (so that a constructor's checks across parameters
    run too) means a bad value fails before anything is computed or stored.
    """
    try:
        spec = registry().get(kind, name)
    except AdpartError as exc:  # the plugin itself is unknown: the option that named it
        raise CLIError(f"{name_option}: {exc}") from None
    try:
        spec.create(params)
    except AdpartError as exc:
        raise CLIError(f"{option}: {exc}") from None


def check_pipeline_options(config: Any) -> None:
    """Every value of a pipeline's config checked up front (plugins, parameters, tasks)."""
    from adpart.workflows.pipeline import check_tasks
    from adpart.workflows.regime import check_regime, layer_params

    try:
        check_tasks(config.env, config.tasks)
    except AdpartError as exc:
        raise CLIError(f"--tasks: {exc}") from None
    _check_plugin_params("subgoal-detector", config.detector, config.detector_params,
                         "--detector-opt", "--detector")
    _check_plugin_params("learner", config.flat_learner, config.flat_params, "--flat-opt",
                         "--flat-learner")
    _check_plugin_params("learner", "hierarchical", layer_params(config), "--hier-opt",
                         "--hier-opt")  # with the regime's default exploration
    check_criterion(config.criterion, config.criterion_params, config.partition)
    try:
        check_regime(config)
    except AdpartError as exc:
        raise CLIError(str(exc)) from None
    if config.hierarchy is not None:
        _check_plugin_params("hierarchy-estimator", config.hierarchy, config.hierarchy_params,
                             "--hierarchy-opt", "--hierarchy")


def split_tasks(text: str) -> tuple[str, ...]:
    """Split ``--tasks`` on commas, keeping a task spec's own commas (``goal:x=9,y=5``,
    ``move-goal:row=0,col=3;from:reward``, ``set-reward:row=1,col=1=-1;terminal``) whole: a
    token that goes on with ``FEATURE=`` continues the spec before it."""
    specs = ("goal:", "move-goal:", "set-reward:", "reward-table:")
    tasks: list[str] = []
    for token in (t.strip() for t in text.split(",")):
        if not token:
            continue
        if (tasks and tasks[-1].startswith(specs) and "=" in token
                and ":" not in token.split("=", 1)[0]):
            tasks[-1] += "," + token
        else:
            tasks.append(token)
    return tuple(tasks)


def _say(quiet: bool):  # type: ignore[no-untyped-def]
    """One stderr line per stage as it starts, timestamped when stderr is a log, not a terminal
    (so a long run written to a file shows where it is); nothing with ``--quiet``/``--json``."""
    if quiet:
        return lambda message: None
    if sys.stderr.isatty():
        return lambda message: click.echo(f"... {message}", err=True)
    return lambda message: click.echo(f"{time.strftime('%H:%M:%S')} {message}", err=True)


@click.command(name="pipeline")
@click.argument("env")
@click.option(
    "--tasks", required=True, help="Comma-separated task sequence; the first is learned flat."
)
@click.option(
    "--detector", default="count-exhaustive", show_default=True, help="Subgoal detector plugin."
)
@click.option(
    "--detector-opt",
    multiple=True,
    metavar="KEY=VALUE",
    help="A detector parameter (repeatable), e.g. --detector-opt p=0.025.",
)
@settings_options(InitiationSettings, "initiation")
@settings_options(PartitionSettings, "partition")
@click.option(
    "--criterion",
    default=DEFAULT_CRITERION,
    show_default=True,
    metavar="NAME",
    help="Partition-criterion plugin refining every phase (default: eqs. 4.6-4.7 with --delta "
    "and --reward-epsilon).",
)
@click.option(
    "--criterion-opt",
    multiple=True,
    metavar="KEY=VALUE",
    help="A parameter of the criterion (repeatable).",
)
@run_options()
@click.option(
    "--first-episodes",
    type=click.IntRange(min=1),
    default=500,
    show_default=True,
    help="Episodes of the first (flat) task.",
)
@click.option(
    "--flat-learner",
    default="q-learning",
    show_default=True,
    metavar="NAME",
    help="Learner of the first task, the baseline and the fallback.",
)
@click.option(
    "--flat-opt",
    multiple=True,
    metavar="KEY=VALUE",
    help="A parameter of the flat learner, e.g. --flat-opt alpha=1.",
)
@click.option(
    "--no-fallback",
    is_flag=True,
    help="Learn on the layer even where the fallback checks predict flat is faster (section "
         "4.4's estimate in the true-model regime; the rehearsal on the agent's own model in "
         "the learned-model regime).",
)
@click.option(
    "--hier-opt",
    multiple=True,
    metavar="KEY=VALUE",
    help="A hierarchical-learner parameter, e.g. --hier-opt mode=inconsistency.",
)
@click.option("--regime", type=click.Choice(REGIMES), default=REGIMES[0], show_default=True,
              help="What the off-line steps read: the model estimated from the first task's "
                   "runs, or the true model (the seed's figures).")
@click.option("--baseline/--no-baseline", default=True, show_default=True,
              help="Also learn each later task flat, for comparison.")
@click.option("--model-baseline/--no-model-baseline", default=True, show_default=True,
              help="Also learn them model-based with the layer learner's dynamics (true or "
                   "estimated), rewards observed.")
@click.option(
    "--hierarchy",
    metavar="NAME",
    help="Start each later task from this hierarchy estimator's layer of the earlier tasks.",
)
@click.option(
    "--hierarchy-opt",
    multiple=True,
    metavar="KEY=VALUE",
    help="An estimator parameter, e.g. --hierarchy-opt threshold-scale=0.001.",
)
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for figures and summary.json [default: adpart-pipeline/ENV].",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("-q", "--quiet", is_flag=True, help="No progress lines.")
@kb_location_options
def pipeline_cmd(
    env: str,
    tasks: str,
    detector: str,
    detector_opt: tuple[str, ...],
    initiation: InitiationSettings,
    partition: PartitionSettings,
    criterion: str,
    criterion_opt: tuple[str, ...],
    runs: int,
    episodes: int,
    first_episodes: int,
    seed: int,
    eval_every: int,
    flat_learner: str,
    flat_opt: tuple[str, ...],
    no_fallback: bool,
    hier_opt: tuple[str, ...],
    regime: str,
    baseline: bool,
    model_baseline: bool,
    hierarchy: str | None,
    hierarchy_opt: tuple[str, ...],
    out: Path | None,
    as_json: bool,
    quiet: bool,
    kb_path: str | None,
    kb_artifacts: str | None,
) -> None:
    """Learn the first task, discover subgoals, learn options, partition, transfer to the rest.

    \b
    Later tasks are learned on the stored layer, refined by 4.3.3, beside the baselines. Every
    step is stored and reused, so a rerun or a resumed crash recomputes nothing. Ends with
    each learner's Kaplan-Meier time to the bound and what it knew (docs/pipeline.md).
    """
    from adpart.store import KBLocation, KnowledgeBase
    from adpart.workflows.pipeline import PipelineConfig, run_pipeline
    from adpart.workflows.pipeline_table import comparison_lines
    from adpart.workflows.progress import progress_bars
    from adpart.workflows.reports import folder_name

    config = PipelineConfig(
        env=env,
        tasks=split_tasks(tasks),
        detector=detector,
        detector_params=key_values(detector_opt, "--detector-opt"),
        initiation=initiation,
        partition=partition,
        criterion=criterion,
        criterion_params=key_values(criterion_opt, "--criterion-opt"),
        runs=runs,
        episodes=episodes,
        first_episodes=first_episodes,
        seed=seed,
        eval_every=eval_every,
        flat_params=key_values(flat_opt, "--flat-opt"),
        hierarchical_params=key_values(hier_opt, "--hier-opt"),
        baseline=baseline,
        model_baseline=model_baseline,
        hierarchy=hierarchy,
        hierarchy_params=key_values(hierarchy_opt, "--hierarchy-opt"),
        flat_learner=flat_learner,
        fallback=not no_fallback,
        regime=regime,
    )
    check_pipeline_options(config)
    out = out or Path("adpart-pipeline") / folder_name(env)
    kb = KnowledgeBase.open(KBLocation.resolve(kb_path, kb_artifacts))
    try:
        with progress_bars(stage_bars(not (quiet or as_json))):  # a bar inside each stage
            report = run_pipeline(kb, config, out=out, progress=_say(quiet or as_json))
    finally:
        kb.close()
    summary = report.to_json()
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(dumps(summary))
    if as_json:
        echo_json(summary)
        return
    for stage in report.stages:
        click.echo(
            f"{stage.stage:<24} {stage.task or '':<20} {stage.result:<28} "
            f"{'reused' if stage.reused else f'{stage.seconds:.2f} s'}"
        )
        if stage.detail.get("reason"):
            click.echo(f"  {stage.detail['reason']}")
        for dropped in stage.detail.get("dropped", ()):
            click.echo(f"  subgoal {dropped['subgoal']} dropped: {dropped['reason']}")
    click.echo("")
    for line in comparison_lines(report.rows):
        click.echo(line)
    click.echo(f"\nwrote {out}/: summary.json " + " ".join(Path(f).name for f in report.figures))


@click.command(name="transfer")
@click.argument("env")
@click.option("--task", required=True, help="The new task to learn on the decision layer.")
@click.option(
    "--partition",
    "partition_ref",
    required=True,
    metavar="ID",
    help="The decision layer (partition:N), e.g. from `adpart partition` or a pipeline.",
)
@run_options()
@click.option(
    "--hier-opt",
    multiple=True,
    metavar="KEY=VALUE",
    help="A hierarchical-learner parameter, e.g. --hier-opt mode=action-refinement.",
)
@click.option("--baseline/--no-baseline", default=False, show_default=True,
              help="Also learn the task flat, for comparison.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for the figure and summary.json [default: adpart-transfer/ENV_TASK].",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@kb_location_options
def transfer_cmd(
    env: str,
    task: str,
    partition_ref: str,
    runs: int,
    episodes: int,
    seed: int,
    eval_every: int,
    hier_opt: tuple[str, ...],
    baseline: bool,
    out: Path | None,
    as_json: bool,
    kb_path: str | None,
    kb_artifacts: str | None,
) -> None:
    """Learn TASK of ENV on a stored decision layer with the hierarchical learner (last step)."""
    from adpart.learning.comparison import task_row
    from adpart.learning.curves import SUCCESS_FRACTION, plot_curves
    from adpart.store import KBLocation, KnowledgeBase
    from adpart.workflows.learning import (
        LearnRequest,
        find_learning,
        load_curve,
        record_learning,
        run_learning,
    )
    from adpart.workflows.pipeline import episode_defaults, learner_defaults
    from adpart.workflows.pipeline_table import comparison_lines
    from adpart.workflows.progress import progress_bars
    from adpart.workflows.refs import parse_ref
    from adpart.workflows.reports import folder_name

    defaults = episode_defaults(env)  # the pipeline's, for both learners
    hier_params = {**learner_defaults("hierarchical", defaults),
                   **key_values(hier_opt, "--hier-opt")}
    _check_plugin_params("learner", "hierarchical", hier_params, "--hier-opt", "--hier-opt")
    out = out or Path("adpart-transfer") / folder_name(env, task)
    requests = {
        "hierarchical": LearnRequest(
            env=env,
            task=task,
            learner="hierarchical",
            params=hier_params,
            runs=runs,
            episodes=episodes,
            seed=seed,
            eval_every=eval_every,
            partition=partition_ref,
        )
    }
    if baseline:
        requests["flat"] = LearnRequest(
            env=env,
            task=task,
            learner="q-learning",
            params=learner_defaults("q-learning", defaults),
            runs=runs,
            episodes=episodes,
            seed=seed,
            eval_every=eval_every,
        )
    kb = KnowledgeBase.open(KBLocation.resolve(kb_path, kb_artifacts))
    rows, curves, ids = [], {}, {}
    try:
        blocks = int(kb.get("partition", parse_ref(partition_ref, "partition")).n_blocks)
        for label, request in requests.items():
            found = find_learning(kb, request)
            if found is None:
                with progress_bars(stage_bars(not as_json)):  # a bar while it learns
                    found = record_learning(kb, run_learning(request, kb=kb))
            run = kb.get("run", parse_ref(found["run"], "run"))
            curves[label] = load_curve(kb, run)
            ids[label] = found["run"]
            extra = {"initial_blocks": blocks} if label == "hierarchical" else {}
            rows.append(task_row(task, label, curves[label], SUCCESS_FRACTION, extra))
    finally:
        kb.close()
    figure = plot_curves(
        curves, out / "transfer.png", metric="value_gap",
        title=(f"{env}/{task}: value gap of the greedy policy\n"
               f"hierarchical on {partition_ref} ({blocks} blocks) vs flat, {runs} runs each"),
        bound=rows[0]["bound"], bound_label=f"success bound ({SUCCESS_FRACTION:.0%} of |V*|)",
    )
    summary = {
        "env": env,
        "task": task,
        "partition": partition_ref,
        "runs": ids,
        "rows": rows,
        "figure": str(figure),
    }
    (out / "summary.json").write_text(dumps(summary))
    if as_json:
        echo_json(summary)
        return
    for line in comparison_lines(rows):
        click.echo(line)
    click.echo(f"\nstored {', '.join(ids.values())}; wrote {out}/transfer.png summary.json")
