"""``adpart learn``: learn a task with a learner plugin; write curve, policy, plot and summary.

Every learner plugin's declared parameters become options of this command (shown in ``--help``
with the learners that take them); an option that the chosen learner does not declare is an error.
Runs can be split into batches that an executor plugin computes in parallel; batch ``b`` of a
learn with seed ``S`` is seeded with ``SeedSequence(S).spawn(n)[b]``, so results depend on the
seed and the batch size, never on the executor or the number of workers.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import click
import numpy as np

from adpart.cli.common import CLIError, dumps, echo_json, progress_callback, registry
from adpart.cli.envs import resolve_domain
from adpart.errors import TaskError
from adpart.store.location import KBLocation


class LearnerOptionsCommand(click.Command):
    """A command whose options include every installed learner's declared parameters."""

    def get_params(self, ctx: click.Context) -> list[click.Parameter]:
        params = super().get_params(ctx)
        reg = registry()
        if getattr(self, "_options_for", None) is not reg:  # rebuilt when the registry is
            self._options_for, self._plugin_params = reg, _learner_options()
        return params[:-1] + self._plugin_params + params[-1:]  # keep --help last


def _learner_options() -> list[click.Option]:
    owners: dict[str, list[str]] = {}
    helps: dict[str, str] = {}
    for spec in registry().all("learner"):
        for p in spec.params:
            owners.setdefault(p.name, []).append(spec.name)
            helps.setdefault(p.name, f"{p.help} (default {p.default})")
    return [
        click.Option(
            [f"--{name}", f"plugin_{name.replace('-', '_')}"],
            default=None,
            help=f"{helps[name]} [learner: {', '.join(owners[name])}]",
        )
        for name in owners
    ]


def _learn_batch(job: dict[str, Any]) -> dict[str, Any]:
    """Executor work item: learn one batch of runs. Module-level so process pools can run it."""
    domain = resolve_domain(job["env"])
    mdp = domain.mdp(job["task"])
    learner = registry().get("learner", job["learner"]).create(job["params"])
    result = learner.learn(
        mdp,
        runs=job["runs"],
        episodes=job["episodes"],
        seed=job["seed"],
        eval_every=job["eval_every"],
        progress=job.get("progress"),
    )
    return {
        "Q": result.Q,
        "curve": result.curve.to_dict(),
        "metadata": dict(result.curve.metadata),
        "seed": result.seed,
        "v_star_start": result.v_star_start,
        "parameters": result.parameters,
    }


def _batch_seeds(seed: int, n: int) -> list[int]:
    if n == 1:
        return [seed]
    return [
        int(c.generate_state(1, np.uint64)[0] >> np.uint64(1))
        for c in np.random.SeedSequence(seed).spawn(n)
    ]


