"""Learn one task with a learner plugin: batches through an executor, outputs, KB records.

Runs can be split into batches that an executor computes in parallel; batch ``b`` of a request
with seed ``S`` and ``n > 1`` batches is seeded from ``SeedSequence(S).spawn(n)[b]``, so results
depend on the seed and the batch size, never on the executor or the number of workers.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from adpart.errors import PluginError, TaskError
from adpart.execution import Executor, SerialExecutor
from adpart.learning.comparison import per_run_to_bound
from adpart.learning.curves import LearningCurve
from adpart.learning.settings import Run
from adpart.mdp.experience import Experience
from adpart.plugins import get_registry
from adpart.workflows.progress import stage_progress
from adpart.workflows.refs import parse_ref
from adpart.workflows.resolve import base_environment, resolve_domain
from adpart.workflows.run_knowledge import run_knowledge
from adpart.workflows.store import KnowledgeStore

#: The run settings' defaults (one declaration: :class:`Run`).
_RUN = Run()


@dataclass(frozen=True)
class LearnRequest:
    """What to learn; plain data, so it can travel to worker processes and into JSON.

    Attributes:
        env: environment name (a plugin, or ``gym:<id>``).
        task: task name or ``goal:...`` spec; None for the environment's default task.
        learner: learner plugin name.
        params: learner parameters as given (validated against the plugin's declaration).
        runs: independent runs.
        episodes: episodes per run.
        seed: root seed.
        eval_every: score greedy policies exactly every this many episodes.
        runs_per_batch: batch size for the executor (0 = all runs in one batch).
        options: for option learners, ``subgoal-set:N``, ``option:1,option:2`` or ``primitive``
            (read from the knowledge base).
        partition: for the hierarchical learner, ``partition:N`` - the decision layer; its option
            set is used when ``options`` is not given.
        model: for the hierarchical learner, the model of the dynamics it may read instead of
            the task's: an environment estimated from experience, ``ENV@experience:run:N``
            (the learned-model regime, :func:`adpart.workflows.experience.belief_model`).
    """

    env: str
    task: str | None = None
    learner: str = "q-learning"
    params: dict[str, Any] = field(default_factory=dict)
    runs: int = _RUN.runs
    episodes: int = _RUN.episodes
    seed: int = _RUN.seed  # type: ignore[assignment]
    eval_every: int = _RUN.eval_every
    runs_per_batch: int = 0
    options: str | None = None
    partition: str | None = None
    model: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The request as plain data; ``model`` only when given (a request on the true model is
        the same data as before the field existed, so stored runs and sweep cells still match).
        """
        data = asdict(self)
        if data["model"] is None:
            del data["model"]
        return data

    def batches(self) -> list[tuple[int, int]]:
        """``(runs, seed)`` of every batch."""
        size = self.runs if self.runs_per_batch == 0 else min(self.runs_per_batch, self.runs)
        n = math.ceil(self.runs / size)
        counts = [size] * (n - 1) + [self.runs - size * (n - 1)]
        if n == 1:
            return [(counts[0], self.seed)]
        seeds = [
            int(c.generate_state(1, np.uint64)[0] >> np.uint64(1))
            for c in np.random.SeedSequence(self.seed).spawn(n)
        ]
        return list(zip(counts, seeds, strict=True))


@dataclass(frozen=True, eq=False)
class LearnOutcome:
    """The merged result of all batches of a :class:`LearnRequest`."""

    request: LearnRequest
    task_name: str
    params: dict[str, Any]
    learner_package: str
    learner_version: str
    Q: np.ndarray
    curve: LearningCurve
    batches: list[tuple[int, int]]
    v_star_start: float
    n_states: int
    n_actions: int
    model_hash: str
    option_ids: tuple[int, ...] = ()
    final_layers: tuple[tuple[np.ndarray, np.ndarray], ...] = ()
    """Per run, the decision layer a layer learner ended on: ``(labels, block actions)``."""
    experience: Experience | None = None
    """The transitions all runs took, when the learner counted them (stored with the run)."""

    def q_columns(self, action_names: Sequence[str]) -> list[str] | None:
        """Names of Q's columns when they are not just the primitive actions (option learners).

        A learner that added options of its own (the hierarchical learner's reward-variation
        modes: one per reward state, recorded as ``extra_subgoals`` in its curve's metadata) has
        them last, named ``reward-subgoal:S``.
        """
        cols = self.Q.shape[2]
        names = [f"option:{i}" for i in self.option_ids]
        extra = [f"reward-subgoal:{s}" for s in self.curve.metadata.get("extra_subgoals") or ()]
        if not names and not extra:
            return None
        if names and cols == len(names):
            return names
        if cols == self.n_actions + len(names) + len(extra):
            return [*action_names, *names, *extra]
        return None

    def summary(self) -> dict[str, Any]:
        from adpart.learning.curves import ROUNDING

        gaps = self.curve.matrix("value_gap")[:, -1]
        # a gap within rounding of 0 is 0 (an exact evaluation of the optimal policy differs
        # from V* by ~1e-15 of either sign): the summary says 0, not -8.9e-17
        v_star = float("nan") if self.v_star_start is None else float(self.v_star_start)
        scale = max(1.0, abs(v_star)) if np.isfinite(v_star) else 1.0
        gaps = np.where(np.abs(gaps) <= ROUNDING * scale, 0.0, gaps)
        return {
            "env": self.request.env,
            "task": self.task_name,
            "learner": self.request.learner,
            "learner_package": self.learner_package,
            "params": self.params,
            "seed": self.request.seed,
            "batch_seeds": [s for _, s in self.batches],
            "runs": int(self.Q.shape[0]),
            "episodes": self.request.episodes,
            "states": self.n_states,
            "actions": self.n_actions,
            "model_hash": self.model_hash,
            "v_star_start": self.v_star_start,
            "final_value_gap": {"mean": float(np.mean(gaps)), "max": float(np.max(gaps))},
            "optimal_runs": int(np.sum(gaps < 1e-6)),
            "total_steps": int(self.curve["steps"].sum()),
        }


def _learn_batch(job: dict[str, Any]) -> dict[str, Any]:
    """Executor work item: one batch of runs. Module-level so process pools can run it."""
    domain = resolve_domain(job["env"])
    mdp = domain.mdp(job["task"])
    learner = get_registry().get("learner", job["learner"]).create(job["params"])
    extra = {}
    if job.get("options") is not None:
        extra["options"] = job["options"]
    if job.get("partition") is not None:
        extra["partition"] = job["partition"]
    for given in ("belief", "experience", "policies"):  # what a --model gives the learner
        if job.get(given) is not None:
            extra[given] = job[given]
    result = learner.learn(
        mdp,
        runs=job["runs"],
        episodes=job["episodes"],
        seed=job["seed"],
        eval_every=job["eval_every"],
        progress=job.get("progress"),
        **extra,
    )
    runs = 1 if getattr(learner, "single_run", False) else job["runs"]
    check_learn_result(result, job["learner"], runs=runs, n_states=mdp.n_states)
    experience = getattr(result, "experience", None)
    return {
        "Q": result.Q,
        "experience": experience,
        "curve": result.curve.to_dict(),
        "metadata": dict(result.curve.metadata),
        "v_star_start": result.v_star_start,
        "layers": [(np.asarray(p.labels), np.asarray(p.admissible))
                   for p in getattr(result, "partitions", ())],
    }


def _check_accepts(spec: Any, request: LearnRequest) -> None:
    """Refuse options, a partition or a model for a learner that does not declare them
    (``accepts``; a model is given as ``belief`` or ``experience``)."""
    model = frozenset({"belief", "experience"})
    for what, option, given, inputs in (
            ("options", "options", request.options, frozenset({"options"})),
            ("partition", "partition", request.partition, frozenset({"partition"})),
            ("a model estimated from experience", "model", request.model, model)):
        if given is None or frozenset(getattr(spec.factory, "accepts", ())) & inputs:
            continue
        users = sorted(s.name for s in get_registry().all("learner")
                       if frozenset(getattr(s.factory, "accepts", ())) & inputs)
        raise PluginError(
            f"learner {spec.name!r} does not learn over {what}; drop --{option} or pick "
            f"--learner {' or '.join(users) or '(none installed)'}"
        )


def check_learn_result(result: Any, learner: str, *, runs: int, n_states: int) -> None:
    """The learner's result has what the workflows read (the :class:`LearnResult` fields).

    Raises:
        PluginError: naming the learner and the missing or misshapen field.
    """
    missing = [f for f in ("Q", "curve", "v_star_start") if not hasattr(result, f)]
    if missing:
        raise PluginError(
            f"learner {learner!r} returned a {type(result).__name__} without "
            f"{', '.join(missing)}; a learner returns an adpart.learning.LearnResult"
        )
    Q = np.asarray(result.Q)
    if Q.ndim != 3 or Q.shape[:2] != (runs, n_states):
        raise PluginError(
            f"learner {learner!r} returned Q of shape {Q.shape}; expected ({runs}, {n_states}, C)"
        )
    if not isinstance(result.curve, LearningCurve):
        raise PluginError(f"learner {learner!r} returned a curve that is not a LearningCurve")


def run_learning(
    request: LearnRequest,
    *,
    executor: Executor | None = None,
    progress: Callable[[int, int], object] | None = None,
    kb: KnowledgeStore | None = None,
) -> LearnOutcome:
    """Validate ``request``, learn all its batches (on ``executor`` when there are several).

    ``progress(done, total)`` is reported for a single batch computed in this process; without
    it, the bar a command installed (:func:`adpart.workflows.progress.progress_bars`) counts the
    episodes of a single batch, or the runs of batches learned one after another. ``kb`` is
    needed when the request names options or a partition.
    """
    spec = get_registry().get("learner", request.learner)
    _check_accepts(spec, request)
    params = spec.resolve_params(request.params)
    domain = resolve_domain(request.env)
    task = domain.task(request.task)
    mdp = domain.mdp(task)
    batches = request.batches()
    layer = _decision_layer(kb, request)
    option_ids = tuple(layer.pop("option_ids", ()))
    if request.model is not None:
        from adpart.workflows.experience import belief_model, resolve_model

        if kb is None:
            raise TaskError("--model is estimated from runs in the knowledge base; give --kb")
        estimated = resolve_model(kb, request.model)
        if base_environment(estimated.name) != request.env:
            raise TaskError(f"--model {request.model} is a model of "
                            f"{base_environment(estimated.name)!r}, not of {request.env!r}")
        accepts = getattr(spec.factory, "accepts", ())
        if "policies" in accepts:
            from adpart.workflows.experience import run_policies

            layer["policies"] = run_policies(kb, estimated.experience.sources)
        if "experience" in accepts:
            layer["experience"] = estimated.experience
        else:
            source = kb.get("run", parse_ref(estimated.experience.sources[0], "run"))
            layer["belief"] = belief_model(estimated, mdp, kb.get("task", source.task_id).name)
    jobs = [
        {
            "env": request.env,
            "task": task.name if request.task is None else request.task,
            "learner": request.learner,
            "params": params,
            "runs": runs,
            "episodes": request.episodes,
            "seed": seed,
            "eval_every": request.eval_every,
            **layer,
        }
        for runs, seed in batches
    ]
    label = f"{request.learner} on {request.env}/{task.name}"
    if len(jobs) == 1:
        with stage_progress(0 if progress else request.episodes, label) as bar:
            results = [_learn_batch({**jobs[0], "progress": progress or bar})]
    else:
        with stage_progress(0 if progress else request.runs, f"{label} (runs)") as bar, \
                executor or SerialExecutor() as ex:
            if bar is None or ex.parallel:
                results = ex.map(_learn_batch, jobs)
            else:  # one batch after another: the bar counts runs done
                results = []
                for job in jobs:
                    results += ex.map(_learn_batch, [job])
                    bar(sum(r["Q"].shape[0] for r in results), request.runs)
    return LearnOutcome(
        request=request,
        task_name=task.name,
        params=params,
        learner_package=spec.package,
        learner_version=spec.version,
        Q=np.concatenate([r["Q"] for r in results]),
        curve=_merge_curves([r["curve"] for r in results], [r["metadata"] for r in results]),
        batches=batches,
        v_star_start=float(results[0]["v_star_start"]),
        n_states=mdp.n_states,
        n_actions=mdp.n_actions,
        model_hash=mdp.content_hash,
        option_ids=option_ids,
        final_layers=tuple(layer for r in results for layer in r.get("layers", ())),
        experience=_merge_experience(results),
    )


def _merge_experience(results: list[dict[str, Any]]) -> Experience | None:
    """All batches' experience together, or None when the learner counts none."""
    parts = [r.get("experience") for r in results]
    return None if any(p is None for p in parts) else Experience.merge(parts)


def _decision_layer(kb: KnowledgeStore | None, request: LearnRequest) -> dict[str, Any]:
    """Options and partition named by ``request``, loaded from the knowledge base."""
    if request.options is None and request.partition is None:
        return {}
    if kb is None:
        raise TaskError("--options/--partition are read from the knowledge base; give --kb")
    return load_decision_layer(kb, request.env, options=request.options,
                               partition=request.partition)


def load_decision_layer(kb: KnowledgeStore, env: str, *, options: str | None = None,
                        partition: str | None = None) -> dict[str, Any]:
    """A layer learner's ``options`` (and their ids, ``option_ids``) and ``partition`` named
    as on the command line (``partition:N``; its own options unless ``options`` is given),
    loaded from the knowledge base."""
    from adpart.workflows.options import resolve_option_set
    from adpart.workflows.refs import get_ref

    layer: dict[str, Any] = {}
    partition_rec = None
    if partition is not None:
        partition_rec = get_ref(kb, partition, "partition")
    options_text = options
    if options_text is None and partition_rec is not None:
        options_text = ",".join(f"option:{i}" for i in partition_rec.option_ids) or "primitive"
    option_set = resolve_option_set(kb, options_text, env)
    layer["options"] = option_set.options
    layer["option_ids"] = option_set.ids
    if partition_rec is not None:
        from adpart.partition import Partition

        if list(partition_rec.option_ids) != option_set.ids:
            raise TaskError(
                f"{partition_rec.ref} was built over options {list(partition_rec.option_ids)}, "
                f"not {option_set.ids}; omit --options to use the partition's own"
            )
        labels = kb.load(partition_rec, "labels")
        admissible = kb.load(partition_rec, "block_actions")
        layer["partition"] = Partition(labels, admissible.astype(bool))
    return layer


#: Curve metadata with one entry per run (concatenated across batches, stored in the run's
#: metrics): a layer learner's blocks after refinement, its firings and the real ones among them.
PER_RUN_METADATA = ("final_blocks", "firings", "real_firings", "tied_firings", "own_step_ties",
                    "phase3_blocks")


def _merge_curves(parts: list[dict[str, np.ndarray]], metadatas: list[dict[str, Any]]
                  ) -> LearningCurve:
    """One curve of all batches' runs; per-run metadata lists (``final_blocks``) concatenated."""
    metadata = metadatas[0]
    offset = 0
    columns: dict[str, list[np.ndarray]] = {}
    for part in parts:
        shifted = dict(part)
        shifted["run"] = np.asarray(part["run"]) + offset
        offset = int(shifted["run"].max()) + 1
        for key, col in shifted.items():
            columns.setdefault(key, []).append(np.asarray(col))
    for key in PER_RUN_METADATA:
        if all(key in part_meta for part_meta in metadatas):
            metadata = {**metadata, key: [b for m in metadatas for b in m[key]]}
    return LearningCurve({k: np.concatenate(v) for k, v in columns.items()}, metadata)


def write_learning_outputs(out: Path, outcome: LearnOutcome) -> dict[str, str]:
    """curve.parquet, policy.parquet (run, state, action, value) and curve.png in ``out``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from adpart.learning.curves import plot_curves

    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TaskError(
            f"cannot create output folder {out}: {exc.strerror}; choose another --out"
        ) from exc
    Q = outcome.Q
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
    pq.write_table(outcome.curve.to_arrow(), out / "curve.parquet", compression="zstd")
    pq.write_table(policy, out / "policy.parquet", compression="zstd")
    plot_curves(outcome.curve, out / "curve.png", metric="value_gap")
    return {name: str(out / name) for name in ("curve.parquet", "policy.parquet", "curve.png")}


def record_learning(kb: KnowledgeStore, outcome: LearnOutcome) -> dict[str, Any]:
    """Record environment, task, one policy per run and the run itself; return their ids.

    Everything is written in one knowledge-base transaction (``kb.transaction()``), so a kill
    or an error part-way leaves no policy without its run: stored whole or not at all.
    """
    with kb.transaction():
        return _record_learning(kb, outcome)


def _record_learning(kb: KnowledgeStore, outcome: LearnOutcome) -> dict[str, Any]:
    request = outcome.request
    domain = resolve_domain(request.env)
    dyn = domain.dynamics()
    task = domain.task(request.task)
    summary = outcome.summary()
    environment = kb.put_environment(
        request.env,
        model_hash=dyn.content_hash,
        n_states=dyn.n_states,
        n_actions=dyn.n_actions,
        spec={"name": request.env, "source": domain.source, "actions": list(dyn.action_names),
              **({"make_kwargs": dict(domain.make_kwargs)}
                 if getattr(domain, "make_kwargs", None) else {})},
    )
    task_rec = kb.put_task(
        environment,
        task.name,
        spec={**task.spec, "name": task.name, "model_hash": outcome.model_hash},
        gamma=task.gamma,
    )
    Q = outcome.Q
    steps = outcome.curve.matrix("steps").sum(axis=1)
    run_seeds = np.repeat([s for _, s in outcome.batches], [k for k, _ in outcome.batches])
    provenance = {
        "plugin_version": outcome.learner_version,
        "parameters": outcome.params,
        "q_columns": outcome.q_columns(dyn.action_names),
    }
    policies = [
        kb.put_policy(
            task_rec,
            request.learner,
            q=np.where(np.isfinite(Q[k]), Q[k], np.nan),
            pi=np.argmax(Q[k], axis=1).astype(np.int64),
            seed=int(run_seeds[k]),
            episodes=request.episodes,
            steps=int(steps[k]),
            **provenance,
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
    for key in PER_RUN_METADATA:  # a decision layer's blocks after refinement, its firings
        if key in outcome.curve.metadata:
            metrics[key] = list(outcome.curve.metadata[key])
    if "initial_blocks" in outcome.curve.metadata:
        metrics["initial_blocks"] = int(outcome.curve.metadata["initial_blocks"])
    per_run = per_run_to_bound(outcome.curve)  # the pipeline's and comparisons' definition
    if per_run is not None:
        metrics["per_run"] = per_run
    if outcome.experience is not None:
        metrics["experience"] = {k: v for k, v in outcome.experience.summary().items()
                                 if k != "sources"}
    partition_id = None
    if request.partition is not None:
        partition_id = parse_ref(request.partition, "partition")
    start = kb.get("partition", partition_id) if partition_id is not None else None
    knowledge = run_knowledge(outcome.curve.metadata.get("knowledge"), outcome.option_ids, start,
                              _estimated_from(kb, outcome.option_ids, request.model))
    if knowledge is not None:
        metrics["knowledge"] = knowledge.to_dict()
    final = _put_final_layers(kb, environment, task_rec, outcome, partition_id)
    if final:
        metrics["final_partitions"] = final
    run = kb.put_run(
        task_rec,
        request.learner,
        partition=partition_id,
        curve=outcome.curve.to_arrow(),
        experience=None if outcome.experience is None else outcome.experience.to_table(),
        metrics=metrics,
        seed=request.seed,
        plugin_version=outcome.learner_version,
        parameters={
            **outcome.params,
            "request": canonical_request(request),
            "policies": [p.id for p in policies],
        },
    )
    return {
        "location": kb.label,
        "environment": f"environment:{environment.id}",
        "task": f"task:{task_rec.id}",
        "run": f"run:{run.id}",
        "policies": [f"policy:{p.id}" for p in policies],
    }


def _estimated_from(kb: KnowledgeStore, option_ids: Sequence[int], model: str | None = None
                    ) -> str | None:
    """The runs whose experience estimated the model the options were built on (None: they
    were built on the true model; a layer's options are all of one environment).

    Environments are keyed by their model's hash, so an estimate equal to the true model (a
    deterministic first task that tried every pair) is stored as the true environment's record;
    with the request's ``model`` (``ENV@experience:run:N``) of that same hash the options were
    built on the estimate all the same, and the record says so."""
    from adpart.workflows.resolve import EXPERIENCE_MARK

    if not option_ids:
        return None
    env = _options_environment(kb, option_ids)
    if EXPERIENCE_MARK in env.name:
        return env.name.split(EXPERIENCE_MARK, 1)[1]
    if model is not None and EXPERIENCE_MARK in model:
        from adpart.workflows.experience import resolve_model

        if resolve_model(kb, model).dynamics().content_hash == env.model_hash:
            return model.split(EXPERIENCE_MARK, 1)[1]
    return None


def _options_environment(kb: KnowledgeStore, option_ids: Sequence[int]) -> Any:
    """The environment record the options (all of one environment) were stored under."""
    return kb.get("environment", kb.get("option", option_ids[0]).environment_id)


def _put_final_layers(kb: KnowledgeStore, environment: Any, task: Any, outcome: LearnOutcome,
                      start: int | None) -> list[int]:
    """Store the distinct layers the runs ended on (kind ``learned``, the starting layer their
    parent); return each run's partition id. A layer whose columns are not the primitives
    followed by the stored options (reward-state options of the learner's own) is not stored."""
    if not outcome.final_layers:
        return []
    n_cols = outcome.n_actions + len(outcome.option_ids)
    meta = outcome.curve.metadata
    named: dict[str, Any] = {}
    if outcome.option_ids:  # the layer is over the options, of their environment (a model
        # estimated from experience, in the learned-model regime: then the task is named only)
        own = _options_environment(kb, outcome.option_ids)
        if own.id != environment.id:
            environment, task, named = own, None, {"task_id": task.id}
    delta = float(meta.get("delta") or 0.0)
    epsilon = meta.get("epsilon")
    stored: dict[bytes, int] = {}
    ids = []
    for labels, admissible in outcome.final_layers:
        if admissible.shape[1] != n_cols:
            return []
        key = labels.astype(np.int64).tobytes() + admissible.astype(bool).tobytes()
        if key not in stored:
            rec = kb.put_partition(
                environment, "learned", labels.astype(np.int64), options=list(outcome.option_ids),
                includes_primitives=True, block_actions=admissible.astype(bool),
                epsilon=float("inf") if epsilon is None else float(epsilon), delta=delta,
                parents=[start] if start is not None else [], task=task,
                plugin=outcome.request.learner, plugin_version=outcome.learner_version,
                parameters={"refined_by": outcome.request.learner,
                            "blocks": int(labels.max()) + 1, **named},
            )
            stored[key] = rec.id
        ids.append(stored[key])
    return ids


def canonical_request(request: LearnRequest) -> dict[str, Any]:
    """``request`` as it is stored and looked up: equal work gives an equal dict.

    The task is the environment's own name for it (``None`` -> the default task's name), and
    the parameters are the learner's full declaration resolved (``max-steps`` and ``max_steps``,
    ``"5000"`` and ``5000``, an omitted default and the default given are the same request).
    Batching stays part of it: batches draw other seeds.
    """
    spec = get_registry().get("learner", request.learner)
    task = resolve_domain(request.env).task(request.task).name
    canonical = replace(request, task=task, params=spec.resolve_params(request.params))
    return json.loads(json.dumps(canonical.to_dict(), allow_nan=False))


def find_learning(kb: KnowledgeStore, request: LearnRequest) -> dict[str, Any] | None:
    """The ids of a run already recorded for exactly ``request``, or None.

    Runs are matched on the request as recorded by :func:`record_learning` (environment, task,
    learner, parameters, runs, episodes, seed, batching, options, partition), in the spelling of
    :func:`canonical_request`, so a pipeline that is run again - or that starts with a task the
    user already learned with ``adpart learn`` - reuses what was learned instead of learning it
    again.
    """
    wanted = canonical_request(request)
    for env in kb.records("environment"):
        if env.name != request.env:
            continue
        for task, runs in kb.learned_tasks(env):
            for run in reversed(runs):
                if run.provenance.parameters.get("request") == wanted:
                    return {
                        "location": kb.label,
                        "environment": f"environment:{env.id}",
                        "task": f"task:{task.id}",
                        "run": f"run:{run.id}",
                        "policies": [
                            f"policy:{p}" for p in run.provenance.parameters.get("policies", [])
                        ],
                    }
    return None


def load_curve(kb: KnowledgeStore, run: Any) -> LearningCurve:
    """A stored run's learning curve, with ``v_star_start`` and the learner restored from the run.

    The knowledge base keeps a curve's columns; what is needed to read them (V* at the start
    distribution) is kept in the run's metrics.
    """
    curve = LearningCurve.from_arrow(kb.load(run, "curve"))
    metadata = {
        **curve.metadata,
        "learner": run.learner,
        "v_star_start": run.metrics.get("v_star_start", curve.metadata.get("v_star_start")),
    }
    for key in ("initial_blocks", *PER_RUN_METADATA):  # a decision layer's blocks, firings
        if key in run.metrics:
            metadata[key] = run.metrics[key]
    return LearningCurve(dict(curve.columns), metadata)