@click.command(name="learn", cls=LearnerOptionsCommand)
@click.argument("env")
@click.option("--task", help="Task name (see `adpart envs`) or goal:FEATURE=VALUE,... .")
@click.option("--learner", default="q-learning", show_default=True, help="Learner plugin.")
@click.option(
    "--episodes",
    type=click.IntRange(min=1),
    default=300,
    show_default=True,
    help="Episodes per run (sweeps for value-iteration).",
)
@click.option(
    "--runs", type=click.IntRange(min=1), default=10, show_default=True, help="Independent runs."
)
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Root seed.")
@click.option(
    "--eval-every",
    type=click.IntRange(min=1),
    default=10,
    show_default=True,
    help="Score the greedy policy exactly every N episodes.",
)
@click.option("--executor", default="local", show_default=True, help="Executor plugin for batches.")
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
@click.option("--no-store", is_flag=True, help="Do not record the run in the knowledge base.")
@click.option(
    "--kb",
    "kb_path",
    envvar="ADPART_KB",
    metavar="PATH|URL",
    help="Knowledge base directory or database URL [env ADPART_KB; default "
    "$ADPART_HOME/kb or ~/.local/share/adpart/kb]",
)
@click.option(
    "--kb-artifacts",
    envvar="ADPART_KB_ARTIFACTS",
    metavar="URI",
    help="Artifact root for a database URL (any pyarrow filesystem URI)",
)
def learn_cmd(
    env: str,
    task: str | None,
    learner: str,
    episodes: int,
    runs: int,
    seed: int,
    eval_every: int,
    executor: str,
    runs_per_batch: int,
    out: Path | None,
    as_json: bool,
    quiet: bool,
    no_store: bool,
    kb_path: str | None,
    kb_artifacts: str | None,
    **plugin_options: str | None,
) -> None:
    """Learn a task of ENV with a learner plugin; write curve, policies, plot and summary.

    \b
    Writes to the output folder:
      curve.parquet   one row per (run, episode): steps, decisions, return, value gap
      policy.parquet  the greedy policy of every run: run, state, action, value
      curve.png       mean value gap over runs with a min-max band
      summary.json    what was run and how it ended

    \b
    and records in the knowledge base (--kb, unless --no-store): the environment and task, one
    policy per run (Q and greedy policy) and one run with the curve; their ids are printed.
    """
    reg = registry()
    spec = reg.get("learner", learner)
    given = {k.removeprefix("plugin_"): v for k, v in plugin_options.items() if v is not None}
    declared = {p.keyword for p in spec.params}
    foreign = sorted(set(given) - declared)
    if foreign:
        raise CLIError(
            f"--{foreign[0].replace('_', '-')} is not a parameter of learner {learner!r}; its "
            f"parameters: {', '.join('--' + p.name for p in spec.params) or 'none'}"
        )
    params = spec.resolve_params(given)
    domain = resolve_domain(env)
    task_obj = domain.task(task)
    mdp = domain.mdp(task_obj)
    executor_spec = reg.get("executor", executor)

    size = runs if runs_per_batch == 0 else min(runs_per_batch, runs)
    n_batches = math.ceil(runs / size)
    counts = [size] * (n_batches - 1) + [runs - size * (n_batches - 1)]
    jobs = [
        {
            "env": env,
            "task": task_obj.name if task is None else task,
            "learner": learner,
            "params": params,
            "runs": k,
            "episodes": episodes,
            "seed": s,
            "eval_every": eval_every,
        }
        for k, s in zip(counts, _batch_seeds(seed, n_batches), strict=True)
    ]
    update, close = progress_callback(not quiet and n_batches == 1, episodes, f"{learner} on {env}")
    try:
        if n_batches == 1:
            jobs[0]["progress"] = update
            batches = [_learn_batch(jobs[0])]
        else:
            with executor_spec.create() as ex:
                batches = ex.map(_learn_batch, jobs)
    finally:
        close()

    from adpart.learning.curves import plot_curves

    curve = _merge_curves([b["curve"] for b in batches], batches[0]["metadata"])
    Q = np.concatenate([b["Q"] for b in batches])
    out = (
        out
        or Path("adpart-learn") / f"{env.replace(':', '_')}_{task_obj.name}_{learner}_seed{seed}"
    )
    files = _write_outputs(out, curve, Q, plot_curves)
    gaps = curve.matrix("value_gap")[:, -1]
    summary = {
        "env": env,
        "task": task_obj.name,
        "learner": learner,
        "learner_package": spec.package,
        "params": params,
        "seed": seed,
        "batch_seeds": [b["seed"] for b in batches],
        "runs": int(Q.shape[0]),
        "episodes": episodes,
        "states": mdp.n_states,
        "actions": mdp.n_actions,
        "model_hash": mdp.content_hash,
        "v_star_start": batches[0]["v_star_start"],
        "final_value_gap": {"mean": float(np.mean(gaps)), "max": float(np.max(gaps))},
        "optimal_runs": int(np.sum(gaps < 1e-6)),
        "total_steps": int(curve["steps"].sum()),
        "files": files,
    }
    if not no_store:
        location = KBLocation.resolve(kb_path, kb_artifacts)  # only now: --no-store writes nothing
        summary["kb"] = _store(
            location,
            env,
            domain,
            task_obj,
            mdp,
            spec,
            Q,
            curve,
            summary,
            [b["seed"] for b in batches],
            counts,
        )
    files["summary"] = str(out / "summary.json")
    (out / "summary.json").write_text(dumps(summary))
    if as_json:
        echo_json(summary)
        return
    click.echo(
        f"{learner} on {env}/{task_obj.name}: {summary['runs']} runs x {episodes} episodes, "
        f"final value gap mean {summary['final_value_gap']['mean']:.3g} "
        f"max {summary['final_value_gap']['max']:.3g} "
        f"({summary['optimal_runs']}/{summary['runs']} runs optimal)"
    )
    click.echo(f"wrote {out}/: curve.parquet policy.parquet curve.png summary.json")
    if "kb" in summary:
        stored = summary["kb"]
        click.echo(
            f"stored in {stored['location']}: {stored['run']}, {stored['task']}, policies "
            f"{stored['policies'][0]} .. {stored['policies'][-1]}"
        )


def _store(
    location: KBLocation,
    env: str,
    domain: Any,
    task: Any,
    mdp: Any,
    spec: Any,
    Q: np.ndarray,
    curve: Any,
    summary: dict[str, Any],
    batch_seeds: list[int],
    counts: list[int],
) -> dict[str, Any]:
    """Record environment, task, one policy per run and the run itself; return their ids."""
    from adpart.store import KnowledgeBase

    dyn = domain.dynamics()
    kb = KnowledgeBase.open(location)
    try:
        environment = kb.put_environment(
            env,
            model_hash=dyn.content_hash,
            n_states=dyn.n_states,
            n_actions=dyn.n_actions,
            spec={"name": env, "source": domain.source, "actions": list(dyn.action_names)},
        )
        task_rec = kb.put_task(
            environment,
            task.name,
            spec={**task.spec, "name": task.name, "model_hash": mdp.content_hash},
            gamma=task.gamma,
        )
        steps = curve.matrix("steps").sum(axis=1)
        run_seeds = np.repeat(batch_seeds, counts)
        policies = [
            kb.put_policy(
                task_rec,
                spec.name,
                q=np.where(np.isfinite(Q[k]), Q[k], np.nan),
                pi=np.argmax(Q[k], axis=1).astype(np.int64),
                seed=int(run_seeds[k]),
                episodes=summary["episodes"],
                steps=int(steps[k]),
                plugin_version=spec.version,
                parameters=summary["params"],
            )
            for k in range(Q.shape[0])
        ]
        metrics = {
            k: summary[k]
            for k in (
                "final_value_gap",
                "optimal_runs",
                "total_steps",
                "v_star_start",
                "runs",
                "episodes",
            )
        }
        run = kb.put_run(
            task_rec,
            spec.name,
            curve=curve.to_arrow(),
            metrics=metrics,
            seed=summary["seed"],
            plugin_version=spec.version,
            parameters={
                **summary["params"],
                "batch_seeds": batch_seeds,
                "policies": [p.id for p in policies],
            },
        )
    finally:
        kb.close()
    return {
        "location": kb.label,
        "environment": f"environment:{environment.id}",
        "task": f"task:{task_rec.id}",
        "run": f"run:{run.id}",
        "policies": [f"policy:{p.id}" for p in policies],
    }


def _merge_curves(parts: list[dict[str, np.ndarray]], metadata: dict[str, Any]) -> Any:
    from adpart.learning.curves import LearningCurve

    offset = 0
    columns: dict[str, list[np.ndarray]] = {}
    for part in parts:
        shifted = dict(part)
        shifted["run"] = np.asarray(part["run"]) + offset
        offset = int(shifted["run"].max()) + 1
        for key, col in shifted.items():
            columns.setdefault(key, []).append(np.asarray(col))
    return LearningCurve({k: np.concatenate(v) for k, v in columns.items()}, metadata)


def _write_outputs(out: Path, curve: Any, Q: np.ndarray, plot_curves: Any) -> dict[str, str]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TaskError(
            f"cannot create output folder {out}: {exc.strerror}; choose another --out"
        ) from exc
    K, S, _ = Q.shape
    actions = np.argmax(Q, axis=2)
    policy = pa.table(
        {
            "run": np.repeat(np.arange(K, dtype=np.int64), S),
            "state": np.tile(np.arange(S, dtype=np.int64), K),
            "action": actions.reshape(-1).astype(np.int64),
            "value": np.take_along_axis(Q, actions[:, :, None], axis=2).reshape(-1),
        }
    )
    pq.write_table(curve.to_arrow(), out / "curve.parquet", compression="zstd")
    pq.write_table(policy, out / "policy.parquet", compression="zstd")
    plot_curves(curve, out / "curve.png", metric="value_gap")
    return {name: str(out / name) for name in ("curve.parquet", "policy.parquet", "curve.png")}
